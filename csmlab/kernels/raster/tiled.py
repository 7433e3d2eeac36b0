"""The depth raster as GPUs rasterize: triangles binned to screen tiles, a thread per texel of a tile.

The same maps and counts as :func:`csmlab.kernels.raster.schedule.rasterize_cascades`, bit for bit:
each texel tests its tile's triangles with the walk's own ``@wp.func`` helpers (the doubled fixed
point, the edge functions and their top-left rule, the caster offset, the alpha test) and keeps the
nearest depth, rounded as the walk rounds it. Four passes, each a plain launch that runs on the CPU
and on CUDA alike:

1. **set-up** (:func:`set_up_triangles_kernel`): a thread per (region, triangle) pair of the chunks
   to rasterize converts the triangle's vertices, turns it counter-clockwise, pushes its depths by
   the caster offset, clamps its bounding box of texel centres to the region and counts the tiles
   that box meets (0 for a triangle that covers no centre of the region);
2. **prefix sum** of those counts (``wp.utils.array_scan``): each pair's first slot in the bin list;
3. **binning** (:func:`binned_triangles_kernel`): each pair writes (tile, pair) into its slots; a
   stable radix sort by tile (``wp.utils.radix_sort_pairs``) leaves every tile's pairs together, in
   the order the walk takes them, and :func:`tile_ranges_kernel` finds where each tile's list lies;
4. **raster** (:func:`rasterize_tiles_kernel`): a thread per texel of a tile, :data:`TILE_TEXELS` of
   them in one thread block, walks its tile's list. Every thread of a block reads the same
   triangle at the same step (one load served to all), keeps its nearest depth in a register and
   writes its texel once: no atomic on the map.

A triangle takes the same test at every texel: the edge functions evaluated afresh at the centre
(:func:`~csmlab.kernels.raster.kernels.edge_values`), decided by
:func:`~csmlab.kernels.raster.kernels.edge_inside`, within the triangle's box of centres. Below
:data:`~csmlab.kernels.raster.kernels.STEPPED_EXTENT` they are the exact integers the walk steps
through, and above it the rounded values its large-triangle path evaluates in the same order, so
every path of the walk gives the same verdicts. Ties between triangles at equal depth keep the
first in the walk's order (chunks by region, then triangles in order), so even the sign of a zero
depth is the walk's.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from csmlab.kernels import checked_device
from csmlab.kernels.alpha import AlphaTextures, alpha_passes
from csmlab.kernels.raster.kernels import (Boxes, CasterOffset, FixedPoint, caster_offset, centre_box, doubled_area,
                                           doubled_fixed_point_vertex, edge_inside, edge_owns_centre, edge_values,
                                           vec2l)
from csmlab.kernels.raster.mesh import CHUNK_BITS, LightSpaceMesh
from csmlab.kernels.raster.schedule import (_boxes, _caster_offset, _checked_bits, _checked_boxes, _checked_mesh,
                                            _checked_regions, _checked_resolution, _fixed_point, light_mesh)
from csmlab.kernels.threads import LaunchPool, checked_threads, split_range

__all__ = ["TILE_BITS", "TILE_TEXELS", "rasterize_tiled"]

# Products and sums rounded one by one on both devices, as in csmlab.kernels.raster.kernels: the
# helpers imported from there are compiled into this module, with this module's options.
wp.set_module_options({"fuse_fp": False})

TILE_BITS = 4
"""``log2`` of a tile's side in texels: tiles of 16 × 16 texels.

Why this value: a tile's 256 texels are one thread block of Warp's default size, each block's
threads walk one list together, and a triangle of the near cascades (a few texels to a few tens
across) meets one to four tiles, so binning copies it few times. Any side gives the same maps.
"""

TILE_TEXELS = 1 << (2 * TILE_BITS)
"""Texels (threads) per tile: one thread block."""


@wp.struct
class SetUpTriangle:
    """A (region, triangle) pair after set-up: what every texel of its tiles reads."""

    a: vec2l
    """First vertex, doubled fixed point of the region's cascade."""
    b: vec2l
    """Second vertex, counter-clockwise from ``a``."""
    c: vec2l
    """Third vertex."""
    depth: wp.vec3d
    """Depths of ``a, b, c`` pushed away from the light by the caster offset, metres."""
    area: wp.float64
    """Twice the area in doubled units squared (the edge functions' sum), > 0."""
    window: wp.vec4i
    """Texel columns ``i0..i1`` and rows ``j0..j1`` (inclusive) of the centres in its box and region."""
    vertices: wp.vec3i
    """Mesh indices of ``a, b, c`` (their texture coordinates)."""
    mask: wp.int32
    """Alpha mask of the triangle, −1 opaque."""


