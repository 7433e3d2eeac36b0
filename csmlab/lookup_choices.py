"""The shadow lookup's choices by name: one record per cascade selection and one per filter.

A :class:`Filter` is everything csmlab knows about one ``[shadow] filter`` value: its family (which
kernel runs it, :data:`FAMILIES`), the integer code that kernel switches on, the texels its taps
reach and the width of its weights as functions of the settings, its tap offsets, what it reads
besides the depth map, and what it does in words. :data:`FILTER_METHODS` maps every name to its
record and :data:`SELECTION_METHODS` does the same for cascade selection. The lookup
(:mod:`csmlab.filters`), the kernels (:mod:`csmlab.kernels.shadow`, :mod:`csmlab.kernels.pcf`,
:mod:`csmlab.kernels.moments`), :attr:`csmlab.settings.ShadowSettings.margin_texels`, the engine
export and the config loader all read these tables; nothing else decides what a filter is.

A record's functions read the ``[shadow]`` fields they declare as keyword-only parameters (their
declaration is the list of fields a filter depends on), taken from a
:class:`~csmlab.settings.ShadowSettings` by :meth:`Filter.radius_of`, :meth:`Filter.width_of`,
:meth:`Filter.offsets_of` and :meth:`Filter.reads_of`.

The kernels switch on the integer constants below; Warp compiles a comparison with a module-level
``int`` into the kernel, so they stay plain constants, each named once here and held by its record.

This module imports neither Warp nor the kernels (NumPy only), so the settings and the config
loader use it without compiling anything.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from csmlab.registry import check_name, parameters

__all__ = ["BLEND_LINEAR", "BLEND_SMOOTHSTEP", "BOX_BILINEAR", "BOX_TAPS", "CASTANO_SIZES", "NORMAL_NONE",
           "NORMAL_OFFSET_SCALES", "NORMAL_ONE_MINUS_COS", "ROTATIONS", "NORMAL_ONE_MINUS_COS_LATERAL", "NORMAL_SIN",
           "FAMILIES", "FILTER_METHODS", "Filter", "MOMENT_EVSM2", "OUTSIDE_METHODS", "MOMENT_EVSM4", "MOMENT_MSM",
           "MOMENT_VSM", "PCF_BILINEAR_BOX", "PCF_CASTANO", "PCF_GAUSSIAN", "PCF_PCSS", "PCF_POISSON", "PCF_TENT",
           "PCF_TENT_BILINEAR", "PCF_VOGEL", "SELECTION_METHODS", "SELECT_BEST_RESOLUTION", "SELECT_INTERVAL",
           "SELECT_MAP", "SELECT_SPHERE", "Selection", "family_code", "family_filters", "poisson_disk", "vogel_disk",
           "GODOT_SOFT_SHADOW_QUALITIES", "GodotSoftShadowQuality", "godot_soft_shadow_fields"]

SELECT_INTERVAL = 0
"""Selection code: the cascade whose split interval holds the view depth."""
SELECT_MAP = 1
"""Selection code: the first cascade whose box holds the point inside its margins."""
SELECT_BEST_RESOLUTION = 2
"""Selection code: of the boxes that hold the point, the one with the smallest texels."""
SELECT_SPHERE = 3
"""Selection code: the first cascade whose split sphere holds the point (Unity)."""

BLEND_LINEAR = 0
"""Blend-curve code: the next cascade's weight rises linearly over the band."""
BLEND_SMOOTHSTEP = 1
"""Blend-curve code: the weight is ``smoothstep`` of the linear one, ``w² (3 - 2w)`` (Stride, Godot, MJP)."""

BOX_TAPS = 0
"""Box family code: the (2r + 1)² texels centred on the one holding the point, equal weights (r = 0: one texel)."""
BOX_BILINEAR = 1
"""Box family code: the 2×2 texels around the point, bilinear weights."""

