"""Unity's built-in render pipeline: ``ProjectSettings/QualitySettings.asset``, read and written.

The asset lists quality levels (``m_QualitySettings``); the one in use is ``m_CurrentQuality``. Each
level's ``shadowProjection`` picks the preset (0 Close Fit: ``configs/engines/unity_builtin_close.toml``,
1 Stable Fit: ``unity_builtin_stable.toml``), and ``shadowCascades`` (1, 2 or 4), ``shadowDistance``,
``shadowCascade2Split`` and ``shadowCascade4Split`` (fractions of the distance: split = "manual"),
``shadows`` (0 off, 1 hard only: pcf_bilinear, 2 soft: the preset's tent) and ``shadowResolution``
(0 Low … 3 Very High) set the fields. The shadow map's size follows the screen (Manual
"shadow-resolution-birp": each level down halves it); the presets' resolution is Very High's at
640 px wide, the lower levels are read as halvings of it.

The snippet (export_unity_builtin) is the quality level as write_unity_builtin writes it.
"""

from __future__ import annotations

from csmlab.cascades.splits import count_one_two_or_four, fractions_of_far, split_boundaries
from csmlab.engines.common import (Engine, EngineFiles, Snippet, blend_lacking, common_lacking, hard_filter,
                                   largest_resolution, one_file, shape_lacking)
from csmlab.engines.reading import Imported, Reading, engine_settings, number
from csmlab.engines.unity_yaml import unity_objects, unity_text
from csmlab.errors import InputError
from csmlab.settings import ShadowSettings

__all__ = ["ENGINE", "FIELDS", "PRESETS", "export_unity_builtin", "preset_of", "read_unity_builtin",
           "write_unity_builtin"]

PRESETS = {0: "unity_builtin_close", 1: "unity_builtin_stable"}
"""The engine preset by ShadowProjection (CloseFit 0, StableFit 1, Unity's default)."""

FIELDS = frozenset({"cascades", "split", "splits", "shadow_distance", "stabilization", "resolution", "filter"})
"""The csmlab fields a quality level carries."""

_VERY_HIGH = 3
"""ShadowResolution.VeryHigh: the presets' resolution."""
_UNMODELLED = ("shadowNearPlaneOffset", "shadowmaskMode", "shadowCascade2Split")


def preset_of(settings: ShadowSettings) -> str:
    """The preset a setting's projection is written with: Stable Fit when it stabilizes, else Close Fit."""
    return PRESETS[1] if settings.stabilization != "none" else PRESETS[0]


def read_unity_builtin(paths) -> Imported:
    """Built-in pipeline settings from ``QualitySettings.asset`` (its current quality level).

    Raises
    ------
    InputError
        A file that is not a Unity asset or holds no QualitySettings, or a value out of range.
    """
    if len(paths) != 1:
        raise InputError(f"expected one QualitySettings.asset, got {len(paths)} files", field="FILE")
    path = paths[0]
    quality = next((f for _, name, f in unity_objects(path) if name == "QualitySettings"), None)
    levels = None if quality is None else quality.get("m_QualitySettings")
    if not isinstance(levels, list) or not levels:
        raise InputError("expected QualitySettings with a list of quality levels", file=path,
                         field="m_QualitySettings")
    current = number(quality.get("m_CurrentQuality", 0), file=path, key="m_CurrentQuality", integer=True, minimum=0)
    if current >= len(levels):
        raise InputError(f"expected a level index below {len(levels)}, got {current}", file=path,
                         field="m_CurrentQuality")
    level = levels[current]
    where = f"m_QualitySettings[{current}]"
    name = level.get("name", current)
    projection = number(level.get("shadowProjection", 1), file=path, key=f"{where}.shadowProjection", integer=True)
    if projection not in PRESETS:
        raise InputError(f"expected 0 (Close Fit) or 1 (Stable Fit), got {projection}", file=path,
                         field=f"{where}.shadowProjection")
    reading = Reading("unity_builtin", PRESETS[projection])
    base = reading.base
    key = f"{where} ({name}).shadowProjection"
    if "shadowProjection" in level:
        reading.set("stabilization", base.stabilization, file=path, key=key, raw=projection)
    cascades = base.cascades
    if "shadowCascades" in level:
        cascades = number(level["shadowCascades"], file=path, key=f"{where}.shadowCascades", integer=True)
        if cascades not in (1, 2, 4):
            raise InputError(f"expected 1, 2 or 4 cascades, got {cascades}", file=path, field=f"{where}.shadowCascades")
        reading.set("cascades", cascades, file=path, key=f"{where}.shadowCascades")
    if cascades > 1:
        split_key = "shadowCascade4Split" if cascades == 4 else "shadowCascade2Split"
        if split_key in level:
            value = level[split_key]
            if cascades == 4:
                if not isinstance(value, dict) or any(a not in value for a in "xyz"):
                    raise InputError(f"expected {{x: …, y: …, z: …}}, got {value!r}", file=path,
                                     field=f"{where}.{split_key}")
                fractions = [number(value[a], file=path, key=f"{where}.{split_key}.{a}", above=0.0) for a in "xyz"]
            else:
                fractions = [number(value, file=path, key=f"{where}.{split_key}", above=0.0)]
            if any(b <= a for a, b in zip(fractions, fractions[1:])) or fractions[-1] >= 1.0:
                raise InputError(f"expected increasing fractions below 1, got {fractions}", file=path,
                                 field=f"{where}.{split_key}")
            reading.set("split", "manual", file=path, key=f"{where}.{split_key}", raw=fractions)
            reading.set("splits", (*fractions, 1.0), file=path, key=f"{where}.{split_key}", raw=fractions)
        elif cascades != base.cascades:
            raise InputError(f"expected {split_key} for {cascades} cascades, found none", file=path,
                             field=f"{where}.{split_key}")
    else:
        reading.set("split", "manual", file=path, key=f"{where}.shadowCascades", raw=1)
        reading.set("splits", (1.0,), file=path, key=f"{where}.shadowCascades", raw=1)
        # One cascade takes the whole shadowmap: csmlab's array of one slice (memory_bytes).
        reading.set("storage", "array", file=path, key=f"{where}.shadowCascades", raw=1)
    if "shadowDistance" in level:
        reading.set("shadow_distance", number(level["shadowDistance"], file=path, key=f"{where}.shadowDistance",
                                              above=0.0), file=path, key=f"{where}.shadowDistance")
    if "shadowResolution" in level:
        steps = number(level["shadowResolution"], file=path, key=f"{where}.shadowResolution", integer=True, minimum=0)
        if steps > _VERY_HIGH:
            raise InputError(f"expected 0 (Low) to 3 (Very High), got {steps}", file=path,
                             field=f"{where}.shadowResolution")
        reading.set("resolution", base.resolution >> (_VERY_HIGH - steps), file=path,
                    key=f"{where}.shadowResolution", raw=steps)
    if "shadows" in level:
        shadows = number(level["shadows"], file=path, key=f"{where}.shadows", integer=True)
        if shadows == 0:
            reading.lack(file=path, key=f"{where}.shadows", value=0, why="shadows disabled at this level")
        elif shadows == 1:
            reading.set("filter", "pcf_bilinear", file=path, key=f"{where}.shadows", raw=1)
    for unmodelled in _UNMODELLED:
        if unmodelled in level and not (unmodelled == "shadowCascade2Split" and cascades == 2):
            reading.lack(file=path, key=f"{where}.{unmodelled}", value=level[unmodelled],
                         why="not used by this level's cascades" if unmodelled == "shadowCascade2Split"
                         else "no csmlab knob")
    return reading.result()


