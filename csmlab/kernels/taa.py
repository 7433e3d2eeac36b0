"""Temporal anti-aliasing's resolve per pixel: reprojected history, disocclusion, neighbourhood clamp, blend.

One thread per pixel of frame t (docs/design.md, "The CSM model", TAA). For a pixel whose current
value c is finite and whose world point X (the G-buffer's, the jittered sample's) lies in front of
frame t−1's camera:

1. **Reprojection**: X's image point in frame t−1's un-jittered camera, ``q``, less frame t's jitter
   — where an engine's motion vector (un-jittered positions in both frames) sends the pixel:
   a static camera fetches its own pixel. The history is read bilinearly there, over the four
   pixel centres around it.
2. **Disocclusion**: a tap counts only where frame t−1's pixel saw a surface (finite history)
   at X's depth from frame t−1's camera within ``depth_tolerance`` of that depth (relative);
   the counted taps' weights are renormalised. No tap counted (or X off frame t−1's image or
   behind its camera): X was not visible, the history is dropped and the output is c.
3. **Clamp** of the history to the current 3×3 neighbourhood's finite values: ``minmax``
   (their min and max; for the grey signals csmlab resolves, the YCoCg box of an engine is its
   luma's) or ``variance`` (μ ± γσ, Salvi's variance clipping); ``none`` keeps it.
4. **Blend**: ``h + α (c − h)``.

The arithmetic is float64 with floating-point contraction off, stored in float32.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from csmlab.kernels import checked_device
from csmlab.kernels.camera import PinholeCamera, pinhole_frame
from csmlab.kernels.floats import is_finite

wp.set_module_options({"fuse_fp": False})

__all__ = ["CLAMP_CODES", "resolve_taa"]

CLAMP_CODES = {"none": 0, "minmax": 1, "variance": 2}
"""The kernel's code of each neighbourhood clamp."""

SNAP = wp.constant(wp.float64(1e-9))
"""Pixels: a reprojected point this close to a pixel centre reads that pixel alone."""


