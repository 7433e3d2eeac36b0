"""Depth rasterization of every cascade in fixed point (DESIGN.md, CSM model step 4).

A texel is covered when its centre lies inside the triangle; it stores the minimum light-space
depth of the triangles covering it (metres, ``d·X − zref``); empty texels hold +inf. Vertices
arrive as int64 fixed-point coordinates in ``2**-bits`` texels relative to the box origin
(:func:`csmlab.texels.fixed_point_coordinates`). The kernel doubles them so that texel centres,
``(i + ½, j + ½)`` texels, are integers too, forms each edge function from int64 *differences*
converted to float64, and interpolates depth with barycentrics made of the same edge functions.
The edge functions are exact integers while a triangle spans less than ``2**(25 − bits)`` texels
(131,072 at 8 bits, 8,192 at 12); then nothing depends on where the box lies, and a box moved by
whole texels gives the same depths, shifted, bit for bit. Larger triangles are still rasterized
deterministically, with float64 rounding in their edge functions.

Centres exactly on an edge follow the top-left rule, stated for triangles turned counter-clockwise
(x right, y up): an edge owns its centres when it points down, or left if horizontal. That is the
sample point nudged toward +x and slightly −y, so two triangles sharing an edge, or a fan around a
vertex, cover each centre exactly once whatever their input winding.

References
----------
- Pineda, "A Parallel Algorithm for Polygon Rasterization", SIGGRAPH 1988 — edge functions.
- Microsoft, Direct3D 11 rasterization rules — the top-left rule and sub-pixel fixed point.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import warp as wp

from csmlab.kernels import checked_device, device_empty
from csmlab.kernels.threads import LaunchPool, checked_threads, split_range

__all__ = ["BANDS_PER_THREAD", "CHUNK_BITS", "LightSpaceMesh", "TriangleBounds", "banded_regions",
           "fixed_point_vertices", "light_space_mesh", "rasterize_cascades", "rasterize_depth", "region_chunks",
           "triangle_bounds", "whole_map_regions", "z_ordered"]

# Products and sums rounded one by one, as Warp's CPU build (generic x86-64, no FMA) rounds them: a
# CUDA build may not contract them into fused multiply-adds, or its bits differ from the CPU's.
wp.set_module_options({"fuse_fp": False})


@wp.func
def edge_owns_centre(dx: wp.int64, dy: wp.int64) -> bool:
    """Top-left tie-break of a counter-clockwise edge with direction ``(dx, dy)``."""
    return dy < wp.int64(0) or (dy == wp.int64(0) and dx < wp.int64(0))


@wp.func
def edge_inside(e: wp.float64, owns: bool) -> bool:
    return e > wp.float64(0.0) or (e == wp.float64(0.0) and owns)


@wp.func
def owned_bias(owns: bool) -> wp.float64:
    """The bound an exact integer edge function must exceed: −½ (≥ 0) for an owning edge, else 0."""
    if owns:
        return wp.float64(-0.5)
    return wp.float64(0.0)


@wp.func
def reciprocal(x: wp.float64) -> wp.float64:
    """``1 / x``, 0 for 0 (an edge parallel to the rows, which :func:`run_bounds` handles apart)."""
    if x == wp.float64(0.0):
        return wp.float64(0.0)
    return wp.float64(1.0) / x


@wp.func
def run_bounds(w: wp.float64, step: wp.float64, inverse_step: wp.float64, bias: wp.float64, start: wp.float64,
               lo: wp.float64, hi: wp.float64):
    """``[lo, hi]`` (texel columns, whole numbers in float64) narrowed to where ``w − step·(i − start) > bias`` may hold.

    ``w`` is the edge function at column ``start``. The bound ``⌊(w − bias)·(1 / step)⌋`` is off by
    far less than a column (|w| < 2**53, a few roundings); the upper bound is widened by one
    column, and the lower one is ``⌊·⌋`` of a quantity whose true value exceeds it by more than
    the error, so the run is never cut: the exact test decides every column in it.
    """
    if step == wp.float64(0.0):
        if not (w > bias):
            hi = lo - wp.float64(1.0)
        return lo, hi
    q = wp.floor((w - bias) * inverse_step)
    if step > wp.float64(0.0):
        hi = wp.min(hi, start + q + wp.float64(1.0))
    else:
        lo = wp.max(lo, start + q - wp.float64(1.0))
    return lo, hi


@wp.func
def first_centre(lo: wp.int64, unit: wp.int64, bits: wp.int64, begin: int, end: int) -> int:
    """First texel whose centre, ``(2k + 1)·unit`` in doubled units, is at or above ``lo``, clamped to ``[begin, end]``.

    ``unit = 2**bits``: the floor division by ``2·unit`` is an arithmetic shift by ``bits + 1``.
    """
    k = -((unit - lo) >> (bits + wp.int64(1)))
    return int(wp.clamp(k, wp.int64(begin), wp.int64(end)))


@wp.func
def last_centre(hi: wp.int64, unit: wp.int64, bits: wp.int64, begin: int, end: int) -> int:
    """Last texel whose centre is at or below ``hi``, clamped to ``[begin − 1, end − 1]``."""
    k = (hi - unit) >> (bits + wp.int64(1))
    return int(wp.clamp(k, wp.int64(begin - 1), wp.int64(end - 1)))


@wp.func
def edge_values(px: wp.int64, ax: wp.int64, ay: wp.int64, bx: wp.int64, by: wp.int64, cx: wp.int64, cy: wp.int64,
                row_ab: wp.float64, row_bc: wp.float64, row_ca: wp.float64):
    """The three edge functions at the centre of column ``px`` (doubled units) of a row, from the row's terms."""
    return (row_ab - wp.float64(by - ay) * wp.float64(px - ax), row_bc - wp.float64(cy - by) * wp.float64(px - bx),
            row_ca - wp.float64(ay - cy) * wp.float64(px - cx))


_KEEP_NEARER = """
#if defined(__CUDA_ARCH__)
    if (covered) wp::atomic_min(&wp::index(depth, c, j, i), z);
#else
    float* texel = reinterpret_cast<float*>(reinterpret_cast<char*>(depth.data) + c * size_t(depth.strides[0])
                                            + j * size_t(depth.strides[1]) + i * size_t(depth.strides[2]));
    const float held = *texel;
    *texel = (covered && z < held) ? z : held;
#endif
"""


@wp.func_native(_KEEP_NEARER)
def keep_nearer(depth: wp.array3d(dtype=wp.float32), c: int, j: int, i: int, z: wp.float32, covered: bool):
    """Texel (i, j) of cascade c keeps the nearer of its depth and ``z`` (metres) where ``covered``; else its own.

    On a GPU an atomic minimum, for many threads meet at a texel. A CPU launch writes texels no
    other launch writes (:func:`rasterize_cascades`), so there it is a plain load, compare and
    store at an address made from the strides (the indices are never negative: no wrap), without
    the atomic's NaN handling (no depth is NaN): 5-8 % faster walks than ``wp.atomic_min``.
    """
    ...


