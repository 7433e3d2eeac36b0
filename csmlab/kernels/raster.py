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

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import warp as wp

from csmlab.kernels import checked_device
from csmlab.kernels.threads import LaunchPool, checked_threads

__all__ = ["TriangleBounds", "banded_candidates", "banded_regions", "rasterize_cascades", "rasterize_depth", "region_candidates", "triangle_bounds",
           "whole_map_regions"]


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


@wp.func
def store_depth(depth: wp.array3d(dtype=wp.float32), c: int, j: int, i: int, w_a: wp.float64, w_b: wp.float64,
                w_c: wp.float64, za: wp.float64, zb: wp.float64, zc: wp.float64, area: wp.float64):
    """Keep the nearer of texel (i, j)'s depth and the triangle's, interpolated with its edge functions.

    An empty ``depth`` (a counting pass, :func:`rasterize_cascades` with ``count_only``) stores nothing.
    """
    if depth.shape[0] > 0:
        wp.atomic_min(depth, c, j, i, wp.float32((w_a * za + w_b * zb + w_c * zc) / area))


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
    step = two * unit
    step_c = wp.float64(by - ay) * wp.float64(step)
    step_a = wp.float64(cy - by) * wp.float64(step)
    step_b = wp.float64(ay - cy) * wp.float64(step)
    count = int(0)
    # With exact integer edge functions, "inside or owned" is one comparison against a bias:
    # e > 0, or e ≥ 0 (e > −½) where the edge owns its centres.
    bias_ab = owned_bias(own_ab)
    bias_bc = owned_bias(own_bc)
    bias_ca = owned_bias(own_ca)
    inverse_c = reciprocal(step_c)
    inverse_a = reciprocal(step_a)
    inverse_b = reciprocal(step_b)
    for j in range(j0, j1 + 1):
        py = (two * wp.int64(j) + wp.int64(1)) * unit
        row_ab = wp.float64(bx - ax) * wp.float64(py - ay)
        row_bc = wp.float64(cx - bx) * wp.float64(py - by)
        row_ca = wp.float64(ax - cx) * wp.float64(py - cy)
        w_c, w_a, w_b = edge_values((two * wp.int64(i0) + wp.int64(1)) * unit, ax, ay, bx, by, cx, cy, row_ab,
                                    row_bc, row_ca)
        if stepped:
            # Each edge function falls by its step per texel, so the centres inside form one run;
            # its ends, solved from the three edges (widened by a texel against rounding), bound
            # the walk, and the exact test below decides every centre in it.
            start = wp.float64(i0)
            lo = start
            hi = wp.float64(i1)
            lo, hi = run_bounds(w_c, step_c, inverse_c, bias_ab, start, lo, hi)
            lo, hi = run_bounds(w_a, step_a, inverse_a, bias_bc, start, lo, hi)
            lo, hi = run_bounds(w_b, step_b, inverse_b, bias_ca, start, lo, hi)
            if lo <= hi:
                first = int(lo)
                last = int(hi)
                skip = lo - start
                w_c = w_c - step_c * skip
                w_a = w_a - step_a * skip
                w_b = w_b - step_b * skip
                for i in range(first, last + 1):
                    if w_c > bias_ab and w_a > bias_bc and w_b > bias_ca:
                        store_depth(depth, c, j, i, w_a, w_b, w_c, za, zb, zc, area)
                        count += 1
                    w_c = w_c - step_c
                    w_a = w_a - step_a
                    w_b = w_b - step_b
        else:
            for i in range(i0, i1 + 1):
                w_c, w_a, w_b = edge_values((two * wp.int64(i) + wp.int64(1)) * unit, ax, ay, bx, by, cx, cy, row_ab,
                                            row_bc, row_ca)
                if edge_inside(w_c, own_ab) and edge_inside(w_a, own_bc) and edge_inside(w_b, own_ca):
                    store_depth(depth, c, j, i, w_a, w_b, w_c, za, zb, zc, area)
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


@wp.func
def doubled_fixed_point(u: wp.float64, texel_size: wp.float64, scale: wp.float64, limit: wp.float64,
                        origin: wp.int64) -> wp.int64:
    """Twice a light-space coordinate ``u`` (metres) in local ``2**-bits`` texels.

    The operations of :func:`csmlab.texels.fixed_point_coordinates`, in its order (no sum, so no
    fused multiply-add can change a rounding): ``rint(u / texel · 2**bits) − origin``, doubled.
    """
    v = wp.rint(wp.clamp(u / texel_size * scale, -limit, limit))
    if wp.isnan(v):
        v = -limit
    return wp.int64(2) * (wp.int64(v) - origin)


