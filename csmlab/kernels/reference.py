"""The ray-traced hard shadow, ground truth of every shadow map (docs/design.md, CSM model step 7).

From each visible point, moved a small epsilon along its normal (relative to the scene's size, far
above the float32 error of the BVH's anchored vertices), a ray toward the light (``−d``) of length
``4·diagonal`` asks whether anything lies in the way. A point whose normal faces away from the light
(``n·(−d) ≤ 0``) receives no direct light and is shadowed without a ray. Two methods answer the same
question, registered in :data:`REFERENCE_METHODS`:

- ``irregular`` — an irregular z-buffer (the default): every ray is parallel to the light, so in
  light space (orthographic along ``d``, :func:`csmlab.geometry.light_basis`) a ray from ``S`` is
  blocked exactly when a triangle's projection contains ``S.xy`` and the triangle's depth there is
  nearer the light than ``S`` by more than 0 and less than the ray's length. The ray starts are
  binned into a uniform light-space grid (a counting sort), then one thread per chunk of triangles
  walks, triangle by triangle, the cells a bounding box covers and tests the starts in them —
  closed point-in-triangle and depth, both in float64 from float64 vertices
  (:func:`hard_shadow_irregular`);
- ``ray`` — one any-hit ray per point through the BVH in float32, ``wp.mesh_query_ray_anyhit``
  (:func:`hard_shadow_ray`), the independent oracle of the tests.

They agree everywhere but within float32 rounding of a triangle's edge or of the ray's start plane,
where the float32 ray cast may decide either way.

Alpha-tested triangles (:mod:`csmlab.kernels.alpha`) block only where their mask is opaque: the
irregular z-buffer interpolates the texture coordinates with the start's light-space barycentric
weights; the ray cast (a masked mesh only) walks the ray's hits nearest first
(``wp.mesh_query_ray``), stepping past each hole at the hit's barycentric coordinates, up to
:data:`MASKED_HITS` of them.

Both take ``threads``: on the CPU, that many concurrent Warp launches share the work, each writing
its own part of the outputs (:mod:`csmlab.kernels.threads`) — but for the flags of the rays that the
irregular z-buffer finds blocked, which every writer sets to 0 — with the same shadow for every value.

References
----------
- Aila and Laine, "Alias-Free Shadow Maps", EGSR 2004 — shadow rays from the eye's samples,
  organised by occluding triangle in light space.
- Johnson, Hux, Lin, Chen and Mark, "The irregular Z-buffer: Hardware acceleration for irregular
  data structures", ACM TOG 24(4), 2005 — the light-space grid of samples, each triangle testing
  the samples of the cells it covers.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import warp as wp

from csmlab.geometry import light_basis
from csmlab.kernels.alpha import AlphaTextures, alpha_passes
from csmlab.kernels.threads import LaunchPool, checked_threads, split_range
from csmlab.kernels.visibility import MeshBVH
from csmlab.registry import check_name

__all__ = ["CHUNK", "COARSE_RAYS_PER_CELL", "MASKED_HITS", "RAYS_PER_CELL", "RAY_OFFSET", "RECEIVER_BLOCK",
           "REFERENCE_METHODS", "hard_shadow", "hard_shadow_irregular", "hard_shadow_ray"]

# Products and sums rounded one by one on both devices (clang and NVRTC may otherwise contract them): a
# CUDA build may not contract them into fused multiply-adds, or its bits differ from the CPU's.
wp.set_module_options({"fuse_fp": False})

RAY_OFFSET = 1e-5
"""Ray start offset along the normal, as a fraction of the scene's bounding-box diagonal."""

RAY_LENGTH = 4.0
"""Length of a shadow ray, as a multiple of the scene's bounding-box diagonal (beyond every occluder)."""

COARSE_RAYS_PER_CELL = 64.0
"""Mean ray starts per coarse cell of the irregular z-buffer's light-space grid."""

