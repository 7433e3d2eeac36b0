"""The depth raster's host side: checks, uploads, and how the launches are scheduled over the threads.

Typed NumPy-in/NumPy-out wrappers of :mod:`csmlab.kernels.raster.kernels`. On the CPU the work of a
call is cut so that concurrent launches write disjoint texels (:mod:`csmlab.kernels.threads`): the
vertex pass by ranges of vertices, the rasterization by regions (:mod:`csmlab.kernels.raster.regions`)
taken in turn, costliest first.
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from csmlab.kernels import checked_device, device_empty
from csmlab.kernels.alpha import MaskedMesh, masked_mesh, no_masks
from csmlab.kernels.raster.kernels import (Boxes, CasterOffset, ChunkRows, FixedPoint, LightMesh, TrianglePaths,
                                           VertexPass, chunk_rectangles_kernel, fixed_point_vertices_kernel,
                                           rasterize_chunks_kernel, rasterize_depth_kernel, triangle_paths, vec2l)
from csmlab.kernels.raster.mesh import CHUNK_BITS, ChunkVertices, LightSpaceMesh, checked_chunk_vertices
from csmlab.kernels.raster.regions import empty_regions, whole_map_regions
from csmlab.kernels.threads import LaunchPool, checked_threads, split_range

__all__ = ["chunks_meeting_regions", "converted_region_chunks", "fixed_point_vertices", "rasterize_cascades",
           "rasterize_depth"]


def _checked_bits(bits) -> int:
    if not (isinstance(bits, (int, np.integer)) and 0 <= bits <= 16):
        raise ValueError(f"bits: expected an integer in 0..16, got {bits!r}")
    return int(bits)


def _checked_resolution(resolution) -> int:
    if not (isinstance(resolution, (int, np.integer)) and 1 <= resolution <= 16384):
        raise ValueError(f"resolution: expected an integer in 1..16384, got {resolution!r}")
    return int(resolution)


def _checked_paths(paths) -> TrianglePaths:
    if paths is None:
        return triangle_paths()
    if not isinstance(paths, TrianglePaths.cls):
        raise ValueError(f"paths: expected a TrianglePaths (triangle_paths) or None, got {type(paths).__name__}")
    return paths


def _checked_mesh(mesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The light-space vertices, depths and triangles of a :class:`LightSpaceMesh`, refused otherwise."""
    if not isinstance(mesh, LightSpaceMesh):
        raise ValueError(f"mesh: expected a LightSpaceMesh (light_space_mesh), got {type(mesh).__name__}")
    return mesh.xy, mesh.depth, mesh.triangles


def _checked_boxes(texel_size, origin) -> tuple[np.ndarray, np.ndarray]:
    """Each cascade's texel size ``(C, 2)`` (metres, float64) and fixed-point origin ``(C, 2)`` (int64)."""
    size = np.ascontiguousarray(texel_size, dtype=np.float64)
    origin_fixed = np.ascontiguousarray(origin, dtype=np.int64)
    if size.ndim != 2 or size.shape[1] != 2 or origin_fixed.shape != size.shape:
        raise ValueError(f"texel_size, origin: expected shapes (C, 2), (C, 2); got {size.shape}, "
                         f"{origin_fixed.shape}")
    return size, origin_fixed


