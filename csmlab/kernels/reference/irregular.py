"""The reference's ``irregular`` method: the triangles in light space, each shadowing the binned ray starts
(:mod:`csmlab.kernels.reference.ray_grid`) its light-space projection holds nearer the light — closed
point-in-triangle and depth, both in float64 from float64 vertices, through alpha masks by the starts'
light-space barycentric weights (:mod:`csmlab.kernels.reference`)."""

from __future__ import annotations

import functools

import numpy as np
import warp as wp

from csmlab.kernels.alpha import AlphaTextures, alpha_passes
from csmlab.kernels.floats import is_nan
from csmlab.kernels.reference.ray_grid import BinnedRays, binned_rays, grid_cell, grid_point, ray_start_kernel, sub_cell
from csmlab.kernels.reference.shadow_rays import RAY_LENGTH, RAY_OFFSET, checked_receivers
from csmlab.kernels.threads import LaunchPool, checked_threads, split_range
from csmlab.kernels.visibility import MeshBVH

__all__ = ["CHUNK", "hard_shadow_irregular"]

# Products and sums rounded one by one on both devices (clang and NVRTC may otherwise contract them): a
# CUDA build may not contract them into fused multiply-adds, or its bits differ from the CPU's.
wp.set_module_options({"fuse_fp": False})

MARGIN = wp.constant(wp.float64(1e-6))
"""Grid cells by which a triangle's reach is widened against rounding (which is below 1e-9 of a cell)."""


SLOPE = wp.constant(wp.float64(1e-3))
"""Below this |dv/du| in grid coordinates, an edge's slice of a sub-row is taken as the whole edge."""


CHUNK = wp.constant(64)
"""Consecutive triangles whose light-space rectangles are joined, to pass them all at once beside the ray starts."""


@wp.struct
class LightTriangles:
    """The scene in light space, and the float32 rectangles of its triangles and chunks (:data:`CHUNK`)."""

    light: wp.array(dtype=wp.vec3d)
    """Vertices relative to the anchor in light space, ``(x·right, x·up, x·d)``, metres."""
    triangles: wp.array2d(dtype=wp.int32)
    box: wp.array(dtype=wp.vec4)
    """Each triangle's light-space rectangle ``(x0, y0, x1, y1)``, float32."""
    chunk_box: wp.array(dtype=wp.vec4)
    """The union of the rectangles of each chunk of :data:`CHUNK` triangles."""
    slack: wp.float64
    """Metres by which a float32 rectangle is widened beyond its rounding."""
    uv: wp.array(dtype=wp.vec2d)
    """Texture coordinates of each vertex (zero-length: no masks)."""
    vertex_mask: wp.array(dtype=wp.int32)
    """Each vertex's alpha mask, −1 opaque (zero-length: every triangle opaque)."""
    textures: AlphaTextures
    """The masks (:mod:`csmlab.kernels.alpha`)."""


_CACHED_LIGHTS = 2
"""Light directions whose light-space vertices a MeshBVH keeps: a frame's and its predecessor's."""


@wp.kernel
def light_space_kernel(
    vertices: wp.array(dtype=wp.vec3d),
    right: wp.vec3d,
    up: wp.vec3d,
    d: wp.vec3d,
    light: wp.array(dtype=wp.vec3d),
):
    """Vertices (relative to the anchor) in light space: ``(x·right, x·up, x·d)``."""
    k = wp.tid()
    v = vertices[k]
    light[k] = wp.vec3d(wp.dot(v, right), wp.dot(v, up), wp.dot(v, d))


@wp.kernel
def triangle_box_kernel(
    light: wp.array(dtype=wp.vec3d),
    triangles: wp.array2d(dtype=wp.int32),
    box: wp.array(dtype=wp.vec4),
    chunk_box: wp.array(dtype=wp.vec4),
):
    """Each triangle's light-space bounding rectangle ``(x_lo, y_lo, x_hi, y_hi)``, rounded to float32, and
    their union over each chunk of :data:`CHUNK` consecutive triangles (one thread per chunk)."""
    k = wp.tid()
    r = wp.vec4(wp.inf, wp.inf, -wp.inf, -wp.inf)
    for t in range(k * CHUNK, wp.min(k * CHUNK + CHUNK, triangles.shape[0])):
        a = light[triangles[t, 0]]
        b = light[triangles[t, 1]]
        c = light[triangles[t, 2]]
        rect = wp.vec4(wp.float32(wp.min(a[0], wp.min(b[0], c[0]))), wp.float32(wp.min(a[1], wp.min(b[1], c[1]))),
                       wp.float32(wp.max(a[0], wp.max(b[0], c[0]))), wp.float32(wp.max(a[1], wp.max(b[1], c[1]))))
        box[t] = rect
        r = wp.vec4(wp.min(r[0], rect[0]), wp.min(r[1], rect[1]), wp.max(r[2], rect[2]), wp.max(r[3], rect[3]))
    chunk_box[k] = r


