"""Stride: a scene asset (``.sdscene``, Stride's asset YAML) holding a directional light, read and written.

The sun is a ``!LightComponent`` whose ``Type`` is ``!LightDirectional``; its ``Shadow`` is a
``LightDirectionalShadowMap`` (stride3d/stride @34c7f40f, sources/engine/Stride.Rendering/Rendering/Lights/
``LightDirectionalShadowMap.cs``, ``LightShadowMap.cs``, ``LightShadowMapFilterTypePCF.cs``), whose members
map to csmlab fields as the renderer uses them (Rendering/Shadows/``LightDirectionalShadowMapRenderer.cs``
``ComputeCascadeSplits``, ``ShadowMapRenderer.cs``):

- ``CascadeCount`` (``OneCascade``, ``TwoCascades``, ``FourCascades``) → ``cascades``;
- ``Size`` (``XSmall`` … ``XLarge``) → ``resolution`` = 1024 · 2^(Size − 3) (``ShadowMapRenderer``:
  ``ReferenceShadowSize · ComputeSizeFactor``, at a screen of at least that many pixels);
- ``StabilizationMode``: ``None`` → stabilization ``none``; ``ProjectionSnapping`` → ``exact`` with snap
  ``centre_nearest``; ``ViewSnapping`` → ``exact`` with snap ``view``;
- ``DepthRange.IsAutomatic`` true → bounds ``sdsm``, hold ``stepped`` (the held visible range); false →
  bounds ``frustum`` over ``[near + ManualMinDistance, near + ManualMaxDistance]``, ``near`` the camera's
  near plane (``CameraComponent.NearClipPlane`` of the scene's camera, Stride's 0.1 m without one):
  ``shadow_distance`` is where the last cascade ends; ``IsBlendingCascades`` → ``blend_band`` 0.2 (the
  shader's fixed band, configs/engines/stride.toml) or 0;
- ``PartitionMode``: ``!LightDirectionalShadowMap.PartitionLogarithmic`` → split ``practical`` with
  ``lambda = 1 − PSSMFactor`` (the renderer lerps uniform to logarithmic by ``1 − PSSMFactor``);
  ``!LightDirectionalShadowMap.PartitionManual`` → split ``manual_range``: cascade ``i`` ends at
  ``min + SplitDistance_k · max`` (four cascades use ``SplitDistance0..3``, two ``1`` and ``3``, one ``1``),
  which from the near plane is ``s_k / s_last`` of the range, the last ending at ``near + s_last · max``;
- ``Filter``: absent (null, ``ShadowMapFilterDefault``: one bilinear comparison) → ``pcf_bilinear``;
  ``!LightShadowMapFilterTypePcf`` ``FilterSize`` ``Filter3x3`` / ``Filter5x5`` → ``pcf_castano`` 3 / 5
  (``ShadowMapFilterPcf.sdsl``'s kernels of bilinear taps);
- ``BiasParameters.DepthBias`` → ``bias_depth_range`` (the cascade's normalized depth);
  ``NormalOffsetScale`` → ``normal_offset_m`` = 2 · NormalOffsetScale / 4096 (the 4096² atlas,
  ShadowMapReceiverBase.sdsl).

A member the file leaves out is the engine's: Stride writes only members that differ from their
``[DefaultValue]``, and those defaults are configs/engines/stride.toml's, except the absent ``Filter``
(null) which is set here. ``ManualMinDistance`` ≠ 0, ``Filter7x7``, ``ComputeTransmittance`` and
``Debug`` have no csmlab knob and are listed as unmodelled.

The snippet (export_stride) is the scene asset's ``LightDirectionalShadowMap`` (``CascadeCount``, ``Size``,
``StabilizationMode``, ``DepthRange``, ``PartitionMode``, ``Filter``, ``BiasParameters``) as write_stride writes it.
"""

from __future__ import annotations

import uuid

import yaml

