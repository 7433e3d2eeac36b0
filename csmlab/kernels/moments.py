"""Moment shadow maps: VSM, EVSM and MSM moments from the cascade pass, a separable blur, their bounds.

Moments are taken of each texel's stored depth normalized over the scene's light-space depth
range, ``z = depth / span`` in [0, 1] (empty texels: 1, the far plane) — the same world-locked
range as :mod:`csmlab.storage`, so a whole-texel box move changes no moment. One depth sample per
texel means rasterizing the moments equals taking them of the rasterized depth.

Methods (the ``moment`` family of :data:`csmlab.lookup_choices.FILTER_METHODS`), moments stored as
float32 ``(C, R, R, 4)``:

- ``vsm`` — ``(z, z², 0, 0)`` (Donnelly and Lauritzen 2006; DirectX VarianceShadows11, seed 002).
- ``evsm2`` — ``(e^{c₊ẑ}, e^{2c₊ẑ}, 0, 0)`` with ``ẑ = 2z − 1`` (Lauritzen and McCool 2008; MJP).
- ``evsm4`` — also the negative warp ``(−e^{−c₋ẑ}, e^{−2c₋ẑ})``; S is the smaller of the two bounds.
- ``msm`` — the four power moments ``(z, z², z³, z⁴)`` (Peters and Klein 2015, "Moment Shadow
  Mapping"), stored as float32 as MJP's Shadows sample stores them in its 32-bit format (its
  ``GetOptimizedMoments`` quantization is for the 16-bit format only, so it is not used here).

Blur: a box of ``2r + 1`` texels along x, then along y, clamped at the map's edge, summed in
float64 in a fixed order (the sample's two-pass separable convolution). Lookup: the 2×2 texels
around the receiver, bilinear in its fixed-point fraction, then Chebyshev's one-tailed bound
``p = σ² / (σ² + (t − μ)²)`` for ``t > μ`` (1 otherwise):

- ``vsm``: ``σ² = clamp(M₂ − M₁² + v_min, 0, 1)`` as the DirectX sample writes it;
- ``evsm``: ``σ² = max(M₂ − M₁², v_min · (c·w)²)``, the minimum variance carried through the
  warp's slope ``c·w`` at the receiver's warped depth ``w``;

``msm`` instead takes the Hamburger four-moment bound (the paper's Algorithm 3; MJP's
``ComputeMSMHamburger``, Shadows/MSM.hlsl @338290a): the moments mixed with (½, ½, ½, ½) by the
moment bias α, ``b ← (1 − α) b + α/2`` (MJP's default 3e-6 for float32 moments, its
``MSMMomentBias`` 0.003 × 10⁻³), the receiver's normalized depth less the depth bias
(``MSMDepthBias``, default 0), the Cholesky factorization of the Hankel matrix
``B = [[1, b₁, b₂], [b₁, b₂, b₃], [b₂, b₃, b₄]]`` solving ``B c = (1, t, t²)``, the roots ``z₂ ≤ z₃``
of ``c₀ + c₁ z + c₂ z² = 0``, and the shadow intensity G of the three cases (``t ≤ z₂``: 0;
``z₂ < t ≤ z₃``; ``t > z₃``), lit ``1 − clamp(G, 0, 1)``. All bounds take
the light-bleeding reductions of the sources: ``p ← p^power`` (seed 002, "raise the
fPercentLit to a power") and ``p ← clamp((p − a) / (1 − a), 0, 1)`` (Lauritzen's linstep, MJP,
Filament).

Mipmapped lookup (``moment_mips``; seed 002, "Variance Shadow Maps" and "Gradients with CSMs";
seed 003, "Filtering across splits"): :func:`moment_mip_chain` builds levels 1 … ``max_lod`` as 2×2
boxes of the level below (the sample's ``GenerateMips`` after the blur), and
:func:`moment_mip_lookup` samples them trilinearly — or anisotropically, several trilinear probes
along the footprint's major axis — at a level of detail from the receiver's screen-space
derivatives. The seeds' caveats, and what csmlab does about each:

- Derivatives come from 2×2 pixel quads; when the pixels of a quad take different branches —
  select different cascades — the derivatives of the texture coordinates are invalid, the level of
  detail (and the anisotropic footprint) is wrong and a jagged seam runs along the cascade border
  (seed 002, Figure 17; seed 003, Figure 4.1.12). :mod:`csmlab.quads` computes the derivatives as
  hardware does (``lod = "quad"``) and offers both fixes: one split index over the quad (PSVSM,
  ``quad_consistent``) and derivatives of the light-view-space position scaled by the selected
  cascade's scale (``analytic``, the sample's ``SampleGrad``).
- Filtering after the comparison (PCF) takes no derivative and has no such seam (seed 003).
- A coarse level reads far beyond the point: the boxes keep that reach free inside their edges
  (the filter record's radius, :mod:`csmlab.lookup_choices`; the sample's "Padding for PCF
  Kernels" carried to the mip footprint), so no lookup reads past a box — where no one rasterized.
- A texture's chain starts its 2×2 blocks at the box's first texel, so a box snapped to whole
  texels still changes every coarser level when it moves by an odd number of them; this chain is
  anchored to the global texel grid instead, as world-locked as level 0, and ``exact`` keeps zero
  same-cascade flicker with it.

References
----------
- Donnelly, Lauritzen, "Variance Shadow Maps", I3D 2006.
- Lauritzen, McCool, "Layered Variance Shadow Maps", GI 2008 (exponential warp, EVSM).
- Peters, Klein, "Moment Shadow Mapping", I3D 2015 (four moments, Hamburger bound, moment bias).
- MJP (TheRealMJP/Shadows @338290a), Shadows/MSM.hlsl ``ComputeMSMHamburger``, AppSettings.cpp
  ``MSMDepthBias``, ``MSMMomentBias``.
- Microsoft, "Cascaded Shadow Maps" (seed 002), "Variance Shadow Maps" and "Light Bleeding".
"""

