"""three.js: the CSM addon's constructor options (examples/jsm/csm/CSM.js) as JSON, read and written.

Keys are the constructor's ``data`` fields — ``cascades``, ``maxFar`` (the cap on the camera's far plane:
``shadow_distance = "camera_far"``, ``max_shadow_distance``), ``mode`` (``uniform``,
``logarithmic``, ``practical`` (λ 0.5), ``custom``), ``shadowMapSize``, ``shadowBias``, ``lightNear``,
``lightFar``, ``lightMargin`` — plus ``fade`` (the property), ``customSplits`` (the breaks
``customSplitsCallback`` pushes, fractions of ``maxFar``: the callback itself is code), and the
renderer's ``shadowMapType`` and each light's ``shadowRadius`` (LightShadow.radius). Missing keys keep
``configs/engines/threejs_csm.toml``.

The snippet (export_threejs_csm) names the ``CSM`` options (examples/jsm/csm): ``cascades``, ``maxFar``, ``mode``
(``practical`` mixes with λ = 0.5), ``customSplitsCallback``, ``shadowMapSize``, ``fade``.
"""

from __future__ import annotations

import json
import math

from csmlab.cascades.bounds import shadow_end
from csmlab.cascades.splits import fractions_of_far, split_boundaries
from csmlab.engines.common import (Engine, EngineFiles, Snippet, TuneSpace, blend_lacking, common_lacking,
                                   fixed_preset, four_digits, largest_resolution, vogel_is)
from csmlab.engines.reading import Imported, Reading, json_document
from csmlab.lookup_choices import FILTER_METHODS
from csmlab.settings import ShadowSettings

__all__ = ["CSM_LIGHT_RANGE", "ENGINE", "FIELDS", "PRESET", "THREEJS_PCF", "TUNE_SPACE", "export_threejs_csm",
           "read_threejs_csm", "write_threejs_csm"]

PRESET = "threejs_csm"
"""The engine preset holding the CSM addon's defaults."""

FIELDS = frozenset({"cascades", "split", "splits", "lambda_", "shadow_distance", "shadow_distance_from",
                    "max_shadow_distance", "resolution", "pancake", "bias_constant", "filter", "vogel_radius"})
"""The csmlab fields the options carry."""

THREEJS_PCF = {"vogel_taps": 5, "vogel_angle": 2.399963229728653, "vogel_scale": "none"}
"""three.js r182+ PCFShadowMap as csmlab's ``pcf_vogel`` fields, its radius LightShadow.radius
(configs/engines/threejs_csm.toml)."""

MAX_FAR = 100000.0
"""CSM.js constructor default maxFar (``data.maxFar || 100000``)."""

CSM_LIGHT_RANGE = (1.0, 2000.0, 1e-6)
"""CSM.js constructor defaults lightNear, lightFar and shadowBias: the bias is a fraction of that depth range."""

_MODES = {"uniform": ("uniform", None), "logarithmic": ("log", None), "practical": ("practical", 0.5)}


