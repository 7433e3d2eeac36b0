"""The shadow settings of one method: every knob of docs/design.md's ``[shadow]`` section.

A plain record shared by the host cascades and the Warp shadow lookup. :mod:`csmlab.config` builds it
from TOML and validates it at the edge; :meth:`ShadowSettings.validated` repeats the range
checks so that a settings object made in Python is held to the same contract.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, fields, replace

from csmlab.culling import BLEND_CASTER_RULES, CULL_METHODS
from csmlab.lookup_choices import CASTANO_SIZES, FILTER_METHODS, NORMAL_OFFSET_SCALES, ROTATIONS
from csmlab.registry import check_name, parameters
from csmlab.shadow_policies import SUN_POLICIES, ZOOM_POLICIES

__all__ = ["APPLIES", "CLIPMAP_FILTERS", "GROUP_OF", "SETTING_GROUPS", "SHADOW_MAP_METHODS", "Applies",
           "SettingGroup", "ShadowSettings"]

SHADOW_MAP_METHODS: dict[str, str] = {
    "cascades": "cascaded shadow maps: one stabilized box per split of the view depth (csmlab.cascades)",
    "virtual_clipmap": "Unreal 5's virtual shadow map clipmap: world-locked levels of pages, marked from the "
                       "G-buffer, rasterized when not cached (csmlab.clipmaps)",
}
"""The ``[shadow] shadow_map`` choices: what a method's depth maps are, by name."""

CLIPMAP_FILTERS = ("none", "pcf")
"""The filters a virtual clipmap's page-table lookup offers (:mod:`csmlab.kernels.pages`): one compare, or a box of
``filter_size``² compares."""

_POWERS_OF_TWO = frozenset(2**k for k in range(17))