@wp.func
def rays_within(rect: wp.vec4, slack: wp.float64, origin: wp.vec2d, inv_side: wp.float64, nx: int, ny: int,
                table: wp.array(dtype=wp.int32)) -> bool:
    """Whether a coarse cell that light-space rectangle ``rect`` (float32, widened by ``slack``) reaches holds rays.

    The cells are those of the rectangle's grid coordinates widened by ``MARGIN``, as a triangle
    within it reaches no others (:func:`block_triangle`).
    """
    c0 = grid_cell((wp.float64(rect[0]) - slack - origin[0]) * inv_side - MARGIN, nx)
    c1 = grid_cell((wp.float64(rect[2]) + slack - origin[0]) * inv_side + MARGIN, nx) + 1
    r0 = grid_cell((wp.float64(rect[1]) - slack - origin[1]) * inv_side - MARGIN, ny)
    r1 = grid_cell((wp.float64(rect[3]) + slack - origin[1]) * inv_side + MARGIN, ny) + 1
    w = nx + 1
    return table[r1 * w + c1] - table[r0 * w + c1] - table[r1 * w + c0] + table[r0 * w + c0] > 0


@wp.func
def reaches_rays(rect: wp.vec4, slack: wp.float64, bounds: wp.array(dtype=wp.float64), origin: wp.vec2d,
                 inv_side: wp.float64, nx: int, ny: int, table: wp.array(dtype=wp.int32)) -> bool:
    """Whether light-space rectangle ``rect`` (float32, widened by ``slack`` beyond its rounding) may hold a start.

    First against the starts' rectangle ``bounds``; then, for the rest, against the coarse cells
    with rays (:func:`rays_within`): the starts' rectangle holds the view's footprint and the gaps in it.
    """
    if wp.float64(rect[2]) + slack < bounds[0] or wp.float64(rect[0]) - slack > bounds[2]:
        return False
    if wp.float64(rect[3]) + slack < bounds[1] or wp.float64(rect[1]) - slack > bounds[3]:
        return False
    return rays_within(rect, slack, origin, inv_side, nx, ny, table)


@wp.func
def inverse_slope(p: wp.vec2d, q: wp.vec2d) -> wp.float64:
    """``du/dv`` of segment ``p``–``q`` in grid coordinates; NaN within ``SLOPE`` of horizontal (ill-conditioned)."""
    du = q[0] - p[0]
    dv = q[1] - p[1]
    if wp.abs(dv) > SLOPE * wp.abs(du):
        return du / dv
    return wp.float64(wp.nan)


@wp.func
def strip_extent(p: wp.vec2d, q: wp.vec2d, du_dv: wp.float64, v_lo: wp.float64, v_hi: wp.float64,
                 extent: wp.vec2d) -> wp.vec2d:
    """``extent`` (least and greatest ``u``) grown by the part of segment ``p``–``q`` with ``v_lo ≤ v ≤ v_hi``.

    A segment of NaN ``du_dv`` (nearly horizontal) counts whole.
    """
    low = wp.min(p[1], q[1])
    high = wp.max(p[1], q[1])
    if high < v_lo or low > v_hi:
        return extent
    u_p = p[0]
    u_q = q[0]
    if not is_nan(du_dv):
        u_p = p[0] + (wp.clamp(v_lo, low, high) - p[1]) * du_dv
        u_q = p[0] + (wp.clamp(v_hi, low, high) - p[1]) * du_dv
    return wp.vec2d(wp.min(extent[0], wp.min(u_p, u_q)), wp.max(extent[1], wp.max(u_p, u_q)))


