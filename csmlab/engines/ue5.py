"""Unreal Engine 5: ``DefaultEngine.ini`` / ``DefaultScalability.ini`` shadow cvars and a DirectionalLight as T3D.

The ini files are read with configparser (duplicate keys allowed, case kept); ``r.Shadow.*`` cvars are
taken from any section of DefaultEngine.ini and from DefaultScalability.ini's ``[ShadowQuality@N]``
with N = ``sg.ShadowQuality`` (default 3, Epic). The light is the editor's clipboard text (T3D:
``Begin Actor Class=…DirectionalLight`` … ``Begin Object`` blocks of ``Key=Value`` lines). Mapping:
``DynamicShadowCascades`` (capped by ``r.Shadow.CSM.MaxCascades``), ``CascadeDistributionExponent``
(split = "exponent"), ``DynamicShadowDistanceMovableLight`` (cm, × ``r.Shadow.DistanceScale``),
``CascadeTransitionFraction`` (blend_band, × ``r.Shadow.CSM.TransitionScale``),
``ShadowDistanceFadeoutFraction`` (fade_out), ``r.Shadow.MaxCSMResolution`` (resolution). Missing values
keep ``configs/engines/ue5.toml`` (T3D holds only properties changed from the defaults).

The snippet (export_ue5) names: console variables ``r.Shadow.CSM.MaxCascades``, ``r.Shadow.MaxCSMResolution``;
directional light properties ``DynamicShadowCascades``, ``DynamicShadowDistanceMovableLight`` (cm),
``CascadeDistributionExponent`` (split i at the geometric sum of exponent powers, ``ComputeAccumulatedScale``
in the renderer), ``CascadeTransitionFraction``, ``ShadowDistanceFadeoutFraction``.
"""

from __future__ import annotations

import configparser
import math
import re
from pathlib import Path

import numpy as np

from csmlab.cascades.splits import split_boundaries, ue_split_fractions
from csmlab.engines.common import (Engine, EngineFiles, Snippet, TuneSpace, common_lacking, fixed_preset, four_digits,
                                   largest_resolution, shape_lacking)
from csmlab.engines.reading import Entry, Imported, Reading, read_text
from csmlab.errors import InputError
from csmlab.settings import ShadowSettings

__all__ = ["ENGINE", "FIELDS", "PRESET", "TUNE_SPACE", "UE5_FILTER", "export_ue5", "read_ue5", "write_ue5"]

PRESET = "ue5"
"""The engine preset holding Unreal's defaults."""

FIELDS = frozenset({"cascades", "split", "distribution_exponent", "shadow_distance", "blend_band", "fade_out",
                    "resolution"})
"""The csmlab fields the ini files and the light carry."""

UE5_FILTER = ("pcf", 3)
"""The csmlab filter and size Unreal's shadow filtering matches (r.Shadow.FilterMethod=0); others are lacking."""

_DEFAULT_SHADOW_QUALITY = 3
"""sg.ShadowQuality's default level (Epic)."""
_BEGIN = re.compile(r"^\s*Begin\s+(\w+)(.*)$", re.I)
_END = re.compile(r"^\s*End\s+(\w+)", re.I)
_PROPERTY = re.compile(r"^\s*([A-Za-z_][\w]*(?:\(\d+\))?)\s*=\s*(.*?)\s*$")


def _ini(path) -> configparser.ConfigParser:
    parser = configparser.ConfigParser(strict=False, interpolation=None, allow_no_value=True,
                                       comment_prefixes=(";", "#"), inline_comment_prefixes=None)
    parser.optionxform = str
    try:
        parser.read_string(read_text(path), source=str(path))
    except configparser.Error as exc:
        raise InputError(f"expected an Unreal ini file, got {exc.message.splitlines()[0]}", file=path,
                         line=getattr(exc, "lineno", None)) from None
    return parser