from __future__ import annotations

import numpy as np
import warp as wp

from csmlab.kernels import checked_device
from csmlab.kernels.floats import is_finite, is_nan
from csmlab.kernels.shadow import bilinear_corner
from csmlab.lookup_choices import MOMENT_EVSM4, MOMENT_MSM, MOMENT_VSM, family_code

__all__ = ["blur_moments", "moment_lookup", "moment_maps", "moment_mip_chain", "moment_mip_lookup"]

wp.set_module_options({"fuse_fp": False})



@wp.func
def normalized_depth(depth: wp.float32, inv_span: wp.float64) -> wp.float64:
    """Depth over the span, clamped to [0, 1]; an empty texel (+inf) is the far plane, 1."""
    if not is_finite(depth):
        return wp.float64(1.0)
    return wp.clamp(wp.float64(depth) * inv_span, wp.float64(0.0), wp.float64(1.0))


@wp.kernel
def moments_kernel(depth: wp.array3d(dtype=wp.float32), inv_span: wp.float64, code: int, c_pos: wp.float64,
                   c_neg: wp.float64, out: wp.array3d(dtype=wp.vec4f)):
    c, j, i = wp.tid()
    z = normalized_depth(depth[c, j, i], inv_span)
    if code == MOMENT_VSM:
        out[c, j, i] = wp.vec4f(wp.float32(z), wp.float32(z * z), wp.float32(0.0), wp.float32(0.0))
        return
    if code == MOMENT_MSM:
        z2 = z * z
        out[c, j, i] = wp.vec4f(wp.float32(z), wp.float32(z2), wp.float32(z2 * z), wp.float32(z2 * z2))
        return
    zw = wp.float64(2.0) * z - wp.float64(1.0)
    p = wp.exp(c_pos * zw)
    n = wp.float64(0.0)
    if code == MOMENT_EVSM4:
        n = -wp.exp(-c_neg * zw)
    out[c, j, i] = wp.vec4f(wp.float32(p), wp.float32(p * p), wp.float32(n), wp.float32(n * n))


@wp.kernel
def blur_kernel(src: wp.array3d(dtype=wp.vec4f), radius: int, along_x: int, dst: wp.array3d(dtype=wp.vec4f)):
    c, j, i = wp.tid()
    top = src.shape[1] - 1
    total = wp.vec4d()
    for k in range(-radius, radius + 1):
        ii = i
        jj = j
        if along_x == 1:
            ii = wp.clamp(i + k, 0, top)
        else:
            jj = wp.clamp(j + k, 0, top)
        v = src[c, jj, ii]
        total += wp.vec4d(wp.float64(v[0]), wp.float64(v[1]), wp.float64(v[2]), wp.float64(v[3]))
    total = total / wp.float64(2 * radius + 1)
    dst[c, j, i] = wp.vec4f(wp.float32(total[0]), wp.float32(total[1]), wp.float32(total[2]), wp.float32(total[3]))


@wp.func
def fetch(moments: wp.array3d(dtype=wp.vec4f), c: int, i: wp.int64, j: wp.int64) -> wp.vec4d:
    top = wp.int64(moments.shape[1] - 1)
    v = moments[c, int(wp.clamp(j, wp.int64(0), top)), int(wp.clamp(i, wp.int64(0), top))]
    return wp.vec4d(wp.float64(v[0]), wp.float64(v[1]), wp.float64(v[2]), wp.float64(v[3]))


@wp.func
def chebyshev(mean: wp.float64, variance: wp.float64, t: wp.float64) -> wp.float64:
    if t <= mean:
        return wp.float64(1.0)
    d = t - mean
    return variance / (variance + d * d)


@wp.func
def bilinear_moments(moments: wp.array3d(dtype=wp.vec4f), c: int, x: wp.int64, y: wp.int64,
                     unit: wp.int64) -> wp.vec4d:
    """The 2×2 texels around fixed-point ``(x, y)`` (``unit`` per texel), bilinear in its exact fraction."""
    i0, wx = bilinear_corner(x, unit)
    j0, wy = bilinear_corner(y, unit)
    one = wp.int64(1)
    w1 = wp.float64(1.0)
    return (w1 - wy) * ((w1 - wx) * fetch(moments, c, i0, j0) + wx * fetch(moments, c, i0 + one, j0)) + wy * (
        (w1 - wx) * fetch(moments, c, i0, j0 + one) + wx * fetch(moments, c, i0 + one, j0 + one))