@wp.func
def block_triangle(
    t: int,
    light: wp.array(dtype=wp.vec3d),
    triangles: wp.array2d(dtype=wp.int32),
    box: wp.array(dtype=wp.vec4),
    slack: wp.float64,
    sorted_start: wp.array(dtype=wp.vec3d),
    origin: wp.vec2d,
    inv_side: wp.float64,
    nx: int,
    ny: int,
    sub: wp.array(dtype=wp.int32),
    offset: wp.array(dtype=wp.int32),
    first: wp.array(dtype=wp.int32),
    bounds: wp.array(dtype=wp.float64),
    max_t: wp.float64,
    table: wp.array(dtype=wp.int32),
    sorted_ray: wp.array(dtype=wp.int32),
    uv: wp.array(dtype=wp.vec2d),
    vertex_mask: wp.array(dtype=wp.int32),
    textures: AlphaTextures,
    lit: wp.array(dtype=wp.float32),
):
    """Triangle ``t``: shadow every ray whose start it covers in light space, nearer the light within ``max_t``
    (and where its alpha mask, if any, is opaque)."""
    # Most triangles reach no start: their float32 rectangle (read in sequence) says so before any
    # vertex is gathered.
    if not reaches_rays(box[t], slack, bounds, origin, inv_side, nx, ny, table):
        return
    a = light[triangles[t, 0]]
    b = light[triangles[t, 1]]
    c = light[triangles[t, 2]]
    # Nothing at or behind every start can block a ray toward the light.
    if wp.min(a[2], wp.min(b[2], c[2])) >= bounds[4]:
        return
    # Light-space edges from vertex a, oriented counter-clockwise.
    e_b = b - a
    e_c = c - a
    area = e_b[0] * e_c[1] - e_c[0] * e_b[1]
    # Seen edge-on, a triangle covers no area of light space.
    if area == wp.float64(0.0):
        return
    m = int(-1)
    uv_a = wp.vec2d()
    uv_b = wp.vec2d()
    uv_c = wp.vec2d()
    if vertex_mask.shape[0] > 0:
        m = vertex_mask[triangles[t, 0]]
        if m >= 0:
            uv_a = uv[triangles[t, 0]]
            uv_b = uv[triangles[t, 1]]
            uv_c = uv[triangles[t, 2]]
    if area < wp.float64(0.0):
        e_b, e_c = e_c, e_b
        uv_b, uv_c = uv_c, uv_b
        area = -area
    # The vertices in grid coordinates (cells from the origin), mapped as the starts were: a start
    # inside the triangle lies inside it there too, within rounding far below MARGIN.
    g_a = grid_point(a, origin, inv_side)
    g_b = grid_point(b, origin, inv_side)
    g_c = grid_point(c, origin, inv_side)
    u_lo = wp.min(g_a[0], wp.min(g_b[0], g_c[0])) - MARGIN
    u_hi = wp.max(g_a[0], wp.max(g_b[0], g_c[0])) + MARGIN
    v_lo = wp.min(g_a[1], wp.min(g_b[1], g_c[1])) - MARGIN
    v_hi = wp.max(g_a[1], wp.max(g_b[1], g_c[1])) + MARGIN
    # The divisions of the slopes wait for the first sub-row with rays in the box's reach: most
    # triangles that reach the starts' rectangle have none.
    ready = int(0)
    slope_x = wp.float64(0.0)
    slope_y = wp.float64(0.0)
    slope_ab = wp.float64(0.0)
    slope_bc = wp.float64(0.0)
    slope_ca = wp.float64(0.0)
    # The loops are `while` loops, each stepping first so that `continue` moves on: on the CPU, a
    # loop over a range known only at run time costs Warp several times more per step.
    col_lo = grid_cell(u_lo, nx)
    col_hi = grid_cell(u_hi, nx)
    row = grid_cell(v_lo, ny) - 1
    row_hi = grid_cell(v_hi, ny)
    while row < row_hi:
        row += 1
        col = col_lo - 1
        while col < col_hi:
            col += 1
            cell = row * nx + col
            n = sub[cell]
            if n == 0:
                continue
            height = wp.float64(1.0) / wp.float64(n)
            box_lo = sub_cell(u_lo, col, n)
            box_hi = sub_cell(u_hi, col, n)
            j = sub_cell(v_lo, row, n) - 1
            j_hi = sub_cell(v_hi, row, n)
            while j < j_hi:
                j += 1
                f = offset[cell] + j * n
                if first[f + box_lo] == first[f + box_hi + 1]:
                    continue
                if ready == 0:
                    slope_x = (e_b[2] * e_c[1] - e_c[2] * e_b[1]) / area
                    slope_y = (e_c[2] * e_b[0] - e_b[2] * e_c[0]) / area
                    slope_ab = inverse_slope(g_a, g_b)
                    slope_bc = inverse_slope(g_b, g_c)
                    slope_ca = inverse_slope(g_c, g_a)
                    ready = 1
                # Only the sub-cells of this sub-row that the triangle's slice of it reaches.
                strip_lo = wp.float64(row) + wp.float64(j) * height - MARGIN
                strip_hi = strip_lo + height + MARGIN + MARGIN
                extent = wp.vec2d(wp.float64(wp.inf), wp.float64(-wp.inf))
                extent = strip_extent(g_a, g_b, slope_ab, strip_lo, strip_hi, extent)
                extent = strip_extent(g_b, g_c, slope_bc, strip_lo, strip_hi, extent)
                extent = strip_extent(g_c, g_a, slope_ca, strip_lo, strip_hi, extent)
                if extent[0] > extent[1]:
                    continue
                i_lo = sub_cell(extent[0] - MARGIN, col, n)
                i_hi = sub_cell(extent[1] + MARGIN, col, n)
                # The sub-cells i_lo..i_hi of a sub-row hold consecutive rays.
                r = first[f + i_lo] - 1
                r_end = first[f + i_hi + 1] - 1
                while r < r_end:
                    r += 1
                    s = sorted_start[r]
                    dx = s[0] - a[0]
                    dy = s[1] - a[1]
                    # Depth first (the cheaper test, failed by the receiver's own triangle):
                    # the plane lies nearer the light than the start, within the ray.
                    along = s[2] - (a[2] + slope_x * dx + slope_y * dy)
                    if along <= wp.float64(0.0) or along >= max_t:
                        continue
                    # Closed point-in-triangle: the barycentric weights of c, of b and of a
                    # (twice the signed areas of the sub-triangles), none negative.
                    w_c = e_b[0] * dy - e_b[1] * dx
                    w_b = e_c[1] * dx - e_c[0] * dy
                    if wp.min(wp.min(w_c, w_b), area - w_b - w_c) >= wp.float64(0.0):
                        if m >= 0:
                            at = ((area - w_b - w_c) * uv_a + w_b * uv_b + w_c * uv_c) / area
                            if not alpha_passes(textures, m, at[0], at[1]):
                                continue
                        lit[sorted_ray[r]] = 0.0


