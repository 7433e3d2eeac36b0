"""The mesh as the depth pass reads it: checked once per light, listed along a Z-order curve, bounded by chunks.

NumPy only, run on the host once per light (:func:`light_space_mesh`, :func:`z_ordered`) or once per
mesh (:class:`TriangleBounds`); :mod:`csmlab.kernels.raster.regions` queries the bounds.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

__all__ = ["CHUNK_BITS", "ChunkVertices", "LightSpaceMesh", "TriangleBounds", "checked_chunk_vertices",
           "chunk_vertices", "light_space_mesh", "triangle_bounds", "z_ordered"]

CHUNK_BITS = 5
"""Triangles are culled in chunks of ``2**CHUNK_BITS`` consecutive ones
(:func:`~csmlab.kernels.raster.regions.region_chunks`).

Meshes list neighbouring triangles together (grids by rows, objects one after another), so a
chunk's rectangle is small: testing 32 times fewer rectangles costs less than the triangles it lets
through, which the kernel drops before any per-texel work.
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
        (:func:`~csmlab.kernels.raster.regions.banded_regions`) meet fewer of them.
        """
        lo_x, lo_y, hi_x, hi_y = self.chunks
        return int(len(lo_x) > 0 and np.median(hi_y - lo_y) < np.median(hi_x - lo_x))


@dataclass(frozen=True)
class ChunkVertices:
    """The vertices each chunk of triangles (:data:`CHUNK_BITS`) uses: chunk k's are
    ``vertices[starts[k]:starts[k + 1]]``.

    Attributes
    ----------
    starts : ndarray, shape (K + 1,), int32
        Offsets into ``vertices``, K = ⌈T / 2**CHUNK_BITS⌉.
    vertices : ndarray, shape (N,), int32
        Vertex indices, chunk after chunk.
    """

    starts: np.ndarray
    vertices: np.ndarray


def chunk_vertices(triangles, *, distinct: bool = True) -> ChunkVertices:
    """The vertices of each chunk of ``triangles`` ``(T, 3)``: each once (``distinct``), or every corner in order.

    A chunk's rectangle in any space is its vertices' (:func:`csmlab.kernels.raster.converted_region_chunks`):
    on a grid's chunk of 32 triangles, ~30 distinct vertices against 96 corners. Taking them apart sorts each
    chunk's corners, ~10 ms at ~250k triangles: worth it for a mesh that serves many frames
    (:attr:`LightSpaceMesh.chunk_vertices`), not for one clipped for a single cascade.
    """
    corners = np.ascontiguousarray(triangles, dtype=np.int32).reshape(-1)
    size = 3 << CHUNK_BITS
    count = -(-corners.size // size)
    if not distinct or count == 0:
        return ChunkVertices(starts=np.minimum(np.arange(count + 1, dtype=np.int64) * size, corners.size)
                             .astype(np.int32), vertices=corners)
    # The last chunk is padded with copies of its first corner, which the distinct vertices drop.
    padded = np.empty(count * size, dtype=np.int32)
    padded[:corners.size] = corners
    padded[corners.size:] = corners[(count - 1) * size]
    ordered = np.sort(padded.reshape(count, size), axis=1)
    first = np.ones_like(ordered, dtype=bool)
    first[:, 1:] = ordered[:, 1:] != ordered[:, :-1]
    starts = np.zeros(count + 1, dtype=np.int32)
    np.cumsum(first.sum(axis=1), out=starts[1:])
    return ChunkVertices(starts=starts, vertices=ordered[first])


def checked_chunk_vertices(vertices: ChunkVertices, *, vertex_count: int) -> tuple[np.ndarray, np.ndarray]:
    """``vertices``' offsets ``(K + 1,)`` and indices ``(N,)`` as contiguous int32, checked: offsets rising from 0 to N
    by at least one (no chunk without a vertex), indices in ``[0, vertex_count)``.

    Raises
    ------
    ValueError
        Naming what was expected and what was given.
    """
    starts = np.ascontiguousarray(vertices.starts, dtype=np.int32)
    listed = np.ascontiguousarray(vertices.vertices, dtype=np.int32)
    if starts.ndim != 1 or starts.size < 1 or listed.ndim != 1 or starts[0] != 0 or starts[-1] != listed.size \
            or np.any(np.diff(starts) < 1) or (listed.size and (listed.min() < 0 or listed.max() >= vertex_count)):
        raise ValueError(f"vertices: expected chunks of at least one vertex each, indices in [0, {vertex_count}); got "
                         f"offsets of shape {starts.shape} over {listed.shape} indices")
    return starts, listed


def triangle_bounds(light_xy, triangles) -> TriangleBounds:
    """Light-space bounding rectangle of every triangle (:func:`~csmlab.kernels.raster.regions.region_chunks`
    queries them).

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
        Vertex indices in ``[0, V)``; either winding. The rows are those the method's face cull
        kept (:func:`csmlab.culling.culled_triangles`, chosen on the host before this record is made).
    uv : ndarray, shape (V, 2), float64, or None
        Texture coordinates of each vertex, where masks apply (:class:`csmlab.scene.core.Scene`).
    vertex_mask : ndarray, shape (V,), int32, or None
        Each vertex's alpha mask, −1 opaque; None: every triangle opaque.
    alpha : tuple of AlphaMask
        The masks ``vertex_mask`` indexes.
    """

    xy: np.ndarray
    depth: np.ndarray
    triangles: np.ndarray
    uv: np.ndarray | None = None
    vertex_mask: np.ndarray | None = None
    alpha: tuple = ()

    @cached_property
    def on_devices(self) -> dict:
        """The mesh's arrays on each device the depth pass read them on, by device name, filled by that pass
        (:func:`csmlab.kernels.raster.schedule.light_mesh`): uploaded and wrapped once, not once per call."""
        return {}

    @cached_property
    def chunk_vertices(self) -> ChunkVertices:
        """The distinct vertices of each chunk of :attr:`triangles` (:func:`chunk_vertices`), taken once per mesh."""
        return chunk_vertices(self.triangles)

    @cached_property
    def bounds(self) -> TriangleBounds:
        """The light-space rectangles of the triangles and of their chunks (queried by
        :func:`~csmlab.kernels.raster.regions.region_chunks`)."""
        return triangle_bounds(self.xy, self.triangles)


def light_space_mesh(light_xy, vertex_depth, triangles, *, uv=None, vertex_mask=None, alpha=()) -> LightSpaceMesh:
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
    uv, vertex_mask, alpha
        The vertices' texture coordinates ``(V, 2)`` and masks ``(V,)`` and the masks' records, in
        the vertices' order here; ``vertex_mask`` None: no masks.

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
    if vertex_mask is None:
        return LightSpaceMesh(*(_read_only(a) for a in (xy, z, tri)))
    m = np.ascontiguousarray(vertex_mask, dtype=np.int32)
    coordinates = np.ascontiguousarray(uv, dtype=np.float64)
    if m.shape != (xy.shape[0],) or coordinates.shape != (xy.shape[0], 2) or m.max(initial=-1) >= len(alpha):
        raise ValueError(f"uv, vertex_mask: expected shapes ({xy.shape[0]}, 2), ({xy.shape[0]},) and masks "
                         f"in [-1, {len(alpha)})")
    return LightSpaceMesh(*(_read_only(a) for a in (xy, z, tri)), uv=_read_only(coordinates),
                          vertex_mask=_read_only(m), alpha=tuple(alpha))


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
