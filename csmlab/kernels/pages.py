"""The shadow of a virtual shadow map's receivers, read through its page table (:mod:`csmlab.clipmaps`).

One thread per receiver. Its level, fixed-point texel coordinate and biased depth come from the
host (:func:`csmlab.clipmaps.read_levels`, which already checked that every tap's page is
resident). Each tap texel ``(i, j)`` of the level's global grid lies in page ``(i >> log2 S,
j >> log2 S)``; the page table gives that page's place in the pool, and the tap compares the
receiver's depth with the pool's texel there: lit when the receiver is not deeper than it (an
empty texel, +inf, is lit). ``radius`` 0 is one compare (Unreal's SMRT with no rays), otherwise
the box of ``(2 radius + 1)²`` compares of ``filter = "pcf"`` averaged.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from csmlab.kernels import checked_device

__all__ = ["page_lookup"]

wp.set_module_options({"fuse_fp": False})


@wp.kernel
def page_lookup_kernel(
    pool: wp.array3d(dtype=wp.float32),
    table: wp.array3d(dtype=wp.int32),
    origin_page: wp.array2d(dtype=wp.int64),
    level: wp.array(dtype=wp.int32),
    coordinates: wp.array2d(dtype=wp.int64),
    depth: wp.array(dtype=wp.float32),
    page_bits: wp.int64,
    bits: wp.int64,
    radius: int,
    lit: wp.array(dtype=wp.float32),
):
    k = wp.tid()
    c = level[k]
    if c < 0:
        lit[k] = wp.nan
        return
    z = depth[k]
    ti = coordinates[k, 0] >> bits
    tj = coordinates[k, 1] >> bits
    mask = (wp.int64(1) << page_bits) - wp.int64(1)
    passed = float(0.0)
    missing = int(0)
    for dj in range(-radius, radius + 1):
        for di in range(-radius, radius + 1):
            i = ti + wp.int64(di)
            j = tj + wp.int64(dj)
            px = int((i >> page_bits) - origin_page[c, 0])
            py = int((j >> page_bits) - origin_page[c, 1])
            slot = table[c, py, px]
            if slot < 0:
                missing += 1
            else:
                stored = pool[slot, int(j & mask), int(i & mask)]
                if z <= stored:
                    passed += 1.0
    side = 2 * radius + 1
    if missing > 0:
        lit[k] = wp.nan
    else:
        lit[k] = passed / float(side * side)


def page_lookup(pool, table, origin_page, level, coordinates, depth, *, radius: int, bits: int,
                device: str = "cpu") -> np.ndarray:
    """Lit fraction ``(N,)`` float32 of receivers read through a page table.

    Parameters
    ----------
    pool : array_like, shape (P, S, S), float32
        The resident pages' depths ``d·X − zref``, metres (+inf empty); ``S`` a power of two.
    table : array_like, shape (L, Q, Q), int32
        ``table[k, y, x]``: the pool index of page ``(x, y)`` of level k's box, -1 where none.
    origin_page : array_like, shape (L, 2), int64
        Each level's first page, a global page index.
    level : array_like, shape (N,), int
        Each receiver's level; -1 for none (NaN out).
    coordinates : array_like, shape (N, 2), int64
        Global fixed-point texel coordinates in ``2**-bits`` texels of the receiver's level.
    depth : array_like, shape (N,), float32
        Biased receiver depths, metres (NaN fails every compare).
    radius : int
        Taps reach ``radius`` texels about the receiver's texel.
    bits : int
    device : str

    Returns
    -------
    ndarray, shape (N,), float32
        NaN for a receiver without a level, or one whose tap lands in a page that is not resident.
    """
    device = checked_device(device)
    pool = np.ascontiguousarray(pool, dtype=np.float32)
    side = pool.shape[1]
    if pool.ndim != 3 or pool.shape[2] != side or side & (side - 1):
        raise ValueError(f"pool: expected (P, S, S) pages with S a power of two, got {pool.shape}")
    table = np.ascontiguousarray(table, dtype=np.int32)
    level = np.ascontiguousarray(level, dtype=np.int32)
    coordinates = np.ascontiguousarray(coordinates, dtype=np.int64).reshape(-1, 2)
    depth = np.ascontiguousarray(depth, dtype=np.float32)
    if level.shape != depth.shape or coordinates.shape[0] != level.shape[0]:
        raise ValueError(f"level, coordinates, depth: expected shapes (N,), (N, 2), (N,); got {level.shape}, "
                         f"{coordinates.shape}, {depth.shape}")
    count = level.shape[0]
    if count == 0:
        return np.zeros(0, dtype=np.float32)
    if len(pool) == 0:
        pool = np.full((1, side, side), np.inf, dtype=np.float32)
    lit = wp.empty(count, dtype=wp.float32, device=device)
    wp.launch(page_lookup_kernel, dim=count,
              inputs=(wp.array(pool, dtype=wp.float32, device=device),
                      wp.array(table, dtype=wp.int32, device=device),
                      wp.array(np.ascontiguousarray(origin_page, dtype=np.int64), dtype=wp.int64, device=device),
                      wp.array(level, dtype=wp.int32, device=device),
                      wp.array(coordinates, dtype=wp.int64, device=device),
                      wp.array(depth, dtype=wp.float32, device=device),
                      wp.int64(side.bit_length() - 1), wp.int64(bits), int(radius)),
              outputs=(lit,), device=device)
    return lit.numpy()