@wp.kernel
def block_kernel(
    scene: LightTriangles,
    rays: BinnedRays,
    max_t: wp.float64,
    phase: int,
    stride: int,
    lit: wp.array(dtype=wp.float32),
):
    """The triangles of chunk ``phase + i·stride`` (:data:`CHUNK` consecutive ones), each by :func:`block_triangle`.

    A ray's flag in ``lit`` is written only to 0, by every triangle that blocks it: the threads of
    one launch and concurrent launches (each taking its own chunks) need no atomics, and the flags
    do not depend on which triangle wrote first.
    """
    k = phase + wp.tid() * stride
    # The structs' fields as locals: the functions below run per triangle, and a struct passed to
    # them would be copied each time (Warp passes structs by value).
    light = scene.light
    triangles = scene.triangles
    box = scene.box
    slack = scene.slack
    grid = rays.grid
    origin = grid.origin
    inv_side = grid.inv_side
    nx = grid.nx
    ny = grid.ny
    bounds = rays.bounds
    table = rays.table
    sorted_start = rays.start
    sorted_ray = rays.ray
    sub = rays.sub
    offset = rays.offset
    first = rays.first
    uv = scene.uv
    vertex_mask = scene.vertex_mask
    textures = scene.textures
    # A chunk's rectangle holds its triangles': a chunk that reaches no start is passed whole.
    if not reaches_rays(scene.chunk_box[k], slack, bounds, origin, inv_side, nx, ny, table):
        return
    # A `while` loop: see block_triangle.
    t = k * CHUNK
    end = wp.min(t + CHUNK, triangles.shape[0])
    while t < end:
        block_triangle(t, light, triangles, box, slack, sorted_start, origin, inv_side, nx, ny, sub, offset, first,
                       bounds, max_t, table, sorted_ray, uv, vertex_mask, textures, lit)
        t += 1