@wp.func
def offer_depth(depth: wp.array3d(dtype=wp.float32), c: int, j: int, i: int, inside: int, w_a: wp.float64,
                w_b: wp.float64, w_c: wp.float64, za: wp.float64, zb: wp.float64, zc: wp.float64, area: wp.float64):
    """Texel (i, j) keeps the nearer of its depth and the triangle's if ``inside`` (interpolated with edge functions).

    The depth is computed whether or not the centre is inside: a test as often false as true
    (a small triangle's bounding box) is not worth a branch. An empty ``depth`` (a counting
    pass, :func:`rasterize_cascades` with ``count_only``) stores nothing.
    """
    if depth.shape[0] > 0:
        keep_nearer(depth, c, j, i, wp.float32((w_a * za + w_b * zb + w_c * zc) / area), inside > 0)


_WALK_RUN = """
int count = 0;
const int n = hi - lo + 1;
#if defined(__CUDA_ARCH__)
for (int k = 0; k < n; ++k) {
    const double step = static_cast<double>(k);
    const double e_c = w_c - step_c * step;
    const double e_a = w_a - step_a * step;
    const double e_b = w_b - step_b * step;
    if (e_c > bias_ab && e_a > bias_bc && e_b > bias_ca) {
        ++count;
        if (depth.shape[0] > 0) {
            const double sum = __dadd_rn(__dadd_rn(__dmul_rn(e_a, za), __dmul_rn(e_b, zb)), __dmul_rn(e_c, zc));
            wp::atomic_min(&wp::index(depth, c, j, lo + k), static_cast<float>(__ddiv_rn(sum, area)));
        }
    }
}
#else
{
#pragma clang fp contract(off)
    float* row = reinterpret_cast<float*>(reinterpret_cast<char*>(depth.data) + c * size_t(depth.strides[0])
                                          + j * size_t(depth.strides[1])) + lo;
    const bool store = depth.shape[0] > 0;
#pragma clang loop vectorize_width(4) interleave_count(1) vectorize_predicate(enable)
    for (int k = 0; k < n; ++k) {
        const double step = static_cast<double>(k);
        const double e_c = w_c - step_c * step;
        const double e_a = w_a - step_a * step;
        const double e_b = w_b - step_b * step;
        const bool inside = (e_c > bias_ab) & (e_a > bias_bc) & (e_b > bias_ca);
        count += inside;
        if (store) {
            const float z = static_cast<float>((e_a * za + e_b * zb + e_c * zc) / area);
            const float held = row[k];
            row[k] = (inside & (z < held)) ? z : held;
        }
    }
}
#endif
return count;
"""


@wp.func_native(_WALK_RUN)
def walk_run(depth: wp.array3d(dtype=wp.float32), c: int, j: int, lo: int, hi: int, w_c: wp.float64,
             w_a: wp.float64, w_b: wp.float64, step_c: wp.float64, step_a: wp.float64, step_b: wp.float64,
             bias_ab: wp.float64, bias_bc: wp.float64, bias_ca: wp.float64, za: wp.float64, zb: wp.float64,
             zc: wp.float64, area: wp.float64) -> int:
    """Texels ``lo..hi`` of row j of cascade c: each centre tested, counted, its depth kept where nearer; the count.

    ``w_c, w_a, w_b`` are a stepped triangle's edge functions at the centre of column ``lo``,
    each falling by its ``step`` per column; a centre is inside where all three exceed their
    bias (:func:`owned_bias`). They are exact integers in float64 (:func:`rasterize_triangle`),
    so ``w − step·k`` is the same number as k subtractions, and the depth
    ``(w_a·za + w_b·zb + w_c·zc) / area`` is rounded in that order, unfused: the map is the same,
    bit for bit, as one walked a texel at a time. The map's rows must be contiguous.

    Native code so that, on a CPU, clang vectorizes the run four texels at a time (masking the
    last ones): at ~1M triangles, 4 × 1024² on two threads 38.5 → 33.4 ms, at 136k 19.3 → 14.4 ms
    (interleaved A/B). On a GPU a thread's run is walked a texel at a time, its depth rounded as
    on the CPU (``__dmul_rn``, ``__dadd_rn``: no fused multiply-add) and kept by an atomic minimum.
    """
    ...


@wp.func
def centre_covered(px: wp.int64, py: wp.int64, ax: wp.int64, ay: wp.int64, bx: wp.int64, by: wp.int64, cx: wp.int64,
                   cy: wp.int64, bias_ab: wp.float64, bias_bc: wp.float64, bias_ca: wp.float64, za: wp.float64,
                   zb: wp.float64, zc: wp.float64, area: wp.float64, depth: wp.array3d(dtype=wp.float32), c: int, j: int,
                   i: int) -> int:
    """1 if the centre ``(px, py)`` (doubled units) of texel (i, j) lies in the triangle, else 0.

    The edge functions are exact integers (a stepped triangle's), so each test is one comparison
    against the edge's bias (:func:`owned_bias`), and they are the walk's values bit for bit. The
    depth is stored without a branch (:func:`offer_depth`).
    """
    w_c, w_a, w_b = edge_values(px, ax, ay, bx, by, cx, cy, wp.float64(bx - ax) * wp.float64(py - ay),
                                wp.float64(cx - bx) * wp.float64(py - by), wp.float64(ax - cx) * wp.float64(py - cy))
    inside = int(w_c > bias_ab) * int(w_a > bias_bc) * int(w_b > bias_ca)
    offer_depth(depth, c, j, i, inside, w_a, w_b, w_c, za, zb, zc, area)
    return inside


