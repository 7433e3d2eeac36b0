"""Godot 4: ``project.godot`` and a ``.tscn`` scene holding a ``DirectionalLight3D``, read and written.

Both are Godot ``ConfigFile`` text: ``[section]`` headers (in a scene, ``[node name="…" type="…"]``)
followed by ``key = value`` lines. The light's ``directional_shadow_*``, ``shadow_*`` and
``light_angular_distance`` properties and the project's ``rendering/lights_and_shadows/directional_shadow/``
settings map to csmlab fields; a property the file leaves out keeps Godot's default, which is
``configs/engines/godot4.toml``'s value (Godot writes only changed properties).

Sources: DirectionalLight3D and Light3D class references; ``light_storage.cpp``
``LightStorage::update_light_buffers`` (``shadow_bias / 100 · bias_scale``, ``bias_scale = depth range ·
soft_shadow_scale`` with soft_shadow_scale 2: ``bias_depth_range = shadow_bias · 0.02``; ``shadow_normal_bias``
texels); ``RendererSceneRenderRD::directional_soft_shadow_filter_set_quality`` (Hard … Ultra: 0 to 32 taps at a
quality radius, × ``shadow_blur``: csmlab.lookup_choices.GODOT_SOFT_SHADOW_QUALITIES); ``scene_forward_clustered.glsl``
``light_process`` (``directional_shadow_blend_splits``: csmlab.cascades.fit.GODOT_BLEND_SPLITS);
``RendererSceneCull::get_directional_light_shadow_size`` (2 or 4 splits: half the atlas).

The snippet (export_godot4) names: ``DirectionalLight3D.directional_shadow_mode`` (orthogonal, 2 or 4 splits),
``directional_shadow_max_distance``, ``directional_shadow_split_1..3``, ``directional_shadow_blend_splits``;
project setting ``rendering/lights_and_shadows/directional_shadow/size`` (the atlas).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from csmlab.cascades.fit import GODOT_BLEND_SPLITS
from csmlab.cascades.splits import count_one_two_or_four, fractions_of_range, split_boundaries
from csmlab.engines.common import (Engine, EngineFiles, Snippet, TuneSpace, common_lacking,
                                   fixed_preset, four_digits, hard_filter, largest_resolution, shape_lacking,
                                   storage_lacking, vogel_is)
from csmlab.engines.reading import Entry, Imported, Located, Reading, engine_settings, read_text
from csmlab.errors import InputError
from csmlab.lookup_choices import GODOT_SOFT_SHADOW_QUALITIES, godot_soft_shadow_fields
from csmlab.settings import ShadowSettings

__all__ = ["ENGINE", "FIELDS", "GODOT_SOFT_LOW", "PRESET", "TUNE_SPACE", "SceneInstance", "config_sections",
           "export_godot4", "gltf_instances", "level_instances", "read_godot4", "settled_godot4", "write_godot4"]

PRESET = "godot4"
"""The engine preset holding Godot's defaults."""

FIELDS = frozenset({"cascades", "split", "splits", "shadow_distance", "fade_out", "pancake", "bias_depth_range",
                    "normal_offset", "vogel_taps", "vogel_radius", "vogel_angle", "vogel_scale", "cull", "resolution",
                    "filter", "depth_format", "blend_band", "transition", "blend_curve", "storage"})
"""The csmlab fields Godot's files carry (storage: one split fills the atlas, directional_shadow_mode = 0)."""

GODOT_SOFT_LOW = {"vogel_taps": 4, "vogel_radius": 2.0, "vogel_angle": 2.4, "vogel_scale": "first_split"}
"""Godot 4's Soft Low (soft_shadow_filter_quality = 2) as csmlab's ``pcf_vogel`` fields
(configs/engines/godot4.toml)."""
GODOT_SOFT_LOW_LEVEL = 2
"""The project setting's default level, Soft Low (the preset's filter)."""

SHADOW_BIAS_SCALE = 0.02
"""bias_depth_range per unit of Light3D.shadow_bias: / 100 × soft_shadow_scale 2.0 (light_storage.cpp)."""

_MODES = {0: 1, 1: 2, 2: 4}
_PROJECT = "rendering/lights_and_shadows/directional_shadow/"
_HEADER = re.compile(r"^\[(?P<kind>[A-Za-z_]+)(?P<attrs>.*)\]\s*$")
_ATTR = re.compile(r'(\w+)=("(?:[^"\\]|\\.)*"|\S+)')


