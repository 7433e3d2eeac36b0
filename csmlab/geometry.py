"""Float64 host math: rotations, view and projection matrices, light basis, frustum slices.

Conventions (docs/design.md, "Conventions"): right-handed world in metres with +Y up; a camera looks
along -Z of its view space, so the view depth of a point is ``-z_view > 0``. Quaternions are
stored scalar-last, ``(x, y, z, w)``, and rotate camera space into world space.

Everything here is plain NumPy in float64; the Warp kernels only ever see the results.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

__all__ = [
    "BoundingSphere",
    "frustum_slice_corners",
    "LIGHT_BASIS_METHODS",
    "light_basis",
    "light_basis_world_y",
    "normalized",
    "orthographic",
    "perspective",
    "quat_from_matrix",
    "quat_multiply",
    "quat_slerp",
    "quat_to_matrix",
    "rotation_looking_at",
    "slice_bounding_sphere",
    "validate_unit_quaternion",
]

_UNIT_TOLERANCE = 1e-6


def normalized(v, *, name: str = "vector") -> np.ndarray:
    """Return ``v / |v|`` as float64, refusing zero-length and non-finite input.

    Raises
    ------
    ValueError
        If ``v`` has a NaN or infinite component or a length below 1e-12; the message names
        ``name``.
    """
    v = np.asarray(v, dtype=np.float64)
    if v.shape[-1:] != (3,):
        raise ValueError(f"{name}: expected 3 components, got shape {v.shape}")
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name}: expected finite components, got {v.tolist()}")
    length = np.linalg.norm(v, axis=-1, keepdims=True)
    if np.any(length < 1e-12):
        raise ValueError(f"{name}: expected a non-zero length, got {v.tolist()}")
    return v / length


def validate_unit_quaternion(q, *, name: str = "orientation") -> np.ndarray:
    """Return ``q`` as a float64 ``(..., 4)`` array after checking it is a finite unit quaternion.

    The tolerance on ``| |q| - 1 |`` is 1e-6; recorded files are normalised by their readers
    before they get here, so a larger error means a broken pose.
    """
    q = np.asarray(q, dtype=np.float64)
    if q.shape[-1:] != (4,):
        raise ValueError(f"{name}: expected a quaternion (x, y, z, w), got shape {q.shape}")
    if not np.all(np.isfinite(q)):
        raise ValueError(f"{name}: expected finite quaternion components, found NaN or inf")
    err = np.abs(np.linalg.norm(q, axis=-1) - 1.0)
    if np.any(err > _UNIT_TOLERANCE):
        raise ValueError(
            f"{name}: expected a unit quaternion (|q| = 1 within {_UNIT_TOLERANCE}), "
            f"got |q| off by {float(np.max(err)):.3g}"
        )
    return q


def quat_to_matrix(q) -> np.ndarray:
    """Rotation matrix ``(..., 3, 3)`` of unit quaternions ``(..., 4)`` stored ``(x, y, z, w)``."""
    q = np.asarray(q, dtype=np.float64)
    x, y, z, w = np.moveaxis(q, -1, 0)
    m = np.empty(q.shape[:-1] + (3, 3))
    m[..., 0, 0] = 1 - 2 * (y * y + z * z)
    m[..., 0, 1] = 2 * (x * y - z * w)
    m[..., 0, 2] = 2 * (x * z + y * w)
    m[..., 1, 0] = 2 * (x * y + z * w)
    m[..., 1, 1] = 1 - 2 * (x * x + z * z)
    m[..., 1, 2] = 2 * (y * z - x * w)
    m[..., 2, 0] = 2 * (x * z - y * w)
    m[..., 2, 1] = 2 * (y * z + x * w)
    m[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return m


def quat_from_matrix(m) -> np.ndarray:
    """Unit quaternion ``(..., 4)`` ``(x, y, z, w)`` with ``w >= 0`` of rotation matrices ``(..., 3, 3)``.

    Shepperd's method: the largest of the four squared components is taken first, which keeps
    the result accurate for every rotation.
    """
    m = np.asarray(m, dtype=np.float64)
    flat = m.reshape(-1, 3, 3)
    out = np.empty((flat.shape[0], 4))
    for k, r in enumerate(flat):
        t = np.trace(r)
        if t > 0:
            s = 2.0 * np.sqrt(1.0 + t)
            q = [(r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s, s / 4]
        elif r[0, 0] > r[1, 1] and r[0, 0] > r[2, 2]:
            s = 2.0 * np.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2])
            q = [s / 4, (r[0, 1] + r[1, 0]) / s, (r[0, 2] + r[2, 0]) / s, (r[2, 1] - r[1, 2]) / s]
        elif r[1, 1] > r[2, 2]:
            s = 2.0 * np.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2])
            q = [(r[0, 1] + r[1, 0]) / s, s / 4, (r[1, 2] + r[2, 1]) / s, (r[0, 2] - r[2, 0]) / s]
        else:
            s = 2.0 * np.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1])
            q = [(r[0, 2] + r[2, 0]) / s, (r[1, 2] + r[2, 1]) / s, s / 4, (r[1, 0] - r[0, 1]) / s]
        q = np.asarray(q)
        out[k] = q / np.linalg.norm(q) * (1.0 if q[3] >= 0 else -1.0)
    return out.reshape(m.shape[:-2] + (4,))


def quat_multiply(a, b) -> np.ndarray:
    """Hamilton product ``a * b`` of quaternions ``(..., 4)`` stored ``(x, y, z, w)``."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    ax, ay, az, aw = np.moveaxis(a, -1, 0)
    bx, by, bz, bw = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ],
        axis=-1,
    )


