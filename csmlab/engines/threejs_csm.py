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

from csmlab.cascades.bounds import shadow_end
from csmlab.cascades.splits import fractions_of_far, split_boundaries
from csmlab.engines.common import (Engine, EngineFiles, Snippet, blend_lacking, common_lacking, fixed_preset,
                                   four_digits, largest_resolution, vogel_is)
from csmlab.engines.reading import Imported, Reading, json_document, number
from csmlab.errors import InputError
from csmlab.lookup_choices import FILTER_METHODS
from csmlab.settings import ShadowSettings

__all__ = ["CSM_LIGHT_RANGE", "ENGINE", "FIELDS", "PRESET", "THREEJS_PCF", "export_threejs_csm", "read_threejs_csm",
           "write_threejs_csm"]

PRESET = "threejs_csm"
"""The engine preset holding the CSM addon's defaults."""

FIELDS = frozenset({"cascades", "split", "splits", "lambda_", "shadow_distance", "shadow_distance_from",
                    "max_shadow_distance", "resolution", "pancake", "bias_constant", "filter", "vogel_radius"})
"""The csmlab fields the options carry."""

THREEJS_PCF = {"vogel_taps": 5, "vogel_angle": 2.399963229728653, "vogel_scale": "none"}
"""three.js r182+ PCFShadowMap as csmlab's ``pcf_vogel`` fields, its radius LightShadow.radius (configs/engines/threejs_csm.toml)."""

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
    for path in paths:
        options = json_document(path)
        known = {"cascades", "maxFar", "mode", "shadowMapSize", "shadowBias", "lightNear", "lightFar", "lightMargin",
                 "fade", "customSplits", "shadowMapType", "shadowRadius"}
        if not isinstance(options, dict) or not set(options) & known:
            raise InputError(f"expected a JSON object of CSM options ({', '.join(sorted(known))})", file=path,
                             field="cascades")
        cascades = base.cascades
        if "cascades" in options:
            cascades = number(options["cascades"], file=path, key="cascades", integer=True, minimum=1)
            reading.set("cascades", cascades, file=path, key="cascades")
        if "maxFar" in options:
            # getBreaks: far = Math.min(camera.far, this.maxFar): the camera's far plane, capped at maxFar.
            reading.set("max_shadow_distance", number(options["maxFar"], file=path, key="maxFar", above=0.0),
                        file=path, key="maxFar")
            reading.set("shadow_distance_from", "camera_far", file=path, key="maxFar", raw=options["maxFar"])
        mode = options.get("mode")
        if mode in _MODES:
            split, lambda_ = _MODES[mode]
            reading.set("split", split, file=path, key="mode", raw=mode)
            if lambda_ is not None:
                reading.set("lambda_", lambda_, file=path, key="mode", raw=mode)
        elif mode == "custom":
            breaks = options.get("customSplits")
            if not isinstance(breaks, list) or len(breaks) != cascades:
                raise InputError(f"expected customSplits, {cascades} fractions of maxFar ending at 1, for mode "
                                 f"'custom', got {breaks!r}", file=path, field="customSplits")
            fractions = [number(v, file=path, key="customSplits", above=0.0) for v in breaks]
            if any(b <= a for a, b in zip(fractions, fractions[1:])) or fractions[-1] != 1.0:
                raise InputError(f"expected increasing fractions ending at 1, got {breaks}", file=path,
                                 field="customSplits")
            reading.set("split", "manual", file=path, key="mode, customSplits", raw=breaks)
            reading.set("splits", tuple(fractions), file=path, key="customSplits", raw=breaks)
        elif mode is not None:
            raise InputError(f"expected one of {[*_MODES, 'custom']}, got {mode!r}", file=path, field="mode")
        if "shadowMapSize" in options:
            reading.set("resolution", number(options["shadowMapSize"], file=path, key="shadowMapSize", integer=True,
                                             minimum=1), file=path, key="shadowMapSize")
        if "lightMargin" in options:
            reading.set("pancake", number(options["lightMargin"], file=path, key="lightMargin", minimum=0.0),
                        file=path, key="lightMargin")
        if {"shadowBias", "lightNear", "lightFar"} & set(options):
            near, far_, bias = (number(options.get(k, d), file=path, key=k) for k, d in
                                zip(("lightNear", "lightFar", "shadowBias"), CSM_LIGHT_RANGE))
            if far_ <= near:
                raise InputError(f"expected lightFar above lightNear ({near}), got {far_}", file=path, field="lightFar")
            # shadowmap_pars_fragment adds shadowBias to the light's normalized depth: away from the light.
            reading.set("bias_constant", -bias * (far_ - near), file=path,
                        key=", ".join(k for k in ("shadowBias", "lightNear", "lightFar") if k in options),
                        raw=[options.get(k) for k in ("shadowBias", "lightNear", "lightFar") if k in options])
        if options.get("fade") is True:
            reading.lack(file=path, key="fade", value=True, why="CSM's fade band has a fixed width; blend_band "
                         "keeps the preset's 0")
        kind = options.get("shadowMapType")
        if kind == "BasicShadowMap":
            reading.set("filter", "none", file=path, key="shadowMapType", raw=kind)
        elif kind not in (None, "PCFShadowMap"):
            reading.lack(file=path, key="shadowMapType", value=kind,
                         why="csmlab models BasicShadowMap and r182+ PCFShadowMap; the latter is kept")
        if "shadowRadius" in options:
            reading.set("vogel_radius", number(options["shadowRadius"], file=path, key="shadowRadius", above=0.0),
                        file=path, key="shadowRadius")
        for key in sorted(set(options) - known):
            reading.lack(file=path, key=key, value=json.dumps(options[key]),
                         why="the light is the experiment's [light]" if key.startswith("light") else "no csmlab knob")
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
    lacking = common_lacking(settings, stable="exact")
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
    lines += [f"  shadowMapSize: {largest_resolution(settings)},", "  camera, parent: scene, lightDirection,", "});"]
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


ENGINE = Engine("threejs_csm", export_threejs_csm, EngineFiles(
    read=read_threejs_csm, write=write_threejs_csm, fields=FIELDS, preset=fixed_preset(PRESET), presets=(PRESET,),
    files="the CSM options as JSON"))
"""What the registries of csmlab.engines take from this module."""