def _value(text: str):
    """A ConfigFile value: bool, number or string (anything else, e.g. ``Transform3D(…)``, as its text)."""
    text = text.strip()
    if text in ("true", "false"):
        return text == "true"
    if text.startswith('"') and text.endswith('"') and len(text) >= 2:
        return text[1:-1]
    try:
        return int(text)
    except ValueError:
        pass
    try:
        return float(text)
    except ValueError:
        return text


def _open(value: str) -> bool:
    """Whether ``value`` continues on the next line: a string or a bracket still open."""
    unquoted = re.sub(r'"(?:[^"\\]|\\.)*"', "", value)
    return '"' in unquoted or sum(unquoted.count(o) - unquoted.count(c) for o, c in ("()", "[]", "{}")) > 0


def _located(line: int) -> Located:
    keys = Located()
    keys.line, keys.key_lines = line, {}
    return keys


def config_sections(path) -> list[tuple[str, dict, dict, int]]:
    """The sections of a Godot ConfigFile: ``(kind, header attributes, {key: value}, header line)`` in file order.

    Lines before the first header form the section of kind ``""``; a value whose brackets are still
    open continues on the next lines. Each ``{key: value}`` is :class:`~csmlab.engines.reading.Located` at its
    header's line, for an :class:`~csmlab.engines.reading.Entry` of it.
    """
    sections = [("", {}, _located(1), 0)]
    lines = read_text(path).splitlines()
    i = 0
    while i < len(lines):
        line = lines[i].strip()
        i += 1
        if not line or line.startswith(";"):
            continue
        header = _HEADER.match(line)
        if header:
            attrs = {k: _value(v) for k, v in _ATTR.findall(header.group("attrs"))}
            sections.append((header.group("kind"), attrs, _located(i), i))
            continue
        if "=" not in line:
            raise InputError(f"expected key = value or a [section] header, got {line[:60]!r}", file=path, line=i)
        key, value = (part.strip() for part in line.split("=", 1))
        sections[-1][2].key_lines[key] = i
        while _open(value) and i < len(lines):
            value += "\n" + lines[i]
            i += 1
        sections[-1][2][key] = _value(value)
    return sections


def _project(path, reading: Reading) -> None:
    sections = config_sections(path)
    if "config_version" not in sections[0][2]:
        raise InputError("expected a Godot project file (config_version at the top), found none", file=path,
                         field="config_version")
    rendering = next((keys for kind, _, keys, _ in sections[1:] if kind == "rendering"), _located(1))
    for key, value in rendering.items():
        if not f"rendering/{key}".startswith(_PROJECT):
            continue
        entry = Entry(value, file=path, key=f"rendering/{key}", line=rendering.key_lines.get(key, rendering.line))
        name = entry.key[len(_PROJECT):]
        if name == "size":
            reading.pending["atlas"] = (entry.integer(minimum=1), entry.key, path)
        elif name == "soft_shadow_filter_quality":
            quality = entry.integer(minimum=0)
            if quality not in GODOT_SOFT_SHADOW_QUALITIES:
                raise entry.error("0 (Hard) to 5 (Soft Ultra)")
            reading.pending["quality"] = (quality, f"{Path(path).name}: {entry.key} = {value}")
        elif name == "16_bits":
            wide = entry.boolean()
            reading.set("depth_format", "unorm16" if wide else "float32", file=path, key=entry.key,
                        raw=str(wide).lower())
        else:
            reading.lack(file=path, key=entry.key, value=value, why="no csmlab knob")