def _scene_in_light_space(bvh: MeshBVH, basis: np.ndarray, pool: LaunchPool) -> tuple[wp.array, wp.array, wp.array]:
    """``bvh``'s vertices in the light space of ``basis`` (relative to the anchor), its triangles' float32
    rectangles there and their union per chunk of :data:`CHUNK`, kept per direction; each thread of
    ``pool`` transforms a range."""
    key = basis.tobytes()
    if key not in bvh.light_space:
        device = bvh.device
        light = wp.empty(bvh.vertices.shape[0], dtype=wp.vec3d, device=device)
        axes = tuple(wp.vec3d(*row) for row in basis)
        pool.run([functools.partial(wp.launch, light_space_kernel, dim=hi - lo, inputs=(bvh.vertices[lo:hi], *axes),
                                    outputs=(light[lo:hi],), device=device)
                  for lo, hi in split_range(light.shape[0], pool.threads)])
        box = wp.empty(bvh.triangles.shape[0], dtype=wp.vec4, device=device)
        chunk_box = wp.empty(-(-box.shape[0] // CHUNK), dtype=wp.vec4, device=device)
        n = box.shape[0]
        pool.run([functools.partial(wp.launch, triangle_box_kernel, dim=hi - lo,
                                    inputs=(light, bvh.triangles[lo * CHUNK:min(hi * CHUNK, n)]),
                                    outputs=(box[lo * CHUNK:min(hi * CHUNK, n)], chunk_box[lo:hi]), device=device)
                  for lo, hi in split_range(chunk_box.shape[0], pool.threads)])
        while len(bvh.light_space) >= _CACHED_LIGHTS:
            bvh.light_space.pop(next(iter(bvh.light_space)))
        bvh.light_space[key] = (light, box, chunk_box)
    return bvh.light_space[key]


def hard_shadow_irregular(bvh: MeshBVH, *, points, normals, light_direction, threads: int = 1) -> np.ndarray:
    """The hard shadow by an irregular z-buffer: rays binned in light space, tested by triangle in float64.

    Arguments of :func:`~csmlab.kernels.reference.hard_shadow`. The grid spans the ray starts' light-space
    rectangle with square cells of :data:`~csmlab.kernels.reference.ray_grid.RAYS_PER_CELL` starts on average.

    Notes
    -----
    The triangles are tested by chunks of :data:`CHUNK`: a chunk, then a triangle, whose light-space
    rectangle lies beside the starts' or reaches only coarse cells without rays (a summed-area
    table of the coarse cells' rays says so in four reads) is passed before any vertex is gathered.

    Split over ``threads`` concurrent CPU launches (:mod:`csmlab.kernels.threads`): the ray starts,
    their coarse and fine bins and their scatter by blocks of
    :data:`~csmlab.kernels.reference.ray_grid.RECEIVER_BLOCK` receivers
    (launch ``k`` takes blocks ``k, k + threads, …``), each launch with its own bounds and per-cell
    counters (a cell's rays are placed launch after launch); the chunks of triangles interleaved
    the same way. A blocked ray's flag is written to 0 by every triangle that blocks it, whichever
    launch it is in. Every ``threads`` gives the same flags, bit for bit: the tests of a ray and a
    triangle do not depend on the grid, nor on the order of the rays in it.
    """
    p, n, basis = checked_receivers(points, normals, light_direction)
    shape = np.shape(points)[:-1]
    device = bvh.device
    threads = checked_threads(threads, device)
    count = p.shape[0]
    lit = wp.empty(count, dtype=wp.float32, device=device)
    if count == 0:
        return lit.numpy().reshape(shape)
    diagonal = max(bvh.diagonal, 1e-9)
    kernels = (ray_start_kernel, light_space_kernel, block_kernel)
    with LaunchPool(threads, kernels=kernels, device=device) as pool:
        light, box, chunk_box = _scene_in_light_space(bvh, basis, pool)
        rays = binned_rays(p, n, anchor=bvh.anchor, basis=basis, start_offset=RAY_OFFSET * diagonal,
                           diagonal=diagonal, lit=lit, pool=pool)
        if rays is None:
            return lit.numpy().reshape(shape)
        scene = LightTriangles()
        scene.light = light
        scene.triangles = bvh.triangles
        scene.box = box
        scene.chunk_box = chunk_box
        scene.slack = diagonal * 2.0**-23
        scene.uv = bvh.masks.uv
        scene.vertex_mask = bvh.masks.vertex_mask
        scene.textures = bvh.masks.textures
        chunks = chunk_box.shape[0]
        launches = len(split_range(chunks, threads))
        pool.run([functools.partial(wp.launch, block_kernel, dim=(chunks - k + launches - 1) // launches,
                                    inputs=(scene, rays, RAY_LENGTH * diagonal, k, launches), outputs=(lit,),
                                    device=device)
                  for k in range(launches)])
    return lit.numpy().reshape(shape)