@wp.kernel
def rasterize_regions_kernel(
    light_xy: wp.array2d(dtype=wp.float64),
    vertex_depth: wp.array(dtype=wp.float64),
    triangles: wp.array2d(dtype=wp.int32),
    texel_size: wp.array2d(dtype=wp.float64),
    origin: wp.array2d(dtype=wp.int64),
    regions: wp.array2d(dtype=wp.int32),
    candidates: wp.array2d(dtype=wp.int32),
    scale: wp.float64,
    limit: wp.float64,
    unit: wp.int64,
    bits: wp.int64,
    depth: wp.array3d(dtype=wp.float32),
    covered: wp.array(dtype=wp.int32),
):
    k = wp.tid()
    g = candidates[k, 0]
    t = candidates[k, 1]
    c = regions[g, 0]
    ia = triangles[t, 0]
    ib = triangles[t, 1]
    ic = triangles[t, 2]
    sx = texel_size[c, 0]
    sy = texel_size[c, 1]
    ox = origin[c, 0]
    oy = origin[c, 1]
    ax = doubled_fixed_point(light_xy[ia, 0], sx, scale, limit, ox)
    ay = doubled_fixed_point(light_xy[ia, 1], sy, scale, limit, oy)
    bx = doubled_fixed_point(light_xy[ib, 0], sx, scale, limit, ox)
    by = doubled_fixed_point(light_xy[ib, 1], sy, scale, limit, oy)
    cx = doubled_fixed_point(light_xy[ic, 0], sx, scale, limit, ox)
    cy = doubled_fixed_point(light_xy[ic, 1], sy, scale, limit, oy)
    covered[k] = rasterize_triangle(ax, ay, bx, by, cx, cy, vertex_depth[ia], vertex_depth[ib], vertex_depth[ic], unit,
                                    bits, depth, c,
                                    wp.vec4i(regions[g, 1], regions[g, 2], regions[g, 3], regions[g, 4]))


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