PCF_GAUSSIAN = 0
"""Weighted family code: Gaussian weights (:func:`csmlab.kernels.pcf.weighted_pcf`)."""
PCF_TENT = 1
"""Weighted family code: tent weights integrated over each texel."""
PCF_POISSON = 2
"""Weighted family code: equal weights at the offsets of a Poisson disk."""
PCF_PCSS = 3
"""Weighted family code: blocker search, then a tent as wide as the penumbra."""
PCF_VOGEL = 4
"""Weighted family code: hardware bilinear-compare taps on a Vogel disk, equal weights (Godot 4, three.js)."""
PCF_CASTANO = 5
"""Weighted family code: Castaño's kernels of hardware bilinear-compare taps (Filament, Bevy, Stride, MJP)."""
PCF_TENT_BILINEAR = 6
"""Weighted family code: a tent folded into hardware bilinear-compare taps, two texels per tap and axis (Unity)."""
PCF_BILINEAR_BOX = 7
"""Weighted family code: N×N hardware bilinear-compare taps a whole texel apart, equal weights (DirectX CSM11)."""

NORMAL_NONE = 0
"""Normal-offset code: ``normal_offset`` texels along the full normal."""
NORMAL_ONE_MINUS_COS = 1
"""Normal-offset code: times ``1 − max(0, cos θ)`` (Unity URP, Stride, MJP)."""
NORMAL_SIN = 2
"""Normal-offset code: times ``sin θ`` (Filament, Unity built-in)."""
NORMAL_ONE_MINUS_COS_LATERAL = 3
"""Normal-offset code: times ``1 − max(0, −cos θ)`` (1 on every lit face), its component along the light removed
(Godot 4)."""

NORMAL_OFFSET_SCALES: dict[str, int] = {"none": NORMAL_NONE, "one_minus_cos": NORMAL_ONE_MINUS_COS, "sin": NORMAL_SIN,
                                        "one_minus_cos_lateral": NORMAL_ONE_MINUS_COS_LATERAL}
"""The ``[shadow] normal_offset_scale`` values by name, with the code the receiver conversion switches on.

θ is the angle between the receiver's normal and the direction toward the light. ``one_minus_cos``:
Unity URP ``ApplyShadowBias`` (``1 − saturate(dot(L, N))``), Stride ``GetShadowPositionOffset``
(``saturate(1 − N·L)``), MJP ``GetShadowPosOffset``; ``sin``: Filament
``computeLightSpacePosition`` (``n · sinθ · b``), Unity built-in ``UnityClipSpaceShadowCasterPos``
(``sqrt(1 − cos²)``); ``one_minus_cos_lateral``: Godot 4 (``scene_forward_clustered.glsl``
``light_process``: ``base_normal_bias = N · (1 − max(0, dot(light_dir, −N)))``, then
``normal_bias −= light_dir · dot(light_dir, normal_bias)``), which moves the receiver across the light
only, never along it. Godot's ``light_dir`` points *toward* the light (``light_storage.cpp``
``update_light_buffers``: the light's +Z, ``basis.xform(Vector3(0, 0, 1))``), so ``dot(light_dir, −N)
= −cos θ`` and every lit face takes the whole offset: ``sin θ`` of it across the light (1.53 texels
of Godot's 2 on flat ground under a 40° sun).
"""

CASTANO_SIZES = (3, 5)
"""The filter_size values of ``pcf_castano``: Castaño's 3×3 kernel (4 taps) and 5×5 kernel (9 taps)."""


@dataclass(frozen=True)
class GodotSoftShadowQuality:
    """One level of Godot 4's ``rendering/lights_and_shadows/directional_shadow/soft_shadow_filter_quality``.

    Attributes
    ----------
    name : str
        The level as Godot's ``RS::ShadowQuality`` names it, lower case.
    samples : int
        ``directional_soft_shadow_samples``: Vogel-disk taps, each a hardware bilinear compare; 0 is one
        compare at the point (``sample_directional_pcf_shadow``: "if only one sample is taken, take it
        from the center").
    radius : float
        ``directional_shadow_quality_radius``: the disk's radius in texels per unit of the light's
        ``shadow_blur`` (``soft_shadow_scale = shadow_blur · quality_radius`` for PCF).
    """

    name: str
    samples: int
    radius: float


GODOT_SOFT_SHADOW_QUALITIES: dict[int, GodotSoftShadowQuality] = {
    0: GodotSoftShadowQuality("hard", 0, 1.0), 1: GodotSoftShadowQuality("soft_very_low", 1, 1.5),
    2: GodotSoftShadowQuality("soft_low", 4, 2.0), 3: GodotSoftShadowQuality("soft_medium", 8, 2.0),
    4: GodotSoftShadowQuality("soft_high", 16, 3.0), 5: GodotSoftShadowQuality("soft_ultra", 32, 4.0)}
