"""The report's per-frame records on the host: the pixels' ground cells, the cells' sums, ρ histogram, animation blocks.

Every frame of every method keeps, for the interactive report (:mod:`csmlab.report.pixels`) and the
animations (:mod:`csmlab.report.capture`), a few reductions of its full-resolution planes. Each was a
chain of whole-image NumPy passes (masks, compactions, ``np.bincount``, strided block sums), ~5 ms a
frame and method of a run's ~12 ms of records; each is one pass here.

The records are files whose bytes do not depend on the device: these kernels run on the CPU, in
one thread per launch, and repeat NumPy's operations in NumPy's order — a cell's change is summed
pixel by pixel in row-major order, as ``np.bincount`` sums its weights, and a block's values row by
row, left to right, then the row sums top to bottom, as :func:`csmlab.report.capture._block_reduce`
does (a mean's last bit, which moves its code only on a half-way value) — so that the records keep
their bits.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from csmlab.kernels import host_array

__all__ = ["animation_codes", "cell_sums", "grid_cells", "log2_histogram"]

# Each product, quotient and sum rounded on its own, as NumPy rounds them.
wp.set_module_options({"fuse_fp": False})

NO_VALUE = wp.constant(wp.uint8(255))


@wp.func
def finite(x: wp.float64) -> bool:
    """``x`` is neither NaN nor infinite (``x − x`` is NaN for both): a subtraction and a comparison clang inlines
    (``wp.isfinite`` is a call into the JIT's runtime, a third of these kernels' time). Not ``|x| ≤ DBL_MAX``: a
    constant made of a NumPy scalar is written into Warp's C++ as NumPy prints it, and after colour-science's
    import (legacy printing) DBL_MAX printed as 1.79769313486e+308, below itself."""
    return x - x == wp.float64(0.0)


@wp.kernel
def grid_cells_kernel(positions: wp.array2d(dtype=wp.vec3d), x0: wp.float64, z0: wp.float64, cell: wp.float64,
                      nx: int, nz: int, cells: wp.array2d(dtype=wp.int64)):
    # A row of pixels a thread (a `while` loop: a range known only at run time costs Warp's CPU code more).
    i = wp.tid()
    j = int(0)
    while j < positions.shape[1]:
        p = positions[i, j]
        column = wp.floor((p[0] - x0) / cell)
        row = wp.floor((p[2] - z0) / cell)
        index = wp.int64(-1)
        # NaN fails every comparison: outside.
        if column >= wp.float64(0.0) and column < wp.float64(nx) and row >= wp.float64(0.0) and row < wp.float64(nz):
            index = wp.int64(row) * wp.int64(nx) + wp.int64(column)
        cells[i, j] = index
        j += 1


@wp.kernel
def cell_sums_kernel(cells: wp.array2d(dtype=wp.int64), change: wp.array2d(dtype=wp.float64),
                     flipped: wp.array2d(dtype=wp.bool), change_sum: wp.array(dtype=wp.float64),
                     counted: wp.array(dtype=wp.int64), flips: wp.array(dtype=wp.int64)):
    # One thread: every pixel in row-major order, so that each cell's sum adds its pixels in their order.
    i = int(0)
    while i < cells.shape[0]:
        j = int(0)
        while j < cells.shape[1]:
            c = cells[i, j]
            d = change[i, j]
            if c >= wp.int64(0) and finite(d):
                change_sum[c] = change_sum[c] + d
                counted[c] = counted[c] + wp.int64(1)
                if flipped[i, j]:
                    flips[c] = flips[c] + wp.int64(1)
            j += 1
        i += 1


@wp.func
def coded(value: wp.float64) -> wp.uint8:
    """``round(254 · v)`` of ``v`` clipped to [0, 1]; :data:`NO_VALUE` where not finite."""
    if not finite(value):
        return NO_VALUE
    return wp.uint8(wp.rint(wp.min(wp.max(value, wp.float64(0.0)), wp.float64(1.0)) * wp.float64(254.0)))


@wp.kernel
def animation_codes_kernel(lit: wp.array2d(dtype=wp.float64), change: wp.array2d(dtype=wp.float64), k: int,
                           lit_codes: wp.array2d(dtype=wp.uint8), change_codes: wp.array2d(dtype=wp.uint8)):
    # A row of blocks a thread. Each block's lit values (0 where undefined) are summed row by row, left to
    # right from the row's first value, then the row sums top to bottom from the first.
    i = wp.tid()
    j = int(0)
    while j < lit_codes.shape[1]:
        total = wp.float64(0.0)
        count = int(0)
        largest = wp.float64(-1.0)
        a = int(0)
        while a < k:
            row_sum = wp.float64(0.0)
            b = int(0)
            while b < k:
                s = lit[i * k + a, j * k + b]
                x = wp.float64(0.0)
                if finite(s):
                    x = s
                    count += 1
                if b == 0:
                    row_sum = x
                else:
                    row_sum = row_sum + x
                d = wp.abs(change[i * k + a, j * k + b])
                if finite(d):
                    largest = wp.max(largest, d)
                b += 1
            if a == 0:
                total = row_sum
            else:
                total = total + row_sum
            a += 1
        mean = wp.float64(wp.nan)
        if count > 0:
            mean = total / wp.float64(count)
        lit_codes[i, j] = coded(mean)
        # -1 where the block has no finite change: coded as no value, as NaN is.
        change_codes[i, j] = coded(wp.where(largest >= wp.float64(0.0), largest, wp.float64(wp.nan)))
        j += 1


@wp.kernel
def log2_histogram_kernel(log2_values: wp.array2d(dtype=wp.float64), bin_of: wp.array2d(dtype=wp.int32),
                          defined: wp.array2d(dtype=wp.bool), per_step: wp.float64, offset: wp.float64,
                          counts: wp.array2d(dtype=wp.int64), outside: wp.array(dtype=wp.int64)):
    # One thread (the counts are added to at random). A group out of range is counted in `outside`, not written.
    i = int(0)
    groups = counts.shape[0]
    bins = counts.shape[1]
    while i < defined.shape[0]:
        j = int(0)
        while j < defined.shape[1]:
            if defined[i, j]:
                step = wp.floor(log2_values[i, j] * per_step) - offset
                step = wp.min(wp.max(step, wp.float64(0.0)), wp.float64(bins - 1))
                c = int(bin_of[i, j])
                if c >= 0 and c < groups:
                    counts[c, int(step)] = counts[c, int(step)] + wp.int64(1)
                else:
                    outside[0] = outside[0] + wp.int64(1)
            j += 1
        i += 1


def grid_cells(positions, *, x0: float, z0: float, cell: float, nx: int, nz: int) -> np.ndarray:
    """Flat ground-cell index ``row · nx + column`` of each world position; −1 outside the grid or NaN.

    Parameters
    ----------
    positions : array_like, shape (H, W, 3), float64
        World positions in metres (Y up), NaN where no surface.
    x0, z0 : float, keyword-only
        World x and z of the grid's minimum corner, metres.
    cell : float, keyword-only
        Cell side, metres (> 0).
    nx, nz : int, keyword-only
        Cells along x (columns) and z (rows).

    Returns
    -------
    ndarray, shape (H, W), int64
        ``floor((z − z0) / cell) · nx + floor((x − x0) / cell)`` where both floors lie in the grid.
    """
    p = np.ascontiguousarray(positions, dtype=np.float64)
    if p.ndim != 3 or p.shape[2] != 3:
        raise ValueError(f"positions: expected an (H, W, 3) image of points, got shape {p.shape}")
    cells = np.empty(p.shape[:2], dtype=np.int64)
    if cells.size:
        wp.launch(grid_cells_kernel, dim=p.shape[0],
                  inputs=(host_array(p, wp.vec3d), wp.float64(x0), wp.float64(z0), wp.float64(cell), int(nx), int(nz)),
                  outputs=(host_array(cells, wp.int64),), device="cpu")
    return cells


def cell_sums(cells, change, flipped, *, size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per ground cell: the summed change, the pixels counted and those that flipped.

    A pixel counts where its cell is ≥ 0 and its change is finite.

    Parameters
    ----------
    cells : array_like, shape (H, W), int64
        :func:`grid_cells` of the pixels, below ``size``.
    change : array_like, shape (H, W), float64
        The pixels' |ΔS|, NaN where not counted.
    flipped : array_like, shape (H, W), bool
        Pixels whose lit/shadow state flipped.
    size : int, keyword-only
        Cells in the grid.

    Returns
    -------
    change_sum : ndarray, shape (size,), float64
        ``np.bincount(cells[kept], weights=change[kept], minlength=size)``, the same bits.
    counted, flips : ndarray, shape (size,), int64
        Counted pixels, and counted pixels that flipped, per cell.
    """
    cells = np.ascontiguousarray(cells, dtype=np.int64)
    change = np.ascontiguousarray(change, dtype=np.float64)
    flipped = np.ascontiguousarray(flipped, dtype=bool)
    if cells.ndim != 2 or change.shape != cells.shape or flipped.shape != cells.shape:
        raise ValueError(f"cells, change, flipped: expected three (H, W) images, got shapes {cells.shape}, "
                         f"{change.shape}, {flipped.shape}")
    if cells.size and cells.max() >= size:
        raise ValueError(f"cells: expected indices below {size}, got {cells.max()}")
    change_sum = np.zeros(size, dtype=np.float64)
    counted = np.zeros(size, dtype=np.int64)
    flips = np.zeros(size, dtype=np.int64)
    if cells.size:
        wp.launch(cell_sums_kernel, dim=1,
                  inputs=(host_array(cells, wp.int64), host_array(change, wp.float64), host_array(flipped, wp.bool)),
                  outputs=(host_array(change_sum, wp.float64), host_array(counted, wp.int64),
                           host_array(flips, wp.int64)), device="cpu")
    return change_sum, counted, flips


