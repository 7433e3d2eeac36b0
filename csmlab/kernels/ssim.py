"""SSIM map of two grey images, operation for operation as scikit-image, only where a change reaches.

:func:`ssim_where_changed` gives the map of ``skimage.metrics.structural_similarity(previous,
current, data_range=1, gaussian_weights=True, sigma=1.5, use_sample_covariance=False,
full=True)`` (``skimage/metrics/_structural_similarity.py``) bit for bit, in two kernels:

1. ``vertical_kernel`` — SciPy's ``gaussian_filter`` first filters along axis 0 (rows of the
   image index i): ``correlate1d`` with the symmetric 11-tap Gaussian (σ = 1.5, truncated at 3.5 σ,
   mode ``reflect``), which SciPy sums as ``x₀·w₀`` then ``+ (x₋ₖ + xₖ)·wₖ`` for k = r … 1
   (``NI_Correlate1D`` of ``ni_filters.c``), in float64 — of the five images SSIM filters:
   previous, current, their squares and their product.
2. ``horizontal_kernel`` — the same filter along axis 1 of those five, then scikit-image's
   arithmetic in its order: ``v = 1·(u₂ − u·u)``, ``A1 = 2·ux·uy + C1``, ``A2 = 2·vxy + C2``,
   ``B1 = ux² + uy² + C1``, ``B2 = vx + vy + C2``, ``S = (A1·A2) / (B1·B2)``.

Where the two images agree over a pixel's whole 11 × 11 support, both images' filtered values are
equal, A1 = B1 and A2 = B2, and S is exactly 1 (the identity :mod:`csmlab.metrics.perceptual`'s
windows rest on): the kernels compute only what a change reaches — the first pass of the current
image (and of the products) within 5 rows of a change and the previous image's where the second
pass reads it; elsewhere the map is 1. So a frame whose shadow changed at 1 % of its pixels costs
a fifth of the image, not the whole, and no windows.

Products and sums are rounded one by one (``fuse_fp`` off), as NumPy and SciPy's C round them.
"""

from __future__ import annotations

import functools

import numpy as np
import warp as wp
from scipy.ndimage import gaussian_filter1d

from csmlab.kernels import checked_device
from csmlab.kernels.reach import nested_reach

__all__ = ["SSIM_RADIUS", "SSIM_SIGMA", "ssim_reach", "ssim_where_changed"]

# NumPy and SciPy multiply and add separately; an FMA would round differently.
wp.set_module_options({"fuse_fp": False})

SSIM_SIGMA: float = 1.5
"""σ in pixels of the Gaussian window (Wang et al. 2004; scikit-image's default)."""

_TRUNCATE = 3.5
SSIM_RADIUS: int = int(_TRUNCATE * SSIM_SIGMA + 0.5)
"""Radius in pixels of the window, as ``ndimage`` rounds it (11 × 11 taps)."""

_K1, _K2, _DATA_RANGE = 0.01, 0.03, 1.0

# Levels of :func:`ssim_reach`.
FIRST_PASS = wp.constant(1)
SECOND_PASS = wp.constant(2)
BOTH_DIFFER = wp.constant(3)


@wp.func
def reflected(index: int, size: int) -> int:
    """``ndimage``'s ``reflect`` mode (d c b a | a b c d | d c b a) for an index within one size of the image."""
    if index < 0:
        return -index - 1
    if index >= size:
        return 2 * size - index - 1
    return index


@wp.func
def vertical_previous(previous: wp.array2d(dtype=wp.float64), i: int, j: int, weights: wp.array(dtype=wp.float64),
                      radius: int):
    """Axis-0 ``correlate1d`` at (i, j) of ``previous`` and ``previous²``, in one walk over the taps."""
    rows = previous.shape[0]
    x = previous[i, j]
    w = weights[0]
    ux = x * w
    uxx = (x * x) * w
    k = radius
    while k >= 1:
        left = previous[reflected(i - k, rows), j]
        right = previous[reflected(i + k, rows), j]
        w = weights[k]
        ux = ux + (left + right) * w
        uxx = uxx + (left * left + right * right) * w
        k -= 1
    return ux, uxx


