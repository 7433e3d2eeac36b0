"""Depth maps as a unorm depth format stores them: one pass over the texels, NumPy's arithmetic bit for bit.

:func:`csmlab.storage.stored_depth` and :func:`csmlab.storage.cascade_stored_depth` state the
quantization (``lo + clip(rint((z − lo) / step), 0, top) · step``, float64, back to float32); the
kernel here runs it texel by texel with the same roundings (``fuse_fp`` off) and the same clip as
NumPy's (a level replaced by a bound only where strictly beyond it: −0 stays −0), in place of
NumPy's ten passes over float64 temporaries of every texel. It may quantize only some rectangles of
the maps into maps that hold the others already (the strips a scrolled frame rasterized,
:func:`csmlab.scrolling.kept_stored`): each rectangle a strided view of its own, so that every launch
runs the same row loop, from column 0 to the row's end, as a whole map's.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from csmlab.kernels.threads import LaunchPool, split_range

__all__ = ["unorm_stored_depth"]

# Products and sums rounded one by one, as NumPy rounds them.
wp.set_module_options({"fuse_fp": False})


@wp.kernel
def unorm_stored_depth_kernel(depth: wp.array3d(dtype=wp.float32), lo: wp.array(dtype=wp.float64),
                              step: wp.array(dtype=wp.float64), top: wp.float64, offset: int, first: int,
                              out: wp.array3d(dtype=wp.float32)):
    """Row ``first + k`` of the maps (rows of every cascade in turn): each finite texel quantized, others kept."""
    row = first + wp.tid()
    c = row // depth.shape[1]
    j = row - c * depth.shape[1]
    low = lo[c]
    size = step[c]
    zero = wp.float64(0.0)
    # A `while` loop: a range known only at run time costs Warp's CPU code several times more per step.
    i = int(0)
    while i < depth.shape[2]:
        z = depth[c, j, i]
        kept = z
        # Finite: z − z is 0 for every finite z, NaN for ±inf and NaN.
        if z - z == wp.float32(0.0):
            x = wp.float64(z)
            if offset != 0:
                x = x - low
            level = wp.rint(x / size)
            # As np.clip: a level is replaced only when strictly beyond a bound, so −0 stays −0.
            if level < zero:
                level = zero
            if level > top:
                level = top
            stored = level * size
            if offset != 0:
                stored = low + stored
            kept = wp.float32(stored)
        out[c, j, i] = kept
        i += 1


def unorm_stored_depth(depth: np.ndarray, *, step, top: float, lo=None, threads: int = 1,
                       overwrite: bool = False, regions=None, out: np.ndarray | None = None) -> np.ndarray:
    """``(C, R, R)`` float32 maps quantized to ``top + 1`` levels of ``step`` metres per cascade, on the CPU.

    Parameters
    ----------
    depth : ndarray, shape (C, R, R), float32
        Depth in metres; non-finite texels (empty: +inf) are kept as they are.
    step : array_like, shape (C,), float64
        Metres per level of each cascade.
    top : float
        The highest level, ``2**bits − 1``.
    lo : array_like, shape (C,), float64, optional
        Each cascade's level 0 in metres (``near + level · step``); None: levels from 0 m
        (``level · step``, no sum: a level of −0 stays −0 as NumPy keeps it).
    threads : int
        CPU launches at once, each over its own rows.
    overwrite : bool
        Whether ``depth`` may hold the result (a writeable C-contiguous float32 array is then
        quantized in place: each texel is read before it is written, by the same thread), sparing
        a fresh array's page faults. Ignored where ``out`` is given.
    regions : array_like, shape (G, 5), integer, optional
        Rows ``(c, i0, i1, j0, j1)``: texel columns ``[i0, i1)`` and rows ``[j0, j1)`` of cascade c
        to quantize, disjoint; the other texels keep the values of the array written into
        (``out``, else ``depth`` itself or its copy). None: every texel.
    out : ndarray, shape (C, R, R), float32, C-contiguous, writeable, optional
        The maps the quantized texels are written into (``depth`` itself allowed), and returned;
        None: ``depth`` (``overwrite``) or a fresh array.

    Returns
    -------
    ndarray, shape (C, R, R), float32
        :func:`csmlab.storage.cascade_stored_depth` (with ``lo``) or :func:`csmlab.storage.stored_depth`, bit for bit,
        at the texels of ``regions``.
    """
    maps = np.ascontiguousarray(depth, dtype=np.float32)
    if maps.ndim != 3:
        raise ValueError(f"depth: expected maps of shape (C, R, R), got {maps.shape}")
    count = maps.shape[0]
    size = np.ascontiguousarray(np.broadcast_to(np.asarray(step, dtype=np.float64), (count,)))
    low = np.zeros(count) if lo is None else np.ascontiguousarray(np.broadcast_to(np.asarray(lo, np.float64), (count,)))
    if out is None:
        out = maps if overwrite and maps.flags.writeable else (np.empty_like(maps) if regions is None else maps.copy())
    elif out.shape != maps.shape or out.dtype != np.float32 or not (out.flags.c_contiguous and out.flags.writeable):
        raise ValueError(f"out: expected writeable C-contiguous float32 maps of shape {maps.shape}")
    # Each piece: maps (C', H, W) read and written, strided views for a region, and their cascades' levels.
    pieces = [(maps, out, low, size)] if regions is None else [
        (maps[c:c + 1, j0:j1, i0:i1], out[c:c + 1, j0:j1, i0:i1], low[c:c + 1], size[c:c + 1])
        for c, i0, i1, j0, j1 in _checked_regions(regions, maps.shape)]
    launches = [((wp.array(source, dtype=wp.float32, device="cpu", copy=False),
                  wp.array(levels_lo, dtype=wp.float64, device="cpu"),
                  wp.array(levels_step, dtype=wp.float64, device="cpu"), float(top), int(lo is not None)),
                 wp.array(target, dtype=wp.float32, device="cpu", copy=False), source.shape[0] * source.shape[1])
                for source, target, levels_lo, levels_step in pieces if source.size]
    if not launches:
        return out
    with LaunchPool(threads, kernels=(unorm_stored_depth_kernel,), device="cpu") as pool:
        pool.run([lambda inputs=inputs, result=result, a=a, b=b: wp.launch(
            unorm_stored_depth_kernel, dim=b - a, inputs=(*inputs, a), outputs=(result,), device="cpu")
            for inputs, result, rows in launches for a, b in split_range(rows, pool.threads)])
    return out


def _checked_regions(regions, shape: tuple[int, int, int]) -> np.ndarray:
    """``(G, 5)`` int64 rectangles ``(c, i0, i1, j0, j1)`` of ``regions``, each inside maps of ``shape``.

    Raises
    ------
    ValueError
        On a rectangle beyond the maps (the kernel reads and writes without bounds checks).
    """
    count, side, width = shape
    areas = np.asarray(regions, dtype=np.int64).reshape(-1, 5)
    if areas.size and (areas[:, 0].min() < 0 or areas[:, 0].max() >= count or areas[:, 1].min() < 0
                       or areas[:, 2].max() > width or areas[:, 3].min() < 0 or areas[:, 4].max() > side):
        raise ValueError(f"regions: expected rectangles (c, i0, i1, j0, j1) inside maps of shape {shape}")
    return areas