@dataclass(frozen=True)
class ShadowSettings:
    """Cascaded-shadow-map settings of one method.

    The fields come in named groups, in the documented order (:data:`SETTING_GROUPS`, one comment line
    before each group's first field). A field whose documentation starts with where it applies
    (``pcf_poisson: …``) takes effect only there: :data:`APPLIES` holds that condition as a test over the
    settings.
    """

    # maps: cascades and the maps they are drawn in
    cascades: int = 4
    """Number of cascades C."""
    resolution: int = 1024
    """Texels per side R of each cascade's depth map."""
    cascade_resolutions: tuple[int, ...] = ()
    """Texels per side of each cascade, one per cascade; empty: resolution for every cascade."""
    shadow_map: str = "cascades"
    """What the depth maps are: cascades (one box per split, the fields below) | virtual_clipmap (Unreal 5's virtual
    shadow map clipmap: levels of pages rasterized where visible pixels need them, csmlab.clipmaps)."""
    # clipmap: the virtual clipmap's levels and pages (only with shadow_map = "virtual_clipmap")
    virtual_resolution: int = 16384
    """virtual_clipmap: virtual texels per side of every clipmap level (Unreal: 16k)."""
    page_size: int = 128
    """virtual_clipmap: texels per side of a page, the unit of marking, caching and rasterization (Unreal: 128)."""
    clipmap_first_level: int = 6
    """virtual_clipmap: the finest level n, covering a radius of 2^n cm around the camera
    (r.Shadow.Virtual.Clipmap.FirstLevel)."""
    clipmap_last_level: int = 22
    """virtual_clipmap: the coarsest level (r.Shadow.Virtual.Clipmap.LastLevel)."""
    lod_bias: float = -0.5
    """virtual_clipmap: log2 bias of the level chosen from a pixel's footprint, -1 doubles the resolution
    (r.Shadow.Virtual.ResolutionLodBiasDirectional)."""
    physical_pages: int = 2048
    """virtual_clipmap: pages of the physical pool, its memory (r.Shadow.Virtual.MaxPhysicalPages)."""
    # split: the splits of the view depth
    split: str = "practical"
    """Split scheme: uniform | log | practical | manual | manual_range | exponent | geometric."""
    lambda_: float = 0.75
    """practical: PSSM blend λ of log and uniform splits (TOML field ``lambda``)."""
    splits: tuple[float, ...] = ()
    """manual: far end of each cascade, metres, or fractions of shadow_distance when all ≤ 1; manual_range: fractions of
    the range from the near plane to shadow_distance (Godot, MJP)."""
    distribution_exponent: float = 3.0
    """split = exponent: depth ratio of consecutive cascades (Unreal's CascadeDistributionExponent)."""
    first_cascade_far: float = 10.0
    """split = geometric: far end of the first cascade in metres, the rest geometric (Bevy's
    first_cascade_far_bound)."""
    shadow_distance: float = 200.0
    """View depth in metres that the last cascade ends at (clamped to the camera's far plane), with shadow_distance_from
    = fixed."""
    shadow_distance_from: str = "fixed"
    """Where the last cascade ends: fixed (shadow_distance) | camera_far (the camera's far plane of each frame:
    three.js, Filament, MJP) | farthest_visible (the farthest visible point, bounds = sdsm: Stride); TOML also takes
    shadow_distance = "camera_far" or "farthest_visible" (csmlab.cascades.bounds.SHADOW_DISTANCE_METHODS)."""
    max_shadow_distance: float = 0.0
    """shadow_distance_from = camera_far or farthest_visible: the engine's cap in metres (three.js maxFar 100000); 0:
    none."""
    # policies: the sun and zoom policies (the light and field of view the maps are built for)
    zoom_policy: str = "camera"
    """cascades: the field of view the cascades are fitted to, camera (the camera's own) | min_fov (max(fov,
    min_fov_deg) while the camera renders at its own: Godot's directional_shadow_min_fov)
    (csmlab.shadow_policies.ZOOM_POLICIES)."""
    min_fov_deg: float = 60.0
    """zoom_policy = min_fov: the smallest vertical field of view in degrees the cascades are fitted to."""
    sun_policy: str = "every_frame"
    """The light direction the shadow maps are built with, every_frame (the true sun) | every_n (the sun of every
    sun_update_frames-th frame, held in between) | quantized (the sun's elevation and azimuth rounded to sun_step_deg);
    shading and reference keep the true sun (csmlab.shadow_policies.SUN_POLICIES)."""
    sun_update_frames: int = 4
    """sun_policy = every_n: frames between updates of the shadow's light direction."""
    sun_step_deg: float = 1.0
    """sun_policy = quantized: the angular step in degrees the sun's elevation and azimuth are rounded to."""
    # bounds: the depth range the splits divide
    bounds: str = "frustum"
    """Depth range the splits divide, frustum (near .. shadow_distance) | sdsm (the frame's visible depth range, from
    the G-buffer)."""
    hold: str = "fraction"
    """bounds = sdsm: how the visible range is held, fraction (hysteresis) | stepped (Stride: grows in 1.1^k and shrinks
    in 2^-k steps) (csmlab.cascades.bounds.HOLD_METHODS)."""
    hysteresis: float = 0.0
    """bounds = sdsm with hold = fraction: the held range grows at once and shrinks only when the visible range is this
    fraction inside it."""
    # fit: each cascade's box across the light: fit and stabilization
    fit: str = "cascade"
    """Fit: cascade (slice [z_i, z_i+1]) | cascade_lerp (its ends lerped from near to far: n + (z_i/f)(f − n), three.js)
    | scene (slice [near, z_i+1])."""
    stabilization: str = "exact"
    """none | exact | quantized | tight_snapped (the tight box padded for the filter, snapped to texels of its own size
    every frame: DirectX CSM11 fit to cascade)."""
    levels: int = 64
    """quantized: number of extent steps of the base extent."""
    quantized_base: str = "sphere"
    """quantized: base extent, sphere (slice bounding-sphere diameter) | frustum (whole frustum box)."""
    extent: str = "sphere"
    """exact, and quantized with quantized_base = sphere: the fixed box diameter, sphere (slice bounding sphere) |
    diagonal (ceil of the slice's largest diagonal, Bevy) | diagonal_unrounded (the same unrounded: three.js) | centroid
    (sphere about the corners' centroid: Godot, Stride) | body_diagonal (the body diagonal alone, unrounded: DirectX
    CSM11 fit to scene)."""
    snap: str = "origin"
    """exact: what is snapped to whole texels, origin (box corner: Valient, DirectX, Unreal) | centre (box centre
    floored, the filter margins kept inside) | centre_full (box centre, texel D/R with no filter margin inside: Bevy,
    three.js) | view (centre in 4-texel steps: Stride view snapping) | nearest2 (edges rounded to the nearest 2-texel
    unit: Godot) | centre_nearest (box centre rounded to the nearest texel: Stride projection snapping)."""
    light_basis: str = "least_aligned"
    """Light space's right and up about the light axis, where the texel grid lies: least_aligned (csmlab's: the world
    axis least aligned with the light as up) | world_y (a look-at with world +Y up: three.js, Godot, Bevy, Stride, MJP,
    DirectX) (csmlab.geometry.LIGHT_BASIS_METHODS)."""
    extent_hysteresis: float = 0.0
    """stabilization = none: the tight box's extent grows at once and shrinks only when the tight extent is this
    fraction below it (csmlab.cascades.stabilize.held_extents)."""
    focus: str = "slice"
    """stabilization = none: what a tight box covers, slice (the view slice) | scene (the slice clipped to the scene's
    light-space bounds, receivers ∩ casters: Filament's tightly bound scene) (csmlab.cascades.focus)."""
    # warp: the light-space perspective warp
    warp: str = "none"
    """Light projection, none (orthographic boxes) | lispsm (Filament's light-space perspective warp, stabilization =
    none only) (csmlab.cascades.warp)."""
    lispsm_near_hint: float = 1.0
    """warp = lispsm: metres from the camera where shadow quality is optimized from (Filament's shadowNearHint)."""
    lispsm_far_hint: float = 100.0
    """warp = lispsm: metres from the camera where shadow quality is optimized up to (Filament's shadowFarHint)."""
    # depth_range: each cascade's box along the light: its depth range
    depth_range: str = "scene"
    """Box depth: scene (near side pushed to the scene bounds) | slice (the slice's own range, less pancake) | sphere
    (the slice corners' centroid sphere ± radius, less pancake: Godot, Stride) | light_camera (light_near to light_far
    in front of a light pancake metres from the slice: three.js) | scene_clipped (the scene's bounding box clipped to
    the cascade's box on x and y: DirectX CSM11)."""
    pancake: float = 0.0
    """depth_range = slice, sphere or light_camera: metres the near side (light_camera: the light) is pulled toward the
    light beyond the slice (Godot pancake_size, three.js lightMargin)."""
    depth_clamp: bool = True
    """depth_range = slice, sphere or light_camera: casters nearer than the near side are flattened onto it (pancaking)
    rather than clipped."""
    light_near: float = 1.0
    """depth_range = light_camera: metres in front of the light where its camera's depth range starts (three.js
    lightNear)."""
    light_far: float = 2000.0
    """depth_range = light_camera: metres in front of the light where its camera's depth range ends (three.js
    lightFar)."""
    # precision: the precision of the cascade math and of the raster
    engine_precision: str = "float64"
    """Cascade math (light matrices, positions, snapping, depth) as csmlab does it, float64 | float32 (an engine's
    float32 pipeline on absolute world positions: Godot 4, Unity) | camera_relative (the same relative to an origin
    rebased near the camera: Unreal 5, HDRP) (csmlab.texels.PRECISION_METHODS)."""
    rebase_distance: float = 0.0
    """engine_precision = camera_relative: metres between the origins the float32 positions are taken from; 0 rebases at
    the camera every frame (Unreal 5, HDRP), d > 0 to the camera rounded to multiples of d."""
    vertex_snap: str = "world"
    """engine_precision = float64: where vertices and receivers are snapped to 2**-subtexel_bits texels, world (global
    fixed point less the box origin: world-locked) | window (the window position, the rasterizer's rule: follows a
    fractional box origin) (csmlab.texels.VERTEX_SNAPS)."""
    subtexel_bits: int = 8
    """Fixed-point bits below a texel for vertices and receivers (docs/design.md, "Exact zero")."""
    # depth_pass: the faces the depth pass rasterizes and how blended casters cast
    cull: str = "none"
    """Faces the depth pass drops, judged in the light's view as OpenGL's glCullFace (counter-clockwise fronts): none
    (both rasterized) | back (keeps the faces turned toward the light) | front (keeps those turned away: three.js's
    shadowSide = BackSide) (csmlab.culling.CULL_METHODS)."""
    blend_casters: str = "scene"
    """How the depth pass casts glTF alphaMode BLEND triangles, scene (as [scene] blend_casters reads them) | opaque
    (solid) | masked (alpha-tested at their alphaCutoff: Godot 4) | none (no shadow: Unity URP); the camera and the
    reference see the level's rule (csmlab.culling.BLEND_CASTER_RULES)."""
    # selection: which cascade a point is looked up in
    selection: str = "interval"
    """Cascade selection: interval | map | best_resolution | sphere (the first split sphere holding the point: Unity) |
    sphere_dither (sphere, the next cascade dithered in over each sphere's border: Unity HDRP)."""
    outside: str = "none"
    """A point no cascade holds: none (no shadow value, left out of the measures) | lit (S = 1: Bevy) | last (interval
    selection keeps the last cascade beyond the last split: Stride, MJP) (csmlab.lookup_choices.OUTSIDE_METHODS)."""
    cascade_borders: tuple[float, ...] = ()
    """selection = sphere_dither: each cascade's border as a fraction of its split sphere's squared radius, one per
    cascade, the last 0 (HDRP cascadeShadowBorder0..3; its fade to lit is fade_out); empty: no border."""
    # filter: the depth-compare filters
    filter: str = "pcf"
    """Filter: none | pcf | pcf_bilinear | pcf_gaussian | pcf_tent | pcf_poisson | pcf_vogel | pcf_castano |
    pcf_tent_bilinear | pcf_bilinear_box | pcss | vsm | evsm2 | evsm4 | msm (csmlab.filters)."""
    filter_size: int = 3
    """pcf, pcf_gaussian, pcf_tent, pcf_poisson, pcss, pcf_castano (3 or 5), pcf_tent_bilinear, pcf_bilinear_box: taps
    per side N (odd)."""
    filter_sigma: float = 1.0
    """pcf_gaussian with filter_width_m = 0: standard deviation σ of the weights, texels."""
    filter_width_m: float = 0.0
    """pcf_gaussian, pcf_tent, pcf_poisson: filter width in metres, the same in every cascade (Unigine); 0: in texels
    from filter_size and filter_sigma."""
    poisson_taps: int = 16
    """pcf_poisson: taps of the fixed Poisson disk."""
    poisson_seed: int = 1
    """pcf_poisson: seed of the disk's (deterministic) construction."""
    poisson_rotation: str = "none"
    """pcf_poisson, pcf_vogel: none (one disk everywhere) | pixel (rotated per screen pixel by interleaved gradient
    noise) | pixel_frame (per pixel and per frame: the noise's pixel offset by 5.588238 · (frame mod 64), Bevy's
    ShadowFilteringMethod::Temporal) | pixel_taa (pixel_frame under [taa], pixel without it: Godot's taa_frame_count
    term) (csmlab.filters.ROTATIONS)."""
    vogel_taps: int = 5
    """pcf_vogel: taps of the Vogel disk (Godot 4 Soft Low: 4, three.js PCFShadowMap: 5)."""
    vogel_radius: float = 1.0
    """pcf_vogel: radius of the disk in texels (Godot 4 Soft Low: 2.0, three.js LightShadow.radius: 1)."""
    vogel_angle: float = 2.399963229728653
    """pcf_vogel: angle between consecutive taps, radians (three.js: 2.399963229728653, Godot 4: 2.4)."""
    vogel_scale: str = "none"
    """pcf_vogel: none (vogel_radius in every cascade) | first_split (× the first cascade's far end / this cascade's:
    Godot 4)."""
    light_size_deg: float = 0.53
    """pcss: angular diameter of the light, degrees (the sun: 0.53)."""
    # moments: the moment filters' moments, bounds and mip chain (only with filter = "vsm", "evsm2", "evsm4" or "msm")
    moment_blur: int = 5
    """vsm, evsm2, evsm4, msm: taps per side of the separable box blur of the moments (odd; 1: none)."""
    evsm_exponents: tuple[float, float] = (40.0, 5.0)
    """evsm2, evsm4: exponents c+ and c- of the positive and negative warps."""
    vsm_min_variance: float = 1e-5
    """vsm, evsm2, evsm4: minimum variance in normalized depth squared (DirectX VarianceShadows11: 0.00001)."""
    vsm_power: float = 1.0
    """vsm, evsm2, evsm4, msm: light-bleeding reduction p ← p^power (seed 002's MAGIC_NUMBER; 1: none)."""
    vsm_bleed: float = 0.0
    """vsm, evsm2, evsm4, msm: light-bleeding reduction p ← linstep(amount, 1, p) (Lauritzen; 0: none), in [0, 1)."""
    msm_moment_bias: float = 3e-6
    """msm: moment bias α in [0, 1), the weight of (0.5, 0.5, 0.5, 0.5) mixed into the moments (MJP's Shadows sample:
    MSMMomentBias 0.003 × 10⁻³ for float32 moments)."""
    msm_depth_bias: float = 0.0
    """msm: depth bias in normalized depth (a fraction of the scene's light-space depth range) subtracted from the
    receiver's (MJP: MSMDepthBias, default 0)."""
    moment_mips: bool = False
    """vsm, evsm2, evsm4, msm: look the moments up in a mip chain, trilinear at a level of detail from screen-space
    derivatives (lod), not bilinear at level 0."""
    lod: str = "quad"
    """moment_mips: derivatives the level of detail comes from: quad (hardware, per 2×2 quad; a seam at splits) |
    quad_consistent (PSVSM) | analytic (csmlab.quads)."""
    max_lod: int = 3
    """moment_mips: coarsest mip level looked up (the sampler's MaxLOD), 0..8; the boxes keep its reach free inside
    their edges."""
    anisotropy: int = 1
    """moment_mips: most probes along the footprint's major axis, 1..16 (1: trilinear)."""
    # bias: the depth biases and offsets of receivers and casters
    bias_constant: float = 0.0
    """Constant depth bias, metres along the light (negative: away from it, toward acne, as three.js's shadowBias)."""
    bias_slope: float = 1.0
    """Slope-scaled bias in texels: bias += bias_slope · texel · tan(angle(n, -d))."""
    bias_depth_range: float = 0.0
    """Constant depth bias as a fraction of each cascade's light-space depth range, added to bias_constant (Godot 4,
    Stride)."""
    bias_texels: float = 0.0
    """Constant depth bias in texels of each cascade, added to bias_constant (Unity URP's depth bias)."""
    caster_bias_texels: float = 0.0
    """Casters pushed away from the light by this many texels of each cascade before they are rasterized (Unity URP's
    depth bias on the caster vertices, ShadowUtils.GetShadowBias)."""
    caster_bias_units: float = 0.0
    """Raster polygon offset, constant part: caster depth pushed away from the light by this many smallest steps of
    depth_format over each cascade's light-space depth range (Direct3D DepthBias, OpenGL polygon offset units;
    csmlab.storage.polygon_offset_unit)."""
    caster_bias_slope: float = 0.0
    """Raster polygon offset, slope part: caster depth pushed away from the light by this times each caster triangle's
    largest depth change over one texel along light-space x or y (Direct3D SlopeScaledDepthBias, OpenGL polygon offset
    factor)."""
    normal_offset: float = 0.5
    """Receiver offset along its normal, in texels."""
    normal_offset_m: float = 0.0
    """Metres added to the normal offset in every cascade, a world distance (Stride: 2 · NormalOffsetScale / atlas
    size)."""
    normal_offset_scale: str = "none"
    """The normal offset per receiver: none | one_minus_cos (× 1 − cos θ: URP, Stride) | sin (× sin θ: Filament, Unity
    built-in) | one_minus_cos_lateral (Godot 4: × 1 − cos θ, across the light only)."""
    receiver_plane_bias: bool = True
    """Compare each filter tap against the receiver's tangent plane at that texel (derivative-based bias)."""
    receiver_plane_offset: float = 0.0
    """MJP's receiver-plane bias for one hardware compare: the depth pulled toward the light by its tangent plane's
    change over a texel in x and one in y, at most this fraction of the cascade's depth range (MJP: 0.01); 0: none."""
    # blend: the blend between cascades and the fade at the shadow's end
    blend_band: float = 0.0
    """Fraction of a cascade's depth range blended with the next cascade, in [0, 0.5]."""
    transition: str = "backward"
    """blend_band > 0: where each band lies, backward (the last blend_band of cascade i's width, cascade i + 1 reaching
    back) | far_bound (from (1 - blend_band) z_i+1 to z_i+1: Bevy) | forward (cascade i reaching blend_band of its width
    past its split: Unreal) (csmlab.cascades.fit.TRANSITION_METHODS)."""
    blend_curve: str = "linear"
    """blend_band > 0: the next cascade's weight over the band, linear | smoothstep (Stride, Godot)
    (csmlab.cascades.fit.BLEND_CURVES)."""
    fade_out: float = 0.0
    """Fraction of the shadow distance at its end over which the shadow fades to lit (Unreal, Unity, Godot 1 -
    fade_start)."""
    fade: str = "linear"
    """fade_out > 0: the fade's shape, linear (in view depth: Unreal) | smoothstep (in view depth: Godot) | radial
    (linear in the distance to the camera: Unity built-in Stable Fit) | squared_radial (linear in its square: Unity URP)
    (csmlab.fades.FADE_METHODS)."""
    # storage: how the depth maps are stored
    depth_format: str = "float32"
    """Stored depth: float32 | unorm24 | unorm16, quantized over depth_quantization's range (csmlab.storage)."""
    depth_bytes: int = 0
    """Bytes per stored depth texel (memory cost only); 0: what depth_format allocates (2, 4, 4)."""
    depth_quantization: str = "scene"
    """depth_format = unorm24 or unorm16: the range its levels divide, scene (the scene's light-space depth span, in
    power-of-two steps) | cascade (each box's own near/far, as engines store it)
    (csmlab.storage.DEPTH_QUANTIZATION_METHODS)."""
    storage: str = "array"
    """Texture the cascades live in: array (C slices) | atlas (one texture, atlas_layout)."""
    atlas_layout: str = "2x2"
    """atlas: 2x2 | 1x4 | unigine (2×2, split 1 below split 0), up to 4 cascades, empty tiles allocated."""

    def validated(self) -> ShadowSettings:
        """Return ``self`` after checking every field's range, group by group (:data:`SETTING_GROUPS`); raise
        ``ValueError`` naming the field."""
        for group in SETTING_GROUPS:
            group.check(self)
        return self

    @property
    def map_count(self) -> int:
        """Depth maps the per-cascade metric columns count: ``cascades``, or a clipmap's levels."""
        if self.shadow_map == "virtual_clipmap":
            return self.clipmap_last_level - self.clipmap_first_level + 1
        return self.cascades

    @property
    def margin_texels(self) -> int:
        """Texels kept free inside each box edge so that filter taps never clamp: the filter's radius + 1.

        The radius is the filter record's (:data:`csmlab.lookup_choices.FILTER_METHODS`).
        """
        return FILTER_METHODS[check_name(self.filter, FILTER_METHODS, field="filter")].radius_of(self) + 1

    def replace(self, **changes) -> ShadowSettings:
        """A copy with ``changes`` applied (TOML name ``lambda`` accepted for ``lambda_``)."""
        if "lambda" in changes:
            changes["lambda_"] = changes.pop("lambda")
        return replace(self, **changes)

    @classmethod
    def field_names(cls) -> list[str]:
        """Field names as a TOML file spells them (``lambda``, not ``lambda_``)."""
        return ["lambda" if f.name == "lambda_" else f.name for f in fields(cls)]