def _light_properties(path) -> dict:
    """``{Key: value}`` of the first DirectionalLight actor in T3D text (its components' property lines)."""
    properties, found = {}, False
    for line in read_text(path).splitlines():
        begin, end = _BEGIN.match(line), _END.match(line)
        if begin and begin.group(1).lower() == "actor":
            if found:
                break
            found = re.search(r"Class=\S*\bDirectionalLight\b", begin.group(2)) is not None
        elif found and end and end.group(1).lower() == "actor":
            break
        elif found and not begin and not end:
            match = _PROPERTY.match(line)
            if match:
                properties.setdefault(match.group(1), match.group(2))
    if not found:
        raise InputError("expected T3D text with a DirectionalLight actor (Begin Actor Class=…DirectionalLight)",
                         file=path, field="Begin Actor")
    return properties


def read_ue5(paths) -> Imported:
    """Unreal settings from ini files and a DirectionalLight's T3D text (any of them).

    Raises
    ------
    InputError
        A file of another kind, malformed text, or a value out of range (file and key named).
    """
    reading = Reading("ue5", PRESET)
    base = reading.base
    cvars, light, scalability = {}, {}, []
    for path in paths:
        if Path(path).suffix.lower() == ".ini":
            parser = _ini(path)
            if any(s.startswith("ShadowQuality@") for s in parser.sections()):
                scalability.append((path, parser))
            for section in parser.sections():
                if "@" in section:
                    continue  # a scalability level: only the one in use applies, below
                for key, value in parser.items(section):
                    if key.lower().startswith(("r.shadow", "sg.shadowquality")):
                        cvars[key.lower()] = _cvar(value, file=path, key=f"[{section}] {key}")
        else:
            light = {k: Entry(v, file=path, key=f"DirectionalLight.{k}") for k, v in _light_properties(path).items()}
    level = cvars["sg.shadowquality"].integer(minimum=0) if "sg.shadowquality" in cvars else _DEFAULT_SHADOW_QUALITY
    for path, parser in scalability:
        section = f"ShadowQuality@{level}"
        if parser.has_section(section):
            for key, value in parser.items(section):
                cvars.setdefault(key.lower(), _cvar(value, file=path, key=f"[{section}] {key}"))

    def cvar(name) -> Entry:
        return cvars.pop(name.lower())

    def prop(name) -> Entry:
        return light.pop(name)

    cascades = base.cascades
    if "DynamicShadowCascades" in light:
        entry = prop("DynamicShadowCascades")
        cascades = entry.integer(minimum=1)
        reading.set("cascades", cascades, file=entry.file, key=entry.key)
    if "r.shadow.csm.maxcascades" in cvars:
        entry = cvar("r.Shadow.CSM.MaxCascades")
        cap = entry.integer(minimum=1)
        if cap < cascades:
            cascades = cap
            reading.set("cascades", cap, file=entry.file, key=entry.key)
    if "CascadeDistributionExponent" in light:
        entry = prop("CascadeDistributionExponent")
        exponent = entry.number(minimum=1.0)
        reading.set("split", "exponent", file=entry.file, key=entry.key, raw=exponent)
        reading.set("distribution_exponent", exponent, file=entry.file, key=entry.key)
    scale = 1.0
    if "r.shadow.distancescale" in cvars:
        scale_entry = cvar("r.Shadow.DistanceScale")
        scale = scale_entry.number(above=0.0)
    if "DynamicShadowDistanceMovableLight" in light:
        entry = prop("DynamicShadowDistanceMovableLight")
        distance = entry.number(above=0.0)
        reading.set("shadow_distance", _finite(distance / 100.0 * scale, entry), file=entry.file, key=entry.key,
                    raw=f"{distance} cm")
    elif scale != 1.0:
        reading.set("shadow_distance", _finite(base.shadow_distance * scale, scale_entry), file=scale_entry.file,
                    key=scale_entry.key, raw=scale)
    transition = 1.0
    if "r.shadow.csm.transitionscale" in cvars:
        transition_entry = cvar("r.Shadow.CSM.TransitionScale")
        transition = transition_entry.number(minimum=0.0)
    if "CascadeTransitionFraction" in light:
        entry = prop("CascadeTransitionFraction")
        fraction = entry.number(minimum=0.0)
        reading.set("blend_band", _finite(fraction * transition, entry), file=entry.file, key=entry.key, raw=fraction)
    elif transition != 1.0:
        reading.set("blend_band", base.blend_band * transition, file=transition_entry.file, key=transition_entry.key,
                    raw=transition)
    if "ShadowDistanceFadeoutFraction" in light:
        entry = prop("ShadowDistanceFadeoutFraction")
        reading.set("fade_out", entry.number(minimum=0.0), file=entry.file, key=entry.key)
    if "r.shadow.maxcsmresolution" in cvars:
        entry = cvar("r.Shadow.MaxCSMResolution")
        reading.set("resolution", entry.integer(minimum=1), file=entry.file, key=entry.key)
    for name, entry in sorted(cvars.items()):
        why = ("virtual shadow maps replace cascaded shadow maps when on; csmlab models the cascades"
               if name == "r.shadow.virtual.enable" else "no csmlab knob")
        if name not in ("sg.shadowquality", "r.shadow.filtermethod") or entry.raw not in ("0", str(level)):
            reading.lack(file=entry.file, key=entry.key, value=entry.raw, why=why)
    for name, entry in sorted(light.items()):
        if re.search(r"Shadow|Cascade", name):
            reading.lack(file=entry.file, key=entry.key, value=entry.raw, why="no csmlab knob")
    return reading.result()