from csmlab.cascades.bounds import shadow_end
from csmlab.cascades.splits import split_boundaries
from csmlab.engines.common import (Engine, EngineFiles, Snippet, TuneSpace, common_lacking, fixed_preset,
                                   largest_resolution, one_file)
from csmlab.documents import described
from csmlab.engines.reading import (Entry, Imported, Located, LocatingLoader, Reading, engine_settings,
                                    located_mapping, read_text, yaml_document)
from csmlab.errors import InputError
from csmlab.lookup_choices import FILTER_METHODS
from csmlab.settings import ShadowSettings

__all__ = ["DEFAULT_NEAR", "ENGINE", "FIELDS", "PRESET", "TUNE_SPACE", "export_stride", "read_stride", "write_stride"]

PRESET = "stride"
"""The engine preset holding Stride's defaults."""

FIELDS = frozenset({"cascades", "resolution", "stabilization", "snap", "bounds", "hold", "shadow_distance",
                    "shadow_distance_from", "split", "lambda_", "splits", "blend_band", "filter", "filter_size",
                    "bias_depth_range", "normal_offset_m"})
"""The csmlab fields a LightDirectionalShadowMap carries."""

CASCADE_COUNTS = {"OneCascade": 1, "TwoCascades": 2, "FourCascades": 4}
"""LightShadowMapCascadeCount by name → cascades."""
SIZES = {"XSmall": 128, "Small": 256, "Medium": 512, "Large": 1024, "XLarge": 2048}
"""LightShadowMapSize by name → texels per side of a cascade: 1024 · 2^(Size − 3)."""
STABILIZATION = {"None": ("none", None), "ProjectionSnapping": ("exact", "centre_nearest"),
                 "ViewSnapping": ("exact", "view")}
"""LightShadowMapStabilizationMode by name → (stabilization, snap)."""
PCF_SIZES = {"Filter3x3": 3, "Filter5x5": 5}
"""LightShadowMapFilterTypePcfSize → pcf_castano's filter_size (Filter7x7 has no csmlab kernel)."""
BLEND_BAND = 0.2
"""IsBlendingCascades: the fraction of the previous cascade each one reaches back (ShadowMapReceiverDirectional)."""
ATLAS_SIZE = 4096
"""ShadowMapRenderer's atlas side (ReferenceShadowSize · 2^(XLarge − 3) · 2): the normal offset's texel."""
DEFAULT_NEAR = 0.1
"""CameraComponent.DefaultNearClipPlane, metres."""
DEFAULT_FAR = 1000.0
"""CameraComponent.DefaultFarClipPlane, metres."""
MANUAL_SPLITS = {1: ("SplitDistance1",), 2: ("SplitDistance1", "SplitDistance3"),
                 4: ("SplitDistance0", "SplitDistance1", "SplitDistance2", "SplitDistance3")}
"""PartitionManual: the members ComputeCascadeSplits uses, by cascade count."""
MANUAL_DEFAULTS = {"SplitDistance0": 0.05, "SplitDistance1": 0.15, "SplitDistance2": 0.5, "SplitDistance3": 1.0}
"""PartitionManual's constructor values (``[DefaultValue]``s)."""
LOGARITHMIC = "LightDirectionalShadowMap.PartitionLogarithmic"
MANUAL = "LightDirectionalShadowMap.PartitionManual"
PCF = "LightShadowMapFilterTypePcf"


class _StrideLoader(LocatingLoader):
    """The safe loader taking Stride's ``!Type`` tags (a tagged mapping's :attr:`Located.tag`) and its ``Member*``
    override marks (the star dropped)."""

    def construct_mapping(self, node, deep=False):
        mapping = super().construct_mapping(node, deep=deep)
        return {(k[:-1] if isinstance(k, str) and k.endswith("*") else k): v for k, v in mapping.items()}


def _construct_tagged(loader: _StrideLoader, suffix: str, node):
    if isinstance(node, yaml.MappingNode):
        value = located_mapping(node, loader.construct_mapping(node, deep=True))
        value.tag = suffix
        return value
    if isinstance(node, yaml.SequenceNode):
        return loader.construct_sequence(node, deep=True)
    return loader.construct_scalar(node)