def _need(ok: bool, name: str, expected: str, value) -> None:
    """Raise ``ValueError("<name>: expected <expected>, got <value>")`` unless ``ok``."""
    if not ok:
        raise ValueError(f"{name}: expected {expected}, got {value!r}")


def _int_in(value, low: int, high: int) -> bool:
    return isinstance(value, int) and low <= value <= high


def _check_maps(s: ShadowSettings) -> None:
    _need(_int_in(s.cascades, 1, 10), "cascades", "an integer in 1..10", s.cascades)
    _need(_int_in(s.resolution, 16, 16384), "resolution", "an integer in 16..16384", s.resolution)
    _need(s.shadow_map in SHADOW_MAP_METHODS, "shadow_map", f"one of {list(SHADOW_MAP_METHODS)}", s.shadow_map)
    _need(not s.cascade_resolutions or (len(s.cascade_resolutions) == s.cascades and all(
        _int_in(r, 16, 16384) for r in s.cascade_resolutions)), "cascade_resolutions",
        f"{s.cascades} integers in 16..16384 (one per cascade) or an empty list", s.cascade_resolutions)


def _check_clipmap(s: ShadowSettings) -> None:
    _need(isinstance(s.page_size, int) and s.page_size in _POWERS_OF_TWO and 8 <= s.page_size <= 1024,
          "page_size", "a power of two in 8..1024", s.page_size)
    _need(isinstance(s.virtual_resolution, int) and s.virtual_resolution in _POWERS_OF_TWO
          and s.page_size <= s.virtual_resolution <= 65536, "virtual_resolution",
          f"a power of two in page_size ({s.page_size})..65536", s.virtual_resolution)
    _need(_int_in(s.clipmap_first_level, -10, 30), "clipmap_first_level", "an integer in -10..30",
          s.clipmap_first_level)
    _need(_int_in(s.clipmap_last_level, s.clipmap_first_level, 30)
          and s.clipmap_last_level - s.clipmap_first_level < 32, "clipmap_last_level",
          f"an integer in clipmap_first_level ({s.clipmap_first_level})..30, at most 32 levels", s.clipmap_last_level)
    _need(math.isfinite(s.lod_bias) and -8.0 <= s.lod_bias <= 8.0, "lod_bias", "a number in [-8, 8]", s.lod_bias)
    _need(_int_in(s.physical_pages, 1, 65536), "physical_pages", "an integer in 1..65536", s.physical_pages)
    _need(s.shadow_map != "virtual_clipmap" or s.filter in CLIPMAP_FILTERS, "filter",
          f"one of {list(CLIPMAP_FILTERS)} with shadow_map = \"virtual_clipmap\" (its page-table lookup)", s.filter)


