"""Host geometry: quaternions, light basis, and the closed-form slice bounding sphere."""

import numpy as np
import pytest

from csmlab.geometry import (frustum_slice_corners, light_basis, normalized, quat_from_matrix,
                             quat_multiply, quat_slerp, quat_to_matrix, rotation_looking_at, slice_bounding_sphere,
                             validate_unit_quaternion)


def _random_quaternions(rng, n):
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def test_quaternion_matrices_are_rotations_and_round_trip():
    q = _random_quaternions(np.random.default_rng(0), 200)
    m = quat_to_matrix(q)
    np.testing.assert_allclose(m @ np.swapaxes(m, -1, -2), np.broadcast_to(np.eye(3), m.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(m), 1.0, atol=1e-12)
    back = quat_from_matrix(m)
    same = np.minimum(np.abs(back - q).max(axis=1), np.abs(back + q).max(axis=1))
    assert same.max() < 1e-12


def test_quaternion_product_composes_rotations():
    rng = np.random.default_rng(1)
    a, b = _random_quaternions(rng, 50), _random_quaternions(rng, 50)
    np.testing.assert_allclose(quat_to_matrix(quat_multiply(a, b)), quat_to_matrix(a) @ quat_to_matrix(b), atol=1e-12)


def test_slerp_keeps_endpoints_and_constant_angular_speed():
    rng = np.random.default_rng(2)
    a, b = _random_quaternions(rng, 2)
    t = np.linspace(0, 1, 11)
    q = quat_slerp(np.repeat(a[None], 11, 0), np.repeat(b[None], 11, 0), t)
    np.testing.assert_allclose(np.abs(np.sum(q[0] * a)), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.abs(np.sum(q[-1] * b)), 1.0, atol=1e-12)
    steps = np.arccos(np.clip(np.abs(np.sum(q[1:] * q[:-1], axis=1)), -1, 1))
    np.testing.assert_allclose(steps, steps[0], atol=1e-9)


@pytest.mark.parametrize("d", [(0, -1, 0), (0, 1, 0), (1, 0, 0), (0, 0, -1), (0.3, -0.8, 0.2), (1e-9, -1, 0)])
def test_light_basis_is_orthonormal_for_any_direction_including_straight_down(d):
    b = light_basis(d)
    np.testing.assert_allclose(b @ b.T, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(b), 1.0, atol=1e-12)
    np.testing.assert_allclose(b[2], np.asarray(d) / np.linalg.norm(d), atol=1e-12)


@pytest.mark.parametrize("d", [(0, 0, 0), (np.nan, -1, 0), (np.inf, 0, 0)])
def test_light_basis_rejects_zero_and_non_finite_directions(d):
    with pytest.raises(ValueError, match="light direction"):
        light_basis(d)


def test_camera_looking_along_the_light_is_valid():
    q = rotation_looking_at((0, -1, 0))
    np.testing.assert_allclose(-quat_to_matrix(q)[:, 2], (0, -1, 0), atol=1e-12)


@pytest.mark.parametrize("fov, aspect, z0, z1", [(60, 16 / 9, 0.1, 13.0), (60, 16 / 9, 59.9, 200.0),
                                                  (90, 1.0, 1.0, 1.5), (30, 2.35, 0.1, 400.0)])
def test_slice_sphere_is_the_smallest_enclosing_sphere_on_the_view_axis(fov, aspect, z0, z1):
    s = slice_bounding_sphere(fov_y_deg=fov, aspect=aspect, z_near=z0, z_far=z1)
    corners = frustum_slice_corners(position=(0, 0, 0), orientation=(0, 0, 0, 1), fov_y_deg=fov, aspect=aspect,
                                    z_near=z0, z_far=z1)
    # Oracle: brute-force search over centre depth for the smallest max distance to the corners.
    depths = np.linspace(z0, z1, 200001)
    centres = np.stack([0 * depths, 0 * depths, -depths], 1)
    radii = np.max(np.linalg.norm(corners[None, :, :] - centres[:, None], axis=2), axis=1)
    assert s.radius == pytest.approx(radii.min(), rel=1e-6)
    dist = np.linalg.norm(corners - np.array([0, 0, -s.centre_depth]), axis=1)
    assert dist.max() <= s.radius * (1 + 1e-12)


def test_normalized_and_quaternion_checks_name_the_field():
    with pytest.raises(ValueError, match="up"):
        normalized((0, 0, 0), name="up")
    with pytest.raises(ValueError, match="orientation.*unit"):
        validate_unit_quaternion((0, 0, 0, 2))
    with pytest.raises(ValueError, match="NaN"):
        validate_unit_quaternion((np.nan, 0, 0, 1))
