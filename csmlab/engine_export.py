"""Shadow settings as engine configuration: snippets to paste, and the knobs each engine lacks.

Each exporter turns a :class:`~csmlab.settings.ShadowSettings` into the settings of one engine —
cascade count, per-cascade resolution, shadow distance, split distances, blending and filter — and
names every csmlab knob the engine has no setting for, so that nobody believes a snippet reproduces
more than it does. Exporters are registered by engine in :data:`EXPORT_METHODS`; :func:`export`
dispatches on ``engine=``.

Split distances are exported as the engine spells them: fractions of the shadow distance (Unity URP,
Godot, three.js ``custom`` mode), metres (Bevy ``CascadeShadowConfig``), or — for Unreal, whose only
split control is a distribution exponent — the exponent whose splits come closest, with the error.

Sources of the engine names
---------------------------
- UE5: console variables ``r.Shadow.CSM.MaxCascades``, ``r.Shadow.MaxCSMResolution``; directional
  light properties ``DynamicShadowCascades``, ``DynamicShadowDistanceMovableLight`` (cm),
  ``CascadeDistributionExponent`` (split i at the geometric sum of exponent powers, ``ComputeAccumulatedScale``
  in the renderer), ``CascadeTransitionFraction``, ``ShadowDistanceFadeoutFraction``.
- Unity URP: ``UniversalRenderPipelineAsset.shadowDistance``, ``shadowCascadeCount``, ``cascade2Split``,
  ``cascade3Split``, ``cascade4Split`` (fractions of the shadow distance), ``mainLightShadowmapResolution``
  (the atlas: one cascade takes all of it, two to four a quarter tile each).
- Godot 4: ``DirectionalLight3D.directional_shadow_mode`` (orthogonal, 2 or 4 splits),
  ``directional_shadow_max_distance``, ``directional_shadow_split_1..3``, ``directional_shadow_blend_splits``;
  project setting ``rendering/lights_and_shadows/directional_shadow/size`` (the atlas).
- Bevy: ``CascadeShadowConfigBuilder { num_cascades, minimum_distance, maximum_distance,
  first_cascade_far_bound, overlap_proportion }``, ``CascadeShadowConfig { bounds, … }``,
  ``DirectionalLightShadowMap { size }``, ``ShadowFilteringMethod``.
- three.js ``CSM`` (examples/jsm/csm): ``cascades``, ``maxFar``, ``mode`` (``practical`` mixes with
  λ = 0.5), ``customSplitsCallback``, ``shadowMapSize``, ``fade``.
- Stride: a ``.sdscene``'s ``LightDirectionalShadowMap`` (``CascadeCount``, ``Size``, ``StabilizationMode``,
  ``DepthRange``, ``PartitionMode``, ``Filter``, ``BiasParameters``), csmlab.importers.stride.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from csmlab.cascades.bounds import BOUNDS_METHODS
from csmlab.cascades.splits import split_distances
from csmlab.lookup_choices import FILTER_METHODS
from csmlab.registry import dispatch
from csmlab.settings import ShadowSettings

__all__ = ["BEVY_EXACT", "BEVY_FILTERING", "EXPORT_METHODS", "GODOT_SOFT_LOW", "Snippet", "THREEJS_PCF", "UE5_FILTER",
           "URP_FILTER", "export", "hard_filter", "split_boundaries", "ue_split_fractions"]


@dataclass(frozen=True)
class Snippet:
    """One engine's configuration for a setting.

    Attributes
    ----------
    engine : str
        A key of :data:`EXPORT_METHODS`.
    title : str
        Where it goes in the engine.
    language : str
        ``ini``, ``csharp``, ``gdscript``, ``rust``, ``javascript``, ``yaml``, ``json`` or ``sdscene`` (Stride's
        asset YAML): csmlab.tune picks the file suffix by it.
    text : str
        The snippet.
    lacking : tuple of str
        csmlab knobs the engine has no setting for, each with the value this setting uses.
    files : tuple of (str, str)
        The engine's own files holding the setting, ``(file name, text)``: what ``csmlab import``
        reads back (csmlab.importers); empty for an engine without an importer.
    """

    engine: str
    title: str
    language: str
    text: str
    lacking: tuple[str, ...]
    files: tuple[tuple[str, str], ...] = ()


def split_boundaries(settings: ShadowSettings, *, near: float, far: float) -> np.ndarray:
    """Cascade boundaries ``(C + 1,)`` in metres of view depth, as the cascades are built: from the camera's
    ``near`` to ``min(shadow_distance, far)``."""
    return split_distances(near=near, far=min(settings.shadow_distance, far), count=settings.cascades,
                           method=settings.split, lambda_=settings.lambda_, splits=settings.splits,
                           distribution_exponent=settings.distribution_exponent,
                           first_cascade_far=settings.first_cascade_far)


def ue_split_fractions(exponent: float, count: int) -> np.ndarray:
    """Unreal's split fractions ``(count + 1,)`` of the shadow range: ``Σ_{k<i} e^k / Σ_{k<C} e^k``."""
    powers = float(exponent) ** np.arange(count, dtype=np.float64)
    return np.concatenate([[0.0], np.cumsum(powers) / powers.sum()])