def _check_split(s: ShadowSettings) -> None:
    _need(0.0 <= s.lambda_ <= 1.0, "lambda", "a value in [0, 1]", s.lambda_)
    _need(all(math.isfinite(z) and z > 0 for z in s.splits) and all(a < b for a, b in zip(s.splits, s.splits[1:])),
          "splits", "increasing positive far ends (metres, or fractions of shadow_distance when all ≤ 1)",
          list(s.splits))
    _need(not s.splits or max(s.splits) > 1.0 or math.isclose(s.splits[-1], 1.0, rel_tol=1e-9), "splits",
          "fractions of shadow_distance ending at 1.0 (the last cascade ends at the shadow distance)", list(s.splits))
    _need(s.shadow_distance > 0, "shadow_distance", "a positive distance in metres", s.shadow_distance)
    _need(s.shadow_distance_from != "farthest_visible" or s.bounds == "sdsm", "shadow_distance_from",
          'fixed or camera_far with bounds = "frustum" (farthest_visible reads the visible range of bounds = "sdsm")',
          s.shadow_distance_from)
    _need(math.isfinite(s.max_shadow_distance) and s.max_shadow_distance >= 0.0, "max_shadow_distance",
          "a non-negative distance in metres (0: no cap)", s.max_shadow_distance)
    _need(1.0 <= s.distribution_exponent <= 100.0, "distribution_exponent", "a ratio of at least 1 and at most 100",
          s.distribution_exponent)
    _need(s.first_cascade_far > 0, "first_cascade_far", "a positive distance in metres", s.first_cascade_far)