RAYS_PER_CELL = 4.0
"""Ray starts per sub-cell the coarse cells are split for (``benchmarks/bench_peers.py`` measures them)."""

MARGIN = wp.constant(wp.float64(1e-6))
"""Grid cells by which a triangle's reach is widened against rounding (which is below 1e-9 of a cell)."""

SLOPE = wp.constant(wp.float64(1e-3))
"""Below this |dv/du| in grid coordinates, an edge's slice of a sub-row is taken as the whole edge."""

CHUNK = wp.constant(64)
"""Consecutive triangles whose light-space rectangles are joined, to pass them all at once beside the ray starts."""

RECEIVER_BLOCK = 2048
"""Receivers per kernel thread of the CPU's passes over them, taken block by block by the launches of a split."""


@wp.struct
class ReceiverBlocks:
    """The receivers one launch takes: blocks ``phase, phase + stride, …`` of ``block`` receivers each."""

    block: int
    """Receivers per kernel thread (:data:`RECEIVER_BLOCK` on the CPU, 1 on a GPU)."""
    phase: int
    """The launch's first block."""
    stride: int
    """Blocks from one of the launch's blocks to its next (the launches of a split)."""


@wp.struct
class RayGrid:
    """The irregular z-buffer's coarse grid over the ray starts' light-space rectangle: square cells."""

    origin: wp.vec2d
    """Light-space x/y of the grid's corner, metres."""
    inv_side: wp.float64
    """Cells per metre."""
    nx: int
    """Columns of cells."""
    ny: int
    """Rows of cells."""


@wp.struct
class BinnedRays:
    """The ray starts sorted by fine cell, and what a triangle reads to find those it covers."""

    grid: RayGrid
    sub: wp.array(dtype=wp.int32)
    """Each coarse cell's split: ``sub × sub`` fine cells."""
    offset: wp.array(dtype=wp.int32)
    """Each coarse cell's first fine cell (row-major within it)."""
    first: wp.array(dtype=wp.int32)
    """Each fine cell's first ray in the sorted rays (and the total after the last)."""
    table: wp.array(dtype=wp.int32)
    """The coarse cells' summed-area table of rays, ``(ny + 1) × (nx + 1)`` row-major."""
    bounds: wp.array(dtype=wp.float64)
    """The starts' ``(min x, min y, max x, max y, max z)`` in light space."""
    start: wp.array(dtype=wp.vec3d)
    """The sorted rays' light-space starts."""
    ray: wp.array(dtype=wp.int32)
    """The sorted rays' receivers."""


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


MASKED_HITS = 64
"""The most holes of alpha-tested triangles the masked ray cast steps through on one ray; a ray with
more is taken as blocked (a forest seen along the light holds far fewer cards per ray)."""

_CACHED_LIGHTS = 2
"""Light directions whose light-space vertices a MeshBVH keeps: a frame's and its predecessor's."""


@wp.kernel
def hard_shadow_kernel(
    mesh: wp.uint64,
    position: wp.array(dtype=wp.vec3d),
    normal: wp.array(dtype=wp.vec3),
    toward_light: wp.vec3d,
    offset: wp.float64,
    max_t: wp.float32,
    lit: wp.array(dtype=wp.float32),
):
    k = wp.tid()
    n = wp.vec3d(normal[k])
    if wp.dot(n, toward_light) <= wp.float64(0.0):
        lit[k] = 0.0
        return
    start = wp.vec3(position[k] + n * offset)
    if wp.mesh_query_ray_anyhit(mesh, start, wp.vec3(toward_light), max_t):
        lit[k] = 0.0
    else:
        lit[k] = 1.0