def write_unity_builtin(settings: ShadowSettings, *, near: float, far: float) -> tuple[dict, list]:
    """``settings`` as a ``QualitySettings.asset`` with one level, and the knobs it cannot hold."""
    cascades = count_one_two_or_four(settings.cascades)
    lacking = []
    if cascades != settings.cascades:
        lacking.append(f"cascades = {settings.cascades} (Unity's built-in pipeline has 1, 2 or 4; {cascades} written)")
    z = split_boundaries(settings.replace(cascades=cascades), near=near, far=far)
    fractions = fractions_of_far(z)
    preset = preset_of(settings)
    top = engine_settings(preset).resolution
    size = largest_resolution(settings)
    steps = next((s for s in range(_VERY_HIGH, -1, -1) if top >> (_VERY_HIGH - s) <= size), 0)
    if top >> (_VERY_HIGH - steps) != size:
        lacking.append(f"resolution = {size} (Unity's levels give {top} >> k at 640 px: "
                       f"{top >> (_VERY_HIGH - steps)} written)")
    four = fractions if cascades == 4 else list(engine_settings(preset).splits[:3])
    level = ["  - serializedVersion: 2", "    name: csmlab",
             f"    shadows: {1 if hard_filter(settings) else 2}", f"    shadowResolution: {steps}",
             f"    shadowProjection: {1 if preset == PRESETS[1] else 0}", f"    shadowCascades: {cascades}",
             f"    shadowDistance: {float(z[-1])!r}",
             f"    shadowCascade2Split: {fractions[0] if cascades == 2 else 1 / 3!r}",
             f"    shadowCascade4Split: {{x: {four[0]!r}, y: {four[1]!r}, z: {four[2]!r}}}"]
    text = unity_text(47, "QualitySettings", ["m_ObjectHideFlags: 0", "serializedVersion: 5", "m_CurrentQuality: 0",
                                              "m_QualitySettings:", *level])
    return {"QualitySettings.asset": text}, lacking


def export_unity_builtin(settings: ShadowSettings, *, near: float, far: float) -> Snippet:
    """Unity's built-in pipeline: a quality level of ``ProjectSettings/QualitySettings.asset``."""
    lacking = common_lacking(settings, stable="exact") + shape_lacking(settings, fade="radial")
    lacking += blend_lacking(settings, "the built-in pipeline blends no cascades")
    text, _ = one_file(write_unity_builtin, settings, near=near, far=far)
    return Snippet("unity_builtin", "Unity built-in pipeline: ProjectSettings/QualitySettings.asset", "yaml", text,
                   tuple(lacking))


ENGINE = Engine("unity_builtin", export_unity_builtin, EngineFiles(
    read=read_unity_builtin, write=write_unity_builtin, fields=FIELDS, preset=preset_of,
    presets=tuple(PRESETS.values()), files="ProjectSettings/QualitySettings.asset"))
"""What the registries of csmlab.engines take from this module."""
