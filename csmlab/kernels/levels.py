"""The level each receiver of a virtual shadow map's clipmap reads (:mod:`csmlab.clipmaps`), one thread per receiver.

A receiver tries the levels from the one its distance wants to the coarsest: at level k it is moved
``normal_offset`` texels along its normal, rounded to the global ``2**-bits`` grid of the level's
texel, and its depth pulled toward the light by ``bias_constant + bias_slope · texel · tan θ``
(tan clamped to 10, NaN when turned from the light); it keeps the first level whose box holds the
pages under the four corners of its taps (``radius`` texels about its own) and, with a page table,
whose table holds all four. The same float64 operations in the same order as the host reference
:func:`csmlab.clipmaps.chosen_levels`, without contraction, so the bits equal it on every device.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from csmlab.kernels import checked_device, device_empty

__all__ = ["MAX_TAN", "receiver_levels"]

# Products and sums rounded one by one on both devices (clang and NVRTC may otherwise contract them).
wp.set_module_options({"fuse_fp": False})

MAX_TAN = 10.0
"""The slope-scaled bias's tan θ is clamped to this, as the cascades' (:func:`csmlab.texels.receiver_lookup`)."""


@wp.func
def slope_tan(cos: wp.float64) -> wp.float64:
    """``tan θ`` of a receiver whose normal makes ``cos θ`` with the direction toward the light, clamped to
    :data:`MAX_TAN`; NaN where ``cos θ ≤ 0`` (or NaN): turned from the light."""
    if cos > wp.float64(0.0):
        return wp.min(wp.sqrt(wp.max(wp.float64(1.0) - cos * cos, wp.float64(0.0))) / cos, wp.float64(MAX_TAN))
    return wp.float64(wp.nan)


@wp.func
def page_held(table: wp.array3d(dtype=wp.int32), k: int, x: wp.int64, y: wp.int64, side: wp.int64,
              use_table: int) -> bool:
    """Whether local page ``(x, y)`` lies in level k's box of ``side`` pages and (``use_table``) is resident."""
    if x < wp.int64(0) or y < wp.int64(0) or x >= side or y >= side:
        return False
    if use_table == 0:
        return True
    return table[k, int(y), int(x)] >= 0


@wp.kernel
def receiver_levels_kernel(
    light_points: wp.array2d(dtype=wp.float64),
    light_normals: wp.array2d(dtype=wp.float64),
    wanted: wp.array(dtype=wp.int64),
    texel: wp.array(dtype=wp.float64),
    origin_page: wp.array2d(dtype=wp.int64),
    table: wp.array3d(dtype=wp.int32),
    use_table: int,
    side: wp.int64,
    normal_offset: wp.float64,
    zref: wp.float64,
    bias_constant: wp.float64,
    bias_slope: wp.float64,
    scale: wp.float64,
    bits: wp.int64,
    page_bits: wp.int64,
    radius: wp.int64,
    level: wp.array(dtype=wp.int64),
    coordinates: wp.array2d(dtype=wp.int64),
    depth: wp.array(dtype=wp.float32),
):
    i = wp.tid()
    px = light_points[i, 0]
    py = light_points[i, 1]
    pz = light_points[i, 2]
    nx = light_normals[i, 0]
    ny = light_normals[i, 1]
    nz = light_normals[i, 2]
    tan = slope_tan(-nz)
    level[i] = wp.int64(-1)
    coordinates[i, 0] = wp.int64(0)
    coordinates[i, 1] = wp.int64(0)
    depth[i] = wp.float32(wp.nan)
    for k in range(int(wanted[i]), texel.shape[0]):
        t = texel[k]
        offset = normal_offset * t
        mx = px + nx * offset
        my = py + ny * offset
        mz = pz + nz * offset
        cx = wp.int64(wp.rint(mx / t * scale))
        cy = wp.int64(wp.rint(my / t * scale))
        # The taps' corner texels' pages, floored (arithmetic shifts), less the level's first page.
        lo_x = (((cx >> bits) - radius) >> page_bits) - origin_page[k, 0]
        hi_x = (((cx >> bits) + radius) >> page_bits) - origin_page[k, 0]
        lo_y = (((cy >> bits) - radius) >> page_bits) - origin_page[k, 1]
        hi_y = (((cy >> bits) + radius) >> page_bits) - origin_page[k, 1]
        if (page_held(table, k, lo_x, lo_y, side, use_table) and page_held(table, k, hi_x, lo_y, side, use_table)
                and page_held(table, k, lo_x, hi_y, side, use_table)
                and page_held(table, k, hi_x, hi_y, side, use_table)):
            level[i] = wp.int64(k)
            coordinates[i, 0] = cx
            coordinates[i, 1] = cy
            depth[i] = wp.float32(mz - zref - (bias_constant + bias_slope * t * tan))
            return


