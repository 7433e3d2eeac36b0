"""The fixed box diameter of a world-locked cascade, and the light-space point it is centred on.

A stabilized cascade keeps one extent for as long as its slice does not change, so that its texel
size is bit-identical from frame to frame. Engines take it from different shapes of the slice
(registered in :data:`EXTENT_METHODS`, chosen by ``[shadow] extent``):

- ``sphere`` — the slice's smallest bounding sphere (Valient, ShaderX6; seed 003 listing 4.1.1;
  Unreal, Unity, Godot): diameter ``2r``, centred on the sphere's centre.
- ``diagonal`` — the larger of the slice's body diagonal (near corner to opposite far corner) and
  far-plane diagonal, rounded up to whole metres, centred on the slice's light-space AABB (Bevy
  ``bevy_light/src/cascade.rs`` ``calculate_cascade``; three.js ``examples/jsm/csm/CSM.js``
  ``updateShadowBounds``, which skips the rounding).
- ``diagonal_unrounded`` — ``diagonal`` without the rounding: the larger of the body and far-plane
  diagonals as they are (three.js ``CSM._updateShadowBounds``: ``squaredBBWidth =
  point1.distanceTo(point2)``, far vertex 0 to far vertex 2 or near vertex 2, whichever is farther).
- ``body_diagonal`` — the slice's body diagonal alone, near corner 0 to far corner 6, not rounded,
  centred on the slice's light-space AABB (DirectX SDK CascadedShadowMaps11,
  ``CascadedShadowsManager::InitFrame``, FIT_TO_SCENE: ``vDiagonal = vFrustumPoints[0] -
  vFrustumPoints[6]``, the box padded to that length on x and y about the AABB's centre). For wide
  fields of view it is shorter than the far-plane diagonal, so the box may not hold its whole slice
  (the sample's behaviour: points it misses fall to the next cascade, or to none). The sample's
  fit-to-scene slices begin at view depth 0, csmlab's at the near plane.
- ``centroid`` — the sphere centred on the centroid of the slice's eight corners, its radius the
  distance to the farthest corner (Godot 4 ``RendererSceneCull::_light_instance_setup_directional_shadow``:
  ``center += endpoints[j]`` … ``center /= 8.0``, ``radius = max(|endpoints[j] - center|)``; Stride
  ``LightDirectionalShadowMapRenderer.Collect``: ``BoundingSphere.FromPoints`` of the corners). The
  centroid lies on the view axis at depth ``(z_n + z_f) / 2``; the radius, to a far corner, is
  ``sqrt(((z_f - z_n) / 2)² + z_f² (tan²(fov_x/2) + tan²(fov_y/2)))``, larger than the smallest
  sphere's (+8.5 % for a 0.1–10 m slice at 60°, 16:9). Godot's ``× T / (T - 2)`` texel of margin is
  :func:`csmlab.cascades.stabilize.snap_nearest2`'s.

Both depend on the projection and the slice's depths only, never on the camera's position or
orientation.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from csmlab.camera import CameraPose
from csmlab.geometry import slice_bounding_sphere

__all__ = ["EXTENT_METHODS", "extent_body_diagonal", "extent_centroid", "extent_diagonal", "extent_diagonal_unrounded",
           "extent_sphere", "radius_rounded_up"]


def radius_rounded_up(radius: float, *, bits: int = 12) -> float:
    """``radius`` rounded up to a multiple of ``2^(floor(log2 r) - bits)`` so float noise cannot change it."""
    quantum = np.ldexp(1.0, int(np.floor(np.log2(radius))) - bits)
    return float(np.ceil(radius / quantum) * quantum)


def extent_sphere(*, pose: CameraPose, basis: np.ndarray, z_near: float, z_far: float,
                  corners: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre x/y ``(2,)`` in light-space metres and radius (metres, rounded up to a 2^-12 quantum) of the bounding
    sphere."""
    sphere = slice_bounding_sphere(fov_y_deg=pose.fov_y_deg, aspect=pose.aspect, z_near=z_near, z_far=z_far)
    centre = basis @ (pose.position + pose.forward * sphere.centre_depth)
    return centre[:2], radius_rounded_up(sphere.radius)


