"""Weighted percentage-closer filters at an already selected cascade: Gaussian, tent, Poisson and Vogel disks,
Castaño's kernels, bilinear tents and boxes, PCSS.

Every filter here is a weighted sum of depth tests ``S = Σ w_k · test(texel_k)`` over texels around
the receiver, the test being the receiver-plane comparison of :func:`csmlab.kernels.shadow.tap`.
Tap positions and weights come from the receiver's fixed-point position less its integer texel
index — exact and the same wherever a box lies — so a box moved by whole texels changes no tap
and no weight (docs/design.md, "Exact zero by construction"); only a per-pixel rotation of the Poisson
disk (screen-space noise) breaks that, on purpose.

Filters (the ``weighted`` family of :data:`csmlab.lookup_choices.FILTER_METHODS`), ``width`` in
texels of the cascade, ``radius`` the tap bound:

- ``pcf_gaussian`` — the (2r + 1)² texels centred on the one holding the point, weighted by
  ``exp(−(di² + dj²) / 2σ²)`` normalized to 1 (σ = ``width``): the weighted-kernel PCF of the
  DirectX CascadedShadowMaps11 sample (seed 002, "PCF").
- ``pcf_tent`` — each texel weighted by the integral over it of a tent (triangle) of half-width
  ``width`` centred on the point, per axis, the 2-D weight the product: Unity's tent filters
  (``SampleShadow_ComputeSamples_Tent_5x5`` is half-width 2.5 over 6 texels; Unity folds the same
  weights into 9 bilinear comparison fetches).
- ``pcf_poisson`` — ``len(disk)`` equally weighted taps at ``point + width · R(θ) · o_k``, ``o_k``
  a fixed Poisson disk in the unit disk, each tap testing the texel its offset point falls in;
  θ per receiver (0 unless rotated per pixel).
- ``pcf_vogel`` — ``len(disk)`` equally weighted hardware bilinear-compare taps
  (:func:`csmlab.kernels.shadow.bilinear_tap`) at ``point + width · R(θ) · o_k``, ``o_k`` a Vogel disk:
  Godot 4's Soft Low and three.js's ``PCFShadowMap``.
- ``pcf_castano`` — Castaño's kernels of bilinear-compare taps, separable: from the texel corner
  ``b = floor(u + ½)`` nearest the point ``u`` (texels) and ``s = u + ½ − b``, per axis the taps
  ``(weight, offset from b − ½)`` are ``(3 − 2s, (2 − s)/(3 − 2s) − 1)``, ``(1 + 2s, s/(1 + 2s) + 1)`` for
  N = 3 (Filament ``ShadowSample_PCF_Low``) and ``(4 − 3s, (3 − 2s)/(4 − 3s) − 2)``, ``(7, (3 + s)/7)``,
  ``(1 + 3s, s/(1 + 3s) + 2)`` for N = 5 (Bevy ``sample_shadow_map_castano_thirteen``, Stride
  ``Get5x5FilterKernel``), the 2-D weight the product, normalized by the weights' sum (16, 144).
- ``pcf_tent_bilinear`` — Unity's ``SampleShadow_ComputeSamples_Tent_NxN``: per axis the tent's
  integrals over the N + 1 texels from ``b − (N + 1)/2``, paired; each pair one bilinear tap of the
  pair's summed weight at the first centre plus the second's share of it.
- ``pcf_bilinear_box`` — N × N bilinear taps at the point plus whole-texel offsets, equal weights
  (DirectX CascadedShadowMaps11 ``CalculatePercentLit``).
- ``pcss`` — percentage-closer soft shadows (Fernando 2005) for a directional light: the blockers
  among the (2r + 1)² texels give their mean depth ``d_b``; the penumbra width is
  ``w = (d_r − d_b) · 2 tan(θ_L / 2) / texel`` texels for a light of angular diameter θ_L (``width``
  carries ``2 tan(θ_L/2) / texel``); then a tent of half-width ``clamp(w / 2, ½, r)``. No blocker:
  lit.

References
----------
- Reeves, Salesin, Cook, "Rendering Antialiased Shadows with Depth Maps", SIGGRAPH 1987.
- Fernando, "Percentage-Closer Soft Shadows", SIGGRAPH 2005 sketch.
- Unity Technologies, ``ShadowSamplingTent.hlsl`` (Core RP library) — the tent weights.
- Microsoft, "Cascaded Shadow Maps" (seed 002), "PCF": a Gaussian over an N × N grid.
"""