def _check_policies(s: ShadowSettings) -> None:
    _need(s.zoom_policy in ZOOM_POLICIES, "zoom_policy", f"one of {list(ZOOM_POLICIES)}", s.zoom_policy)
    _need(math.isfinite(s.min_fov_deg) and 0.0 < s.min_fov_deg < 180.0, "min_fov_deg",
          "a field of view in (0, 180) degrees", s.min_fov_deg)
    _need(s.sun_policy in SUN_POLICIES, "sun_policy", f"one of {list(SUN_POLICIES)}", s.sun_policy)
    _need(isinstance(s.sun_update_frames, int) and s.sun_update_frames >= 1, "sun_update_frames",
          "a positive whole number of frames", s.sun_update_frames)
    _need(math.isfinite(s.sun_step_deg) and 0.0 < s.sun_step_deg <= 90.0, "sun_step_deg",
          "an angle in (0, 90] degrees", s.sun_step_deg)


def _check_bounds(s: ShadowSettings) -> None:
    _need(0.0 <= s.hysteresis < 1.0, "hysteresis", "a fraction in [0, 1)", s.hysteresis)


def _check_fit(s: ShadowSettings) -> None:
    _need(isinstance(s.levels, int) and s.levels >= 1, "levels", "a positive integer", s.levels)
    _need(s.quantized_base in ("sphere", "frustum"), "quantized_base", "sphere or frustum", s.quantized_base)
    _need(0.0 <= s.extent_hysteresis < 1.0, "extent_hysteresis", "a fraction in [0, 1)", s.extent_hysteresis)
    _need(s.focus in ("slice", "scene"), "focus", "slice or scene", s.focus)


def _check_warp(s: ShadowSettings) -> None:
    _need(s.warp in ("none", "lispsm"), "warp", "none or lispsm", s.warp)
    _need(s.warp == "none" or s.stabilization == "none", "warp",
          'none with a stabilized box (Filament: "We can\'t use LISPSM in stable mode"); lispsm needs '
          'stabilization = "none"', s.warp)
    _need(s.warp == "none" or s.engine_precision == "float64", "warp",
          'none with engine_precision = "float32" (the warp is computed in float64)', s.warp)
    _need(0.0 <= s.lispsm_near_hint < s.lispsm_far_hint, "lispsm_near_hint",
          "a distance in metres of at least 0 and below lispsm_far_hint", s.lispsm_near_hint)


def _check_depth_range(s: ShadowSettings) -> None:
    _need(s.pancake >= 0, "pancake", "a non-negative distance in metres", s.pancake)
    _need(0.0 <= s.light_near < s.light_far, "light_near", f"a distance in metres in [0, light_far = {s.light_far})",
          s.light_near)
    _need(isinstance(s.depth_clamp, bool), "depth_clamp", "true or false", s.depth_clamp)


def _check_precision(s: ShadowSettings) -> None:
    _need(math.isfinite(s.rebase_distance) and s.rebase_distance >= 0.0, "rebase_distance",
          "a non-negative distance in metres (0: rebased at the camera every frame)", s.rebase_distance)
    _need(_int_in(s.subtexel_bits, 0, 16), "subtexel_bits", "an integer in 0..16", s.subtexel_bits)


def _check_depth_pass(s: ShadowSettings) -> None:
    _need(s.cull in CULL_METHODS, "cull", f"one of {list(CULL_METHODS)}", s.cull)
    _need(s.blend_casters in BLEND_CASTER_RULES, "blend_casters", f"one of {list(BLEND_CASTER_RULES)}",
          s.blend_casters)


def _check_selection(s: ShadowSettings) -> None:
    _need(not s.cascade_borders or (len(s.cascade_borders) == s.cascades and all(0.0 <= b <= 1.0 for b in
                                                                                 s.cascade_borders)
                                    and s.cascade_borders[-1] == 0.0), "cascade_borders",
          f"{s.cascades} fractions in [0, 1] (one per cascade), the last 0 (the last cascade's fade to lit is "
          f"fade_out), or an empty list", list(s.cascade_borders))


def _check_filter(s: ShadowSettings) -> None:
    _need(_int_in(s.filter_size, 1, 63) and s.filter_size % 2 == 1, "filter_size", "an odd integer in 1..63",
          s.filter_size)
    _need(s.filter_sigma > 0, "filter_sigma", "a positive number of texels", s.filter_sigma)
    _need(s.filter_width_m >= 0, "filter_width_m", "a non-negative width in metres", s.filter_width_m)
    _need(_int_in(s.poisson_taps, 1, 256), "poisson_taps", "an integer in 1..256", s.poisson_taps)
    _need(isinstance(s.poisson_seed, int) and s.poisson_seed >= 0, "poisson_seed", "a non-negative integer",
          s.poisson_seed)
    _need(s.poisson_rotation in ROTATIONS, "poisson_rotation", f"one of {list(ROTATIONS)}", s.poisson_rotation)
    _need(s.filter != "pcf_castano" or s.filter_size in CASTANO_SIZES, "filter_size",
          "3 or 5 with filter = \"pcf_castano\" (Castaño's 3×3 and 5×5 kernels)", s.filter_size)
    _need(_int_in(s.vogel_taps, 1, 64), "vogel_taps", "an integer in 1..64", s.vogel_taps)
    _need(0.0 < s.vogel_radius <= 16.0, "vogel_radius", "a radius in (0, 16] texels", s.vogel_radius)
    _need(0.0 <= s.vogel_angle <= 2.0 * math.pi, "vogel_angle", "an angle in [0, 2π] radians", s.vogel_angle)
    _need(s.vogel_scale in ("none", "first_split"), "vogel_scale", "none or first_split", s.vogel_scale)
    _need(0.0 < s.light_size_deg < 90.0, "light_size_deg", "an angle in (0, 90) degrees", s.light_size_deg)


