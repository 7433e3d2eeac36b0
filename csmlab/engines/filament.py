"""Filament: the viewer's settings JSON (``libs/viewer``: ``Settings.h``, ``JsonSerializer``), read and written.

The sun's ``LightManager::ShadowOptions`` sit at ``lighting.sunlight.shadowOptions`` (older viewers:
``lighting.shadowOptions``) and ``view.shadowType`` picks the filter (google/filament @000e151b,
libs/viewer/src/Settings.cpp ``parse(…, LightManager::ShadowOptions*)``). ``mapSize`` (resolution),
``shadowCascades``, ``cascadeSplitPositions`` (fractions of the range from the near plane: split =
"manual_range"), ``shadowFar`` (0: the camera's far plane, ``shadow_distance = "camera_far"``), ``stable``,
``lispsm`` (ignored when stable: warp), ``shadowNearHint``/``shadowFarHint``, ``constantBias`` (metres toward
the light), ``normalBias`` (ShadowMapManager halves it: normal_offset = 0.5 · normalBias texels),
``polygonOffsetSlope`` and ``polygonOffsetConstant`` (the casters' raster offset: caster_bias_slope and
caster_bias_units, in DEPTH16 steps) map to csmlab fields; missing keys keep ``configs/engines/filament.toml``.

The snippet (export_filament) is the viewer's settings JSON as write_filament writes it.
"""

from __future__ import annotations

import json

from csmlab.cascades.splits import fractions_of_range, split_boundaries
from csmlab.engines.common import (Engine, EngineFiles, Snippet, blend_lacking, common_lacking, fixed_preset,
                                   largest_resolution, one_file)
from csmlab.engines.reading import Imported, Reading, engine_settings, json_document, number
from csmlab.errors import InputError
from csmlab.settings import ShadowSettings

__all__ = ["ENGINE", "FIELDS", "PRESET", "export_filament", "read_filament", "write_filament"]

PRESET = "filament"
"""The engine preset holding Filament's defaults."""

FIELDS = frozenset({"cascades", "split", "splits", "lambda_", "shadow_distance", "shadow_distance_from",
                    "stabilization", "warp", "lispsm_near_hint", "lispsm_far_hint", "bias_constant", "normal_offset",
                    "caster_bias_units", "caster_bias_slope", "resolution"})
"""The csmlab fields the settings JSON carries."""

NORMAL_BIAS_SCALE = 0.5
"""ShadowMapManager: normalBias = 0.5 · ShadowOptions.normalBias · texel ("a half-texel size")."""


def _options(document: dict, path) -> tuple[dict, str]:
    lighting = document.get("lighting")
    if not isinstance(lighting, dict):
        raise InputError("expected a Filament viewer settings object with a lighting section", file=path,
                         field="lighting")
    sun = lighting.get("sunlight")
    if isinstance(sun, dict) and isinstance(sun.get("shadowOptions"), dict):
        return sun["shadowOptions"], "lighting.sunlight.shadowOptions"
    if isinstance(lighting.get("shadowOptions"), dict):
        return lighting["shadowOptions"], "lighting.shadowOptions"
    return {}, "lighting.sunlight.shadowOptions"


def read_filament(paths) -> Imported:
    """Filament settings from the viewer's settings JSON.

    Raises
    ------
    InputError
        Not JSON, not viewer settings, or a value out of range (file and key named).
    """
    reading = Reading("filament", PRESET)
    base = reading.base
    for path in paths:
        document = json_document(path)
        if not isinstance(document, dict):
            raise InputError("expected a JSON object of viewer settings", file=path, field="lighting")
        options, where = _options(document, path)
        cascades = base.cascades
        if "shadowCascades" in options:
            cascades = number(options["shadowCascades"], file=path, key=f"{where}.shadowCascades", integer=True,
                              minimum=1)
            if cascades > 4:
                raise InputError(f"expected 1 to 4 cascades, got {cascades}", file=path, field=f"{where}.shadowCascades")
            reading.set("cascades", cascades, file=path, key=f"{where}.shadowCascades")
        if "cascadeSplitPositions" in options:
            key = f"{where}.cascadeSplitPositions"
            positions = options["cascadeSplitPositions"]
            if not isinstance(positions, list) or len(positions) < cascades - 1:
                raise InputError(f"expected a list of at least {cascades - 1} fractions, got {positions!r}", file=path,
                                 field=key)
            fractions = [number(v, file=path, key=key, above=0.0) for v in positions[:cascades - 1]] + [1.0]
            if any(b <= a for a, b in zip(fractions, fractions[1:])):
                raise InputError(f"expected increasing fractions below 1, got {positions}", file=path, field=key)
            reading.set("split", "manual_range", file=path, key=key, raw=positions)
            reading.set("splits", tuple(fractions), file=path, key=key, raw=positions)
        if "shadowFar" in options:
            # ShadowMapManager: shadowFar > 0 replaces the camera's far plane (cameraInfo.zf); 0 keeps it.
            far = number(options["shadowFar"], file=path, key=f"{where}.shadowFar", minimum=0.0)
            if far > 0:
                reading.set("shadow_distance", far, file=path, key=f"{where}.shadowFar")
            reading.set("shadow_distance_from", "fixed" if far > 0 else "camera_far", file=path,
                        key=f"{where}.shadowFar", raw=options["shadowFar"])
        _warp(options, where, path, reading)
        scaled = {"constantBias": ("bias_constant", 1.0), "normalBias": ("normal_offset", NORMAL_BIAS_SCALE),
                  "polygonOffsetSlope": ("caster_bias_slope", 1.0),
                  "polygonOffsetConstant": ("caster_bias_units", 1.0)}
        for key, (attribute, scale) in scaled.items():
            if key in options:
                value = number(options[key], file=path, key=f"{where}.{key}", minimum=0.0)
                reading.set(attribute, value * scale, file=path, key=f"{where}.{key}", raw=options[key])
        if "mapSize" in options:
            reading.set("resolution", number(options["mapSize"], file=path, key=f"{where}.mapSize", integer=True,
                                             minimum=1), file=path, key=f"{where}.mapSize")
        for key, attribute in (("shadowNearHint", "lispsm_near_hint"), ("shadowFarHint", "lispsm_far_hint")):
            if key in options:
                reading.set(attribute, number(options[key], file=path, key=f"{where}.{key}", minimum=0.0),
                            file=path, key=f"{where}.{key}")
        for key in ("screenSpaceContactShadows", "vsm", "shadowBulbRadius", "transform", "maxShadowDistance",
                    "stepCount"):
            if key in options and not (key == "screenSpaceContactShadows" and options[key] is False):
                reading.lack(file=path, key=f"{where}.{key}", value=json.dumps(options[key]), why="no csmlab knob")
        shadow_type = document.get("view", {}).get("shadowType", "PCF") if isinstance(document.get("view"), dict) \
            else "PCF"
        if shadow_type != "PCF":
            reading.lack(file=path, key="view.shadowType", value=shadow_type,
                         why="csmlab models PCF (PCF_LOW); the preset's pcf_castano 3 is kept")
    return reading.result()