@wp.kernel
def taa_resolve_kernel(
    current: wp.array2d(dtype=wp.float32),
    position: wp.array2d(dtype=wp.vec3d),
    history: wp.array2d(dtype=wp.float32),
    history_depth: wp.array2d(dtype=wp.float32),
    camera: PinholeCamera,
    jitter_x: wp.float64,
    jitter_y: wp.float64,
    alpha: wp.float64,
    clamp: int,
    gamma: wp.float64,
    depth_tolerance: wp.float64,
    out: wp.array2d(dtype=wp.float32),
    reprojected: wp.array2d(dtype=wp.float32),
):
    row, col = wp.tid()
    height = current.shape[0]
    width = current.shape[1]
    c = wp.float64(current[row, col])
    nan = wp.float64(wp.nan)
    if not is_finite(c):
        out[row, col] = wp.float32(nan)
        reprojected[row, col] = wp.float32(nan)
        return
    p = position[row, col] - camera.eye
    z = wp.dot(p, camera.forward)
    half = wp.float64(0.5)
    total = wp.float64(0.0)
    weight = wp.float64(0.0)
    if z > wp.float64(0.0):
        # Frame t−1's image point of X in pixels (x right, y down), less frame t's jitter, less the
        # half pixel to the centres' lattice.
        fx = wp.dot(p, camera.right) / (z * camera.step_x) + half * wp.float64(width) - jitter_x - half
        fy = half * wp.float64(height) - wp.dot(p, camera.up) / (z * camera.step_y) - jitter_y - half
        if fx > wp.float64(-1.0) and fy > wp.float64(-1.0) and fx < wp.float64(width) and fy < wp.float64(height):
            # A point within SNAP of a pixel centre is at it: the projection's float64 rounding (~1e-13
            # pixel) would otherwise leak the neighbour's value at that weight, which a float32 output
            # near 0 keeps, and a static camera would not return its own history.
            x0 = int(wp.floor(fx + SNAP))
            y0 = int(wp.floor(fy + SNAP))
            ax = fx - wp.float64(x0)
            ay = fy - wp.float64(y0)
            if ax < SNAP:
                ax = wp.float64(0.0)
            if ay < SNAP:
                ay = wp.float64(0.0)
            for k in range(4):
                x = x0 + (k % 2)
                y = y0 + (k // 2)
                if x >= 0 and y >= 0 and x < width and y < height:
                    w = wp.where(k % 2 == 1, ax, wp.float64(1.0) - ax) * wp.where(k // 2 == 1, ay,
                                                                                    wp.float64(1.0) - ay)
                    h = wp.float64(history[y, x])
                    seen = wp.float64(history_depth[y, x])
                    if w > wp.float64(0.0) and is_finite(h) and is_finite(seen):
                        if wp.abs(seen - z) <= depth_tolerance * z:
                            total += w * h
                            weight += w
    if weight <= wp.float64(0.0):
        out[row, col] = wp.float32(c)
        reprojected[row, col] = wp.float32(nan)
        return
    h = total / weight
    reprojected[row, col] = wp.float32(h)
    if clamp != 0:
        lo = wp.float64(wp.inf)
        hi = -wp.float64(wp.inf)
        s1 = wp.float64(0.0)
        s2 = wp.float64(0.0)
        n = wp.float64(0.0)
        for dy in range(-1, 2):
            for dx in range(-1, 2):
                y = row + dy
                x = col + dx
                if x >= 0 and y >= 0 and x < width and y < height:
                    v = wp.float64(current[y, x])
                    if is_finite(v):
                        lo = wp.min(lo, v)
                        hi = wp.max(hi, v)
                        s1 += v
                        s2 += v * v
                        n += wp.float64(1.0)
        if clamp == 2:
            mean = s1 / n
            sigma = wp.sqrt(wp.max(s2 / n - mean * mean, wp.float64(0.0)))
            lo = mean - gamma * sigma
            hi = mean + gamma * sigma
        h = wp.min(wp.max(h, lo), hi)
    out[row, col] = wp.float32(h + alpha * (c - h))


def resolve_taa(current, *, position, history, history_depth, eye, rotation, fov_y_deg: float, aspect: float,
                jitter, alpha: float, clamp: str, gamma: float, depth_tolerance: float,
                device: str = "cpu") -> tuple[np.ndarray, np.ndarray]:
    """One TAA resolve of a grey signal: frame t's output and its reprojected history.

    Parameters
    ----------
    current : array_like, shape (H, W), float32
        Frame t's signal (a shadow S or the reference R), NaN where there is none.
    position : array_like, shape (H, W, 3), float64
        Frame t's world point per pixel, metres; NaN on a miss.
    history : array_like, shape (H, W), float32
        Frame t−1's TAA output, NaN where it had none.
    history_depth : array_like, shape (H, W), float32
        Frame t−1's view depth per pixel, metres (+inf on a miss).
    eye, rotation : array_like, shapes (3,) and (3, 3), float64
        Frame t−1's camera position (world metres) and camera-to-world rotation (columns right, up, back).
    fov_y_deg, aspect : float
        Frame t−1's vertical field of view (degrees) and width / height.
    jitter : tuple of float
        Frame t's sub-pixel jitter ``(x, y)`` in pixels (x right, y down).
    alpha : float
        Weight of the current frame in (0, 1].
    clamp : str
        A key of :data:`CLAMP_CODES`.
    gamma : float
        ``variance``: the clip box's half-width in standard deviations.
    depth_tolerance : float
        Largest relative difference between X's depth from frame t−1's camera and frame t−1's
        depth at a history tap for the tap to count.
    device : str

    Returns
    -------
    out : ndarray, shape (H, W), float32
        The resolved frame t; NaN where ``current`` is.
    reprojected : ndarray, shape (H, W), float32
        The history at X before the clamp; NaN where X was disoccluded or ``current`` is NaN.
    """
    device = checked_device(device)
    c = np.ascontiguousarray(current, dtype=np.float32)
    shape = c.shape
    pos = np.ascontiguousarray(position, dtype=np.float64)
    hist = np.ascontiguousarray(history, dtype=np.float32)
    depth = np.ascontiguousarray(history_depth, dtype=np.float32)
    if pos.shape != (*shape, 3) or hist.shape != shape or depth.shape != shape:
        raise ValueError(f"current, position, history, history_depth: expected shapes (H, W), (H, W, 3), (H, W), "
                         f"(H, W); got {shape}, {pos.shape}, {hist.shape}, {depth.shape}")
    height, width = shape
    camera = pinhole_frame(eye, rotation, fov_y_deg, aspect, width, height)
    out = wp.empty(shape, dtype=wp.float32, device=device)
    reprojected = wp.empty(shape, dtype=wp.float32, device=device)
    wp.launch(taa_resolve_kernel, dim=shape,
              inputs=(wp.array(c, dtype=wp.float32, device=device), wp.array(pos, dtype=wp.vec3d, device=device),
                      wp.array(hist, dtype=wp.float32, device=device), wp.array(depth, dtype=wp.float32, device=device),
                      camera, float(jitter[0]), float(jitter[1]), float(alpha), int(CLAMP_CODES[clamp]), float(gamma),
                      float(depth_tolerance)),
              outputs=(out, reprojected), device=device)
    return out.numpy(), reprojected.numpy()
