"""Region planning of the depth pass: which texels to rasterize, cut how, and which chunks of triangles meet them.

A region is a row ``(c, i0, i1, j0, j1)``: texel columns ``[i0, i1)`` and rows ``[j0, j1)`` of
cascade c. NumPy only; :mod:`csmlab.kernels.raster.schedule` hands the regions to the threads.
"""

from __future__ import annotations

import numpy as np

from csmlab.kernels.raster.mesh import TriangleBounds

__all__ = ["BANDS_PER_THREAD", "banded_regions", "empty_regions", "region_chunks", "whole_map_regions"]

BANDS_PER_THREAD = 1
"""Bands each region is cut into per thread (:func:`banded_regions`), which the threads take in turn,
costliest first (:func:`~csmlab.kernels.raster.schedule.rasterize_cascades`).

One band per thread is enough for them to finish together: a map's cascades are regions too, and
each band costs its launch, its culling pass and the triangles its edges cut. Four cascades at
~1M triangles, 2 threads, same process, interleaved (ms): 1024² 40.2 with one band per thread,
41.5 with 2, 45.0 with 4; 2048² 88.6, 90.8, 94.8; at 136k, 1024² 21.5, 22.5, 24.0.
"""


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
        :func:`~csmlab.kernels.raster.mesh.triangle_bounds`.
    texel_size : array_like, shape (C, 2)
        Metres per texel of each cascade.
    origin : array_like, shape (C, 2)
        Box minimum corner in texels of each cascade.
    regions : array_like, shape (G, 5), integer
        Rows ``(c, i0, i1, j0, j1)``: texel columns ``[i0, i1)`` and rows ``[j0, j1)`` of cascade c
        (:func:`whole_map_regions` for whole maps).
    """
    size = np.asarray(texel_size, dtype=np.float64)
    origin_texels = np.asarray(origin, dtype=np.float64)
    lo_x, lo_y, hi_x, hi_y = bounds.chunks
    rows = [np.zeros((0, 2), np.int32)]
    for g, (c, i0, i1, j0, j1) in enumerate(np.asarray(regions, dtype=np.int64).reshape(-1, 5)):
        box_lo = (origin_texels[c] + [i0 - 1.0, j0 - 1.0]) * size[c]
        box_hi = (origin_texels[c] + [i1 + 1.0, j1 + 1.0]) * size[c]
        meeting = np.flatnonzero((hi_x >= box_lo[0]) & (lo_x <= box_hi[0]) & (hi_y >= box_lo[1]) & (lo_y <= box_hi[1]))
        pair = np.empty((meeting.size, 2), dtype=np.int32)
        pair[:, 0] = g
        pair[:, 1] = meeting
        rows.append(pair)
    return np.concatenate(rows)


def empty_regions(maps: np.ndarray, regions: np.ndarray) -> None:
    """Set every texel of ``regions`` ``(G, 5)`` (rows ``(c, i0, i1, j0, j1)``) of ``maps`` ``(C, R, R)`` to +inf."""
    for c, i0, i1, j0, j1 in regions:
        maps[c, j0:j1, i0:i1] = np.inf