def _light(path, reading: Reading) -> None:
    if not read_text(path).lstrip().startswith(("[gd_scene", "[gd_resource")):
        raise InputError("expected a Godot scene ([gd_scene …] on the first line)", file=path, field="gd_scene")
    sections = config_sections(path)
    if len(sections) < 2 or sections[1][0] not in ("gd_scene", "gd_resource"):
        raise InputError("expected a Godot scene ([gd_scene …] on the first line)", file=path, field="gd_scene")
    lights = [Entry(keys, file=path, key=str(attrs.get("name", "DirectionalLight3D"))) for kind, attrs, keys, _
              in sections if kind == "node" and attrs.get("type") == "DirectionalLight3D"]
    if not lights:
        raise InputError("expected a node of type DirectionalLight3D, found none", file=path,
                         field="DirectionalLight3D")
    shadowed = [light for light in lights if _flag(light, "shadow_enabled")]
    light = (shadowed or lights)[0]
    prefix = f"{light.key}."
    base = reading.base
    if not shadowed:
        enabled = light.member("shadow_enabled")
        reading.lack(file=path, key=prefix + "shadow_enabled", value=False if enabled is None else enabled.raw,
                     why="the light casts no shadow in Godot; csmlab measures its shadows anyway")
    mode_key = "directional_shadow_mode"
    cascades = base.cascades
    mode_entry = light.member(mode_key)
    if mode_entry is not None:
        mode = mode_entry.integer(minimum=0)
        if mode not in _MODES:
            raise mode_entry.error("0, 1 or 2")
        cascades = _MODES[mode]
        reading.set("cascades", cascades, file=path, key=prefix + mode_key, raw=mode)
    split_entries = [light.member(f"directional_shadow_split_{i}") for i in range(1, cascades)]
    if mode_entry is not None or any(e is not None for e in split_entries):
        fractions = [e.number(above=0.0) if e is not None else base.splits[i]
                     for i, e in enumerate(split_entries)] + [1.0]
        if any(b <= a for a, b in zip(fractions, fractions[1:])):
            raise InputError(f"expected increasing splits below 1, got {fractions[:-1]}", file=path,
                             field=prefix + "directional_shadow_split_1", line=light.line)
        found = [e.key for e in split_entries if e is not None] or [prefix + mode_key]
        raw = fractions[:-1] if any(e is not None for e in split_entries) else mode_entry.raw
        reading.set("split", "manual_range", file=path, key=", ".join(found), raw=raw)
        reading.set("splits", tuple(fractions), file=path, key=", ".join(found), raw=raw)
    plain = {"directional_shadow_max_distance": ("shadow_distance", 1.0, 0.0),
             "directional_shadow_pancake_size": ("pancake", 1.0, None),
             "shadow_normal_bias": ("normal_offset", 1.0, None),
             "shadow_bias": ("bias_depth_range", SHADOW_BIAS_SCALE, None)}
    if (entry := light.member("shadow_blur")) is not None:
        reading.pending["blur"] = (entry.number(above=0.0), f"{Path(path).name}: {entry.key} = {entry.raw}")
    for key, (attribute, scale, above) in plain.items():
        if (entry := light.member(key)) is not None:
            value = entry.number(above=above) if above is not None else entry.number(minimum=0.0)
            reading.set(attribute, value * scale, file=path, key=entry.key, raw=entry.raw)
    if (entry := light.member("directional_shadow_fade_start")) is not None:
        start = entry.number(minimum=0.0, maximum=1.0, what="a fraction in [0, 1]")
        # Rounded to 12 digits: 1 - 0.8 is 0.19999999999999996 in binary, Godot's fade_start is a float32.
        reading.set("fade_out", round(1.0 - start, 12), file=path, key=entry.key, raw=start)
    if (entry := light.member("shadow_reverse_cull_face")) is not None:
        reversed_ = entry.boolean()
        reading.set("cull", "front" if reversed_ else "back", file=path, key=entry.key, raw=reversed_)
    if (entry := light.member("directional_shadow_blend_splits")) is not None:
        blend = entry.boolean()
        reading.pending["blend"] = (blend, f"{Path(path).name}: {entry.key} = {str(blend).lower()}")
    angular = light.member("light_angular_distance")
    if angular is not None and angular.number() != 0.0:
        reading.lack(file=path, key=angular.key, value=angular.raw,
                     why="a nonzero angle turns on Godot's PCSS penumbra, not modelled; the Soft Low disk is kept")
    for key in ("shadow_opacity", "shadow_transmittance_bias", "directional_shadow_fade_start.mobile",
                "shadow_caster_mask"):
        if (entry := light.member(key)) is not None:
            reading.lack(file=path, key=entry.key, value=entry.raw, why="no csmlab knob")


def _flag(light: Entry, key: str) -> bool:
    """Light property ``key``, true or false (false when the scene leaves it out: Godot's default)."""
    entry = light.member(key)
    return entry is not None and entry.boolean()


