"""The irregular z-buffer's rays: every receiver's ray start in light space, binned into a uniform grid
over the starts' rectangle (a counting sort), that the blocking triangles read
(:mod:`csmlab.kernels.reference.irregular`).

The grid has square coarse cells of :data:`COARSE_RAYS_PER_CELL` starts were they spread evenly,
each split ``sub × sub`` ways for :data:`RAYS_PER_CELL` starts per fine cell wherever the starts
crowd; a summed-area table of the coarse cells' rays lets a triangle's rectangle ask in four reads
whether it reaches any.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import warp as wp

from csmlab.kernels.floats import is_finite
from csmlab.kernels.threads import LaunchPool, split_range

__all__ = ["COARSE_RAYS_PER_CELL", "RAYS_PER_CELL", "RECEIVER_BLOCK", "BinnedRays", "RayGrid", "binned_rays",
           "grid_cell", "grid_point", "sub_cell"]

# Products and sums rounded one by one on both devices (clang and NVRTC may otherwise contract them): a
# CUDA build may not contract them into fused multiply-adds, or its bits differ from the CPU's.
wp.set_module_options({"fuse_fp": False})

COARSE_RAYS_PER_CELL = 64.0
"""Mean ray starts per coarse cell of the irregular z-buffer's light-space grid."""


RAYS_PER_CELL = 4.0
"""Ray starts per sub-cell the coarse cells are split for (``benchmarks/bench_peers.py`` measures them)."""


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


@wp.func
def receiver_block(i: int, take: ReceiverBlocks, count: int):
    """Thread ``i``'s receivers, of a launch taking the blocks ``take``: ``(first − 1, last)``, for a `while`
    loop that steps first (see :func:`~csmlab.kernels.reference.irregular.block_triangle`)."""
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
        if not (is_finite(p[0]) and is_finite(p[1]) and is_finite(p[2])):
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


def _receiver_blocks(block: int, phase: int, stride: int) -> ReceiverBlocks:
    """The :class:`ReceiverBlocks` of a launch."""
    take = ReceiverBlocks()
    take.block = block
    take.phase = phase
    take.stride = stride
    return take


def binned_rays(points: np.ndarray, normals: np.ndarray, *, anchor, basis: np.ndarray, start_offset: float,
                diagonal: float, lit: wp.array, pool: LaunchPool) -> BinnedRays | None:
    """Each receiver's ray start in light space, binned into the grid of the starts' rectangle (a counting sort).

    Parameters
    ----------
    points, normals : ndarray, shape (N, 3), float64 and float32
        The receivers (:func:`~csmlab.kernels.reference.shadow_rays.checked_receivers`), world metres.
    anchor : array_like, shape (3,)
        The scene's anchor (:attr:`csmlab.kernels.visibility.MeshBVH.anchor`), world metres.
    basis : ndarray, shape (3, 3)
        The light basis, rows right, up and the light direction d.
    start_offset : float
        Metres the starts are moved along the normals.
    diagonal : float
        The scene's diagonal, metres (the least extent of a grid's side is ``1e-12`` of it).
    lit : wp.array, shape (N,), float32
        Written here: NaN (no point), 0 (turned from the light) or 1 (a ray, to be tested).
    pool : LaunchPool
        The launches: the receivers by blocks of :data:`RECEIVER_BLOCK` (one receiver on CUDA),
        launch k of the pool's taking blocks k, k + threads, … (the sky and the ground of an image
        share out evenly), each with its own bounds and per-cell counters.

    Returns
    -------
    BinnedRays or None
        None where no receiver has a ray.
    """
    device = lit.device
    count = points.shape[0]
    block = RECEIVER_BLOCK if wp.get_device(device).is_cpu else 1
    blocks = -(-count // block)
    parts = len(split_range(blocks, pool.threads))
    receivers = [(len(range(k, blocks, parts)), _receiver_blocks(block, k, parts)) for k in range(parts)]
    axes = tuple(wp.vec3d(*row) for row in basis)
    start = wp.empty(count, dtype=wp.vec3d, device=device)
    # A row of bounds per launch, 128 bytes apart: every block of receivers updates its launch's
    # row, and two cores writing to one cache line would pass it back and forth.
    bounds = np.zeros((parts, 16))
    bounds[:, :5] = [np.inf, np.inf, -np.inf, -np.inf, -np.inf]
    bounds = wp.array(bounds, dtype=wp.float64, device=device)
    # On the CPU the kernel reads the NumPy arrays in place.
    copy = not wp.get_device(device).is_cpu
    points_in = wp.array(points, dtype=wp.vec3d, device=device, copy=copy)
    normals_in = wp.array(normals, dtype=wp.vec3, device=device, copy=copy)
    pool.run([functools.partial(wp.launch, ray_start_kernel, dim=dim,
                                inputs=(points_in, normals_in, wp.vec3d(*anchor), *axes, start_offset, take),
                                outputs=(start, lit, bounds[k]), device=device)
              for k, (dim, take) in enumerate(receivers)])
    each = bounds.numpy()[:, :5]
    x0, y0 = each[:, :2].min(axis=0)
    x1, y1, z1 = each[:, 2:].max(axis=0)
    if not x0 <= x1:
        return None
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
    return rays