def _shape_lacking(settings: ShadowSettings, *, transition: str | None = None, blend_curve: str = "linear",
                   fade: str | None = None) -> list[str]:
    """Where the engine's blend band or far fade has another shape than the setting's (``transition``,
    ``blend_curve``: csmlab.cascades.fit; ``fade``: csmlab.filters); None: the engine has no such knob here."""
    lacking = []
    if transition is not None and settings.blend_band > 0:
        if settings.transition != transition:
            lacking.append(f"transition = {settings.transition!r} (the engine's band is {transition!r})")
        if settings.blend_curve != blend_curve:
            lacking.append(f"blend_curve = {settings.blend_curve!r} (the engine's weight is {blend_curve!r})")
    if fade is not None and settings.fade_out > 0 and settings.fade != fade:
        lacking.append(f"fade = {settings.fade!r} (the engine's fade is {fade!r})")
    return lacking


def _common_lacking(settings: ShadowSettings, *, stable: str) -> list[str]:
    """Knobs no exporter maps: stabilization other than the engine's own, fit, selection, per-cascade
    resolution, splits over the visible depth range, depth format, bias units."""
    lacking = []
    if settings.stabilization != stable:
        lacking.append(f"stabilization = {settings.stabilization!r} (the engine always stabilizes its own way, "
                       f"closest to csmlab's {stable!r})")
    if settings.stabilization == "quantized":
        lacking.append(f"levels = {settings.levels}")
    if settings.fit != "cascade":
        lacking.append(f"fit = {settings.fit!r}")
    if settings.selection != "interval":
        lacking.append(f"selection = {settings.selection!r}")
    if settings.cascade_resolutions:
        # The engines below give every cascade one size; the largest keeps the nearest cascades as sharp.
        lacking.append(f"cascade_resolutions = {list(settings.cascade_resolutions)} (one size for every cascade: "
                       f"{max(settings.cascade_resolutions)} written)")
    if BOUNDS_METHODS[settings.bounds].visible:
        lacking.append(f"bounds = {settings.bounds!r} (splits over the visible depth range need the engine's "
                       f"depth readback)")
    if settings.depth_format != "float32":
        lacking.append(f"depth_format = {settings.depth_format!r} (set the shadow map's depth format in the engine)")
    lacking.append(f"bias_constant = {settings.bias_constant}, bias_slope = {settings.bias_slope}, normal_offset = "
                   f"{settings.normal_offset} (engine bias units differ: tune by eye)")
    return lacking


def _fractions(settings: ShadowSettings, near: float, far: float) -> list[float]:
    z = split_boundaries(settings, near=near, far=far)
    return [float(v / z[-1]) for v in z[1:-1]]


def _size(settings: ShadowSettings) -> int:
    """Texels per side each engine gets: the largest cascade's (engines give every cascade one size)."""
    return max(settings.cascade_resolutions or (settings.resolution,))


def _g(value: float) -> str:
    return f"{value:.4g}"


def hard_filter(settings: ShadowSettings) -> bool:
    """The filter is one depth test (its record's ``hard``) or one hardware 2×2 comparison (``pcf_bilinear``):
    what engines call no soft shadows (URP's soft shadows off, Godot's Hard, both a linear comparison sampler)."""
    return FILTER_METHODS[settings.filter].hard or settings.filter == "pcf_bilinear"