def read_threejs_csm(paths) -> Imported:
    """three.js CSM settings from its options as JSON.

    Raises
    ------
    InputError
        Not JSON, not a CSM options object, or a value out of range (file and key named).
    """
    reading = Reading("threejs_csm", PRESET)
    base = reading.base
    known = {"cascades", "maxFar", "mode", "shadowMapSize", "shadowBias", "lightNear", "lightFar", "lightMargin",
             "fade", "customSplits", "shadowMapType", "shadowRadius"}
    for path in paths:
        options = json_document(path)
        if not options.is_object() or not set(options.keys()) & known:
            raise options.error(f"a JSON object of CSM options ({', '.join(sorted(known))})")
        cascades = base.cascades
        if (entry := options.member("cascades")) is not None:
            cascades = entry.integer(minimum=1)
            reading.set("cascades", cascades, file=path, key="cascades")
        if (entry := options.member("maxFar")) is not None:
            # getBreaks: far = Math.min(camera.far, this.maxFar): the camera's far plane, capped at maxFar.
            reading.set("max_shadow_distance", entry.number(above=0.0), file=path, key="maxFar")
            reading.set("shadow_distance_from", "camera_far", file=path, key="maxFar", raw=entry.raw)
        mode = options.member("mode")
        if mode is not None:
            mode_name = mode.text([*_MODES, "custom"])
            if mode_name in _MODES:
                split, lambda_ = _MODES[mode_name]
                reading.set("split", split, file=path, key="mode", raw=mode_name)
                if lambda_ is not None:
                    reading.set("lambda_", lambda_, file=path, key="mode", raw=mode_name)
            else:
                breaks = options.at("customSplits", f"customSplits, {cascades} fractions of maxFar ending at 1, "
                                                    f"for mode 'custom'")
                entries = breaks.items()
                if len(entries) != cascades:
                    raise breaks.error(f"{cascades} fractions of maxFar ending at 1 (one per cascade)")
                fractions = [entry.number(above=0.0) for entry in entries]
                if any(b <= a for a, b in zip(fractions, fractions[1:])) or fractions[-1] != 1.0:
                    raise breaks.error("increasing fractions ending at 1")
                reading.set("split", "manual", file=path, key="mode, customSplits", raw=fractions)
                reading.set("splits", tuple(fractions), file=path, key="customSplits", raw=fractions)
        if (entry := options.member("shadowMapSize")) is not None:
            reading.set("resolution", entry.integer(minimum=1), file=path, key="shadowMapSize")
        if (entry := options.member("lightMargin")) is not None:
            reading.set("pancake", entry.number(minimum=0.0), file=path, key="lightMargin")
        light_keys = ("lightNear", "lightFar", "shadowBias")
        if set(light_keys) & set(options.keys()):
            near, far_, bias = (options.member(k).number() if options.member(k) is not None else d
                                for k, d in zip(light_keys, CSM_LIGHT_RANGE))
            if far_ <= near:
                raise options.at("lightFar").error(f"lightFar above lightNear ({near})")
            depth = far_ - near
            if not math.isfinite(bias * depth):
                raise options.at("shadowBias").error(f"a bias that times lightFar − lightNear ({depth:g}) is finite")
            # shadowmap_pars_fragment adds shadowBias to the light's normalized depth: away from the light.
            found = [k for k in ("shadowBias", "lightNear", "lightFar") if k in options.keys()]
            reading.set("bias_constant", -bias * depth, file=path, key=", ".join(found),
                        raw=[options.member(k).raw for k in found])
        if (entry := options.member("fade")) is not None and entry.boolean():
            reading.lack(file=path, key="fade", value=True, why="CSM's fade band has a fixed width; blend_band "
                         "keeps the preset's 0")
        if (entry := options.member("shadowMapType")) is not None:
            kind = entry.text()
            if kind == "BasicShadowMap":
                reading.set("filter", "none", file=path, key="shadowMapType", raw=kind)
            elif kind != "PCFShadowMap":
                reading.lack(file=path, key="shadowMapType", value=kind,
                             why="csmlab models BasicShadowMap and r182+ PCFShadowMap; the latter is kept")
        if (entry := options.member("shadowRadius")) is not None:
            reading.set("vogel_radius", entry.number(above=0.0), file=path, key="shadowRadius")
        for key, entry in sorted(options.fields(), key=lambda field: field[0]):
            if key not in known:
                why = "the light is the experiment's [light]" if key.startswith("light") else "no csmlab knob"
                reading.lack(file=path, key=key, value=json.dumps(entry.raw), why=why)
    return reading.result()


def _csm_mode(settings: ShadowSettings) -> str:
    """CSM's ``mode`` for ``settings``' split scheme: its own name where CSM has it (``practical`` only at
    λ = 0.5), else ``custom``."""
    return {"uniform": "uniform", "log": "logarithmic"}.get(settings.split, "practical" if (
        settings.split == "practical" and settings.lambda_ == 0.5) else "custom")


def _max_far(settings: ShadowSettings, *, far: float) -> tuple[float, list]:
    """CSM's ``maxFar`` for ``settings`` and what it cannot hold: three.js ends at ``min(camera.far, maxFar)``, so
    a fixed distance is written as the cap (the same end under a camera whose far plane is ``far``)."""
    if settings.shadow_distance_from == "camera_far":
        cap = settings.max_shadow_distance
        return (cap, []) if cap > 0 else (MAX_FAR, [f"max_shadow_distance = 0.0 (no cap; three.js caps the camera's "
                                                   f"far plane at maxFar, {MAX_FAR:g} written)"])
    lacking = [f"shadow_distance = {settings.shadow_distance!r}, shadow_distance_from = "
               f"{settings.shadow_distance_from!r} (three.js ends at min(camera.far, maxFar): the end under this "
               f"camera is written as maxFar)"]
    end = shadow_end(method=settings.shadow_distance_from, shadow_distance=settings.shadow_distance,
                     max_shadow_distance=settings.max_shadow_distance, camera_far=far)
    return end, lacking