@wp.func
def rasterize_triangle(
    ax: wp.int64,
    ay: wp.int64,
    bx: wp.int64,
    by: wp.int64,
    cx: wp.int64,
    cy: wp.int64,
    za: wp.float64,
    zb: wp.float64,
    zc: wp.float64,
    unit: wp.int64,
    bits: wp.int64,
    depth: wp.array3d(dtype=wp.float32),
    c: int,
    window: wp.vec4i,
) -> int:
    """Rasterize one triangle into texels ``[i0, i1) × [j0, j1)`` (``window``) of cascade c's map.

    The vertices are fixed-point coordinates already doubled (texel centres at odd multiples of
    ``unit = 2**bits``), with depths ``za, zb, zc``. Returns the number of texel centres covered.
    """
    # Cull before any per-texel work: triangles whose bounding box holds no texel centre of the
    # window, and triangles of zero area.
    two = wp.int64(2)
    i0 = first_centre(wp.min(wp.min(ax, bx), cx), unit, bits, window[0], window[1])
    i1 = last_centre(wp.max(wp.max(ax, bx), cx), unit, bits, window[0], window[1])
    j0 = first_centre(wp.min(wp.min(ay, by), cy), unit, bits, window[2], window[3])
    j1 = last_centre(wp.max(wp.max(ay, by), cy), unit, bits, window[2], window[3])
    if i0 > i1 or j0 > j1:
        return 0
    area = wp.float64(bx - ax) * wp.float64(cy - ay) - wp.float64(by - ay) * wp.float64(cx - ax)
    if area == wp.float64(0.0):
        return 0
    if area < wp.float64(0.0):
        # Turn the triangle counter-clockwise so that one top-left rule serves both windings.
        sx = bx
        sy = by
        sz = zb
        bx = cx
        by = cy
        zb = zc
        cx = sx
        cy = sy
        zc = sz
        area = -area
    own_ab = edge_owns_centre(bx - ax, by - ay)
    own_bc = edge_owns_centre(cx - bx, cy - by)
    own_ca = edge_owns_centre(ax - cx, ay - cy)
    # Every centre walked lies in the triangle's bounding box, so each product of differences is
    # at most extent² and each edge function 2·extent² in magnitude: below 2**53 they are exact
    # integers in float64, and stepping one texel right by adding the constant −dy·2·unit gives
    # the same bits as evaluating afresh — three additions per texel instead of three products.
    extent = wp.max(wp.max(wp.max(ax, bx), cx) - wp.min(wp.min(ax, bx), cx),
                    wp.max(wp.max(ay, by), cy) - wp.min(wp.min(ay, by), cy))
    stepped = extent < wp.int64(67108864)  # 2**26
    if stepped and i0 == i1 and j0 == j1:
        # One centre to test (most triangles of a far cascade): tested and stored without a branch,
        # as the walk below would, without its set-up.
        return centre_covered((two * wp.int64(i0) + wp.int64(1)) * unit, (two * wp.int64(j0) + wp.int64(1)) * unit,
                              ax, ay, bx, by, cx, cy, owned_bias(own_ab), owned_bias(own_bc), owned_bias(own_ca), za,
                              zb, zc, area, depth, c, j0, i0)
    step = two * unit
    count = int(0)
    if stepped:
        step_c = wp.float64(by - ay) * wp.float64(step)
        step_a = wp.float64(cy - by) * wp.float64(step)
        step_b = wp.float64(ay - cy) * wp.float64(step)
        # With exact integer edge functions, "inside or owned" is one comparison against a bias:
        # e > 0, or e ≥ 0 (e > −½) where the edge owns its centres.
        bias_ab = owned_bias(own_ab)
        bias_bc = owned_bias(own_bc)
        bias_ca = owned_bias(own_ca)
        # A run is solved for only across bounding boxes wide enough to repay three divisions and
        # the solving of each row: a narrow one is walked whole (walk_run, four texels at a time).
        # Seventeen columns: 2-5 % less than from nine, as much as from 33; never solving took
        # 3-27 % more (~1M and 136k triangles, 4 × 1024² and 2048², interleaved A/B).
        wide = i1 - i0 >= 16
        inverse_c = wp.float64(0.0)
        inverse_a = wp.float64(0.0)
        inverse_b = wp.float64(0.0)
        if wide:
            inverse_c = reciprocal(step_c)
            inverse_a = reciprocal(step_a)
            inverse_b = reciprocal(step_b)
        # The edge functions at the first centre of the first row; a row up adds dx·2·unit, exactly.
        bottom = (two * wp.int64(j0) + wp.int64(1)) * unit
        row_c, row_a, row_b = edge_values((two * wp.int64(i0) + wp.int64(1)) * unit, ax, ay, bx, by, cx, cy,
                                          wp.float64(bx - ax) * wp.float64(bottom - ay),
                                          wp.float64(cx - bx) * wp.float64(bottom - by),
                                          wp.float64(ax - cx) * wp.float64(bottom - cy))
        rise_c = wp.float64(bx - ax) * wp.float64(step)
        rise_a = wp.float64(cx - bx) * wp.float64(step)
        rise_b = wp.float64(ax - cx) * wp.float64(step)
        start = wp.float64(i0)
        end = wp.float64(i1)
        # `while` loops: a range known only at run time costs Warp's CPU code several times more per step.
        j = j0
        while j <= j1:
            # Each edge function falls by its step per texel, so the centres inside form one run;
            # its ends, solved from the three edges (widened by a texel against rounding), bound
            # the walk, and walk_run's exact test decides every centre in it.
            lo = start
            hi = end
            if wide:
                lo, hi = run_bounds(row_c, step_c, inverse_c, bias_ab, start, lo, hi)
                lo, hi = run_bounds(row_a, step_a, inverse_a, bias_bc, start, lo, hi)
                lo, hi = run_bounds(row_b, step_b, inverse_b, bias_ca, start, lo, hi)
            if lo <= hi:
                skip = lo - start
                w_c = row_c - step_c * skip
                w_a = row_a - step_a * skip
                w_b = row_b - step_b * skip
                count += walk_run(depth, c, j, int(lo), int(hi), w_c, w_a, w_b, step_c, step_a, step_b, bias_ab,
                                  bias_bc, bias_ca, za, zb, zc, area)
            row_c = row_c + rise_c
            row_a = row_a + rise_a
            row_b = row_b + rise_b
            j += 1
    else:
        for j in range(j0, j1 + 1):
            py = (two * wp.int64(j) + wp.int64(1)) * unit
            row_ab = wp.float64(bx - ax) * wp.float64(py - ay)
            row_bc = wp.float64(cx - bx) * wp.float64(py - by)
            row_ca = wp.float64(ax - cx) * wp.float64(py - cy)
            for i in range(i0, i1 + 1):
                w_c, w_a, w_b = edge_values((two * wp.int64(i) + wp.int64(1)) * unit, ax, ay, bx, by, cx, cy, row_ab,
                                            row_bc, row_ca)
                if edge_inside(w_c, own_ab) and edge_inside(w_a, own_bc) and edge_inside(w_b, own_ca):
                    offer_depth(depth, c, j, i, 1, w_a, w_b, w_c, za, zb, zc, area)
                    count += 1
    return count


@wp.kernel
def rasterize_depth_kernel(
    points: wp.array3d(dtype=wp.int64),
    vertex_depth: wp.array(dtype=wp.float64),
    triangles: wp.array2d(dtype=wp.int32),
    unit: wp.int64,
    bits: wp.int64,
    depth: wp.array3d(dtype=wp.float32),
    covered: wp.array2d(dtype=wp.int32),
):
    c, t = wp.tid()
    ia = triangles[t, 0]
    ib = triangles[t, 1]
    ic = triangles[t, 2]
    two = wp.int64(2)
    covered[c, t] = rasterize_triangle(
        two * points[c, ia, 0], two * points[c, ia, 1], two * points[c, ib, 0], two * points[c, ib, 1],
        two * points[c, ic, 0], two * points[c, ic, 1], vertex_depth[ia], vertex_depth[ib], vertex_depth[ic], unit,
        bits, depth, c, wp.vec4i(0, depth.shape[2], 0, depth.shape[1]))


vec2l = wp.types.vector(length=2, dtype=wp.int64)
"""A vertex's two fixed-point coordinates (x, y): read and written as one 16-byte value."""


@wp.func
def doubled_fixed_point(u: wp.float64, step: wp.float64, limit: wp.float64, origin: wp.int64) -> wp.int64:
    """Twice a light-space coordinate ``u`` (metres) in local ``2**-bits`` texels; ``step = texel / 2**bits`` metres.

    :func:`csmlab.texels.fixed_point_coordinates` computes ``rint(u / texel · 2**bits) − origin``.
    Scaling by a power of two commutes with rounding, so ``u / (texel / 2**bits)`` is the same
    float64 (both sides overflow alike, and an underflow differs only below 2**-1000, which rounds
    to 0 anyway): one division, no product. No sum, so no fused multiply-add can change a
    rounding. NaN is caught by ``v != v``: ``wp.isnan`` is a function call on the CPU.
    """
    v = wp.rint(wp.clamp(u / step, -limit, limit))
    if v != v:
        v = -limit
    return wp.int64(2) * (wp.int64(v) - origin)