def _vogel_is(settings: ShadowSettings, **fields) -> bool:
    """``settings`` run ``pcf_vogel`` rotated per pixel with ``fields`` (an engine's disk)."""
    return settings.filter == "pcf_vogel" and settings.poisson_rotation in ("pixel", "pixel_taa") and all(
        getattr(settings, name) == value for name, value in fields.items())


GODOT_SOFT_LOW = {"vogel_taps": 4, "vogel_radius": 2.0, "vogel_angle": 2.4, "vogel_scale": "first_split"}
"""Godot 4's Soft Low (soft_shadow_filter_quality = 2) as csmlab's ``pcf_vogel`` fields (configs/engines/godot4.toml)."""

THREEJS_PCF = {"vogel_taps": 5, "vogel_angle": 2.399963229728653, "vogel_scale": "none"}
"""three.js r182+ PCFShadowMap as csmlab's ``pcf_vogel`` fields, its radius LightShadow.radius (configs/engines/threejs_csm.toml)."""


UE5_FILTER = ("pcf", 3)
"""The csmlab filter and size Unreal's shadow filtering matches (r.Shadow.FilterMethod=0); others are lacking."""

URP_FILTER = ("pcf_tent_bilinear", 5)
"""The filter and size of URP's soft shadows at the asset's Medium quality (SampleShadow_ComputeSamples_Tent_5x5);
another soft filter is lacking (soft shadows off: pcf_bilinear)."""


def export_ue5(settings: ShadowSettings, *, near: float, far: float) -> Snippet:
    """UE5: cvars for an ini file, directional light properties as comments (distances in cm)."""
    z = split_boundaries(settings, near=near, far=far)
    wanted = (z - z[0]) / (z[-1] - z[0])
    exponents = np.arange(1.0, 10.0001, 0.01)
    errors = [np.abs(ue_split_fractions(e, settings.cascades) - wanted).max() for e in exponents]
    best = int(np.argmin(errors))
    error_m = errors[best] * (z[-1] - z[0])
    lacking = _common_lacking(settings, stable="exact") + _shape_lacking(settings, transition="forward", fade="linear")
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
        f"r.Shadow.MaxCSMResolution={_size(settings)}",
        "r.Shadow.FilterMethod=0",
        "",
        "; DirectionalLight > Cascaded Shadow Maps",
        f";   DynamicShadowCascades={settings.cascades}",
        f";   DynamicShadowDistanceMovableLight={z[-1] * 100.0:.0f}    ; cm",
        f";   CascadeDistributionExponent={exponents[best]:.2f}",
        f";   CascadeTransitionFraction={_g(settings.blend_band)}",
        f";   ShadowDistanceFadeoutFraction={_g(settings.fade_out)}",
    ])
    return Snippet("ue5", "Unreal Engine 5: console variables and directional light", "ini", text + "\n",
                   tuple(lacking))


def export_unity_urp(settings: ShadowSettings, *, near: float, far: float) -> Snippet:
    """Unity URP: the pipeline asset's shadow fields, set from a script."""
    lacking = _common_lacking(settings, stable="exact") + _shape_lacking(settings, fade="squared_radial")
    cascades = min(settings.cascades, 4)
    if settings.cascades > 4:
        lacking.append(f"cascades = {settings.cascades} (URP has at most 4)")
    wanted = _size(settings) * (1 if cascades == 1 else 2)
    # The asset's resolution is one of 256 … 8192 (powers of two): the largest that is not bigger.
    atlas = 1 << max(8, min(13, wanted.bit_length() - 1))
    if atlas != wanted:
        lacking.append(f"resolution = {_size(settings)} per cascade (URP's atlas is a power of two in 256..8192: "
                       f"{atlas} written for {wanted})")
    if settings.blend_band > 0:
        lacking.append(f"blend_band = {settings.blend_band} (URP blends no cascades; cascadeBorder fades the last)")
    if not hard_filter(settings) and (settings.filter, settings.filter_size) != URP_FILTER:
        lacking.append(f"filter = {settings.filter!r}, filter_size = {settings.filter_size} (URP's soft shadows are "
                       f"fixed tents of bilinear taps: Medium {URP_FILTER[0]} {URP_FILTER[1]})")
    fractions = _fractions(settings.replace(cascades=cascades), near, far)
    lines = ["// UniversalRenderPipelineAsset asset = …;",
             f"asset.shadowDistance = {_g(min(settings.shadow_distance, far))}f;",
             f"asset.shadowCascadeCount = {cascades};"]
    if cascades == 2:
        lines.append(f"asset.cascade2Split = {_g(fractions[0])}f;")
    elif cascades == 3:
        lines.append(f"asset.cascade3Split = new Vector2({', '.join(_g(f) + 'f' for f in fractions)});")
    elif cascades == 4:
        lines.append(f"asset.cascade4Split = new Vector3({', '.join(_g(f) + 'f' for f in fractions)});")
    lines += [f"asset.mainLightShadowmapResolution = {atlas};  // atlas: {atlas // (1 if cascades == 1 else 2)}² "
              f"per cascade",
              f"asset.supportsSoftShadows = {'false' if hard_filter(settings) else 'true'};"]
    return Snippet("unity_urp", "Unity URP: UniversalRenderPipelineAsset", "csharp", "\n".join(lines) + "\n",
                   tuple(lacking))


