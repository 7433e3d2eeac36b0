"""How far a change reaches through separable filters: masks grown along one axis at a time.

A separable filter of radius r, its taps clamped to the image (or reflected at its edge), gives a
pixel a value that depends only on the pixels within r of it along the axis it filters, inside the
image. :func:`nested_reach` follows a change through a sequence of such passes, as the kernels
that skip what no change reaches need it (:func:`csmlab.kernels.flip.flip_reach`,
:func:`csmlab.kernels.ssim.ssim_reach`).
"""

from __future__ import annotations

import numpy as np

__all__ = ["grown_along", "nested_reach"]


def grown_along(mask, radius: int, axis: int) -> np.ndarray:
    """``mask`` (bool, any shape) grown by ``radius`` (≥ 0) along ``axis``, the window clipped to the array.

    A pixel is set where any pixel within ``radius`` of it along ``axis`` is: the maximum filter
    of size ``2·radius + 1`` (``scipy.ndimage.maximum_filter1d``, whose ``nearest`` edge repeats a
    value the clipped window already holds). Grown by shifts of 1, 2, 4, … (the last cut to what is
    left): a few whole-array ORs of bytes, where the filter walks every line.
    """
    if radius < 0:
        raise ValueError(f"radius: expected an integer >= 0, got {radius}")
    out = np.array(mask, dtype=bool, copy=True)
    size = out.shape[axis]
    reached, step = 0, 1
    while reached < radius and reached < size - 1:
        shift = min(step, radius - reached, size - 1)
        before = out.copy()
        later = [slice(None)] * out.ndim
        earlier = list(later)
        later[axis] = slice(shift, None)
        earlier[axis] = slice(None, -shift)
        out[tuple(later)] |= before[tuple(earlier)]
        out[tuple(earlier)] |= before[tuple(later)]
        reached += shift
        step *= 2
    return out


def nested_reach(changed, radius: int, axes: tuple[int, ...]) -> np.ndarray:
    """``(H, W)`` uint8: how many of the nested levels of ``changed`` each pixel lies in.

    Level 0 is ``changed`` (bool ``(H, W)``); level k is level k − 1 grown by ``radius`` along
    ``axes[k − 1]`` (:func:`grown_along`). The levels nest, so a pixel's count says which it lies in.
    """
    level = np.asarray(changed, dtype=bool)
    reach = level.astype(np.uint8)
    for axis in axes:
        level = grown_along(level, radius, axis)
        reach += level.view(np.uint8)
    return reach
