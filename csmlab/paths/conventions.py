"""Axis conventions of recorded camera paths, and csmlab's yaw/pitch/roll.

csmlab's own convention, ``opengl`` (docs/design.md, "Conventions"): a right-handed world in metres
with +Y up; a camera looks along its -Z axis with +Y up and +X right, and its quaternion
``(x, y, z, w)`` rotates camera coordinates into world coordinates.

A file written in another convention states a position ``p_f`` and a camera-to-world rotation
``R_f`` in its own world and camera axes and its own length unit. Each :class:`Convention` holds

- ``world`` ``W`` (3×3): the file's world coordinates → csmlab world coordinates;
- ``camera`` ``K`` (3×3): csmlab camera coordinates → the file's camera coordinates;
- ``metres_per_unit``: the file's length unit in metres;

and the pose in csmlab's convention is

    p = metres_per_unit · W p_f,        R = W R_f K.

``W`` and ``K`` are signed permutations with ``det W = det K``: a left-handed file flips both,
so ``R`` stays a rotation. For ``opengl``, ``tum``/``kitti``, ``unreal`` and ``unity``,
``W K = I``: the file's identity camera is csmlab's identity camera (looking along world -Z
with +Y up). The matrices of every convention are listed in the docstring of its entry in
:data:`CONVENTIONS`.

References: TUM RGB-D benchmark file formats (Sturm et al. 2012); KITTI odometry devkit
(Geiger et al. 2012); EuRoC MAV dataset (Burri et al. 2016), ``mav0/cam0/sensor.yaml``;
Unreal Engine and Unity coordinate-system documentation; ROS REP 103 "Standard Units of Measure
and Coordinate Conventions".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from csmlab.geometry import quat_from_matrix, quat_multiply
from csmlab.registry import check_name

__all__ = [
    "CONVENTIONS",
    "Convention",
    "convention_named",
    "orientation_from_yaw_pitch_roll",
    "poses_from_opengl",
    "poses_to_opengl",
]


@dataclass(frozen=True)
class Convention:
    """The axes and unit of one camera-path convention (see the module docstring for the formula).

    Attributes
    ----------
    world : ndarray, shape (3, 3), float64
        ``W``: the file's world coordinates → csmlab world coordinates (a signed permutation).
    camera : ndarray, shape (3, 3), float64
        ``K``: csmlab camera coordinates → the file's camera coordinates (a signed permutation).
    metres_per_unit : float
        The file's length unit in metres.
    description : str
        One line for ``csmlab list`` and error messages.
    """

    world: np.ndarray
    camera: np.ndarray
    metres_per_unit: float
    description: str

    def __post_init__(self) -> None:
        for field in ("world", "camera"):
            m = np.asarray(getattr(self, field), dtype=np.float64)
            if m.shape != (3, 3) or not np.allclose(m @ m.T, np.eye(3)) or not np.all(np.isin(m, (-1.0, 0.0, 1.0))):
                raise ValueError(f"convention {field}: expected a 3×3 signed permutation matrix, got {m.tolist()}")
            m.setflags(write=False)
            object.__setattr__(self, field, m)
        if round(np.linalg.det(self.world)) != round(np.linalg.det(self.camera)):
            raise ValueError("convention: world and camera matrices must have the same handedness (equal determinants)")
        if not np.isfinite(self.metres_per_unit) or self.metres_per_unit <= 0:
            raise ValueError(f"convention metres_per_unit: expected a positive length, got {self.metres_per_unit}")


_FLIP_YZ = [[1, 0, 0], [0, -1, 0], [0, 0, -1]]
_Z_UP_TO_Y_UP = [[1, 0, 0], [0, 0, 1], [0, -1, 0]]

CONVENTIONS: dict[str, Convention] = {
    "opengl": Convention(
        world=np.eye(3), camera=np.eye(3), metres_per_unit=1.0,
        description="csmlab's own: right-handed, metres, world +Y up, camera looks -Z with +Y up",
    ),
    "tum": Convention(
        world=_FLIP_YZ, camera=_FLIP_YZ, metres_per_unit=1.0,
        description="computer vision (TUM estimates, ORB-SLAM): camera x right, y down, z forward; "
                    "world = the first camera's axes (y down); metres",
    ),
    "kitti": Convention(
        world=_FLIP_YZ, camera=_FLIP_YZ, metres_per_unit=1.0,
        description="KITTI odometry: camera x right, y down, z forward; world = the first camera's axes; metres",
    ),
    "mocap": Convention(
        world=_Z_UP_TO_Y_UP, camera=_FLIP_YZ, metres_per_unit=1.0,
        description="motion-capture ground truth (TUM RGB-D groundtruth.txt): world z up; "
                    "camera x right, y down, z forward; metres",
    ),
    "euroc": Convention(
        world=_Z_UP_TO_Y_UP, camera=[[0, 1, 0], [1, 0, 0], [0, 0, -1]], metres_per_unit=1.0,
        description="EuRoC MAV ground truth: world z up; the body (IMU) frame used as the camera, "
                    "x up, y right, z forward (cam0's nominal mounting); metres",
    ),
    "ros": Convention(
        world=_Z_UP_TO_Y_UP, camera=[[0, 0, -1], [-1, 0, 0], [0, 1, 0]], metres_per_unit=1.0,
        description="ROS REP 103 (GNSS/INS, robot logs): world x east/forward, y left, z up; body x forward, "
                    "y left, z up, used as the camera (looks along body +x); metres",
    ),
    "nerfstudio": Convention(
        world=_Z_UP_TO_Y_UP, camera=np.eye(3), metres_per_unit=1.0,
        description="nerfstudio camera paths: world z up (its data parsers' orientation 'up'); camera OpenGL, "
                    "x right, y up, looks -z; the scene's own unit",
    ),
    "unreal": Convention(
        world=[[0, 1, 0], [0, 0, 1], [-1, 0, 0]], camera=[[0, 0, -1], [1, 0, 0], [0, 1, 0]], metres_per_unit=0.01,
        description="Unreal Engine: left-handed, x forward, y right, z up, centimetres; camera looks +x",
    ),
    "unity": Convention(
        world=np.diag([1.0, 1.0, -1.0]), camera=np.diag([1.0, 1.0, -1.0]), metres_per_unit=1.0,
        description="Unity: left-handed, x right, y up, z forward, metres; camera looks +z",
    ),
}
"""Conventions by name; add an entry to register a new one.

