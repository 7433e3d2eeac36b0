"""The shadow settings of one method: every knob of docs/design.md's ``[shadow]`` section.

A plain record shared by the host cascades and the Warp shadow lookup. :mod:`csmlab.config` builds it
from TOML and validates it at the edge; :meth:`ShadowSettings.validated` repeats the range
checks so that a settings object made in Python is held to the same contract.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, fields, replace

from csmlab.culling import CULL_METHODS
from csmlab.lookup_choices import CASTANO_SIZES, FILTER_METHODS, NORMAL_OFFSET_SCALES, ROTATIONS
from csmlab.registry import check_name, parameters
from csmlab.shadow_policies import SUN_POLICIES, ZOOM_POLICIES

__all__ = ["APPLIES", "CLIPMAP_FILTERS", "SHADOW_MAP_METHODS", "Applies", "ShadowSettings"]

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

    A field whose documentation starts with where it applies (``pcf_poisson: …``) takes effect only
    there: :data:`APPLIES` holds that condition as a test over the settings.
    """

    cascades: int = 4
    """Number of cascades C."""
    resolution: int = 1024
    """Texels per side R of each cascade's depth map."""
    shadow_map: str = "cascades"
    """What the depth maps are: cascades (one box per split, the fields below) | virtual_clipmap (Unreal 5's virtual shadow map clipmap: levels of pages rasterized where visible pixels need them, csmlab.clipmaps)."""
    virtual_resolution: int = 16384
    """virtual_clipmap: virtual texels per side of every clipmap level (Unreal: 16k)."""
    page_size: int = 128
    """virtual_clipmap: texels per side of a page, the unit of marking, caching and rasterization (Unreal: 128)."""
    clipmap_first_level: int = 6
    """virtual_clipmap: the finest level n, covering a radius of 2^n cm around the camera (r.Shadow.Virtual.Clipmap.FirstLevel)."""
    clipmap_last_level: int = 22
    """virtual_clipmap: the coarsest level (r.Shadow.Virtual.Clipmap.LastLevel)."""
    lod_bias: float = -0.5
    """virtual_clipmap: log2 bias of the level chosen from a pixel's footprint, -1 doubles the resolution (r.Shadow.Virtual.ResolutionLodBiasDirectional)."""
    physical_pages: int = 2048
    """virtual_clipmap: pages of the physical pool, its memory (r.Shadow.Virtual.MaxPhysicalPages)."""
    split: str = "practical"
    """Split scheme: uniform | log | practical | manual | manual_range | exponent | geometric."""
    lambda_: float = 0.75
    """practical: PSSM blend λ of log and uniform splits (TOML field ``lambda``)."""
    splits: tuple[float, ...] = ()
    """manual: far end of each cascade, metres, or fractions of shadow_distance when all ≤ 1; manual_range: fractions of the range from the near plane to shadow_distance (Godot, MJP)."""
    shadow_distance: float = 200.0
    """View depth in metres that the last cascade ends at (clamped to the camera's far plane), with shadow_distance_from = fixed."""
    shadow_distance_from: str = "fixed"
    """Where the last cascade ends: fixed (shadow_distance) | camera_far (the camera's far plane of each frame: three.js, Filament, MJP) | farthest_visible (the farthest visible point, bounds = sdsm: Stride); TOML also takes shadow_distance = "camera_far" or "farthest_visible" (csmlab.cascades.bounds.SHADOW_DISTANCE_METHODS)."""
    max_shadow_distance: float = 0.0
    """shadow_distance_from = camera_far or farthest_visible: the engine's cap in metres (three.js maxFar 100000); 0: none."""
    zoom_policy: str = "camera"
    """cascades: the field of view the cascades are fitted to, camera (the camera's own) | min_fov (max(fov, min_fov_deg) while the camera renders at its own: Godot's directional_shadow_min_fov) (csmlab.shadow_policies.ZOOM_POLICIES)."""
    min_fov_deg: float = 60.0
    """zoom_policy = min_fov: the smallest vertical field of view in degrees the cascades are fitted to."""
    sun_policy: str = "every_frame"
    """The light direction the shadow maps are built with, every_frame (the true sun) | every_n (the sun of every sun_update_frames-th frame, held in between) | quantized (the sun's elevation and azimuth rounded to sun_step_deg); shading and reference keep the true sun (csmlab.shadow_policies.SUN_POLICIES)."""
    sun_update_frames: int = 4
    """sun_policy = every_n: frames between updates of the shadow's light direction."""
    sun_step_deg: float = 1.0
    """sun_policy = quantized: the angular step in degrees the sun's elevation and azimuth are rounded to."""
    fit: str = "cascade"
    """Fit: cascade (slice [z_i, z_i+1]) | cascade_lerp (its ends lerped from near to far: n + (z_i/f)(f − n), three.js) | scene (slice [near, z_i+1])."""
    stabilization: str = "exact"
    """none | exact | quantized | tight_snapped (the tight box padded for the filter, snapped to texels of its own size every frame: DirectX CSM11 fit to cascade)."""
    levels: int = 64
    """quantized: number of extent steps of the base extent."""
    quantized_base: str = "sphere"
    """quantized: base extent, sphere (slice bounding-sphere diameter) | frustum (whole frustum box)."""
    selection: str = "interval"
    """Cascade selection: interval | map | best_resolution | sphere (the first split sphere holding the point: Unity) | sphere_dither (sphere, the next cascade dithered in over each sphere's border: Unity HDRP)."""
    cascade_borders: tuple[float, ...] = ()
    """selection = sphere_dither: each cascade's border as a fraction of its split sphere's squared radius, one per cascade, the last 0 (HDRP cascadeShadowBorder0..3; its fade to lit is fade_out); empty: no border."""
    outside: str = "none"
    """A point no cascade holds: none (no shadow value, left out of the measures) | lit (S = 1: Bevy) | last (interval selection keeps the last cascade beyond the last split: Stride, MJP) (csmlab.lookup_choices.OUTSIDE_METHODS)."""
    filter: str = "pcf"
    """Filter: none | pcf | pcf_bilinear | pcf_gaussian | pcf_tent | pcf_poisson | pcf_vogel | pcf_castano | pcf_tent_bilinear | pcf_bilinear_box | pcss | vsm | evsm2 | evsm4 | msm (csmlab.filters)."""
    filter_size: int = 3
    """pcf, pcf_gaussian, pcf_tent, pcf_poisson, pcss, pcf_castano (3 or 5), pcf_tent_bilinear, pcf_bilinear_box: taps per side N (odd)."""
    bias_constant: float = 0.0
    """Constant depth bias, metres along the light (negative: away from it, toward acne, as three.js's shadowBias)."""
    bias_slope: float = 1.0
    """Slope-scaled bias in texels: bias += bias_slope · texel · tan(angle(n, -d))."""
    bias_depth_range: float = 0.0
    """Constant depth bias as a fraction of each cascade's light-space depth range, added to bias_constant (Godot 4, Stride)."""
    bias_texels: float = 0.0
    """Constant depth bias in texels of each cascade, added to bias_constant (Unity URP's depth bias)."""
    caster_bias_texels: float = 0.0
    """Casters pushed away from the light by this many texels of each cascade before they are rasterized (Unity URP's depth bias on the caster vertices, ShadowUtils.GetShadowBias)."""
    caster_bias_units: float = 0.0
    """Raster polygon offset, constant part: caster depth pushed away from the light by this many smallest steps of depth_format over each cascade's light-space depth range (Direct3D DepthBias, OpenGL polygon offset units; csmlab.storage.polygon_offset_unit)."""
    caster_bias_slope: float = 0.0
    """Raster polygon offset, slope part: caster depth pushed away from the light by this times each caster triangle's largest depth change over one texel along light-space x or y (Direct3D SlopeScaledDepthBias, OpenGL polygon offset factor)."""
    normal_offset: float = 0.5
    """Receiver offset along its normal, in texels."""
    normal_offset_m: float = 0.0
    """Metres added to the normal offset in every cascade, a world distance (Stride: 2 · NormalOffsetScale / atlas size)."""
    normal_offset_scale: str = "none"
    """The normal offset per receiver: none | one_minus_cos (× 1 − cos θ: URP, Stride) | sin (× sin θ: Filament, Unity built-in) | one_minus_cos_lateral (Godot 4: × 1 − cos θ, across the light only)."""
    receiver_plane_offset: float = 0.0
    """MJP's receiver-plane bias for one hardware compare: the depth pulled toward the light by its tangent plane's change over a texel in x and one in y, at most this fraction of the cascade's depth range (MJP: 0.01); 0: none."""
    receiver_plane_bias: bool = True
    """Compare each filter tap against the receiver's tangent plane at that texel (derivative-based bias)."""
    blend_band: float = 0.0
    """Fraction of a cascade's depth range blended with the next cascade, in [0, 0.5]."""
    transition: str = "backward"
    """blend_band > 0: where each band lies, backward (the last blend_band of cascade i's width, cascade i + 1 reaching back) | far_bound (from (1 - blend_band) z_i+1 to z_i+1: Bevy) | forward (cascade i reaching blend_band of its width past its split: Unreal) (csmlab.cascades.fit.TRANSITION_METHODS)."""
    blend_curve: str = "linear"
    """blend_band > 0: the next cascade's weight over the band, linear | smoothstep (Stride, Godot) (csmlab.cascades.fit.BLEND_CURVES)."""
    subtexel_bits: int = 8
    """Fixed-point bits below a texel for vertices and receivers (docs/design.md, "Exact zero")."""
    depth_bytes: int = 0
    """Bytes per stored depth texel (memory cost only); 0: what depth_format allocates (2, 4, 4)."""
    depth_format: str = "float32"
    """Stored depth: float32 | unorm24 | unorm16, quantized over depth_quantization's range (csmlab.storage)."""
    depth_quantization: str = "scene"
    """depth_format = unorm24 or unorm16: the range its levels divide, scene (the scene's light-space depth span, in power-of-two steps) | cascade (each box's own near/far, as engines store it) (csmlab.storage.DEPTH_QUANTIZATION_METHODS)."""
    storage: str = "array"
    """Texture the cascades live in: array (C slices) | atlas (one texture, atlas_layout)."""
    atlas_layout: str = "2x2"
    """atlas: 2x2 | 1x4 | unigine (2×2, split 1 below split 0), up to 4 cascades, empty tiles allocated."""
    cascade_resolutions: tuple[int, ...] = ()
    """Texels per side of each cascade, one per cascade; empty: resolution for every cascade."""
    filter_sigma: float = 1.0
    """pcf_gaussian with filter_width_m = 0: standard deviation σ of the weights, texels."""
    filter_width_m: float = 0.0
    """pcf_gaussian, pcf_tent, pcf_poisson: filter width in metres, the same in every cascade (Unigine); 0: in texels from filter_size and filter_sigma."""
    poisson_taps: int = 16
    """pcf_poisson: taps of the fixed Poisson disk."""
    poisson_seed: int = 1
    """pcf_poisson: seed of the disk's (deterministic) construction."""
    poisson_rotation: str = "none"
    """pcf_poisson, pcf_vogel: none (one disk everywhere) | pixel (rotated per screen pixel by interleaved gradient noise) | pixel_frame (per pixel and per frame: the noise's pixel offset by 5.588238 · (frame mod 64), Bevy's ShadowFilteringMethod::Temporal) | pixel_taa (pixel_frame under [taa], pixel without it: Godot's taa_frame_count term) (csmlab.filters.ROTATIONS)."""
    cull: str = "none"
    """Faces the depth pass drops, judged in the light's view as OpenGL's glCullFace (counter-clockwise fronts): none (both rasterized) | back (keeps the faces turned toward the light) | front (keeps those turned away: three.js's shadowSide = BackSide) (csmlab.culling.CULL_METHODS)."""
    vogel_taps: int = 5
    """pcf_vogel: taps of the Vogel disk (Godot 4 Soft Low: 4, three.js PCFShadowMap: 5)."""
    vogel_radius: float = 1.0
    """pcf_vogel: radius of the disk in texels (Godot 4 Soft Low: 2.0, three.js LightShadow.radius: 1)."""
    vogel_angle: float = 2.399963229728653
    """pcf_vogel: angle between consecutive taps, radians (three.js: 2.399963229728653, Godot 4: 2.4)."""
    vogel_scale: str = "none"
    """pcf_vogel: none (vogel_radius in every cascade) | first_split (× the first cascade's far end / this cascade's: Godot 4)."""
    light_size_deg: float = 0.53
    """pcss: angular diameter of the light, degrees (the sun: 0.53)."""
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
    """msm: moment bias α in [0, 1), the weight of (0.5, 0.5, 0.5, 0.5) mixed into the moments (MJP's Shadows sample: MSMMomentBias 0.003 × 10⁻³ for float32 moments)."""
    msm_depth_bias: float = 0.0
    """msm: depth bias in normalized depth (a fraction of the scene's light-space depth range) subtracted from the receiver's (MJP: MSMDepthBias, default 0)."""
    moment_mips: bool = False
    """vsm, evsm2, evsm4, msm: look the moments up in a mip chain, trilinear at a level of detail from screen-space derivatives (lod), not bilinear at level 0."""
    lod: str = "quad"
    """moment_mips: derivatives the level of detail comes from: quad (hardware, per 2×2 quad; a seam at splits) | quad_consistent (PSVSM) | analytic (csmlab.quads)."""
    max_lod: int = 3
    """moment_mips: coarsest mip level looked up (the sampler's MaxLOD), 0..8; the boxes keep its reach free inside their edges."""
    anisotropy: int = 1
    """moment_mips: most probes along the footprint's major axis, 1..16 (1: trilinear)."""
    distribution_exponent: float = 3.0
    """split = exponent: depth ratio of consecutive cascades (Unreal's CascadeDistributionExponent)."""
    first_cascade_far: float = 10.0
    """split = geometric: far end of the first cascade in metres, the rest geometric (Bevy's first_cascade_far_bound)."""
    extent: str = "sphere"
    """exact, and quantized with quantized_base = sphere: the fixed box diameter, sphere (slice bounding sphere) | diagonal (ceil of the slice's largest diagonal, Bevy) | diagonal_unrounded (the same unrounded: three.js) | centroid (sphere about the corners' centroid: Godot, Stride) | body_diagonal (the body diagonal alone, unrounded: DirectX CSM11 fit to scene)."""
    snap: str = "origin"
    """exact: what is snapped to whole texels, origin (box corner: Valient, DirectX, Unreal) | centre (box centre floored, the filter margins kept inside) | centre_full (box centre, texel D/R with no filter margin inside: Bevy, three.js) | view (centre in 4-texel steps: Stride view snapping) | nearest2 (edges rounded to the nearest 2-texel unit: Godot) | centre_nearest (box centre rounded to the nearest texel: Stride projection snapping)."""
    light_basis: str = "least_aligned"
    """Light space's right and up about the light axis, where the texel grid lies: least_aligned (csmlab's: the world axis least aligned with the light as up) | world_y (a look-at with world +Y up: three.js, Godot, Bevy, Stride, MJP, DirectX) (csmlab.geometry.LIGHT_BASIS_METHODS)."""
    depth_range: str = "scene"
    """Box depth: scene (near side pushed to the scene bounds) | slice (the slice's own range, less pancake) | sphere (the slice corners' centroid sphere ± radius, less pancake: Godot, Stride) | light_camera (light_near to light_far in front of a light pancake metres from the slice: three.js) | scene_clipped (the scene's bounding box clipped to the cascade's box on x and y: DirectX CSM11)."""
    pancake: float = 0.0
    """depth_range = slice, sphere or light_camera: metres the near side (light_camera: the light) is pulled toward the light beyond the slice (Godot pancake_size, three.js lightMargin)."""
    light_near: float = 1.0
    """depth_range = light_camera: metres in front of the light where its camera's depth range starts (three.js lightNear)."""
    light_far: float = 2000.0
    """depth_range = light_camera: metres in front of the light where its camera's depth range ends (three.js lightFar)."""
    depth_clamp: bool = True
    """depth_range = slice, sphere or light_camera: casters nearer than the near side are flattened onto it (pancaking) rather than clipped."""
    fade_out: float = 0.0
    """Fraction of the shadow distance at its end over which the shadow fades to lit (Unreal, Unity, Godot 1 - fade_start)."""
    fade: str = "linear"
    """fade_out > 0: the fade's shape, linear (in view depth: Unreal) | smoothstep (in view depth: Godot) | radial (linear in the distance to the camera: Unity built-in Stable Fit) | squared_radial (linear in its square: Unity URP) (csmlab.fades.FADE_METHODS)."""
    bounds: str = "frustum"
    """Depth range the splits divide, frustum (near .. shadow_distance) | sdsm (the frame's visible depth range, from the G-buffer)."""
    hysteresis: float = 0.0
    """bounds = sdsm with hold = fraction: the held range grows at once and shrinks only when the visible range is this fraction inside it."""
    hold: str = "fraction"
    """bounds = sdsm: how the visible range is held, fraction (hysteresis) | stepped (Stride: grows in 1.1^k and shrinks in 2^-k steps) (csmlab.cascades.bounds.HOLD_METHODS)."""
    extent_hysteresis: float = 0.0
    """stabilization = none: the tight box's extent grows at once and shrinks only when the tight extent is this fraction below it (csmlab.cascades.stabilize.held_extents)."""
    focus: str = "slice"
    """stabilization = none: what a tight box covers, slice (the view slice) | scene (the slice clipped to the scene's light-space bounds, receivers ∩ casters: Filament's tightly bound scene) (csmlab.cascades.focus)."""
    warp: str = "none"
    """Light projection, none (orthographic boxes) | lispsm (Filament's light-space perspective warp, stabilization = none only) (csmlab.cascades.warp)."""
    lispsm_near_hint: float = 1.0
    """warp = lispsm: metres from the camera where shadow quality is optimized from (Filament's shadowNearHint)."""
    lispsm_far_hint: float = 100.0
    """warp = lispsm: metres from the camera where shadow quality is optimized up to (Filament's shadowFarHint)."""
    engine_precision: str = "float64"
    """Cascade math (light matrices, positions, snapping, depth) as csmlab does it, float64 | float32 (an engine's float32 pipeline on absolute world positions: Godot 4, Unity) | camera_relative (the same relative to an origin rebased near the camera: Unreal 5, HDRP) (csmlab.texels.PRECISION_METHODS)."""
    rebase_distance: float = 0.0
    """engine_precision = camera_relative: metres between the origins the float32 positions are taken from; 0 rebases at the camera every frame (Unreal 5, HDRP), d > 0 to the camera rounded to multiples of d."""
    vertex_snap: str = "world"
    """engine_precision = float64: where vertices and receivers are snapped to 2**-subtexel_bits texels, world (global fixed point less the box origin: world-locked) | window (the window position, the rasterizer's rule: follows a fractional box origin) (csmlab.texels.VERTEX_SNAPS)."""

    def validated(self) -> "ShadowSettings":
        """Return ``self`` after checking every field's range; raise ``ValueError`` naming the field."""
        def need(ok: bool, name: str, expected: str, value) -> None:
            if not ok:
                raise ValueError(f"{name}: expected {expected}, got {value!r}")

        need(isinstance(self.cascades, int) and 1 <= self.cascades <= 10, "cascades", "an integer in 1..10", self.cascades)
        need(isinstance(self.resolution, int) and 16 <= self.resolution <= 16384, "resolution",
             "an integer in 16..16384", self.resolution)
        need(self.shadow_map in SHADOW_MAP_METHODS, "shadow_map", f"one of {list(SHADOW_MAP_METHODS)}", self.shadow_map)
        need(isinstance(self.page_size, int) and self.page_size in _POWERS_OF_TWO and 8 <= self.page_size <= 1024,
             "page_size", "a power of two in 8..1024", self.page_size)
        need(isinstance(self.virtual_resolution, int) and self.virtual_resolution in _POWERS_OF_TWO
             and self.page_size <= self.virtual_resolution <= 65536, "virtual_resolution",
             f"a power of two in page_size ({self.page_size})..65536", self.virtual_resolution)
        need(isinstance(self.clipmap_first_level, int) and -10 <= self.clipmap_first_level <= 30,
             "clipmap_first_level", "an integer in -10..30", self.clipmap_first_level)
        need(isinstance(self.clipmap_last_level, int) and self.clipmap_first_level <= self.clipmap_last_level <= 30
             and self.clipmap_last_level - self.clipmap_first_level < 32, "clipmap_last_level",
             f"an integer in clipmap_first_level ({self.clipmap_first_level})..30, at most 32 levels",
             self.clipmap_last_level)
        need(math.isfinite(self.lod_bias) and -8.0 <= self.lod_bias <= 8.0, "lod_bias", "a number in [-8, 8]",
             self.lod_bias)
        need(isinstance(self.physical_pages, int) and 1 <= self.physical_pages <= 65536, "physical_pages",
             "an integer in 1..65536", self.physical_pages)
        need(self.shadow_map != "virtual_clipmap" or self.filter in CLIPMAP_FILTERS, "filter",
             f"one of {list(CLIPMAP_FILTERS)} with shadow_map = \"virtual_clipmap\" (its page-table lookup)",
             self.filter)
        need(0.0 <= self.lambda_ <= 1.0, "lambda", "a value in [0, 1]", self.lambda_)
        need(all(math.isfinite(z) and z > 0 for z in self.splits)
             and all(a < b for a, b in zip(self.splits, self.splits[1:])), "splits",
             "increasing positive far ends (metres, or fractions of shadow_distance when all ≤ 1)", list(self.splits))
        need(not self.splits or max(self.splits) > 1.0 or math.isclose(self.splits[-1], 1.0, rel_tol=1e-9), "splits",
             "fractions of shadow_distance ending at 1.0 (the last cascade ends at the shadow distance)",
             list(self.splits))
        need(self.shadow_distance > 0, "shadow_distance", "a positive distance in metres", self.shadow_distance)
        need(self.shadow_distance_from != "farthest_visible" or self.bounds == "sdsm", "shadow_distance_from",
             'fixed or camera_far with bounds = "frustum" (farthest_visible reads the visible range of bounds = '
             '"sdsm")', self.shadow_distance_from)
        need(not self.cascade_borders or (len(self.cascade_borders) == self.cascades
                                          and all(0.0 <= b <= 1.0 for b in self.cascade_borders)
                                          and self.cascade_borders[-1] == 0.0), "cascade_borders",
             f"{self.cascades} fractions in [0, 1] (one per cascade), the last 0 (the last cascade's fade to lit is "
             f"fade_out), or an empty list", list(self.cascade_borders))
        need(math.isfinite(self.max_shadow_distance) and self.max_shadow_distance >= 0.0, "max_shadow_distance",
             "a non-negative distance in metres (0: no cap)", self.max_shadow_distance)
        need(self.zoom_policy in ZOOM_POLICIES, "zoom_policy", f"one of {list(ZOOM_POLICIES)}", self.zoom_policy)
        need(math.isfinite(self.min_fov_deg) and 0.0 < self.min_fov_deg < 180.0, "min_fov_deg",
             "a field of view in (0, 180) degrees", self.min_fov_deg)
        need(self.sun_policy in SUN_POLICIES, "sun_policy", f"one of {list(SUN_POLICIES)}", self.sun_policy)
        need(isinstance(self.sun_update_frames, int) and self.sun_update_frames >= 1, "sun_update_frames",
             "a positive whole number of frames", self.sun_update_frames)
        need(math.isfinite(self.sun_step_deg) and 0.0 < self.sun_step_deg <= 90.0, "sun_step_deg",
             "an angle in (0, 90] degrees", self.sun_step_deg)
        need(isinstance(self.levels, int) and self.levels >= 1, "levels", "a positive integer", self.levels)
        need(self.quantized_base in ("sphere", "frustum"), "quantized_base", "sphere or frustum", self.quantized_base)
        need(isinstance(self.filter_size, int) and 1 <= self.filter_size <= 63 and self.filter_size % 2 == 1,
             "filter_size", "an odd integer in 1..63", self.filter_size)
        need(self.bias_constant >= -1.0, "bias_constant",
             "a distance in metres of at least -1 (negative: away from the light, three.js's shadowBias)",
             self.bias_constant)
        need(self.bias_slope >= 0, "bias_slope", "a non-negative number of texels", self.bias_slope)
        need(0.0 <= self.bias_depth_range <= 1.0, "bias_depth_range", "a fraction in [0, 1]", self.bias_depth_range)
        need(0.0 <= self.bias_texels <= 1000.0, "bias_texels", "a number of texels in [0, 1000]", self.bias_texels)
        need(0.0 <= self.caster_bias_texels <= 1000.0, "caster_bias_texels", "a number of texels in [0, 1000]",
             self.caster_bias_texels)
        need(0.0 <= self.caster_bias_units <= 2.0**24, "caster_bias_units", "a number of depth steps in [0, 2^24]",
             self.caster_bias_units)
        need(0.0 <= self.caster_bias_slope <= 1000.0, "caster_bias_slope", "a slope factor in [0, 1000]",
             self.caster_bias_slope)
        need(self.normal_offset_scale in NORMAL_OFFSET_SCALES, "normal_offset_scale",
             f"one of {list(NORMAL_OFFSET_SCALES)}", self.normal_offset_scale)
        need(0.0 <= self.receiver_plane_offset <= 1.0, "receiver_plane_offset", "a fraction in [0, 1]",
             self.receiver_plane_offset)
        need(0.0 <= self.normal_offset_m <= 10.0, "normal_offset_m", "a distance in [0, 10] metres", self.normal_offset_m)
        need(self.normal_offset >= 0, "normal_offset", "a non-negative number of texels", self.normal_offset)
        need(isinstance(self.receiver_plane_bias, bool), "receiver_plane_bias", "true or false",
             self.receiver_plane_bias)
        need(0.0 <= self.blend_band <= 0.5, "blend_band", "a fraction in [0, 0.5]", self.blend_band)
        need(self.filter_sigma > 0, "filter_sigma", "a positive number of texels", self.filter_sigma)
        need(self.filter_width_m >= 0, "filter_width_m", "a non-negative width in metres", self.filter_width_m)
        need(isinstance(self.poisson_taps, int) and 1 <= self.poisson_taps <= 256, "poisson_taps",
             "an integer in 1..256", self.poisson_taps)
        need(isinstance(self.poisson_seed, int) and self.poisson_seed >= 0, "poisson_seed", "a non-negative integer",
             self.poisson_seed)
        need(self.poisson_rotation in ROTATIONS, "poisson_rotation", f"one of {list(ROTATIONS)}", self.poisson_rotation)
        need(self.filter != "pcf_castano" or self.filter_size in CASTANO_SIZES, "filter_size",
             "3 or 5 with filter = \"pcf_castano\" (Castaño's 3×3 and 5×5 kernels)", self.filter_size)
        need(isinstance(self.vogel_taps, int) and 1 <= self.vogel_taps <= 64, "vogel_taps", "an integer in 1..64",
             self.vogel_taps)
        need(0.0 < self.vogel_radius <= 16.0, "vogel_radius", "a radius in (0, 16] texels", self.vogel_radius)
        need(0.0 <= self.vogel_angle <= 2.0 * math.pi, "vogel_angle", "an angle in [0, 2π] radians", self.vogel_angle)
        need(self.vogel_scale in ("none", "first_split"), "vogel_scale", "none or first_split", self.vogel_scale)
        need(0.0 < self.light_size_deg < 90.0, "light_size_deg", "an angle in (0, 90) degrees", self.light_size_deg)
        need(isinstance(self.moment_blur, int) and 1 <= self.moment_blur <= 63 and self.moment_blur % 2 == 1,
             "moment_blur", "an odd integer in 1..63", self.moment_blur)
        need(len(self.evsm_exponents) == 2 and all(0 < c <= 44 for c in self.evsm_exponents), "evsm_exponents",
             "two exponents in (0, 44] (e^(2c) must fit float32)", self.evsm_exponents)
        need(self.vsm_min_variance >= 0, "vsm_min_variance", "a non-negative variance", self.vsm_min_variance)
        need(self.vsm_power > 0, "vsm_power", "a positive exponent", self.vsm_power)
        need(0.0 <= self.vsm_bleed < 1.0, "vsm_bleed", "an amount in [0, 1)", self.vsm_bleed)
        need(0.0 <= self.msm_moment_bias < 1.0, "msm_moment_bias", "a weight in [0, 1)", self.msm_moment_bias)
        need(math.isfinite(self.msm_depth_bias), "msm_depth_bias", "a finite normalized depth", self.msm_depth_bias)
        need(isinstance(self.moment_mips, bool), "moment_mips", "true or false", self.moment_mips)
        need(self.lod in ("quad", "quad_consistent", "analytic"), "lod", "quad, quad_consistent or analytic", self.lod)
        need(isinstance(self.max_lod, int) and 0 <= self.max_lod <= 8, "max_lod", "an integer in 0..8", self.max_lod)
        need(isinstance(self.anisotropy, int) and 1 <= self.anisotropy <= 16, "anisotropy", "an integer in 1..16",
             self.anisotropy)
        need(isinstance(self.depth_bytes, int) and 0 <= self.depth_bytes <= 16, "depth_bytes",
             "an integer in 0..16 (0: from depth_format)", self.depth_bytes)
        need(self.depth_format in ("float32", "unorm24", "unorm16"), "depth_format", "float32, unorm24 or unorm16",
             self.depth_format)
        need(self.storage in ("array", "atlas"), "storage", "array or atlas", self.storage)
        need(self.atlas_layout in ("2x2", "1x4", "unigine"), "atlas_layout", "2x2, 1x4 or unigine", self.atlas_layout)
        need(self.storage != "atlas" or self.cascades <= 4, "storage", "array for more than 4 cascades (an atlas "
             "layout holds 4 tiles)", self.storage)
        need(not self.cascade_resolutions or (len(self.cascade_resolutions) == self.cascades and all(
            isinstance(r, int) and 16 <= r <= 16384 for r in self.cascade_resolutions)), "cascade_resolutions",
             f"{self.cascades} integers in 16..16384 (one per cascade) or an empty list", self.cascade_resolutions)
        need(isinstance(self.subtexel_bits, int) and 0 <= self.subtexel_bits <= 16, "subtexel_bits",
             "an integer in 0..16", self.subtexel_bits)
        need(1.0 <= self.distribution_exponent <= 100.0, "distribution_exponent",
             "a ratio of at least 1 and at most 100", self.distribution_exponent)
        need(self.first_cascade_far > 0, "first_cascade_far", "a positive distance in metres", self.first_cascade_far)
        need(self.pancake >= 0, "pancake", "a non-negative distance in metres", self.pancake)
        need(0.0 <= self.light_near < self.light_far, "light_near", f"a distance in metres in [0, light_far = "
             f"{self.light_far})", self.light_near)
        need(isinstance(self.depth_clamp, bool), "depth_clamp", "true or false", self.depth_clamp)
        need(self.cull in CULL_METHODS, "cull", f"one of {list(CULL_METHODS)}", self.cull)
        need(0.0 <= self.fade_out <= 1.0, "fade_out", "a fraction in [0, 1]", self.fade_out)
        need(0.0 <= self.hysteresis < 1.0, "hysteresis", "a fraction in [0, 1)", self.hysteresis)
        need(0.0 <= self.extent_hysteresis < 1.0, "extent_hysteresis", "a fraction in [0, 1)", self.extent_hysteresis)
        need(self.focus in ("slice", "scene"), "focus", "slice or scene", self.focus)
        need(self.warp in ("none", "lispsm"), "warp", "none or lispsm", self.warp)
        need(self.warp == "none" or self.stabilization == "none", "warp",
             'none with a stabilized box (Filament: "We can\'t use LISPSM in stable mode"); lispsm needs '
             'stabilization = "none"', self.warp)
        need(self.warp == "none" or self.engine_precision == "float64", "warp",
             'none with engine_precision = "float32" (the warp is computed in float64)', self.warp)
        need(0.0 <= self.lispsm_near_hint < self.lispsm_far_hint, "lispsm_near_hint",
             "a distance in metres of at least 0 and below lispsm_far_hint", self.lispsm_near_hint)
        need(math.isfinite(self.rebase_distance) and self.rebase_distance >= 0.0, "rebase_distance",
             "a non-negative distance in metres (0: rebased at the camera every frame)", self.rebase_distance)
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

    def replace(self, **changes) -> "ShadowSettings":
        """A copy with ``changes`` applied (TOML name ``lambda`` accepted for ``lambda_``)."""
        if "lambda" in changes:
            changes["lambda_"] = changes.pop("lambda")
        return replace(self, **changes)

    @classmethod
    def field_names(cls) -> list[str]:
        """Field names as a TOML file spells them (``lambda``, not ``lambda_``)."""
        return ["lambda" if f.name == "lambda_" else f.name for f in fields(cls)]


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