_StrideLoader.add_multi_constructor("!", _construct_tagged)


def _asset(path) -> Entry:
    """The scene (or prefab) asset of ``path``."""
    document = yaml_document(read_text(path), file=path, loader=_StrideLoader, what="Stride asset YAML")
    if getattr(document, "tag", "") not in ("SceneAsset", "PrefabAsset"):
        raise InputError("expected a Stride scene asset (a .sdscene starting with !SceneAsset)", file=path,
                         field="!SceneAsset")
    return Entry(document, file=path)


def _shown(entry: Entry) -> str:
    """A value as a message about a tagged one shows it: its tag, or what it is."""
    return f"!{entry.tag}" if entry.tag else described(entry.raw)


def _components(asset: Entry) -> list[tuple[str, Entry]]:
    """``(entity name, component)`` of every tagged component of every entity in the asset's hierarchy."""
    hierarchy = asset.get("Hierarchy")
    parts = None if hierarchy is None else hierarchy.mapping("the scene's hierarchy (Hierarchy.Parts)").get("Parts")
    if parts is None:
        raise InputError("expected Hierarchy.Parts, the scene's entities", file=asset.file, field="Hierarchy.Parts")
    found = []
    for index, part in enumerate(parts.items("a list of the scene's entities")):
        entity = part.mapping("an entity part (Entity: …)").get("Entity")
        if entity is None:
            continue
        entity.mapping("an entity (Id, Name, Components)")
        name = entity.get("Name")
        label = str(name.raw) if name is not None and not isinstance(name.raw, (dict, list)) else \
            f"Hierarchy.Parts[{index}]"
        components = entity.get("Components")
        if components is not None:
            found += [(label, c) for _, c in components.mapping("the entity's components").fields() if c.tag]
    return found


def _sun(components, path) -> tuple[str, Entry]:
    """The entity name and ``Shadow`` of the scene's one enabled directional light."""
    lights = []
    for name, component in components:
        enabled = component.member("Enabled")
        kind = component.get("Type")
        if component.tag == "LightComponent" and (enabled is None or enabled.boolean()) and kind is not None \
                and kind.tag == "LightDirectional":
            lights.append((name, kind))
    if len(lights) != 1:
        names = ", ".join(name for name, _ in lights)
        raise InputError("expected one enabled LightComponent of Type !LightDirectional, found "
                         + (f"{len(lights)}: {names}" if lights else "none"), file=path, field="LightDirectional")
    name, kind = lights[0]
    shadow = kind.get("Shadow")
    if shadow is None or not shadow.is_object():
        raise InputError("expected the directional light's Shadow (a LightDirectionalShadowMap)", file=path,
                         field=f"{name}.Shadow", line=kind.line)
    return name, Entry(shadow.raw, file=path, key=f"{name}.Shadow", line=shadow.line)


def _near(components, reading: Reading) -> float:
    """The scene camera's near plane in metres (the first CameraComponent's; Stride's default without one)."""
    cameras = [(name, c) for name, c in components if c.tag == "CameraComponent"]
    if not cameras:
        return DEFAULT_NEAR
    if len(cameras) > 1:
        reading.lack(file=cameras[0][1].file, key="CameraComponent", value=", ".join(name for name, _ in cameras),
                     why=f"several cameras: the first one's near plane, {cameras[0][0]}'s, places a manual depth range")
    name, camera = cameras[0]
    near = Entry(camera.raw, file=camera.file, key=name, line=camera.line).member("NearClipPlane")
    return DEFAULT_NEAR if near is None else near.number(above=0.0)


def _members(entry: Entry | None, what: str) -> Entry | None:
    """``entry``, checked to be a member set, or None where it is absent or null (all members the defaults)."""
    return None if entry is None or entry.raw is None else entry.mapping(what)


