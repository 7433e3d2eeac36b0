"""Camera poses and paths: float64 positions, unit quaternions, projection and time.

A pose's quaternion ``(x, y, z, w)`` rotates camera space into world space; the camera looks
along its -Z axis with +Y up (docs/design.md, "Conventions").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from csmlab.geometry import quat_slerp, quat_to_matrix, validate_unit_quaternion

__all__ = ["CameraPath", "CameraPose"]


def _check_projection(*, fov_y_deg, aspect: float, near: float, far: float) -> None:
    fov = np.asarray(fov_y_deg, dtype=np.float64)
    if not np.all(np.isfinite(fov)) or np.any(fov <= 0.0) or np.any(fov >= 180.0):
        raise ValueError(f"fov_y_deg: expected a value in (0, 180) degrees, got {fov_y_deg}")
    if not np.isfinite(aspect) or aspect <= 0.0:
        raise ValueError(f"aspect: expected a positive width/height ratio, got {aspect}")
    if not np.isfinite(near) or near <= 0.0:
        raise ValueError(f"near: expected a positive distance in metres, got {near}")
    if not np.isfinite(far) or far <= near:
        raise ValueError(f"far: expected a distance greater than near ({near}), got {far}")


@dataclass(frozen=True)
class CameraPose:
    """One camera: where it is, where it looks, and its projection.

    Attributes
    ----------
    position : ndarray, shape (3,), float64
        World position in metres.
    orientation : ndarray, shape (4,), float64
        Unit quaternion ``(x, y, z, w)``, camera space to world space.
    fov_y_deg : float
        Vertical field of view in degrees.
    aspect : float
        Width / height of the image.
    near, far : float
        Clip distances in metres, ``0 < near < far``.
    time_s : float
        Time stamp in seconds.
    """

    position: np.ndarray
    orientation: np.ndarray
    fov_y_deg: float = 60.0
    aspect: float = 16.0 / 9.0
    near: float = 0.1
    far: float = 400.0
    time_s: float = 0.0

    def __post_init__(self) -> None:
        position = np.asarray(self.position, dtype=np.float64)
        if position.shape != (3,) or not np.all(np.isfinite(position)):
            raise ValueError(f"position: expected 3 finite coordinates in metres, got {self.position!r}")
        object.__setattr__(self, "position", position)
        object.__setattr__(self, "orientation", validate_unit_quaternion(self.orientation))
        _check_projection(fov_y_deg=self.fov_y_deg, aspect=self.aspect, near=self.near, far=self.far)

    @property
    def rotation(self) -> np.ndarray:
        """Camera-to-world rotation ``(3, 3)``; columns are the camera's right, up and back axes."""
        return quat_to_matrix(self.orientation)

    @property
    def forward(self) -> np.ndarray:
        """Unit view direction ``(3,)`` in world space (the camera's -Z axis)."""
        return -self.rotation[:, 2]

    def view_depth(self, points) -> np.ndarray:
        """View depth ``-z_view`` in metres of world points ``(..., 3)``; shape ``(...)``."""
        return (np.asarray(points, dtype=np.float64) - self.position) @ self.forward