@wp.struct
class TileGrid:
    """The tiles every region is cut into, row by row, regions one after another."""

    regions: wp.array2d(dtype=wp.int32)
    """Rows ``(c, i0, i1, j0, j1)`` of the regions."""
    first_tile: wp.array(dtype=wp.int32)
    """Each region's first tile."""
    columns: wp.array(dtype=wp.int32)
    """Tiles per row of each region."""
    tile_region: wp.array(dtype=wp.int32)
    """Each tile's region."""


@wp.struct
class TiledMesh:
    """The mesh as the set-up pass reads it: light-plane vertices, depths, triangles and masks."""

    xy: wp.array(dtype=wp.vec2d)
    depth: wp.array(dtype=wp.float64)
    triangles: wp.array2d(dtype=wp.int32)
    vertex_mask: wp.array(dtype=wp.int32)
    """Each vertex's alpha mask, −1 opaque (zero-length: every triangle opaque)."""


@wp.kernel
def set_up_triangles_kernel(
    mesh: TiledMesh,
    boxes: Boxes,
    grid: TileGrid,
    chunks: wp.array2d(dtype=wp.int32),
    fixed: FixedPoint,
    offset: CasterOffset,
    set_up: wp.array(dtype=SetUpTriangle),
    tiles: wp.array(dtype=wp.int32),
):
    """``tiles[p]``: the tiles pair p's box of centres meets (0: it covers none); ``set_up[p]`` where any.

    Pair p is triangle ``p mod 2**CHUNK_BITS`` of the chunk of row ``p >> CHUNK_BITS`` of ``chunks``
    (region, chunk); past the last triangle, none.
    """
    p = wp.tid()
    row = p >> CHUNK_BITS
    t = (chunks[row, 1] << CHUNK_BITS) + (p & ((1 << CHUNK_BITS) - 1))
    tiles[p] = 0
    if t >= mesh.triangles.shape[0]:
        return
    g = chunks[row, 0]
    c = grid.regions[g, 0]
    region = wp.vec4i(grid.regions[g, 1], grid.regions[g, 2], grid.regions[g, 3], grid.regions[g, 4])
    step = boxes.texel_size[c] / fixed.scale
    corner = boxes.origin_fixed[c]
    ia = mesh.triangles[t, 0]
    ib = mesh.triangles[t, 1]
    ic = mesh.triangles[t, 2]
    a = doubled_fixed_point_vertex(mesh.xy[ia], step, fixed.limit, corner)
    b = doubled_fixed_point_vertex(mesh.xy[ib], step, fixed.limit, corner)
    q = doubled_fixed_point_vertex(mesh.xy[ic], step, fixed.limit, corner)
    unit = fixed.unit
    i0, i1, j0, j1 = centre_box(a[0], a[1], b[0], b[1], q[0], q[1], fixed, region)
    if i0 > i1 or j0 > j1:
        return
    area = doubled_area(a[0], a[1], b[0], b[1], q[0], q[1])
    if area == wp.float64(0.0):
        return
    za = mesh.depth[ia]
    zb = mesh.depth[ib]
    zc = mesh.depth[ic]
    # Pushed before the triangle is turned, as the walk's kernels push it.
    push = caster_offset(offset, c, a[0], a[1], b[0], b[1], q[0], q[1], za, zb, zc, unit)
    m = int(-1)
    if mesh.vertex_mask.shape[0] > 0:
        m = mesh.vertex_mask[ia]
    out = SetUpTriangle()
    out.a = a
    out.mask = m
    out.window = wp.vec4i(i0, i1, j0, j1)
    if area > wp.float64(0.0):
        out.b = b
        out.c = q
        out.depth = wp.vec3d(za + push, zb + push, zc + push)
        out.vertices = wp.vec3i(ia, ib, ic)
        out.area = area
    else:
        # Counter-clockwise, as rasterize_triangle turns it: one top-left rule serves both windings.
        out.b = q
        out.c = b
        out.depth = wp.vec3d(za + push, zc + push, zb + push)
        out.vertices = wp.vec3i(ia, ic, ib)
        out.area = -area
    set_up[p] = out
    tiles[p] = (((i1 - region[0]) >> TILE_BITS) - ((i0 - region[0]) >> TILE_BITS) + 1) * (
        ((j1 - region[2]) >> TILE_BITS) - ((j0 - region[2]) >> TILE_BITS) + 1)