@wp.func
def hamburger_lit(m: wp.vec4d, t: wp.float64, moment_bias: wp.float64, depth_bias: wp.float64) -> wp.float64:
    """Lit fraction ``1 − G`` of the Hamburger four-moment bound at normalized depth ``t``.

    MJP's ``ComputeMSMHamburger`` (Shadows/MSM.hlsl) step by step, in float64: the moments pulled
    toward 0.5 by ``moment_bias``, the Hankel matrix's Cholesky factors, the quadratic's roots.
    """
    half = wp.float64(0.5)
    keep = wp.float64(1.0) - moment_bias
    b0 = keep * m[0] + moment_bias * half
    b1 = keep * m[1] + moment_bias * half
    b2 = keep * m[2] + moment_bias * half
    b3 = keep * m[3] + moment_bias * half
    zf = t - depth_bias
    l32_d22 = b2 - b0 * b1
    d22 = b1 - b0 * b0
    d33_d22 = (b3 - b1 * b1) * d22 - l32_d22 * l32_d22
    inv_d22 = wp.float64(1.0) / d22
    l32 = l32_d22 * inv_d22
    c1 = zf - b0
    c2 = zf * zf - b1 - l32 * c1
    c1 = c1 * inv_d22
    c2 = c2 * d22 / d33_d22
    c1 = c1 - l32 * c2
    c0 = wp.float64(1.0) - (c1 * b0 + c2 * b1)
    p = c1 / c2
    q = c0 / c2
    # Rounding can take the discriminant of a double root just below zero.
    r = wp.sqrt(wp.max(p * p * wp.float64(0.25) - q, wp.float64(0.0)))
    z1 = -p * half - r
    z2 = -p * half + r
    g = wp.float64(0.0)
    if z2 < zf:
        g = wp.float64(1.0) - (z1 * z2 - b0 * (z1 + z2) + b1) / ((zf - z1) * (zf - z2))
    elif z1 < zf:
        g = (zf * z2 - b0 * (zf + z2) + b1) / ((z2 - z1) * (zf - z1))
    return wp.float64(1.0) - wp.clamp(g, wp.float64(0.0), wp.float64(1.0))


@wp.struct
class MomentBound:
    """What the bound of filtered moments reads (:func:`moment_bound`), one record per lookup (:func:`_bound`).

    Attributes
    ----------
    inv_span : float64
        1 / the depth range in metres the moments were normalized over.
    code : int
        The moment filter (:data:`csmlab.lookup_choices.MOMENT_VSM` …).
    c_pos, c_neg : float64
        The EVSM warps' exponents c₊, c₋.
    min_variance : float64
        Variance floor in normalized depth² (not read by msm).
    moment_bias, depth_bias : float64
        msm: the moment bias α and the depth bias in normalized depth.
    power, bleed : float64
        The light-bleeding reductions ``p ← p^power`` and ``p ← linstep(bleed, 1, p)``.
    """

    inv_span: wp.float64
    code: int
    c_pos: wp.float64
    c_neg: wp.float64
    min_variance: wp.float64
    moment_bias: wp.float64
    depth_bias: wp.float64
    power: wp.float64
    bleed: wp.float64


@wp.func
def moment_bound(m: wp.vec4d, receiver: wp.float32, bound: MomentBound) -> wp.float64:
    """Chebyshev's (or MSM's Hamburger) bound of filtered moments ``m`` at the receiver's depth, then the
    light-bleeding reductions."""
    inv_span = bound.inv_span
    code = bound.code
    c_pos = bound.c_pos
    c_neg = bound.c_neg
    min_variance = bound.min_variance
    power = bound.power
    bleed = bound.bleed
    # The receiver's own depth is not clamped: one beyond the range is behind everything stored.
    t = wp.float64(receiver) * inv_span
    p = wp.float64(0.0)
    if code == MOMENT_MSM:
        p = hamburger_lit(m, t, bound.moment_bias, bound.depth_bias)
    elif code == MOMENT_VSM:
        variance = wp.clamp(m[1] - m[0] * m[0] + min_variance, wp.float64(0.0), wp.float64(1.0))
        p = chebyshev(m[0], variance, t)
    else:
        tw = wp.float64(2.0) * t - wp.float64(1.0)
        wpos = wp.exp(c_pos * tw)
        floor_pos = min_variance * (c_pos * wpos) * (c_pos * wpos)
        p = chebyshev(m[0], wp.max(m[1] - m[0] * m[0], floor_pos), wpos)
        if code == MOMENT_EVSM4:
            wneg = -wp.exp(-c_neg * tw)
            floor_neg = min_variance * (c_neg * wneg) * (c_neg * wneg)
            p = wp.min(p, chebyshev(m[2], wp.max(m[3] - m[2] * m[2], floor_neg), wneg))
    if power != wp.float64(1.0):
        p = wp.pow(p, power)
    if bleed > wp.float64(0.0):
        p = wp.clamp((p - bleed) / (wp.float64(1.0) - bleed), wp.float64(0.0), wp.float64(1.0))
    return p


@wp.func
def moment_lit(moments: wp.array3d(dtype=wp.vec4f), coords: wp.array3d(dtype=wp.int64),
               receiver_depth: wp.array2d(dtype=wp.float32), c: int, k: int, unit: wp.int64,
               bound: MomentBound) -> wp.float64:
    receiver = receiver_depth[c, k]
    if is_nan(receiver):
        return wp.float64(0.0)
    m = bilinear_moments(moments, c, coords[c, k, 0], coords[c, k, 1], unit)
    return moment_bound(m, receiver, bound)