@wp.func
def vertical_both(previous: wp.array2d(dtype=wp.float64), current: wp.array2d(dtype=wp.float64), i: int, j: int,
                  weights: wp.array(dtype=wp.float64), radius: int):
    """Axis-0 ``correlate1d`` at (i, j) of the five planes, in one walk over the taps (each sum in
    SciPy's order, as a walk of its own): previous, current, their squares and their product."""
    rows = previous.shape[0]
    x = previous[i, j]
    y = current[i, j]
    w = weights[0]
    ux = x * w
    uy = y * w
    uxx = (x * x) * w
    uyy = (y * y) * w
    uxy = (x * y) * w
    k = radius
    while k >= 1:
        a = reflected(i - k, rows)
        b = reflected(i + k, rows)
        xa = previous[a, j]
        xb = previous[b, j]
        ya = current[a, j]
        yb = current[b, j]
        w = weights[k]
        ux = ux + (xa + xb) * w
        uy = uy + (ya + yb) * w
        uxx = uxx + (xa * xa + xb * xb) * w
        uyy = uyy + (ya * ya + yb * yb) * w
        uxy = uxy + (xa * ya + xb * yb) * w
        k -= 1
    return ux, uy, uxx, uyy, uxy


@wp.func
def vertical_pixel(previous: wp.array2d(dtype=wp.float64), current: wp.array2d(dtype=wp.float64), level: int, i: int,
                   j: int, weights: wp.array(dtype=wp.float64), radius: int, filtered: wp.array3d(dtype=wp.float64)):
    """The five planes' axis-0 pass at (i, j), written to ``filtered``."""
    if level >= BOTH_DIFFER:
        ux, uy, uxx, uyy, uxy = vertical_both(previous, current, i, j, weights, radius)
        filtered[0, i, j] = ux
        filtered[1, i, j] = uy
        filtered[2, i, j] = uxx
        filtered[3, i, j] = uyy
        filtered[4, i, j] = uxy
        return
    # No change within the column's support: the current image, its square and the product are
    # the previous image and its square there.
    ux, uxx = vertical_previous(previous, i, j, weights, radius)
    filtered[0, i, j] = ux
    filtered[1, i, j] = ux
    filtered[2, i, j] = uxx
    filtered[3, i, j] = uxx
    filtered[4, i, j] = uxx


@wp.kernel
def vertical_kernel(previous: wp.array2d(dtype=wp.float64), current: wp.array2d(dtype=wp.float64),
                    reach: wp.array2d(dtype=wp.uint8), weights: wp.array(dtype=wp.float64), radius: int, run: int,
                    filtered: wp.array3d(dtype=wp.float64)):
    # Planes: previous, current, previous², current², previous·current. A thread per run of ``run``
    # pixels of a row: on the CPU the whole row, so that a thread's start, which copies every
    # argument, serves them all; on a GPU one.
    i, k = wp.tid()
    j = k * run
    end = wp.min(j + run, reach.shape[1])
    while j < end:
        level = int(reach[i, j])
        if level >= FIRST_PASS:
            vertical_pixel(previous, current, level, i, j, weights, radius, filtered)
        j += 1


@wp.func
def horizontal_pixel(filtered: wp.array3d(dtype=wp.float64), i: int, j: int, weights: wp.array(dtype=wp.float64),
                     radius: int, c1: wp.float64, c2: wp.float64) -> wp.float64:
    """The SSIM at (i, j) from the five planes' axis-0 pass."""
    # Axis-1 ``correlate1d`` at (i, j) of the five planes of the first pass, in one walk over the taps.
    columns = filtered.shape[2]
    w = weights[0]
    ux = filtered[0, i, j] * w
    uy = filtered[1, i, j] * w
    uxx = filtered[2, i, j] * w
    uyy = filtered[3, i, j] * w
    uxy = filtered[4, i, j] * w
    k = radius
    while k >= 1:
        a = reflected(j - k, columns)
        b = reflected(j + k, columns)
        w = weights[k]
        ux = ux + (filtered[0, i, a] + filtered[0, i, b]) * w
        uy = uy + (filtered[1, i, a] + filtered[1, i, b]) * w
        uxx = uxx + (filtered[2, i, a] + filtered[2, i, b]) * w
        uyy = uyy + (filtered[3, i, a] + filtered[3, i, b]) * w
        uxy = uxy + (filtered[4, i, a] + filtered[4, i, b]) * w
        k -= 1
    # use_sample_covariance=False: cov_norm = 1.0.
    one = wp.float64(1.0)
    two = wp.float64(2.0)
    vx = one * (uxx - ux * ux)
    vy = one * (uyy - uy * uy)
    vxy = one * (uxy - ux * uy)
    a1 = two * ux * uy + c1
    a2 = two * vxy + c2
    b1 = ux * ux + uy * uy + c1
    b2 = vx + vy + c2
    d = b1 * b2
    return (a1 * a2) / d