def read_stride(paths) -> Imported:
    """Stride settings from a ``.sdscene`` holding a directional light with a shadow map.

    Raises
    ------
    InputError
        Not Stride asset YAML, no (or several) enabled directional lights, or a value out of range (file
        and key named).
    """
    if len(paths) != 1:
        raise InputError(f"expected one .sdscene, got {len(paths)} files", field="FILE")
    path = paths[0]
    reading = Reading("stride", PRESET)
    components = _components(_asset(path))
    _, shadow = _sun(components, path)
    enabled = shadow.member("Enabled")
    if enabled is None or not enabled.boolean():
        reading.lack(file=path, key=f"{shadow.key}.Enabled", value=False,
                     why="the light casts no shadow in Stride; csmlab always shadows")
    cascades = engine_settings(PRESET).cascades
    if (entry := shadow.member("CascadeCount")) is not None:
        cascades = entry.choice(CASCADE_COUNTS)
        reading.set("cascades", cascades, file=path, key=entry.key, raw=entry.raw)
    if (entry := shadow.member("Size")) is not None:
        reading.set("resolution", entry.choice(SIZES), file=path, key=entry.key, raw=entry.raw)
    if (entry := shadow.member("StabilizationMode")) is not None:
        stabilization, snap = entry.choice(STABILIZATION)
        reading.set("stabilization", stabilization, file=path, key=entry.key, raw=entry.raw)
        if snap is not None:
            reading.set("snap", snap, file=path, key=entry.key, raw=entry.raw)
    _read_filter(shadow.member("Filter") or Entry(None, file=path, key=f"{shadow.key}.Filter"), reading)
    depth = _members(shadow.member("DepthRange"), "the DepthRange members") or Entry(
        Located(), file=path, key=f"{shadow.key}.DepthRange", line=shadow.line)
    automatic = depth.member("IsAutomatic")
    automatic = True if automatic is None else automatic.boolean()
    near = DEFAULT_NEAR if automatic else _near(components, reading)
    _read_depth_range(depth, reading, automatic=automatic, near=near)
    _read_partition(shadow.member("PartitionMode"), depth, reading, cascades=cascades, automatic=automatic, near=near)
    bias = _members(shadow.member("BiasParameters"), "the BiasParameters members")
    if bias is not None and (entry := bias.member("DepthBias")) is not None:
        reading.set("bias_depth_range", entry.number(minimum=0.0), file=path, key=entry.key, raw=entry.raw)
    if bias is not None and (entry := bias.member("NormalOffsetScale")) is not None:
        scale = entry.number(minimum=0.0)
        reading.set("normal_offset_m", 2.0 * scale / ATLAS_SIZE, file=path, key=entry.key, raw=entry.raw)
    for member, why in (("ComputeTransmittance", "transmittance through thin objects (hair, skin)"),
                        ("Debug", "cascade debug colours")):
        if (entry := shadow.member(member)) is not None and entry.boolean():
            reading.lack(file=path, key=entry.key, value=True, why=why)
    return reading.result()


def _read_filter(value: Entry, reading: Reading) -> None:
    path, key = value.file, value.key
    if value.raw is None:
        reading.set("filter", "pcf_bilinear", file=path, key=key, raw="null (ShadowMapFilterDefault)")
        return
    if value.tag != PCF:
        raise InputError(f"expected !{PCF} or no filter, got {_shown(value)}", file=path, field=key, line=value.line)
    size = value.member("FilterSize")
    reading.set("filter", "pcf_castano", file=path, key=key, raw=f"!{PCF}")
    if size is not None and size.raw == "Filter7x7":
        reading.lack(file=path, key=size.key, value=size.raw,
                     why="csmlab's pcf_castano has the 3×3 and 5×5 kernels; the preset's size is kept")
        return
    size_key = f"{key}.FilterSize"
    reading.set("filter_size", PCF_SIZES["Filter3x3"] if size is None else size.choice(PCF_SIZES), file=path,
                key=size_key, raw="Filter3x3" if size is None else size.raw)