from __future__ import annotations

import functools

import numpy as np
import warp as wp

from csmlab.kernels import checked_device
from csmlab.kernels.floats import is_finite, is_nan
from csmlab.kernels.shadow import bilinear_corner_shifted, bilinear_tap, bilinear_taps, tap
from csmlab.lookup_choices import (PCF_BILINEAR_BOX, PCF_CASTANO, PCF_GAUSSIAN, PCF_POISSON, PCF_TENT,
                                   PCF_TENT_BILINEAR, PCF_VOGEL, family_code)

__all__ = ["weighted_pcf"]

wp.set_module_options({"fuse_fp": False})

AXIS_TAPS = 32
"""The most taps along one axis that a separable filter's table holds (:func:`axis_table`): Castaño's kernels take
2 or 3, the bilinear tent ``(N + 1) / 2``, at most 32 for ``filter_size`` ≤ 63 (the settings' bound, which
:func:`weighted_pcf` checks)."""

axis_texels = wp.types.vector(AXIS_TAPS, wp.int64)
axis_values = wp.types.vector(AXIS_TAPS, wp.float64)

@wp.func
def tent_cdf(x: wp.float64, h: wp.float64) -> wp.float64:
    """Integral from −∞ to ``x`` of the tent ``max(0, 1 − |x|/h) / h`` (unit area)."""
    if x <= -h:
        return wp.float64(0.0)
    if x >= h:
        return wp.float64(1.0)
    if x <= wp.float64(0.0):
        return (x + h) * (x + h) / (wp.float64(2.0) * h * h)
    return wp.float64(1.0) - (h - x) * (h - x) / (wp.float64(2.0) * h * h)


@wp.func
def tent_sum(depth: wp.array3d(dtype=wp.float32), c: int, i: wp.int64, j: wp.int64, tx: wp.float64, ty: wp.float64,
             h: wp.float64, radius: int, receiver: wp.float32, slope: wp.vec2d, x: wp.int64, y: wp.int64,
             unit: wp.int64, inverse_span: wp.float64) -> wp.float64:
    """Tent-weighted tests of the (2r + 1)² texels around texel (i, j); ``tx, ty`` the point in texels from
    texel i, j."""
    s = wp.float64(0.0)
    for dj in range(-radius, radius + 1):
        # The texel spans [dj, dj + 1) relative to texel j; the tent is centred at ty.
        wy = tent_cdf(wp.float64(dj + 1) - ty, h) - tent_cdf(wp.float64(dj) - ty, h)
        if wy > wp.float64(0.0):
            for di in range(-radius, radius + 1):
                wx = tent_cdf(wp.float64(di + 1) - tx, h) - tent_cdf(wp.float64(di) - tx, h)
                if wx > wp.float64(0.0):
                    t = tap(depth, c, i + wp.int64(di), j + wp.int64(dj), receiver, slope, x, y, unit, inverse_span)
                    s += wx * wy * wp.float64(t)
    return s


@wp.func
def blocker_depth(depth: wp.array3d(dtype=wp.float32), c: int, i: wp.int64, j: wp.int64, radius: int,
                  receiver: wp.float32, slope: wp.vec2d, x: wp.int64, y: wp.int64, unit: wp.int64,
                  inverse_span: wp.float64) -> wp.float64:
    """Mean stored depth of the texels among the (2r + 1)² around (i, j) that shadow the receiver plane; +inf if
    none."""
    total = wp.float64(0.0)
    count = int(0)
    top = wp.int64(depth.shape[1] - 1)
    for dj in range(-radius, radius + 1):
        for di in range(-radius, radius + 1):
            ii = i + wp.int64(di)
            jj = j + wp.int64(dj)
            if tap(depth, c, ii, jj, receiver, slope, x, y, unit, inverse_span) == 0:
                stored = depth[c, int(wp.clamp(jj, wp.int64(0), top)), int(wp.clamp(ii, wp.int64(0), top))]
                if is_finite(stored):
                    total += wp.float64(stored)
                    count += 1
    if count == 0:
        return wp.float64(wp.inf)
    return total / wp.float64(count)