"""Godot 4's directional soft-shadow levels by their project-setting value (``RendererSceneRenderRD::
directional_soft_shadow_filter_set_quality``: samples and quality radius per ``RS::SHADOW_QUALITY_*``; the disk
from ``get_vogel_disk``, golden angle 2.4, ``r = sqrt(i + 0.5) / sqrt(n)``)."""


def godot_soft_shadow_fields(quality: int, *, blur: float = 1.0) -> dict:
    """The ``[shadow]`` filter fields of Godot 4's soft-shadow level ``quality`` (0 Hard … 5 Ultra) and its light's
    ``shadow_blur``: ``pcf_bilinear`` (one hardware compare) for Hard, else ``pcf_vogel`` with the level's taps and
    radius × blur at Godot's golden angle 2.4 (:data:`GODOT_SOFT_SHADOW_QUALITIES`).

    Raises
    ------
    ValueError
        For a level that is not 0..5 or a blur that is not positive.
    """
    if quality not in GODOT_SOFT_SHADOW_QUALITIES or isinstance(quality, bool):
        raise ValueError(f"soft_shadow_filter_quality: expected one of {sorted(GODOT_SOFT_SHADOW_QUALITIES)} (Hard … "
                         f"Ultra), got {quality!r}")
    if not blur > 0.0:
        raise ValueError(f"shadow_blur: expected a positive blur, got {blur!r}")
    level = GODOT_SOFT_SHADOW_QUALITIES[quality]
    if level.samples == 0:
        return {"filter": "pcf_bilinear"}
    return {"filter": "pcf_vogel", "vogel_taps": level.samples, "vogel_radius": level.radius * blur, "vogel_angle": 2.4}

MOMENT_VSM = 0
"""Moment family code: ``(z, z²)`` (:mod:`csmlab.kernels.moments`)."""
MOMENT_EVSM2 = 1
"""Moment family code: the positive exponential warp."""
MOMENT_EVSM4 = 2
"""Moment family code: the positive and negative exponential warps."""
MOMENT_MSM = 3
"""Moment family code: four power moments ``(z, z², z³, z⁴)``, Hamburger reconstruction (Peters and Klein 2015)."""


@dataclass(frozen=True)
class Selection:
    """One cascade selection method.

    Attributes
    ----------
    name : str
        The ``[shadow] selection`` value.
    code : int
        What :func:`csmlab.kernels.shadow.shadow_lookup_kernel` switches on.
    description : str
    """

    name: str
    code: int
    description: str


SELECTION_METHODS: dict[str, Selection] = {s.name: s for s in (
    Selection("interval", SELECT_INTERVAL, "the cascade whose split interval holds the view depth"),
    Selection("map", SELECT_MAP, "the first cascade whose box holds the point, less the margin"),
    Selection("best_resolution", SELECT_BEST_RESOLUTION,
              "of the boxes that hold the point, the one with the smallest texels (seed 003)"),
    Selection("sphere", SELECT_SPHERE, "the first cascade whose split sphere holds the point (Unity built-in "
              "Stable Fit getCascadeWeights_splitSpheres, URP ComputeCascadeIndex)"),
    Selection("sphere_dither", SELECT_SPHERE, "the first cascade whose split sphere holds the point, the next one "
              "where the pixel's interleaved gradient noise is at most its border weight (Unity HDRP "
              "EvalShadow_GetSplitIndex, EvalShadow_CascadedDepth_Dither_SplitIndex; cascade_borders, "
              "csmlab.cascades.borders)"),
)}
"""Cascade selection methods by name."""

OUTSIDE_METHODS: dict[str, str] = {
    "none": "no cascade: no shadow value, the point left out of the measures (csmlab's own)",
    "lit": "shaded as lit, S = 1 (Bevy shadows.wesl fetch_directional_shadow: cascade_index >= num_cascades, or a "
           "point outside the cascade's box, returns 1.0)",
    "last": "the interval selection keeps the last cascade beyond the last split (Stride ShadowMapReceiverDirectional: "
            "the index stops at TCascadeCount - 1; MJP Mesh.hlsl ShadowVisibility: cascadeIdx starts at "
            "NumCascades - 1)",
}
"""What a point that no cascade's selection holds is given, by name (``[shadow] outside``)."""

