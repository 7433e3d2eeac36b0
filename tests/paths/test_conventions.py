"""Axis conventions: hand-worked poses in each convention land in csmlab's as documented.

Oracle: for every convention a pose written down by hand in that convention's own terms (its
world axes, camera axes and unit), with the csmlab position, view direction and up vector that
the docstring of :data:`csmlab.paths.conventions.CONVENTIONS` says it must give, worked out on
paper. csmlab's camera looks along -Z with +Y up, so forward = -R[:, 2] and up = R[:, 1].
"""

from __future__ import annotations

import numpy as np
import pytest

from csmlab.geometry import quat_from_matrix, quat_to_matrix
from csmlab.paths.conventions import (
    CONVENTIONS,
    orientation_from_yaw_pitch_roll,
    poses_from_opengl,
    poses_to_opengl,
)

S = np.sqrt(0.5)
IDENTITY = (0.0, 0.0, 0.0, 1.0)

# (convention, position in the file, quaternion in the file,
#  expected csmlab position, forward, up)
HAND_POSES = [
    # csmlab's own: nothing changes; a yaw of +90° about +Y turns the camera left, to -X.
    ("opengl", (1, 2, 3), IDENTITY, (1, 2, 3), (0, 0, -1), (0, 1, 0)),
    ("opengl", (1, 2, 3), (0, S, 0, S), (1, 2, 3), (-1, 0, 0), (0, 1, 0)),
    # TUM / KITTI: the identity camera looks along its world's +Z with -Y up: y and z turn over.
    ("tum", (1, 2, 3), IDENTITY, (1, -2, -3), (0, 0, -1), (0, 1, 0)),
    # +90° about the camera's down axis (y) turns z into x: looks along world +X, which is +X.
    ("tum", (1, 2, 3), (0, S, 0, S), (1, -2, -3), (1, 0, 0), (0, 1, 0)),
    ("kitti", (4, 5, 6), IDENTITY, (4, -5, -6), (0, 0, -1), (0, 1, 0)),
    # mocap: z up. The identity camera looks along world +Z (straight up), its -Y (up on the
    # image) along world -Y, which is csmlab +Z.
    ("mocap", (1, 2, 3), IDENTITY, (1, 3, -2), (0, 1, 0), (0, 0, 1)),
    # EuRoC body frame as the camera: looks along body +z, body +x is up.
    ("euroc", (1, 2, 3), IDENTITY, (1, 3, -2), (0, 1, 0), (1, 0, 0)),
    # Unreal: centimetres, x forward, y right, z up; the camera looks along its +x.
    ("unreal", (100, 200, 300), IDENTITY, (2, 3, -1), (0, 0, -1), (0, 1, 0)),
    # Unreal yaw +90° about z turns x into y: looks right (Unreal +Y), which is csmlab +X.
    ("unreal", (0, 0, 170), (0, 0, S, S), (0, 1.7, 0), (1, 0, 0), (0, 1, 0)),
    # Unity: z forward; the camera looks along its +z, which is csmlab -Z.
    ("unity", (1, 2, 3), IDENTITY, (1, 2, -3), (0, 0, -1), (0, 1, 0)),
    # Unity yaw +90° about y turns z into x: looks right (+X), which is csmlab +X.
    ("unity", (1, 2, 3), (0, S, 0, S), (1, 2, -3), (1, 0, 0), (0, 1, 0)),
]


@pytest.mark.parametrize("convention, p_file, q_file, p_expected, forward, up", HAND_POSES)
def test_hand_pose_lands_in_csmlab_convention_as_documented(convention, p_file, q_file, p_expected, forward, up):
    p, q = poses_to_opengl(np.array([p_file], float), np.array([q_file], float), convention=convention)
    r = quat_to_matrix(q[0])
    np.testing.assert_allclose(p[0], p_expected, atol=1e-12)
    np.testing.assert_allclose(-r[:, 2], forward, atol=1e-12)
    np.testing.assert_allclose(r[:, 1], up, atol=1e-12)


def _quaternion_of_axes(right_down_forward):
    """Quaternion of an optical camera (x right, y down, z forward) whose axes are the given world vectors."""
    return quat_from_matrix(np.array(right_down_forward, dtype=float).T)