def _read_depth_range(depth: Entry, reading: Reading, *, automatic: bool, near: float) -> None:
    path, where = depth.file, depth.key
    if depth.member("IsAutomatic") is not None:
        reading.set("bounds", "sdsm" if automatic else "frustum", file=path, key=f"{where}.IsAutomatic", raw=automatic)
        # Automatic: the farthest visible object ends the range, uncapped; manual: near + ManualMaxDistance.
        reading.set("shadow_distance_from", "farthest_visible" if automatic else "fixed", file=path,
                    key=f"{where}.IsAutomatic", raw=automatic)
        if automatic:
            reading.set("hold", "stepped", file=path, key=f"{where}.IsAutomatic", raw=automatic)
    if not automatic:
        farthest = _manual_max(depth)
        reading.set("shadow_distance", near + farthest, file=path, key=f"{where}.ManualMaxDistance",
                    raw=f"{farthest} (+ near plane {near:g})")
    lowest = depth.member("ManualMinDistance")
    lowest = 0.0 if lowest is None else lowest.number(minimum=0.0)
    if lowest and not automatic:
        reading.lack(file=path, key=f"{where}.ManualMinDistance", value=lowest,
                     why="csmlab's cascades start at the camera's near plane")
    if (entry := depth.member("IsBlendingCascades")) is not None:
        blending = entry.boolean()
        reading.set("blend_band", BLEND_BAND if blending else 0.0, file=path, key=entry.key, raw=blending)


def _manual_max(depth: Entry) -> float:
    """DepthRange.ManualMaxDistance in metres (Stride's 50 when the file leaves it out)."""
    farthest = depth.member("ManualMaxDistance")
    return 50.0 if farthest is None else farthest.number(above=0.0)


def _read_partition(partition: Entry | None, depth: Entry, reading: Reading, *, cascades: int, automatic: bool,
                    near: float) -> None:
    if partition is None or partition.raw is None:
        return
    path, key = partition.file, partition.key
    if partition.tag not in (LOGARITHMIC, MANUAL):
        raise InputError(f"expected !{LOGARITHMIC} or !{MANUAL}, got {_shown(partition)}", file=path, field=key,
                         line=partition.line)
    if partition.tag == LOGARITHMIC:
        reading.set("split", "practical", file=path, key=key, raw=f"!{LOGARITHMIC}")
        if (entry := partition.member("PSSMFactor")) is not None:
            factor = entry.number(minimum=0.0)
            reading.set("lambda_", 1.0 - min(factor, 1.0), file=path, key=entry.key, raw=entry.raw)
        return
    members = MANUAL_SPLITS[cascades]
    ends = [MANUAL_DEFAULTS[m] if partition.member(m) is None else partition.member(m).number(above=0.0)
            for m in members]
    if any(b <= a for a, b in zip(ends, ends[1:])):
        raise InputError(f"expected increasing {', '.join(members)}, got {ends}", file=path, field=key,
                         line=partition.line)
    shown = ", ".join(f"{m} = {e:g}" for m, e in zip(members, ends))
    reading.set("split", "manual_range", file=path, key=key, raw=f"!{MANUAL}")
    reading.set("splits", tuple(e / ends[-1] for e in ends), file=path, key=key, raw=shown)
    if not automatic:
        # Cascade i ends at min + s_i · max with min = near, max = near + ManualMaxDistance.
        farthest = _manual_max(depth)
        reading.set("shadow_distance", near + ends[-1] * (near + farthest), file=path, key=key,
                    raw=f"near plane {near:g} + {ends[-1]:g} · (near plane + ManualMaxDistance {farthest:g})")
    else:
        reading.lack(file=path, key=key, value=shown,
                     why="Stride ends cascade i at min + s_i · max of the held visible range, csmlab's manual_range "
                         "at min + s_i · (max − min)")


def _float(value: float) -> str:
    """A float as Stride's YAML writes one (a decimal point always)."""
    text = repr(float(value))
    return text if any(c in text for c in ".en") else text + ".0"