def _check_moments(s: ShadowSettings) -> None:
    _need(_int_in(s.moment_blur, 1, 63) and s.moment_blur % 2 == 1, "moment_blur", "an odd integer in 1..63",
          s.moment_blur)
    _need(len(s.evsm_exponents) == 2 and all(0 < c <= 44 for c in s.evsm_exponents), "evsm_exponents",
          "two exponents in (0, 44] (e^(2c) must fit float32)", s.evsm_exponents)
    _need(s.vsm_min_variance >= 0, "vsm_min_variance", "a non-negative variance", s.vsm_min_variance)
    _need(s.vsm_power > 0, "vsm_power", "a positive exponent", s.vsm_power)
    _need(0.0 <= s.vsm_bleed < 1.0, "vsm_bleed", "an amount in [0, 1)", s.vsm_bleed)
    _need(0.0 <= s.msm_moment_bias < 1.0, "msm_moment_bias", "a weight in [0, 1)", s.msm_moment_bias)
    _need(math.isfinite(s.msm_depth_bias), "msm_depth_bias", "a finite normalized depth", s.msm_depth_bias)
    _need(isinstance(s.moment_mips, bool), "moment_mips", "true or false", s.moment_mips)
    _need(s.lod in ("quad", "quad_consistent", "analytic"), "lod", "quad, quad_consistent or analytic", s.lod)
    _need(_int_in(s.max_lod, 0, 8), "max_lod", "an integer in 0..8", s.max_lod)
    _need(_int_in(s.anisotropy, 1, 16), "anisotropy", "an integer in 1..16", s.anisotropy)


def _check_bias(s: ShadowSettings) -> None:
    _need(s.bias_constant >= -1.0, "bias_constant",
          "a distance in metres of at least -1 (negative: away from the light, three.js's shadowBias)", s.bias_constant)
    _need(s.bias_slope >= 0, "bias_slope", "a non-negative number of texels", s.bias_slope)
    _need(0.0 <= s.bias_depth_range <= 1.0, "bias_depth_range", "a fraction in [0, 1]", s.bias_depth_range)
    _need(0.0 <= s.bias_texels <= 1000.0, "bias_texels", "a number of texels in [0, 1000]", s.bias_texels)
    _need(0.0 <= s.caster_bias_texels <= 1000.0, "caster_bias_texels", "a number of texels in [0, 1000]",
          s.caster_bias_texels)
    _need(0.0 <= s.caster_bias_units <= 2.0**24, "caster_bias_units", "a number of depth steps in [0, 2^24]",
          s.caster_bias_units)
    _need(0.0 <= s.caster_bias_slope <= 1000.0, "caster_bias_slope", "a slope factor in [0, 1000]",
          s.caster_bias_slope)
    _need(s.normal_offset_scale in NORMAL_OFFSET_SCALES, "normal_offset_scale", f"one of {list(NORMAL_OFFSET_SCALES)}",
          s.normal_offset_scale)
    _need(0.0 <= s.receiver_plane_offset <= 1.0, "receiver_plane_offset", "a fraction in [0, 1]",
          s.receiver_plane_offset)
    _need(0.0 <= s.normal_offset_m <= 10.0, "normal_offset_m", "a distance in [0, 10] metres", s.normal_offset_m)
    _need(s.normal_offset >= 0, "normal_offset", "a non-negative number of texels", s.normal_offset)
    _need(isinstance(s.receiver_plane_bias, bool), "receiver_plane_bias", "true or false", s.receiver_plane_bias)


def _check_blend(s: ShadowSettings) -> None:
    _need(0.0 <= s.blend_band <= 0.5, "blend_band", "a fraction in [0, 0.5]", s.blend_band)
    _need(0.0 <= s.fade_out <= 1.0, "fade_out", "a fraction in [0, 1]", s.fade_out)


def _check_storage(s: ShadowSettings) -> None:
    _need(_int_in(s.depth_bytes, 0, 16), "depth_bytes", "an integer in 0..16 (0: from depth_format)", s.depth_bytes)
    _need(s.depth_format in ("float32", "unorm24", "unorm16"), "depth_format", "float32, unorm24 or unorm16",
          s.depth_format)
    _need(s.storage in ("array", "atlas"), "storage", "array or atlas", s.storage)
    _need(s.atlas_layout in ("2x2", "1x4", "unigine"), "atlas_layout", "2x2, 1x4 or unigine", s.atlas_layout)
    _need(s.storage != "atlas" or s.cascades <= 4, "storage", "array for more than 4 cascades (an atlas layout holds "
          "4 tiles)", s.storage)


def _family(filter: str) -> str | None:
    """The family of the filter named ``filter`` (:data:`csmlab.lookup_choices.FAMILIES`); None for another name."""
    record = FILTER_METHODS.get(filter)
    return None if record is None else record.family


@dataclass(frozen=True)
class Applies:
    """Where a ``[shadow]`` field takes effect: elsewhere setting it changes nothing.

    Attributes
    ----------
    test : callable
        ``test(*, <fields>) -> bool``: whether the field takes effect, from the fields it declares
        (keyword-only, as :class:`ShadowSettings` names them).
    when : str
        The condition in words, as a message shows it.
    """

    test: Callable[..., bool]
    when: str

    def inputs(self, settings: ShadowSettings) -> dict:
        """The fields :attr:`test` reads, from ``settings``."""
        return {name: getattr(settings, name) for name in parameters(self.test)}

    def holds(self, settings: ShadowSettings) -> bool:
        """Whether the field takes effect under ``settings``."""
        return self.test(**self.inputs(settings))


def _filters_when(test: Callable[[str], bool]) -> str:
    """``filter = "a", "b" or "c"``: the filters ``test`` accepts, in words."""
    names = [f'"{name}"' for name in FILTER_METHODS if test(name)]
    return f"filter = {', '.join(names[:-1])} or {names[-1]}" if len(names) > 1 else f"filter = {names[0]}"


def _filters(test: Callable[[str], bool], why: str) -> Applies:
    """The field takes effect with the filters ``test`` accepts (named in the condition): ``why``."""
    return Applies(lambda *, filter: test(filter), f"{_filters_when(test)} ({why})")


def _moment_mips(*, filter: str, moment_mips: bool) -> bool:
    return _family(filter) == "moment" and moment_mips


def _lispsm(*, warp: str, stabilization: str) -> bool:
    return warp == "lispsm" and stabilization == "none"


def _is_moment(name: str) -> bool:
    return _family(name) == "moment"


@dataclass(frozen=True)
class SettingGroup:
    """One named group of ``[shadow]`` fields: what docs/design.md, ``csmlab list``, the validation and the
    applicability rules read.

    Attributes
    ----------
    name : str
        Short name (``clipmap``), as docs/design.md's ``# group NAME: title`` lines spell it.
    title : str
        What the group sets, in words.
    fields : tuple of str
        Its fields by their TOML names, in :class:`ShadowSettings`' (and the documented) order.
    check : callable
        ``check(settings)``: raise ``ValueError("<field>: expected …, got …")`` on the first field of the
        group out of range (a check may read fields of earlier groups).
    applies : Applies or None
        Where every field of the group takes effect; None: each field's own rule, if any, says.
    rules : dict
        Per field that takes effect only somewhere: its own :class:`Applies`, or under :attr:`applies` the
        reason it matters there (a string, appended to the group's condition in messages). A field's own
        rule inside a conditional group is narrower than the group's condition.
    """

    name: str
    title: str
    fields: tuple[str, ...]
    check: Callable[[ShadowSettings], None]
    applies: Applies | None = None
    rules: Mapping[str, Applies | str] = field(default_factory=dict)

    def rule(self, key: str) -> Applies | None:
        """Where the field ``key`` takes effect (None: everywhere)."""
        own = self.rules.get(key)
        if isinstance(own, str):
            return Applies(self.applies.test, f"{self.applies.when} ({own})")
        return own