@wp.kernel
def binned_triangles_kernel(
    set_up: wp.array(dtype=SetUpTriangle),
    grid: TileGrid,
    chunks: wp.array2d(dtype=wp.int32),
    tiles: wp.array(dtype=wp.int32),
    first_slot: wp.array(dtype=wp.int32),
    tile_of_slot: wp.array(dtype=wp.int32),
    pair_of_slot: wp.array(dtype=wp.int32),
):
    """Pair p writes (tile, p) into its slots ``first_slot[p] …``, one per tile its box meets, row by row."""
    p = wp.tid()
    if tiles[p] == 0:
        return
    g = chunks[p >> CHUNK_BITS, 0]
    window = set_up[p].window
    i0 = grid.regions[g, 1]
    j0 = grid.regions[g, 3]
    columns = grid.columns[g]
    slot = first_slot[p]
    ty = (window[2] - j0) >> TILE_BITS
    while ty <= (window[3] - j0) >> TILE_BITS:
        tx = (window[0] - i0) >> TILE_BITS
        while tx <= (window[1] - i0) >> TILE_BITS:
            tile_of_slot[slot] = grid.first_tile[g] + ty * columns + tx
            pair_of_slot[slot] = p
            slot += 1
            tx += 1
        ty += 1


@wp.kernel
def tile_ranges_kernel(tile_of_slot: wp.array(dtype=wp.int32), count: int, first: wp.array(dtype=wp.int32),
                       end: wp.array(dtype=wp.int32)):
    """``[first[t], end[t])``: the slots of tile t in the list sorted by tile (both left 0 for a tile without any)."""
    k = wp.tid()
    tile = tile_of_slot[k]
    if k == 0 or tile_of_slot[k - 1] != tile:
        first[tile] = k
    if k == count - 1 or tile_of_slot[k + 1] != tile:
        end[tile] = k + 1


