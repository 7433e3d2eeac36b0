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
from csmlab.engines.common import (Engine, EngineFiles, Snippet, TuneSpace, blend_lacking, common_lacking, hard_filter,
                                   largest_resolution, one_file, shape_lacking, storage_lacking)
from csmlab.engines.reading import Imported, Reading, engine_settings
from csmlab.engines.unity_yaml import unity_objects, unity_text
from csmlab.errors import InputError
from csmlab.settings import ShadowSettings

__all__ = ["ENGINE", "FIELDS", "PRESETS", "TUNE_SPACE", "export_unity_builtin", "preset_of", "read_unity_builtin",
           "settled_unity_builtin", "write_unity_builtin"]

PRESETS = {0: "unity_builtin_close", 1: "unity_builtin_stable"}
"""The engine preset by ShadowProjection (CloseFit 0, StableFit 1, Unity's default)."""

FIELDS = frozenset({"cascades", "split", "splits", "shadow_distance", "stabilization", "resolution", "filter",
                    "storage"})
"""The csmlab fields a quality level carries (storage: one cascade takes the whole shadowmap)."""

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
    levels = None if quality is None or not quality.is_object() else quality.get("m_QualitySettings")
    if levels is None or not isinstance(levels.raw, list) or not levels.raw:
        raise InputError("expected QualitySettings with a list of quality levels", file=path,
                         field="m_QualitySettings")
    levels = levels.items()
    current = quality.member("m_CurrentQuality")
    current = 0 if current is None else current.integer(minimum=0, below=len(levels),
                                                        what=f"a level index below {len(levels)}")
    level = levels[current].mapping("a quality level (name, shadows, shadowCascades, …)")
    where = level.key
    name = level.get("name")
    name = current if name is None or isinstance(name.raw, (dict, list)) else name.raw
    projection_entry = level.member("shadowProjection")
    projection = 1 if projection_entry is None else projection_entry.integer(what="0 (Close Fit) or 1 (Stable Fit)")
    if projection not in PRESETS:
        raise projection_entry.error("0 (Close Fit) or 1 (Stable Fit)")
    reading = Reading("unity_builtin", PRESETS[projection])
    base = reading.base
    if projection_entry is not None:
        reading.set("stabilization", base.stabilization, file=path, key=f"{where} ({name}).shadowProjection",
                    raw=projection)
    cascades = base.cascades
    if (entry := level.member("shadowCascades")) is not None:
        cascades = entry.integer(what="1, 2 or 4 cascades")
        if cascades not in (1, 2, 4):
            raise entry.error("1, 2 or 4 cascades")
        reading.set("cascades", cascades, file=path, key=entry.key)
    if cascades > 1:
        split_key = "shadowCascade4Split" if cascades == 4 else "shadowCascade2Split"
        value = level.member(split_key)
        if value is not None:
            if cascades == 4:
                value.mapping("{x: …, y: …, z: …}")
                fractions = [value.at(a).number(above=0.0) for a in "xyz"]
            else:
                fractions = [value.number(above=0.0)]
            if any(b <= a for a, b in zip(fractions, fractions[1:])) or fractions[-1] >= 1.0:
                raise InputError(f"expected increasing fractions below 1, got {fractions}", file=path,
                                 field=value.key, line=value.line)
            reading.set("split", "manual", file=path, key=value.key, raw=fractions)
            reading.set("splits", (*fractions, 1.0), file=path, key=value.key, raw=fractions)
        elif cascades != base.cascades:
            raise InputError(f"expected {split_key} for {cascades} cascades, found none", file=path,
                             field=f"{where}.{split_key}", line=level.line)
    else:
        reading.set("split", "manual", file=path, key=f"{where}.shadowCascades", raw=1)
        reading.set("splits", (1.0,), file=path, key=f"{where}.shadowCascades", raw=1)
        # One cascade takes the whole shadowmap: csmlab's array of one slice (memory_bytes).
        reading.set("storage", "array", file=path, key=f"{where}.shadowCascades", raw=1)
    if (entry := level.member("shadowDistance")) is not None:
        reading.set("shadow_distance", entry.number(above=0.0), file=path, key=entry.key)
    if (entry := level.member("shadowResolution")) is not None:
        steps = entry.integer(minimum=0, below=_VERY_HIGH + 1, what="0 (Low) to 3 (Very High)")
        reading.set("resolution", base.resolution >> (_VERY_HIGH - steps), file=path, key=entry.key, raw=steps)
    if (entry := level.member("shadows")) is not None:
        shadows = entry.integer()
        if shadows == 0:
            reading.lack(file=path, key=entry.key, value=0, why="shadows disabled at this level")
        elif shadows == 1:
            reading.set("filter", "pcf_bilinear", file=path, key=entry.key, raw=1)
    for unmodelled in _UNMODELLED:
        entry = level.member(unmodelled)
        if entry is None or (unmodelled == "shadowCascade2Split" and cascades == 2):
            continue
        entry.number()  # a number, checked: shown as written
        reading.lack(file=path, key=entry.key, value=entry.raw,
                     why=("not used by this level's cascades" if unmodelled == "shadowCascade2Split"
                          else "no csmlab knob"))
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
    lacking += storage_lacking(settings, cascades=cascades, atlas=engine_settings(preset).storage)
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
    lacking = common_lacking(settings, stable="exact", carried=FIELDS) + shape_lacking(settings, fade="radial")
    lacking += blend_lacking(settings, "the built-in pipeline blends no cascades")
    text, _ = one_file(write_unity_builtin, settings, near=near, far=far)
    return Snippet("unity_builtin", "Unity built-in pipeline: ProjectSettings/QualitySettings.asset", "yaml", text,
                   tuple(lacking))