@wp.kernel
def moment_lookup_kernel(
    moments: wp.array3d(dtype=wp.vec4f),
    coords: wp.array3d(dtype=wp.int64),
    receiver_depth: wp.array2d(dtype=wp.float32),
    cascade: wp.array(dtype=wp.int32),
    blend_weight: wp.array(dtype=wp.float64),
    unit: wp.int64,
    bound: MomentBound,
    lit: wp.array(dtype=wp.float32),
):
    k = wp.tid()
    c = cascade[k]
    if c < 0:
        lit[k] = wp.float32(wp.nan)
        return
    s = moment_lit(moments, coords, receiver_depth, c, k, unit, bound)
    w = blend_weight[k]
    if w > wp.float64(0.0):
        s = (wp.float64(1.0) - w) * s + w * moment_lit(moments, coords, receiver_depth, c + 1, k, unit, bound)
    lit[k] = wp.float32(s)


def _code(method: str) -> int:
    return family_code(method, family="moment", field="method")


def _bound(*, method: str, span: float, exponents: tuple[float, float], min_variance: float, moment_bias: float,
           depth_bias: float, power: float, bleed: float) -> MomentBound:
    """The :class:`MomentBound` of a lookup, its values checked.

    Raises
    ------
    ValueError
        An unknown method, or a reduction, floor or bias out of range.
    """
    code = _code(method)
    if not (0.0 <= bleed < 1.0 and power > 0 and min_variance >= 0 and 0.0 <= moment_bias < 1.0
            and np.isfinite(depth_bias)):
        raise ValueError(f"bleed, power, min_variance, moment_bias, depth_bias: expected [0, 1), > 0, ≥ 0, [0, 1), "
                         f"finite; got {bleed}, {power}, {min_variance}, {moment_bias}, {depth_bias}")
    bound = MomentBound()
    bound.inv_span = 1.0 / span
    bound.code = code
    bound.c_pos = float(exponents[0])
    bound.c_neg = float(exponents[1])
    bound.min_variance = float(min_variance)
    bound.moment_bias = float(moment_bias)
    bound.depth_bias = float(depth_bias)
    bound.power = float(power)
    bound.bleed = float(bleed)
    return bound


def moment_maps(depth, *, span: float, method: str, exponents: tuple[float, float] = (40.0, 5.0),
                device: str = "cpu") -> np.ndarray:
    """Moments of every texel's depth, normalized over ``span``.

    Parameters
    ----------
    depth : array_like, shape (C, R, R), float32
        Stored depth ``d·X − zref`` in metres; +inf where empty.
    span : float
        The scene's light-space depth range in metres (depth 0 … span maps to 0 … 1).
    method : str
        A filter of the ``moment`` family (:data:`csmlab.lookup_choices.FILTER_METHODS`).
    exponents : tuple of float
        ``(c₊, c₋)`` of the EVSM warps (ignored by ``vsm``).
    device : str

    Returns
    -------
    ndarray, shape (C, R, R, 4), float32
        See the module docstring; unused components are 0.
    """
    device = checked_device(device)
    code = _code(method)
    maps = np.ascontiguousarray(depth, dtype=np.float32)
    if maps.ndim != 3 or maps.shape[1] != maps.shape[2]:
        raise ValueError(f"depth: expected depth maps of shape (C, R, R), got {maps.shape}")
    if not (np.isfinite(span) and span > 0):
        raise ValueError(f"span: expected a positive depth range in metres, got {span!r}")
    if not all(np.isfinite(c) and 0 < c <= 44 for c in exponents):
        raise ValueError(f"exponents: expected two exponents in (0, 44] (e^(2c) must fit float32), got {exponents!r}")
    out = wp.empty(maps.shape, dtype=wp.vec4f, device=device)
    wp.launch(moments_kernel, dim=maps.shape, inputs=(wp.array(maps, dtype=wp.float32, device=device), 1.0 / span, code,
                                                       float(exponents[0]), float(exponents[1])),
              outputs=(out,), device=device)
    return out.numpy()


def blur_moments(moments, *, radius: int, device: str = "cpu") -> np.ndarray:
    """Separable box blur of ``2·radius + 1`` texels, x then y, clamped at the edges.

    Parameters
    ----------
    moments : array_like, shape (C, R, R, 4), float32
    radius : int
        Texels on each side; 0 returns the moments unchanged.

    Returns
    -------
    ndarray, shape (C, R, R, 4), float32
    """
    device = checked_device(device)
    m = np.ascontiguousarray(moments, dtype=np.float32)
    if m.ndim != 4 or m.shape[3] != 4 or m.shape[1] != m.shape[2]:
        raise ValueError(f"moments: expected shape (C, R, R, 4), got {m.shape}")
    if not (isinstance(radius, (int, np.integer)) and radius >= 0):
        raise ValueError(f"radius: expected a non-negative integer, got {radius!r}")
    if radius == 0:
        return m
    src = wp.array(m, dtype=wp.vec4f, device=device)
    half = wp.empty(m.shape[:3], dtype=wp.vec4f, device=device)
    out = wp.empty(m.shape[:3], dtype=wp.vec4f, device=device)
    wp.launch(blur_kernel, dim=m.shape[:3], inputs=(src, int(radius), 1), outputs=(half,), device=device)
    wp.launch(blur_kernel, dim=m.shape[:3], inputs=(half, int(radius), 0), outputs=(out,), device=device)
    return out.numpy()