@dataclass
class TriangleBounds:
    """Light-space bounding rectangles of a mesh's triangles, sorted for rectangle queries on first use.

    Attributes
    ----------
    lo, hi : ndarray, shape (T, 2), float64
        Each triangle's rectangle, metres.
    """

    lo: np.ndarray
    hi: np.ndarray

    @cached_property
    def columns(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``lo_x, lo_y, hi_x, hi_y`` ``(T,)`` each contiguous: what every rectangle test reads."""
        return tuple(np.ascontiguousarray(a[:, k]) for a in (self.lo, self.hi) for k in (0, 1))

    @cached_property
    def sorted_axes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``order (2, T)``: triangles sorted by ``lo`` along x (row 0) and y (row 1); ``sorted_lo (2, T)``:
        ``lo`` in those orders; ``reach (2,)``: the widest rectangle along x and y, metres (a triangle
        meets ``[a, b]`` along an axis only if its ``lo`` lies in ``[a − reach, b]``)."""
        order = np.argsort(self.lo.T, axis=1, kind="stable")
        reach = (self.hi - self.lo).max(axis=0) if len(self.lo) else np.zeros(2)
        return order, np.take_along_axis(self.lo.T, order, axis=1), reach


def triangle_bounds(light_xy, triangles) -> TriangleBounds:
    """Light-space bounding rectangle of every triangle (:func:`region_candidates` queries them).

    Parameters
    ----------
    light_xy : array_like, shape (V, 2), float64
        Vertices' light-space x/y in metres (:func:`csmlab.texels.light_plane_coordinates`).
    triangles : array_like, shape (T, 3), integer
    """
    xy = np.asarray(light_xy, dtype=np.float64)[np.asarray(triangles)]
    return TriangleBounds(lo=xy.min(axis=1), hi=xy.max(axis=1))


def _near_triangles(bounds: TriangleBounds, box_lo, box_hi) -> np.ndarray | None:
    """Sorted indices of the triangles whose ``lo`` lies within reach of the box along its narrow side.

    None when those are half the triangles or more: testing all of them in order is then cheaper.
    """
    order, sorted_lo, reach = bounds.sorted_axes
    axis = int(np.argmin(np.asarray(box_hi) - np.asarray(box_lo)))
    first = np.searchsorted(sorted_lo[axis], box_lo[axis] - reach[axis], side="left")
    last = np.searchsorted(sorted_lo[axis], box_hi[axis], side="right")
    return np.sort(order[axis, first:last]) if 2 * (last - first) < len(bounds.lo) else None


def whole_map_regions(resolutions) -> np.ndarray:
    """One region per cascade covering its whole map: ``(C, 5)`` int32 rows ``(c, 0, R_c, 0, R_c)``."""
    sizes = np.asarray(resolutions, dtype=np.int32).reshape(-1)
    return np.stack([np.arange(sizes.size, dtype=np.int32), np.zeros_like(sizes), sizes, np.zeros_like(sizes), sizes],
                    axis=1)


def banded_regions(regions, *, parts: int) -> np.ndarray:
    """``regions`` ``(G, 5)`` each cut across its longer side into ``parts`` bands as equal as whole texels allow.

    Rows ``(c, i0, i1, j0, j1)`` as :func:`region_candidates`; a region narrower than ``parts``
    texels gives as many bands as it is wide. The bands of a region follow one another, so that
    :func:`rasterize_cascades` deals them to its threads in turn.
    """
    out = []
    for c, i0, i1, j0, j1 in np.asarray(regions, dtype=np.int64).reshape(-1, 5):
        rows = j1 - j0 >= i1 - i0
        lo, hi = (j0, j1) if rows else (i0, i1)
        cuts = np.unique(np.linspace(lo, hi, min(parts, hi - lo) + 1).round().astype(np.int64))
        for a, b in zip(cuts[:-1], cuts[1:]):
            out.append((c, i0, i1, a, b) if rows else (c, a, b, j0, j1))
    return np.array(out, dtype=np.int32).reshape(-1, 5)


def region_candidates(bounds: TriangleBounds, *, texel_size, origin, regions) -> np.ndarray:
    """(region, triangle) pairs whose light-space rectangle meets the region: ``(K, 2)`` int32.

    Conservative: each region is widened by one texel on every side, far more than the fixed-point
    snap (half a ``2**-bits`` texel) and float rounding can move a vertex, so a triangle left out
    covers no texel centre of that region. Pairs are sorted by region, then triangle. A narrow
    region (a strip a scrolled box newly covers) tests only the triangles whose ``lo`` lies within
    reach of it along its narrow side.

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
    pairs = [np.zeros((0, 2), np.int32)]
    for g, (c, i0, i1, j0, j1) in enumerate(np.asarray(regions, dtype=np.int64).reshape(-1, 5)):
        box_lo = (corner[c] + [i0 - 1.0, j0 - 1.0]) * size[c]
        box_hi = (corner[c] + [i1 + 1.0, j1 + 1.0]) * size[c]
        narrow = min(i1 - i0, j1 - j0) * 4 < max(i1 - i0, j1 - j0)
        tested = _near_triangles(bounds, box_lo, box_hi) if narrow else None
        pairs.append(_pairs(g, _meeting(bounds, box_lo, box_hi, tested)))
    return np.concatenate(pairs)


def _region_starts(pairs: np.ndarray, regions: int) -> np.ndarray:
    """``(G + 1,)``: where each region's rows begin in ``pairs`` sorted by region (and where the last ends)."""
    return np.concatenate([[0], np.cumsum(np.bincount(pairs[:, 0], minlength=regions))])


def _pairs(region: int, triangles: np.ndarray) -> np.ndarray:
    """``(K, 2)`` int32 rows ``(region, triangle)``."""
    out = np.empty((triangles.size, 2), dtype=np.int32)
    out[:, 0] = region
    out[:, 1] = triangles
    return out


def _meeting(bounds: TriangleBounds, box_lo, box_hi, tested) -> np.ndarray:
    """Sorted indices among ``tested`` (None: all) of the triangles whose rectangle meets ``[box_lo, box_hi]``."""
    lo_x, lo_y, hi_x, hi_y = bounds.columns
    if tested is None:
        return np.flatnonzero((hi_x >= box_lo[0]) & (lo_x <= box_hi[0]) & (hi_y >= box_lo[1]) & (lo_y <= box_hi[1]))
    meets = ((hi_x[tested] >= box_lo[0]) & (lo_x[tested] <= box_hi[0]) & (hi_y[tested] >= box_lo[1])
             & (lo_y[tested] <= box_hi[1]))
    return tested[meets]


def banded_candidates(bounds: TriangleBounds, *, texel_size, origin, regions, candidates,
                      parts: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`banded_regions` of ``regions`` and their (band, triangle) pairs, each band culled from its region's.

    ``candidates`` are :func:`region_candidates` of ``regions`` (sorted by region); the other
    arguments as there. A band spans its region across one axis, so only the other axis is
    tested, widened by a texel as there. Returns the bands ``(G', 5)`` int32 and their pairs
    ``(K', 2)`` int32, sorted by band, then triangle.
    """
    regions = np.asarray(regions, dtype=np.int32).reshape(-1, 5)
    pairs = np.asarray(candidates)
    size = np.asarray(texel_size, dtype=np.float64)
    corner = np.asarray(origin, dtype=np.float64)
    lo_x, lo_y, hi_x, hi_y = bounds.columns
    starts = _region_starts(pairs, len(regions))
    bands, out = [], [np.zeros((0, 2), np.int32)]
    for g, region in enumerate(regions):
        mine = pairs[starts[g]:starts[g + 1], 1]
        c = region[0]
        for band in banded_regions(region[None], parts=parts):
            # A band cut across rows spans its region's columns, and the reverse.
            axis, first, last = (1, band[3], band[4]) if band[1] == region[1] and band[2] == region[2] \
                else (0, band[1], band[2])
            lo, hi = (lo_y, hi_y) if axis == 1 else (lo_x, hi_x)
            low = (corner[c, axis] + first - 1.0) * size[c, axis]
            high = (corner[c, axis] + last + 1.0) * size[c, axis]
            inside = mine[(hi[mine] >= low) & (lo[mine] <= high)]
            out.append(_pairs(len(bands), inside))
            bands.append(band)
    return np.array(bands, dtype=np.int32).reshape(-1, 5), np.concatenate(out)


def rasterize_cascades(light_xy, vertex_depth, triangles, *, texel_size, origin, resolution: int, bits: int,
                       regions=None, candidates=None, depth=None, count_only: bool = False, threads: int = 1,
                       device: str = "cpu") -> tuple[np.ndarray | None, np.ndarray]:
    """Depth maps of every cascade from light-space vertices: fixed point and rasterization on the device.

    The same maps as :func:`rasterize_depth` of
    :func:`csmlab.texels.fixed_point_coordinates` — bit for bit — with the fixed-point conversion
    of each vertex inside the kernel and, with ``candidates``, only the (region, triangle) pairs
    that can cover a texel rasterized. With ``regions``, only those texels are rasterized and every
    other texel of ``depth`` keeps its value: a texel's depth and coverage depend only on the
    triangles and on the fixed-point differences, not on the region it is rasterized in
    (:mod:`csmlab.scrolling` copies the rest from the previous frame).

    Parameters
    ----------
    light_xy : array_like, shape (V, 2), float64
        Vertices' light-space x/y in metres (:func:`csmlab.texels.light_plane_coordinates`).
    vertex_depth : array_like, shape (V,), float64
        ``d·X − zref`` of each vertex in metres.
    triangles : array_like, shape (T, 3), integer
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
    candidates : array_like, shape (K, 2), int32, optional
        (region, triangle) pairs to rasterize (:func:`region_candidates`); None: every pair.
    depth : ndarray, shape (C, R, R), float32, optional
        The maps to rasterize into (default +inf everywhere): texels outside the regions keep their
        values. Consumed: on the CPU it is filled in place and returned.
    count_only : bool
        Count the coverage tests that pass and store no depth (``depth`` is ignored and None returned).
    threads : int
        CPU launches run at once (one Warp CPU launch runs on one thread). The regions, which are
        disjoint, are dealt to them in turn, so no two launches write one texel; cut large regions
        into bands first (:func:`banded_regions`) so that each thread gets a share of each. Ignored
        on CUDA.
    device : str

    Returns
    -------
    depth : ndarray, shape (C, R, R), float32, or None
        None with ``count_only``.
    texels_rasterized : ndarray, shape (G,), int64
        Coverage tests that passed in each region.
    """
    device = checked_device(device)
    xy = np.ascontiguousarray(light_xy, dtype=np.float64)
    size = np.ascontiguousarray(texel_size, dtype=np.float64)
    corner = np.ascontiguousarray(origin, dtype=np.int64)
    tri = np.ascontiguousarray(triangles, dtype=np.int32)
    z = np.ascontiguousarray(vertex_depth, dtype=np.float64)
    if xy.ndim != 2 or xy.shape[1] != 2 or size.ndim != 2 or size.shape[1] != 2 or corner.shape != size.shape:
        raise ValueError(f"light_xy, texel_size, origin: expected shapes (V, 2), (C, 2), (C, 2); "
                         f"got {xy.shape}, {size.shape}, {corner.shape}")
    if z.shape != (xy.shape[0],) or not np.all(np.isfinite(z)) or not np.all(np.isfinite(xy)):
        raise ValueError(f"light_xy, vertex_depth: expected {xy.shape[0]} finite vertices and depths")
    if tri.ndim != 2 or tri.shape[1] != 3 or (tri.size and (tri.min() < 0 or tri.max() >= xy.shape[0])):
        raise ValueError(f"triangles: expected indices of shape (T, 3) in [0, {xy.shape[0]})")
    bits = _checked_bits(bits)
    resolution = _checked_resolution(resolution)
    shape = (size.shape[0], resolution, resolution)
    areas = np.ascontiguousarray(whole_map_regions([resolution] * shape[0]) if regions is None else regions,
                                 dtype=np.int32)
    if (areas.ndim != 2 or areas.shape[1] != 5 or np.any(areas[:, 0] < 0) or np.any(areas[:, 0] >= shape[0])
            or np.any(areas[:, 1:] < 0) or np.any(areas[:, 1:] > resolution)):
        raise ValueError(f"regions: expected rows (c, i0, i1, j0, j1) within {shape}, got shape {areas.shape}")
    pairs = (np.stack(np.meshgrid(np.arange(areas.shape[0]), np.arange(tri.shape[0]), indexing="ij"), -1).reshape(-1, 2)
             if candidates is None else np.asarray(candidates)).astype(np.int32)
    if pairs.ndim != 2 or pairs.shape[1] != 2 or (pairs.size and (pairs[:, 0].max() >= areas.shape[0]
                                                                   or pairs[:, 1].max() >= tri.shape[0])):
        raise ValueError(f"candidates: expected (region, triangle) pairs of shape (K, 2), got {pairs.shape}")
    if count_only:
        maps = np.zeros((0, 0, 0), dtype=np.float32)
    elif depth is None:
        maps = np.full(shape, np.inf, dtype=np.float32)
    elif depth.shape != shape or depth.dtype != np.float32:
        raise ValueError(f"depth: expected float32 maps of shape {shape}, got {depth.dtype} {depth.shape}")
    else:
        maps = depth
    parts = min(checked_threads(threads, device), areas.shape[0])
    if pairs.shape[0] == 0:
        return None if count_only else maps, np.zeros(areas.shape[0], dtype=np.int64)
    maps_on = wp.array(maps, dtype=wp.float32, device=device, copy=False)
    inputs = (wp.array(xy, dtype=wp.float64, device=device, copy=False),
              wp.array(z, dtype=wp.float64, device=device, copy=False),
              wp.array(tri, dtype=wp.int32, device=device, copy=False),
              wp.array(size, dtype=wp.float64, device=device, copy=False),
              wp.array(corner, dtype=wp.int64, device=device, copy=False),
              wp.array(areas, dtype=wp.int32, device=device, copy=False))
    fixed = (float(2**bits), float(2**50), wp.int64(2**bits), wp.int64(bits))
    # Region g goes to launch g mod parts: disjoint regions, so no texel is written by two launches.
    if parts > 1 and np.any(np.diff(pairs[:, 0]) < 0):
        pairs = pairs[np.argsort(pairs[:, 0], kind="stable")]
    starts = _region_starts(pairs, areas.shape[0])
    subsets = [np.ascontiguousarray(np.concatenate([pairs[starts[g]:starts[g + 1]]
                                                    for g in range(k, areas.shape[0], parts)] or [pairs[:0]]))
               for k in range(parts)]
    shares = [np.zeros(areas.shape[0])] * parts

    def launch(k: int) -> None:
        covered = wp.empty(subsets[k].shape[0], dtype=wp.int32, device=device)
        wp.launch(rasterize_regions_kernel, dim=subsets[k].shape[0],
                  inputs=(*inputs, wp.array(subsets[k], dtype=wp.int32, device=device), *fixed),
                  outputs=(maps_on, covered), device=device)
        shares[k] = np.bincount(subsets[k][:, 0], weights=covered.numpy(), minlength=areas.shape[0])

    with LaunchPool(parts, kernels=(rasterize_regions_kernel,), device=device) as pool:
        pool.run([lambda k=k: launch(k) for k in range(parts)])
    texels = np.sum(shares, axis=0)
    return None if count_only else maps_on.numpy(), texels.astype(np.int64)