_TWO_SPLIT = 1 / 3
"""QualitySettings.shadowCascade2Split's default."""


def settled_unity_builtin(settings: ShadowSettings) -> ShadowSettings:
    """``settings`` with the fields a quality level derives from the tuned ones: for another cascade count,
    that count's split field at Unity's default (shadowCascade2Split; 4: the preset's shadowCascade4Split), one
    cascade taking the whole shadowmap (storage ``array``); soft shadows as the preset filters them."""
    base = engine_settings(preset_of(settings))
    count = settings.cascades
    if len(settings.splits) != count:
        fractions = {1: (), 2: (_TWO_SPLIT,), 4: base.splits[:-1]}[count]
        settings = settings.replace(split="manual", splits=(*fractions, 1.0))
    if not hard_filter(settings):
        settings = settings.replace(filter=base.filter, filter_size=base.filter_size)
    return settings.replace(storage="array" if count == 1 else base.storage)


TUNE_SPACE = TuneSpace({
    # shadowCascades No, Two or Four Cascades; shadowResolution Low to Very High (the preset's size >> 3..0).
    "cascades": ("choice", (1, 2, 4)),
    "resolution": ("choice", (256, 512, 1024, 2048)),
    # shadowDistance (from 5 m: the first of 4 default splits, 0.067 of it, beyond a camera's near plane).
    "shadow_distance": ("range", 5.0, 1000.0, True, None),
    # shadows Hard Only (one hardware comparison) or Hard and Soft (the preset's tent).
    "filter": ("choice", ("pcf_bilinear", "pcf_tent_bilinear")),
}, settle=settled_unity_builtin)
"""What a tune of a built-in pipeline preset may try: a quality level's own shadow settings."""

ENGINE = Engine("unity_builtin", export_unity_builtin, EngineFiles(
    read=read_unity_builtin, write=write_unity_builtin, fields=FIELDS, preset=preset_of,
    presets=tuple(PRESETS.values()), files="ProjectSettings/QualitySettings.asset"), tune=TUNE_SPACE)
"""What the registries of csmlab.engines take from this module."""
