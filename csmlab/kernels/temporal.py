"""The temporal metric's per-pixel maps on the host: S_{t−1} placed at frame t's pixels, the change, its subsets.

:func:`csmlab.metrics.temporal.temporal_maps` looks frame t's visible points up in frame t−1's maps
(one result per visible pixel, in row-major order) and compares them with frame t's shadow. NumPy
made that a dozen whole-image passes (three scatters, the masks, the change in float64 and its NaN
fill, ~2.5 ms a frame and method); :func:`change_maps` walks the pixels once, in one thread, and
writes every map's pixel there.

Each value is the one NumPy's passes give: S widened to float64 before the subtraction, the
reference's change ``R_t − R_{t−1}`` taken first and subtracted after, each operation rounded on its
own (contraction off). The maps are read by NumPy on the host whatever the run's device: the kernel
runs on the CPU.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from csmlab.kernels import host_array

__all__ = ["change_maps"]

# Each difference rounded on its own, as NumPy rounds it.
wp.set_module_options({"fuse_fp": False})

@wp.func
def finite(x: wp.float32) -> bool:
    """``x`` is neither NaN nor infinite (``x − x`` is NaN for both; ``wp.isfinite`` is a call into the JIT's
    runtime)."""
    return x - x == wp.float32(0.0)


@wp.func
def lit_state(x: wp.float32) -> int:
    """1 where ``x > 0.5`` (lit), else 0 (NaN too)."""
    if x > wp.float32(0.5):
        return 1
    return 0


@wp.kernel
def change_maps_kernel(rows: wp.array(dtype=wp.int64), earlier_lit: wp.array(dtype=wp.float32),
                       earlier_cascade: wp.array(dtype=wp.int8), earlier_blend: wp.array(dtype=wp.bool),
                       lit: wp.array(dtype=wp.float32), cascade: wp.array(dtype=wp.int8),
                       blend: wp.array(dtype=wp.bool), light_moved: int, reference: wp.array(dtype=wp.float32),
                       previous_reference: wp.array(dtype=wp.float32), previous_lit: wp.array(dtype=wp.float32),
                       change: wp.array(dtype=wp.float64), flipped: wp.array(dtype=wp.bool),
                       counted: wp.array(dtype=wp.bool), same: wp.array(dtype=wp.bool),
                       met: wp.array(dtype=wp.int64)):
    # One thread: the pixels in order, the visible ones (``rows``, ascending) met as the walk reaches them.
    n = int(0)
    p = int(0)
    while p < lit.shape[0]:
        before = wp.float32(wp.nan)
        before_cascade = wp.int8(-1)
        before_blend = False
        visible = n < rows.shape[0]
        if visible:
            visible = rows[n] == wp.int64(p)
        if visible:
            before = earlier_lit[n]
            before_cascade = earlier_cascade[n]
            before_blend = earlier_blend[n]
            n += 1
        now = lit[p]
        is_counted = visible and before_cascade >= wp.int8(0) and finite(before) and finite(now)
        difference = wp.float64(now) - wp.float64(before)
        state_change = lit_state(now) != lit_state(before)
        if light_moved != 0:
            r = reference[p]
            r0 = previous_reference[p]
            is_counted = is_counted and finite(r) and finite(r0)
            difference = difference - (wp.float64(r) - wp.float64(r0))
            state_change = lit_state(now) - lit_state(before) != lit_state(r) - lit_state(r0)
        previous_lit[p] = before
        if is_counted:
            change[p] = difference
        else:
            change[p] = wp.float64(wp.nan)
        flipped[p] = state_change and is_counted
        counted[p] = is_counted
        same[p] = is_counted and before_cascade == cascade[p] and not before_blend and not blend[p]
        p += 1
    met[0] = wp.int64(n)


def _flat(name: str, values, dtype, size: int) -> wp.array:
    array = host_array(np.reshape(values, -1), dtype)
    if array.size != size:
        raise ValueError(f"{name}: expected {size} values, got {array.size}")
    return array


def change_maps(rows, earlier_lit, earlier_cascade, earlier_blend, *, lit, cascade, blend, reference=None,
                previous_reference=None) -> dict[str, np.ndarray]:
    """Frame t−1's shadow at frame t's pixels and the change from it to frame t's.

    Parameters
    ----------
    rows : array_like, shape (N,), integer
        The visible pixels' flat indices, ascending.
    earlier_lit, earlier_cascade, earlier_blend : array_like, shape (N,)
        S_{t−1} (float32), its cascade (int8, −1 none) and blend-band flag (bool) at each visible pixel.
    lit, cascade, blend : array_like, shape (H, W)
        Frame t's S (float32), cascade (int8) and blend flag (bool).
    reference, previous_reference : array_like, shape (H, W), float32, optional
        R_t and R_{t−1} at frame t's points when the light moved (both or neither): their change is
        subtracted and a flip is a change of state other than theirs.

    Returns
    -------
    dict of str to ndarray, each shape (H, W)
        ``previous_lit`` float32 (NaN where not visible), ``change`` float64 (NaN where not
        counted), ``flipped``, ``counted`` and ``same_cascade`` bool, as
        :class:`csmlab.metrics.temporal.TemporalMaps` defines them.

    Raises
    ------
    ValueError
        On one reference without the other, arrays of other lengths, or ``rows`` not ascending
        indices of distinct pixels of the image.
    """
    shape = np.shape(lit)
    size = int(np.prod(shape))
    rows = np.ascontiguousarray(rows, dtype=np.int64)
    count = rows.size
    if (reference is None) != (previous_reference is None):
        raise ValueError("reference, previous_reference: expected both (the light moved) or neither")
    moved = reference is not None
    if not moved:
        reference = previous_reference = np.zeros(0, dtype=np.float32)
        reference_size = 0
    else:
        reference_size = size
    out = {"previous_lit": np.empty(shape, dtype=np.float32), "change": np.empty(shape, dtype=np.float64),
           "flipped": np.empty(shape, dtype=bool), "counted": np.empty(shape, dtype=bool),
           "same_cascade": np.empty(shape, dtype=bool)}
    inputs = (host_array(rows, wp.int64),
              _flat("earlier_lit", earlier_lit, wp.float32, count),
              _flat("earlier_cascade", earlier_cascade, wp.int8, count),
              _flat("earlier_blend", earlier_blend, wp.bool, count),
              _flat("lit", lit, wp.float32, size), _flat("cascade", cascade, wp.int8, size),
              _flat("blend", blend, wp.bool, size), int(moved),
              _flat("reference", reference, wp.float32, reference_size),
              _flat("previous_reference", previous_reference, wp.float32, reference_size))
    met = np.zeros(1, dtype=np.int64)
    outputs = (*(host_array(a.reshape(-1), wp.dtype_from_numpy(a.dtype)) for a in out.values()),
               host_array(met, wp.int64))
    wp.launch(change_maps_kernel, dim=1, inputs=inputs, outputs=outputs, device="cpu")
    if met[0] != count:
        raise ValueError(f"rows: expected {count} ascending flat indices below {size}, got indices that the walk over "
                         f"the pixels met {met[0]} of")
    return out