==========  ===================================  ===================================  =====
name        ``W`` (file world → csmlab world)    ``K`` (csmlab camera → file camera)  unit
==========  ===================================  ===================================  =====
opengl      I                                    I                                    1 m
tum         diag(1, -1, -1)                      diag(1, -1, -1)                      1 m
kitti       diag(1, -1, -1)                      diag(1, -1, -1)                      1 m
mocap       [[1,0,0], [0,0,1], [0,-1,0]]         diag(1, -1, -1)                      1 m
euroc       [[1,0,0], [0,0,1], [0,-1,0]]         [[0,1,0], [1,0,0], [0,0,-1]]         1 m
ros         [[1,0,0], [0,0,1], [0,-1,0]]         [[0,0,-1], [-1,0,0], [0,1,0]]        1 m
nerfstudio  [[1,0,0], [0,0,1], [0,-1,0]]         I                                    1 m
unreal      [[0,1,0], [0,0,1], [-1,0,0]]         [[0,0,-1], [1,0,0], [0,1,0]]         1 cm
unity       diag(1, 1, -1)                       diag(1, 1, -1)                       1 m
==========  ===================================  ===================================  =====

- ``tum``/``kitti``: the world is the first camera's frame (y down, z forward), as SLAM estimates
  and KITTI poses are written; turning y and z over makes it csmlab's (y up, the first camera
  looking along -Z). A TUM *ground-truth* file is in the motion-capture room's frame (z up):
  read it with ``mocap``.
- ``mocap``: a z-up world: file (x, y, z) → csmlab (x, z, -y); camera optical axes as ``tum``.
- ``euroc``: EuRoC ground truth gives the body (IMU) frame in the z-up Vicon/Leica room frame.
  csmlab uses that body pose as the camera pose (the 7 cm lever arm to cam0 is ignored) with
  cam0's nominal axes: ``mav0/cam0/sensor.yaml`` T_BS puts cam0's x (right) along body +y, its
  y (down) along body -x and its z (forward) along body +z, each within 1.5°. So the camera
  looks along body +z with body +x up.
- ``ros``: REP 103 axes, world (x east or forward, y north or left, z up) → csmlab (x, z, -y) as
  ``mocap``; the body's x forward, y left, z up is the camera: it looks along body +x with body +z
  up, so body +x = csmlab -Z, body -y = csmlab +X (right), body +z = csmlab +Y. UTM or local ENU
  positions of a GNSS/INS log go in with ``anchor = "first"``.
- ``nerfstudio``: a z-up world as ``mocap`` (nerfstudio's data parsers turn the mean camera up
  to +z and its viewer shows +z up) with OpenGL camera axes, as its camera paths store them;
  a path recorded over a y-up world is read with ``opengl``.
