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

import numpy as np
import warp as wp

from csmlab.kernels import checked_device

__all__ = ["cascade_candidates", "rasterize_cascades", "rasterize_depth", "triangle_bounds"]


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
def first_centre(lo: wp.int64, unit: wp.int64, bits: wp.int64, resolution: int) -> int:
    """First texel whose centre, ``(2k + 1)·unit`` in doubled units, is at or above ``lo`` (clamped to the map).

    ``unit = 2**bits``: the floor division by ``2·unit`` is an arithmetic shift by ``bits + 1``.
    """
    k = -((unit - lo) >> (bits + wp.int64(1)))
    return int(wp.clamp(k, wp.int64(0), wp.int64(resolution)))


@wp.func
def last_centre(hi: wp.int64, unit: wp.int64, bits: wp.int64, resolution: int) -> int:
    """Last texel whose centre is at or below ``hi`` (clamped to the map)."""
    k = (hi - unit) >> (bits + wp.int64(1))
    return int(wp.clamp(k, wp.int64(-1), wp.int64(resolution - 1)))


@wp.func
def edge_values(px: wp.int64, ax: wp.int64, ay: wp.int64, bx: wp.int64, by: wp.int64, cx: wp.int64, cy: wp.int64,
                row_ab: wp.float64, row_bc: wp.float64, row_ca: wp.float64):
    """The three edge functions at the centre of column ``px`` (doubled units) of a row, from the row's terms."""
    return (row_ab - wp.float64(by - ay) * wp.float64(px - ax), row_bc - wp.float64(cy - by) * wp.float64(px - bx),
            row_ca - wp.float64(ay - cy) * wp.float64(px - cx))


@wp.func
def store_depth(depth: wp.array3d(dtype=wp.float32), c: int, j: int, i: int, w_a: wp.float64, w_b: wp.float64,
                w_c: wp.float64, za: wp.float64, zb: wp.float64, zc: wp.float64, area: wp.float64):
    """Keep the nearer of texel (i, j)'s depth and the triangle's, interpolated with its edge functions."""
    wp.atomic_min(depth, c, j, i, wp.float32((w_a * za + w_b * zb + w_c * zc) / area))


@wp.func
def rasterize_triangle(
    points: wp.array3d(dtype=wp.int64),
    vertex_depth: wp.array(dtype=wp.float64),
    triangles: wp.array2d(dtype=wp.int32),
    unit: wp.int64,
    bits: wp.int64,
    depth: wp.array3d(dtype=wp.float32),
    c: int,
    t: int,
) -> int:
    """Rasterize triangle t into cascade c's map; the number of texel centres it covers."""
    resolution = depth.shape[1]
    ia = triangles[t, 0]
    ib = triangles[t, 1]
    ic = triangles[t, 2]
    two = wp.int64(2)
    ax = two * points[c, ia, 0]
    ay = two * points[c, ia, 1]
    bx = two * points[c, ib, 0]
    by = two * points[c, ib, 1]
    cx = two * points[c, ic, 0]
    cy = two * points[c, ic, 1]
    # Cull before any per-texel work: triangles whose bounding box holds no texel centre of the
    # map, and triangles of zero area.
    i0 = first_centre(wp.min(wp.min(ax, bx), cx), unit, bits, resolution)
    i1 = last_centre(wp.max(wp.max(ax, bx), cx), unit, bits, resolution)
    j0 = first_centre(wp.min(wp.min(ay, by), cy), unit, bits, resolution)
    j1 = last_centre(wp.max(wp.max(ay, by), cy), unit, bits, resolution)
    if i0 > i1 or j0 > j1:
        return 0
    area = wp.float64(bx - ax) * wp.float64(cy - ay) - wp.float64(by - ay) * wp.float64(cx - ax)
    if area == wp.float64(0.0):
        return 0
    za = vertex_depth[ia]
    zb = vertex_depth[ib]
    zc = vertex_depth[ic]
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
    covered[c, t] = rasterize_triangle(points, vertex_depth, triangles, unit, bits, depth, c, t)


@wp.kernel
def rasterize_candidates_kernel(
    points: wp.array3d(dtype=wp.int64),
    vertex_depth: wp.array(dtype=wp.float64),
    triangles: wp.array2d(dtype=wp.int32),
    candidates: wp.array2d(dtype=wp.int32),
    unit: wp.int64,
    bits: wp.int64,
    depth: wp.array3d(dtype=wp.float32),
    covered: wp.array(dtype=wp.int32),
):
    k = wp.tid()
    covered[k] = rasterize_triangle(points, vertex_depth, triangles, unit, bits, depth, candidates[k, 0], candidates[k, 1])


@wp.kernel
def fixed_point_vertices_kernel(
    light_xy: wp.array2d(dtype=wp.float64),
    texel_size: wp.array2d(dtype=wp.float64),
    origin: wp.array2d(dtype=wp.int64),
    scale: wp.float64,
    limit: wp.float64,
    points: wp.array3d(dtype=wp.int64),
):
    c, v = wp.tid()
    for axis in range(2):
        # The operations of csmlab.texels.fixed_point_coordinates, in its order: no sum, so no
        # fused multiply-add can change a rounding.
        u = light_xy[v, axis] / texel_size[c, axis] * scale
        u = wp.rint(wp.clamp(u, -limit, limit))
        if wp.isnan(u):
            u = -limit
        points[c, v, axis] = wp.int64(u) - origin[c, axis]


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
    if not (isinstance(resolution, (int, np.integer)) and 1 <= resolution <= 16384):
        raise ValueError(f"resolution: expected an integer in 1..16384, got {resolution!r}")
    if not (isinstance(bits, (int, np.integer)) and 0 <= bits <= 16):
        raise ValueError(f"bits: expected an integer in 0..16, got {bits!r}")
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