def _checked_regions(regions, chunks, shape: tuple[int, int, int], *, triangles: int) -> tuple[np.ndarray, np.ndarray]:
    """The regions ``(G, 5)`` rows ``(c, i0, i1, j0, j1)`` (int32; None: every whole map) within maps of ``shape``,
    and the ``(region, chunk)`` rows ``(K, 2)`` (int32; None: every chunk of ``triangles`` in every region)."""
    resolution = shape[1]
    areas = np.ascontiguousarray(whole_map_regions([resolution] * shape[0]) if regions is None else regions,
                                 dtype=np.int32)
    if (areas.ndim != 2 or areas.shape[1] != 5 or np.any(areas[:, 0] < 0) or np.any(areas[:, 0] >= shape[0])
            or np.any(areas[:, 1:] < 0) or np.any(areas[:, 1:] > resolution)
            or np.any(areas[:, 2] < areas[:, 1]) or np.any(areas[:, 4] < areas[:, 3])):
        raise ValueError(f"regions: expected rows (c, i0, i1, j0, j1) within {shape}, got shape {areas.shape}")
    count = -(-triangles // (1 << CHUNK_BITS))
    rows = (np.stack(np.meshgrid(np.arange(areas.shape[0]), np.arange(count), indexing="ij"), -1).reshape(-1, 2)
            if chunks is None else np.asarray(chunks)).astype(np.int32)
    if rows.ndim != 2 or rows.shape[1] != 2 or (rows.size and (rows.min() < 0 or rows[:, 0].max() >= areas.shape[0]
                                                               or rows[:, 1].max() >= count)):
        raise ValueError(f"chunks: expected (region, chunk) rows of shape (K, 2) within ({areas.shape[0]}, {count}), "
                         f"got {rows.shape}")
    return areas, rows


def _fixed_point(bits: int) -> FixedPoint:
    """The :class:`FixedPoint` grid of ``bits`` sub-texel bits."""
    fixed = FixedPoint()
    fixed.scale = float(2**bits)
    fixed.limit = _FIXED_LIMIT
    fixed.unit = 2**bits
    fixed.bits = bits
    return fixed


def rasterize_depth(points, vertex_depth, triangles, *, resolution: int, bits: int, paths: TrianglePaths | None = None,
                    masks: MaskedMesh | None = None, caster_constant=None, caster_slope: float = 0.0,
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
    paths : TrianglePaths, optional
        Which path each triangle takes (:func:`~csmlab.kernels.raster.kernels.triangle_paths`); None:
        the module's thresholds. Every choice gives the same maps: tests force each path with it.
    masks : MaskedMesh, optional
        The vertices' texture coordinates and alpha masks on ``device``
        (:func:`csmlab.kernels.alpha.masked_mesh`); None: every triangle opaque.
    caster_constant : array_like, shape (C,), float64, optional
        Metres every triangle of cascade c is pushed away from the light before it is stored
        (a polygon offset's constant part); None: 0.
    caster_slope : float
        Times each triangle's largest light-space depth change over one texel along x or y, added
        to that push (a polygon offset's slope-scaled part, :class:`~csmlab.kernels.raster.kernels.CasterOffset`).
    device : str
        ``"cpu"`` or ``"cuda"``.

    Returns
    -------
    depth : ndarray, shape (C, R, R), float32
        ``depth[c, j, i]`` is the minimum depth over triangles whose interior (top-left rule on
        edges) contains the centre of texel column i, row j of cascade c, where an alpha-tested
        triangle's mask is opaque there; +inf where none.
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
    paths = _checked_paths(paths)
    cascades = pts.shape[0]
    depth = wp.full((cascades, resolution, resolution), value=np.inf, dtype=wp.float32, device=device)
    if tri.shape[0] == 0:
        return depth.numpy(), 0
    covered = wp.empty((cascades, tri.shape[0]), dtype=wp.int32, device=device)
    masks = masks or no_masks(device=device)
    wp.launch(
        rasterize_depth_kernel,
        dim=(cascades, tri.shape[0]),
        inputs=(
            wp.array(pts, dtype=wp.int64, device=device, copy=False),
            wp.array(z, dtype=wp.float64, device=device, copy=False),
            wp.array(tri, dtype=wp.int32, device=device, copy=False),
            masks.uv,
            masks.vertex_mask,
            masks.textures,
            _fixed_point(bits),
            paths,
            _caster_offset(caster_constant, caster_slope, cascades, device),
        ),
        outputs=(depth, covered),
        device=device,
    )
    return depth.numpy(), int(covered.numpy().sum(dtype=np.int64))


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
    origin_fixed = np.ascontiguousarray(origin, dtype=np.int64)
    if (xy.ndim != 2 or xy.shape[1] != 2 or size.ndim != 2 or size.shape[1] != 2
            or origin_fixed.shape != size.shape):
        raise ValueError(f"light_xy, texel_size, origin: expected shapes (V, 2), (C, 2), (C, 2); "
                         f"got {xy.shape}, {size.shape}, {origin_fixed.shape}")
    chosen = np.arange(size.shape[0], dtype=np.int32) if cascades is None else np.asarray(cascades, dtype=np.int32)
    if chosen.ndim != 1 or np.any(chosen < 0) or np.any(chosen >= size.shape[0]):
        raise ValueError(f"cascades: expected indices in [0, {size.shape[0]}), got {cascades!r}")
    bits = _checked_bits(bits)
    with LaunchPool(checked_threads(threads, device), kernels=(fixed_point_vertices_kernel,), device=device) as pool:
        return _vertex_pass(pool, wp.array(xy, dtype=wp.vec2d, device=device, copy=False),
                            _boxes(device, size, origin_fixed), chosen, _fixed_point(bits), device=device).numpy()


def _caster_offset(constant, slope: float, cascades: int, device: str) -> CasterOffset:
    """The :class:`CasterOffset` of ``constant`` (``(C,)`` metres; None: 0) and ``slope``, checked, on ``device``."""
    offset = CasterOffset()
    push = np.zeros(cascades) if constant is None else np.ascontiguousarray(constant, dtype=np.float64)
    if push.shape != (cascades,) or not np.all(np.isfinite(push)):
        raise ValueError(f"caster_constant: expected {cascades} finite offsets in metres, got {constant!r}")
    if not (isinstance(slope, (int, float)) and math.isfinite(slope)):
        raise ValueError(f"caster_slope: expected a finite factor, got {slope!r}")
    offset.constant = wp.array(push, dtype=wp.float64, device=device)
    offset.slope = float(slope)
    return offset


def _boxes(device: str, size: np.ndarray, origin_fixed: np.ndarray) -> Boxes:
    """The :class:`Boxes` of texel sizes (metres) and origins (``2**-bits`` texels), ``(C, 2)`` each, on ``device``."""
    boxes = Boxes()
    boxes.texel_size = wp.array(size, dtype=wp.vec2d, device=device, copy=False)
    boxes.origin_fixed = wp.array(origin_fixed, dtype=vec2l, device=device, copy=False)
    return boxes


def _vertex_pass(pool: LaunchPool, xy: wp.array, boxes: Boxes, cascades: np.ndarray, fixed: FixedPoint, *,
                 device: str) -> wp.array:
    """:func:`fixed_point_vertices` of ``cascades`` on ``device``, each of the pool's launches over its own vertices."""
    points = device_empty((cascades.size, xy.shape[0]), vec2l, device)
    if cascades.size == 0 or xy.shape[0] == 0:
        return points
    chosen = wp.array(cascades, dtype=wp.int32, device=device)

    run = _VERTEX_RUN if wp.get_device(device).is_cpu else 1

    def launch(lo: int, hi: int) -> None:
        wp.launch(fixed_point_vertices_kernel, dim=(cascades.size, -(-(hi - lo) // run)),
                  inputs=(xy, boxes, chosen, lo, hi, run, fixed), outputs=(points,),
                  device=device)

    pool.run([lambda lo=lo, hi=hi: launch(lo, hi) for lo, hi in split_range(xy.shape[0], pool.threads)])
    return points


_VERTEX_RUN = 256
"""Vertices a CPU thread of the vertex pass converts (:func:`fixed_point_vertices`)."""

_FIXED_LIMIT = float(2**50)
"""The clip of global fixed-point values (:mod:`csmlab.texels`)."""


def converted_region_chunks(points, vertices: ChunkVertices, *, regions, bits: int,
                            device: str = "cpu") -> np.ndarray:
    """(region, chunk) rows whose chunk can cover a texel centre of the region, from converted vertices.

    :func:`~csmlab.kernels.raster.regions.region_chunks` for vertices already in each cascade's
    fixed point (an engine's window space, :func:`csmlab.kernels.engine.window_vertices`), where
    light-space metres do not bound them: each chunk's rectangle is taken in the fixed point
    itself, over the chunk's vertices, and a chunk is kept for a region when that rectangle reaches
    a texel centre of it. Exact, no margin: a chunk left out holds no triangle whose bounding box
    holds a centre of the region.

    Parameters
    ----------
    points : array_like, shape (C, V, 2), int64
        Every vertex in every cascade's doubled fixed point (texel centres at odd multiples of ``2**bits``).
    vertices : ChunkVertices
        The vertices of each chunk of the triangles (:func:`~csmlab.kernels.raster.mesh.chunk_vertices`, or a
        mesh's :attr:`~csmlab.kernels.raster.mesh.LightSpaceMesh.chunk_vertices`), indices in ``[0, V)``.
    regions : array_like, shape (G, 5), integer
        Rows ``(c, i0, i1, j0, j1)`` (:func:`~csmlab.kernels.raster.regions.whole_map_regions`).
    bits : int
    device : str

    Returns
    -------
    ndarray, shape (K, 2), int32
        Sorted by region, then chunk.
    """
    device = checked_device(device)
    pts = np.ascontiguousarray(points, dtype=np.int64)
    areas = np.asarray(regions, dtype=np.int64).reshape(-1, 5)
    _checked_bits(bits)
    if pts.ndim != 3 or pts.shape[2] != 2:
        raise ValueError(f"points: expected shape (C, V, 2), got {pts.shape}")
    starts, listed = checked_chunk_vertices(vertices, vertex_count=pts.shape[1])
    count = starts.size - 1
    if count == 0:
        return np.zeros((0, 2), np.int32)
    shape = (pts.shape[0], count)
    lo = device_empty(shape, vec2l, device)
    hi = device_empty(shape, vec2l, device)
    wp.launch(chunk_rectangles_kernel, dim=shape,
              inputs=(wp.array(pts, dtype=vec2l, device=device, copy=False),
                      wp.array(starts, dtype=wp.int32, device=device, copy=False),
                      wp.array(listed, dtype=wp.int32, device=device, copy=False)), outputs=(lo, hi),
              device=device)
    return chunks_meeting_regions(lo.numpy().view(np.int64).reshape(shape + (2,)),
                                  hi.numpy().view(np.int64).reshape(shape + (2,)), regions=areas, bits=bits)


def chunks_meeting_regions(low, high, *, regions, bits: int) -> np.ndarray:
    """(region, chunk) rows whose rectangle ``[low, high]`` in the region's cascade reaches a texel centre of it.

    Parameters
    ----------
    low, high : array_like, shape (C, K, 2), int64
        Each chunk's rectangle in each cascade's doubled fixed point (texel centres at odd multiples
        of ``2**bits``); an empty one (low above high) meets no region.
    regions : array_like, shape (G, 5), integer
        Rows ``(c, i0, i1, j0, j1)``.
    bits : int

    Returns
    -------
    ndarray, shape (N, 2), int32
        Sorted by region, then chunk.
    """
    areas = np.asarray(regions, dtype=np.int64).reshape(-1, 5)
    unit = 1 << _checked_bits(bits)
    rows = [np.zeros((0, 2), np.int32)]
    for g, (c, i0, i1, j0, j1) in enumerate(areas):
        # Doubled units: texel i's centre lies at (2i + 1)·unit.
        meeting = np.flatnonzero((high[c, :, 0] >= (2 * i0 + 1) * unit) & (low[c, :, 0] <= (2 * i1 - 1) * unit)
                                 & (high[c, :, 1] >= (2 * j0 + 1) * unit) & (low[c, :, 1] <= (2 * j1 - 1) * unit))
        pair = np.empty((meeting.size, 2), dtype=np.int32)
        pair[:, 0] = g
        pair[:, 1] = meeting
        rows.append(pair)
    return np.concatenate(rows)


def rasterize_cascades(mesh: LightSpaceMesh, *, texel_size, origin, resolution: int, bits: int,
                       regions=None, chunks=None, depth=None, count_only: bool = False,
                       stored_cascades: int | None = None, threads: int = 1,
                       paths: TrianglePaths | None = None, caster_constant=None, caster_slope: float = 0.0,
                       points=None, vertex_depth=None, near=None,
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
        The vertices' light-space x/y and depths and the triangles, checked
        (:func:`~csmlab.kernels.raster.mesh.light_space_mesh`).
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
        (region, chunk) rows to rasterize (:func:`~csmlab.kernels.raster.regions.region_chunks`); None: every
        chunk of every region.
    depth : ndarray, shape (S, R, R), float32, C-contiguous, optional
        The maps of the stored cascades ``[0, S)`` to rasterize into (default +inf everywhere): the
        regions' texels are rasterized afresh (their values are not read), the others keep theirs.
        Consumed: on the CPU it is filled in place and returned.
    count_only : bool
        Count the coverage tests that pass and store no depth (``depth`` is ignored and None returned).
    stored_cascades : int, optional
        S: cascades ``[0, S)`` are stored; the regions of cascades ``[S, C)`` are only counted (their
        coverage tests, no depth), and may overlap any region: e.g. the strips a scrolled frame's
        previous boxes left, counted in the call that rasterizes the new ones
        (:func:`csmlab.render.shadow_maps`). None: every cascade (0 with ``count_only``).
    threads : int
        CPU launches run at once (one Warp CPU launch runs on one thread). The regions, which are
        disjoint, are taken by the threads one at a time, costliest first, so no two launches write
        one texel; cut large regions into bands first
        (:func:`~csmlab.kernels.raster.regions.banded_regions`,
        :data:`~csmlab.kernels.raster.regions.BANDS_PER_THREAD` per thread) so that the threads
        finish together. Ignored on CUDA.
    paths : TrianglePaths, optional
        Which path each triangle takes (:func:`~csmlab.kernels.raster.kernels.triangle_paths`); None:
        the module's thresholds. Every choice gives the same maps: tests force each path with it.
    caster_constant : array_like, shape (C,), float64, optional
    caster_slope : float
        The polygon offset each triangle is stored with, as :func:`rasterize_depth`'s.
    points : array_like, shape (C, V, 2), int64, optional
        Every vertex already in every cascade's doubled fixed point (an engine's window space,
        :func:`csmlab.kernels.engine.window_vertices`), within ±2**52; ``texel_size`` and ``origin``
        then serve only the chunks' selection by the caller (pass ``chunks`` from
        :func:`converted_region_chunks`). None: converted from ``mesh.xy`` here.
    vertex_depth : array_like, shape (C, V), float64, optional
        Every vertex's stored depth in every cascade, metres, finite; None: ``mesh.depth`` in all.
    near : array_like, shape (C,), float64, optional
        Cascade c keeps only the triangles whose largest ``mesh.depth`` reaches ``near[c]``
        (:func:`csmlab.render.clipped_casters`); None: every triangle.
    device : str

    Returns
    -------
    depth : ndarray, shape (S, R, R), float32, or None
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
    xy, z, tri = _checked_mesh(mesh)
    size, origin_fixed = _checked_boxes(texel_size, origin)
    bits = _checked_bits(bits)
    resolution = _checked_resolution(resolution)
    paths = _checked_paths(paths)
    shape = (size.shape[0], resolution, resolution)
    areas, rows = _checked_regions(regions, chunks, shape, triangles=tri.shape[0])
    count = -(-tri.shape[0] // (1 << CHUNK_BITS))
    parts = min(checked_threads(threads, device), areas.shape[0])
    extent = (areas[:, 2].astype(np.int64) - areas[:, 1]) * (areas[:, 4] - areas[:, 3])
    stored = _checked_stored(stored_cascades, shape[0], count_only=count_only)
    filled = areas[:, 0] < stored
    stored_shape = (stored, resolution, resolution)
    if count_only:
        maps = np.zeros((0, 0, 0), dtype=np.float32)
    elif depth is None:
        # Regions that tile the maps leave nothing to fill but what each region fills itself.
        maps = (np.empty(stored_shape, dtype=np.float32) if extent[filled].sum() == np.prod(stored_shape)
                else np.full(stored_shape, np.inf, dtype=np.float32))
    elif depth.shape != stored_shape or depth.dtype != np.float32 or not depth.flags.c_contiguous:
        raise ValueError(f"depth: expected C-contiguous float32 maps of shape {stored_shape}, got {depth.dtype} "
                         f"{depth.shape}")
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
    given = _converted_vertices(points, vertex_depth, near, shape[0], xy.shape[0])
    if given[0] is not None:
        slots = np.arange(shape[0], dtype=np.int32)
    # On the CPU each launch empties its own regions first (on two threads at once); a GPU gets
    # the maps emptied by the host before they are copied to it.
    on_cpu = wp.get_device(device).is_cpu
    empty_regions(maps, areas[filled] if not on_cpu else areas[:0])
    light = light_mesh(mesh, device)
    boxes = _boxes(device, size, origin_fixed)
    fixed = _fixed_point(bits)
    offset = _caster_offset(caster_constant, caster_slope, shape[0], device)
    region_rows = wp.array(areas, dtype=wp.int32, device=device)
    maps_on = wp.array(maps, dtype=wp.float32, device=device, copy=False)
    covered = wp.zeros(areas.shape[0], dtype=wp.int64, device=device)
    # A CPU thread takes a whole chunk, so that what it reads first serves 32 triangles; a GPU thread one.
    run_bits = CHUNK_BITS if on_cpu else 0
    with LaunchPool(parts, kernels=(rasterize_chunks_kernel, fixed_point_vertices_kernel), device=device) as pool:
        converted_here = VertexPass()
        converted_here.points = (_vertex_pass(pool, light.xy, boxes, converted, fixed, device=device)
                                 if given[0] is None else wp.array(given[0], dtype=vec2l, device=device, copy=False))
        converted_here.slots = wp.array(slots, dtype=wp.int32, device=device)
        converted_here.depth = wp.array(given[1], dtype=wp.float64, device=device, copy=False)
        converted_here.near = wp.array(given[2], dtype=wp.float64, device=device)

        def rasterize_region(g: int) -> None:
            # Emptied just before it is rasterized, while its texels are still in the cache.
            if on_cpu and filled[g]:
                empty_regions(maps, areas[g:g + 1])
            if held[g]:
                work = ChunkRows()
                work.regions = region_rows
                work.chunks = wp.array(rows[starts[g]:starts[g + 1]], dtype=wp.int32, device=device)
                work.chunk_bits = CHUNK_BITS
                work.run_bits = run_bits
                wp.launch(rasterize_chunks_kernel, dim=int(held[g]) >> run_bits,
                          inputs=(light, boxes, converted_here, work, fixed, paths, offset), outputs=(maps_on, covered),
                          device=device)

        # Disjoint regions, so no texel is written by two launches: the threads take them in turn,
        # costliest first (triangles, then texels), so that they finish together.
        pool.take_in_turn(np.lexsort((-extent, -held)).tolist(), rasterize_region)
    return None if count_only else maps_on.numpy(), covered.numpy()



def _checked_stored(stored_cascades, cascades: int, *, count_only: bool) -> int:
    """The cascades :func:`rasterize_cascades` stores (``stored_cascades``; None: all, or none with ``count_only``)."""
    if stored_cascades is None:
        return 0 if count_only else cascades
    if not (isinstance(stored_cascades, (int, np.integer)) and 0 <= stored_cascades <= cascades):
        raise ValueError(f"stored_cascades: expected an integer in 0..{cascades}, got {stored_cascades!r}")
    return 0 if count_only else int(stored_cascades)


def light_mesh(mesh: LightSpaceMesh, device: str) -> LightMesh:
    """The :class:`LightMesh` of ``mesh`` on ``device`` (checked), made on the first call and kept with the mesh
    (:attr:`LightSpaceMesh.on_devices`).

    A mesh is rasterized by every cascade and frame of its light: wrapping its arrays and masks for
    Warp cost ~0.2 ms a call on the CPU (the masks' six arrays most), and a GPU uploaded the whole
    mesh each call. The arrays are read-only, so what one call made serves the next.
    """
    device = checked_device(device)
    light = mesh.on_devices.get(device)
    if light is None:
        light = LightMesh()
        light.xy = wp.array(mesh.xy, dtype=wp.vec2d, device=device, copy=False)
        light.depth = wp.array(mesh.depth, dtype=wp.float64, device=device, copy=False)
        light.triangles = wp.array(mesh.triangles, dtype=wp.int32, device=device, copy=False)
        masks = masked_mesh(mesh.uv, mesh.vertex_mask, mesh.alpha, device=device)
        light.uv = masks.uv
        light.vertex_mask = masks.vertex_mask
        light.textures = masks.textures
        mesh.on_devices[device] = light
    return light


def _converted_vertices(points, vertex_depth, near, cascades: int,
                        vertices: int) -> tuple[np.ndarray | None, np.ndarray, np.ndarray]:
    """:func:`rasterize_cascades`'s ``points`` ``(C, V, 2)`` (None where not given), ``vertex_depth`` ``(C, V)`` (zero
    rows where not given) and ``near`` ``(C,)`` (zero-length where not given), checked."""
    pts = None
    if points is not None:
        pts = np.ascontiguousarray(points, dtype=np.int64)
        # Two passes over the values, no array of their magnitudes (|INT64_MIN| wraps negative, as a bound must not).
        if pts.shape != (cascades, vertices, 2) or (pts.size and (pts.min() < -2**52 or pts.max() > 2**52)):
            raise ValueError(f"points: expected doubled fixed-point vertices of shape {(cascades, vertices, 2)} "
                             f"within ±2**52, got {pts.shape}")
    z = np.zeros((0, 0), dtype=np.float64)
    if vertex_depth is not None:
        z = np.ascontiguousarray(vertex_depth, dtype=np.float64)
        if z.shape != (cascades, vertices) or not np.all(np.isfinite(z)):
            raise ValueError(f"vertex_depth: expected finite depths of shape {(cascades, vertices)} in metres, "
                             f"got {z.shape}")
        if pts is None:
            raise ValueError("vertex_depth: expected with points (the depths of converted vertices)")
    cut = np.zeros(0, dtype=np.float64)
    if near is not None:
        cut = np.ascontiguousarray(near, dtype=np.float64).reshape(-1)
        if cut.shape != (cascades,) or np.any(np.isnan(cut)):
            raise ValueError(f"near: expected {cascades} depths in metres, got {near!r}")
    return pts, z, cut