@wp.kernel
def hard_shadow_masked_kernel(
    mesh: wp.uint64,
    position: wp.array(dtype=wp.vec3d),
    normal: wp.array(dtype=wp.vec3),
    toward_light: wp.vec3d,
    offset: wp.float64,
    max_t: wp.float32,
    triangles: wp.array2d(dtype=wp.int32),
    uv: wp.array(dtype=wp.vec2d),
    vertex_mask: wp.array(dtype=wp.int32),
    textures: AlphaTextures,
    lit: wp.array(dtype=wp.float32),
):
    """:func:`hard_shadow_kernel` through alpha masks: the hits nearest first, each hole stepped past."""
    k = wp.tid()
    n = wp.vec3d(normal[k])
    if wp.dot(n, toward_light) <= wp.float64(0.0):
        lit[k] = 0.0
        return
    start = wp.vec3(position[k] + n * offset)
    direction = wp.vec3(toward_light)
    left = max_t
    lit[k] = 1.0
    for _ in range(MASKED_HITS):
        query = wp.mesh_query_ray(mesh, start, direction, left)
        if not query.result:
            return
        face = query.face
        ia = triangles[face, 0]
        m = vertex_mask[ia]
        # Warp's barycentrics: the hit is u·A + v·B + (1 − u − v)·C.
        u = wp.float64(query.u)
        v = wp.float64(query.v)
        at = u * uv[ia] + v * uv[triangles[face, 1]] + (wp.float64(1.0) - u - v) * uv[triangles[face, 2]]
        if alpha_passes(textures, m, at[0], at[1]):
            lit[k] = 0.0
            return
        # Past the hole by a float32 step of the distance travelled, and on from there.
        step = query.t + wp.max(query.t, wp.float32(1.0)) * wp.float32(1e-6)
        start = start + direction * step
        left = left - step
        if left <= wp.float32(0.0):
            return
    lit[k] = 0.0


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
def receiver_block(i: int, take: ReceiverBlocks, count: int):
    """Thread ``i``'s receivers, of a launch taking the blocks ``take``: ``(first − 1, last)``, for a `while`
    loop that steps first (see :func:`block_triangle`)."""
    first = (take.phase + i * take.stride) * take.block
    return first - 1, wp.min(first + take.block, count) - 1


@wp.kernel
def ray_start_kernel(
    position: wp.array(dtype=wp.vec3d),
    normal: wp.array(dtype=wp.vec3),
    anchor: wp.vec3d,
    right: wp.vec3d,
    up: wp.vec3d,
    d: wp.vec3d,
    offset: wp.float64,
    take: ReceiverBlocks,
    start: wp.array(dtype=wp.vec3d),
    lit: wp.array(dtype=wp.float32),
    bounds: wp.array(dtype=wp.float64),
):
    """Light-space start of each receiver's ray; NaN (no point), 0 (turned away) or 1 (a ray) in ``lit``.

    ``bounds`` gathers the starts' ``(min x, min y, max x, max y, max z)``. Each thread takes a block
    of receivers (:func:`receiver_block`).
    """
    k, last = receiver_block(wp.tid(), take, lit.shape[0])
    x_lo = wp.float64(wp.inf)
    y_lo = wp.float64(wp.inf)
    x_hi = wp.float64(-wp.inf)
    y_hi = wp.float64(-wp.inf)
    z_hi = wp.float64(-wp.inf)
    while k < last:
        k += 1
        p = position[k]
        if not (wp.isfinite(p[0]) and wp.isfinite(p[1]) and wp.isfinite(p[2])):
            lit[k] = wp.nan
            continue
        n = wp.vec3d(normal[k])
        # The ray cast's test, n·(−d) ≤ 0, with the same operations.
        if wp.dot(n, -d) <= wp.float64(0.0):
            lit[k] = 0.0
            continue
        q = p - anchor + n * offset
        s = wp.vec3d(wp.dot(q, right), wp.dot(q, up), wp.dot(q, d))
        start[k] = s
        lit[k] = 1.0
        x_lo = wp.min(x_lo, s[0])
        y_lo = wp.min(y_lo, s[1])
        x_hi = wp.max(x_hi, s[0])
        y_hi = wp.max(y_hi, s[1])
        z_hi = wp.max(z_hi, s[2])
    wp.atomic_min(bounds, 0, x_lo)
    wp.atomic_min(bounds, 1, y_lo)
    wp.atomic_max(bounds, 2, x_hi)
    wp.atomic_max(bounds, 3, y_hi)
    wp.atomic_max(bounds, 4, z_hi)