@wp.func
def doubled_fixed_point_vertex(u: wp.vec2d, step: wp.vec2d, limit: wp.float64, origin: vec2l) -> vec2l:
    """:func:`doubled_fixed_point` of both coordinates of a vertex."""
    return vec2l(doubled_fixed_point(u[0], step[0], limit, origin[0]),
                 doubled_fixed_point(u[1], step[1], limit, origin[1]))


@wp.kernel
def fixed_point_vertices_kernel(
    light_xy: wp.array(dtype=wp.vec2d),
    texel_size: wp.array(dtype=wp.vec2d),
    origin: wp.array(dtype=vec2l),
    cascades: wp.array(dtype=wp.int32),
    first: int,
    last: int,
    run: int,
    scale: wp.float64,
    limit: wp.float64,
    points: wp.array2d(dtype=vec2l),
):
    """``points[s, v]``: vertex v of ``[first, last)`` in cascade ``cascades[s]``'s doubled fixed point.

    A thread per s and run of ``run`` vertices (on the CPU many, so that a thread's set-up serves
    them all; on a GPU one). A vertex is read and written as one vector of its two coordinates, so
    the index arithmetic is done once per vertex, not per coordinate: at ~500k vertices × 4
    cascades, 15 → 4.5 ms on one thread.
    """
    s, k = wp.tid()
    v = first + k * run
    end = wp.min(v + run, last)
    c = cascades[s]
    step = texel_size[c] / scale
    corner = origin[c]
    while v < end:
        points[s, v] = doubled_fixed_point_vertex(light_xy[v], step, limit, corner)
        v += 1


@wp.func
def doubled_vertex(points: wp.array2d(dtype=vec2l), s: int, light_xy: wp.array(dtype=wp.vec2d), v: int,
                   step: wp.vec2d, corner: vec2l, limit: wp.float64) -> vec2l:
    """Vertex v's doubled fixed point: read from ``points[s]`` when the vertex pass made it (s >= 0), else made here."""
    if s >= 0:
        return points[s, v]
    return doubled_fixed_point_vertex(light_xy[v], step, limit, corner)


@wp.func
def misses_span(u: wp.float64, v: wp.float64, w: wp.float64, origin: wp.int64, scale: wp.float64, size: wp.float64,
                first: int, end: int) -> bool:
    """Coordinates ``u, v, w`` (metres) all below texel ``first − 1`` or all above texel ``end + 1`` of a box.

    ``origin`` in ``2**-bits`` texels (``scale = 2**bits``), ``size`` metres per texel. The texel of
    margin is far more than the fixed-point snap and float rounding can move a vertex.
    """
    corner = wp.float64(origin) / scale
    low = (corner + wp.float64(first - 1)) * size
    high = (corner + wp.float64(end + 1)) * size
    return wp.max(wp.max(u, v), w) < low or wp.min(wp.min(u, v), w) > high


@wp.kernel
def rasterize_chunks_kernel(
    light_xy: wp.array(dtype=wp.vec2d),
    vertex_depth: wp.array(dtype=wp.float64),
    triangles: wp.array2d(dtype=wp.int32),
    texel_size: wp.array(dtype=wp.vec2d),
    origin: wp.array(dtype=vec2l),
    points: wp.array2d(dtype=vec2l),
    slots: wp.array(dtype=wp.int32),
    regions: wp.array2d(dtype=wp.int32),
    chunks: wp.array2d(dtype=wp.int32),
    chunk_bits: int,
    run_bits: int,
    scale: wp.float64,
    limit: wp.float64,
    unit: wp.int64,
    bits: wp.int64,
    depth: wp.array3d(dtype=wp.float32),
    covered: wp.array(dtype=wp.int64),
):
    """A thread per run of ``2**run_bits`` triangles of a (region, chunk) row; ``covered[g]`` sums region g's
    coverage tests passed.

    A chunk is ``2**chunk_bits`` consecutive triangles (the last one shorter), cut into runs
    (``run_bits <= chunk_bits``): on the CPU a run is the whole chunk, so that what a thread reads
    once (its row, region, cascade and box) serves every triangle of the chunk; a GPU wants a
    thread per triangle. A triangle that meets no texel centre of its region returns before any
    per-texel work, so the chunks need only be a superset of the triangles that cover a texel.
    """
    first = wp.tid() << run_bits
    row = first >> chunk_bits
    t = (chunks[row, 1] << chunk_bits) + (first & ((1 << chunk_bits) - 1))
    end = wp.min(t + (1 << run_bits), triangles.shape[0])
    g = chunks[row, 0]
    c = regions[g, 0]
    s = slots[c]
    size = texel_size[c]
    step = size / scale
    corner = origin[c]
    window = wp.vec4i(regions[g, 1], regions[g, 2], regions[g, 3], regions[g, 4])
    n = wp.int64(0)
    while t < end:
        ia = triangles[t, 0]
        ib = triangles[t, 1]
        ic = triangles[t, 2]
        keep = s >= 0
        if not keep:
            # Converted here: first drop, in metres, a triangle whose rectangle misses the region
            # widened by a texel, as region_chunks tests chunks (its neighbours in a chunk may not).
            ua = light_xy[ia]
            ub = light_xy[ib]
            uc = light_xy[ic]
            keep = not (misses_span(ua[0], ub[0], uc[0], corner[0], scale, size[0], window[0], window[1])
                        or misses_span(ua[1], ub[1], uc[1], corner[1], scale, size[1], window[2], window[3]))
        if keep:
            a = doubled_vertex(points, s, light_xy, ia, step, corner, limit)
            b = doubled_vertex(points, s, light_xy, ib, step, corner, limit)
            p = doubled_vertex(points, s, light_xy, ic, step, corner, limit)
            n += wp.int64(rasterize_triangle(a[0], a[1], b[0], b[1], p[0], p[1], vertex_depth[ia], vertex_depth[ib],
                                             vertex_depth[ic], unit, bits, depth, c, window))
        t += 1
    if n > wp.int64(0):
        wp.atomic_add(covered, g, n)


def _checked_bits(bits) -> int:
    if not (isinstance(bits, (int, np.integer)) and 0 <= bits <= 16):
        raise ValueError(f"bits: expected an integer in 0..16, got {bits!r}")
    return int(bits)


def _checked_resolution(resolution) -> int:
    if not (isinstance(resolution, (int, np.integer)) and 1 <= resolution <= 16384):
        raise ValueError(f"resolution: expected an integer in 1..16384, got {resolution!r}")
    return int(resolution)