def _id(*names: str) -> uuid.UUID:
    """A fixed identifier per object, so that the same setting writes the same file."""
    return uuid.uuid5(uuid.NAMESPACE_URL, "csmlab/stride/" + "/".join(names))


def write_stride(settings: ShadowSettings, *, near: float, far: float) -> tuple[dict, list]:
    """``settings`` as a ``.sdscene`` with a camera (``near``, ``far``) and a directional light, and the knobs it
    cannot hold."""
    lacking = []
    cascades = settings.cascades if settings.cascades in MANUAL_SPLITS else (2 if settings.cascades < 4 else 4)
    if cascades != settings.cascades:
        lacking.append(f"cascades = {settings.cascades} (Stride has 1, 2 or 4 cascades; {cascades} written)")
    wanted = largest_resolution(settings)
    size = max((n for n, side in SIZES.items() if side <= wanted), key=SIZES.get, default="XSmall")
    if SIZES[size] != wanted:
        lacking.append(f"resolution = {wanted} (Stride's Size gives 128 · 2^k up to 2048; {size}, {SIZES[size]}, "
                       f"written)")
    shadow = ["Enabled: true"]
    if settings.filter == "pcf_castano" and settings.filter_size in PCF_SIZES.values():
        shadow += [f"Filter: !{PCF}", f"    FilterSize: Filter{settings.filter_size}x{settings.filter_size}"]
    elif FILTER_METHODS[settings.filter].hard:
        lacking.append(f"filter = {settings.filter!r} (Stride's least filter is one bilinear comparison, "
                       f"pcf_bilinear: no Filter written)")
    elif settings.filter != "pcf_bilinear":
        written = 3 if settings.filter_size <= 3 else 5
        lacking.append(f"filter = {settings.filter!r}, filter_size = {settings.filter_size} (Stride filters with one "
                       f"bilinear comparison or PCF: Castaño's kernels of bilinear taps, pcf_castano; "
                       f"Filter{written}x{written} written)")
        shadow += [f"Filter: !{PCF}", f"    FilterSize: Filter{written}x{written}"]
    shadow.append(f"Size: {size}")
    if cascades != 4:
        shadow.append(f"CascadeCount: {next(n for n, c in CASCADE_COUNTS.items() if c == cascades)}")
    if settings.stabilization == "none":
        shadow.append("StabilizationMode: None")
    elif settings.stabilization == "exact" and settings.snap == "view":
        shadow.append("StabilizationMode: ViewSnapping")
    else:
        if settings.stabilization != "exact":
            lacking.append(f"stabilization = {settings.stabilization!r} (Stride snaps exactly or not at all; "
                           f"ProjectionSnapping written)")
        elif settings.snap != "centre_nearest":
            lacking.append(f"snap = {settings.snap!r} (Stride's ProjectionSnapping puts the box centre on the nearest "
                           f"texel: centre_nearest)")
    shadow += _depth_and_partition(settings.replace(cascades=cascades), lacking, near=near, far=far)
    shadow.append("ComputeTransmittance: false")
    bias = []
    if settings.bias_depth_range != 0.01:
        bias.append(f"    DepthBias: {_float(settings.bias_depth_range)}")
    if settings.normal_offset_m * ATLAS_SIZE / 2.0 != 10.0:
        bias.append(f"    NormalOffsetScale: {_float(settings.normal_offset_m * ATLAS_SIZE / 2.0)}")
    shadow += ["BiasParameters:", *bias] if bias else ["BiasParameters: {}"]
    return {"MainScene.sdscene": _scene_text(shadow, near=near, far=far)}, lacking