def _warp(options: dict, where: str, path, reading: Reading) -> None:
    """``stable`` → stabilization and ``lispsm`` → warp: Filament warps only a map that is not stable
    (ShadowMap::updateDirectional: "We can't use LISPSM in stable mode"), so lispsm = true with stable = true is
    an orthographic stable map."""
    base = reading.base
    stable, lispsm = base.stabilization != "none", base.warp == "lispsm"
    for key in ("stable", "lispsm"):
        if key in options and not isinstance(options[key], bool):
            raise InputError(f"expected true or false, got {options[key]!r}", file=path, field=f"{where}.{key}")
    if "stable" in options:
        stable = options["stable"]
        reading.set("stabilization", "exact" if stable else "none", file=path, key=f"{where}.stable", raw=stable)
    if "lispsm" in options:
        lispsm = options["lispsm"]
    if "stable" in options or "lispsm" in options:
        key = f"{where}.lispsm" if "lispsm" in options else f"{where}.stable"
        reading.set("warp", "lispsm" if lispsm and not stable else "none", file=path, key=key,
                    raw=json.dumps(options.get("lispsm", lispsm)))


def write_filament(settings: ShadowSettings, *, near: float, far: float) -> tuple[dict, list]:
    """``settings`` as the viewer's settings JSON, and the knobs it cannot hold."""
    cascades = min(settings.cascades, 4)
    z = split_boundaries(settings.replace(cascades=cascades), near=near, far=far)
    lacking = []
    if settings.cascades > 4:
        lacking.append(f"cascades = {settings.cascades} (Filament has at most 4; 4 written)")
    base = engine_settings(PRESET)
    options = {"mapSize": largest_resolution(settings), "shadowCascades": cascades}
    if (settings.split, settings.lambda_) != (base.split, base.lambda_):
        options["cascadeSplitPositions"] = fractions_of_range(z)
    camera_far = settings.shadow_distance_from == "camera_far" and settings.max_shadow_distance == 0.0
    if settings.shadow_distance_from == "farthest_visible":
        lacking.append("shadow_distance_from = 'farthest_visible' (Filament ends at shadowFar or the camera's far "
                       "plane: the end under this camera is written)")
    options.update({"shadowFar": 0.0 if camera_far else float(z[-1]), "stable": settings.stabilization != "none",
                    "constantBias": settings.bias_constant, "normalBias": settings.normal_offset / NORMAL_BIAS_SCALE,
                    "polygonOffsetConstant": settings.caster_bias_units,
                    "polygonOffsetSlope": settings.caster_bias_slope, "lispsm": settings.warp == "lispsm"})
    if settings.warp == "lispsm":
        options.update({"shadowNearHint": settings.lispsm_near_hint, "shadowFarHint": settings.lispsm_far_hint})
    document = {"view": {"shadowType": "PCF"},
                "lighting": {"enableShadows": True, "sunlight": {"castShadows": True, "shadowOptions": options}}}
    return {"settings.json": json.dumps(document, indent=4) + "\n"}, lacking


def export_filament(settings: ShadowSettings, *, near: float, far: float) -> Snippet:
    """Filament: the sun's ``LightManager::ShadowOptions`` in the viewer's settings JSON."""
    lacking = common_lacking(settings, stable="none")
    lacking = [item for item in lacking if not item.startswith(("stabilization", "bias_constant"))]
    if settings.stabilization not in ("none", "exact"):
        lacking.append(f"stabilization = {settings.stabilization!r} (Filament's stable is on or off)")
    lacking += blend_lacking(settings, "Filament blends no cascades")
    text, _ = one_file(write_filament, settings, near=near, far=far)
    return Snippet("filament", "Filament: the viewer's settings JSON (LightManager::ShadowOptions)", "json", text,
                   tuple(lacking))


ENGINE = Engine("filament", export_filament, EngineFiles(
    read=read_filament, write=write_filament, fields=FIELDS, preset=fixed_preset(PRESET), presets=(PRESET,),
    files="the viewer's settings JSON"))
"""What the registries of csmlab.engines take from this module."""