def _cvar(value: str | None, *, file, key: str) -> Entry:
    """A cvar's value: the engine reads its leading text, project files often trail it with "; comment"."""
    return Entry(None if value is None else value.split(";", 1)[0].strip(), file=file, key=key)


def _finite(value: float, entry: Entry) -> float:
    """``value``, a product of ``entry``'s number and a scale, checked finite."""
    if not math.isfinite(value):
        raise entry.error("a value whose product with its scale cvar is finite")
    return value


def _nearest_exponent(boundaries: np.ndarray, count: int) -> tuple[float, float]:
    """The CascadeDistributionExponent in 1 … 10 (steps of 0.01) whose splits come closest to ``boundaries``
    ``(count + 1,)``, and its largest miss as a fraction of the range (Unreal's only split control)."""
    wanted = (boundaries - boundaries[0]) / (boundaries[-1] - boundaries[0])
    exponents = np.arange(1.0, 10.0001, 0.01)
    errors = [np.abs(ue_split_fractions(e, count) - wanted).max() for e in exponents]
    best = int(np.argmin(errors))
    return float(exponents[best]), errors[best]


def write_ue5(settings: ShadowSettings, *, near: float, far: float) -> tuple[dict, list]:
    """``settings`` as ``DefaultEngine.ini`` and a DirectionalLight's T3D text, and the knobs they cannot hold."""
    z = split_boundaries(settings, near=near, far=far)
    if settings.split == "exponent":
        exponent = settings.distribution_exponent
    else:
        exponent, _ = _nearest_exponent(z, settings.cascades)
    size = largest_resolution(settings)
    ini = ["[/Script/Engine.RendererSettings]", "r.Shadow.Virtual.Enable=0", "",
           "[SystemSettings]", f"r.Shadow.CSM.MaxCascades={settings.cascades}", f"r.Shadow.MaxCSMResolution={size}",
           "r.Shadow.FilterMethod=0"]
    t3d = ["Begin Map", "   Begin Level",
           "      Begin Actor Class=/Script/Engine.DirectionalLight Name=DirectionalLight_0",
           '         Begin Object Class=/Script/Engine.DirectionalLightComponent Name="LightComponent0"',
           "         End Object",
           '         Begin Object Name="LightComponent0"',
           f"            DynamicShadowDistanceMovableLight={float(z[-1]) * 100.0!r}",
           f"            DynamicShadowCascades={settings.cascades}",
           f"            CascadeDistributionExponent={exponent!r}",
           f"            CascadeTransitionFraction={settings.blend_band!r}",
           f"            ShadowDistanceFadeoutFraction={settings.fade_out!r}",
           "         End Object",
           '         LightComponent="LightComponent0"',
           "      End Actor", "   End Level", "End Map"]
    return {"DefaultEngine.ini": "\n".join(ini) + "\n", "DirectionalLight.t3d": "\n".join(t3d) + "\n"}, []