_CLIPMAP = Applies(lambda *, shadow_map: shadow_map == "virtual_clipmap", 'shadow_map = "virtual_clipmap"')
_MOMENTS = Applies(lambda *, filter: _is_moment(filter), _filters_when(_is_moment))
_DEPTH_RANGE_SIDE = ("slice", "sphere", "light_camera")

SETTING_GROUPS: tuple[SettingGroup, ...] = (
    SettingGroup("maps", "cascades and the maps they are drawn in",
                 ("cascades", "resolution", "cascade_resolutions", "shadow_map"), _check_maps),
    SettingGroup("clipmap", "the virtual clipmap's levels and pages",
                 ("virtual_resolution", "page_size", "clipmap_first_level", "clipmap_last_level", "lod_bias",
                  "physical_pages"), _check_clipmap, _CLIPMAP,
                 {"virtual_resolution": "the texels per side of each level",
                  "page_size": "the texels per side of a page",
                  "clipmap_first_level": "its finest level", "clipmap_last_level": "its coarsest level",
                  "lod_bias": "the bias of its level choice", "physical_pages": "its page pool"}),
    SettingGroup("split", "the splits of the view depth",
                 ("split", "lambda", "splits", "distribution_exponent", "first_cascade_far", "shadow_distance",
                  "shadow_distance_from", "max_shadow_distance"),
                 _check_split, rules={
                     "shadow_distance": Applies(lambda *, shadow_distance_from: shadow_distance_from == "fixed",
                                                'shadow_distance_from = "fixed" (a number of metres; "camera_far" and '
                                                '"farthest_visible" end each frame where the camera or its view ends)'),
                     "max_shadow_distance": Applies(lambda *, shadow_distance_from: shadow_distance_from != "fixed",
                                                    'shadow_distance_from = "camera_far" or "farthest_visible" '
                                                    '(the cap on where they end)'),
                     "lambda": Applies(lambda *, split: split == "practical",
                                       'split = "practical" (the blend of log and uniform splits)'),
                     "splits": Applies(lambda *, split: split in ("manual", "manual_range"),
                                       'split = "manual" or "manual_range" (the far end of each cascade)'),
                     "distribution_exponent": Applies(lambda *, split: split == "exponent",
                                                      'split = "exponent" (the depth ratio of consecutive cascades)'),
                     "first_cascade_far": Applies(lambda *, split: split == "geometric",
                                                  'split = "geometric" (the first far end)')}),
    SettingGroup("policies", "the sun and zoom policies (the light and field of view the maps are built for)",
                 ("zoom_policy", "min_fov_deg", "sun_policy", "sun_update_frames", "sun_step_deg"),
                 _check_policies, rules={
                     "zoom_policy": Applies(lambda *, shadow_map: shadow_map == "cascades",
                                            'shadow_map = "cascades" (a virtual clipmap\'s levels do not follow the '
                                            'slices)'),
                     "min_fov_deg": Applies(lambda *, shadow_map, zoom_policy: shadow_map == "cascades"
                                            and zoom_policy == "min_fov",
                                            'zoom_policy = "min_fov" with shadow_map = "cascades" (the field of view '
                                            'it floors)'),
                     "sun_update_frames": Applies(lambda *, sun_policy: sun_policy == "every_n",
                                                  'sun_policy = "every_n" (the frames between updates)'),
                     "sun_step_deg": Applies(lambda *, sun_policy: sun_policy == "quantized",
                                             'sun_policy = "quantized" (the step the sun\'s angles are rounded to)')}),
    SettingGroup("bounds", "the depth range the splits divide", ("bounds", "hold", "hysteresis"), _check_bounds,
                 rules={"hysteresis": Applies(lambda *, bounds, hold: bounds == "sdsm" and hold == "fraction",
                                              'bounds = "sdsm" with hold = "fraction" (the hold of its visible range)'),
                        "hold": Applies(lambda *, bounds: bounds == "sdsm",
                                        'bounds = "sdsm" (how its visible range is held)')}),
    SettingGroup("fit", "each cascade's box across the light: fit and stabilization",
                 ("fit", "stabilization", "levels", "quantized_base", "extent", "snap", "light_basis",
                  "extent_hysteresis", "focus"), _check_fit, rules={
                     "levels": Applies(lambda *, stabilization: stabilization == "quantized",
                                       'stabilization = "quantized" (the steps an extent is rounded up to)'),
                     "quantized_base": Applies(lambda *, stabilization: stabilization == "quantized",
                                               'stabilization = "quantized" (the extent its steps divide)'),
                     "extent": Applies(lambda *, stabilization, quantized_base: stabilization == "exact" or (
                         stabilization == "quantized" and quantized_base == "sphere"),
                         'stabilization = "exact", or "quantized" with quantized_base = "sphere" (the fixed box '
                         'diameter)'),
                     "snap": Applies(lambda *, stabilization: stabilization == "exact",
                                     'stabilization = "exact" (what its fixed box snaps to whole texels)'),
                     "extent_hysteresis": Applies(
                         lambda *, stabilization, warp, focus: stabilization == "none" and warp == "none"
                         and focus == "slice",
                         'stabilization = "none" with warp = "none" and focus = "slice" (a stabilized box already has '
                         'a fixed extent; a warped map is focused every frame; the held extent is the slice\'s)'),
                     "focus": Applies(lambda *, stabilization: stabilization == "none",
                                      'stabilization = "none" (what its tight box covers)')}),
    SettingGroup("warp", "the light-space perspective warp", ("warp", "lispsm_near_hint", "lispsm_far_hint"),
                 _check_warp, rules={
                     "lispsm_near_hint": Applies(_lispsm, 'warp = "lispsm" with stabilization = "none" (its virtual '
                                                          'near plane)'),
                     "lispsm_far_hint": Applies(_lispsm, 'warp = "lispsm" with stabilization = "none" (its virtual far '
                                                         'plane)')}),
    SettingGroup("depth_range", "each cascade's box along the light: its depth range",
                 ("depth_range", "pancake", "depth_clamp", "light_near", "light_far"), _check_depth_range, rules={
                     "pancake": Applies(lambda *, depth_range: depth_range in _DEPTH_RANGE_SIDE,
                                        'depth_range = "slice", "sphere" or "light_camera" (the pull of its near side '
                                        'toward the light)'),
                     "depth_clamp": Applies(lambda *, depth_range: depth_range in _DEPTH_RANGE_SIDE,
                                            'depth_range = "slice", "sphere" or "light_camera" (casters nearer than '
                                            'its near side)'),
                     "light_near": Applies(lambda *, depth_range: depth_range == "light_camera",
                                           'depth_range = "light_camera" (where its camera\'s range starts)'),
                     "light_far": Applies(lambda *, depth_range: depth_range == "light_camera",
                                          'depth_range = "light_camera" (where its camera\'s range ends)')}),
    SettingGroup("precision", "the precision of the cascade math and of the raster",
                 ("engine_precision", "rebase_distance", "vertex_snap", "subtexel_bits"), _check_precision, rules={
                     "rebase_distance": Applies(lambda *, engine_precision: engine_precision == "camera_relative",
                                                'engine_precision = "camera_relative" (how often its origin is '
                                                'rebased)'),
                     "vertex_snap": Applies(lambda *, engine_precision: engine_precision == "float64",
                                            'engine_precision = "float64" (a float32 pipeline snaps its window '
                                            'position)')}),
    SettingGroup("depth_pass", "the faces the depth pass rasterizes and how blended casters cast",
                 ("cull", "blend_casters"), _check_depth_pass),
    SettingGroup("selection", "which cascade a point is looked up in", ("selection", "outside", "cascade_borders"),
                 _check_selection, rules={
                     "cascade_borders": Applies(lambda *, selection: selection == "sphere_dither",
                                                'selection = "sphere_dither" (the borders it dithers over)')}),
    SettingGroup("filter", "the depth-compare filters",
                 ("filter", "filter_size", "filter_sigma", "filter_width_m", "poisson_taps", "poisson_seed",
                  "poisson_rotation", "vogel_taps", "vogel_radius", "vogel_angle", "vogel_scale", "light_size_deg"),
                 _check_filter, rules={
                     "filter_size": _filters(lambda f: f == "pcf" or (_family(f) == "weighted" and f != "pcf_vogel"),
                                             "taps per side"),
                     "filter_sigma": Applies(lambda *, filter, filter_width_m: filter == "pcf_gaussian"
                                             and filter_width_m == 0,
                                             'filter = "pcf_gaussian" and filter_width_m = 0 (σ in texels; a width in '
                                             'metres sets σ otherwise)'),
                     "filter_width_m": _filters(lambda f: f in ("pcf_gaussian", "pcf_tent", "pcf_poisson"),
                                                "the width in metres"),
                     "poisson_taps": _filters(lambda f: f == "pcf_poisson", "the taps of its disk"),
                     "poisson_seed": _filters(lambda f: f == "pcf_poisson", "the seed of its disk"),
                     "poisson_rotation": _filters(lambda f: f in ("pcf_poisson", "pcf_vogel"),
                                                  "the rotation of its disk"),
                     "vogel_taps": _filters(lambda f: f == "pcf_vogel", "the taps of its disk"),
                     "vogel_radius": _filters(lambda f: f == "pcf_vogel", "the radius of its disk"),
                     "vogel_angle": _filters(lambda f: f == "pcf_vogel", "the angle between its taps"),
                     "vogel_scale": _filters(lambda f: f == "pcf_vogel", "its radius per cascade"),
                     "light_size_deg": _filters(lambda f: f == "pcss", "the light's size that sets the penumbra")}),
    SettingGroup("moments", "the moment filters' moments, bounds and mip chain",
                 ("moment_blur", "evsm_exponents", "vsm_min_variance", "vsm_power", "vsm_bleed", "msm_moment_bias",
                  "msm_depth_bias", "moment_mips", "lod", "max_lod", "anisotropy"), _check_moments, _MOMENTS, {
                     "moment_blur": "the blur of the moments",
                     "evsm_exponents": _filters(lambda f: f in ("evsm2", "evsm4"), "the exponents of the warps"),
                     "vsm_min_variance": _filters(lambda f: _is_moment(f) and f != "msm",
                                                  "the variance floor of the Chebyshev bound"),
                     "vsm_power": "a light-bleeding reduction",
                     "vsm_bleed": "a light-bleeding reduction",
                     "msm_moment_bias": _filters(lambda f: f == "msm", "the moment bias of the Hamburger bound"),
                     "msm_depth_bias": _filters(lambda f: f == "msm", "the depth bias of the Hamburger bound"),
                     "moment_mips": "the moments' mip chain",
                     "lod": Applies(_moment_mips, "a moment filter with moment_mips = true (the mip chain's level of "
                                                  "detail)"),
                     "max_lod": Applies(_moment_mips, "a moment filter with moment_mips = true (the mip chain's "
                                                      "coarsest level)"),
                     "anisotropy": Applies(_moment_mips, "a moment filter with moment_mips = true (the probes along "
                                                         "the footprint)")}),
    SettingGroup("bias", "the depth biases and offsets of receivers and casters",
                 ("bias_constant", "bias_slope", "bias_depth_range", "bias_texels", "caster_bias_texels",
                  "caster_bias_units", "caster_bias_slope", "normal_offset", "normal_offset_m", "normal_offset_scale",
                  "receiver_plane_bias", "receiver_plane_offset"), _check_bias),
    SettingGroup("blend", "the blend between cascades and the fade at the shadow's end",
                 ("blend_band", "transition", "blend_curve", "fade_out", "fade"), _check_blend, rules={
                     "transition": Applies(lambda *, blend_band: blend_band > 0,
                                           "blend_band > 0 (where its bands lie)"),
                     "blend_curve": Applies(lambda *, blend_band: blend_band > 0,
                                            "blend_band > 0 (the weight over its bands)"),
                     "fade": Applies(lambda *, fade_out: fade_out > 0, "fade_out > 0 (the shape of the far fade)")}),
    SettingGroup("storage", "how the depth maps are stored",
                 ("depth_format", "depth_bytes", "depth_quantization", "storage", "atlas_layout"), _check_storage,
                 rules={"depth_quantization": Applies(lambda *, depth_format: depth_format != "float32",
                                                      'depth_format = "unorm24" or "unorm16" (the range its levels '
                                                      'divide)'),
                        "atlas_layout": Applies(lambda *, storage: storage == "atlas",
                                                'storage = "atlas" (the tiles of the atlas)')}),
)
"""The ``[shadow]`` fields in named groups, in the documented order (docs/design.md, "Experiment file"): the one
table that validation (:meth:`ShadowSettings.validated` runs each group's check in order), the applicability
rules (:data:`APPLIES`), ``csmlab list`` and the documentation test read. A new field goes in one group's
``fields`` at the place it holds among the class's fields, with its range check in the group's ``check`` and,
where it takes effect only somewhere, its rule in ``rules``."""

GROUP_OF: dict[str, SettingGroup] = {key: group for group in SETTING_GROUPS for key in group.fields}
"""The group of each ``[shadow]`` field (TOML name): what orders and heads the lists of fields people read (an
engine's lacking lines, the tune page's search space)."""

APPLIES: dict[str, Applies] = {key: group.rule(key) for group in SETTING_GROUPS for key in group.fields
                               if group.rule(key) is not None}
"""The ``[shadow]`` fields that take effect only with some settings (TOML names), and where; every other
field takes effect in every method. The config loader refuses a field written where it does not apply."""
