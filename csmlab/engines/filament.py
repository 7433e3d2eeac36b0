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
from csmlab.engines.common import (Engine, EngineFiles, Snippet, TuneSpace, blend_lacking, common_lacking,
                                   fixed_preset, largest_resolution, one_file)
from csmlab.engines.reading import Entry, Imported, Reading, engine_settings, json_document
from csmlab.settings import ShadowSettings

__all__ = ["ENGINE", "FIELDS", "PRESET", "TUNE_SPACE", "export_filament", "read_filament", "settled_filament",
           "write_filament"]

PRESET = "filament"
"""The engine preset holding Filament's defaults."""

FIELDS = frozenset({"cascades", "split", "splits", "lambda_", "shadow_distance", "shadow_distance_from",
                    "stabilization", "warp", "lispsm_near_hint", "lispsm_far_hint", "bias_constant", "normal_offset",
                    "caster_bias_units", "caster_bias_slope", "resolution"})
"""The csmlab fields the settings JSON carries."""

NORMAL_BIAS_SCALE = 0.5
"""ShadowMapManager: normalBias = 0.5 · ShadowOptions.normalBias · texel ("a half-texel size")."""


def _options(document: Entry) -> Entry:
    """The sun's ShadowOptions (an empty object at their key when the settings have none)."""
    lighting = document.at("lighting", "a Filament viewer settings object with a lighting section").mapping()
    sun = lighting.get("sunlight")
    if sun is not None and sun.mapping().get("shadowOptions") is not None:
        return sun.at("shadowOptions").mapping()
    if lighting.get("shadowOptions") is not None:
        return lighting.at("shadowOptions").mapping()
    return Entry({}, file=document.file, key="lighting.sunlight.shadowOptions", line=lighting.line)


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
        document = json_document(path).mapping("a JSON object of viewer settings")
        options = _options(document)
        cascades = base.cascades
        if (entry := options.member("shadowCascades")) is not None:
            cascades = entry.integer(minimum=1, below=5, what="1 to 4 cascades")
            reading.set("cascades", cascades, file=path, key=entry.key)
        if (positions := options.member("cascadeSplitPositions")) is not None:
            entries = positions.items(f"a list of at least {cascades - 1} fractions")
            if len(entries) < cascades - 1:
                raise positions.error(f"a list of at least {cascades - 1} fractions")
            fractions = [entry.number(above=0.0) for entry in entries[:cascades - 1]] + [1.0]
            if any(b <= a for a, b in zip(fractions, fractions[1:])):
                raise positions.error("increasing fractions below 1")
            reading.set("split", "manual_range", file=path, key=positions.key, raw=positions.raw)
            reading.set("splits", tuple(fractions), file=path, key=positions.key, raw=positions.raw)
        if (entry := options.member("shadowFar")) is not None:
            # ShadowMapManager: shadowFar > 0 replaces the camera's far plane (cameraInfo.zf); 0 keeps it.
            far = entry.number(minimum=0.0)
            if far > 0:
                reading.set("shadow_distance", far, file=path, key=entry.key)
            reading.set("shadow_distance_from", "fixed" if far > 0 else "camera_far", file=path, key=entry.key,
                        raw=entry.raw)
        _warp(options, path, reading)
        scaled = {"constantBias": ("bias_constant", 1.0), "normalBias": ("normal_offset", NORMAL_BIAS_SCALE),
                  "polygonOffsetSlope": ("caster_bias_slope", 1.0),
                  "polygonOffsetConstant": ("caster_bias_units", 1.0)}
        for key, (attribute, scale) in scaled.items():
            if (entry := options.member(key)) is not None:
                reading.set(attribute, entry.number(minimum=0.0) * scale, file=path, key=entry.key, raw=entry.raw)
        if (entry := options.member("mapSize")) is not None:
            reading.set("resolution", entry.integer(minimum=1), file=path, key=entry.key)
        for key, attribute in (("shadowNearHint", "lispsm_near_hint"), ("shadowFarHint", "lispsm_far_hint")):
            if (entry := options.member(key)) is not None:
                reading.set(attribute, entry.number(minimum=0.0), file=path, key=entry.key)
        for key in ("screenSpaceContactShadows", "vsm", "shadowBulbRadius", "transform", "maxShadowDistance",
                    "stepCount"):
            entry = options.member(key)
            if entry is not None and not (key == "screenSpaceContactShadows" and entry.raw is False):
                reading.lack(file=path, key=entry.key, value=json.dumps(entry.raw), why="no csmlab knob")
        view = document.get("view")
        shadow_type = view.mapping().member("shadowType") if view is not None else None
        if shadow_type is not None and shadow_type.text() != "PCF":
            reading.lack(file=path, key=shadow_type.key, value=shadow_type.raw,
                         why="csmlab models PCF (PCF_LOW); the preset's pcf_castano 3 is kept")
    return reading.result()