@dataclass(frozen=True)
class CameraPath:
    """A timed sequence of camera poses sharing one projection.

    Attributes
    ----------
    times : ndarray, shape (N,), float64
        Seconds, strictly increasing.
    positions : ndarray, shape (N, 3), float64
        World positions in metres.
    orientations : ndarray, shape (N, 4), float64
        Unit quaternions ``(x, y, z, w)``, camera to world.
    fov_y_deg : ndarray, shape (N,), float64
        Vertical field of view per pose, degrees.
    aspect, near, far : float
        Shared projection (width / height, metres, metres).
    name : str
        Where the path came from (a generator name or a file name).
    """

    times: np.ndarray
    positions: np.ndarray
    orientations: np.ndarray
    fov_y_deg: np.ndarray
    aspect: float = 16.0 / 9.0
    near: float = 0.1
    far: float = 400.0
    name: str = "path"

    def __post_init__(self) -> None:
        times = np.asarray(self.times, dtype=np.float64).reshape(-1)
        n = times.shape[0]
        if n == 0:
            raise ValueError(f"{self.name}: expected at least one pose, got none")
        positions = np.asarray(self.positions, dtype=np.float64)
        if positions.shape != (n, 3):
            raise ValueError(f"{self.name}: positions: expected shape ({n}, 3), got {positions.shape}")
        if not np.all(np.isfinite(positions)):
            bad = int(np.argwhere(~np.all(np.isfinite(positions), axis=1))[0, 0])
            raise ValueError(f"{self.name}: position of pose {bad}: expected finite coordinates, got NaN or inf")
        if not np.all(np.isfinite(times)) or np.any(np.diff(times) <= 0):
            raise ValueError(f"{self.name}: times: expected finite, strictly increasing seconds")
        orientations = np.asarray(self.orientations, dtype=np.float64)
        if orientations.shape != (n, 4):
            raise ValueError(f"{self.name}: orientations: expected shape ({n}, 4), got {orientations.shape}")
        validate_unit_quaternion(orientations, name=f"{self.name}: orientations")
        fov = np.broadcast_to(np.asarray(self.fov_y_deg, dtype=np.float64), (n,)).copy()
        _check_projection(fov_y_deg=fov, aspect=self.aspect, near=self.near, far=self.far)
        for field, value in (("times", times), ("positions", positions), ("orientations", orientations),
                             ("fov_y_deg", fov)):
            value.setflags(write=False)
            object.__setattr__(self, field, value)

    def __len__(self) -> int:
        return self.times.shape[0]

    def pose(self, i: int) -> CameraPose:
        """The ``i``-th pose as a :class:`CameraPose`."""
        return CameraPose(
            position=self.positions[i],
            orientation=self.orientations[i],
            fov_y_deg=float(self.fov_y_deg[i]),
            aspect=self.aspect,
            near=self.near,
            far=self.far,
            time_s=float(self.times[i]),
        )

    def poses(self) -> list[CameraPose]:
        """All poses in order."""
        return [self.pose(i) for i in range(len(self))]

    def sample(self, t) -> CameraPath:
        """Poses at times ``t`` (seconds, within the path): linear positions and fov, slerped orientations."""
        t = np.asarray(t, dtype=np.float64).reshape(-1)
        if np.any(t < self.times[0] - 1e-9) or np.any(t > self.times[-1] + 1e-9):
            raise ValueError(
                f"{self.name}: sample times must lie in [{self.times[0]}, {self.times[-1]}] s"
            )
        t = np.clip(t, self.times[0], self.times[-1])
        if len(self) == 1:
            idx = np.zeros(t.shape, dtype=np.int64)
            frac = np.zeros(t.shape)
            nxt = idx
        else:
            idx = np.clip(np.searchsorted(self.times, t, side="right") - 1, 0, len(self) - 2)
            nxt = idx + 1
            frac = (t - self.times[idx]) / (self.times[nxt] - self.times[idx])
        positions = self.positions[idx] + frac[:, None] * (self.positions[nxt] - self.positions[idx])
        fov = self.fov_y_deg[idx] + frac * (self.fov_y_deg[nxt] - self.fov_y_deg[idx])
        orientations = quat_slerp(self.orientations[idx], self.orientations[nxt], frac)
        return CameraPath(
            times=t, positions=positions, orientations=orientations, fov_y_deg=fov,
            aspect=self.aspect, near=self.near, far=self.far, name=self.name,
        )

    def resample(self, fps: float) -> CameraPath:
        """The path at a fixed frame rate ``fps`` (Hz) from its first time stamp, slerping orientations.

        The first pose is kept; the last kept pose is the last whole frame inside the path.
        """
        if not np.isfinite(fps) or fps <= 0:
            raise ValueError(f"fps: expected a positive frame rate in Hz, got {fps}")
        duration = self.times[-1] - self.times[0]
        count = int(np.floor(duration * fps + 1e-9)) + 1
        return self.sample(self.times[0] + np.arange(count) / fps)

    def crop(self, start_s: float, end_s: float) -> CameraPath:
        """Poses with ``start_s <= time <= end_s`` (seconds)."""
        keep = (self.times >= start_s) & (self.times <= end_s)
        if not np.any(keep):
            raise ValueError(f"{self.name}: no pose lies in the time window [{start_s}, {end_s}] s")
        return CameraPath(
            times=self.times[keep], positions=self.positions[keep], orientations=self.orientations[keep],
            fov_y_deg=self.fov_y_deg[keep], aspect=self.aspect, near=self.near, far=self.far, name=self.name,
        )

    def head(self, count: int) -> CameraPath:
        """The first ``count`` poses."""
        if count < 1:
            raise ValueError(f"frames: expected at least 1, got {count}")
        return self.crop(self.times[0], self.times[min(count, len(self)) - 1])