def quat_slerp(a, b, t) -> np.ndarray:
    """Spherical linear interpolation between unit quaternions ``a`` and ``b`` (``(..., 4)``) at ``t``.

    Takes the short way round (flips ``b`` when ``a . b < 0``) and falls back to normalised
    linear interpolation for nearly equal rotations.
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)[..., None]
    dot = np.sum(a * b, axis=-1, keepdims=True)
    b = np.where(dot < 0, -b, b)
    dot = np.abs(dot)
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    sin_theta = np.sin(theta)
    near = sin_theta < 1e-9
    safe = np.where(near, 1.0, sin_theta)
    wa = np.where(near, 1.0 - t, np.sin((1.0 - t) * theta) / safe)
    wb = np.where(near, t, np.sin(t * theta) / safe)
    q = wa * a + wb * b
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def rotation_looking_at(forward, up=(0.0, 1.0, 0.0)) -> np.ndarray:
    """Camera-to-world quaternion ``(4,)`` of a camera looking along ``forward`` with ``up`` roughly up.

    The camera's -Z axis is ``forward``. When ``forward`` is parallel to ``up`` a helper axis that
    is never parallel to it is used instead, so looking straight down is valid.
    """
    f = normalized(forward, name="forward")
    u = normalized(up, name="up")
    if abs(float(np.dot(f, u))) > 1.0 - 1e-9:
        u = np.eye(3)[int(np.argmin(np.abs(f)))]
    right = np.cross(f, u)
    right /= np.linalg.norm(right)
    true_up = np.cross(right, f)
    return quat_from_matrix(np.stack([right, true_up, -f], axis=1))


def perspective(*, fov_y_deg: float, aspect: float, near: float, far: float) -> np.ndarray:
    """OpenGL perspective projection ``(4, 4)``: view space to clip space, depth to [-1, 1]."""
    f = 1.0 / np.tan(np.radians(fov_y_deg) / 2.0)
    m = np.zeros((4, 4))
    m[0, 0] = f / aspect
    m[1, 1] = f
    m[2, 2] = (far + near) / (near - far)
    m[2, 3] = 2.0 * far * near / (near - far)
    m[3, 2] = -1.0
    return m


def orthographic(*, left: float, right: float, bottom: float, top: float, near: float, far: float) -> np.ndarray:
    """OpenGL orthographic projection ``(4, 4)`` of the box ``[left, right] x [bottom, top] x [-far, -near]``."""
    m = np.eye(4)
    m[0, 0] = 2.0 / (right - left)
    m[1, 1] = 2.0 / (top - bottom)
    m[2, 2] = -2.0 / (far - near)
    m[0, 3] = -(right + left) / (right - left)
    m[1, 3] = -(top + bottom) / (top - bottom)
    m[2, 3] = -(far + near) / (far - near)
    return m


def light_basis(direction) -> np.ndarray:
    """Light-space rotation ``(3, 3)`` whose rows are (right, up, d), from the light direction alone.

    ``d`` points from the light toward the scene. The helper axis is the world axis least aligned
    with ``d``, so it is never parallel to it: a light straight down or along any axis is valid.
    Because the basis depends on ``d`` only and light space is anchored at the world origin, a
    texel grid in light space is fixed in the world.

    Raises
    ------
    ValueError
        If ``direction`` has zero length or a non-finite component.
    """
    d = normalized(direction, name="light direction")
    helper = np.eye(3)[int(np.argmin(np.abs(d)))]
    right = np.cross(helper, d)
    right /= np.linalg.norm(right)
    up = np.cross(d, right)
    return np.stack([right, up, d])


def light_basis_world_y(direction) -> np.ndarray:
    """Light-space rotation ``(3, 3)``, rows (right, up, d), of a look-at along ``d`` with world +Y as up.

    The engines' own light camera: three.js ``CSM.update()`` (``Matrix4.lookAt(origin, lightDirection,
    +Y)``: x = +Y × z with z = −d), Stride ``LightDirectionalShadowMapRenderer`` (``side = Y × d``, the
    view ``LookAtRH``), MJP's Shadows and DirectX CascadedShadowMaps11 (``XMMatrixLookAtLH`` with up +Y
    in their left-handed worlds), and Godot and Bevy, whose light node looks along its −Z: a node
    posed without roll has its +X horizontal and its +Y in the vertical plane through ``d``. In
    csmlab's right-handed world every one of them is the camera's view space: ``right = d × Y``
    normalized, ``up = right × d`` (the component of +Y across ``d``), and light depth along ``d``
    (= −z of the look-at), so ``right × up = −d``. The texel grid then turns with the light's
    azimuth only, never about the light axis. A light along ±Y, where ``d × Y`` vanishes, takes
    right = +X, as three.js's ``lookAt`` does (it nudges z by 1e-4 along +Z).

    Raises
    ------
    ValueError
        If ``direction`` has zero length or a non-finite component.
    """
    d = normalized(direction, name="light direction")
    right = np.cross(d, np.array([0.0, 1.0, 0.0]))
    length = np.linalg.norm(right)
    right = np.array([1.0, 0.0, 0.0]) if length < 1e-9 else right / length
    up = np.cross(right, d)
    up /= np.linalg.norm(up)
    return np.stack([right, up, d])


LIGHT_BASIS_METHODS: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "least_aligned": light_basis,
    "world_y": light_basis_world_y,
}
"""Light-space bases by name (``[shadow] light_basis``): ``f(direction) -> (3, 3)`` rows (right, up, d).
Each depends on ``d`` only, so a box snapped in it keeps world-locked texels."""


def frustum_slice_corners(
    *, position, orientation, fov_y_deg: float, aspect: float, z_near: float, z_far: float
) -> np.ndarray:
    """World-space corners ``(8, 3)`` of the view frustum between view depths ``z_near`` and ``z_far``.

    Order: the four corners at ``z_near`` then the four at ``z_far``, each as
    (-x -y), (+x -y), (+x +y), (-x +y) in view space.
    """
    ty = np.tan(np.radians(fov_y_deg) / 2.0)
    tx = ty * aspect
    signs = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=np.float64)
    corners = []
    for z in (z_near, z_far):
        for sx, sy in signs:
            corners.append([sx * tx * z, sy * ty * z, -z])
    view = np.asarray(corners)
    r = quat_to_matrix(orientation)
    return view @ r.T + np.asarray(position, dtype=np.float64)


@dataclass(frozen=True)
class BoundingSphere:
    """A sphere in view space on the view axis: ``centre_depth`` (m, along -Z) and ``radius`` (m)."""

    centre_depth: float
    radius: float


def slice_bounding_sphere(*, fov_y_deg: float, aspect: float, z_near: float, z_far: float) -> BoundingSphere:
    """Smallest sphere enclosing the frustum slice ``[z_near, z_far]``, in closed form.

    With ``g = tan²(fov_x/2) + tan²(fov_y/2)`` the corners at depth ``z`` lie at radius ``z·√g``
    from the view axis. The sphere through both rings has its centre at depth
    ``c = (z_near + z_far)(1 + g)/2``; when that lies beyond ``z_far`` the far ring alone sets
    the sphere (``c = z_far``). The result depends on the slice and the projection only, never on
    the camera's position or orientation, so its radius is bit-identical from frame to frame —
    what the exact method needs.
    """
    ty = np.tan(np.radians(fov_y_deg) / 2.0)
    g = ty * ty * (1.0 + aspect * aspect)
    c = min(0.5 * (z_near + z_far) * (1.0 + g), z_far)
    r = np.sqrt((c - z_far) ** 2 + z_far * z_far * g)
    return BoundingSphere(centre_depth=float(c), radius=float(r))