def rasterize_depth(points, vertex_depth, triangles, *, resolution: int, bits: int,
                    device: str = "cpu") -> tuple[np.ndarray, int]:
    """Depth maps of every cascade: per texel centre the nearest caster's light-space depth.

    Parameters
    ----------
    points : array_like, shape (C, V, 2), int64
        Every vertex in every cascade's local fixed point: ``2**-bits`` texels from the box origin
        (:func:`csmlab.texels.fixed_point_coordinates`), within ±2**52.
    vertex_depth : array_like, shape (V,), float64
        ``d·X − zref`` of each vertex in metres (the same in every cascade).
    triangles : array_like, shape (T, 3), integer
        Vertex indices; either winding.
    resolution : int
        Texels per side R of each map.
    bits : int
        Sub-texel bits of ``points`` (0..16).
    device : str
        ``"cpu"`` or ``"cuda"``.

    Returns
    -------
    depth : ndarray, shape (C, R, R), float32
        ``depth[c, j, i]`` is the minimum depth over triangles whose interior (top-left rule on
        edges) contains the centre of texel column i, row j of cascade c; +inf where none.
    texels_rasterized : int
        Coverage tests that passed, summed over triangles and cascades.

    Raises
    ------
    ValueError
        On shapes that do not match, non-finite depths, out-of-range indices, bits or resolution.

    Notes
    -----
    One thread per cascade and triangle. A triangle whose bounding box holds no texel centre of
    the map, or of zero area, returns before any per-texel work; the others walk their bounding
    box clamped to the map, so geometry far larger than the box costs no more than the box.
    Depth is not clipped: casters in front of the box's near plane are kept (the box is pushed to
    the scene bounds anyway). Atomic minima make the result independent of thread order.
    """
    device = checked_device(device)
    pts = np.ascontiguousarray(points, dtype=np.int64)
    z = np.ascontiguousarray(vertex_depth, dtype=np.float64)
    tri = np.ascontiguousarray(triangles, dtype=np.int32)
    if pts.ndim != 3 or pts.shape[2] != 2 or pts.shape[0] == 0:
        raise ValueError(f"points: expected fixed-point vertices of shape (C, V, 2), got {pts.shape}")
    if np.any(np.abs(pts) > 2**52):
        raise ValueError("points: expected fixed-point coordinates within ±2**52")
    if z.shape != (pts.shape[1],) or not np.all(np.isfinite(z)):
        raise ValueError(f"vertex_depth: expected {pts.shape[1]} finite depths in metres, got shape {z.shape}")
    if tri.ndim != 2 or tri.shape[1] != 3:
        raise ValueError(f"triangles: expected vertex indices of shape (T, 3), got {tri.shape}")
    if tri.size and (tri.min() < 0 or tri.max() >= pts.shape[1]):
        raise ValueError(f"triangles: expected indices in [0, {pts.shape[1]}), got [{tri.min()}, {tri.max()}]")
    resolution = _checked_resolution(resolution)
    bits = _checked_bits(bits)
    cascades = pts.shape[0]
    depth = wp.full((cascades, resolution, resolution), value=np.inf, dtype=wp.float32, device=device)
    if tri.shape[0] == 0:
        return depth.numpy(), 0
    covered = wp.empty((cascades, tri.shape[0]), dtype=wp.int32, device=device)
    wp.launch(
        rasterize_depth_kernel,
        dim=(cascades, tri.shape[0]),
        inputs=(
            wp.array(pts, dtype=wp.int64, device=device, copy=False),
            wp.array(z, dtype=wp.float64, device=device, copy=False),
            wp.array(tri, dtype=wp.int32, device=device, copy=False),
            wp.int64(2**bits),
            wp.int64(bits),
        ),
        outputs=(depth, covered),
        device=device,
    )
    return depth.numpy(), int(covered.numpy().sum(dtype=np.int64))


CHUNK_BITS = 5
"""Triangles are culled in chunks of ``2**CHUNK_BITS`` consecutive ones (:func:`region_chunks`).

Meshes list neighbouring triangles together (grids by rows, objects one after another), so a
chunk's rectangle is small: testing 32 times fewer rectangles costs less than the triangles it lets
through, which the kernel drops before any per-texel work.
"""


BANDS_PER_THREAD = 1
"""Bands each region is cut into per thread (:func:`banded_regions`), which the threads take in turn,
costliest first (:func:`rasterize_cascades`).

One band per thread is enough for them to finish together: a map's cascades are regions too, and
each band costs its launch, its culling pass and the triangles its edges cut. Four cascades at
~1M triangles, 2 threads, same process, interleaved (ms): 1024² 40.2 with one band per thread,
41.5 with 2, 45.0 with 4; 2048² 88.6, 90.8, 94.8; at 136k, 1024² 21.5, 22.5, 24.0.
"""


