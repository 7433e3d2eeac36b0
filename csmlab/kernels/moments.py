"""Moment shadow maps: VSM and EVSM moments from the cascade pass, a separable blur, the Chebyshev lookup.

Moments are taken of each texel's stored depth normalized over the scene's light-space depth
range, ``z = depth / span`` in [0, 1] (empty texels: 1, the far plane) — the same world-locked
range as :mod:`csmlab.storage`, so a whole-texel box move changes no moment. One depth sample per
texel means rasterizing the moments equals taking them of the rasterized depth.

Methods (:data:`MOMENT_METHODS`), moments stored as float32 ``(C, R, R, 4)``:

- ``vsm`` — ``(z, z², 0, 0)`` (Donnelly and Lauritzen 2006; DirectX VarianceShadows11, seed 002).
- ``evsm2`` — ``(e^{c₊ẑ}, e^{2c₊ẑ}, 0, 0)`` with ``ẑ = 2z − 1`` (Lauritzen and McCool 2008; MJP).
- ``evsm4`` — also the negative warp ``(−e^{−c₋ẑ}, e^{−2c₋ẑ})``; S is the smaller of the two bounds.

Blur: a box of ``2r + 1`` texels along x, then along y, clamped at the map's edge, summed in
float64 in a fixed order (the sample's two-pass separable convolution). Lookup: the 2×2 texels
around the receiver, bilinear in its fixed-point fraction, then Chebyshev's one-tailed bound
``p = σ² / (σ² + (t − μ)²)`` for ``t > μ`` (1 otherwise):

- ``vsm``: ``σ² = clamp(M₂ − M₁² + v_min, 0, 1)`` as the DirectX sample writes it;
- ``evsm``: ``σ² = max(M₂ − M₁², v_min · (c·w)²)``, the minimum variance carried through the
  warp's slope ``c·w`` at the receiver's warped depth ``w``;

then the light-bleeding reductions of the sources: ``p ← p^power`` (seed 002, "raise the
fPercentLit to a power") and ``p ← clamp((p − a) / (1 − a), 0, 1)`` (Lauritzen's linstep, MJP,
Filament).

Caveat (seed 002, "Filtering across splits"; seed 003): hardware would filter these maps
trilinearly with a level of detail from screen-space derivatives of 2×2 pixel quads; here the
lookup is bilinear at level 0, so the split-boundary seam of mipmapped lookups does not arise.

References
----------
- Donnelly, Lauritzen, "Variance Shadow Maps", I3D 2006.
- Lauritzen, McCool, "Layered Variance Shadow Maps", GI 2008 (exponential warp, EVSM).
- Microsoft, "Cascaded Shadow Maps" (seed 002), "Variance Shadow Maps" and "Light Bleeding".
"""

from __future__ import annotations

import numpy as np
import warp as wp

from csmlab.kernels import checked_device

__all__ = ["MOMENT_METHODS", "blur_moments", "moment_lookup", "moment_maps"]

MOMENT_METHODS: dict[str, int] = {"vsm": 0, "evsm2": 1, "evsm4": 2}
"""Moment filters by name, mapped to the kernels' code."""


@wp.func
def normalized_depth(depth: wp.float32, inv_span: wp.float64) -> wp.float64:
    """Depth over the span, clamped to [0, 1]; an empty texel (+inf) is the far plane, 1."""
    if not wp.isfinite(depth):
        return wp.float64(1.0)
    return wp.clamp(wp.float64(depth) * inv_span, wp.float64(0.0), wp.float64(1.0))


