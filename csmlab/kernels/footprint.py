"""Texel footprint of a screen pixel: the Jacobian from screen pixels to shadow-map texels.

A pixel's ray differentials ``dX/du`` and ``dX/dv`` (metres per pixel, on the hit point's tangent
plane, from :class:`csmlab.frame.GBuffer`) are mapped into the selected cascade's texel
coordinates. Light space is an orthographic projection, so the map from world metres to texels is
linear, ``T = diag(1/tx, 1/ty) · [right; up]``, and the Jacobian is exactly

    J = T · [dX/du, dX/dv]        (2 × 2, texels per pixel)

with ρ = sqrt|det J| (texels per pixel, linear) and σ_min(J) (the worst direction). Taking the
differentials on the tangent plane rather than differencing neighbouring hit points keeps J
meaningful at silhouettes (DESIGN.md, "Metrics").

References
----------
- Igehy, "Tracing Ray Differentials", SIGGRAPH 1999 — differentials on the tangent plane.
- Blinn, "Consider the Lowly 2×2 Matrix", IEEE CG&A 1996 — closed-form 2×2 singular values.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from csmlab.kernels import checked_device

__all__ = ["texel_footprint"]


@wp.func
def smallest_singular_value(a: float, b: float, c: float, d: float) -> float:
    """σ_min of ``[[a, b], [c, d]]`` from its conformal and anticonformal parts (no cancellation)."""
    e = 0.5 * (a + d)
    f = 0.5 * (a - d)
    g = 0.5 * (c + b)
    h = 0.5 * (c - b)
    q = wp.sqrt(e * e + h * h)
    r = wp.sqrt(f * f + g * g)
    return wp.abs(q - r)


@wp.kernel
def texel_footprint_kernel(
    dpdx: wp.array2d(dtype=wp.vec3),
    dpdy: wp.array2d(dtype=wp.vec3),
    cascade: wp.array2d(dtype=wp.int32),
    axis_x: wp.array(dtype=wp.vec3),
    axis_y: wp.array(dtype=wp.vec3),
    rho: wp.array2d(dtype=float),
    sigma_min: wp.array2d(dtype=float),
):
    i, j = wp.tid()
    c = cascade[i, j]
    if c < 0:
        rho[i, j] = wp.nan
        sigma_min[i, j] = wp.nan
        return
    du = dpdx[i, j]
    dv = dpdy[i, j]
    a = wp.dot(axis_x[c], du)
    b = wp.dot(axis_x[c], dv)
    cc = wp.dot(axis_y[c], du)
    d = wp.dot(axis_y[c], dv)
    rho[i, j] = wp.sqrt(wp.abs(a * d - b * cc))
    sigma_min[i, j] = smallest_singular_value(a, b, cc, d)


def texel_footprint(dpdx, dpdy, cascade, *, texel_axes, device: str = "cpu") -> tuple[np.ndarray, np.ndarray]:
    """Texels per pixel ρ = sqrt|det J| and σ_min(J) of every pixel in its selected cascade.

    Parameters
    ----------
    dpdx, dpdy : array_like, shape (H, W, 3), float32
        Ray differentials on the tangent plane toward the next pixel centre right (+x) and below
        (+y), world metres.
    cascade : array_like, shape (H, W), integer
        Selected cascade per pixel; negative where there is none (miss or outside every cascade).
    texel_axes : array_like, shape (C, 2, 3), float64
        Per cascade, the world directions of light-space x and y divided by the cascade's texel
        size along them: texels per metre (rows ``right / tx`` and ``up / ty``).
    device : str
        Warp device, ``"cpu"`` or ``"cuda"``.

    Returns
    -------
    rho : ndarray, shape (H, W), float32
        sqrt|det J|, texels per pixel (linear); NaN where ``cascade < 0``.
    sigma_min : ndarray, shape (H, W), float32
        Smallest singular value of J, texels per pixel; NaN where ``cascade < 0``.

    Raises
    ------
    ValueError
        On mismatched shapes, non-finite ``texel_axes``, a cascade index ≥ C or an unusable device.
    """
    device = checked_device(device)
    dpdx = np.ascontiguousarray(dpdx, dtype=np.float32)
    dpdy = np.ascontiguousarray(dpdy, dtype=np.float32)
    cascade = np.ascontiguousarray(cascade, dtype=np.int32)
    axes = np.asarray(texel_axes, dtype=np.float64)
    if dpdx.ndim != 3 or dpdx.shape[2] != 3 or dpdy.shape != dpdx.shape:
        raise ValueError(f"dpdx, dpdy: expected two (H, W, 3) arrays, got {dpdx.shape} and {dpdy.shape}")
    if cascade.shape != dpdx.shape[:2]:
        raise ValueError(f"cascade: expected shape {dpdx.shape[:2]}, got {cascade.shape}")
    if axes.ndim != 3 or axes.shape[1:] != (2, 3) or axes.shape[0] == 0 or not np.all(np.isfinite(axes)):
        raise ValueError(f"texel_axes: expected a finite (C, 2, 3) array with C >= 1, got shape {axes.shape}")
    if cascade.size and cascade.max() >= axes.shape[0]:
        raise ValueError(f"cascade: expected indices below {axes.shape[0]} (the cascade count), got {cascade.max()}")
    shape = cascade.shape
    rho = wp.empty(shape, dtype=float, device=device)
    sigma_min = wp.empty(shape, dtype=float, device=device)
    wp.launch(
        texel_footprint_kernel,
        dim=shape,
        inputs=(
            wp.array(dpdx, dtype=wp.vec3, device=device),
            wp.array(dpdy, dtype=wp.vec3, device=device),
            wp.array(cascade, dtype=wp.int32, device=device),
            wp.array(np.ascontiguousarray(axes[:, 0], dtype=np.float32), dtype=wp.vec3, device=device),
            wp.array(np.ascontiguousarray(axes[:, 1], dtype=np.float32), dtype=wp.vec3, device=device),
        ),
        outputs=(rho, sigma_min),
        device=device,
    )
    return rho.numpy(), sigma_min.numpy()
