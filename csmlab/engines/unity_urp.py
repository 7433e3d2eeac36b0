"""Unity URP: the ``UniversalRenderPipelineAsset`` (``.asset``, YAML), read and written.

Fields (``Runtime/Data/UniversalRenderPipelineAsset.cs``): ``m_ShadowCascadeCount``, ``m_Cascade2Split``
(a fraction), ``m_Cascade3Split`` ``{x, y}``, ``m_Cascade4Split`` ``{x, y, z}`` (fractions of the shadow
distance: split = "manual"), ``m_ShadowDistance``, ``m_CascadeBorder`` (fade_out),
``m_ShadowDepthBias`` and ``m_ShadowNormalBias`` (texels: bias_texels, normal_offset),
``m_MainLightShadowmapResolution`` (the atlas: one cascade takes it all, two to four a half-side tile
each, ``ShadowUtils.GetMaxTileResolutionInAtlas``), ``m_SoftShadowsSupported`` and ``m_SoftShadowQuality``
(off: one hardware 2×2 compare, pcf_bilinear; Medium: Tent 5×5). A field the asset lacks keeps the
default, ``configs/engines/unity_urp.toml``'s value.

The snippet (export_unity_urp) names: ``UniversalRenderPipelineAsset.shadowDistance``, ``shadowCascadeCount``,
``cascade2Split``, ``cascade3Split``, ``cascade4Split`` (fractions of the shadow distance),
``mainLightShadowmapResolution`` (the atlas: one cascade takes all of it, two to four a quarter tile each).
"""

from __future__ import annotations

from csmlab.cascades.splits import fractions_of_far, split_boundaries
from csmlab.engines.common import (Engine, EngineFiles, Snippet, TuneSpace, blend_lacking, common_lacking, fixed_preset,
                                   four_digits, hard_filter, largest_resolution, shape_lacking, storage_lacking)
from csmlab.engines.reading import Entry, Imported, Reading, engine_settings
from csmlab.engines.unity_yaml import unity_objects, unity_text
from csmlab.errors import InputError
from csmlab.settings import ShadowSettings

__all__ = ["ENGINE", "FIELDS", "PRESET", "TUNE_SPACE", "URP_FILTER", "export_unity_urp", "read_unity_urp",
           "settled_unity_urp", "write_unity_urp"]

PRESET = "unity_urp"
"""The engine preset holding URP's defaults."""

FIELDS = frozenset({"cascades", "split", "splits", "shadow_distance", "fade_out", "bias_texels", "normal_offset",
                    "resolution", "filter", "filter_size", "storage"})
"""The csmlab fields the URP asset carries (storage: one cascade takes the whole shadowmap)."""

URP_FILTER = ("pcf_tent_bilinear", 5)
"""The filter and size of URP's soft shadows at the asset's Medium quality (SampleShadow_ComputeSamples_Tent_5x5);
another soft filter is lacking (soft shadows off: pcf_bilinear)."""

_FEWER_SPLITS = {2: (0.25,), 3: (0.1, 0.3)}
"""URP's m_Cascade2Split and m_Cascade3Split defaults (UniversalRenderPipelineAsset.cs); 4 cascades: the preset's."""

_SOFT_MEDIUM = 2
"""UnityEngine.Rendering.Universal.SoftShadowQuality.Medium, the quality csmlab models (URP_FILTER)."""
_UNMODELLED = {"m_ConservativeEnclosingSphere": "URP's tighter cascade spheres (Unity 2023+)",
               "m_NumIterationsEnclosingSphere": "URP's tighter cascade spheres (Unity 2023+)",
               "m_MainLightShadowsSupported": "main light shadows switched off in the asset",
               "m_ShadowType": "an obsolete field of early URP assets"}