FAMILIES: dict[str, str] = {
    "box": "equal or bilinear weights over whole texels, run by the selection kernel itself (csmlab.kernels.shadow)",
    "weighted": "weighted percentage-closer filtering at the selected cascade (csmlab.kernels.pcf)",
    "moment": "Chebyshev's bound (or MSM's Hamburger bound) of filtered depth moments at the selected cascade "
              "(csmlab.kernels.moments)",
}
"""Filter families by name: which kernel runs a filter after (or with) the cascade selection."""


def _depth_only() -> frozenset:
    return frozenset({"depth"})


def _call(function: Callable, settings, *args):
    """``function(*args, **{each field it declares: settings.field})``."""
    return function(*args, **{name: getattr(settings, name) for name in parameters(function)})


@dataclass(frozen=True)
class Filter:
    """One shadow filter.

    Attributes
    ----------
    name : str
        The ``[shadow] filter`` value.
    family : str
        A key of :data:`FAMILIES`.
    code : int
        What the family's kernel switches on.
    description : str
        What it does, in a line.
    taps : str
        Which texels it tests and how it weighs them.
    radius : callable
        ``radius(*, <fields>) -> int``: texels the taps reach beyond the texel holding the point
        (the boxes keep them inside their edges, so no tap is ever clamped; docs/design.md "Exact zero").
    width : callable, optional
        ``width(texel, far, /, *, <fields>) -> ndarray``: the width of the weights per cascade from the
        cascades' texel sizes ``(C,)`` in metres (the larger side) and their far split ends ``(C,)``
        in metres of view depth; None where the taps set it.
    offsets : callable, optional
        ``offsets(*, <fields>) -> ndarray (K, 2)``: tap offsets in the unit disk; None where the
        taps are whole texels.
    reads : callable
        ``reads(*, <fields>) -> frozenset``: what the lookup needs besides the receivers, of
        ``depth`` (the depth maps), ``moments`` (their moments), ``mips`` (the moments' mip chain
        and every receiver's pixel quad) and ``pixels`` (each receiver's pixel: a per-pixel rotation).
    hard : bool
        One depth test per receiver, no filtering: a hard shadow.
    """

    name: str
    family: str
    code: int
    description: str
    taps: str
    radius: Callable[..., int]
    width: Callable[..., np.ndarray] | None = None
    offsets: Callable[..., np.ndarray] | None = None
    reads: Callable[..., frozenset] = _depth_only
    hard: bool = False

    def radius_of(self, settings) -> int:
        """Texels the taps reach under ``settings`` (a ShadowSettings, or anything with the fields ``radius`` reads)."""
        return _call(self.radius, settings)

    def width_of(self, texel, settings, far=None) -> np.ndarray | None:
        """The weights' width ``(C,)`` for texel sizes ``texel`` ``(C,)`` in metres and the cascades' far split
        ends ``far`` ``(C,)`` (metres; None: the width must not need them); None where the filter has none."""
        if self.width is None:
            return None
        texel = np.asarray(texel, dtype=np.float64)
        ends = np.full(texel.shape, np.nan) if far is None else np.asarray(far, dtype=np.float64)
        return _call(self.width, settings, texel, ends)

    def offsets_of(self, settings) -> np.ndarray | None:
        """Tap offsets ``(K, 2)`` in the unit disk; None where the taps are whole texels."""
        return None if self.offsets is None else _call(self.offsets, settings)

    def reads_of(self, settings) -> frozenset:
        """What the lookup of this filter reads under ``settings`` (see :attr:`reads`)."""
        return _call(self.reads, settings)


def _no_reach() -> int:
    return 0


def _half(*, filter_size: int) -> int:
    return filter_size // 2


def _one() -> int:
    return 1


def _half_and_one(*, filter_size: int) -> int:
    # A width of N/2 texels around a point anywhere in its texel reaches one texel further.
    return filter_size // 2 + 1