def test_level_camera_in_z_up_conventions_looks_level_in_csmlab():
    # A camera looking horizontally along the room's +X with the room's +Z up on the image:
    # optical axes z = +X, y (down) = -Z, x = y × z = -Y; EuRoC body axes x (up) = +Z,
    # y (right) = -Y, z (forward) = +X. Both must look along csmlab +X with +Y up.
    optical = _quaternion_of_axes([(0, -1, 0), (0, 0, -1), (1, 0, 0)])
    body = quat_from_matrix(np.array([(0, 0, 1), (0, -1, 0), (1, 0, 0)], float).T)
    for convention, q in (("mocap", optical), ("euroc", body)):
        _, q_gl = poses_to_opengl(np.zeros((1, 3)), q[None], convention=convention)
        r = quat_to_matrix(q_gl[0])
        np.testing.assert_allclose(-r[:, 2], (1, 0, 0), atol=1e-12, err_msg=convention)
        np.testing.assert_allclose(r[:, 1], (0, 1, 0), atol=1e-12, err_msg=convention)


def test_conversion_matches_matrix_formula_and_inverts_for_every_convention():
    # Oracle: p = u·W p_f and R = W R_f K evaluated with plain matrices.
    rng = np.random.default_rng(7)
    p_file = rng.normal(size=(20, 3)) * 10
    q_file = rng.normal(size=(20, 4))
    q_file /= np.linalg.norm(q_file, axis=1, keepdims=True)
    for name, c in CONVENTIONS.items():
        p, q = poses_to_opengl(p_file, q_file, convention=name)
        np.testing.assert_allclose(p, c.metres_per_unit * p_file @ c.world.T, atol=1e-12, err_msg=name)
        np.testing.assert_allclose(quat_to_matrix(q), c.world @ quat_to_matrix(q_file) @ c.camera, atol=1e-12,
                                   err_msg=name)
        p_back, q_back = poses_from_opengl(p, q, convention=name)
        np.testing.assert_allclose(p_back, p_file, atol=1e-12, err_msg=name)
        np.testing.assert_allclose(quat_to_matrix(q_back), quat_to_matrix(q_file), atol=1e-12, err_msg=name)


def test_unknown_convention_lists_the_valid_ones():
    with pytest.raises(ValueError, match="convention: expected one of .*'unity'.*got 'blender'"):
        poses_to_opengl(np.zeros((1, 3)), np.array([IDENTITY]), convention="blender")


def _rotation(axis: int, degrees: float) -> np.ndarray:
    a = np.radians(degrees)
    c, s = np.cos(a), np.sin(a)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    m = np.eye(3)
    m[i, i] = m[j, j] = c
    m[i, j], m[j, i] = -s, s
    return m


def test_yaw_pitch_roll_is_ry_rx_rz_of_textbook_rotation_matrices():
    rng = np.random.default_rng(3)
    angles = rng.uniform(-180, 180, size=(10, 3))
    q = orientation_from_yaw_pitch_roll(yaw_deg=angles[:, 0], pitch_deg=angles[:, 1], roll_deg=angles[:, 2])
    for (yaw, pitch, roll), r in zip(angles, quat_to_matrix(q)):
        expected = _rotation(1, yaw) @ _rotation(0, pitch) @ _rotation(2, roll)
        np.testing.assert_allclose(r, expected, atol=1e-12)


def test_yaw_turns_left_and_pitch_looks_up():
    q = orientation_from_yaw_pitch_roll(yaw_deg=[90.0, 0.0, 0.0], pitch_deg=[0.0, 30.0, 0.0],
                                        roll_deg=[0.0, 0.0, 90.0])
    r = quat_to_matrix(q)
    np.testing.assert_allclose(-r[0][:, 2], (-1, 0, 0), atol=1e-12)
    np.testing.assert_allclose(-r[1][:, 2], (0, 0.5, -np.sqrt(0.75)), atol=1e-12)
    np.testing.assert_allclose(r[2][:, 1], (-1, 0, 0), atol=1e-12)
