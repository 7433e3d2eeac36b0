"""A map's values grouped by the cascade each pixel selected, on the host: what the aliasing summary sorts.

:func:`csmlab.metrics.aliasing.aliasing_summary` takes order statistics of ρ over every pixel with a
cascade and over the pixels of each cascade, and of σ_min over every pixel with a cascade. NumPy
gathered them with a mask, a compaction and two takes, then a mask and a compaction per cascade
(~2 ms a frame and method); :func:`values_by_cascade` writes them in one walk over the pixels.

Order statistics do not depend on the order of the values, only on the values: each group may be
partitioned in place and the whole buffer then taken as the values of every group together.
The counts below 1 and ½ are those of NumPy's comparisons of the float32 values. The arrays are
NumPy's on the host whatever the run's device: the kernel runs on the CPU.
"""

from __future__ import annotations

import numpy as np
import warp as wp

__all__ = ["values_by_cascade"]


@wp.kernel
def values_by_cascade_kernel(values: wp.array(dtype=wp.float32), other: wp.array(dtype=wp.float32),
                             cascade: wp.array(dtype=wp.int8), starts: wp.array(dtype=wp.int64),
                             grouped: wp.array(dtype=wp.float32), other_selected: wp.array(dtype=wp.float32),
                             below_one: wp.array(dtype=wp.int64), below_half: wp.array(dtype=wp.int64)):
    # One thread, the pixels in row-major order: each group's values in their order, as a mask keeps them.
    next_other = int(0)
    p = int(0)
    while p < cascade.shape[0]:
        c = int(cascade[p])
        if c >= 0:
            v = values[p]
            k = starts[c]
            grouped[k] = v
            starts[c] = k + wp.int64(1)
            other_selected[next_other] = other[p]
            next_other += 1
            if v < wp.float32(1.0):
                below_one[c] = below_one[c] + wp.int64(1)
            if v < wp.float32(0.5):
                below_half[c] = below_half[c] + wp.int64(1)
        p += 1


def values_by_cascade(values, other, cascade, *, cascades: int) -> dict[str, np.ndarray]:
    """``values`` grouped by the cascade of each pixel, and ``other`` at the pixels with a cascade.

    Parameters
    ----------
    values, other : array_like, shape (H, W), float32
        The map grouped (ρ) and a second one gathered at the pixels with a cascade (σ_min).
    cascade : array_like, shape (H, W), int8
        Each pixel's cascade, −1 where none; at most ``cascades − 1``.
    cascades : int
        The number of cascades C.

    Returns
    -------
    dict of str to ndarray
        ``grouped`` ``(N,)`` float32: the N pixels with a cascade, cascade 0's first, each group in
        row-major order; ``bounds`` ``(C + 1,)`` int64: group c is ``grouped[bounds[c]:bounds[c + 1]]``;
        ``other`` ``(N,)`` float32 in row-major order; ``below_one`` and ``below_half`` ``(C,)`` int64:
        each group's values below 1 and below ½.

    Raises
    ------
    ValueError
        On shapes that differ or a cascade index of C or more.
    """
    values = np.ascontiguousarray(values, dtype=np.float32)
    other = np.ascontiguousarray(other, dtype=np.float32)
    cascade = np.ascontiguousarray(cascade, dtype=np.int8)
    if other.shape != values.shape or cascade.shape != values.shape:
        raise ValueError(f"values, other, cascade: expected one shape, got {values.shape}, {other.shape}, "
                         f"{cascade.shape}")
    # Counted as bytes: −1 is 255, and any other byte from C on is an index the maps lack.
    sizes = np.bincount(cascade.reshape(-1).view(np.uint8), minlength=256)
    if sizes[cascades:255].any():
        bad = int(np.flatnonzero(sizes[cascades:255])[0]) + cascades
        raise ValueError(f"cascade: expected -1 or indices below {cascades}, got {bad if bad < 128 else bad - 256}")
    bounds = np.zeros(cascades + 1, dtype=np.int64)
    np.cumsum(sizes[:cascades], out=bounds[1:])
    count = int(bounds[-1])
    out = {"grouped": np.empty(count, dtype=np.float32), "bounds": bounds, "other": np.empty(count, dtype=np.float32),
           "below_one": np.zeros(cascades, dtype=np.int64), "below_half": np.zeros(cascades, dtype=np.int64)}
    if count:
        host = {"device": "cpu", "copy": False}
        wp.launch(values_by_cascade_kernel, dim=1,
                  inputs=(wp.array(values.reshape(-1), dtype=wp.float32, **host),
                          wp.array(other.reshape(-1), dtype=wp.float32, **host),
                          wp.array(cascade.reshape(-1), dtype=wp.int8, **host),
                          wp.array(bounds[:-1].copy(), dtype=wp.int64, device="cpu")),
                  outputs=tuple(wp.array(out[name], dtype=wp.dtype_from_numpy(out[name].dtype), **host)
                                for name in ("grouped", "other", "below_one", "below_half")), device="cpu")
    return out