def moment_lookup(moments, coords, receiver_depth, *, cascade, method: str, span: float, bits: int,
                  exponents: tuple[float, float] = (40.0, 5.0), min_variance: float = 1e-5,
                  moment_bias: float = 3e-6, depth_bias: float = 0.0, power: float = 1.0, bleed: float = 0.0,
                  blend_weight=None, device: str = "cpu") -> np.ndarray:
    """Lit fraction S of receivers from (blurred) moment maps at their selected cascade.

    Parameters
    ----------
    moments : array_like, shape (C, R, R, 4), float32
        From :func:`moment_maps` (and :func:`blur_moments`) with the same ``method`` and ``span``.
    coords : array_like, shape (C, N, 2), int64
        Receivers in ``2**-bits`` texels of each cascade.
    receiver_depth : array_like, shape (C, N), float32
        Biased receiver depth, metres (``d·X − zref − bias``); NaN is shadowed.
    cascade : array_like, shape (N,), int
        Selected cascade, −1 for none (S is NaN).
    method : str
        A filter of the ``moment`` family (:data:`csmlab.lookup_choices.FILTER_METHODS`).
    span : float
        Depth range in metres the moments were normalized over.
    bits : int
        Sub-texel bits of ``coords``.
    exponents : tuple of float
        ``(c₊, c₋)`` of the EVSM warps.
    min_variance : float
        Minimum variance in normalized depth² (DirectX's 0.00001); not read by ``msm``.
    moment_bias : float
        ``msm``: the weight α in [0, 1) of (0.5, 0.5, 0.5, 0.5) mixed into the moments (MJP's default
        3e-6 for float32 moments).
    depth_bias : float
        ``msm``: subtracted from the receiver's normalized depth (MJP's default 0).
    power : float
        ``p ← p^power`` light-bleeding reduction (1: none).
    bleed : float
        Linstep light-bleeding reduction amount in [0, 1) (0: none).
    blend_weight : array_like, shape (N,), float64, optional
        Weight of cascade ``cascade + 1`` mixed in (blend band).
    device : str

    Returns
    -------
    ndarray, shape (N,), float32
    """
    device = checked_device(device)
    bound = _bound(method=method, span=span, exponents=exponents, min_variance=min_variance, moment_bias=moment_bias,
                   depth_bias=depth_bias, power=power, bleed=bleed)
    m = np.ascontiguousarray(moments, dtype=np.float32)
    xy = np.ascontiguousarray(coords, dtype=np.int64)
    rd = np.ascontiguousarray(receiver_depth, dtype=np.float32)
    chosen = np.ascontiguousarray(cascade, dtype=np.int32)
    count = m.shape[0] if m.ndim == 4 else 0
    n = chosen.shape[0] if chosen.ndim == 1 else -1
    if m.ndim != 4 or m.shape[3] != 4 or xy.shape != (count, n, 2) or rd.shape != (count, n):
        raise ValueError(f"moments, coords, receiver_depth, cascade: expected shapes (C, R, R, 4), (C, N, 2), (C, N), "
                         f"(N,); got {m.shape}, {xy.shape}, {rd.shape}, {chosen.shape}")
    blend = np.zeros(n) if blend_weight is None else np.ascontiguousarray(blend_weight, dtype=np.float64)
    if n == 0:
        return np.zeros(0, np.float32)
    lit = wp.empty(n, dtype=wp.float32, device=device)
    wp.launch(
        moment_lookup_kernel,
        dim=n,
        inputs=(wp.array(m, dtype=wp.vec4f, device=device), wp.array(xy, dtype=wp.int64, device=device, copy=False),
                wp.array(rd, dtype=wp.float32, device=device, copy=False),
                wp.array(chosen, dtype=wp.int32, device=device, copy=False),
                wp.array(blend, dtype=wp.float64, device=device, copy=False), wp.int64(2**bits), bound),
        outputs=(lit,),
        device=device,
    )
    return lit.numpy()


@wp.kernel
def downsample_kernel(src: wp.array3d(dtype=wp.vec4f), parity: wp.array2d(dtype=wp.int64),
                      dst: wp.array3d(dtype=wp.vec4f)):
    c, j, i = wp.tid()
    top = wp.int64(src.shape[1] - 1)
    # Children 2k − b and 2k − b + 1 on each axis: b = 1 where the box's first texel is the second
    # child of a parent on the global grid (see moment_mip_chain).
    x0 = wp.int64(2) * wp.int64(i) - parity[c, 0]
    y0 = wp.int64(2) * wp.int64(j) - parity[c, 1]
    total = wp.vec4d()
    for dj in range(2):
        for di in range(2):
            ii = int(wp.clamp(x0 + wp.int64(di), wp.int64(0), top))
            jj = int(wp.clamp(y0 + wp.int64(dj), wp.int64(0), top))
            v = src[c, jj, ii]
            total += wp.vec4d(wp.float64(v[0]), wp.float64(v[1]), wp.float64(v[2]), wp.float64(v[3]))
    total = total * wp.float64(0.25)
    dst[c, j, i] = wp.vec4f(wp.float32(total[0]), wp.float32(total[1]), wp.float32(total[2]), wp.float32(total[3]))