@wp.func
def axis_fetch(code: int, size: int, a: int, x: wp.int64, unit: wp.int64):
    """Tap ``a`` of a separable bilinear-tap filter along one axis: its fixed-point position and weight.

    ``x`` is the point on that axis in ``2**-bits`` texels; the taps depend on ``x`` only through
    its remainder past a texel corner, so they move with a box by whole texels.
    """
    if code == PCF_BILINEAR_BOX:
        return x + wp.int64(a - size // 2) * unit, wp.float64(1.0)
    span = wp.int64(2) * unit
    # b: the texel corner nearest the point; s in [0, 1): the point's distance past b − ½, in texels.
    b = (wp.int64(2) * x + unit) // span
    s = wp.float64(wp.int64(2) * x + unit - b * span) / wp.float64(span)
    one = wp.float64(1.0)
    two = wp.float64(2.0)
    three = wp.float64(3.0)
    if code == PCF_CASTANO:
        u = wp.float64(0.0)
        w = wp.float64(0.0)
        if size == 3:
            if a == 0:
                w = three - two * s
                u = (two - s) / w - one
            else:
                w = one + two * s
                u = s / w + one
        else:
            if a == 0:
                w = wp.float64(4.0) - three * s
                u = (three - two * s) / w - two
            elif a == 1:
                w = wp.float64(7.0)
                u = (three + s) / w
            else:
                w = one + three * s
                u = s / w + two
        return b * unit + wp.int64(wp.round((u - wp.float64(0.5)) * wp.float64(unit))), w
    # PCF_TENT_BILINEAR: texels t0 = b − m + 2a and t0 + 1 of the N + 1 around b (m = (N + 1) / 2).
    h = wp.float64(size) * wp.float64(0.5)
    t0 = b - wp.int64((size + 1) // 2) + wp.int64(2 * a)
    p = wp.float64(x - t0 * unit) / wp.float64(unit)
    w0 = tent_cdf(one - p, h) - tent_cdf(-p, h)
    w1 = tent_cdf(two - p, h) - tent_cdf(one - p, h)
    w = w0 + w1
    share = wp.float64(0.5)
    if w > wp.float64(0.0):
        share = w1 / w
    return t0 * unit + wp.int64(wp.round((wp.float64(0.5) + share) * wp.float64(unit))), w


@wp.func
def axis_table(code: int, size: int, count: int, x: wp.int64, unit: wp.int64, bits: int, inverse_span: wp.float64):
    """The first ``count`` taps of a separable bilinear-tap filter along one axis (:func:`axis_fetch`), each as the
    texel its bilinear footprint starts at and its fraction
    (:func:`csmlab.kernels.shadow.bilinear_corner_shifted`), and its weight: taken once per axis, not once per
    tap of the 2-D kernel (``count`` at most :data:`AXIS_TAPS`)."""
    texel = axis_texels()
    fraction = axis_values()
    weight = axis_values()
    a = int(0)
    while a < count:
        q, w = axis_fetch(code, size, a, x, unit)
        t, f = bilinear_corner_shifted(q, unit, bits, inverse_span)
        texel[a] = t
        fraction[a] = f
        weight[a] = w
        a += 1
    return texel, fraction, weight


@wp.kernel
def axis_tables_kernel(code: int, sizes: wp.array(dtype=int), bits: int, texel: wp.array3d(dtype=wp.int64),
                       fraction: wp.array3d(dtype=wp.float64), weight: wp.array3d(dtype=wp.float64)):
    # The taps of size sizes[c] at the point r − unit/2 past the texel corner b = 0: those of any point of that
    # remainder, moved by b (see axis_tables).
    c, r = wp.tid()
    unit = wp.int64(1) << wp.int64(bits)
    inverse_span = wp.float64(1.0) / wp.float64(wp.int64(2) * unit)
    size = sizes[c]
    t, f, w = axis_table(code, size, (size + 1) // 2, wp.int64(r) - unit // wp.int64(2), unit, bits, inverse_span)
    a = int(0)
    while a < (size + 1) // 2:
        texel[c, r, a] = t[a]
        fraction[c, r, a] = f[a]
        weight[c, r, a] = w[a]
        a += 1


@wp.struct
class AxisTables:
    """The taps along one axis of a separable filter at every sub-texel remainder, per filter size
    (:func:`axis_tables`): ``texel[t, r, a]`` the first texel of tap a's footprint less the texel corner b
    nearest the point, ``fraction`` and ``weight`` its bilinear fraction and weight, for the size of table
    ``t = slot[c]`` of cascade c; ``r`` is the point's ``x − b·unit + unit/2``, in ``[0, unit)``."""

    slot: wp.array(dtype=int)
    texel: wp.array3d(dtype=wp.int64)
    fraction: wp.array3d(dtype=wp.float64)
    weight: wp.array3d(dtype=wp.float64)


@wp.func
def separable_lit(depth: wp.array3d(dtype=wp.float32), c: int, tables: AxisTables, size: int, x: wp.int64,
                  y: wp.int64, receiver: wp.float32, slope: wp.vec2d, unit: wp.int64,
                  inverse_span: wp.float64) -> wp.float64:
    """S of Castaño's kernel or the bilinear tent of ``size`` N in cascade c: ``Σ wx·wy·tap / Σ wx·wy`` over their
    ``(N + 1) / 2`` taps per axis, rows outer, each axis's taps read from the :class:`AxisTables` at the point's
    remainder."""
    count = (size + 1) // 2
    span = wp.int64(2) * unit
    table = tables.slot[c]
    # b: the texel corner nearest the point, as axis_fetch finds it; the tables hold the taps relative to it.
    bx = (wp.int64(2) * x + unit) // span
    by = (wp.int64(2) * y + unit) // span
    rx = int(x - bx * unit + unit // wp.int64(2))
    ry = int(y - by * unit + unit // wp.int64(2))
    s = wp.float64(0.0)
    total = wp.float64(0.0)
    # `while` loops: a range known only at run time costs Warp's CPU code several times more per step.
    bj = int(0)
    while bj < count:
        row_weight = tables.weight[table, ry, bj]
        row_texel = by + tables.texel[table, ry, bj]
        row_fraction = tables.fraction[table, ry, bj]
        ai = int(0)
        while ai < count:
            w = tables.weight[table, rx, ai] * row_weight
            s += w * bilinear_taps(depth, c, bx + tables.texel[table, rx, ai], tables.fraction[table, rx, ai],
                                   row_texel, row_fraction, receiver, slope, x, y, unit, inverse_span)
            total += w
            ai += 1
        bj += 1
    return s / total


@wp.func
def bilinear_box_lit(depth: wp.array3d(dtype=wp.float32), c: int, size: int, x: wp.int64, y: wp.int64,
                     receiver: wp.float32, slope: wp.vec2d, unit: wp.int64, bits: int,
                     inverse_span: wp.float64) -> wp.float64:
    """S of ``pcf_bilinear_box`` of ``size`` N: the mean of N × N bilinear taps at the point plus whole-texel offsets.

    A whole-texel offset moves a tap's footprint by whole texels and leaves its fraction, so one
    :func:`csmlab.kernels.shadow.bilinear_corner_shifted` per axis places every tap, and neighbouring taps
    of a row share a column of texels: each texel's test is taken once per row of taps, ``2(N + 1)`` tests
    a row for ``4N`` (UE5's 5 × 5: 60 for 100). The sum runs rows outer, as the weighted form
    ``Σ 1·1·tap`` does, each tap weighted as :func:`csmlab.kernels.shadow.bilinear_taps` weighs it: the same bits.
    """
    half = wp.int64(size // 2) * unit
    i0, fx = bilinear_corner_shifted(x - half, unit, bits, inverse_span)
    j0, fy = bilinear_corner_shifted(y - half, unit, bits, inverse_span)
    w1 = wp.float64(1.0)
    s = wp.float64(0.0)
    total = wp.float64(0.0)
    bj = int(0)
    while bj < size:
        j = j0 + wp.int64(bj)
        # Neighbouring taps share a column of their footprints: each column's two tests are taken once, as the
        # right column of one tap and the left of the next.
        left0 = wp.float64(tap(depth, c, i0, j, receiver, slope, x, y, unit, inverse_span))
        left1 = wp.float64(tap(depth, c, i0, j + wp.int64(1), receiver, slope, x, y, unit, inverse_span))
        ai = int(0)
        while ai < size:
            i = i0 + wp.int64(ai + 1)
            right0 = wp.float64(tap(depth, c, i, j, receiver, slope, x, y, unit, inverse_span))
            right1 = wp.float64(tap(depth, c, i, j + wp.int64(1), receiver, slope, x, y, unit, inverse_span))
            # bilinear_taps' weighting of the footprint's four tests, in its order.
            s += (w1 - fy) * ((w1 - fx) * left0 + fx * right0) + fy * ((w1 - fx) * left1 + fx * right1)
            total += w1
            left0 = right0
            left1 = right1
            ai += 1
        bj += 1
    return s / total


@wp.func
def weighted_lit(depth: wp.array3d(dtype=wp.float32), coords: wp.array3d(dtype=wp.int64),
                 receiver_depth: wp.array2d(dtype=wp.float32), receiver_slope: wp.array2d(dtype=wp.vec2d),
                 planar: int, c: int, row: int, k: int, bits: int, code: int, radius: int, width: wp.float64,
                 disk: wp.array(dtype=wp.vec2d), angle: wp.float64, tables: AxisTables) -> wp.float64:
    """S of receiver k in cascade c, its position, depth and slope in ``row`` of the receivers' arrays, under the
    weighted filter of kernel code ``code`` (PCF_GAUSSIAN … PCF_PCSS), ``bits`` sub-texel bits; ``planar`` 0: a flat
    receiver (``receiver_slope`` not read)."""
    unit = wp.int64(1) << wp.int64(bits)
    x = coords[row, k, 0]
    y = coords[row, k, 1]
    receiver = receiver_depth[row, k]
    slope = wp.vec2d()
    if planar != 0:
        slope = receiver_slope[row, k]
    inverse_span = wp.float64(1.0) / wp.float64(wp.int64(2) * unit)
    # An arithmetic shift floors as `//` does, without a division.
    i = x >> wp.int64(bits)
    j = y >> wp.int64(bits)
    # The point's position inside its texel, in texels: an exact fraction of `unit`.
    tx = wp.float64(x - i * unit) / wp.float64(unit)
    ty = wp.float64(y - j * unit) / wp.float64(unit)
    if code == PCF_GAUSSIAN:
        s = wp.float64(0.0)
        total = wp.float64(0.0)
        for dj in range(-radius, radius + 1):
            for di in range(-radius, radius + 1):
                w = wp.exp(-wp.float64(di * di + dj * dj) / (wp.float64(2.0) * width * width))
                t = tap(depth, c, i + wp.int64(di), j + wp.int64(dj), receiver, slope, x, y, unit, inverse_span)
                s += w * wp.float64(t)
                total += w
        return s / total
    if code == PCF_TENT:
        return tent_sum(depth, c, i, j, tx, ty, width, radius, receiver, slope, x, y, unit, inverse_span)
    if code == PCF_VOGEL:
        ca = wp.cos(angle)
        sa = wp.sin(angle)
        total = wp.float64(0.0)
        n = int(0)
        while n < disk.shape[0]:
            o = disk[n]
            ox = wp.int64(wp.round(width * (ca * o[0] - sa * o[1]) * wp.float64(unit)))
            oy = wp.int64(wp.round(width * (sa * o[0] + ca * o[1]) * wp.float64(unit)))
            total += bilinear_tap(depth, c, x + ox, y + oy, receiver, slope, x, y, unit, bits, inverse_span)
            n += 1
        return total / wp.float64(disk.shape[0])
    if code == PCF_CASTANO or code == PCF_TENT_BILINEAR or code == PCF_BILINEAR_BOX:
        # width carries N / 2; Castaño's and the tent's N + 1 texels per axis take (N + 1) / 2 taps.
        size = int(wp.round(wp.float64(2.0) * width))
        if code == PCF_BILINEAR_BOX:
            return bilinear_box_lit(depth, c, size, x, y, receiver, slope, unit, bits, inverse_span)
        return separable_lit(depth, c, tables, size, x, y, receiver, slope, unit, inverse_span)
    if code == PCF_POISSON:
        ca = wp.cos(angle)
        sa = wp.sin(angle)
        count = int(0)
        for n in range(disk.shape[0]):
            o = disk[n]
            ox = wp.int64(wp.round(width * (ca * o[0] - sa * o[1]) * wp.float64(unit)))
            oy = wp.int64(wp.round(width * (sa * o[0] + ca * o[1]) * wp.float64(unit)))
            count += tap(depth, c, (x + ox) >> wp.int64(bits), (y + oy) >> wp.int64(bits), receiver, slope, x, y, unit,
                         inverse_span)
        return wp.float64(count) / wp.float64(disk.shape[0])
    if is_nan(receiver):
        return wp.float64(0.0)
    blocker = blocker_depth(depth, c, i, j, radius, receiver, slope, x, y, unit, inverse_span)
    if not is_finite(blocker):
        return wp.float64(1.0)
    half = wp.clamp(wp.float64(0.5) * (wp.float64(receiver) - blocker) * width, wp.float64(0.5), wp.float64(radius))
    return tent_sum(depth, c, i, j, tx, ty, half, radius, receiver, slope, x, y, unit, inverse_span)


@wp.kernel
def weighted_pcf_kernel(
    depth: wp.array3d(dtype=wp.float32),
    coords: wp.array3d(dtype=wp.int64),
    receiver_depth: wp.array2d(dtype=wp.float32),
    receiver_slope: wp.array2d(dtype=wp.vec2d),
    planar: int,
    picked: int,
    cascade: wp.array(dtype=wp.int32),
    blend_weight: wp.array(dtype=wp.float64),
    width: wp.array(dtype=wp.float64),
    angle: wp.array(dtype=wp.float64),
    disk: wp.array(dtype=wp.vec2d),
    bits: int,
    code: int,
    radius: int,
    tables: AxisTables,
    lit: wp.array(dtype=wp.float32),
):
    k = wp.tid()
    c = cascade[k]
    if c < 0:
        lit[k] = wp.float32(wp.nan)
        return
    # The rows of the receivers' arrays: every cascade's, or (picked) the selected cascade's and the next's.
    row = c
    if picked != 0:
        row = 0
    s = weighted_lit(depth, coords, receiver_depth, receiver_slope, planar, c, row, k, bits, code, radius, width[c],
                     disk, angle[k], tables)
    w = blend_weight[k]
    if w > wp.float64(0.0):
        s = (wp.float64(1.0) - w) * s + w * weighted_lit(depth, coords, receiver_depth, receiver_slope, planar, c + 1,
                                                         row + 1, k, bits, code, radius, width[c + 1], disk, angle[k],
                                                         tables)
    lit[k] = wp.float32(s)


def axis_tables(code: int, width, *, bits: int, device: str) -> AxisTables:
    """The :class:`AxisTables` of a separable filter (kernel ``code``) of per-cascade ``width`` N / 2, at ``bits``
    sub-texel bits; for any other filter one element stands in for each table.

    A separable filter's taps along an axis depend on the point ``x`` only through its remainder
    ``x − b·unit`` past the texel corner ``b`` nearest it (:func:`axis_fetch`): its fixed-point tap
    positions move by ``b·unit``, their bilinear footprints by ``b`` texels and their fractions and
    weights not at all. So the taps are computed once for each of the ``unit`` remainders, by
    :func:`axis_table` itself, and the kernel reads them: the same texels, fractions and weights as
    computing them per receiver, bit for bit, without the tent's or Castaño's divisions per tap
    (Unity's 7×7 tent: 78 → 50 ms a lookup of 197k receivers).
    """
    separable = code in (PCF_CASTANO, PCF_TENT_BILINEAR)
    # The kernel's wp.round(2·width), which rounds half away from zero (the widths are positive).
    sizes = [int(np.floor(2.0 * v + 0.5)) for v in np.atleast_1d(width)] if separable else []
    return _axis_tables(code, tuple(sizes), int(bits), device)


@functools.lru_cache(maxsize=16)
def _axis_tables(code: int, sizes: tuple, bits: int, device: str) -> AxisTables:
    distinct = sorted(set(sizes))
    tables = AxisTables()
    tables.slot = wp.array([distinct.index(size) for size in sizes] or [0], dtype=int, device=device)
    shape = (len(distinct), 1 << bits, max((size + 1) // 2 for size in distinct)) if distinct else (1, 1, 1)
    tables.texel = wp.zeros(shape, dtype=wp.int64, device=device)
    tables.fraction = wp.zeros(shape, dtype=wp.float64, device=device)
    tables.weight = wp.zeros(shape, dtype=wp.float64, device=device)
    if distinct:
        wp.launch(axis_tables_kernel, dim=shape[:2], inputs=(code, wp.array(distinct, dtype=int, device=device), bits),
                  outputs=(tables.texel, tables.fraction, tables.weight), device=device)
    return tables


def _checked(depth, coords, receiver_depth, receiver_slope, cascade, width, picked: bool):
    maps = np.ascontiguousarray(depth, dtype=np.float32)
    if maps.ndim != 3 or maps.shape[1] != maps.shape[2] or maps.shape[0] == 0:
        raise ValueError(f"depth: expected depth maps of shape (C, R, R), got {maps.shape}")
    cascades = maps.shape[0]
    count = 2 if picked else cascades
    xy = np.ascontiguousarray(coords, dtype=np.int64)
    n = xy.shape[1] if xy.ndim == 3 else -1
    rd = np.ascontiguousarray(receiver_depth, dtype=np.float32)
    # No slope: flat receivers, and one element stands in for the array the kernel does not read.
    slope = np.zeros((1, 1, 2)) if receiver_slope is None else np.ascontiguousarray(receiver_slope, dtype=np.float64)
    chosen = np.ascontiguousarray(cascade, dtype=np.int32)
    w = np.ascontiguousarray(np.broadcast_to(np.asarray(width, dtype=np.float64), (cascades,)))
    if xy.shape != (count, n, 2) or rd.shape != (count, n) or chosen.shape != (n,) or (
            receiver_slope is not None and slope.shape != (count, n, 2)):
        raise ValueError(f"coords, receiver_depth, receiver_slope, cascade: expected shapes ({count}, N, 2), "
                         f"({count}, N), ({count}, N, 2), (N,); got {xy.shape}, {rd.shape}, {slope.shape}, "
                         f"{chosen.shape}")
    if np.any(chosen >= cascades):
        raise ValueError(f"cascade: expected indices below {cascades} (or −1 for none), got {chosen.max()}")
    if not np.all(np.isfinite(w) & (w > 0)):
        raise ValueError(f"width: expected positive texel widths per cascade, got {w}")
    return maps, xy, rd, slope, chosen, w, n


def weighted_pcf(depth, coords, receiver_depth, *, cascade, filter: str, width, radius: int, bits: int,
                 receiver_slope=None, blend_weight=None, angle=None, disk=None, picked: bool = False,
                 device: str = "cpu") -> np.ndarray:
    """Lit fraction S of receivers at their selected cascade under a weighted PCF filter.

    Parameters
    ----------
    depth : array_like, shape (C, R, R), float32
        Depth maps, metres (``depth[c, j, i]``), +inf where empty.
    coords : array_like, shape (C, N, 2), int64
        Receivers in ``2**-bits`` texels of each cascade (:func:`csmlab.texels.receiver_lookup`).
    receiver_depth : array_like, shape (C, N), float32
        Biased receiver depth per cascade, metres; NaN is shadowed by every texel.
    cascade : array_like, shape (N,), int
        The selected cascade of each receiver, −1 for none (S is NaN there).
    filter : str
        A filter of the ``weighted`` family (:data:`csmlab.lookup_choices.FILTER_METHODS`).
    width : float or array_like, shape (C,)
        Per cascade, in texels: σ (``pcf_gaussian``), tent half-width (``pcf_tent``), disk radius
        (``pcf_poisson``, ``pcf_vogel``), N / 2 (``pcf_castano``, ``pcf_tent_bilinear``,
        ``pcf_bilinear_box``); for ``pcss`` the penumbra per metre of blocker distance,
        ``2 tan(θ_L / 2) / texel`` (1/m).
    radius : int
        Taps reach at most ``radius`` texels from the texel holding the point: the filter record's
        ``radius_of`` (the caller keeps the taps inside the box).
    bits : int
        Sub-texel bits of ``coords``.
    receiver_slope : array_like, shape (C, N, 2), float64, optional
        Receiver-plane depth change per texel (metres); None compares the receiver's own depth.
    blend_weight : array_like, shape (N,), float64, optional
        Weight in [0, 1) of cascade ``cascade + 1`` mixed into S (blend band); None: no blend.
    angle : array_like, shape (N,), float64, optional
        ``pcf_poisson``, ``pcf_vogel``: rotation of the disk per receiver, radians; None: unrotated.
    disk : array_like, shape (K, 2), float64, optional
        ``pcf_poisson``, ``pcf_vogel``: tap offsets in the unit disk.
    picked : bool
        ``coords``, ``receiver_depth`` and ``receiver_slope`` hold two rows, ``(2, N, ...)``: each
        receiver at its selected cascade and at the next
        (:func:`csmlab.kernels.shadow.select_world_cascades`,
        :func:`~csmlab.kernels.shadow.select_window_cascades`), in place of every cascade's.
    device : str
        ``"cpu"`` or ``"cuda"``.

    Returns
    -------
    ndarray, shape (N,), float32
        S in [0, 1]; NaN where ``cascade`` is −1.

    Raises
    ------
    ValueError
        On an unknown filter (the message lists the valid names), shapes that do not match, a
        non-positive width (or one of more than :data:`AXIS_TAPS` taps per axis for ``pcf_castano`` and
        ``pcf_tent_bilinear``), a missing disk for ``pcf_poisson`` or a negative radius.
    """
    device = checked_device(device)
    code = family_code(filter, family="weighted")
    if not (isinstance(radius, (int, np.integer)) and radius >= 0):
        raise ValueError(f"radius: expected a non-negative integer, got {radius!r}")
    maps, xy, rd, slope, chosen, w, n = _checked(depth, coords, receiver_depth, receiver_slope, cascade, width,
                                                 picked)
    if code in (PCF_CASTANO, PCF_TENT_BILINEAR) and np.any((np.floor(2.0 * w + 0.5) + 1) // 2 > AXIS_TAPS):
        raise ValueError(f"width: {filter} takes at most {AXIS_TAPS} taps per axis (N / 2 ≤ {AXIS_TAPS - 0.5}), "
                         f"got {w}")
    taps = np.zeros((1, 2)) if disk is None else np.ascontiguousarray(disk, dtype=np.float64)
    if code in (PCF_POISSON, PCF_VOGEL) and (disk is None or taps.ndim != 2 or taps.shape[1] != 2
                                             or taps.shape[0] == 0):
        raise ValueError(f"disk: expected tap offsets of shape (K, 2) for {filter}, got {np.shape(disk)}")
    blend = np.zeros(n) if blend_weight is None else np.ascontiguousarray(blend_weight, dtype=np.float64)
    turn = np.zeros(n) if angle is None else np.ascontiguousarray(angle, dtype=np.float64)
    if blend.shape != (n,) or turn.shape != (n,):
        raise ValueError(f"blend_weight, angle: expected shape ({n},), got {blend.shape}, {turn.shape}")
    if np.any((blend > 0) & (chosen + 1 >= maps.shape[0])):
        raise ValueError("blend_weight: a receiver of the last cascade cannot blend with a next one")
    if n == 0:
        return np.zeros(0, np.float32)
    lit = wp.empty(n, dtype=wp.float32, device=device)
    wp.launch(
        weighted_pcf_kernel,
        dim=n,
        inputs=(
            wp.array(maps, dtype=wp.float32, device=device, copy=False),
            wp.array(xy, dtype=wp.int64, device=device, copy=False),
            wp.array(rd, dtype=wp.float32, device=device, copy=False),
            wp.array(slope, dtype=wp.vec2d, device=device, copy=False),
            int(receiver_slope is not None),
            int(bool(picked)),
            wp.array(chosen, dtype=wp.int32, device=device, copy=False),
            wp.array(blend, dtype=wp.float64, device=device, copy=False),
            wp.array(w, dtype=wp.float64, device=device, copy=False),
            wp.array(turn, dtype=wp.float64, device=device, copy=False),
            wp.array(taps, dtype=wp.vec2d, device=device),
            int(bits),
            code,
            int(radius),
            axis_tables(code, w, bits=int(bits), device=device),
        ),
        outputs=(lit,),
        device=device,
    )
    return lit.numpy()