@wp.func
def grid_cell(u: wp.float64, count: int) -> int:
    """Coarse cell of grid coordinate ``u`` (in cells from the origin), clamped to ``[0, count)``: monotone in ``u``."""
    return wp.clamp(int(wp.floor(u)), 0, count - 1)


@wp.func
def grid_point(p: wp.vec3d, origin: wp.vec2d, inv_side: wp.float64) -> wp.vec2d:
    """Light-space point ``p``'s x and y in grid coordinates: cells from the grid's corner ``origin``."""
    return wp.vec2d((p[0] - origin[0]) * inv_side, (p[1] - origin[1]) * inv_side)


@wp.func
def sub_cell(u: wp.float64, cell: int, sub: int) -> int:
    """Sub-cell of grid coordinate ``u`` within coarse cell ``cell`` split ``sub`` ways, clamped: monotone in ``u``."""
    return wp.clamp(int(wp.floor((u - wp.float64(cell)) * wp.float64(sub))), 0, sub - 1)


@wp.kernel
def coarse_bin_kernel(
    start: wp.array(dtype=wp.vec3d),
    lit: wp.array(dtype=wp.float32),
    grid: RayGrid,
    take: ReceiverBlocks,
    count: wp.array(dtype=wp.int32),
):
    """The rays per coarse cell, of the receivers of :func:`receiver_block`."""
    k, last = receiver_block(wp.tid(), take, lit.shape[0])
    while k < last:
        k += 1
        if lit[k] != 1.0:
            continue
        g = grid_point(start[k], grid.origin, grid.inv_side)
        wp.atomic_add(count, grid_cell(g[1], grid.ny) * grid.nx + grid_cell(g[0], grid.nx), 1)


@wp.kernel
def sub_grid_kernel(
    count: wp.array2d(dtype=wp.int32),
    rays_per_cell: wp.float64,
    sub: wp.array(dtype=wp.int32),
    cells: wp.array(dtype=wp.int32),
):
    """Each coarse cell split ``sub × sub`` ways, ``rays_per_cell`` rays per sub-cell were they spread evenly.

    ``count[k, c]``: the rays of coarse cell ``c`` that the ``k``-th launch over the receivers binned.
    """
    c = wp.tid()
    n = int(0)
    for k in range(count.shape[0]):
        n += count[k, c]
    s = 0
    if n > 0:
        s = int(wp.ceil(wp.sqrt(wp.float64(n) / rays_per_cell)))
    sub[c] = s
    cells[c] = s * s


@wp.kernel
def ray_table_rows_kernel(
    count: wp.array2d(dtype=wp.int32),
    nx: int,
    table: wp.array(dtype=wp.int32),
):
    """Row ``r + 1`` of the coarse cells' summed-area table (``(ny + 1) × (nx + 1)``, row-major): the
    rays of coarse cells ``(r, 0..c − 1)`` at column ``c``; the columns' sums follow
    (:func:`ray_table_columns_kernel`).

    ``count[k, c]``: the rays of coarse cell ``c`` that the ``k``-th launch over the receivers binned.
    """
    r = wp.tid()
    w = nx + 1
    total = int(0)
    table[(r + 1) * w] = 0
    for c in range(nx):
        for k in range(count.shape[0]):
            total += count[k, r * nx + c]
        table[(r + 1) * w + c + 1] = total