def extent_diagonal(*, pose: CameraPose, basis: np.ndarray, z_near: float, z_far: float,
                    corners: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre x/y ``(2,)`` of the slice's light-space AABB and half of ``ceil(max(body, far diagonal))`` metres.

    With half-extents ``(x, y) = z (tan(fov_x/2), tan(fov_y/2))`` at view depth ``z``, the body
    diagonal is ``sqrt((x_n + x_f)² + (y_n + y_f)² + (z_f - z_n)²)`` and the far-plane diagonal
    ``2 sqrt(x_f² + y_f²)``.
    """
    ty = np.tan(np.radians(pose.fov_y_deg) / 2.0)
    tx = ty * pose.aspect
    xn, yn, xf, yf = z_near * tx, z_near * ty, z_far * tx, z_far * ty
    body = np.sqrt((xn + xf) ** 2 + (yn + yf) ** 2 + (z_far - z_near) ** 2)
    far_plane = 2.0 * np.hypot(xf, yf)
    diameter = float(np.ceil(max(body, far_plane)))
    lo, hi = corners[:, :2].min(axis=0), corners[:, :2].max(axis=0)
    return 0.5 * (lo + hi), 0.5 * diameter


def extent_diagonal_unrounded(*, pose: CameraPose, basis: np.ndarray, z_near: float, z_far: float,
                              corners: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre x/y ``(2,)`` of the slice's light-space AABB and half of ``max(body, far diagonal)`` metres, unrounded.

    :func:`extent_diagonal`'s diagonals as three.js sizes its box (``CSM._updateShadowBounds``), a
    closed form of the projection and the slice depths, so bit-stable from frame to frame.
    """
    ty = np.tan(np.radians(pose.fov_y_deg) / 2.0)
    tx = ty * pose.aspect
    xn, yn, xf, yf = z_near * tx, z_near * ty, z_far * tx, z_far * ty
    body = np.sqrt((xn + xf) ** 2 + (yn + yf) ** 2 + (z_far - z_near) ** 2)
    lo, hi = corners[:, :2].min(axis=0), corners[:, :2].max(axis=0)
    return 0.5 * (lo + hi), 0.5 * float(max(body, 2.0 * np.hypot(xf, yf)))


def extent_body_diagonal(*, pose: CameraPose, basis: np.ndarray, z_near: float, z_far: float,
                         corners: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre x/y ``(2,)`` of the slice's light-space AABB and half its body diagonal (DirectX CSM11 fit to scene).

    ``sqrt((x_n + x_f)² + (y_n + y_f)² + (z_f - z_n)²)`` with the half-extents of :func:`extent_diagonal`,
    neither widened to the far-plane diagonal nor rounded.
    """
    ty = np.tan(np.radians(pose.fov_y_deg) / 2.0)
    tx = ty * pose.aspect
    body = float(np.sqrt((z_near * tx + z_far * tx) ** 2 + (z_near * ty + z_far * ty) ** 2 + (z_far - z_near) ** 2))
    lo, hi = corners[:, :2].min(axis=0), corners[:, :2].max(axis=0)
    return 0.5 * (lo + hi), 0.5 * body


def extent_centroid(*, pose: CameraPose, basis: np.ndarray, z_near: float, z_far: float,
                    corners: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre x/y ``(2,)`` of the corners' centroid and the distance to the farthest corner (rounded up to a 2^-12
    quantum).

    Closed form in the view frame, so it is bit-stable from frame to frame (the centroid of the
    corners lies on the view axis at depth ``(z_n + z_f) / 2``; the far corners are the farthest).
    """
    ty = np.tan(np.radians(pose.fov_y_deg) / 2.0)
    tx = ty * pose.aspect
    mid = 0.5 * (z_near + z_far)
    radius = float(np.sqrt((z_far - mid) ** 2 + (z_far * tx) ** 2 + (z_far * ty) ** 2))
    centre = basis @ (pose.position + pose.forward * mid)
    return centre[:2], radius_rounded_up(radius)


EXTENT_METHODS: dict[str, Callable[..., tuple[np.ndarray, float]]] = {
    "sphere": extent_sphere,
    "diagonal": extent_diagonal,
    "diagonal_unrounded": extent_diagonal_unrounded,
    "centroid": extent_centroid,
    "body_diagonal": extent_body_diagonal,
}
"""Fixed-extent shapes by name: ``f(*, pose, basis, z_near, z_far, corners) -> (centre_xy, radius)``."""
