"""Depth rasterization of every cascade in fixed point (docs/design.md, CSM model step 4).

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

The package by job:

- :mod:`~csmlab.kernels.raster.kernels` — the Warp code: a triangle's three paths (one centre,
  walk, large triangle) and the thresholds that choose them, the vertex pass, the three kernels
  and the structs they take;
- :mod:`~csmlab.kernels.raster.mesh` — mesh preparation (NumPy): the checked light-space mesh,
  its Z-order, the bounding rectangles of its triangles and chunks;
- :mod:`~csmlab.kernels.raster.regions` — region planning (NumPy): whole maps, bands per thread,
  the chunks of triangles that meet a region;
- :mod:`~csmlab.kernels.raster.schedule` — the NumPy-in/NumPy-out wrappers: checks, uploads,
  the vertex pass (or vertices converted elsewhere, :mod:`csmlab.kernels.engine`, with the chunks
  their own rectangles choose) and the regions' launches taken in turn by the threads;
- :mod:`~csmlab.kernels.raster.tiled` — the same maps rasterized as GPUs do: triangles binned to
  tiles, a thread per texel of a tile;
- :mod:`~csmlab.kernels.raster.dispatch` — which of the two a device gets (``rasterize_cascades``).

References
----------
- Pineda, "A Parallel Algorithm for Polygon Rasterization", SIGGRAPH 1988 — edge functions.
- Microsoft, Direct3D 11 rasterization rules — the top-left rule and sub-pixel fixed point.
"""

from csmlab.kernels.raster.kernels import TrianglePaths, triangle_paths
from csmlab.kernels.raster.mesh import (CHUNK_BITS, ChunkVertices, LightSpaceMesh, TriangleBounds, chunk_vertices,
                                        light_space_mesh, triangle_bounds, z_ordered)
from csmlab.kernels.raster.regions import BANDS_PER_THREAD, banded_regions, region_chunks, whole_map_regions
from csmlab.kernels.raster.schedule import (chunks_meeting_regions, converted_region_chunks, fixed_point_vertices,
                                            rasterize_depth)
from csmlab.kernels.raster.dispatch import rasterize_cascades

__all__ = ["BANDS_PER_THREAD", "CHUNK_BITS", "ChunkVertices", "LightSpaceMesh", "TriangleBounds", "TrianglePaths",
           "banded_regions", "chunk_vertices", "chunks_meeting_regions", "converted_region_chunks",
           "fixed_point_vertices", "light_space_mesh", "rasterize_cascades", "rasterize_depth", "region_chunks",
           "triangle_bounds", "triangle_paths", "whole_map_regions", "z_ordered"]