@wp.kernel
def moments_kernel(depth: wp.array3d(dtype=wp.float32), inv_span: wp.float64, code: int, c_pos: wp.float64,
                   c_neg: wp.float64, out: wp.array3d(dtype=wp.vec4f)):
    c, j, i = wp.tid()
    z = normalized_depth(depth[c, j, i], inv_span)
    if code == 0:
        out[c, j, i] = wp.vec4f(wp.float32(z), wp.float32(z * z), wp.float32(0.0), wp.float32(0.0))
        return
    zw = wp.float64(2.0) * z - wp.float64(1.0)
    p = wp.exp(c_pos * zw)
    n = wp.float64(0.0)
    if code == 2:
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
def moment_lit(moments: wp.array3d(dtype=wp.vec4f), coords: wp.array3d(dtype=wp.int64),
               receiver_depth: wp.array2d(dtype=wp.float32), c: int, k: int, unit: wp.int64, inv_span: wp.float64,
               code: int, c_pos: wp.float64, c_neg: wp.float64, min_variance: wp.float64, power: wp.float64,
               bleed: wp.float64) -> wp.float64:
    receiver = receiver_depth[c, k]
    if wp.isnan(receiver):
        return wp.float64(0.0)
    x2 = wp.int64(2) * coords[c, k, 0] - unit
    y2 = wp.int64(2) * coords[c, k, 1] - unit
    span = wp.int64(2) * unit
    i0 = x2 // span
    j0 = y2 // span
    wx = wp.float64(x2 - i0 * span) / wp.float64(span)
    wy = wp.float64(y2 - j0 * span) / wp.float64(span)
    one = wp.int64(1)
    w1 = wp.float64(1.0)
    m = (w1 - wy) * ((w1 - wx) * fetch(moments, c, i0, j0) + wx * fetch(moments, c, i0 + one, j0)) + wy * (
        (w1 - wx) * fetch(moments, c, i0, j0 + one) + wx * fetch(moments, c, i0 + one, j0 + one))
    # The receiver's own depth is not clamped: one beyond the range is behind everything stored.
    t = wp.float64(receiver) * inv_span
    p = wp.float64(0.0)
    if code == 0:
        variance = wp.clamp(m[1] - m[0] * m[0] + min_variance, wp.float64(0.0), wp.float64(1.0))
        p = chebyshev(m[0], variance, t)
    else:
        tw = wp.float64(2.0) * t - wp.float64(1.0)
        wpos = wp.exp(c_pos * tw)
        floor_pos = min_variance * (c_pos * wpos) * (c_pos * wpos)
        p = chebyshev(m[0], wp.max(m[1] - m[0] * m[0], floor_pos), wpos)
        if code == 2:
            wneg = -wp.exp(-c_neg * tw)
            floor_neg = min_variance * (c_neg * wneg) * (c_neg * wneg)
            p = wp.min(p, chebyshev(m[2], wp.max(m[3] - m[2] * m[2], floor_neg), wneg))
    if power != wp.float64(1.0):
        p = wp.pow(p, power)
    if bleed > wp.float64(0.0):
        p = wp.clamp((p - bleed) / (wp.float64(1.0) - bleed), wp.float64(0.0), wp.float64(1.0))
    return p


@wp.kernel
def moment_lookup_kernel(
    moments: wp.array3d(dtype=wp.vec4f),
    coords: wp.array3d(dtype=wp.int64),
    receiver_depth: wp.array2d(dtype=wp.float32),
    cascade: wp.array(dtype=wp.int32),
    blend_weight: wp.array(dtype=wp.float64),
    unit: wp.int64,
    inv_span: wp.float64,
    code: int,
    c_pos: wp.float64,
    c_neg: wp.float64,
    min_variance: wp.float64,
    power: wp.float64,
    bleed: wp.float64,
    lit: wp.array(dtype=wp.float32),
):
    k = wp.tid()
    c = cascade[k]
    if c < 0:
        lit[k] = wp.float32(wp.nan)
        return
    s = moment_lit(moments, coords, receiver_depth, c, k, unit, inv_span, code, c_pos, c_neg, min_variance, power,
                   bleed)
    w = blend_weight[k]
    if w > wp.float64(0.0):
        s = (wp.float64(1.0) - w) * s + w * moment_lit(moments, coords, receiver_depth, c + 1, k, unit, inv_span, code,
                                                       c_pos, c_neg, min_variance, power, bleed)
    lit[k] = wp.float32(s)


def _code(method: str) -> int:
    if method not in MOMENT_METHODS:
        raise ValueError(f"method: expected one of {sorted(MOMENT_METHODS)}, got {method!r}")
    return MOMENT_METHODS[method]


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
        A key of :data:`MOMENT_METHODS`.
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
                  exponents: tuple[float, float] = (40.0, 5.0), min_variance: float = 1e-5, power: float = 1.0,
                  bleed: float = 0.0, blend_weight=None, device: str = "cpu") -> np.ndarray:
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
        A key of :data:`MOMENT_METHODS`.
    span : float
        Depth range in metres the moments were normalized over.
    bits : int
        Sub-texel bits of ``coords``.
    exponents : tuple of float
        ``(c₊, c₋)`` of the EVSM warps.
    min_variance : float
        Minimum variance in normalized depth² (DirectX's 0.00001).
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
    code = _code(method)
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
    if not (0.0 <= bleed < 1.0 and power > 0 and min_variance >= 0):
        raise ValueError(f"bleed, power, min_variance: expected [0, 1), > 0, ≥ 0; got {bleed}, {power}, {min_variance}")
    if n == 0:
        return np.zeros(0, np.float32)
    lit = wp.empty(n, dtype=wp.float32, device=device)
    wp.launch(
        moment_lookup_kernel,
        dim=n,
        inputs=(wp.array(m, dtype=wp.vec4f, device=device), wp.array(xy, dtype=wp.int64, device=device, copy=False),
                wp.array(rd, dtype=wp.float32, device=device, copy=False),
                wp.array(chosen, dtype=wp.int32, device=device, copy=False),
                wp.array(blend, dtype=wp.float64, device=device, copy=False), wp.int64(2**bits), 1.0 / span, code,
                float(exponents[0]), float(exponents[1]), float(min_variance), float(power), float(bleed)),
        outputs=(lit,),
        device=device,
    )
    return lit.numpy()