- ``unreal``: file (x forward, y right, z up) → csmlab (y, z, -x), centimetres; the camera looks
  along its +x with +z up. Quaternions are read as the rotation matrix they represent, which is
  how the engine stores an ``FQuat``.
- ``unity``: z turned over; the camera looks along its +z with +y up.
"""


def convention_named(name: str) -> Convention:
    """The :class:`Convention` called ``name``; a ``ValueError`` listing the valid names otherwise."""
    check_name(name, CONVENTIONS, field="convention")
    return CONVENTIONS[name]


def _proper_quaternions(convention: Convention) -> tuple[np.ndarray, np.ndarray]:
    """Quaternions ``(4,)`` of ``s·W`` and ``s·K`` with ``s = det W``: rotations, whatever the handedness.

    ``W R_f K = (sW) R_f (sK)`` because ``s² = 1``.
    """
    s = round(float(np.linalg.det(convention.world)))
    return quat_from_matrix(s * convention.world), quat_from_matrix(s * convention.camera)


def _conjugate(q: np.ndarray) -> np.ndarray:
    return q * np.array([-1.0, -1.0, -1.0, 1.0])


def poses_to_opengl(positions, orientations, *, convention: str) -> tuple[np.ndarray, np.ndarray]:
    """Poses in ``convention`` → csmlab's: ``p = u·W p_f``, ``R = W R_f K``.

    Parameters
    ----------
    positions : array_like, shape (N, 3)
        Positions in the file's world axes and length unit.
    orientations : array_like, shape (N, 4)
        Unit quaternions ``(x, y, z, w)``, the file's camera axes to its world axes.
    convention : str
        A key of :data:`CONVENTIONS`.

    Returns
    -------
    positions : ndarray, shape (N, 3), float64
        csmlab world positions in metres.
    orientations : ndarray, shape (N, 4), float64
        Unit quaternions ``(x, y, z, w)``, csmlab camera to csmlab world.
    """
    c = convention_named(convention)
    q_world, q_camera = _proper_quaternions(c)
    p = np.asarray(positions, dtype=np.float64) @ c.world.T * c.metres_per_unit
    q = quat_multiply(quat_multiply(q_world, np.asarray(orientations, dtype=np.float64)), q_camera)
    return p, q / np.linalg.norm(q, axis=-1, keepdims=True)


def poses_from_opengl(positions, orientations, *, convention: str) -> tuple[np.ndarray, np.ndarray]:
    """csmlab poses → ``convention``: the inverse of :func:`poses_to_opengl`.

    ``p_f = W^T p / u``, ``R_f = W^T R K^T``; shapes as in :func:`poses_to_opengl`.
    """
    c = convention_named(convention)
    q_world, q_camera = _proper_quaternions(c)
    p = np.asarray(positions, dtype=np.float64) @ c.world / c.metres_per_unit
    q = quat_multiply(quat_multiply(_conjugate(q_world), np.asarray(orientations, dtype=np.float64)),
                      _conjugate(q_camera))
    return p, q / np.linalg.norm(q, axis=-1, keepdims=True)


def orientation_from_yaw_pitch_roll(*, yaw_deg, pitch_deg, roll_deg) -> np.ndarray:
    """csmlab camera-to-world quaternions ``(..., 4)`` ``(x, y, z, w)`` from angles in degrees.

    ``R = R_y(yaw) · R_x(pitch) · R_z(roll)``: roll about the view axis, then pitch about the
    camera's right axis, then yaw about the world's +Y (intrinsic Y-X'-Z''). Every angle turns
    counter-clockwise about its positive axis (right-hand rule), so with all three at zero the
    camera looks along -Z with +Y up, positive yaw turns it left (toward -X), positive pitch
    looks up, and positive roll tilts its up vector toward -X. Looking along a horizontal
    direction ``(f_x, 0, f_z)`` is ``yaw = atan2(-f_x, -f_z)``.

    Parameters
    ----------
    yaw_deg, pitch_deg, roll_deg : array_like, broadcastable, degrees
    """
    yaw, pitch, roll = np.broadcast_arrays(*(np.radians(np.asarray(a, dtype=np.float64))
                                             for a in (yaw_deg, pitch_deg, roll_deg)))
    zero = np.zeros_like(yaw)

    def about(axis: int, angle: np.ndarray) -> np.ndarray:
        parts = [zero, zero, zero, np.cos(angle / 2)]
        parts[axis] = np.sin(angle / 2)
        return np.stack(parts, axis=-1)

    q = quat_multiply(quat_multiply(about(1, yaw), about(0, pitch)), about(2, roll))
    return q / np.linalg.norm(q, axis=-1, keepdims=True)
