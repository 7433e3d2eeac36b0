"""The sun's and the zoom's policies by name: which light direction and field of view the cascades are fitted to.

Engines answer two reported causes of shimmer with policies that change what the *shadow* sees, not
what the camera renders:

- a moving sun (a day-night cycle) re-rasterizes every cascade under a new light every frame, so
  every shadow edge swims; the workarounds update the shadow's light direction only every N frames,
  or quantize it to an angular step (:data:`SUN_POLICIES`, ``[shadow] sun_policy``). The shading
  and the sky keep the true sun every frame, and so does the ray-traced reference: the shadow then
  stands still between updates and pops at each (docs/design.md, "Sun and zoom policies");
- a field of view that changes (a sprint zoom) narrows every slice and with it every box; Godot's
  ``directional_shadow_min_fov`` (godotengine/godot PR #119680, for issue #72015) fits the cascades
  to ``max(fov, min_fov)`` while the camera renders at its own (:data:`ZOOM_POLICIES`,
  ``[shadow] zoom_policy``).

NumPy only, no Warp: the config loader checks the names, and the cascades (:mod:`csmlab.cascades`)
and the run (:mod:`csmlab.experiment`) apply them.
"""

from __future__ import annotations

import math

import numpy as np

from csmlab.registry import dispatch

__all__ = ["SUN_POLICIES", "ZOOM_POLICIES", "shadow_fov_deg", "shadow_light_direction", "sun_angles_deg"]


def sun_angles_deg(direction) -> tuple[float, float]:
    """Elevation and azimuth in degrees of a unit light direction ``(3,)`` (light toward the scene).

    The inverse of :func:`csmlab.light.direction_from_angles`: elevation above the horizon in
    [-90, 90], azimuth from +Z toward +X about +Y in (-180, 180].
    """
    toward_sun = -np.asarray(direction, dtype=np.float64)
    elevation = math.degrees(math.asin(min(1.0, max(-1.0, float(toward_sun[1])))))
    return elevation, math.degrees(math.atan2(float(toward_sun[0]), float(toward_sun[2])))


def _direction_of(elevation_deg: float, azimuth_deg: float) -> np.ndarray:
    el, az = math.radians(elevation_deg), math.radians(azimuth_deg)
    toward_sun = np.array([math.cos(el) * math.sin(az), math.sin(el), math.cos(el) * math.cos(az)])
    return -toward_sun / np.linalg.norm(toward_sun)


def _every_frame(directions: np.ndarray, frame: int) -> np.ndarray:
    """The true sun of ``frame``: the shadow follows the light every frame."""
    return directions[frame]


def _every_n(directions: np.ndarray, frame: int, *, update_frames: int) -> np.ndarray:
    """The sun of the last update, frame ``update_frames · ⌊frame / update_frames⌋``: held in between."""
    return directions[(frame // update_frames) * update_frames]


def _quantized(directions: np.ndarray, frame: int, *, step_deg: float) -> np.ndarray:
    """The true sun's elevation and azimuth each rounded to the nearest multiple of ``step_deg``.

    The cells are ``[(k − ½)·step, (k + ½)·step)`` in elevation and in azimuth (about the world's
    up axis +Y), so the shadow's direction stays bit for bit the same while the sun stays inside one.
    """
    elevation, azimuth = sun_angles_deg(directions[frame])
    held = [step_deg * math.floor(angle / step_deg + 0.5) for angle in (elevation, azimuth)]
    return _direction_of(min(90.0, max(-90.0, held[0])), held[1])


SUN_POLICIES = {
    "every_frame": _every_frame,
    "every_n": _every_n,
    "quantized": _quantized,
}
"""``[shadow] sun_policy``: the shadow's light direction of a frame from the true sun's path, by name."""


def shadow_light_direction(directions, frame: int, *, policy: str, update_frames: int = 1,
                           step_deg: float = 1.0) -> np.ndarray:
    """The light direction ``(3,)`` the shadow maps of ``frame`` are built with.

    Parameters
    ----------
    directions : array_like, shape (N, 3)
        The true sun of every frame, unit vectors from the light toward the scene (world space).
    frame : int
        Index into ``directions``.
    policy : str
        A key of :data:`SUN_POLICIES`.
    update_frames : int
        ``every_n``: frames between updates (≥ 1).
    step_deg : float
        ``quantized``: the angular step in degrees (> 0).

    Returns
    -------
    ndarray, shape (3,), float64
        A unit direction; the true sun's own row with ``every_frame`` and ``every_n``.
    """
    return dispatch(SUN_POLICIES, policy, np.asarray(directions, dtype=np.float64), frame, field="sun_policy",
                    offered=dict(update_frames=update_frames, step_deg=step_deg))


def _camera_fov(fov_y_deg: float) -> float:
    """The camera's own field of view."""
    return fov_y_deg


def _min_fov(fov_y_deg: float, *, min_fov_deg: float) -> float:
    """``max(fov, min_fov)``: Godot's ``directional_shadow_min_fov`` (PR #119680)."""
    return max(fov_y_deg, min_fov_deg)


ZOOM_POLICIES = {
    "camera": _camera_fov,
    "min_fov": _min_fov,
}
"""``[shadow] zoom_policy``: the vertical field of view the cascades are fitted to, by name."""


def shadow_fov_deg(fov_y_deg: float, *, policy: str, min_fov_deg: float = 0.0) -> float:
    """The vertical field of view in degrees the cascades of a camera of ``fov_y_deg`` are fitted to.

    ``policy`` is a key of :data:`ZOOM_POLICIES`; ``min_fov_deg`` the floor of ``min_fov``. The
    camera's aspect ratio is kept: the horizontal field of view widens with the vertical.
    """
    return float(dispatch(ZOOM_POLICIES, policy, float(fov_y_deg), field="zoom_policy",
                          offered=dict(min_fov_deg=min_fov_deg)))