@wp.kernel
def rasterize_tiles_kernel(
    set_up: wp.array(dtype=SetUpTriangle),
    pair_of_slot: wp.array(dtype=wp.int32),
    first: wp.array(dtype=wp.int32),
    end: wp.array(dtype=wp.int32),
    grid: TileGrid,
    first_launched: int,
    uv: wp.array(dtype=wp.vec2d),
    textures: AlphaTextures,
    fixed: FixedPoint,
    depth: wp.array3d(dtype=wp.float32),
    covered: wp.array(dtype=wp.int64),
):
    """A thread per texel of tiles ``first_launched …``: its nearest depth written (+inf where no triangle covers it),
    its coverage tests passed added to ``covered[tile]``.

    ``depth`` zero-length: counting alone.
    """
    k = wp.tid()
    tile = first_launched + (k >> (2 * TILE_BITS))
    lane = k & (TILE_TEXELS - 1)
    g = grid.tile_region[tile]
    index = tile - grid.first_tile[g]
    columns = grid.columns[g]
    i = grid.regions[g, 1] + ((index % columns) << TILE_BITS) + (lane & ((1 << TILE_BITS) - 1))
    j = grid.regions[g, 3] + ((index // columns) << TILE_BITS) + (lane >> TILE_BITS)
    if i >= grid.regions[g, 2] or j >= grid.regions[g, 4]:
        return
    two = wp.int64(2)
    px = (two * wp.int64(i) + wp.int64(1)) * fixed.unit
    py = (two * wp.int64(j) + wp.int64(1)) * fixed.unit
    nearest = wp.float32(wp.inf)
    count = int(0)
    slot = first[tile]
    while slot < end[tile]:
        tri = set_up[pair_of_slot[slot]]
        slot += 1
        window = tri.window
        if i < window[0] or i > window[1] or j < window[2] or j > window[3]:
            continue
        a = tri.a
        b = tri.b
        q = tri.c
        w_c, w_a, w_b = edge_values(px, a[0], a[1], b[0], b[1], q[0], q[1],
                                    wp.float64(b[0] - a[0]) * wp.float64(py - a[1]),
                                    wp.float64(q[0] - b[0]) * wp.float64(py - b[1]),
                                    wp.float64(a[0] - q[0]) * wp.float64(py - q[1]))
        if not (edge_inside(w_c, edge_owns_centre(b[0] - a[0], b[1] - a[1]))
                and edge_inside(w_a, edge_owns_centre(q[0] - b[0], q[1] - b[1]))
                and edge_inside(w_b, edge_owns_centre(a[0] - q[0], a[1] - q[1]))):
            continue
        count += 1
        area = tri.area
        if tri.mask >= 0:
            v = tri.vertices
            at = (w_a * uv[v[0]] + w_b * uv[v[1]] + w_c * uv[v[2]]) / area
            if not alpha_passes(textures, tri.mask, at[0], at[1]):
                continue
        z = tri.depth
        held = wp.float32((w_a * z[0] + w_b * z[1] + w_c * z[2]) / area)
        if held < nearest:
            nearest = held
    if depth.shape[0] > 0:
        depth[grid.regions[g, 0], j, i] = nearest
    if count > 0:
        wp.atomic_add(covered, tile, wp.int64(count))


def _tile_grid(areas: np.ndarray, device: str) -> tuple[TileGrid, np.ndarray]:
    """The :class:`TileGrid` of regions ``(G, 5)`` on ``device`` and each tile's region ``(N,)`` (host)."""
    side = 1 << TILE_BITS
    columns = (areas[:, 2] - areas[:, 1] + side - 1) >> TILE_BITS
    rows = (areas[:, 4] - areas[:, 3] + side - 1) >> TILE_BITS
    counts = (columns * rows).astype(np.int64)
    tile_region = np.repeat(np.arange(areas.shape[0], dtype=np.int32), counts)
    grid = TileGrid()
    grid.regions = wp.array(areas, dtype=wp.int32, device=device)
    grid.first_tile = wp.array(np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int32), dtype=wp.int32,
                               device=device)
    grid.columns = wp.array(np.maximum(columns, 1).astype(np.int32), dtype=wp.int32, device=device)
    grid.tile_region = wp.array(tile_region, dtype=wp.int32, device=device)
    return grid, tile_region


def rasterize_tiled(mesh: LightSpaceMesh, *, texel_size, origin, resolution: int, bits: int, regions=None,
                    chunks=None, depth=None, count_only: bool = False, threads: int = 1, caster_constant=None,
                    caster_slope: float = 0.0, device: str = "cpu") -> tuple[np.ndarray | None, np.ndarray]:
    """:func:`~csmlab.kernels.raster.schedule.rasterize_cascades`'s maps and counts, bit for bit, rasterized by tiles.

    Parameters and returns as :func:`~csmlab.kernels.raster.schedule.rasterize_cascades` (which
    also takes ``paths``: every path of its walk gives these maps). ``threads``: on the CPU the
    raster pass's tiles are cut into that many ranges launched at once (disjoint texels); ignored
    on CUDA, where each tile is a thread block.

    Returns
    -------
    depth : ndarray, shape (C, R, R), float32, or None
        Every texel of the regions rasterized afresh (+inf where no triangle covers it), the others
        as ``depth`` held them; None with ``count_only``.
    texels_rasterized : ndarray, shape (G,), int64
        Coverage tests passed in each region.

    Raises
    ------
    ValueError
        On the inputs :func:`~csmlab.kernels.raster.schedule.rasterize_cascades` refuses.
    """
    device = checked_device(device)
    _checked_mesh(mesh)
    size, origin_fixed = _checked_boxes(texel_size, origin)
    bits = _checked_bits(bits)
    resolution = _checked_resolution(resolution)
    shape = (size.shape[0], resolution, resolution)
    areas, rows = _checked_regions(regions, chunks, shape, triangles=mesh.triangles.shape[0])
    if count_only:
        maps = wp.zeros((0, 0, 0), dtype=wp.float32, device=device)
    elif depth is None:
        maps = wp.full(shape, value=np.inf, dtype=wp.float32, device=device)
    elif depth.shape != shape or depth.dtype != np.float32 or not depth.flags.c_contiguous:
        raise ValueError(f"depth: expected C-contiguous float32 maps of shape {shape}, got {depth.dtype} {depth.shape}")
    else:
        maps = wp.array(depth, dtype=wp.float32, device=device, copy=False)
    # The walk's order (by region, chunks as given): the first of equal depths is kept, as the walk keeps it.
    rows = rows[np.argsort(rows[:, 0], kind="stable")]
    grid, tile_region = _tile_grid(areas, device)
    tile_count = tile_region.size
    covered = wp.zeros(tile_count, dtype=wp.int64, device=device)
    if tile_count:
        _rasterize_tiles(mesh, grid, tile_count, rows, size, origin_fixed, bits, caster_constant, caster_slope,
                         maps, covered, checked_threads(threads, device), device)
    per_region = np.bincount(tile_region, weights=covered.numpy(), minlength=areas.shape[0])
    return None if count_only else maps.numpy(), per_region.astype(np.int64)


def _rasterize_tiles(mesh: LightSpaceMesh, grid: TileGrid, tile_count: int, rows: np.ndarray, size: np.ndarray,
                     origin_fixed: np.ndarray, bits: int, caster_constant, caster_slope: float, maps: wp.array,
                     covered: wp.array, threads: int, device: str) -> None:
    """The four passes of the module's docstring over the pairs of ``rows`` into ``maps`` and ``covered`` (per tile)."""
    # The mesh's device arrays and masks as the walk keeps them with the mesh (made once per device).
    kept = light_mesh(mesh, device)
    light = TiledMesh()
    light.xy = kept.xy
    light.depth = kept.depth
    light.triangles = kept.triangles
    light.vertex_mask = kept.vertex_mask
    fixed = _fixed_point(bits)
    pairs = rows.shape[0] << CHUNK_BITS
    set_up = wp.empty(pairs, dtype=SetUpTriangle, device=device)
    tiles = wp.empty(pairs, dtype=wp.int32, device=device)
    chunks = wp.array(rows.reshape(-1, 2), dtype=wp.int32, device=device)
    first = wp.zeros(tile_count, dtype=wp.int32, device=device)
    end = wp.zeros(tile_count, dtype=wp.int32, device=device)
    slots = 0
    if pairs:
        wp.launch(set_up_triangles_kernel, dim=pairs,
                  inputs=(light, _boxes(device, size, origin_fixed), grid, chunks, fixed,
                          _caster_offset(caster_constant, caster_slope, size.shape[0], device)),
                  outputs=(set_up, tiles), device=device)
        first_slot = wp.empty(pairs, dtype=wp.int32, device=device)
        wp.utils.array_scan(tiles, first_slot, inclusive=False)
        slots = int(first_slot[pairs - 1:].numpy()[0]) + int(tiles[pairs - 1:].numpy()[0])
    # The radix sort takes twice the slots: its second half is its scratch.
    tile_of_slot = wp.empty(max(2 * slots, 2), dtype=wp.int32, device=device)
    pair_of_slot = wp.empty(max(2 * slots, 2), dtype=wp.int32, device=device)
    if slots:
        wp.launch(binned_triangles_kernel, dim=pairs, inputs=(set_up, grid, chunks, tiles, first_slot),
                  outputs=(tile_of_slot, pair_of_slot), device=device)
        wp.utils.radix_sort_pairs(tile_of_slot, pair_of_slot, slots)
        wp.launch(tile_ranges_kernel, dim=slots, inputs=(tile_of_slot, slots), outputs=(first, end), device=device)
    inputs = (set_up, pair_of_slot, first, end, grid)
    with LaunchPool(threads, kernels=(rasterize_tiles_kernel,), device=device) as pool:
        def launch(lo: int, hi: int) -> None:
            wp.launch(rasterize_tiles_kernel, dim=(hi - lo) * TILE_TEXELS,
                      inputs=(*inputs, lo, kept.uv, kept.textures, fixed), outputs=(maps, covered),
                      block_dim=TILE_TEXELS, device=device)

        pool.run([lambda lo=lo, hi=hi: launch(lo, hi) for lo, hi in split_range(tile_count, threads)])