def _depth_and_partition(settings: ShadowSettings, lacking: list, *, near: float, far: float) -> list[str]:
    """The ``DepthRange`` and ``PartitionMode`` lines of ``settings`` (its cascade count one Stride has)."""
    depth = []
    automatic = settings.bounds == "sdsm"
    if automatic and settings.hold != "stepped":
        lacking.append(f"hold = {settings.hold!r} (Stride holds the visible range in steps: 'stepped')")
    if automatic and settings.shadow_distance_from != "farthest_visible":
        lacking.append(f"shadow_distance_from = {settings.shadow_distance_from!r}, shadow_distance = "
                       f"{settings.shadow_distance} (Stride's automatic depth range ends at the farthest visible "
                       f"object: no distance is written)")
    if not automatic:
        end = shadow_end(method=settings.shadow_distance_from, shadow_distance=settings.shadow_distance,
                         max_shadow_distance=settings.max_shadow_distance, camera_far=far)
        if settings.shadow_distance_from != "fixed":
            lacking.append(f"shadow_distance_from = {settings.shadow_distance_from!r} (Stride's manual depth range "
                           f"is fixed: the end under this camera, {end:g} m, written)")
        elif settings.shadow_distance > far:
            lacking.append(f"shadow_distance = {settings.shadow_distance} (beyond the camera's far plane, {far:g} m, "
                           f"written)")
        depth += ["IsAutomatic: false", f"ManualMaxDistance: {_float(end - near)}"]
    if settings.blend_band == 0.0:
        depth.append("IsBlendingCascades: false")
    elif settings.blend_band != BLEND_BAND:
        lacking.append(f"blend_band = {settings.blend_band} (Stride's blend band is {BLEND_BAND} of the previous "
                       f"cascade)")
    lines = ["DepthRange:", *(f"    {line}" for line in depth)] if depth else ["DepthRange: {}"]
    if settings.split == "practical":
        factor = 1.0 - settings.lambda_
        return lines + ([f"PartitionMode: !{LOGARITHMIC} {{}}"] if factor == 0.5 else
                        [f"PartitionMode: !{LOGARITHMIC}", f"    PSSMFactor: {_float(factor)}"])
    if settings.split in ("log", "uniform"):
        return lines + [f"PartitionMode: !{LOGARITHMIC}",
                        f"    PSSMFactor: {_float(0.0 if settings.split == 'log' else 1.0)}"]
    if automatic:
        lacking.append(f"split = {settings.split!r} over the visible range (Stride's manual splits end at min + s · "
                       f"max of it; written as fractions of the range)")
    z = split_boundaries(settings, near=near, far=far)
    # Stride ends cascade i at near + s_i · (near + ManualMaxDistance), ManualMaxDistance = z_C − near above.
    scale = (z[-1] - near) / z[-1] if not automatic else 1.0
    fractions = [(v - z[0]) / (z[-1] - z[0]) * scale for v in z[1:]]
    members = MANUAL_SPLITS[settings.cascades]
    return lines + [f"PartitionMode: !{MANUAL}",
                    *(f"    {m}: {_float(f)}" for m, f in zip(members, fractions))]