@dataclass
class TriangleBounds:
    """Light-space bounding rectangles of a mesh's triangles, and of its chunks (:data:`CHUNK_BITS`).

    Attributes
    ----------
    lo, hi : ndarray, shape (T, 2), float64
        Each triangle's rectangle, metres.
    """

    lo: np.ndarray
    hi: np.ndarray

    @cached_property
    def chunks(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``lo_x, lo_y, hi_x, hi_y`` ``(⌈T / 2**CHUNK_BITS⌉,)`` each: the rectangle of every chunk of triangles."""
        count = len(self.lo)
        size = 1 << CHUNK_BITS
        rows = -(-count // size)
        # The last chunk is padded with copies of the last triangle, which change no minimum or maximum.
        fill = np.arange(rows * size).clip(max=max(count - 1, 0))
        lo = self.lo[fill].reshape(rows, size, 2).min(axis=1) if count else np.zeros((0, 2))
        hi = self.hi[fill].reshape(rows, size, 2).max(axis=1) if count else np.zeros((0, 2))
        return tuple(np.ascontiguousarray(a[:, k]) for a in (lo, hi) for k in (0, 1))

    @cached_property
    def narrow_axis(self) -> int:
        """The light-space axis (0: x, 1: y) along which chunks are narrower (median extent).

        A grid listed row by row makes chunks long along its rows: bands cut along the other axis
        (:func:`banded_regions`) meet fewer of them.
        """
        lo_x, lo_y, hi_x, hi_y = self.chunks
        return int(len(lo_x) > 0 and np.median(hi_y - lo_y) < np.median(hi_x - lo_x))


def triangle_bounds(light_xy, triangles) -> TriangleBounds:
    """Light-space bounding rectangle of every triangle (:func:`region_chunks` queries them).

    Parameters
    ----------
    light_xy : array_like, shape (V, 2), float64
        Vertices' light-space x/y in metres (:func:`csmlab.texels.light_plane_coordinates`).
    triangles : array_like, shape (T, 3), integer
    """
    xy = np.asarray(light_xy, dtype=np.float64)[np.asarray(triangles)]
    return TriangleBounds(lo=xy.min(axis=1), hi=xy.max(axis=1))


@dataclass(frozen=True)
class LightSpaceMesh:
    """A mesh as the depth pass reads it, checked once (:func:`light_space_mesh`) and read by every cascade and frame.

    Attributes
    ----------
    xy : ndarray, shape (V, 2), float64
        Vertices' light-space x/y in metres (:func:`csmlab.texels.light_plane_coordinates`), finite.
    depth : ndarray, shape (V,), float64
        ``d·X − zref`` of each vertex in metres, finite.
    triangles : ndarray, shape (T, 3), int32
        Vertex indices in ``[0, V)``; either winding.
    """

    xy: np.ndarray
    depth: np.ndarray
    triangles: np.ndarray

    @cached_property
    def bounds(self) -> TriangleBounds:
        """The light-space rectangles of the triangles and of their chunks (:func:`region_chunks` queries them)."""
        return triangle_bounds(self.xy, self.triangles)


def light_space_mesh(light_xy, vertex_depth, triangles) -> LightSpaceMesh:
    """A :class:`LightSpaceMesh` of the arrays, checked: finite vertices and depths, indices within the mesh.

    The check reads every array (~24 MB at ~1M triangles, a few ms from memory): a run makes the mesh
    once per light, not once per frame. The arrays are not copied when already contiguous and of
    their type, and are read-only through the record; do not change them afterwards.

    Parameters
    ----------
    light_xy : array_like, shape (V, 2), float64
        Vertices' light-space x/y in metres.
    vertex_depth : array_like, shape (V,), float64
        ``d·X − zref`` of each vertex in metres.
    triangles : array_like, shape (T, 3), integer

    Raises
    ------
    ValueError
        Naming the argument: a shape that does not match, a value not finite, an index outside the mesh.
    """
    xy = np.ascontiguousarray(light_xy, dtype=np.float64)
    z = np.ascontiguousarray(vertex_depth, dtype=np.float64)
    tri = np.ascontiguousarray(triangles, dtype=np.int32)
    if xy.ndim != 2 or xy.shape[1] != 2:
        raise ValueError(f"light_xy: expected vertices of shape (V, 2), got {xy.shape}")
    if z.shape != (xy.shape[0],) or not np.all(np.isfinite(z)) or not np.all(np.isfinite(xy)):
        raise ValueError(f"light_xy, vertex_depth: expected {xy.shape[0]} finite vertices and depths")
    if tri.ndim != 2 or tri.shape[1] != 3 or (tri.size and (tri.min() < 0 or tri.max() >= xy.shape[0])):
        raise ValueError(f"triangles: expected indices of shape (T, 3) in [0, {xy.shape[0]})")
    return LightSpaceMesh(*(_read_only(a) for a in (xy, z, tri)))


def _read_only(array: np.ndarray) -> np.ndarray:
    view = array.view()
    view.flags.writeable = False
    return view


def _spread_bits(v: np.ndarray) -> np.ndarray:
    """The 16 low bits of ``v`` (int64) moved to the even bit positions 0, 2, …, 30."""
    v = v & 0xFFFF
    for shift, mask in ((8, 0x00FF00FF), (4, 0x0F0F0F0F), (2, 0x33333333), (1, 0x55555555)):
        v = (v | (v << shift)) & mask
    return v


def z_ordered(light_xy, triangles) -> tuple[np.ndarray, np.ndarray]:
    """A mesh's triangles along a Z-order curve in light space, its vertices in the order they are first used.

    Neighbouring triangles then lie close in the list at every scale, so that chunks
    (:data:`CHUNK_BITS`) are compact, bands meet few of them, and the rasterization writes the
    depth maps place by place rather than across them.

    Parameters
    ----------
    light_xy : array_like, shape (V, 2), float64
        Vertices' light-space x/y in metres.
    triangles : array_like, shape (T, 3), integer

    Returns
    -------
    order : ndarray, shape (V,), int64
        The vertices' new order: new vertex k is old vertex ``order[k]`` (unused vertices last).
    triangles : ndarray, shape (T, 3), int32
        The triangles in their new order, indexing the reordered vertices.
    """
    xy = np.asarray(light_xy, dtype=np.float64)
    tri = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    if tri.shape[0] == 0:
        return np.arange(xy.shape[0]), tri.astype(np.int32)
    key = np.zeros(tri.shape[0], dtype=np.int64)
    for axis in (0, 1):
        # Each triangle's centre (times 3) on a 2**16 grid over the centres' extent.
        u = xy[:, axis]
        centre = u[tri[:, 0]] + u[tri[:, 1]] + u[tri[:, 2]]
        lo = centre.min()
        cell = np.minimum((centre - lo) * (65536.0 / max(centre.max() - lo, 1e-300)), 65535.0).astype(np.int64)
        key |= _spread_bits(cell) << axis
    sorted_tri = tri[np.argsort(key, kind="stable")]
    # First use of each vertex: assigned in reverse so that the earliest use is the last write.
    flat = sorted_tri.reshape(-1)
    first = np.full(xy.shape[0], flat.size, dtype=np.int64)
    first[flat[::-1]] = np.arange(flat.size - 1, -1, -1)
    order = np.argsort(first, kind="stable")
    renumber = np.empty(xy.shape[0], dtype=np.int64)
    renumber[order] = np.arange(xy.shape[0])
    return order, renumber[sorted_tri].astype(np.int32)


def whole_map_regions(resolutions) -> np.ndarray:
    """One region per cascade covering its whole map: ``(C, 5)`` int32 rows ``(c, 0, R_c, 0, R_c)``."""
    sizes = np.asarray(resolutions, dtype=np.int32).reshape(-1)
    return np.stack([np.arange(sizes.size, dtype=np.int32), np.zeros_like(sizes), sizes, np.zeros_like(sizes), sizes],
                    axis=1)


def banded_regions(regions, *, parts: int, axis: int | None = None) -> np.ndarray:
    """``regions`` ``(G, 5)`` each cut into ``parts`` bands as equal as whole texels allow.

    Rows ``(c, i0, i1, j0, j1)`` as :func:`region_chunks`. A region is cut along ``axis`` (0: into
    bands of columns, 1: of rows; :attr:`TriangleBounds.narrow_axis`) when it is at least ``parts``
    texels long that way, else across its longer side; a region shorter than ``parts`` texels
    gives as many bands as it is long. The bands of a region follow one another.
    """
    out = []
    for c, i0, i1, j0, j1 in np.asarray(regions, dtype=np.int64).reshape(-1, 5):
        rows = j1 - j0 >= i1 - i0
        if axis is not None and (j1 - j0 if axis == 1 else i1 - i0) >= parts:
            rows = axis == 1
        lo, hi = (j0, j1) if rows else (i0, i1)
        cuts = np.unique(np.linspace(lo, hi, min(parts, hi - lo) + 1).round().astype(np.int64))
        for a, b in zip(cuts[:-1], cuts[1:]):
            out.append((c, i0, i1, a, b) if rows else (c, a, b, j0, j1))
    return np.array(out, dtype=np.int32).reshape(-1, 5)


def region_chunks(bounds: TriangleBounds, *, texel_size, origin, regions) -> np.ndarray:
    """(region, chunk) rows whose chunk rectangle meets the region: ``(K, 2)`` int32, sorted by region, then chunk.

    Chunk k holds triangles ``[k·2**CHUNK_BITS, (k + 1)·2**CHUNK_BITS)``. Conservative: each region
    is widened by one texel on every side, far more than the fixed-point snap (half a ``2**-bits``
    texel) and float rounding can move a vertex, so a chunk left out holds no triangle that covers
    a texel centre of that region.

    Parameters
    ----------
    bounds : TriangleBounds
        :func:`triangle_bounds`.
    texel_size : array_like, shape (C, 2)
        Metres per texel of each cascade.
    origin : array_like, shape (C, 2)
        Box minimum corner in texels of each cascade.
    regions : array_like, shape (G, 5), integer
        Rows ``(c, i0, i1, j0, j1)``: texel columns ``[i0, i1)`` and rows ``[j0, j1)`` of cascade c
        (:func:`whole_map_regions` for whole maps).
    """
    size = np.asarray(texel_size, dtype=np.float64)
    corner = np.asarray(origin, dtype=np.float64)
    lo_x, lo_y, hi_x, hi_y = bounds.chunks
    rows = [np.zeros((0, 2), np.int32)]
    for g, (c, i0, i1, j0, j1) in enumerate(np.asarray(regions, dtype=np.int64).reshape(-1, 5)):
        box_lo = (corner[c] + [i0 - 1.0, j0 - 1.0]) * size[c]
        box_hi = (corner[c] + [i1 + 1.0, j1 + 1.0]) * size[c]
        meeting = np.flatnonzero((hi_x >= box_lo[0]) & (lo_x <= box_hi[0]) & (hi_y >= box_lo[1]) & (lo_y <= box_hi[1]))
        pair = np.empty((meeting.size, 2), dtype=np.int32)
        pair[:, 0] = g
        pair[:, 1] = meeting
        rows.append(pair)
    return np.concatenate(rows)


def fixed_point_vertices(light_xy, *, texel_size, origin, bits: int, cascades=None, threads: int = 1,
                         device: str = "cpu") -> np.ndarray:
    """Every vertex in cascades' local fixed point, doubled: ``2 ·`` :func:`csmlab.texels.fixed_point_coordinates`.

    Parameters
    ----------
    light_xy : array_like, shape (V, 2), float64
        Vertices' light-space x/y in metres (:func:`csmlab.texels.light_plane_coordinates`).
    texel_size : array_like, shape (C, 2), float64
        Metres per texel of each cascade.
    origin : array_like, shape (C, 2), int64
        Each box origin in ``2**-bits`` texels (:func:`csmlab.texels.fixed_point_origin`).
    bits : int
        Sub-texel bits (0..16).
    cascades : sequence of int, optional
        The cascades to convert, in this order; None: all C.
    threads : int
        CPU launches run at once, each over its own range of vertices. Ignored on CUDA.
    device : str

    Returns
    -------
    ndarray, shape (len(cascades), V, 2), int64
        Twice the global fixed point ``rint(x / texel · 2**bits)`` (clipped to ±2**50) less the
        origin, in ``2**-bits`` texels: texel centres fall on odd multiples of ``2**bits``.
    """
    device = checked_device(device)
    xy = np.ascontiguousarray(light_xy, dtype=np.float64)
    size = np.ascontiguousarray(texel_size, dtype=np.float64)
    corner = np.ascontiguousarray(origin, dtype=np.int64)
    if xy.ndim != 2 or xy.shape[1] != 2 or size.ndim != 2 or size.shape[1] != 2 or corner.shape != size.shape:
        raise ValueError(f"light_xy, texel_size, origin: expected shapes (V, 2), (C, 2), (C, 2); "
                         f"got {xy.shape}, {size.shape}, {corner.shape}")
    chosen = np.arange(size.shape[0], dtype=np.int32) if cascades is None else np.asarray(cascades, dtype=np.int32)
    if chosen.ndim != 1 or np.any(chosen < 0) or np.any(chosen >= size.shape[0]):
        raise ValueError(f"cascades: expected indices in [0, {size.shape[0]}), got {cascades!r}")
    bits = _checked_bits(bits)
    with LaunchPool(checked_threads(threads, device), kernels=(fixed_point_vertices_kernel,), device=device) as pool:
        return _vertex_pass(pool, _device_arrays(device, xy, size, corner), chosen, bits=bits, device=device).numpy()


def _device_arrays(device: str, xy: np.ndarray, size: np.ndarray, corner: np.ndarray) -> tuple:
    """Vertices' x/y ``(V, 2)``, texel sizes and box origins ``(C, 2)`` as Warp arrays of 2-vectors."""
    return (wp.array(xy, dtype=wp.vec2d, device=device, copy=False),
            wp.array(size, dtype=wp.vec2d, device=device, copy=False),
            wp.array(corner, dtype=vec2l, device=device, copy=False))


def _vertex_pass(pool: LaunchPool, arrays: tuple, cascades: np.ndarray, *, bits: int, device: str) -> wp.array:
    """:func:`fixed_point_vertices` of ``cascades`` on ``device``, each of the pool's launches over its own vertices."""
    xy = arrays[0]
    points = device_empty((cascades.size, xy.shape[0]), vec2l, device)
    if cascades.size == 0 or xy.shape[0] == 0:
        return points
    chosen = wp.array(cascades, dtype=wp.int32, device=device)

    run = _VERTEX_RUN if wp.get_device(device).is_cpu else 1

    def launch(lo: int, hi: int) -> None:
        wp.launch(fixed_point_vertices_kernel, dim=(cascades.size, -(-(hi - lo) // run)),
                  inputs=(*arrays, chosen, lo, hi, run, float(2**bits), _FIXED_LIMIT), outputs=(points,),
                  device=device)

    pool.run([lambda lo=lo, hi=hi: launch(lo, hi) for lo, hi in split_range(xy.shape[0], pool.threads)])
    return points


_VERTEX_RUN = 256
"""Vertices a CPU thread of the vertex pass converts (:func:`fixed_point_vertices`)."""

_FIXED_LIMIT = float(2**50)
"""The clip of global fixed-point values (:mod:`csmlab.texels`)."""


def empty_regions(maps: np.ndarray, regions: np.ndarray) -> None:
    """Set every texel of ``regions`` ``(G, 5)`` (rows ``(c, i0, i1, j0, j1)``) of ``maps`` ``(C, R, R)`` to +inf."""
    for c, i0, i1, j0, j1 in regions:
        maps[c, j0:j1, i0:i1] = np.inf


def rasterize_cascades(mesh: LightSpaceMesh, *, texel_size, origin, resolution: int, bits: int,
                       regions=None, chunks=None, depth=None, count_only: bool = False, threads: int = 1,
                       device: str = "cpu") -> tuple[np.ndarray | None, np.ndarray]:
    """Depth maps of every cascade from light-space vertices: fixed point and rasterization on the device.

    The same maps as :func:`rasterize_depth` of
    :func:`csmlab.texels.fixed_point_coordinates` — bit for bit — with the fixed-point conversion
    on the device and, with ``chunks``, only the chunks of triangles that can cover a texel of a
    region rasterized. With ``regions``, only those texels are rasterized and every other texel of
    ``depth`` keeps its value: a texel's depth and coverage depend only on the triangles and on the
    fixed-point differences, not on the region it is rasterized in (:mod:`csmlab.scrolling` copies
    the rest from the previous frame).

    Parameters
    ----------
    mesh : LightSpaceMesh
        The vertices' light-space x/y and depths and the triangles, checked (:func:`light_space_mesh`).
    texel_size : array_like, shape (C, 2), float64
        Metres per texel of each cascade.
    origin : array_like, shape (C, 2), int64
        Each box origin in ``2**-bits`` texels (:func:`csmlab.texels.fixed_point_origin`).
    resolution : int
        Texels per side R of the maps (the largest cascade's: a smaller cascade's regions lie in
        the corner ``[0, R_c)²`` of its map).
    bits : int
        Sub-texel bits (0..16).
    regions : array_like, shape (G, 5), integer, optional
        Rows ``(c, i0, i1, j0, j1)``: texel columns ``[i0, i1)`` and rows ``[j0, j1)`` of cascade c
        to rasterize, disjoint; None: every cascade's whole map (:func:`whole_map_regions`).
    chunks : array_like, shape (K, 2), int32, optional
        (region, chunk) rows to rasterize (:func:`region_chunks`); None: every chunk of every region.
    depth : ndarray, shape (C, R, R), float32, C-contiguous, optional
        The maps to rasterize into (default +inf everywhere): the regions' texels are rasterized
        afresh (their values are not read), the others keep theirs. Consumed: on the CPU it is
        filled in place and returned.
    count_only : bool
        Count the coverage tests that pass and store no depth (``depth`` is ignored and None returned).
    threads : int
        CPU launches run at once (one Warp CPU launch runs on one thread). The regions, which are
        disjoint, are taken by the threads one at a time, costliest first, so no two launches write
        one texel; cut large regions into bands first (:func:`banded_regions`,
        :data:`BANDS_PER_THREAD` per thread) so that the threads finish together. Ignored on CUDA.
    device : str

    Returns
    -------
    depth : ndarray, shape (C, R, R), float32, or None
        None with ``count_only``.
    texels_rasterized : ndarray, shape (G,), int64
        Coverage tests that passed in each region.

    Notes
    -----
    A cascade whose chunks hold more triangles than a third of the vertices gets every vertex
    converted once (:func:`fixed_point_vertices`, split over the threads) before the
    rasterization reads them; the others, such as the strips a scrolled box newly covers, convert
    the vertices of each triangle as they rasterize it. Both give the same integers.
    """
    device = checked_device(device)
    if not isinstance(mesh, LightSpaceMesh):
        raise ValueError(f"mesh: expected a LightSpaceMesh (light_space_mesh), got {type(mesh).__name__}")
    xy, z, tri = mesh.xy, mesh.depth, mesh.triangles
    size = np.ascontiguousarray(texel_size, dtype=np.float64)
    corner = np.ascontiguousarray(origin, dtype=np.int64)
    if size.ndim != 2 or size.shape[1] != 2 or corner.shape != size.shape:
        raise ValueError(f"texel_size, origin: expected shapes (C, 2), (C, 2); got {size.shape}, {corner.shape}")
    bits = _checked_bits(bits)
    resolution = _checked_resolution(resolution)
    shape = (size.shape[0], resolution, resolution)
    areas = np.ascontiguousarray(whole_map_regions([resolution] * shape[0]) if regions is None else regions,
                                 dtype=np.int32)
    if (areas.ndim != 2 or areas.shape[1] != 5 or np.any(areas[:, 0] < 0) or np.any(areas[:, 0] >= shape[0])
            or np.any(areas[:, 1:] < 0) or np.any(areas[:, 1:] > resolution)):
        raise ValueError(f"regions: expected rows (c, i0, i1, j0, j1) within {shape}, got shape {areas.shape}")
    count = -(-tri.shape[0] // (1 << CHUNK_BITS))
    rows = (np.stack(np.meshgrid(np.arange(areas.shape[0]), np.arange(count), indexing="ij"), -1).reshape(-1, 2)
            if chunks is None else np.asarray(chunks)).astype(np.int32)
    if rows.ndim != 2 or rows.shape[1] != 2 or (rows.size and (rows.min() < 0 or rows[:, 0].max() >= areas.shape[0]
                                                               or rows[:, 1].max() >= count)):
        raise ValueError(f"chunks: expected (region, chunk) rows of shape (K, 2) within ({areas.shape[0]}, {count}), "
                         f"got {rows.shape}")
    parts = min(checked_threads(threads, device), areas.shape[0])
    extent = (areas[:, 2].astype(np.int64) - areas[:, 1]) * (areas[:, 4] - areas[:, 3])
    if count_only:
        maps = np.zeros((0, 0, 0), dtype=np.float32)
    elif depth is None:
        # Regions that tile the maps leave nothing to fill but what each region fills itself.
        maps = np.empty(shape, dtype=np.float32) if extent.sum() == np.prod(shape) else np.full(shape, np.inf,
                                                                                               dtype=np.float32)
    elif depth.shape != shape or depth.dtype != np.float32 or not depth.flags.c_contiguous:
        raise ValueError(f"depth: expected C-contiguous float32 maps of shape {shape}, got {depth.dtype} {depth.shape}")
    else:
        maps = depth
    if areas.shape[0] == 0:
        return None if count_only else maps, np.zeros(0, dtype=np.int64)
    if np.any(np.diff(rows[:, 0]) < 0):
        rows = rows[np.argsort(rows[:, 0], kind="stable")]
    held = np.bincount(rows[:, 0], minlength=areas.shape[0]) << CHUNK_BITS
    starts = np.concatenate([[0], np.cumsum(held >> CHUNK_BITS)])
    # Triangles each cascade's chunks hold (a chunk met by two of its regions once), against what
    # converting its every vertex costs: a vertex pass converts V vertices, the triangles 3 each.
    distinct = np.zeros((shape[0], count), dtype=bool)
    distinct[areas[rows[:, 0], 0], rows[:, 1]] = True
    converted = np.flatnonzero(3 * (distinct.sum(axis=1) << CHUNK_BITS) > xy.shape[0]).astype(np.int32)
    slots = np.full(shape[0], -1, dtype=np.int32)
    slots[converted] = np.arange(converted.size, dtype=np.int32)
    # On the CPU each launch empties its own regions first (on two threads at once); a GPU gets
    # the maps emptied by the host before they are copied to it.
    on_cpu = wp.get_device(device).is_cpu
    empty_regions(maps, areas if not on_cpu and not count_only else areas[:0])
    arrays = _device_arrays(device, xy, size, corner)
    maps_on = wp.array(maps, dtype=wp.float32, device=device, copy=False)
    covered = wp.zeros(areas.shape[0], dtype=wp.int64, device=device)
    fixed = (float(2**bits), _FIXED_LIMIT, wp.int64(2**bits), wp.int64(bits))
    run_bits = CHUNK_BITS if on_cpu else 0
    with LaunchPool(parts, kernels=(rasterize_chunks_kernel, fixed_point_vertices_kernel), device=device) as pool:
        points = _vertex_pass(pool, arrays, converted, bits=bits, device=device)
        inputs = (arrays[0], wp.array(z, dtype=wp.float64, device=device, copy=False),
                  wp.array(tri, dtype=wp.int32, device=device, copy=False), *arrays[1:], points,
                  wp.array(slots, dtype=wp.int32, device=device), wp.array(areas, dtype=wp.int32, device=device))

        # Disjoint regions, so no texel is written by two launches: each thread takes the next region
        # left, costliest first (triangles, then texels), until none is left. Each region is emptied
        # just before it is rasterized, while its texels are still in the cache.
        queue = iter(np.lexsort((-extent, -held)).tolist())
        lock = threading.Lock()

        def work() -> None:
            while True:
                with lock:
                    g = next(queue, None)
                if g is None:
                    return
                if on_cpu and not count_only:
                    empty_regions(maps, areas[g:g + 1])
                if held[g]:
                    wp.launch(rasterize_chunks_kernel, dim=int(held[g]) >> run_bits,
                              inputs=(*inputs, wp.array(rows[starts[g]:starts[g + 1]], dtype=wp.int32, device=device),
                                      CHUNK_BITS, run_bits, *fixed), outputs=(maps_on, covered), device=device)

        pool.run([work] * parts)
    return None if count_only else maps_on.numpy(), covered.numpy()