@wp.func
def fetch_level(levels: wp.array(dtype=wp.vec4f), offset: wp.array(dtype=wp.int64), size: wp.array(dtype=wp.int64),
                level: int, c: int, i: wp.int64, j: wp.int64) -> wp.vec4d:
    s = size[level]
    top = s - wp.int64(1)
    ii = wp.clamp(i, wp.int64(0), top)
    jj = wp.clamp(j, wp.int64(0), top)
    v = levels[int(offset[level] + (wp.int64(c) * s + jj) * s + ii)]
    return wp.vec4d(wp.float64(v[0]), wp.float64(v[1]), wp.float64(v[2]), wp.float64(v[3]))


@wp.func
def bilinear_level(levels: wp.array(dtype=wp.vec4f), offset: wp.array(dtype=wp.int64),
                   size: wp.array(dtype=wp.int64), shift: wp.array3d(dtype=wp.int64), level: int, c: int,
                   x: wp.int64, y: wp.int64, unit: wp.int64) -> wp.vec4d:
    """:func:`bilinear_moments` at ``level``: fixed-point level-0 ``(x, y)`` moved onto the level's global grid."""
    lunit = unit * (wp.int64(1) << wp.int64(level))
    i0, wx = bilinear_corner(x + shift[c, level, 0], lunit)
    j0, wy = bilinear_corner(y + shift[c, level, 1], lunit)
    one = wp.int64(1)
    w1 = wp.float64(1.0)
    return (w1 - wy) * ((w1 - wx) * fetch_level(levels, offset, size, level, c, i0, j0)
                        + wx * fetch_level(levels, offset, size, level, c, i0 + one, j0)) + wy * (
        (w1 - wx) * fetch_level(levels, offset, size, level, c, i0, j0 + one)
        + wx * fetch_level(levels, offset, size, level, c, i0 + one, j0 + one))


@wp.func
def filtered_moments(levels: wp.array(dtype=wp.vec4f), offset: wp.array(dtype=wp.int64),
                     size: wp.array(dtype=wp.int64), shift: wp.array3d(dtype=wp.int64), c: int, x: wp.int64,
                     y: wp.int64, ddx: wp.vec2d, ddy: wp.vec2d, unit: wp.int64, max_lod: int,
                     max_aniso: int) -> wp.vec4d:
    """Trilinear (``max_aniso`` 1) or anisotropic moments at fixed-point ``(x, y)`` for a footprint ``ddx, ddy``
    (texels)."""
    px = wp.length(ddx)
    py = wp.length(ddy)
    major = ddx
    pmax = px
    pmin = py
    if py > px:
        major = ddy
        pmax = py
        pmin = px
    probes = int(1)
    if max_aniso > 1 and pmax > wp.float64(0.0):
        ratio = wp.float64(max_aniso)
        if pmin > wp.float64(0.0):
            ratio = wp.min(wp.ceil(pmax / pmin), wp.float64(max_aniso))
        probes = int(ratio)
    lod = wp.float64(0.0)
    if pmax > wp.float64(0.0):
        lod = wp.clamp(wp.log2(pmax / wp.float64(probes)), wp.float64(0.0), wp.float64(max_lod))
    if not is_finite(lod):
        lod = wp.float64(max_lod)
    base = int(wp.floor(lod))
    frac = lod - wp.float64(base)
    # The probes cover the major axis, at most probes · 2^max_lod texels long (the box's padding).
    reach = wp.float64(probes) * wp.pow(wp.float64(2.0), wp.float64(max_lod))
    if pmax > reach:
        major = major * (reach / pmax)
    total = wp.vec4d()
    for p in range(probes):
        t = (wp.float64(p) + wp.float64(0.5)) / wp.float64(probes) - wp.float64(0.5)
        xp = x + wp.int64(wp.rint(major[0] * t * wp.float64(unit)))
        yp = y + wp.int64(wp.rint(major[1] * t * wp.float64(unit)))
        m = bilinear_level(levels, offset, size, shift, base, c, xp, yp, unit)
        if frac > wp.float64(0.0):
            m = (wp.float64(1.0) - frac) * m + frac * bilinear_level(levels, offset, size, shift, base + 1, c, xp, yp,
                                                                     unit)
        total += m
    return total / wp.float64(probes)


@wp.kernel
def mip_lookup_kernel(
    levels: wp.array(dtype=wp.vec4f),
    offset: wp.array(dtype=wp.int64),
    size: wp.array(dtype=wp.int64),
    shift: wp.array3d(dtype=wp.int64),
    coords: wp.array3d(dtype=wp.int64),
    receiver_depth: wp.array2d(dtype=wp.float32),
    cascade: wp.array(dtype=wp.int32),
    ddx: wp.array2d(dtype=wp.vec2d),
    ddy: wp.array2d(dtype=wp.vec2d),
    blend_weight: wp.array(dtype=wp.float64),
    unit: wp.int64,
    max_lod: int,
    max_aniso: int,
    bound: MomentBound,
    lit: wp.array(dtype=wp.float32),
):
    k = wp.tid()
    c = cascade[k]
    if c < 0:
        lit[k] = wp.float32(wp.nan)
        return
    s = wp.float64(0.0)
    # Row 0 of ddx/ddy is the footprint in cascade c's texels, row 1 in cascade c + 1's (blend band).
    for b in range(2):
        w = blend_weight[k]
        if b == 0:
            w = wp.float64(1.0) - w
        if w > wp.float64(0.0):
            receiver = receiver_depth[c + b, k]
            p = wp.float64(0.0)
            if not is_nan(receiver):
                m = filtered_moments(levels, offset, size, shift, c + b, coords[c + b, k, 0], coords[c + b, k, 1],
                                     ddx[b, k], ddy[b, k], unit, max_lod, max_aniso)
                p = moment_bound(m, receiver, bound)
            if b == 0 and w == wp.float64(1.0):
                s = p
            else:
                s = s + w * p
    lit[k] = wp.float32(s)


