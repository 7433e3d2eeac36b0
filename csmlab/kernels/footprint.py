"""Texel footprint of a screen pixel: the Jacobian from screen pixels to shadow-map texels.

:func:`surface_differentials` gives a pixel's exact ray differentials ``dX/du`` and ``dX/dv``
(metres per pixel): the derivatives of the hit point with respect to the pixel coordinates at the
pixel centre, from the derivative of the ray direction transferred to the hit surface's tangent
plane (Igehy 1999). With ``V = X − C`` the hit relative to the eye, ``t = V·f`` its view depth
(the ray direction ``D = V/t`` has unit forward component), ``∂D/∂u`` the change of ``D`` per pixel
and ``n`` the surface normal,

    dX/du = t · (∂D/∂u − D (n·∂D/∂u) / (n·D)),

exact for any surface, not a finite difference: differencing the hit points of neighbouring pixel
centres (a one-pixel forward difference) under-estimates the footprint on a plane by the factor
``D_n / (D_n + δ)`` per axis, where ``D_n`` is ``n·D`` and ``δ`` its change over one pixel — without
bound toward the horizon, where perspective aliasing lives.

:func:`texel_footprint` maps the differentials into the selected cascade's texel coordinates. For an
orthographic cascade the map from world metres to texels is linear, ``T = diag(1/tx, 1/ty) · [right; up]``,
and the Jacobian is exactly

    J = T · [dX/du, dX/dv]        (2 × 2, texels per pixel)

with ρ = sqrt|det J| (texels per pixel, linear) and σ_min(J) (the worst direction). Taking the
differentials on the tangent plane rather than differencing neighbouring hit points keeps J
meaningful at silhouettes (docs/design.md, "Metrics"). A perspective-warped cascade (LiSPSM,
:mod:`csmlab.cascades.warp`) maps through a homography whose Jacobian changes from point to point:
:func:`warped_texel_footprint` evaluates it at each pixel's point.

References
----------
- Igehy, "Tracing Ray Differentials", SIGGRAPH 1999 — differentials on the tangent plane.
- Blinn, "Consider the Lowly 2×2 Matrix", IEEE CG&A 1996 — closed-form 2×2 singular values.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from csmlab.kernels import checked_device
from csmlab.kernels.floats import is_finite

__all__ = ["surface_differentials", "texel_footprint", "warped_texel_footprint"]

# Products and sums rounded one by one on both devices (clang and NVRTC may otherwise contract them): a
# CUDA build may not contract them into fused multiply-adds, or its bits differ from the CPU's.
wp.set_module_options({"fuse_fp": False})


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


@wp.func
def transferred_differential(v: wp.vec3d, n: wp.vec3d, t: wp.float64, step: wp.vec3d) -> wp.vec3d:
    """dX for a change ``step`` of the unit-forward ray direction, on the plane through the hit with normal ``n``.

    ``t·step − V (n·t·step)/(n·V)``; a ray lying in the plane (``n·V = 0``, an edge-on hit of zero
    measure) has no transfer, and keeps ``t·step``.
    """
    d = step * t
    along = wp.dot(n, v)
    if along == wp.float64(0.0):
        return d
    return d - v * (wp.dot(n, d) / along)


@wp.func
def finite_difference(a: wp.float64, b: wp.float64) -> wp.float64:
    """``a − b``, or 0 where ``a`` is not finite (a ray that missed has a NaN hit point)."""
    if is_finite(a):
        return a - b
    return wp.float64(0.0)


@wp.kernel
def surface_differentials_kernel(
    position: wp.array(dtype=wp.vec3d),
    eye: wp.vec3d,
    normal: wp.array(dtype=wp.vec3),
    forward: wp.vec3d,
    step_u: wp.vec3d,
    step_v: wp.vec3d,
    dpdu: wp.array(dtype=wp.vec3),
    dpdv: wp.array(dtype=wp.vec3),
):
    k = wp.tid()
    p = position[k]
    v = wp.vec3d(finite_difference(p[0], eye[0]), finite_difference(p[1], eye[1]), finite_difference(p[2], eye[2]))
    n = wp.vec3d(normal[k])
    t = wp.dot(v, forward)
    if not (t > wp.float64(0.0)) or wp.dot(n, n) == wp.float64(0.0):
        dpdu[k] = wp.vec3(0.0)
        dpdv[k] = wp.vec3(0.0)
        return
    dpdu[k] = wp.vec3(transferred_differential(v, n, t, step_u))
    dpdv[k] = wp.vec3(transferred_differential(v, n, t, step_v))


def surface_differentials(position, normal, *, eye, rotation, fov_y_deg: float, aspect: float,
                          device: str = "cpu") -> tuple[np.ndarray, np.ndarray]:
    """Exact ray differentials of every pixel: ∂X/∂u and ∂X/∂v of the hit point at the pixel centre.

    Parameters
    ----------
    position : array_like, shape (H, W, 3), float64
        Hit points, world metres; NaN where the ray missed.
    normal : array_like, shape (H, W, 3), float32
        Unit normals of the hit surface (either side); 0 where the ray missed.
    eye : array_like, shape (3,), float64
        Camera position, world metres.
    rotation : array_like, shape (3, 3), float64
        Camera-to-world rotation; columns are the camera's right, up and back axes.
    fov_y_deg : float
        Vertical field of view, degrees.
    aspect : float
        Width / height of the image plane.
    device : str
        Warp device, ``"cpu"`` or ``"cuda"``.

    Returns
    -------
    dpdu, dpdv : ndarray, shape (H, W, 3), float32
        Metres per pixel toward +u (right, column) and +v (down, row) on the tangent plane of the
        hit; 0 where the ray missed or the point is not in front of the camera.

    Raises
    ------
    ValueError
        On mismatched shapes, a non-finite camera or an unusable device.
    """
    device = checked_device(device)
    p = np.ascontiguousarray(position, dtype=np.float64)
    n = np.ascontiguousarray(normal, dtype=np.float32)
    if p.ndim != 3 or p.shape[2] != 3 or n.shape != p.shape:
        raise ValueError(f"position, normal: expected two (H, W, 3) arrays, got {p.shape} and {n.shape}")
    c = np.asarray(eye, dtype=np.float64)
    r = np.asarray(rotation, dtype=np.float64)
    if c.shape != (3,) or r.shape != (3, 3) or not (np.all(np.isfinite(c)) and np.all(np.isfinite(r))):
        raise ValueError("eye, rotation: expected a finite camera position (3,) and rotation (3, 3)")
    if not 0.0 < fov_y_deg < 180.0 or not aspect > 0.0:
        raise ValueError(f"fov_y_deg, aspect: expected (0, 180) degrees and > 0, got {fov_y_deg}, {aspect}")
    height, width = p.shape[:2]
    tan_y = np.tan(np.radians(fov_y_deg) / 2.0)
    # The ray through image point (u, v) is f + r·(2u/W − 1)·tan_y·aspect + up·(1 − 2v/H)·tan_y.
    step_u = r[:, 0] * (2.0 * tan_y * aspect / width)
    step_v = -r[:, 1] * (2.0 * tan_y / height)
    count = height * width
    dpdu = wp.empty(count, dtype=wp.vec3, device=device)
    dpdv = wp.empty(count, dtype=wp.vec3, device=device)
    wp.launch(
        surface_differentials_kernel,
        # One thread per pixel in row-major order: a 1-D launch, which spares each CPU thread the division that
        # splits a 2-D index.
        dim=count,
        # Read in place where the device can (the CPU), both checked above; the hit relative to the eye is taken
        # per pixel in the kernel (float64 subtractions, as NumPy's), not as two (H, W, 3) temporaries on the host.
        inputs=(
            wp.array(p.reshape(-1, 3), dtype=wp.vec3d, device=device, copy=False),
            wp.vec3d(*c),
            wp.array(n.reshape(-1, 3), dtype=wp.vec3, device=device, copy=False),
            wp.vec3d(*(-r[:, 2])), wp.vec3d(*step_u), wp.vec3d(*step_v),
        ),
        outputs=(dpdu, dpdv),
        device=device,
    )
    return dpdu.numpy().reshape(height, width, 3), dpdv.numpy().reshape(height, width, 3)


@wp.kernel
def texel_footprint_kernel(
    dpdx: wp.array(dtype=wp.vec3),
    dpdy: wp.array(dtype=wp.vec3),
    cascade: wp.array(dtype=wp.int32),
    axis_x: wp.array(dtype=wp.vec3),
    axis_y: wp.array(dtype=wp.vec3),
    rho: wp.array(dtype=float),
    sigma_min: wp.array(dtype=float),
):
    k = wp.tid()
    c = cascade[k]
    if c < 0:
        rho[k] = wp.nan
        sigma_min[k] = wp.nan
        return
    du = dpdx[k]
    dv = dpdy[k]
    a = wp.dot(axis_x[c], du)
    b = wp.dot(axis_x[c], dv)
    cc = wp.dot(axis_y[c], du)
    d = wp.dot(axis_y[c], dv)
    rho[k] = wp.sqrt(wp.abs(a * d - b * cc))
    sigma_min[k] = smallest_singular_value(a, b, cc, d)


@wp.kernel
def warped_texel_footprint_kernel(
    position: wp.array(dtype=wp.vec3d),
    dpdx: wp.array(dtype=wp.vec3),
    dpdy: wp.array(dtype=wp.vec3),
    cascade: wp.array(dtype=wp.int32),
    right: wp.vec3d,
    up: wp.vec3d,
    homography: wp.array(dtype=wp.mat33d),
    rho: wp.array(dtype=float),
    sigma_min: wp.array(dtype=float),
):
    k = wp.tid()
    c = cascade[k]
    if c < 0:
        rho[k] = wp.nan
        sigma_min[k] = wp.nan
        return
    h = homography[c]
    p = position[k]
    x = wp.dot(right, p)
    y = wp.dot(up, p)
    w = h[2, 0] * x + h[2, 1] * y + h[2, 2]
    u = (h[0, 0] * x + h[0, 1] * y + h[0, 2]) / w
    v = (h[1, 0] * x + h[1, 1] * y + h[1, 2]) / w
    # The homography's Jacobian at (x, y), (H[:2, :2] − (u, v) ⊗ H[2, :2]) / w, composed with the
    # light basis: the world directions of texel u and v per metre at this point.
    axis_u = ((h[0, 0] - u * h[2, 0]) * right + (h[0, 1] - u * h[2, 1]) * up) / w
    axis_v = ((h[1, 0] - v * h[2, 0]) * right + (h[1, 1] - v * h[2, 1]) * up) / w
    du = wp.vec3d(dpdx[k])
    dv = wp.vec3d(dpdy[k])
    a = wp.float32(wp.dot(axis_u, du))
    b = wp.float32(wp.dot(axis_u, dv))
    cc = wp.float32(wp.dot(axis_v, du))
    d = wp.float32(wp.dot(axis_v, dv))
    rho[k] = wp.sqrt(wp.abs(a * d - b * cc))
    sigma_min[k] = smallest_singular_value(a, b, cc, d)


def warped_texel_footprint(position, dpdx, dpdy, cascade, *, basis, homographies,
                           device: str = "cpu") -> tuple[np.ndarray, np.ndarray]:
    """ρ and σ_min of every pixel in its selected cascade through the cascade's homography (a warped projection).

    The map from world metres to texels is no longer linear: at the pixel's point ``X`` its
    Jacobian is ``(H[:2, :2] − t ⊗ H[2, :2]) / w · [right; up]`` (``t`` the point's texel
    coordinates, ``w`` its homogeneous weight; :mod:`csmlab.cascades.warp`), and
    ``J = that · [dX/du, dX/dv]`` as in :func:`texel_footprint`.

    Parameters
    ----------
    position : array_like, shape (H, W, 3), float64
        World positions of the pixels' points, metres.
    dpdx, dpdy, cascade
        As :func:`texel_footprint`.
    basis : array_like, shape (3, 3), float64
        The light basis (rows right, up, d).
    homographies : array_like, shape (C, 3, 3), float64
        Each cascade's light-space ``(x, y, 1)`` to ``(i·w, j·w, w)`` (:attr:`csmlab.cascades.Cascade.homography`).
    device : str

    Returns
    -------
    rho, sigma_min : ndarray, shape (H, W), float32
        As :func:`texel_footprint`.
    """
    device = checked_device(device)
    p = np.ascontiguousarray(position, dtype=np.float64)
    dpdx = np.ascontiguousarray(dpdx, dtype=np.float32)
    dpdy = np.ascontiguousarray(dpdy, dtype=np.float32)
    cascade = np.ascontiguousarray(cascade, dtype=np.int32)
    h = np.ascontiguousarray(homographies, dtype=np.float64)
    rows = np.asarray(basis, dtype=np.float64)
    if p.ndim != 3 or p.shape[2] != 3 or dpdx.shape != p.shape or dpdy.shape != p.shape \
            or cascade.shape != p.shape[:2]:
        raise ValueError(f"position, dpdx, dpdy, cascade: expected (H, W, 3) ×3 and (H, W), got {p.shape}, "
                         f"{dpdx.shape}, {dpdy.shape}, {cascade.shape}")
    if h.ndim != 3 or h.shape[1:] != (3, 3) or h.shape[0] == 0 or rows.shape != (3, 3):
        raise ValueError(f"homographies, basis: expected (C, 3, 3) and (3, 3), got {h.shape} and {rows.shape}")
    if cascade.size and cascade.max() >= h.shape[0]:
        raise ValueError(f"cascade: expected indices below {h.shape[0]} (the cascade count), got {cascade.max()}")
    shape = cascade.shape
    rho = wp.empty(cascade.size, dtype=float, device=device)
    sigma_min = wp.empty(cascade.size, dtype=float, device=device)
    wp.launch(
        warped_texel_footprint_kernel,
        # One thread per pixel in row-major order (a 1-D launch: no division to split a 2-D index).
        dim=cascade.size,
        # The checked arrays are read in place where the device can (the CPU), not copied again.
        inputs=(
            wp.array(np.nan_to_num(p).reshape(-1, 3), dtype=wp.vec3d, device=device, copy=False),
            wp.array(dpdx.reshape(-1, 3), dtype=wp.vec3, device=device, copy=False),
            wp.array(dpdy.reshape(-1, 3), dtype=wp.vec3, device=device, copy=False),
            wp.array(cascade.reshape(-1), dtype=wp.int32, device=device, copy=False),
            wp.vec3d(*rows[0]),
            wp.vec3d(*rows[1]),
            wp.array(h, dtype=wp.mat33d, device=device),
        ),
        outputs=(rho, sigma_min),
        device=device,
    )
    return rho.numpy().reshape(shape), sigma_min.numpy().reshape(shape)


def texel_footprint(dpdx, dpdy, cascade, *, texel_axes, device: str = "cpu") -> tuple[np.ndarray, np.ndarray]:
    """Texels per pixel ρ = sqrt|det J| and σ_min(J) of every pixel in its selected cascade.

    Parameters
    ----------
    dpdx, dpdy : array_like, shape (H, W, 3), float32
        Ray differentials on the tangent plane per pixel right (+x) and down (+y), world metres
        (:func:`surface_differentials`).
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
    rho = wp.empty(cascade.size, dtype=float, device=device)
    sigma_min = wp.empty(cascade.size, dtype=float, device=device)
    wp.launch(
        texel_footprint_kernel,
        # One thread per pixel in row-major order (a 1-D launch: no division to split a 2-D index).
        dim=cascade.size,
        # The checked arrays are read in place where the device can (the CPU), not copied again.
        inputs=(
            wp.array(dpdx.reshape(-1, 3), dtype=wp.vec3, device=device, copy=False),
            wp.array(dpdy.reshape(-1, 3), dtype=wp.vec3, device=device, copy=False),
            wp.array(cascade.reshape(-1), dtype=wp.int32, device=device, copy=False),
            wp.array(np.ascontiguousarray(axes[:, 0], dtype=np.float32), dtype=wp.vec3, device=device),
            wp.array(np.ascontiguousarray(axes[:, 1], dtype=np.float32), dtype=wp.vec3, device=device),
        ),
        outputs=(rho, sigma_min),
        device=device,
    )
    return rho.numpy().reshape(shape), sigma_min.numpy().reshape(shape)