@wp.kernel
def ray_table_columns_kernel(
    ny: int,
    nx: int,
    table: wp.array(dtype=wp.int32),
):
    """Column ``c`` of the summed-area table summed down its rows: then ``table[r·(nx + 1) + c]`` holds the
    rays of the coarse cells of rows below ``r`` and columns below ``c``."""
    c = wp.tid()
    w = nx + 1
    table[c] = 0
    for r in range(1, ny + 1):
        table[r * w + c] += table[(r - 1) * w + c]


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


@wp.kernel
def fine_bin_kernel(
    start: wp.array(dtype=wp.vec3d),
    lit: wp.array(dtype=wp.float32),
    grid: RayGrid,
    sub: wp.array(dtype=wp.int32),
    offset: wp.array(dtype=wp.int32),
    take: ReceiverBlocks,
    fine: wp.array(dtype=wp.int32),
    slot: wp.array(dtype=wp.int32),
    count: wp.array(dtype=wp.int32),
):
    """Each ray's sub-cell (row-major within its coarse cell) and its slot there (counting sort, first pass), of
    the receivers of :func:`receiver_block`."""
    k, last = receiver_block(wp.tid(), take, lit.shape[0])
    while k < last:
        k += 1
        if lit[k] != 1.0:
            continue
        g = grid_point(start[k], grid.origin, grid.inv_side)
        col = grid_cell(g[0], grid.nx)
        row = grid_cell(g[1], grid.ny)
        c = row * grid.nx + col
        n = sub[c]
        f = offset[c] + sub_cell(g[1], row, n) * n + sub_cell(g[0], col, n)
        fine[k] = f
        slot[k] = wp.atomic_add(count, f, 1)


@wp.kernel
def scatter_kernel(
    start: wp.array(dtype=wp.vec3d),
    lit: wp.array(dtype=wp.float32),
    fine: wp.array(dtype=wp.int32),
    slot: wp.array(dtype=wp.int32),
    first: wp.array(dtype=wp.int32),
    take: ReceiverBlocks,
    sorted_start: wp.array(dtype=wp.vec3d),
    sorted_ray: wp.array(dtype=wp.int32),
):
    """Rays in sub-cell order (counting sort, second pass), of the receivers of :func:`receiver_block`."""
    k, last = receiver_block(wp.tid(), take, lit.shape[0])
    while k < last:
        k += 1
        if lit[k] != 1.0:
            continue
        j = first[fine[k]] + slot[k]
        sorted_start[j] = start[k]
        sorted_ray[j] = k


@wp.kernel
def launch_first_kernel(
    count: wp.array2d(dtype=wp.int32),
    first: wp.array2d(dtype=wp.int32),
):
    """``first[k, f]``: the rays of every fine cell before ``f`` and of launches ``0..k − 1`` in ``f``
    (``count[k, f]``: launch ``k``'s rays in ``f``), by one thread in one pass — for a CPU split into
    more than one launch.
    """
    total = int(0)
    # `while` loops: see block_triangle.
    f = int(0)
    while f < count.shape[1]:
        k = int(0)
        while k < count.shape[0]:
            first[k, f] = total
            total += count[k, f]
            k += 1
        f += 1


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
    if not wp.isnan(du_dv):
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


def _receiver_blocks(block: int, phase: int, stride: int) -> ReceiverBlocks:
    """The :class:`ReceiverBlocks` of a launch."""
    take = ReceiverBlocks()
    take.block = block
    take.phase = phase
    take.stride = stride
    return take