def _split_fractions(fields: Entry, cascades: int) -> tuple[list, str] | None:
    key = {2: "m_Cascade2Split", 3: "m_Cascade3Split", 4: "m_Cascade4Split"}.get(cascades)
    value = None if key is None else fields.member(key)
    if value is None:
        return None
    if cascades == 2:
        fractions = [value.number(above=0.0)]
    else:
        axes = "xyz"[:cascades - 1]
        value.mapping(f"{{{', '.join(a + ': …' for a in axes)}}}")
        fractions = [value.at(a).number(above=0.0) for a in axes]
    if any(b <= a for a, b in zip(fractions, fractions[1:])) or fractions[-1] >= 1.0:
        raise InputError(f"expected increasing fractions below 1, got {fractions}", file=fields.file, field=key,
                         line=value.line)
    return fractions, key


def read_unity_urp(paths) -> Imported:
    """URP settings from a ``UniversalRenderPipelineAsset`` ``.asset``.

    Raises
    ------
    InputError
        A file that is not a Unity asset, an asset without a URP pipeline asset's shadow fields, or a
        value out of range (file and key named).
    """
    reading = Reading("unity_urp", PRESET)
    base = reading.base
    for path in paths:
        assets = [f for class_id, name, f in unity_objects(path) if name == "MonoBehaviour" and f.is_object()
                  and {"m_ShadowCascadeCount", "m_MainLightShadowmapResolution"} & set(f.keys())]
        if not assets:
            raise InputError("expected a UniversalRenderPipelineAsset (a MonoBehaviour with m_ShadowCascadeCount)",
                             file=path, field="m_ShadowCascadeCount")
        fields = assets[0]
        cascades = base.cascades
        count = fields.member("m_ShadowCascadeCount")
        if count is not None:
            cascades = count.integer(minimum=1, below=5, what="1 to 4 cascades")
            reading.set("cascades", cascades, file=path, key=count.key)
        found = _split_fractions(fields, cascades)
        if found is not None or count is not None:
            fractions, key = found if found is not None else (
                list(_FEWER_SPLITS.get(cascades, base.splits[:cascades - 1])), "m_ShadowCascadeCount")
            reading.set("split", "manual", file=path, key=key, raw=fractions)
            reading.set("splits", (*fractions, 1.0), file=path, key=key, raw=fractions)
        for key, attribute, above in (("m_ShadowDistance", "shadow_distance", 0.0),
                                      ("m_CascadeBorder", "fade_out", None),
                                      ("m_ShadowDepthBias", "bias_texels", None),
                                      ("m_ShadowNormalBias", "normal_offset", None)):
            if (entry := fields.member(key)) is not None:
                value = entry.number(above=above) if above is not None else entry.number(minimum=0.0)
                reading.set(attribute, value, file=path, key=key, raw=entry.raw)
        if (entry := fields.member("m_MainLightShadowmapResolution")) is not None:
            atlas = entry.integer(minimum=1)
            reading.set("resolution", atlas if cascades == 1 else atlas // 2, file=path, key=entry.key, raw=atlas)
        if cascades == 1:
            # One cascade takes the whole shadowmap: one texture of one map, csmlab's array of one slice.
            reading.set("storage", "array", file=path, key="m_ShadowCascadeCount", raw=1)
        elif cascades == 2:
            reading.lack(file=path, key="m_ShadowCascadeCount", value=2,
                         why="URP allocates 2 tiles (the atlas's half height), csmlab's 2x2 layout counts 4 in "
                             "memory_bytes")
        if (entry := fields.member("m_SoftShadowsSupported")) is not None:
            soft = entry.integer()
            quality_entry = fields.member("m_SoftShadowQuality")
            quality = _SOFT_MEDIUM if quality_entry is None else quality_entry.integer()
            if not soft:
                reading.set("filter", "pcf_bilinear", file=path, key=entry.key, raw=soft)
            elif quality == _SOFT_MEDIUM:
                reading.set("filter", URP_FILTER[0], file=path, key=entry.key, raw=soft)
                reading.set("filter_size", URP_FILTER[1], file=path, key="m_SoftShadowQuality" if quality_entry
                            is not None else "m_SoftShadowsSupported (no m_SoftShadowQuality: Medium)", raw=quality)
            else:
                reading.lack(file=path, key="m_SoftShadowQuality", value=quality,
                             why="csmlab models soft shadows off and Medium (Tent 5×5); the asset's default, "
                                 "soft shadows off, is kept")
        for key, why in _UNMODELLED.items():
            entry = fields.member(key)
            # Each a number, checked, then shown as written.
            if entry is not None and not (entry.number() == 1 and key == "m_MainLightShadowsSupported"):
                reading.lack(file=path, key=key, value=entry.raw, why=why)
    return reading.result()


def write_unity_urp(settings: ShadowSettings, *, near: float, far: float) -> tuple[dict, list]:
    """``settings`` as a ``UniversalRenderPipelineAsset`` asset text, and the knobs it cannot hold."""
    cascades = min(settings.cascades, 4)
    wanted = largest_resolution(settings) * (1 if cascades == 1 else 2)
    atlas = 1 << max(8, min(13, wanted.bit_length() - 1))
    z = split_boundaries(settings.replace(cascades=cascades), near=near, far=far)
    fractions = fractions_of_far(z)
    splits = {**_FEWER_SPLITS, 4: engine_settings(PRESET).splits[:3]}
    if cascades > 1:
        splits[cascades] = fractions
    lacking = []
    if settings.depth_format != "unorm16":
        lacking.append(f"depth_format = {settings.depth_format!r} (URP's shadowmap is 16-bit)")
    lacking += storage_lacking(settings, cascades=cascades, atlas=engine_settings(PRESET).storage)
    soft = not hard_filter(settings)
    fields = ["m_Name: UniversalRP", "m_MainLightShadowsSupported: 1", f"m_MainLightShadowmapResolution: {atlas}",
              f"m_ShadowDistance: {float(z[-1])!r}", f"m_ShadowCascadeCount: {cascades}",
              f"m_Cascade2Split: {splits[2][0]!r}",
              f"m_Cascade3Split: {{x: {splits[3][0]!r}, y: {splits[3][1]!r}}}",
              f"m_Cascade4Split: {{x: {splits[4][0]!r}, y: {splits[4][1]!r}, z: {splits[4][2]!r}}}",
              f"m_CascadeBorder: {settings.fade_out!r}", f"m_ShadowDepthBias: {settings.bias_texels!r}",
              f"m_ShadowNormalBias: {settings.normal_offset!r}", f"m_SoftShadowsSupported: {int(soft)}",
              f"m_SoftShadowQuality: {_SOFT_MEDIUM}"]
    return {"UniversalRP.asset": unity_text(114, "MonoBehaviour", fields)}, lacking


def export_unity_urp(settings: ShadowSettings, *, near: float, far: float) -> Snippet:
    """Unity URP: the pipeline asset's shadow fields, set from a script."""
    lacking = common_lacking(settings, stable="exact", carried=FIELDS) + shape_lacking(settings, fade="squared_radial")
    cascades = min(settings.cascades, 4)
    if settings.cascades > 4:
        lacking.append(f"cascades = {settings.cascades} (URP has at most 4)")
    wanted = largest_resolution(settings) * (1 if cascades == 1 else 2)
    # The asset's resolution is one of 256 … 8192 (powers of two): the largest that is not bigger.
    atlas = 1 << max(8, min(13, wanted.bit_length() - 1))
    if atlas != wanted:
        lacking.append(f"resolution = {largest_resolution(settings)} per cascade (URP's atlas is a power of two in "
                       f"256..8192: {atlas} written for {wanted})")
    lacking += blend_lacking(settings, "URP blends no cascades; cascadeBorder fades the last")
    if not hard_filter(settings) and (settings.filter, settings.filter_size) != URP_FILTER:
        lacking.append(f"filter = {settings.filter!r}, filter_size = {settings.filter_size} (URP's soft shadows are "
                       f"fixed tents of bilinear taps: Medium {URP_FILTER[0]} {URP_FILTER[1]})")
    fractions = fractions_of_far(split_boundaries(settings.replace(cascades=cascades), near=near, far=far))
    lines = ["// UniversalRenderPipelineAsset asset = …;",
             f"asset.shadowDistance = {four_digits(min(settings.shadow_distance, far))}f;",
             f"asset.shadowCascadeCount = {cascades};"]
    if cascades == 2:
        lines.append(f"asset.cascade2Split = {four_digits(fractions[0])}f;")
    elif cascades == 3:
        lines.append(f"asset.cascade3Split = new Vector2({', '.join(four_digits(f) + 'f' for f in fractions)});")
    elif cascades == 4:
        lines.append(f"asset.cascade4Split = new Vector3({', '.join(four_digits(f) + 'f' for f in fractions)});")
    lines += [f"asset.mainLightShadowmapResolution = {atlas};  // atlas: {atlas // (1 if cascades == 1 else 2)}² "
              f"per cascade",
              f"asset.supportsSoftShadows = {'false' if hard_filter(settings) else 'true'};",
              f"asset.cascadeBorder = {four_digits(settings.fade_out)}f;",
              f"asset.shadowDepthBias = {four_digits(settings.bias_texels)}f;",
              f"asset.shadowNormalBias = {four_digits(settings.normal_offset)}f;"]
    return Snippet("unity_urp", "Unity URP: UniversalRenderPipelineAsset", "csharp", "\n".join(lines) + "\n",
                   tuple(lacking))


def settled_unity_urp(settings: ShadowSettings) -> ShadowSettings:
    """``settings`` with the fields URP derives from the tuned ones: for another cascade count, the asset's split
    field of that count at URP's default (m_Cascade2Split, m_Cascade3Split; 4: the preset's), one cascade taking
    the whole shadowmap (storage ``array``); soft shadows at Medium (URP_FILTER's 5×5 tent)."""
    base = engine_settings(PRESET)
    count = settings.cascades
    if len(settings.splits) != count:
        fractions = base.splits[:-1] if count == 4 else _FEWER_SPLITS.get(count, ())
        settings = settings.replace(split="manual", splits=(*fractions, 1.0))
    if settings.filter == URP_FILTER[0]:
        settings = settings.replace(filter_size=URP_FILTER[1])
    return settings.replace(storage="array" if count == 1 else base.storage)


TUNE_SPACE = TuneSpace({
    # m_ShadowCascadeCount 1 to 4; m_MainLightShadowmapResolution 256 to 8192 (per cascade: halved for 2 or more).
    "cascades": ("choice", (1, 2, 3, 4)),
    "resolution": ("choice", (256, 512, 1024, 2048, 4096)),
    # The asset inspector's sliders: m_ShadowDistance (from 5 m, so that the first of 4 default splits, 0.067 of
    # it, lies beyond a camera's near plane), m_CascadeBorder, m_ShadowDepthBias, m_ShadowNormalBias.
    "shadow_distance": ("range", 5.0, 1000.0, True, None),
    "fade_out": ("range", 0.0, 1.0, False, None),
    "bias_texels": ("range", 0.0, 10.0, False, None),
    "normal_offset": ("range", 0.0, 10.0, False, None),
    # m_SoftShadowsSupported off (one hardware comparison) or on at Medium.
    "filter": ("choice", ("pcf_bilinear", URP_FILTER[0])),
}, settle=settled_unity_urp)
"""What a tune of the URP preset may try: the pipeline asset's own shadow settings."""

ENGINE = Engine("unity_urp", export_unity_urp, EngineFiles(
    read=read_unity_urp, write=write_unity_urp, fields=FIELDS, preset=fixed_preset(PRESET), presets=(PRESET,),
    files="a UniversalRenderPipelineAsset .asset"), tune=TUNE_SPACE)
"""What the registries of csmlab.engines take from this module."""