def _mip_grid(origin_texels, *, max_lod: int) -> tuple[np.ndarray, np.ndarray]:
    """Per cascade, level and axis: the children's parity ``b`` and the level's shift in level-0 texels."""
    o = np.asarray(origin_texels, dtype=np.int64)
    s = np.stack([o // (1 << level) for level in range(max_lod + 2)], axis=1)  # (C, L + 1, 2) global index of texel 0
    parity = s[:, :-1] - 2 * s[:, 1:]
    shift = o[:, None, :] - s[:, :-1] * (1 << np.arange(max_lod + 1))[None, :, None]
    return parity, shift


def moment_mip_chain(moments, *, origin_texels, max_lod: int, device: str = "cpu") -> list[np.ndarray]:
    """Mip levels 0 … ``max_lod`` of (blurred) moment maps, each a 2×2 box of the level below on the global texel grid.

    A texel of level l covers the 2^l × 2^l level-0 texels of a *global* block — one whose
    global texel indices start at a multiple of 2^l — so the chain is as world-locked as level 0
    (a box moved by whole texels shifts every level by whole texels of that level, or by none).
    A hardware texture's chain starts its blocks at the box's own first texel instead, which
    changes every coarser level when a box moves by an odd number of texels.

    Parameters
    ----------
    moments : array_like, shape (C, R, R, 4), float32
        Level 0 (:func:`blur_moments`).
    origin_texels : array_like, shape (C, 2), int
        Global texel index of each box's texel (0, 0) (x, y).
    max_lod : int
        Coarsest level, ≥ 0.
    device : str

    Returns
    -------
    list of ndarray
        Level l of shape ``(C, S_l, S_l, 4)`` float32 with ``S_0 = R`` and ``S_{l+1} = S_l // 2 + 1``
        (one more texel than half, for a block that starts before the box). Children outside the
        level below are clamped to its edge; texel k on an axis averages children ``2k − b`` and
        ``2k − b + 1`` with ``b`` 1 where the box's first texel of that level is a second child.
    """
    device = checked_device(device)
    m = np.ascontiguousarray(moments, dtype=np.float32)
    if m.ndim != 4 or m.shape[3] != 4 or m.shape[1] != m.shape[2]:
        raise ValueError(f"moments: expected shape (C, R, R, 4), got {m.shape}")
    o = np.asarray(origin_texels)
    if o.shape != (m.shape[0], 2) or not np.issubdtype(o.dtype, np.integer):
        raise ValueError(f"origin_texels: expected integer texel indices of shape ({m.shape[0]}, 2), "
                         f"got {o.shape} {o.dtype}")
    if not (isinstance(max_lod, (int, np.integer)) and max_lod >= 0):
        raise ValueError(f"max_lod: expected a non-negative integer, got {max_lod!r}")
    parity, _ = _mip_grid(o, max_lod=int(max_lod))
    chain = [m]
    src = wp.array(m, dtype=wp.vec4f, device=device)
    for level in range(int(max_lod)):
        size = src.shape[1] // 2 + 1
        dst = wp.empty((m.shape[0], size, size), dtype=wp.vec4f, device=device)
        wp.launch(downsample_kernel, dim=dst.shape,
                  inputs=(src, wp.array(np.ascontiguousarray(parity[:, level]), dtype=wp.int64, device=device)),
                  outputs=(dst,), device=device)
        chain.append(dst.numpy())
        src = dst
    return chain


def moment_mip_lookup(chain, coords, receiver_depth, *, origin_texels, cascade, ddx, ddy, method: str, span: float,
                      bits: int, anisotropy: int = 1, exponents: tuple[float, float] = (40.0, 5.0),
                      min_variance: float = 1e-5, moment_bias: float = 3e-6, depth_bias: float = 0.0,
                      power: float = 1.0, bleed: float = 0.0, blend_weight=None, device: str = "cpu") -> np.ndarray:
    """Lit fraction S from a moment mip chain, trilinear or anisotropic at a level of detail from a footprint.

    The footprint is the pair of screen-space derivatives of the receiver's level-0 texel
    coordinates, ``ddx`` and ``ddy`` (texels per pixel). With ``Pmax ≥ Pmin`` their lengths and
    ``N = min(ceil(Pmax / Pmin), anisotropy)`` probes (1 when ``anisotropy`` is 1), the level of
    detail is ``λ = clamp(log2(Pmax / N), 0, max_lod)`` (``max_lod = len(chain) − 1``); each probe
    mixes the bilinear moments of levels ``⌊λ⌋`` and ``⌊λ⌋ + 1`` by ``λ − ⌊λ⌋``, and the N probes
    sit at ``((p + ½) / N − ½)`` of the major axis (at most ``N · 2^max_lod`` texels long), their
    offsets rounded to the fixed-point grid (EXT_texture_filter_anisotropic's footprint). The
    moments are averaged, then bounded as :func:`moment_lookup` does. With a footprint under one
    texel it equals :func:`moment_lookup` on level 0.

    Parameters
    ----------
    chain : list of ndarray
        :func:`moment_mip_chain` of the moments, built with the same ``origin_texels``.
    coords : array_like, shape (C, N, 2), int64
        Receivers in ``2**-bits`` texels of each cascade.
    receiver_depth : array_like, shape (C, N), float32
        Biased receiver depth, metres; NaN is shadowed.
    origin_texels : array_like, shape (C, 2), int
        Global texel index of each box's texel (0, 0).
    cascade : array_like, shape (N,), int
        Cascade looked up, −1 for none (S is NaN).
    ddx, ddy : array_like, shape (N, 2) or (2, N, 2), float64
        Footprint in the looked-up cascade's level-0 texels; with a leading 2, row 1 is the same
        footprint in cascade ``cascade + 1``'s texels, for the blend band.
    method : str
        A filter of the ``moment`` family (:data:`csmlab.lookup_choices.FILTER_METHODS`).
    span : float
        Depth range in metres the moments were normalized over.
    bits : int
        Sub-texel bits of ``coords``.
    anisotropy : int
        Largest number of probes, 1..16 (1: trilinear).
    exponents, min_variance, moment_bias, depth_bias, power, bleed, blend_weight, device
        As :func:`moment_lookup`.

    Returns
    -------
    ndarray, shape (N,), float32
    """
    device = checked_device(device)
    bound = _bound(method=method, span=span, exponents=exponents, min_variance=min_variance, moment_bias=moment_bias,
                   depth_bias=depth_bias, power=power, bleed=bleed)
    levels = [np.ascontiguousarray(level, dtype=np.float32) for level in chain]
    if not levels or any(level.ndim != 4 or level.shape[3] != 4 or level.shape[1] != level.shape[2]
                         or level.shape[0] != levels[0].shape[0] for level in levels):
        raise ValueError(f"chain: expected levels of shape (C, S, S, 4), got {[np.shape(level) for level in levels]}")
    count = levels[0].shape[0]
    xy = np.ascontiguousarray(coords, dtype=np.int64)
    rd = np.ascontiguousarray(receiver_depth, dtype=np.float32)
    chosen = np.ascontiguousarray(cascade, dtype=np.int32)
    n = chosen.shape[0] if chosen.ndim == 1 else -1
    dx = np.asarray(ddx, dtype=np.float64)
    dy = np.asarray(ddy, dtype=np.float64)
    if dx.ndim == 2:
        dx, dy = np.stack([dx, dx]), np.stack([dy, dy])
    if xy.shape != (count, n, 2) or rd.shape != (count, n) or dx.shape != (2, n, 2) or dy.shape != dx.shape:
        raise ValueError(f"coords, receiver_depth, cascade, ddx, ddy: expected shapes (C, N, 2), (C, N), (N,), (N, 2) "
                         f"or (2, N, 2); got {xy.shape}, {rd.shape}, {chosen.shape}, {dx.shape}, {dy.shape}")
    if not (isinstance(anisotropy, (int, np.integer)) and 1 <= anisotropy <= 16):
        raise ValueError(f"anisotropy: expected an integer in 1..16, got {anisotropy!r}")
    blend = np.zeros(n) if blend_weight is None else np.ascontiguousarray(blend_weight, dtype=np.float64)
    if n == 0:
        return np.zeros(0, np.float32)
    max_lod = len(levels) - 1
    _, shift = _mip_grid(origin_texels, max_lod=max_lod)
    sizes = np.array([level.shape[1] for level in levels], dtype=np.int64)
    offsets = np.concatenate([[0], np.cumsum([level.shape[0] * level.shape[1] ** 2 for level in levels])[:-1]])
    flat = np.concatenate([level.reshape(-1, 4) for level in levels])
    lit = wp.empty(n, dtype=wp.float32, device=device)
    wp.launch(
        mip_lookup_kernel,
        dim=n,
        inputs=(wp.array(flat, dtype=wp.vec4f, device=device), wp.array(offsets.astype(np.int64), dtype=wp.int64,
                                                                         device=device),
                wp.array(sizes, dtype=wp.int64, device=device),
                wp.array(np.ascontiguousarray(shift * 2**bits), dtype=wp.int64, device=device),
                wp.array(xy, dtype=wp.int64, device=device, copy=False),
                wp.array(rd, dtype=wp.float32, device=device, copy=False),
                wp.array(chosen, dtype=wp.int32, device=device, copy=False),
                wp.array(np.ascontiguousarray(dx), dtype=wp.vec2d, device=device),
                wp.array(np.ascontiguousarray(dy), dtype=wp.vec2d, device=device),
                wp.array(blend, dtype=wp.float64, device=device, copy=False), wp.int64(2**bits), int(max_lod),
                int(anisotropy), bound),
        outputs=(lit,),
        device=device,
    )
    return lit.numpy()