def _receivers(points, normals, light_direction) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``points`` (float64) and ``normals`` (float32) as contiguous ``(N, 3)`` arrays, and the light basis."""
    p = np.asarray(points, dtype=np.float64)
    n = np.asarray(normals, dtype=np.float32)
    if p.shape[-1:] != (3,) or n.shape != p.shape:
        raise ValueError(f"points, normals: expected two arrays of shape (..., 3), got {p.shape} and {n.shape}")
    d = np.asarray(light_direction, dtype=np.float64)
    if d.shape != (3,) or not np.all(np.isfinite(d)) or np.linalg.norm(d) == 0.0:
        raise ValueError(f"light_direction: expected a finite non-zero vector (3,), got {light_direction!r}")
    return np.ascontiguousarray(p.reshape(-1, 3)), np.ascontiguousarray(n.reshape(-1, 3)), light_basis(d)


def hard_shadow_ray(bvh: MeshBVH, *, points, normals, light_direction, threads: int = 1) -> np.ndarray:
    """The hard shadow by one float32 any-hit ray per point through the BVH (arguments of :func:`hard_shadow`).

    With ``threads`` > 1 on the CPU, each thread casts the rays of one range of points.
    """
    p, n, basis = _receivers(points, normals, light_direction)
    shape = np.shape(points)[:-1]
    device = bvh.device
    threads = checked_threads(threads, device)
    valid = np.all(np.isfinite(p), axis=1)
    out = np.full(p.shape[0], np.nan, dtype=np.float32)
    if np.any(valid):
        start = wp.array(np.ascontiguousarray(p[valid] - bvh.anchor), dtype=wp.vec3d, device=device, copy=False)
        normal = wp.array(np.ascontiguousarray(n[valid]), dtype=wp.vec3, device=device, copy=False)
        lit = wp.empty(start.shape[0], dtype=wp.float32, device=device)
        inputs = (wp.vec3d(*-basis[2]), RAY_OFFSET * max(bvh.diagonal, 1e-9),
                  float(RAY_LENGTH * max(bvh.diagonal, 1e-9)))
        kernel, masks = hard_shadow_kernel, ()
        if bvh.masked:
            kernel = hard_shadow_masked_kernel
            masks = (bvh.triangles, bvh.masks.uv, bvh.masks.vertex_mask, bvh.masks.textures)
        with LaunchPool(threads, kernels=(kernel,), device=device) as pool:
            pool.run([functools.partial(wp.launch, kernel, dim=hi - lo,
                                        inputs=(bvh.mesh.id, start[lo:hi], normal[lo:hi], *inputs, *masks),
                                        outputs=(lit[lo:hi],), device=device)
                      for lo, hi in split_range(start.shape[0], threads)])
        out[valid] = lit.numpy()
    return out.reshape(shape)


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

    Arguments of :func:`hard_shadow`. The grid spans the ray starts' light-space rectangle with
    square cells of :data:`RAYS_PER_CELL` starts on average.

    Notes
    -----
    The triangles are tested by chunks of :data:`CHUNK`: a chunk, then a triangle, whose light-space
    rectangle lies beside the starts' or reaches only coarse cells without rays (a summed-area
    table of the coarse cells' rays says so in four reads) is passed before any vertex is gathered.

    Split over ``threads`` concurrent CPU launches (:mod:`csmlab.kernels.threads`): the ray starts,
    their coarse and fine bins and their scatter by blocks of :data:`RECEIVER_BLOCK` receivers
    (launch ``k`` takes blocks ``k, k + threads, …``), each launch with its own bounds and per-cell
    counters (a cell's rays are placed launch after launch); the chunks of triangles interleaved
    the same way. A blocked ray's flag is written to 0 by every triangle that blocks it, whichever
    launch it is in. Every ``threads`` gives the same flags, bit for bit: the tests of a ray and a
    triangle do not depend on the grid, nor on the order of the rays in it.
    """
    p, n, basis = _receivers(points, normals, light_direction)
    shape = np.shape(points)[:-1]
    device = bvh.device
    threads = checked_threads(threads, device)
    count = p.shape[0]
    lit = wp.empty(count, dtype=wp.float32, device=device)
    if count == 0:
        return lit.numpy().reshape(shape)
    diagonal = max(bvh.diagonal, 1e-9)
    # Blocks of receivers, one per kernel thread on the CPU (one receiver each on CUDA), launch k of
    # `parts` taking blocks k, k + parts, …: the sky and the ground of an image share out evenly.
    block = RECEIVER_BLOCK if wp.get_device(device).is_cpu else 1
    blocks = -(-count // block)
    parts = len(split_range(blocks, threads))
    receivers = [(len(range(k, blocks, parts)), _receiver_blocks(block, k, parts)) for k in range(parts)]
    kernels = (ray_start_kernel, light_space_kernel, block_kernel)
    with LaunchPool(threads, kernels=kernels, device=device) as pool:
        light, box, chunk_box = _scene_in_light_space(bvh, basis, pool)
        axes = tuple(wp.vec3d(*row) for row in basis)
        start = wp.empty(count, dtype=wp.vec3d, device=device)
        # A row of bounds per launch, 128 bytes apart: every block of receivers updates its launch's
        # row, and two cores writing to one cache line would pass it back and forth.
        bounds = np.zeros((parts, 16))
        bounds[:, :5] = [np.inf, np.inf, -np.inf, -np.inf, -np.inf]
        bounds = wp.array(bounds, dtype=wp.float64, device=device)
        # On the CPU the kernel reads the NumPy arrays in place.
        copy = not wp.get_device(device).is_cpu
        points_in = wp.array(p, dtype=wp.vec3d, device=device, copy=copy)
        normals_in = wp.array(n, dtype=wp.vec3, device=device, copy=copy)
        pool.run([functools.partial(wp.launch, ray_start_kernel, dim=dim,
                                    inputs=(points_in, normals_in, wp.vec3d(*bvh.anchor), *axes, RAY_OFFSET * diagonal,
                                            take),
                                    outputs=(start, lit, bounds[k]), device=device)
                  for k, (dim, take) in enumerate(receivers)])
        each = bounds.numpy()[:, :5]
        x0, y0 = each[:, :2].min(axis=0)
        x1, y1, z1 = each[:, 2:].max(axis=0)
        if not x0 <= x1:
            return lit.numpy().reshape(shape)
        bounds = wp.array([x0, y0, x1, y1, z1], dtype=wp.float64, device=device)
        # Square coarse cells, COARSE_RAYS_PER_CELL starts each were the starts spread evenly over
        # their rectangle (no more along a side than there are rays: a thin rectangle); each then split
        # for RAYS_PER_CELL starts per sub-cell, wherever the starts crowd.
        width, height = max(x1 - x0, 1e-12 * diagonal), max(y1 - y0, 1e-12 * diagonal)
        side = max(math.sqrt(width * height * COARSE_RAYS_PER_CELL / count), max(width, height) / count)
        nx, ny = math.ceil(width / side), math.ceil(height / side)
        grid = RayGrid()
        grid.origin = wp.vec2d(x0, y0)
        grid.inv_side = 1.0 / side
        grid.nx = nx
        grid.ny = ny
        per_coarse = wp.zeros((parts, nx * ny), dtype=wp.int32, device=device)
        pool.run([functools.partial(wp.launch, coarse_bin_kernel, dim=dim, inputs=(start, lit, grid, take),
                                    outputs=(per_coarse[k],), device=device)
                  for k, (dim, take) in enumerate(receivers)])
        sub = wp.empty(nx * ny, dtype=wp.int32, device=device)
        cells = wp.zeros(nx * ny + 1, dtype=wp.int32, device=device)
        wp.launch(sub_grid_kernel, dim=nx * ny, inputs=(per_coarse, RAYS_PER_CELL), outputs=(sub, cells),
                  device=device)
        table = wp.empty((nx + 1) * (ny + 1), dtype=wp.int32, device=device)
        wp.launch(ray_table_rows_kernel, dim=ny, inputs=(per_coarse, nx), outputs=(table,), device=device)
        wp.launch(ray_table_columns_kernel, dim=nx + 1, inputs=(ny, nx), outputs=(table,), device=device)
        offset = wp.empty_like(cells)
        wp.utils.array_scan(cells, offset, inclusive=False)
        fine_cells = int(offset.numpy()[-1])
        fine = wp.empty(count, dtype=wp.int32, device=device)
        slot = wp.empty(count, dtype=wp.int32, device=device)
        # Rays per launch over the receivers and fine cell, a contiguous row per launch (kernels
        # indexing a strided column of a cell-major table ran several times slower).
        per_fine = wp.zeros((parts, fine_cells + 1), dtype=wp.int32, device=device)
        pool.run([functools.partial(wp.launch, fine_bin_kernel, dim=dim,
                                    inputs=(start, lit, grid, sub, offset, take),
                                    outputs=(fine, slot, per_fine[k]), device=device)
                  for k, (dim, take) in enumerate(receivers)])
        # first_each[k, f]: where launch k's rays of fine cell f go — after every ray of the earlier
        # cells (row 0: the exclusive scan of the cells' totals) and the earlier launches' rays of f.
        first_each = wp.empty_like(per_fine)
        if parts == 1:
            wp.utils.array_scan(per_fine[0], first_each[0], inclusive=False)
        else:
            # A serial pass over the cells (tens of thousands) costs less than the launches of a sum
            # over the launches and a scan.
            wp.launch(launch_first_kernel, dim=1, inputs=(per_fine,), outputs=(first_each,), device=device)
        rays = int(first_each.numpy()[0, -1])
        sorted_start = wp.empty(rays, dtype=wp.vec3d, device=device)
        sorted_ray = wp.empty(rays, dtype=wp.int32, device=device)
        pool.run([functools.partial(wp.launch, scatter_kernel, dim=dim,
                                    inputs=(start, lit, fine, slot, first_each[k], take),
                                    outputs=(sorted_start, sorted_ray), device=device)
                  for k, (dim, take) in enumerate(receivers)])
        rays = BinnedRays()
        rays.grid = grid
        rays.sub = sub
        rays.offset = offset
        rays.first = first_each[0]  # The first ray of each fine cell (and the total after the last).
        rays.table = table
        rays.bounds = bounds
        rays.start = sorted_start
        rays.ray = sorted_ray
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


REFERENCE_METHODS = {"irregular": hard_shadow_irregular, "ray": hard_shadow_ray}
"""Methods of the hard shadow by name: the irregular z-buffer (float64, the default) and the BVH ray cast (float32)."""


def hard_shadow(bvh: MeshBVH, *, points, normals, light_direction, method: str = "irregular",
                threads: int = 1) -> np.ndarray:
    """Ray-traced hard shadow R at receiver points: 1 lit, 0 shadowed, NaN where no point.

    Parameters
    ----------
    bvh : MeshBVH
        The scene, on the device the kernels run on.
    points : array_like, shape (..., 3), float64
        World positions in metres; rows with a NaN are not receivers.
    normals : array_like, shape (..., 3), float32
        Unit normals of the receivers (facing the camera).
    light_direction : array_like, shape (3,)
        From the light toward the scene; normalised here.
    method : str
        A key of :data:`REFERENCE_METHODS`: ``"irregular"`` (float64, the faster) or ``"ray"``
        (BVH rays in float32).
    threads : int
        Concurrent CPU launches (:mod:`csmlab.kernels.threads`), each writing its own part of the
        outputs; the result is the same, bit for bit, for every value. Ignored on CUDA.

    Returns
    -------
    ndarray, shape (...), float32

    Raises
    ------
    ValueError
        On an unknown method, mis-shaped points or normals, a zero or non-finite light direction, or
        ``threads`` not an integer ≥ 1.
    """
    return REFERENCE_METHODS[check_name(method, REFERENCE_METHODS, field="method")](
        bvh, points=points, normals=normals, light_direction=light_direction, threads=threads)