def export_godot4(settings: ShadowSettings, *, near: float, far: float) -> Snippet:
    """Godot 4: DirectionalLight3D properties and the directional shadow atlas size."""
    lacking = _common_lacking(settings, stable="exact") + _shape_lacking(settings, fade="smoothstep")
    modes = {1: 0, 2: 1, 4: 2}
    cascades = settings.cascades if settings.cascades in modes else (2 if settings.cascades < 4 else 4)
    if cascades != settings.cascades:
        lacking.append(f"cascades = {settings.cascades} (Godot has 1, 2 or 4 splits; {cascades} written)")
    # Godot places each split at min_distance + split · (max_distance - min_distance) from the camera's near
    # plane (RendererSceneCull::_light_instance_setup_directional_shadow): fractions of the range, not of far.
    z = split_boundaries(settings.replace(cascades=cascades), near=near, far=far)
    fractions = [float((v - z[0]) / (z[-1] - z[0])) for v in z[1:-1]]
    atlas = _size(settings) * (1 if cascades == 1 else 2)
    lines = ["# DirectionalLight3D",
             f"directional_shadow_mode = {modes[cascades]}",
             f"directional_shadow_max_distance = {_g(min(settings.shadow_distance, far))}"]
    lines += [f"directional_shadow_split_{i + 1} = {_g(f)}" for i, f in enumerate(fractions)]
    lines += [f"directional_shadow_blend_splits = {'true' if settings.blend_band > 0 else 'false'}",
              "# Project Settings",
              f"rendering/lights_and_shadows/directional_shadow/size = {atlas}  "
              f"# {_size(settings)}² per split (2 splits: half the atlas each)",
              "rendering/lights_and_shadows/directional_shadow/soft_shadow_filter_quality = "
              f"{0 if hard_filter(settings) else 2}  # 2: Soft Low, 4 Vogel taps of 2 texels"]
    if settings.blend_band > 0:
        lacking.append(f"blend_band = {settings.blend_band} (Godot blends splits over a fixed band)")
    if not hard_filter(settings) and not _vogel_is(settings, **GODOT_SOFT_LOW):
        lacking.append(f"filter = {settings.filter!r}, filter_size = {settings.filter_size} (Godot filters with its "
                       f"own soft-shadow kernel: Soft Low is pcf_vogel {GODOT_SOFT_LOW})")
    return Snippet("godot4", "Godot 4: DirectionalLight3D and project settings", "gdscript", "\n".join(lines) + "\n",
                   tuple(lacking))


BEVY_FILTERING: dict[str, str] = {"pcf_bilinear": "Hardware2x2", "pcf": "Gaussian", "pcf_gaussian": "Gaussian",
                                  "pcf_tent": "Gaussian", "pcf_castano": "Gaussian", "pcf_tent_bilinear": "Gaussian",
                                  "pcf_bilinear_box": "Gaussian"}
"""Bevy's nearest ``ShadowFilteringMethod`` by csmlab filter (a key of csmlab.lookup_choices.FILTER_METHODS).

Bevy's Gaussian is Castaño's 5×5 of 9 bilinear taps, ``sample_shadow_map_castano_thirteen``
(csmlab's ``pcf_castano`` 5, configs/engines/bevy.toml); a filter not here gets no method.
"""

