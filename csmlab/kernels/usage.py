"""Which texels of each cascade the visible pixels look up (the ``utilization`` metric's count).

A pixel looks up the texel that contains its surface point: ``floor`` of the point's texel
coordinates in its selected cascade, ``(light x/y) / texel size − box origin``
(:func:`csmlab.texels.texel_coordinates`, whose operations the kernel repeats in the same order, so
the floors are the same). One thread per pixel marks its texel in a per-cascade bitmap, one bit a
texel (an atomic OR on a GPU, where two pixels may mark bits of one word at once), and the marks
are counted once. A bit, not a byte, a texel: 4 × 1024² marks take 512 KB rather than 4 MB, to
clear, to mark (in a CPU's caches) and to count (3.1 → 2.4 ms a call on the default run).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from csmlab.kernels import checked_device

__all__ = ["looked_up_texels"]

# Products and sums rounded one by one on both devices (clang and NVRTC may otherwise contract them): a
# CUDA build may not contract them into fused multiply-adds, or its bits differ from the CPU's.
wp.set_module_options({"fuse_fp": False})


@wp.func
def mark_texel(p: wp.vec3d, c: int, rows: wp.mat22d, rows_z: wp.vec2d, texel_size: wp.array2d(dtype=wp.float64),
               origin: wp.array2d(dtype=wp.float64), resolution: wp.array(dtype=wp.int32),
               marked: wp.array3d(dtype=wp.uint32)):
    """Set the bit of the texel of cascade c that world point ``p`` lies in, if inside the cascade's map."""
    # (x·r_x + z·r_z) + y·r_y per light axis, as csmlab.texels._light_space sums it.
    u = (p[0] * rows[0, 0] + p[2] * rows_z[0]) + p[1] * rows[0, 1]
    v = (p[0] * rows[1, 0] + p[2] * rows_z[1]) + p[1] * rows[1, 1]
    i = wp.floor(u / texel_size[c, 0] - origin[c, 0])
    j = wp.floor(v / texel_size[c, 1] - origin[c, 1])
    size = wp.float64(resolution[c])
    if i >= wp.float64(0.0) and i < size and j >= wp.float64(0.0) and j < size:
        column = int(i)
        wp.atomic_or(marked, c, int(j), column >> 5, wp.uint32(1) << wp.uint32(column & 31))


@wp.kernel
def mark_texels_kernel(
    points: wp.array(dtype=wp.vec3d),
    cascade: wp.array(dtype=wp.int32),
    rows: wp.mat22d,
    rows_z: wp.vec2d,
    texel_size: wp.array2d(dtype=wp.float64),
    origin: wp.array2d(dtype=wp.float64),
    resolution: wp.array(dtype=wp.int32),
    run: int,
    marked: wp.array3d(dtype=wp.uint32),
):
    # A thread per run of ``run`` points: on the CPU many, so that a thread's start, which copies every
    # argument, serves them all; on a GPU one.
    k = wp.tid() * run
    end = wp.min(k + run, points.shape[0])
    while k < end:
        c = cascade[k]
        if c >= 0:
            mark_texel(points[k], c, rows, rows_z, texel_size, origin, resolution, marked)
        k += 1


_POINT_RUN = 256
"""Points a CPU thread of :func:`mark_texels_kernel` marks (a GPU thread one)."""


def looked_up_texels(points, cascade, *, basis, texel_size, origin, resolution, device: str = "cpu") -> np.ndarray:
    """Distinct texels of each cascade that the points look up, ``(C,)`` int64.

    Parameters
    ----------
    points : array_like, shape (N, 3), float64
        World positions in metres.
    cascade : array_like, shape (N,), integer
        Each point's selected cascade; −1 for none (not counted).
    basis : array_like, shape (3, 3), float64
        The light basis (rows x, y, light direction; :attr:`csmlab.cascades.CascadeSet.basis`).
    texel_size : array_like, shape (C, 2), float64
        Metres per texel.
    origin : array_like, shape (C, 2), float64
        Box minimum corners in texels.
    resolution : array_like, shape (C,), integer
        Texels per side of each cascade; a point outside ``[0, R)²`` is not counted.
    device : str

    Returns
    -------
    ndarray, shape (C,), int64
    """
    device = checked_device(device)
    p = np.ascontiguousarray(points, dtype=np.float64)
    selected = np.ascontiguousarray(cascade, dtype=np.int32)
    rows = np.asarray(basis, dtype=np.float64)
    size = np.ascontiguousarray(texel_size, dtype=np.float64)
    corner = np.ascontiguousarray(origin, dtype=np.float64)
    sides = np.ascontiguousarray(resolution, dtype=np.int32)
    count = size.shape[0] if size.ndim == 2 else 0
    if p.ndim != 2 or p.shape[1] != 3 or selected.shape != (p.shape[0],) or rows.shape != (3, 3) \
            or size.shape != (count, 2) or corner.shape != (count, 2) or sides.shape != (count,) or count == 0:
        raise ValueError(f"points, cascade, basis, texel_size, origin, resolution: expected shapes (N, 3), (N,), "
                         f"(3, 3), (C, 2), (C, 2), (C,); got {p.shape}, {selected.shape}, {rows.shape}, {size.shape}, "
                         f"{corner.shape}, {sides.shape}")
    if selected.size and selected.max() >= count:
        raise ValueError(f"cascade: expected indices below {count}, got {selected.max()}")
    largest = int(sides.max())
    marked = wp.zeros((count, largest, -(-largest // 32)), dtype=wp.uint32, device=device)
    if p.shape[0]:
        run = _POINT_RUN if wp.get_device(device).is_cpu else 1
        wp.launch(mark_texels_kernel, dim=-(-p.shape[0] // run),
                  inputs=(wp.array(p, dtype=wp.vec3d, device=device, copy=False),
                          wp.array(selected, dtype=wp.int32, device=device, copy=False),
                          wp.mat22d(rows[0, 0], rows[0, 1], rows[1, 0], rows[1, 1]), wp.vec2d(rows[0, 2], rows[1, 2]),
                          wp.array(size, dtype=wp.float64, device=device),
                          wp.array(corner, dtype=wp.float64, device=device),
                          wp.array(sides, dtype=wp.int32, device=device), run),
                  outputs=(marked,), device=device)
    marks = marked.numpy()
    return np.bitwise_count(marks).reshape(count, -1).sum(axis=1, dtype=np.int64)