def animation_codes(lit, change, *, k: int) -> tuple[np.ndarray, np.ndarray]:
    """An animation frame's two planes: each ``k``×``k`` block's mean lit fraction and largest |change|, coded.

    Parameters
    ----------
    lit : array_like, shape (H, W)
        The lit fraction S (as float64), NaN where undefined.
    change : array_like, shape (H, W), float64
        The signed change ΔS, NaN where not counted.
    k : int, keyword-only
        Block side in pixels, 1 … 7 (a row of 8 or more NumPy sums pairwise, not left to right).

    Returns
    -------
    lit_codes, change_codes : ndarray, shape (H // k, W // k), uint8
        ``round(254 · v)`` of the block's mean S over its defined pixels and of its largest finite
        ``|ΔS|``, each clipped to [0, 1]; 255 where the block has none.
    """
    lit = np.ascontiguousarray(lit, dtype=np.float64)
    change = np.ascontiguousarray(change, dtype=np.float64)
    if lit.ndim != 2 or change.shape != lit.shape:
        raise ValueError(f"lit, change: expected two (H, W) images, got shapes {lit.shape}, {change.shape}")
    if not 1 <= k < 8:
        raise ValueError(f"k: expected a block side of 1 to 7 pixels, got {k}")
    shape = (lit.shape[0] // k, lit.shape[1] // k)
    lit_codes = np.empty(shape, dtype=np.uint8)
    change_codes = np.empty(shape, dtype=np.uint8)
    if lit_codes.size:
        wp.launch(animation_codes_kernel, dim=shape[0],
                  inputs=(host_array(lit, wp.float64), host_array(change, wp.float64), k),
                  outputs=(host_array(lit_codes, wp.uint8), host_array(change_codes, wp.uint8)), device="cpu")
    return lit_codes, change_codes


def log2_histogram(log2_values, group, defined, *, edges, groups: int) -> np.ndarray:
    """Defined pixels per bin of ``edges`` (log2 units, a power-of-two step) and group, ``(groups, len(edges) − 1)``.

    A value's bin is ``floor(v / step) − edges[0] / step`` clipped to the first and last bins, ``step`` the
    edges' spacing: exact, where shifting by the first edge before the floor could round up into the next bin.

    Parameters
    ----------
    log2_values : array_like, shape (H, W), float64
        Each pixel's value (``log2 ρ``); read where ``defined`` only.
    group : array_like, shape (H, W), integer
        Each pixel's group (a cascade), ``0 … groups − 1`` where defined.
    defined : array_like, shape (H, W), bool
        The pixels counted.
    edges : array_like, shape (B + 1,)
        Bin edges.
    groups : int, keyword-only

    Returns
    -------
    ndarray, shape (groups, B), int64

    Raises
    ------
    ValueError
        On shapes that differ, or a defined pixel's group out of range.
    """
    values = np.ascontiguousarray(log2_values, dtype=np.float64)
    defined = np.ascontiguousarray(defined, dtype=bool)
    group = np.ascontiguousarray(group)
    edges = np.asarray(edges, dtype=np.float64)
    bins = len(edges) - 1
    if defined.ndim != 2 or group.shape != defined.shape or values.shape != defined.shape:
        raise ValueError(f"log2_values, group, defined: expected three (H, W) images, got shapes {values.shape}, "
                         f"{group.shape}, {defined.shape}")
    counts = np.zeros((groups, bins), dtype=np.int64)
    outside = np.zeros(1, dtype=np.int64)
    if defined.size:
        per_step = bins / (edges[-1] - edges[0])
        wp.launch(log2_histogram_kernel, dim=1,
                  inputs=(host_array(values, wp.float64), host_array(group, wp.int32), host_array(defined, wp.bool),
                          wp.float64(per_step), wp.float64(edges[0] * per_step)),
                  outputs=(host_array(counts, wp.int64), host_array(outside, wp.int64)), device="cpu")
    if outside[0]:
        raise ValueError(f"group: expected 0 … {groups - 1} where defined, got {outside[0]} pixels outside")
    return counts