BEVY_EXACT: dict[str, int | None] = {"pcf_bilinear": None, "pcf_castano": 5}
"""The filters Bevy runs as csmlab does, with the filter_size that matches (None: any); the others are lacking."""


def export_bevy(settings: ShadowSettings, *, near: float, far: float) -> Snippet:
    """Bevy: the CascadeShadowConfigBuilder, and the exact bounds as a CascadeShadowConfig."""
    z = split_boundaries(settings, near=near, far=far)
    lacking = _common_lacking(settings, stable="exact") + _shape_lacking(settings, transition="far_bound")
    filtering = BEVY_FILTERING.get(settings.filter)
    if settings.filter not in BEVY_EXACT or BEVY_EXACT[settings.filter] not in (None, settings.filter_size):
        lacking.append(f"filter = {settings.filter!r}, filter_size = {settings.filter_size} (Bevy filters with "
                       f"Hardware2x2, Gaussian or Temporal)")
    bounds = ", ".join(f"{v:.3f}" for v in z[1:])
    lines = ["// The builder spaces the cascades after the first geometrically:",
             "let config: CascadeShadowConfig = CascadeShadowConfigBuilder {",
             f"    num_cascades: {settings.cascades},",
             f"    minimum_distance: {z[0]:.3f},",
             f"    maximum_distance: {z[-1]:.3f},",
             f"    first_cascade_far_bound: {z[1]:.3f},",
             f"    overlap_proportion: {settings.blend_band:.3f},",
             "}.build();",
             "// csmlab's bounds exactly:",
             f"let config = CascadeShadowConfig {{ bounds: vec![{bounds}], overlap_proportion: "
             f"{settings.blend_band:.3f}, minimum_distance: {z[0]:.3f} }};",
             f"app.insert_resource(DirectionalLightShadowMap {{ size: {_size(settings)} }});"]
    if filtering:
        lines.append(f"// on the camera: ShadowFilteringMethod::{filtering}")
    return Snippet("bevy", "Bevy: CascadeShadowConfig and DirectionalLightShadowMap", "rust", "\n".join(lines) + "\n",
                   tuple(lacking))


def export_threejs_csm(settings: ShadowSettings, *, near: float, far: float) -> Snippet:
    """three.js CSM (examples/jsm/csm/CSM.js) options."""
    lacking = _common_lacking(settings, stable="exact")
    modes = {"uniform": "uniform", "log": "logarithmic"}
    mode = modes.get(settings.split, "practical" if settings.split == "practical" and settings.lambda_ == 0.5
                     else "custom")
    lines = ["const csm = new CSM({",
             f"  maxFar: {_g(min(settings.shadow_distance, far))},",
             f"  cascades: {settings.cascades},",
             f"  mode: '{mode}',"]
    if mode == "custom":
        fractions = ", ".join(_g(f) for f in _fractions(settings, near, far))
        lines.append(f"  customSplitsCallback: (cascades, near, far, breaks) => breaks.push({fractions}, 1),")
    lines += [f"  shadowMapSize: {_size(settings)},", "  camera, parent: scene, lightDirection,", "});"]
    if _vogel_is(settings, **THREEJS_PCF) and settings.vogel_radius != 1.0:
        lines.append(f"csm.lights.forEach((light) => {{ light.shadow.radius = {_g(settings.vogel_radius)}; }});")
    lines += [
              f"csm.fade = {'true' if settings.blend_band > 0 else 'false'};",
              "renderer.shadowMap.type = THREE." + ("BasicShadowMap" if FILTER_METHODS[settings.filter].hard
                                                    else "PCFShadowMap") + ";"]
    if settings.blend_band > 0:
        lacking.append(f"blend_band = {settings.blend_band} (CSM's fade has a fixed width)")
    if settings.filter != "none" and not _vogel_is(settings, **THREEJS_PCF):
        lacking.append(f"filter = {settings.filter!r}, filter_size = {settings.filter_size} (three.js picks its PCF "
                       f"kernel from shadowMap.type: PCFShadowMap is pcf_vogel {THREEJS_PCF}, radius = shadow.radius)")
    return Snippet("threejs_csm", "three.js: CSM options", "javascript", "\n".join(lines) + "\n", tuple(lacking))