def write_threejs_csm(settings: ShadowSettings, *, near: float, far: float) -> tuple[dict, list]:
    """``settings`` as CSM options JSON, and the knobs it cannot hold."""
    z = split_boundaries(settings, near=near, far=far)
    mode = _csm_mode(settings)
    light_near, light_far, _ = CSM_LIGHT_RANGE
    max_far, lacking = _max_far(settings, far=far)
    options = {"cascades": settings.cascades, "maxFar": max_far, "mode": mode}
    if mode == "custom":
        options["customSplits"] = [float(v / z[-1]) for v in z[1:]]
    options.update({"shadowMapSize": largest_resolution(settings),
                    "lightMargin": settings.pancake, "lightNear": light_near, "lightFar": light_far,
                    "shadowBias": -settings.bias_constant / (light_far - light_near), "fade": settings.blend_band > 0,
                    "shadowMapType": "BasicShadowMap" if FILTER_METHODS[settings.filter].hard else "PCFShadowMap",
                    "shadowRadius": settings.vogel_radius})
    if settings.filter not in ("none", "pcf_vogel") or (settings.filter == "pcf_vogel" and any(
            getattr(settings, k) != v for k, v in THREEJS_PCF.items())):
        lacking.append(f"filter = {settings.filter!r} (three.js's PCFShadowMap is pcf_vogel {THREEJS_PCF})")
    return {"csm.json": json.dumps(options, indent=2) + "\n"}, lacking


def export_threejs_csm(settings: ShadowSettings, *, near: float, far: float) -> Snippet:
    """three.js CSM (examples/jsm/csm/CSM.js) options."""
    lacking = common_lacking(settings, stable="exact", carried=FIELDS)
    mode = _csm_mode(settings)
    max_far, far_lacking = _max_far(settings, far=far)
    lacking += far_lacking
    lines = ["const csm = new CSM({",
             f"  maxFar: {four_digits(max_far)},",
             f"  cascades: {settings.cascades},",
             f"  mode: '{mode}',"]
    if mode == "custom":
        fractions = ", ".join(four_digits(f) for f in fractions_of_far(split_boundaries(settings, near=near, far=far)))
        lines.append(f"  customSplitsCallback: (cascades, near, far, breaks) => breaks.push({fractions}, 1),")
    light_near, light_far, _ = CSM_LIGHT_RANGE
    lines += [f"  shadowMapSize: {largest_resolution(settings)},",
              f"  lightMargin: {four_digits(settings.pancake)},",
              f"  shadowBias: {-settings.bias_constant / (light_far - light_near):.6g},  // of lightFar − lightNear",
              "  camera, parent: scene, lightDirection,", "});"]
    if vogel_is(settings, **THREEJS_PCF) and settings.vogel_radius != 1.0:
        radius = four_digits(settings.vogel_radius)
        lines.append(f"csm.lights.forEach((light) => {{ light.shadow.radius = {radius}; }});")
    lines += [
              f"csm.fade = {'true' if settings.blend_band > 0 else 'false'};",
              "renderer.shadowMap.type = THREE." + ("BasicShadowMap" if FILTER_METHODS[settings.filter].hard
                                                    else "PCFShadowMap") + ";"]
    lacking += blend_lacking(settings, "CSM's fade has a fixed width")
    if settings.filter != "none" and not vogel_is(settings, **THREEJS_PCF):
        lacking.append(f"filter = {settings.filter!r}, filter_size = {settings.filter_size} (three.js picks its PCF "
                       f"kernel from shadowMap.type: PCFShadowMap is pcf_vogel {THREEJS_PCF}, radius = shadow.radius)")
    return Snippet("threejs_csm", "three.js: CSM options", "javascript", "\n".join(lines) + "\n", tuple(lacking))


TUNE_SPACE = TuneSpace({
    # CSM options: cascades, mode (uniform, logarithmic, or practical at CSM's λ 0.5), maxFar (the cap on the
    # camera's far plane: max_shadow_distance), shadowMapSize,
    # lightMargin, shadowBias (a fraction of lightFar − lightNear); renderer.shadowMap.type BasicShadowMap or
    # PCFShadowMap and LightShadow.radius (csmlab's disk radius is at most 16 texels).
    "cascades": ("choice", (1, 2, 3, 4, 5, 6)),
    "split": ("choice", ("uniform", "log", "practical")),
    "max_shadow_distance": ("range", 10.0, 2000.0, True, None),
    "resolution": ("choice", (512, 1024, 2048, 4096)),
    "pancake": ("range", 0.0, 500.0, False, None),
    "bias_constant": ("range", -0.01, 0.01, False, None),
    "filter": ("choice", ("pcf_vogel", "none")),
    "vogel_radius": ("range", 0.1, 16.0, False, None),
})
"""What a tune of the three.js preset may try: the CSM addon's options and the renderer's shadow map type."""

ENGINE = Engine("threejs_csm", export_threejs_csm, EngineFiles(
    read=read_threejs_csm, write=write_threejs_csm, fields=FIELDS, preset=fixed_preset(PRESET), presets=(PRESET,),
    files="the CSM options as JSON"), tune=TUNE_SPACE)
"""What the registries of csmlab.engines take from this module."""