def _warp(options, path, reading: Reading) -> None:
    """``stable`` → stabilization and ``lispsm`` → warp: Filament warps only a map that is not stable
    (ShadowMap::updateDirectional: "We can't use LISPSM in stable mode"), so lispsm = true with stable = true is
    an orthographic stable map."""
    base = reading.base
    stable, lispsm = base.stabilization != "none", base.warp == "lispsm"
    stable_entry, lispsm_entry = options.member("stable"), options.member("lispsm")
    if stable_entry is not None:
        stable = stable_entry.boolean()
        reading.set("stabilization", "exact" if stable else "none", file=path, key=stable_entry.key, raw=stable)
    if lispsm_entry is not None:
        lispsm = lispsm_entry.boolean()
    if stable_entry is not None or lispsm_entry is not None:
        key = (lispsm_entry or stable_entry).key
        reading.set("warp", "lispsm" if lispsm and not stable else "none", file=path, key=key,
                    raw=json.dumps(lispsm))


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
    lacking = common_lacking(settings, stable="none", carried=FIELDS)
    lacking = [item for item in lacking if not item.startswith(("stabilization", "bias_constant"))]
    if settings.stabilization not in ("none", "exact"):
        lacking.append(f"stabilization = {settings.stabilization!r} (Filament's stable is on or off)")
    lacking += blend_lacking(settings, "Filament blends no cascades")
    text, _ = one_file(write_filament, settings, near=near, far=far)
    return Snippet("filament", "Filament: the viewer's settings JSON (LightManager::ShadowOptions)", "json", text,
                   tuple(lacking))


def settled_filament(settings: ShadowSettings) -> ShadowSettings:
    """``settings`` with the distance Filament derives from ``shadowFar``: a tuned ``shadow_distance`` is a
    ``shadowFar`` above 0, which replaces the camera's far plane (ShadowMapManager), so it ends the shadow as a
    fixed distance; the preset's own distance stays the camera's far plane (``shadowFar = 0``)."""
    if settings.shadow_distance_from == "camera_far" and \
            settings.shadow_distance != engine_settings(PRESET).shadow_distance:
        return settings.replace(shadow_distance_from="fixed")
    return settings


TUNE_SPACE = TuneSpace({
    # ShadowOptions: shadowCascades 1 to 4 (split positions Filament's own, practical λ 0.5), shadowFar,
    # constantBias, normalBias (in half texels), mapSize. Not stable: Filament turns LiSPSM off in stable mode,
    # and its reader does not yet take the warp from the file.
    "cascades": ("choice", (1, 2, 3, 4)),
    "shadow_distance": ("range", 10.0, 1000.0, True, None),
    "bias_constant": ("range", 0.0, 0.01, False, None),
    "normal_offset": ("range", 0.0, 3.0 * NORMAL_BIAS_SCALE, False, None),
    "resolution": ("choice", (512, 1024, 2048, 4096)),
}, settle=settled_filament)
"""What a tune of the Filament preset may try: the sun's own ShadowOptions."""

ENGINE = Engine("filament", export_filament, EngineFiles(
    read=read_filament, write=write_filament, fields=FIELDS, preset=fixed_preset(PRESET), presets=(PRESET,),
    files="the viewer's settings JSON"), tune=TUNE_SPACE)
"""What the registries of csmlab.engines take from this module."""