def export_unity_builtin(settings: ShadowSettings, *, near: float, far: float) -> Snippet:
    """Unity's built-in pipeline: a quality level of ``ProjectSettings/QualitySettings.asset``."""
    from csmlab.importers.unity_builtin import write_unity_builtin

    lacking = _common_lacking(settings, stable="exact") + _shape_lacking(settings, fade="radial")
    if settings.blend_band > 0:
        lacking.append(f"blend_band = {settings.blend_band} (the built-in pipeline blends no cascades)")
    files, _ = write_unity_builtin(settings, near=near, far=far)
    (text,) = files.values()
    return Snippet("unity_builtin", "Unity built-in pipeline: ProjectSettings/QualitySettings.asset", "yaml", text,
                   tuple(lacking))


def export_filament(settings: ShadowSettings, *, near: float, far: float) -> Snippet:
    """Filament: the sun's ``LightManager::ShadowOptions`` in the viewer's settings JSON."""
    from csmlab.importers.filament import write_filament

    lacking = _common_lacking(settings, stable="none")
    lacking = [item for item in lacking if not item.startswith(("stabilization", "bias_constant"))]
    if settings.stabilization not in ("none", "exact"):
        lacking.append(f"stabilization = {settings.stabilization!r} (Filament's stable is on or off)")
    if settings.blend_band > 0:
        lacking.append(f"blend_band = {settings.blend_band} (Filament blends no cascades)")
    files, _ = write_filament(settings, near=near, far=far)
    (text,) = files.values()
    return Snippet("filament", "Filament: the viewer's settings JSON (LightManager::ShadowOptions)", "json", text,
                   tuple(lacking))


def export_stride(settings: ShadowSettings, *, near: float, far: float) -> Snippet:
    """Stride: the directional light's ``LightDirectionalShadowMap`` in a scene asset (``.sdscene``)."""
    from csmlab.importers.stride import write_stride

    # Stride has its own automatic depth range (bounds = sdsm), None / ProjectionSnapping / ViewSnapping and
    # a DepthBias and NormalOffsetScale that csmlab.importers.stride maps: write_stride names what differs.
    lacking = [item for item in _common_lacking(settings, stable="exact")
               if not item.startswith(("stabilization", "bounds", "bias_constant"))]
    files, more = write_stride(settings, near=near, far=far)
    (text,) = files.values()
    return Snippet("stride", "Stride: the directional light's shadow map in the scene (.sdscene)", "sdscene", text,
                   tuple(lacking + more))


EXPORT_METHODS: dict[str, Callable[..., Snippet]] = {
    "ue5": export_ue5,
    "unity_urp": export_unity_urp,
    "unity_builtin": export_unity_builtin,
    "godot4": export_godot4,
    "bevy": export_bevy,
    "threejs_csm": export_threejs_csm,
    "filament": export_filament,
    "stride": export_stride,
}
"""Exporters by engine name (the names of their presets in ``configs/engines``)."""


def export(settings: ShadowSettings, *, near: float, far: float, engine: str) -> Snippet:
    """``settings`` as ``engine``'s configuration.

    Parameters
    ----------
    settings : ShadowSettings
    near, far : float
        The camera's near and far planes, metres (splits start at ``near`` and end at
        ``min(shadow_distance, far)``).
    engine : str
        A key of :data:`EXPORT_METHODS`.

    An engine with an importer (csmlab.importers.IMPORT_METHODS) also gets its own files, and every
    knob they cannot hold is added to ``lacking``.

    Raises
    ------
    ValueError
        For an unknown engine (the known ones listed).
    """
    from csmlab.importers import IMPORT_METHODS, engine_files

    snippet = dispatch(EXPORT_METHODS, engine, settings, field="engine", near=near, far=far)
    if engine not in IMPORT_METHODS:
        return snippet
    files, more = engine_files(settings, near=near, far=far, engine=engine)
    named = " ".join(snippet.lacking)
    extra = tuple(item for item in more if f"{item.split(' =', 1)[0]} =" not in named)
    return replace(snippet, lacking=snippet.lacking + extra, files=tuple(files.items()))
