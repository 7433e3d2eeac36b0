"""Camera poses and paths refuse bad input with the field's name, and sample correctly."""

import numpy as np
import pytest

from csmlab.camera import CameraPath, CameraPose
from csmlab.geometry import quat_to_matrix, rotation_looking_at


@pytest.mark.parametrize("kwargs, match", [
    (dict(near=0.0), "near"), (dict(near=-1.0), "near"), (dict(near=1.0, far=1.0), "far"),
    (dict(orientation=(0, 0, 0, 0)), "unit quaternion"), (dict(orientation=(np.nan, 0, 0, 1)), "NaN"),
    (dict(orientation=(0, 0, 0, 1.1)), "unit quaternion"), (dict(position=(np.nan, 0, 0)), "position"),
    (dict(fov_y_deg=0.0), "fov_y_deg"),
])
def test_bad_pose_names_the_field(kwargs, match):
    args = dict(position=(0, 0, 0), orientation=(0, 0, 0, 1)) | kwargs
    with pytest.raises(ValueError, match=match):
        CameraPose(**args)


def test_path_rejects_times_going_back_and_nan_positions():
    q = np.tile([0, 0, 0, 1.0], (3, 1))
    with pytest.raises(ValueError, match="increasing"):
        CameraPath(times=[0, 2, 1], positions=np.zeros((3, 3)), orientations=q, fov_y_deg=60)
    with pytest.raises(ValueError, match="pose 1"):
        CameraPath(times=[0, 1, 2], positions=[[0, 0, 0], [np.nan, 0, 0], [0, 0, 0]], orientations=q, fov_y_deg=60)


def test_resample_keeps_endpoints_and_is_monotone():
    q = np.stack([rotation_looking_at((np.sin(a), 0, -np.cos(a))) for a in (0, 0.5, 1.0)])
    path = CameraPath(times=[0.0, 0.5, 1.0], positions=[[0, 0, 0], [1, 0, 0], [1, 1, 0]], orientations=q, fov_y_deg=60)
    r = path.resample(10)
    assert len(r) == 11 and np.all(np.diff(r.times) > 0)
    np.testing.assert_allclose(r.positions[[0, -1]], path.positions[[0, -1]], atol=1e-12)
    np.testing.assert_allclose(np.abs(np.sum(r.orientations[-1] * q[-1])), 1.0, atol=1e-12)



def test_resample_interpolates_positions_linearly_and_turns_at_a_constant_rate():
    # Yaw 0 → 0.5 → 1 rad about +Y at t = 0, 0.5, 1 s: the forward at time t points at yaw t.
    q = np.stack([rotation_looking_at((np.sin(a), 0, -np.cos(a))) for a in (0, 0.5, 1.0)])
    path = CameraPath(times=[0.0, 0.5, 1.0], positions=[[0, 0, 0], [1, 0, 0], [1, 1, 0]], orientations=q, fov_y_deg=60)
    r = path.resample(10)
    np.testing.assert_allclose(r.times, np.arange(11) / 10, atol=1e-12)
    expected = [[min(2 * t, 1.0), max(2 * t - 1.0, 0.0), 0.0] for t in r.times]
    np.testing.assert_allclose(r.positions, expected, atol=1e-12)
    forward = np.stack([quat_to_matrix(o) @ [0.0, 0.0, -1.0] for o in r.orientations])
    np.testing.assert_allclose(forward, np.stack([np.sin(r.times), 0 * r.times, -np.cos(r.times)], axis=1), atol=1e-9)


def test_view_depth_is_distance_along_the_view_axis():
    pose = CameraPose(position=(1, 2, 3), orientation=rotation_looking_at((0, 0, -1)))
    assert pose.view_depth([1, 2, -7]) == pytest.approx(10.0)