def read_godot4(paths) -> Imported:
    """Godot 4 settings from ``project.godot`` and/or a ``.tscn`` with a DirectionalLight3D.

    Raises
    ------
    InputError
        A file that is neither, a foreign or malformed one, or a value out of range (file and key named).
    """
    reading = Reading("godot4", PRESET)
    for path in paths:
        suffix = Path(path).suffix
        if suffix == ".godot":
            _project(path, reading)
        elif suffix in (".tscn", ".escn"):
            _light(path, reading)
        else:
            raise InputError("expected project.godot or a .tscn scene", file=path, field="file")
    _soft_shadows(reading)
    if "atlas" in reading.pending:
        size, key, project = reading.pending["atlas"]
        cascades = reading.values.get("cascades", reading.base.cascades)
        # get_directional_light_shadow_size: 2 or 4 splits share the atlas, each split half its side.
        reading.set("resolution", size if cascades == 1 else size // 2, file=project, key=key, raw=size)
    elif reading.values.get("cascades", reading.base.cascades) == 1:
        # One split takes the whole default atlas, twice the side of the preset's 4-split tile.
        reading.set("resolution", 2 * reading.base.resolution, file=reading.origins["cascades"].split(":")[0],
                    key="directional_shadow_mode",
                    raw="0 (one split takes the whole default atlas)")
    if reading.values.get("cascades", reading.base.cascades) == 1:
        # One split fills the atlas: one texture of one map, csmlab's array of one slice (memory_bytes).
        reading.set("storage", "array", file=reading.origins["cascades"].split(":")[0],
                    key="directional_shadow_mode", raw="0 (one split fills the atlas)")
    return reading.result()


def _soft_shadows(reading: Reading) -> None:
    """The filter of the project's soft-shadow level and the light's blur, and the light's blend splits, once every
    file is read: the level's Vogel disk has its quality radius × shadow_blur texels
    (csmlab.lookup_choices.godot_soft_shadow_fields), and blending splits drops the first-split blur scaling
    (csmlab.cascades.fit.GODOT_BLEND_SPLITS)."""
    origins = {}
    if "quality" in reading.pending or "blur" in reading.pending:
        quality, said_quality = reading.pending.get("quality", (GODOT_SOFT_LOW_LEVEL, None))
        blur, said_blur = reading.pending.get("blur", (1.0, None))
        origin = "; ".join(o for o in (said_quality, said_blur) if o)
        origins.update({name: (value, origin) for name, value in godot_soft_shadow_fields(quality, blur=blur).items()})
    if "blend" in reading.pending:
        blend, origin = reading.pending["blend"]
        fields = {**GODOT_BLEND_SPLITS, "vogel_scale": "none"} if blend else {
            "blend_band": 0.0, "vogel_scale": GODOT_SOFT_LOW["vogel_scale"]}
        origins.update({name: (value, origin) for name, value in fields.items()})
    for name, (value, origin) in origins.items():
        reading.values[name] = value
        reading.origins[name] = origin


def _soft_level(settings: ShadowSettings) -> tuple[int, float, list]:
    """The soft_shadow_filter_quality and shadow_blur that give ``settings``' filter, and what the files cannot hold
    of its filter and blend (Godot's blend splits are GODOT_BLEND_SPLITS, its disk unscaled under them)."""
    lacking = []
    differing = [k for k, v in GODOT_BLEND_SPLITS.items() if getattr(settings, k) != v]
    if settings.blend_band > 0 and differing:
        lacking.append(", ".join(f"{k} = {getattr(settings, k)!r}" for k in differing) +
                       f" (Godot blends splits over the last tenth of each: {GODOT_BLEND_SPLITS})")
    if hard_filter(settings):
        return 0, 1.0, lacking
    scale = "none" if settings.blend_band > 0 else GODOT_SOFT_LOW["vogel_scale"]
    if settings.filter == "pcf_vogel" and settings.vogel_scale != scale:
        lacking.append(f"vogel_scale = {settings.vogel_scale!r} (Godot scales its disk by the first split unless it "
                       f"blends splits: {scale!r} here)")
    for quality, level in GODOT_SOFT_SHADOW_QUALITIES.items():
        if level.samples and vogel_is(settings, vogel_taps=level.samples, vogel_angle=2.4):
            return quality, settings.vogel_radius / level.radius, lacking
    return GODOT_SOFT_LOW_LEVEL, 1.0, lacking + [
        f"filter = {settings.filter!r}, filter_size = {settings.filter_size} (Godot filters with its own soft-shadow "
        f"kernel: pcf_vogel at golden angle 2.4 with 1, 4, 8, 16 or 32 taps; Soft Low written)"]


def write_godot4(settings: ShadowSettings, *, near: float, far: float) -> tuple[dict, list]:
    """``settings`` as ``project.godot`` and ``light.tscn`` texts, and the knobs they cannot hold."""
    quality, blur, lacking = _soft_level(settings)
    cascades = count_one_two_or_four(settings.cascades)
    z = split_boundaries(settings.replace(cascades=cascades), near=near, far=far)
    fractions = fractions_of_range(z)
    size = largest_resolution(settings)
    if settings.cull == "none":
        lacking.append("cull = 'none' (Godot culls the material's back faces, or its front ones reversed)")
    if settings.depth_format not in ("unorm16", "float32"):
        lacking.append(f"depth_format = {settings.depth_format!r} (Godot's shadow atlas is 16-bit or 32-bit float)")
    lacking += storage_lacking(settings, cascades=cascades, atlas=engine_settings(PRESET).storage)
    mode = {v: k for k, v in _MODES.items()}[cascades]
    project = ["; Engine configuration file.", "config_version=5", "", "[rendering]", "",
               f"lights_and_shadows/directional_shadow/size={size * (1 if cascades == 1 else 2)}",
               f"lights_and_shadows/directional_shadow/soft_shadow_filter_quality={quality}",
               "lights_and_shadows/directional_shadow/16_bits="
               f"{'true' if settings.depth_format == 'unorm16' else 'false'}"]
    light = ['[gd_scene format=3]', '', '[node name="DirectionalLight3D" type="DirectionalLight3D"]',
             "shadow_enabled = true",
             f"shadow_bias = {settings.bias_depth_range / SHADOW_BIAS_SCALE!r}",
             f"shadow_normal_bias = {settings.normal_offset!r}",
             f"shadow_blur = {blur!r}",
             f"shadow_reverse_cull_face = {'true' if settings.cull == 'front' else 'false'}",
             f"directional_shadow_mode = {mode}",
             *(f"directional_shadow_split_{i + 1} = {f!r}" for i, f in enumerate(fractions)),
             f"directional_shadow_max_distance = {float(z[-1])!r}",
             f"directional_shadow_fade_start = {1.0 - settings.fade_out!r}",
             f"directional_shadow_pancake_size = {settings.pancake!r}",
             f"directional_shadow_blend_splits = {'true' if settings.blend_band > 0 else 'false'}"]
    return {"project.godot": "\n".join(project) + "\n", "light.tscn": "\n".join(light) + "\n"}, lacking


def export_godot4(settings: ShadowSettings, *, near: float, far: float) -> Snippet:
    """Godot 4: DirectionalLight3D properties and the directional shadow atlas size."""
    quality, blur, soft_lacking = _soft_level(settings)
    lacking = (common_lacking(settings, stable="exact", carried=FIELDS) + shape_lacking(settings, fade="smoothstep")
               + soft_lacking)
    modes = {1: 0, 2: 1, 4: 2}
    cascades = count_one_two_or_four(settings.cascades)
    if cascades != settings.cascades:
        lacking.append(f"cascades = {settings.cascades} (Godot has 1, 2 or 4 splits; {cascades} written)")
    # Godot places each split at min_distance + split · (max_distance - min_distance) from the camera's near
    # plane (RendererSceneCull::_light_instance_setup_directional_shadow): fractions of the range, not of far.
    z = split_boundaries(settings.replace(cascades=cascades), near=near, far=far)
    fractions = fractions_of_range(z)
    atlas = largest_resolution(settings) * (1 if cascades == 1 else 2)
    lines = ["# DirectionalLight3D",
             f"directional_shadow_mode = {modes[cascades]}",
             f"directional_shadow_max_distance = {four_digits(min(settings.shadow_distance, far))}"]
    lines += [f"directional_shadow_split_{i + 1} = {four_digits(f)}" for i, f in enumerate(fractions)]
    lines += [f"directional_shadow_blend_splits = {'true' if settings.blend_band > 0 else 'false'}",
              f"directional_shadow_fade_start = {four_digits(1.0 - settings.fade_out)}",
              f"directional_shadow_pancake_size = {four_digits(settings.pancake)}",
              f"shadow_bias = {four_digits(settings.bias_depth_range / SHADOW_BIAS_SCALE)}",
              f"shadow_normal_bias = {four_digits(settings.normal_offset)}",
              f"shadow_blur = {four_digits(blur)}",
              f"shadow_reverse_cull_face = {'true' if settings.cull == 'front' else 'false'}",
              "# Project Settings",
              f"rendering/lights_and_shadows/directional_shadow/size = {atlas}  "
              f"# {largest_resolution(settings)}² per split (2 or 4 splits: half the atlas side each)",
              "rendering/lights_and_shadows/directional_shadow/soft_shadow_filter_quality = "
              f"{quality}  # {GODOT_SOFT_SHADOW_QUALITIES[quality].name}",
              "rendering/lights_and_shadows/directional_shadow/16_bits = "
              f"{'true' if settings.depth_format == 'unorm16' else 'false'}"]
    return Snippet("godot4", "Godot 4: DirectionalLight3D and project settings", "gdscript", "\n".join(lines) + "\n",
                   tuple(lacking))


def settled_godot4(settings: ShadowSettings) -> ShadowSettings:
    """``settings`` with the fields Godot derives from its split mode: ``directional_shadow_split_1..C-1`` at the
    setting's own first fractions, or the preset's where it has fewer (Godot's 2 splits use split_1 only), and one
    split filling the atlas (storage ``array``, the preset's atlas otherwise, as :func:`read_godot4` reads them)."""
    base = engine_settings(PRESET)
    storage = "array" if settings.cascades == 1 else base.storage
    if len(settings.splits) == settings.cascades:
        return settings.replace(storage=storage)
    kept = settings.splits if len(settings.splits) > settings.cascades else base.splits
    return settings.replace(split="manual_range", splits=(*kept[:settings.cascades - 1], 1.0), storage=storage)


TUNE_SPACE = TuneSpace({
    # DirectionalLight3D.directional_shadow_mode: orthogonal (1), PSSM 2 or 4 splits.
    "cascades": ("choice", (1, 2, 4)),
    # Per split: project setting directional_shadow/size (a power of two) halved for 2 or 4 splits.
    "resolution": ("choice", (512, 1024, 2048, 4096)),
    # The property ranges of the DirectionalLight3D and Light3D class references (the inspector's sliders).
    "shadow_distance": ("range", 1.0, 8192.0, True, None),
    "fade_out": ("range", 0.0, 1.0, False, None),
    "pancake": ("range", 0.0, 1024.0, False, None),
    "bias_depth_range": ("range", 0.0, 10.0 * SHADOW_BIAS_SCALE, False, None),
    "normal_offset": ("range", 0.0, 10.0, False, None),
    # shadow_blur 0.1 to 8: csmlab's disk radius is (0, 16] texels.
    "vogel_radius": ("range", 0.1 * GODOT_SOFT_LOW["vogel_radius"], 16.0, False, None),
    # soft_shadow_filter_quality Hard (0) or Soft Low (2); shadow_reverse_cull_face; directional_shadow/16_bits.
    "filter": ("choice", ("pcf_vogel", "pcf_bilinear")),
    "cull": ("choice", ("back", "front")),
    "depth_format": ("choice", ("unorm16", "float32")),
}, settle=settled_godot4)
"""What a tune of the Godot preset may try: the DirectionalLight3D's and the project's own settings."""

ENGINE = Engine("godot4", export_godot4, EngineFiles(
    read=read_godot4, write=write_godot4, fields=FIELDS, preset=fixed_preset(PRESET), presets=(PRESET,),
    files="project.godot and/or a .tscn with a DirectionalLight3D"), tune=TUNE_SPACE)
"""What the registries of csmlab.engines take from this module."""


# --- a level's glTF instances ------------------------------------------------------------------------------

_INSTANCE = re.compile(r'\binstance\s*=\s*ExtResource\(\s*"?([^")\s]+)"?\s*\)')
_TRANSFORM = re.compile(r"^\s*Transform(?:3D)?\((?P<numbers>[^()]*)\)\s*$")
_GLTF = (".glb", ".gltf")
_TEXT_SCENE = ".tscn"


@dataclass(frozen=True)
class SceneInstance:
    """One glTF file a Godot scene instances, where the scene places it.

    Attributes
    ----------
    file : Path
        The glTF file (``.glb`` or ``.gltf``), absolute.
    transform : numpy.ndarray
        ``(4, 4)`` float64: the file's coordinates to the scene's, metres, acting on column vectors (the last row
        ``0, 0, 0, 1``): the product of the node's and its ancestors' ``transform``, the root's included.
    node : str
        The instancing node's path from the root (``Street/Lamp2``; through an instanced ``.tscn``, that
        scene's node path after its own), as messages name it.
    """

    file: Path
    transform: np.ndarray
    node: str


class _UnreadableInstance(InputError):
    """An instanced file csmlab cannot read — another format, absent, or named by uid alone: refused by
    :func:`gltf_instances`, or listed with ``why`` where its caller collects them (:func:`level_instances`)."""

    def __init__(self, message: str, *, why: str, **where):
        super().__init__(message, **where)
        self.why = why


def gltf_instances(path, *, skipped: list | None = None) -> list[SceneInstance]:
    """The glTF files a Godot ``.tscn`` instances, each with the transform that places it, in file order.

    Every node with ``instance=ExtResource(…)`` of a ``.glb`` or ``.gltf`` is one record; an instanced
    ``.tscn`` contributes its own glTF instances, placed by the instancing node. A node with
    ``visible = false`` hides its subtree (Godot neither draws it nor casts its shadows). ``res://`` paths
    resolve from the folder holding ``project.godot`` (searched upward from the scene), others from the
    scene's folder. Godot writes a ``Transform3D`` as the basis's rows, then the origin (variant_parser.cpp).

    ``skipped``, when given, collects one line ``"<node> (<file>): <why>"`` for each instance of a file csmlab cannot
    read (another format, absent, or named by uid alone) in place of refusing it.

    Raises
    ------
    InputError
        A file that is no Godot scene, a node whose parent or resource is missing, a transform that is not 12
        numbers, an instanced file that does not exist or is neither glTF nor a text scene (unless ``skipped``
        collects those), or scenes that instance each other (file, line and node named).
    """
    return _instances(Path(path).resolve(), np.eye(4), None, prefix="", chain=(), skipped=skipped)


def _instances(path: Path, placed: np.ndarray, root: np.ndarray | None, *, prefix: str,
               chain: tuple, skipped: list | None) -> list[SceneInstance]:
    """The glTF instances of the scene ``path`` whose root's parent is at ``placed`` ``(4, 4)``; ``root``, the
    instancing node's own transform, replaces the root's (the instancing node is the root: its ``transform``
    property overrides the scene's), None where it sets none."""
    if path in chain:
        raise InputError(f"expected scenes that do not instance each other, got {' → '.join(map(str, chain))} → "
                         f"{path}", file=chain[-1], field="instance")
    text = read_text(path)
    if not text.lstrip().startswith("[gd_scene"):
        raise InputError("expected a Godot scene ([gd_scene …] on the first line)", file=path, field="gd_scene")
    lines = text.splitlines()
    resources, world, hidden, found = {}, {}, set(), []
    for kind, attrs, keys, line in config_sections(path):
        if kind == "ext_resource":
            resources[str(attrs.get("id"))] = (attrs.get("path"), line)
        if kind != "node":
            continue
        name, parent = str(attrs.get("name", "")), attrs.get("parent")
        node = "." if parent is None else (name if parent == "." else f"{parent}/{name}")
        if parent is not None and parent not in world:
            raise InputError(f"expected the parent node {parent!r} before node {name!r}, found none", file=path,
                             line=line, field=f"{node}.parent")
        local = _transform(keys.get("transform"), file=path, line=line, node=node)
        if parent is None and root is not None:
            local = root
        above = placed if parent is None else world[parent]
        world[node] = above @ local
        if keys.get("visible") is False or parent in hidden:
            hidden.add(node)
        instance = _INSTANCE.search(lines[line - 1])
        if instance is None or node in hidden:
            continue
        shown = f"{prefix}{node}"
        try:
            target = _resource_file(resources, instance.group(1), scene=path, line=line, node=node)
        except _UnreadableInstance as exc:
            if skipped is None:
                raise
            skipped.append(f"{shown} ({resources[instance.group(1)][0] or instance.group(1)}): {exc.why}")
            continue
        if target.suffix.lower() in _GLTF:
            found.append(SceneInstance(file=target, transform=world[node], node=shown))
        else:
            own = None if keys.get("transform") is None else local
            found += _instances(target, above, own, prefix=f"{shown}/", chain=(*chain, path), skipped=skipped)
    return found


def _transform(value, *, file, line: int, node: str) -> np.ndarray:
    """A node's ``transform = Transform3D(xx, xy, xz, yx, yy, yz, zx, zy, zz, ox, oy, oz)`` as a ``(4, 4)`` matrix
    (the identity where the node has none): the basis's rows, then the origin."""
    if value is None:
        return np.eye(4)
    match = _TRANSFORM.match(str(value))
    numbers = [] if match is None else [part.strip() for part in match.group("numbers").split(",")]
    try:
        parsed = [float(v) for v in numbers]
    except ValueError:
        parsed = []
    if len(parsed) != 12 or not all(np.isfinite(parsed)):
        raise InputError(f"expected Transform3D( of 12 numbers: the basis's rows, then the origin), got "
                         f"{str(value)[:80]!r}", file=file, line=line, field=f"{node}.transform")
    matrix = np.eye(4)
    matrix[:3, :3] = np.reshape(parsed[:9], (3, 3))
    matrix[:3, 3] = parsed[9:]
    return matrix


def _resource_file(resources: dict, key: str, *, scene: Path, line: int, node: str) -> Path:
    """The file of ext_resource ``key`` that ``node`` instances: existing, and glTF or a text scene."""
    if key not in resources:
        raise InputError(f"expected an [ext_resource] with id {key!r} for node {node!r}, found none", file=scene,
                         line=line, field=f"{node}.instance")
    written, declared = resources[key]
    if not isinstance(written, str) or not written:
        raise _UnreadableInstance(f"expected a path on the [ext_resource] with id {key!r} (a uid alone is not "
                                  "resolved)", why="its [ext_resource] has a uid and no path; csmlab does not "
                                  "resolve uids", file=scene, line=declared, field="ext_resource.path")
    if written.startswith("res://"):
        root = next((folder for folder in scene.parents if (folder / "project.godot").is_file()), None)
        if root is None:
            raise InputError(f"expected project.godot in a folder above the scene to resolve {written!r}, found "
                             "none", file=scene, line=declared, field="ext_resource.path")
        target = root / written[len("res://"):]
    else:
        target = scene.parent / written
    if target.suffix.lower() not in (*_GLTF, _TEXT_SCENE):
        raise _UnreadableInstance(f"expected node {node!r} to instance a glTF file (.glb, .gltf) or a text scene "
                                  f"(.tscn), got {written!r}",
                                  why=f"csmlab reads glTF (.glb, .gltf) and text scenes (.tscn), not "
                                      f"{target.suffix or 'a file without a suffix'}: export it as glTF 2.0",
                                  file=scene, line=line, field=f"{node}.instance")
    if not target.is_file():
        raise _UnreadableInstance(f"expected the file node {node!r} instances, {written!r}, at {target}, found none",
                                  why=f"no file at {target}", file=scene, line=line, field=f"{node}.instance")
    return target.resolve()


def level_instances(paths) -> tuple[list[SceneInstance], list[str]]:
    """The glTF instances of the ``.tscn``/``.escn`` scenes among ``paths`` (``csmlab import godot4``'s files) that a
    ``[[scene.parts]]`` entry can place, and one line ``"<node> (<file>): <why>"`` for each instance that cannot be:
    a file csmlab cannot read (:func:`gltf_instances`' ``skipped``), or a transform that flattens it (a scale of 0:
    Godot draws nothing of it; :func:`csmlab.scene.parts.matrix_fault`).

    Raises
    ------
    InputError
        A scene :func:`gltf_instances` refuses for its structure (file, line and node named).
    """
    from csmlab.scene.parts import matrix_fault

    placed, skipped = [], []
    for path in paths:
        if Path(path).suffix not in (".tscn", ".escn"):
            continue
        for instance in gltf_instances(path, skipped=skipped):
            if matrix_fault(instance.transform):
                skipped.append(f"{instance.node} ({instance.file.name}): its transform flattens it (a scale of 0); "
                               "Godot draws nothing of it")
            else:
                placed.append(instance)
    return placed, skipped