@wp.kernel
def horizontal_kernel(filtered: wp.array3d(dtype=wp.float64), reach: wp.array2d(dtype=wp.uint8),
                      weights: wp.array(dtype=wp.float64), radius: int, c1: wp.float64, c2: wp.float64, run: int,
                      ssim: wp.array2d(dtype=wp.float64)):
    # A thread per run of a row's pixels, as vertical_kernel.
    i, k = wp.tid()
    j = k * run
    end = wp.min(j + run, reach.shape[1])
    while j < end:
        # Below SECOND_PASS the images are equal over the whole support: A1 = B1, A2 = B2.
        value = wp.float64(1.0)
        if int(reach[i, j]) >= SECOND_PASS:
            value = horizontal_pixel(filtered, i, j, weights, radius, c1, c2)
        ssim[i, j] = value
        j += 1


@functools.lru_cache(maxsize=1)
def _weights() -> np.ndarray:
    """``(r + 1,)`` float64: SciPy's Gaussian taps at distance 0 … r, read off its impulse response
    (each output of an impulse is one tap times 1, plus zeros: the taps exactly)."""
    impulse = np.zeros(2 * SSIM_RADIUS + 1)
    impulse[SSIM_RADIUS] = 1.0
    response = gaussian_filter1d(impulse, SSIM_SIGMA, truncate=_TRUNCATE, mode="constant")
    return np.ascontiguousarray(response[SSIM_RADIUS:])


def ssim_reach(changed) -> np.ndarray:
    """How near each pixel lies to a change, as the two passes need to know, ``(H, W)`` uint8.

    Each level is the previous grown by :data:`SSIM_RADIUS`, first along axis 0 then twice along
    axis 1, and a pixel holds the number of them it lies in: 4 changed; 3 (``BOTH_DIFFER``) within
    the radius of a change along its column — the first pass differs; 2 (``SECOND_PASS``) the SSIM
    may differ from 1; 1 (``FIRST_PASS``) the second pass reads its first pass; 0 nothing.
    """
    return nested_reach(changed, SSIM_RADIUS, (0, 1, 1))


def ssim_where_changed(previous, current, changed, *, device: str = "cpu") -> np.ndarray:
    """scikit-image's SSIM map ``(H, W)`` float64 of two grey images, computed where ``changed`` reaches.

    Parameters
    ----------
    previous, current : array_like, shape (H, W)
        The two images (converted to float64), ``data_range`` 1; both sides at least 11 pixels.
    changed : array_like, shape (H, W), bool
        Where the two differ (a superset is fine: only the cost grows).
    device : str
        Warp device.

    Returns
    -------
    ndarray, shape (H, W), float64
        ``structural_similarity(previous, current, data_range=1, gaussian_weights=True, sigma=1.5,
        use_sample_covariance=False, full=True)[1]``, bit for bit; exactly 1 out of a change's reach.

    Raises
    ------
    ValueError
        On shapes that differ or are not 2-D, a side below 11 pixels, or a ``changed`` of another shape.
    """
    device = checked_device(device)
    previous = np.ascontiguousarray(previous, dtype=np.float64)
    current = np.ascontiguousarray(current, dtype=np.float64)
    changed = np.asarray(changed, dtype=bool)
    if previous.ndim != 2 or current.shape != previous.shape or changed.shape != previous.shape:
        raise ValueError(f"previous, current, changed: expected three (H, W) arrays of one shape, got "
                         f"{previous.shape}, {current.shape}, {changed.shape}")
    if min(previous.shape) < 2 * SSIM_RADIUS + 1:
        raise ValueError(f"previous: expected sides of at least {2 * SSIM_RADIUS + 1} pixels, got {previous.shape}")
    height, width = previous.shape
    # The checked arrays are read in place where the device can (the CPU), not copied again.
    reach = wp.array(ssim_reach(changed), dtype=wp.uint8, device=device, copy=False)
    weights = wp.array(_weights(), dtype=wp.float64, device=device)
    filtered = wp.empty((5, height, width), dtype=wp.float64, device=device)
    run = width if wp.get_device(device).is_cpu else 1
    runs = (height, -(-width // run))
    wp.launch(vertical_kernel, dim=runs,
              inputs=(wp.array(previous, dtype=wp.float64, device=device, copy=False),
                      wp.array(current, dtype=wp.float64, device=device, copy=False), reach, weights, SSIM_RADIUS,
                      run),
              outputs=(filtered,), device=device)
    ssim = wp.empty((height, width), dtype=wp.float64, device=device)
    c1 = (_K1 * _DATA_RANGE) ** 2
    c2 = (_K2 * _DATA_RANGE) ** 2
    wp.launch(horizontal_kernel, dim=runs, inputs=(filtered, reach, weights, SSIM_RADIUS, c1, c2, run),
              outputs=(ssim,), device=device)
    return ssim.numpy()