def triangle_bounds(light_xy, triangles) -> tuple[np.ndarray, np.ndarray]:
    """Light-space bounding rectangle of every triangle: ``lo, hi`` of shape (T, 2), metres.

    Parameters
    ----------
    light_xy : array_like, shape (V, 2), float64
        Vertices' light-space x/y in metres (:func:`csmlab.texels.light_plane_coordinates`).
    triangles : array_like, shape (T, 3), integer
    """
    xy = np.asarray(light_xy, dtype=np.float64)[np.asarray(triangles)]
    return xy.min(axis=1), xy.max(axis=1)


def cascade_candidates(lo, hi, *, texel_size, origin, resolution: int) -> np.ndarray:
    """(cascade, triangle) pairs whose light-space rectangle meets the cascade's box: ``(K, 2)`` int32.

    Conservative: each box is widened by one texel on every side, far more than the fixed-point
    snap (half a ``2**-bits`` texel) and float rounding can move a vertex, so a triangle left out
    covers no texel centre of that cascade. Pairs are sorted by cascade, then triangle.

    Parameters
    ----------
    lo, hi : array_like, shape (T, 2)
        :func:`triangle_bounds`, metres.
    texel_size : array_like, shape (C, 2)
        Metres per texel of each cascade.
    origin : array_like, shape (C, 2)
        Box minimum corner in texels of each cascade.
    resolution : int
        Texels per side R.
    """
    lo = np.asarray(lo, dtype=np.float64)
    hi = np.asarray(hi, dtype=np.float64)
    pairs = []
    for c, (size, corner) in enumerate(zip(np.asarray(texel_size, np.float64), np.asarray(origin, np.float64))):
        box_lo = (corner - 1.0) * size
        box_hi = (corner + resolution + 1.0) * size
        inside = np.flatnonzero((hi[:, 0] >= box_lo[0]) & (lo[:, 0] <= box_hi[0]) & (hi[:, 1] >= box_lo[1])
                                & (lo[:, 1] <= box_hi[1]))
        pairs.append(np.stack([np.full(inside.size, c), inside], axis=1))
    return np.concatenate(pairs).astype(np.int32) if pairs else np.zeros((0, 2), np.int32)


def rasterize_cascades(light_xy, vertex_depth, triangles, *, texel_size, origin, resolution: int, bits: int,
                       candidates=None, device: str = "cpu") -> tuple[np.ndarray, int]:
    """Depth maps of every cascade from light-space vertices: fixed point and rasterization on the device.

    The same maps as :func:`rasterize_depth` of
    :func:`csmlab.texels.fixed_point_coordinates` — bit for bit — with the fixed-point conversion
    of every vertex in a Warp kernel and, with ``candidates``, only the (cascade, triangle) pairs
    that can cover a texel rasterized.

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
    resolution, bits : int
        As :func:`rasterize_depth`.
    candidates : array_like, shape (K, 2), int32, optional
        (cascade, triangle) pairs to rasterize (:func:`cascade_candidates`); None: every pair.
    device : str

    Returns
    -------
    depth : ndarray, shape (C, R, R), float32
    texels_rasterized : int
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
    if not (isinstance(bits, (int, np.integer)) and 0 <= bits <= 16):
        raise ValueError(f"bits: expected an integer in 0..16, got {bits!r}")
    if not (isinstance(resolution, (int, np.integer)) and 1 <= resolution <= 16384):
        raise ValueError(f"resolution: expected an integer in 1..16384, got {resolution!r}")
    cascades = size.shape[0]
    points = wp.empty((cascades, xy.shape[0], 2), dtype=wp.int64, device=device)
    wp.launch(fixed_point_vertices_kernel, dim=(cascades, xy.shape[0]),
              inputs=(wp.array(xy, dtype=wp.float64, device=device, copy=False),
                      wp.array(size, dtype=wp.float64, device=device, copy=False),
                      wp.array(corner, dtype=wp.int64, device=device, copy=False), float(2**bits), float(2**50)),
              outputs=(points,), device=device)
    depth = wp.full((cascades, resolution, resolution), value=np.inf, dtype=wp.float32, device=device)
    pairs = (np.stack(np.meshgrid(np.arange(cascades), np.arange(tri.shape[0]), indexing="ij"), -1).reshape(-1, 2)
             if candidates is None else np.asarray(candidates)).astype(np.int32)
    if pairs.ndim != 2 or pairs.shape[1] != 2 or (pairs.size and (pairs[:, 0].max() >= cascades
                                                                   or pairs[:, 1].max() >= tri.shape[0])):
        raise ValueError(f"candidates: expected (cascade, triangle) pairs of shape (K, 2), got {pairs.shape}")
    if pairs.shape[0] == 0:
        return depth.numpy(), 0
    covered = wp.empty(pairs.shape[0], dtype=wp.int32, device=device)
    wp.launch(rasterize_candidates_kernel, dim=pairs.shape[0],
              inputs=(points, wp.array(z, dtype=wp.float64, device=device, copy=False),
                      wp.array(tri, dtype=wp.int32, device=device, copy=False),
                      wp.array(np.ascontiguousarray(pairs), dtype=wp.int32, device=device, copy=False),
                      wp.int64(2**bits), wp.int64(bits)),
              outputs=(depth, covered), device=device)
    return depth.numpy(), int(covered.numpy().sum(dtype=np.int64))