def _moment_reach(*, moment_blur: int, moment_mips: bool, max_lod: int, anisotropy: int) -> int:
    """A bilinear lookup reads one texel beyond the point, each blurred from ``moment_blur // 2`` more.

    With mips a bilinear lookup at level l reads within 1.5 · 2^l texels of its probe, and the
    probes spread over at most ``(anisotropy − 1) / 2 · 2^max_lod`` texels on each side
    (csmlab.kernels.moments): ``⌈(anisotropy + 2) / 2 · 2^max_lod⌉``.
    """
    if moment_mips:
        return -(-(anisotropy + 2) * 2**max_lod // 2) + moment_blur // 2
    return moment_blur // 2 + 1


def _gaussian_width(texel, far, /, *, filter_width_m: float, filter_sigma: float) -> np.ndarray:
    """σ in texels: ``filter_sigma``, or a quarter of ``filter_width_m`` (±2σ) in every cascade's texels."""
    if filter_width_m > 0:
        return filter_width_m / 4.0 / texel
    return np.full(texel.shape, filter_sigma)


def _half_width(texel, far, /, *, filter_width_m: float, filter_size: int) -> np.ndarray:
    """Half-width in texels: N/2, or half of ``filter_width_m`` in every cascade's texels, capped at N/2.

    The width in metres is Unigine's (seed 003, "self-adjusting filtering kernel size", Listing 4.1.8).
    """
    half = filter_size / 2.0
    if filter_width_m > 0:
        # A width of zero texels is no filter; the narrowest kept is a hundredth of a texel.
        return np.clip(filter_width_m / 2.0 / texel, 0.01, half)
    return np.full(texel.shape, half)


def _penumbra_per_metre(texel, far, /, *, light_size_deg: float) -> np.ndarray:
    """Penumbra texels per metre between blocker and receiver, ``2 tan(θ_L / 2) / texel``."""
    return np.full(texel.shape, 2.0 * np.tan(np.radians(light_size_deg) / 2.0)) / texel


@functools.lru_cache(maxsize=16)
def _disk(taps: int, seed: int) -> tuple:
    rng = np.random.default_rng(seed)
    points = np.zeros((0, 2))
    for _ in range(taps):
        # Mitchell's best candidate: of 30 uniform candidates in the disk, keep the one farthest
        # from the taps so far — a blue-noise (Poisson-disk-like) set, fixed by the seed.
        r = np.sqrt(rng.random(30))
        a = 2.0 * np.pi * rng.random(30)
        candidates = np.column_stack([r * np.cos(a), r * np.sin(a)])
        if len(points):
            gap = np.min(np.linalg.norm(candidates[:, None] - points[None], axis=2), axis=1)
            best = candidates[np.argmax(gap)]
        else:
            best = candidates[0]
        points = np.vstack([points, best])
    return tuple(map(tuple, points))


def poisson_disk(taps: int, *, seed: int) -> np.ndarray:
    """A fixed Poisson-disk-like set of ``taps`` offsets ``(taps, 2)`` in the unit disk, the same for the same seed."""
    if not (isinstance(taps, (int, np.integer)) and taps >= 1):
        raise ValueError(f"taps: expected a positive integer, got {taps!r}")
    return np.array(_disk(int(taps), int(seed)), dtype=np.float64)


def _poisson_offsets(*, poisson_taps: int, poisson_seed: int) -> np.ndarray:
    return poisson_disk(poisson_taps, seed=poisson_seed)


def vogel_disk(taps: int, *, angle: float) -> np.ndarray:
    """The Vogel disk of ``taps`` offsets ``(taps, 2)`` in the unit disk: tap i at radius ``sqrt((i + 0.5) / taps)``,
    angle ``i · angle``.

    Godot 4 (``RendererSceneRenderRD::get_vogel_disk``: ``r = sqrt(i + 0.5) / sqrt(n)``,
    ``theta = i · golden_angle`` with ``golden_angle = 2.4``) and three.js r182+
    (``shadowmap_pars_fragment`` ``vogelDiskSample``: ``r = sqrt((i + 0.5) / n)``,
    ``theta = i · 2.399963229728653 + phi``).
    """
    if not (isinstance(taps, (int, np.integer)) and taps >= 1):
        raise ValueError(f"taps: expected a positive integer, got {taps!r}")
    i = np.arange(int(taps), dtype=np.float64)
    r = np.sqrt((i + 0.5) / float(taps))
    theta = i * float(angle)
    return np.column_stack([r * np.cos(theta), r * np.sin(theta)])


def _vogel_offsets(*, vogel_taps: int, vogel_angle: float) -> np.ndarray:
    return vogel_disk(vogel_taps, angle=vogel_angle)


def _vogel_reach(*, vogel_radius: float) -> int:
    # A bilinear tap at most vogel_radius texels from the point reads one texel beyond the texel it falls in.
    return int(np.ceil(vogel_radius)) + 1


def _vogel_width(texel, far, /, *, vogel_radius: float, vogel_scale: str) -> np.ndarray:
    """The disk's radius in texels per cascade: ``vogel_radius``, times ``far_0 / far_k`` with ``first_split``.

    Godot 4 (``scene_forward_lights_inc.glsl``, directional lights without ``blend_splits``): the
    radius is ``directional_shadow_pixel_size · soft_shadow_scale · blur_factor`` with
    ``blur_factor = shadow_split_offsets.x / shadow_split_offsets[k]`` ("Adjust shadow blur with
    reference to the first split").
    """
    if vogel_scale == "first_split":
        if not np.all(np.isfinite(far)):
            raise ValueError("far: vogel_scale = \"first_split\" needs the cascades' far split ends")
        return vogel_radius * far[0] / far
    return np.full(texel.shape, float(vogel_radius))


def _half_size(texel, far, /, *, filter_size: int) -> np.ndarray:
    """N / 2 texels in every cascade: the kernel's size, which its taps and weights follow."""
    return np.full(texel.shape, filter_size / 2.0)


def _castano_reach(*, filter_size: int) -> int:
    # Castaño's taps sit around the texel corner nearest the point, up to N/2 + ½ texels from it.
    return filter_size // 2 + 1


ROTATIONS = ("none", "pixel", "pixel_frame", "pixel_taa")
"""The rotations of a Poisson or Vogel disk (``poisson_rotation``): none; per screen pixel by interleaved
gradient noise; per pixel and per frame (the noise's pixel offset by 5.588238 · (frame mod 64), Bevy's
``interleaved_gradient_noise(frag_coord, frame_count)``, utils.wesl @4805ca7); per pixel and, under
``[taa]``, per frame (Godot's ``taa_frame_count`` term, 0 without TAA)."""


def _poisson_reads(*, poisson_rotation: str) -> frozenset:
    # Rotated per pixel, the disk turns with each receiver's pixel (screen-space noise).
    return frozenset({"depth"} if poisson_rotation == "none" else {"depth", "pixels"})


def _moment_reads(*, moment_mips: bool) -> frozenset:
    return frozenset({"moments", "mips"} if moment_mips else {"moments"})


_MOMENT_TAPS = "the 2×2 blurred moment texels around the point, bilinear (trilinear in the mips with moment_mips)"

FILTER_METHODS: dict[str, Filter] = {f.name: f for f in (
    Filter("none", "box", BOX_TAPS, "the one texel holding the point", "that texel", _no_reach, hard=True),
    Filter("pcf", "box", BOX_TAPS, "N×N texels, equal weights",
           "the N×N texels centred on the point's, equal weights", _half),
    Filter("pcf_bilinear", "box", BOX_BILINEAR, "2×2 texels, bilinear weights (hardware comparison sampler)",
           "the 2×2 texels around the point, weighted by its fixed-point fraction between their centres", _one),
    Filter("pcf_gaussian", "weighted", PCF_GAUSSIAN,
           "N×N texels, Gaussian weights of σ = filter_sigma (DirectX CascadedShadowMaps11)",
           "the N×N texels centred on the point's, weighted exp(−(di² + dj²) / 2σ²), normalized", _half,
           width=_gaussian_width),
    Filter("pcf_tent", "weighted", PCF_TENT,
           "tent of half-width N/2 integrated over each texel (Unity's 3×3/5×5/7×7 tents)",
           "every texel the tent centred on the point covers, weighted by the tent's integral over it", _half_and_one,
           width=_half_width),
    Filter("pcf_poisson", "weighted", PCF_POISSON,
           "poisson_taps taps of a fixed Poisson disk of radius N/2 (optionally rotated per pixel)",
           "the texel under each disk offset scaled by the half-width, equal weights", _half_and_one,
           width=_half_width, offsets=_poisson_offsets, reads=_poisson_reads),
    Filter("pcf_vogel", "weighted", PCF_VOGEL,
           "vogel_taps hardware bilinear-compare taps on a Vogel disk of vogel_radius texels, equal weights, "
           "optionally rotated per pixel (Godot 4 Soft Low: 4 taps, 2.0 texels; three.js PCFShadowMap: 5, 1.0)",
           "a 2×2 bilinear depth comparison at each disk offset (scaled by the radius, rotated by the pixel's "
           "noise), weighted by its fixed-point fraction; the taps averaged", _vogel_reach,
           width=_vogel_width, offsets=_vogel_offsets, reads=_poisson_reads),
    Filter("pcf_castano", "weighted", PCF_CASTANO,
           "Castaño's N×N kernel (N = 3: 4 taps, N = 5: 9 taps) of hardware bilinear-compare taps "
           "(Filament PCF_LOW, Bevy Gaussian, Stride PCF 5×5, MJP OptimizedPCF)",
           "per axis, taps of weights (3 − 2s, 1 + 2s) / 4 (N = 3) or (4 − 3s, 7, 1 + 3s) / 12 (N = 5) at "
           "Castaño's offsets from the texel corner nearest the point (s its fraction past that corner), "
           "each a 2×2 bilinear comparison: texel weights [1, 2, 1] / 4 or [1, 3, 4, 3, 1] / 12 at a texel "
           "centre", _castano_reach, width=_half_size),
    Filter("pcf_tent_bilinear", "weighted", PCF_TENT_BILINEAR,
           "tent of half-width N/2 folded into ((N + 1) / 2)² hardware bilinear-compare taps (Unity's "
           "SampleShadow_ComputeSamples_Tent_NxN: 3×3 4 taps, 5×5 9, 7×7 16)",
           "per axis, the tent's integrals over the N + 1 texels around the texel corner nearest the point, "
           "paired: each pair one bilinear comparison of their summed weight, placed between their centres "
           "at the second's share", _castano_reach, width=_half_size),
    Filter("pcf_bilinear_box", "weighted", PCF_BILINEAR_BOX,
           "N×N hardware bilinear-compare taps one texel apart, equal weights (DirectX CascadedShadowMaps11's "
           "CalculatePercentLit)",
           "a 2×2 bilinear depth comparison at the point moved by each whole-texel offset in [−N/2, N/2]², "
           "averaged", _half_and_one, width=_half_size),
    Filter("pcss", "weighted", PCF_PCSS, "blocker search over N×N, penumbra from light_size_deg, then a tent (PCSS)",
           "the N×N texels for the blocker search, then a tent as wide as the penumbra, clamped to them", _half,
           width=_penumbra_per_metre),
    Filter("vsm", "moment", MOMENT_VSM,
           "variance shadow map: blurred (z, z²), Chebyshev bound (DirectX VarianceShadows11)", _MOMENT_TAPS,
           _moment_reach, reads=_moment_reads),
    Filter("evsm2", "moment", MOMENT_EVSM2, "exponential VSM, positive warp (MJP, Filament)", _MOMENT_TAPS,
           _moment_reach, reads=_moment_reads),
    Filter("evsm4", "moment", MOMENT_EVSM4, "exponential VSM, positive and negative warps (MJP, Filament)",
           _MOMENT_TAPS, _moment_reach, reads=_moment_reads),
    Filter("msm", "moment", MOMENT_MSM,
           "moment shadow map: blurred (z, z², z³, z⁴), Hamburger 4-moment lower bound with moment and depth bias "
           "(Peters and Klein 2015; MJP's MSM Hamburger)", _MOMENT_TAPS, _moment_reach, reads=_moment_reads),
)}
"""Filters by name (the ``[shadow] filter`` values)."""


def family_filters(family: str) -> dict[str, Filter]:
    """The filters of one family (a key of :data:`FAMILIES`), by name."""
    check_name(family, FAMILIES, field="family")
    return {name: f for name, f in FILTER_METHODS.items() if f.family == family}


def family_code(name: str, *, family: str, field: str = "filter") -> int:
    """The kernel code of filter ``name``, which must belong to ``family``.

    Raises
    ------
    ValueError
        ``"<field>: expected one of [...]"``, the family's filters, on any other name.
    """
    members = family_filters(family)
    return members[check_name(name, members, field=field)].code