def _filters(test: Callable[[str], bool], why: str) -> Applies:
    """The field takes effect with the filters ``test`` accepts (named in the condition): ``why``."""
    names = [f'"{name}"' for name in FILTER_METHODS if test(name)]
    listed = f"{', '.join(names[:-1])} or {names[-1]}" if len(names) > 1 else names[0]
    return Applies(lambda *, filter: test(filter), f"filter = {listed} ({why})")


def _moment_mips(*, filter: str, moment_mips: bool) -> bool:
    return _family(filter) == "moment" and moment_mips


def _clipmap(why: str) -> Applies:
    """The field takes effect in a virtual clipmap: ``why``."""
    return Applies(lambda *, shadow_map: shadow_map == "virtual_clipmap", f'shadow_map = "virtual_clipmap" ({why})')


APPLIES: dict[str, Applies] = {
    "lambda": Applies(lambda *, split: split == "practical", 'split = "practical" (the blend of log and uniform splits)'),
    "virtual_resolution": _clipmap("the texels per side of each level"),
    "page_size": _clipmap("the texels per side of a page"),
    "clipmap_first_level": _clipmap("its finest level"),
    "clipmap_last_level": _clipmap("its coarsest level"),
    "lod_bias": _clipmap("the bias of its level choice"),
    "physical_pages": _clipmap("its page pool"),
    "splits": Applies(lambda *, split: split in ("manual", "manual_range"),
                      'split = "manual" or "manual_range" (the far end of each cascade)'),
    "distribution_exponent": Applies(lambda *, split: split == "exponent",
                                     'split = "exponent" (the depth ratio of consecutive cascades)'),
    "first_cascade_far": Applies(lambda *, split: split == "geometric", 'split = "geometric" (the first far end)'),
    "shadow_distance": Applies(lambda *, shadow_distance_from: shadow_distance_from == "fixed",
                               'shadow_distance_from = "fixed" (a number of metres; "camera_far" and '
                               '"farthest_visible" end each frame where the camera or its view ends)'),
    "max_shadow_distance": Applies(lambda *, shadow_distance_from: shadow_distance_from != "fixed",
                                   'shadow_distance_from = "camera_far" or "farthest_visible" (the cap on where '
                                   'they end)'),
    "cascade_borders": Applies(lambda *, selection: selection == "sphere_dither",
                               'selection = "sphere_dither" (the borders it dithers over)'),
    "levels": Applies(lambda *, stabilization: stabilization == "quantized",
                      'stabilization = "quantized" (the steps an extent is rounded up to)'),
    "quantized_base": Applies(lambda *, stabilization: stabilization == "quantized",
                              'stabilization = "quantized" (the extent its steps divide)'),
    "extent": Applies(lambda *, stabilization, quantized_base: stabilization == "exact" or (
        stabilization == "quantized" and quantized_base == "sphere"),
        'stabilization = "exact", or "quantized" with quantized_base = "sphere" (the fixed box diameter)'),
    "snap": Applies(lambda *, stabilization: stabilization == "exact",
                    'stabilization = "exact" (what its fixed box snaps to whole texels)'),
    "extent_hysteresis": Applies(lambda *, stabilization, warp, focus: stabilization == "none" and warp == "none"
                                 and focus == "slice",
                                 'stabilization = "none" with warp = "none" and focus = "slice" (a stabilized box '
                                 'already has a fixed extent; a warped map is focused every frame; the held extent '
                                 'is the slice\'s)'),
    "zoom_policy": Applies(lambda *, shadow_map: shadow_map == "cascades",
                           'shadow_map = "cascades" (a virtual clipmap\'s levels do not follow the slices)'),
    "min_fov_deg": Applies(lambda *, shadow_map, zoom_policy: shadow_map == "cascades" and zoom_policy == "min_fov",
                           'zoom_policy = "min_fov" with shadow_map = "cascades" (the field of view it floors)'),
    "sun_update_frames": Applies(lambda *, sun_policy: sun_policy == "every_n",
                                 'sun_policy = "every_n" (the frames between updates)'),
    "sun_step_deg": Applies(lambda *, sun_policy: sun_policy == "quantized",
                            'sun_policy = "quantized" (the step the sun\'s angles are rounded to)'),
    "focus": Applies(lambda *, stabilization: stabilization == "none",
                     'stabilization = "none" (what its tight box covers)'),
    "lispsm_near_hint": Applies(lambda *, warp, stabilization: warp == "lispsm" and stabilization == "none",
                                'warp = "lispsm" with stabilization = "none" (its virtual near plane)'),
    "lispsm_far_hint": Applies(lambda *, warp, stabilization: warp == "lispsm" and stabilization == "none",
                               'warp = "lispsm" with stabilization = "none" (its virtual far plane)'),
    "rebase_distance": Applies(lambda *, engine_precision: engine_precision == "camera_relative",
                               'engine_precision = "camera_relative" (how often its origin is rebased)'),
    "vertex_snap": Applies(lambda *, engine_precision: engine_precision == "float64",
                           'engine_precision = "float64" (a float32 pipeline snaps its window position)'),
    "pancake": Applies(lambda *, depth_range: depth_range in ("slice", "sphere", "light_camera"),
                       'depth_range = "slice", "sphere" or "light_camera" (the pull of its near side toward the light)'),
    "light_near": Applies(lambda *, depth_range: depth_range == "light_camera",
                          'depth_range = "light_camera" (where its camera\'s range starts)'),
    "light_far": Applies(lambda *, depth_range: depth_range == "light_camera",
                         'depth_range = "light_camera" (where its camera\'s range ends)'),
    "depth_clamp": Applies(lambda *, depth_range: depth_range in ("slice", "sphere", "light_camera"),
                           'depth_range = "slice", "sphere" or "light_camera" (casters nearer than its near side)'),
    "transition": Applies(lambda *, blend_band: blend_band > 0, "blend_band > 0 (where its bands lie)"),
    "blend_curve": Applies(lambda *, blend_band: blend_band > 0, "blend_band > 0 (the weight over its bands)"),
    "fade": Applies(lambda *, fade_out: fade_out > 0, "fade_out > 0 (the shape of the far fade)"),
    "hysteresis": Applies(lambda *, bounds, hold: bounds == "sdsm" and hold == "fraction",
                          'bounds = "sdsm" with hold = "fraction" (the hold of its visible range)'),
    "hold": Applies(lambda *, bounds: bounds == "sdsm", 'bounds = "sdsm" (how its visible range is held)'),
    "depth_quantization": Applies(lambda *, depth_format: depth_format != "float32",
                                  'depth_format = "unorm24" or "unorm16" (the range its levels divide)'),
    "atlas_layout": Applies(lambda *, storage: storage == "atlas", 'storage = "atlas" (the tiles of the atlas)'),
    "filter_size": _filters(lambda f: f == "pcf" or (_family(f) == "weighted" and f != "pcf_vogel"), "taps per side"),
    "filter_sigma": Applies(lambda *, filter, filter_width_m: filter == "pcf_gaussian" and filter_width_m == 0,
                            'filter = "pcf_gaussian" and filter_width_m = 0 (σ in texels; a width in metres sets '
                            'σ otherwise)'),
    "filter_width_m": _filters(lambda f: f in ("pcf_gaussian", "pcf_tent", "pcf_poisson"), "the width in metres"),
    "poisson_taps": _filters(lambda f: f == "pcf_poisson", "the taps of its disk"),
    "poisson_seed": _filters(lambda f: f == "pcf_poisson", "the seed of its disk"),
    "poisson_rotation": _filters(lambda f: f in ("pcf_poisson", "pcf_vogel"), "the rotation of its disk"),
    "vogel_taps": _filters(lambda f: f == "pcf_vogel", "the taps of its disk"),
    "vogel_radius": _filters(lambda f: f == "pcf_vogel", "the radius of its disk"),
    "vogel_angle": _filters(lambda f: f == "pcf_vogel", "the angle between its taps"),
    "vogel_scale": _filters(lambda f: f == "pcf_vogel", "its radius per cascade"),
    "light_size_deg": _filters(lambda f: f == "pcss", "the light's size that sets the penumbra"),
    "moment_blur": _filters(lambda f: _family(f) == "moment", "the blur of the moments"),
    "evsm_exponents": _filters(lambda f: f in ("evsm2", "evsm4"), "the exponents of the warps"),
    "vsm_min_variance": _filters(lambda f: _family(f) == "moment" and f != "msm", "the variance floor of the Chebyshev bound"),
    "vsm_power": _filters(lambda f: _family(f) == "moment", "a light-bleeding reduction"),
    "vsm_bleed": _filters(lambda f: _family(f) == "moment", "a light-bleeding reduction"),
    "msm_moment_bias": _filters(lambda f: f == "msm", "the moment bias of the Hamburger bound"),
    "msm_depth_bias": _filters(lambda f: f == "msm", "the depth bias of the Hamburger bound"),
    "moment_mips": _filters(lambda f: _family(f) == "moment", "the moments' mip chain"),
    "lod": Applies(_moment_mips, "a moment filter with moment_mips = true (the mip chain's level of detail)"),
    "max_lod": Applies(_moment_mips, "a moment filter with moment_mips = true (the mip chain's coarsest level)"),
    "anisotropy": Applies(_moment_mips, "a moment filter with moment_mips = true (the probes along the footprint)"),
}
"""The ``[shadow]`` fields that take effect only with some settings (TOML names), and where; every other
field takes effect in every method. The config loader refuses a field written where it does not apply."""