def _scene_text(shadow: list[str], *, near: float, far: float) -> str:
    """A Stride scene asset of a camera and a directional light whose ``Shadow`` holds ``shadow`` (lines)."""
    camera, light = _id("Camera"), _id("Directional light")
    pad = " " * 16
    camera_planes = ([f"{pad}        NearClipPlane: {_float(near)}"] if near != DEFAULT_NEAR else []) + \
        ([f"{pad}        FarClipPlane: {_float(far)}"] if far != DEFAULT_FAR else [])
    lines = [
        "!SceneAsset",
        f"Id: {_id('scene')}",
        "SerializedVersion: {Stride: 3.1.0.1}",
        "Tags: []",
        "ChildrenIds: []",
        "Offset: {X: 0.0, Y: 0.0, Z: 0.0}",
        "Hierarchy:",
        "    RootParts:",
        f"        - ref!! {camera}",
        f"        - ref!! {light}",
        "    Parts:",
        "        -   Entity:",
        f"{pad}Id: {camera}",
        f"{pad}Name: Camera",
        f"{pad}Components:",
        f"{pad}    {_id('Camera', 'transform').hex}: !TransformComponent",
        f"{pad}        Id: {_id('Camera', 'transform id')}",
        f"{pad}        Position: {{X: 0.0, Y: 1.7, Z: 0.0}}",
        f"{pad}        Rotation: {{X: 0.0, Y: 0.0, Z: 0.0, W: 1.0}}",
        f"{pad}        Scale: {{X: 1.0, Y: 1.0, Z: 1.0}}",
        f"{pad}        Children: {{}}",
        f"{pad}    {_id('Camera', 'camera').hex}: !CameraComponent",
        f"{pad}        Id: {_id('Camera', 'camera id')}",
        f"{pad}        Name: null",
        f"{pad}        Projection: Perspective",
        *camera_planes,
        f"{pad}        Slot: {_id('Camera', 'slot')}",
        "        -   Entity:",
        f"{pad}Id: {light}",
        f"{pad}Name: Directional light",
        f"{pad}Components:",
        f"{pad}    {_id('Directional light', 'transform').hex}: !TransformComponent",
        f"{pad}        Id: {_id('Directional light', 'transform id')}",
        f"{pad}        Position: {{X: 0.0, Y: 2.0, Z: 0.0}}",
        f"{pad}        Rotation: {{X: -0.5, Y: 0.0, Z: 0.0, W: 0.8660254}}",
        f"{pad}        Scale: {{X: 1.0, Y: 1.0, Z: 1.0}}",
        f"{pad}        Children: {{}}",
        f"{pad}    {_id('Directional light', 'light').hex}: !LightComponent",
        f"{pad}        Id: {_id('Directional light', 'light id')}",
        f"{pad}        Type: !LightDirectional",
        f"{pad}            Color: !ColorRgbProvider",
        f"{pad}                Value: {{R: 1.0, G: 1.0, B: 1.0}}",
        f"{pad}            Shadow:",
        *(f"{pad}                {line}" for line in shadow),
        f"{pad}        Intensity: 20.0",
    ]
    return "\n".join(lines) + "\n"


def export_stride(settings: ShadowSettings, *, near: float, far: float) -> Snippet:
    """Stride: the directional light's ``LightDirectionalShadowMap`` in a scene asset (``.sdscene``)."""
    # Stride has its own automatic depth range (bounds = sdsm), None / ProjectionSnapping / ViewSnapping and
    # a DepthBias and NormalOffsetScale that csmlab.engines.stride maps: write_stride names what differs.
    lacking = [item for item in common_lacking(settings, stable="exact")
               if not item.startswith(("stabilization", "bounds", "bias_constant"))]
    text, more = one_file(write_stride, settings, near=near, far=far)
    return Snippet("stride", "Stride: the directional light's shadow map in the scene (.sdscene)", "sdscene", text,
                   tuple(lacking + more))


TUNE_SPACE = TuneSpace({
    # LightDirectionalShadowMap: CascadeCount, Size (128 · 2^k), PCF FilterSize 3×3 or 5×5, StabilizationMode
    # None or ProjectionSnapping, IsBlendingCascades, PartitionLogarithmic's PSSMFactor (λ = 1 − factor),
    # BiasParameters DepthBias and NormalOffsetScale (metres: normal_offset_m). The depth range stays automatic.
    "cascades": ("choice", tuple(CASCADE_COUNTS.values())),
    "resolution": ("choice", tuple(SIZES.values())),
    "filter_size": ("choice", tuple(PCF_SIZES.values())),
    "stabilization": ("choice", ("none", "exact")),
    "blend_band": ("choice", (0.0, BLEND_BAND)),
    "lambda": ("range", 0.0, 1.0, False, None),
    "bias_depth_range": ("range", 0.0, 0.1, False, None),
    "normal_offset_m": ("range", 0.0, 0.05, False, None),
})
"""What a tune of the Stride preset may try: the directional light's shadow map settings."""

ENGINE = Engine("stride", export_stride, EngineFiles(
    read=read_stride, write=write_stride, fields=FIELDS, preset=fixed_preset(PRESET), presets=(PRESET,),
    files="a .sdscene with a LightComponent of Type !LightDirectional"), tune=TUNE_SPACE)
"""What the registries of csmlab.engines take from this module."""