def receiver_levels(light_points, light_normals, wanted, *, texel, origin_page, page_size: int, pages_per_side: int,
                    table, normal_offset: float, zref: float, bias_constant: float, bias_slope: float, bits: int,
                    radius: int, device: str = "cpu") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The level each receiver reads, and its fixed-point texel coordinates and biased depth there.

    Parameters
    ----------
    light_points, light_normals : array_like, shape (N, 3), float64
        Receivers and their unit normals in light space (x, y, ``dot(X, d)``, metres).
    wanted : array_like, shape (N,), int
        The level index each receiver starts from, ``>= 0`` (one past the last: none).
    texel : array_like, shape (L,), float64
        Metres per texel of each level.
    origin_page : array_like, shape (L, 2), int64
        Each level's first page, a global page index along light x, y.
    page_size : int
        Texels per side of a page, a power of two.
    pages_per_side : int
        Pages per side of a level's box.
    table : array_like, shape (L, pages_per_side, pages_per_side), int32, or None
        ``table[k, y, x] >= 0`` where page ``(x, y)`` of level k's box is resident; None: every page
        of a box counts as held (marking).
    normal_offset, zref, bias_constant, bias_slope : float
        Texels of normal offset; depth offset, constant bias and slope bias in metres.
    bits : int
        Sub-texel bits of the fixed point.
    radius : int
        Texels the taps reach about the receiver's texel, ``>= 0``.
    device : str

    Returns
    -------
    level : ndarray, shape (N,), int64
        -1 where no level holds the taps.
    coordinates : ndarray, shape (N, 2), int64
        Global fixed-point coordinates in ``2**-bits`` texels of that level (0 where none).
    depth : ndarray, shape (N,), float32
        ``d·X' − zref − bias`` in metres (NaN where none, or turned from the light).
    """
    device = checked_device(device)
    points = np.ascontiguousarray(light_points, dtype=np.float64)
    normals = np.ascontiguousarray(light_normals, dtype=np.float64)
    wanted = np.ascontiguousarray(wanted, dtype=np.int64)
    texel = np.ascontiguousarray(texel, dtype=np.float64)
    origin_page = np.ascontiguousarray(origin_page, dtype=np.int64)
    count, levels = wanted.shape[0], texel.shape[0]
    if points.shape != (count, 3) or normals.shape != (count, 3) or wanted.ndim != 1:
        raise ValueError(f"light_points, light_normals, wanted: expected shapes (N, 3), (N, 3), (N,); got "
                         f"{points.shape}, {normals.shape}, {wanted.shape}")
    if texel.ndim != 1 or origin_page.shape != (levels, 2):
        raise ValueError(f"texel, origin_page: expected shapes (L,), (L, 2); got {texel.shape}, {origin_page.shape}")
    if page_size < 1 or page_size & (page_size - 1) or pages_per_side < 1 or radius < 0 or bits < 0:
        raise ValueError(f"page_size, pages_per_side, radius, bits: expected a power of two, >= 1, >= 0, >= 0; got "
                         f"{page_size}, {pages_per_side}, {radius}, {bits}")
    if count and wanted.min() < 0:
        raise ValueError(f"wanted: expected level indices >= 0, got {wanted.min()}")
    if table is None:
        held = np.full((1, 1, 1), -1, dtype=np.int32)
    else:
        held = np.ascontiguousarray(table, dtype=np.int32)
        if held.shape != (levels, pages_per_side, pages_per_side):
            raise ValueError(f"table: expected shape {(levels, pages_per_side, pages_per_side)}, got {held.shape}")
    level = device_empty(count, wp.int64, device)
    coordinates = device_empty((count, 2), wp.int64, device)
    depth = device_empty(count, wp.float32, device)
    if count:
        wp.launch(receiver_levels_kernel, dim=count,
                  inputs=(wp.array(points, dtype=wp.float64, device=device),
                          wp.array(normals, dtype=wp.float64, device=device),
                          wp.array(wanted, dtype=wp.int64, device=device),
                          wp.array(texel, dtype=wp.float64, device=device),
                          wp.array(origin_page, dtype=wp.int64, device=device),
                          wp.array(held, dtype=wp.int32, device=device), int(table is not None),
                          wp.int64(pages_per_side), wp.float64(normal_offset), wp.float64(zref),
                          wp.float64(bias_constant), wp.float64(bias_slope), wp.float64(float(2**bits)),
                          wp.int64(bits), wp.int64(page_size.bit_length() - 1), wp.int64(radius)),
                  outputs=(level, coordinates, depth), device=device)
    return level.numpy(), coordinates.numpy(), depth.numpy()