def export_ue5(settings: ShadowSettings, *, near: float, far: float) -> Snippet:
    """UE5: cvars for an ini file, directional light properties as comments (distances in cm)."""
    z = split_boundaries(settings, near=near, far=far)
    # An exponent split is Unreal's own: written as it is, it misses nothing.
    exponent, error = ((settings.distribution_exponent, 0.0) if settings.split == "exponent"
                       else _nearest_exponent(z, settings.cascades))
    error_m = error * (z[-1] - z[0])
    lacking = common_lacking(settings, stable="exact", carried=FIELDS) + shape_lacking(settings, transition="forward",
                                                                                      fade="linear")
    if error_m > 0.01:
        lacking.append(f"split distances {[round(float(v), 2) for v in z[1:-1]]} m: Unreal's exponent spacing "
                       f"misses them by up to {error_m:.2f} m")
    if (settings.filter, settings.filter_size) != UE5_FILTER:
        lacking.append(f"filter = {settings.filter!r}, filter_size = {settings.filter_size} (Unreal's PCF kernel "
                       f"follows r.ShadowQuality)")
    text = "\n".join([
        "; DefaultEngine.ini (or ConsoleVariables.ini)",
        "[SystemSettings]",
        f"r.Shadow.CSM.MaxCascades={settings.cascades}",
        f"r.Shadow.MaxCSMResolution={largest_resolution(settings)}",
        "r.Shadow.FilterMethod=0",
        "",
        "; DirectionalLight > Cascaded Shadow Maps",
        f";   DynamicShadowCascades={settings.cascades}",
        f";   DynamicShadowDistanceMovableLight={z[-1] * 100.0:.0f}    ; cm",
        f";   CascadeDistributionExponent={exponent:.2f}",
        f";   CascadeTransitionFraction={four_digits(settings.blend_band)}",
        f";   ShadowDistanceFadeoutFraction={four_digits(settings.fade_out)}",
    ])
    return Snippet("ue5", "Unreal Engine 5: console variables and directional light", "ini", text + "\n",
                   tuple(lacking))


TUNE_SPACE = TuneSpace({
    # DirectionalLightComponent: DynamicShadowCascades 1 to 10, CascadeDistributionExponent 1 to 4,
    # DynamicShadowDistanceMovableLight (from 5 m), CascadeTransitionFraction 0 to 0.3,
    # ShadowDistanceFadeoutFraction 0 to 1 (the component's UI ranges; the exponent to the 0.01 the snippet
    # prints); r.Shadow.MaxCSMResolution.
    "cascades": ("choice", tuple(range(1, 11))),
    "distribution_exponent": ("range", 1.0, 4.0, False, 0.01),
    "shadow_distance": ("range", 5.0, 2000.0, True, None),
    "blend_band": ("range", 0.0, 0.3, False, None),
    "fade_out": ("range", 0.0, 1.0, False, None),
    "resolution": ("choice", (512, 1024, 2048, 4096)),
})
"""What a tune of the Unreal preset may try: the directional light's and the cvars' own cascade settings."""

ENGINE = Engine("ue5", export_ue5, EngineFiles(
    read=read_ue5, write=write_ue5, fields=FIELDS, preset=fixed_preset(PRESET), presets=(PRESET,),
    files="DefaultEngine.ini, DefaultScalability.ini and/or a DirectionalLight's T3D text"), tune=TUNE_SPACE)
"""What the registries of csmlab.engines take from this module."""
