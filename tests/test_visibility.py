"""Camera G-buffer against analytic ray casts on ``plane_box`` (a plane and an axis-aligned box)."""

import numpy as np
import pytest
import warp as wp

from csmlab.camera import CameraPose
from csmlab.geometry import rotation_looking_at
from csmlab.kernels.visibility import camera_hits, mesh_bvh
from csmlab.scene import Scene
from csmlab.scene.plane_box import plane_box

PLANE_HALF = 20.0
BOX_LO = np.array([-1.0, 0.0, -1.0])
BOX_HI = np.array([1.0, 2.0, 1.0])


def shifted_plane_box(offset) -> Scene:
    s = plane_box(plane_size=2 * PLANE_HALF, box_size=2.0, box_height=2.0)
    return Scene(s.vertices + np.asarray(offset), s.triangles, s.normals, s.albedo, name=s.name)


def pixel_rays(pose: CameraPose, width: int, height: int, *, dx=0.0, dy=0.0):
    """Unnormalised world directions ``(H, W, 3)`` through image points ``(col + ½ + dx, row + ½ + dy)``."""
    row, col = np.mgrid[0:height, 0:width].astype(np.float64)
    tan_y = np.tan(np.radians(pose.fov_y_deg) / 2)
    x = (2 * (col + 0.5 + dx) / width - 1) * tan_y * pose.aspect
    y = (1 - 2 * (row + 0.5 + dy) / height) * tan_y
    return np.stack([x, y, -np.ones_like(x)], axis=-1) @ pose.rotation.T


def analytic_hits(origin, directions, offset):
    """Nearest hit of each ray on the plane (y = 0, |x|,|z| ≤ 20) and the box: ray parameter, surface id, normal."""
    o = origin - np.asarray(offset)
    d = directions
    with np.errstate(divide="ignore", invalid="ignore"):
        t_plane = -o[1] / d[..., 1]
        p = o + t_plane[..., None] * d
        on_plane = (t_plane > 0) & (np.abs(p[..., 0]) <= PLANE_HALF) & (np.abs(p[..., 2]) <= PLANE_HALF)
        t1 = (BOX_LO - o) / d
        t2 = (BOX_HI - o) / d
    t_near = np.minimum(t1, t2).max(axis=-1)
    t_far = np.maximum(t1, t2).min(axis=-1)
    on_box = (t_near <= t_far) & (t_near > 0)
    axis = np.minimum(t1, t2).argmax(axis=-1)
    t = np.where(on_plane, t_plane, np.inf)
    box_first = on_box & (t_near < t)
    t = np.where(box_first, t_near, t)
    surface = np.where(box_first, 1 + axis, np.where(on_plane, 0, -1))
    normal = np.zeros(d.shape)
    normal[..., 1] = 1.0
    facing = -np.sign(np.take_along_axis(d[box_first], axis[box_first, None], 1))
    normal[box_first] = np.eye(3)[axis[box_first]] * facing
    return t, surface, normal


@pytest.mark.parametrize("offset", [(0.0, 0.0, 0.0), (1e5, 30.0, -2e5)], ids=["origin", "far"])
def test_view_depth_equals_analytic_ray_plane_intersection(offset):
    width, height = 64, 40
    eye = np.array([6.0, 4.0, 9.0]) + offset
    pose = CameraPose(position=eye, orientation=rotation_looking_at(np.array([-6.0, -3.5, -9.0])),
                      aspect=width / height, far=100.0)
    bvh = mesh_bvh(shifted_plane_box(offset).vertices, shifted_plane_box(offset).triangles)
    hits = camera_hits(bvh, position=pose.position, rotation=pose.rotation, fov_y_deg=pose.fov_y_deg,
                       aspect=pose.aspect, far=pose.far, width=width, height=height)
    directions = pixel_rays(pose, width, height)
    t, surface, normal = analytic_hits(eye, directions, offset)
    # Pixels whose ray passes within a thousandth of a pixel of a silhouette are not compared.
    robust = np.ones(surface.shape, dtype=bool)
    for dx, dy in ((1e-3, 0), (-1e-3, 0), (0, 1e-3), (0, -1e-3)):
        robust &= analytic_hits(eye, pixel_rays(pose, width, height, dx=dx, dy=dy), offset)[1] == surface
    assert robust.mean() > 0.9
    hit = surface >= 0
    assert 0.2 < hit.mean() < 0.95 and np.any(surface > 0)
    np.testing.assert_array_equal(hits.triangle[robust] >= 0, hit[robust])

    both = robust & hit
    expected_position = eye + np.where(hit, t, 0.0)[..., None] * directions
    expected_depth = (expected_position - eye) @ pose.forward
    np.testing.assert_allclose(hits.view_depth[both], expected_depth[both], rtol=0, atol=1e-5)
    np.testing.assert_allclose(hits.position[both], expected_position[both], rtol=0, atol=1e-8)
    np.testing.assert_allclose(hits.normal[both], normal[both], atol=1e-6)
    missed = robust & ~hit
    assert np.all(np.isnan(hits.position[missed])) and np.all(hits.view_depth[missed] == np.inf)
    assert np.all(hits.normal[missed] == 0) and np.all(hits.triangle[missed] == -1)


def test_normals_face_the_camera_whatever_the_winding():
    scene = shifted_plane_box((0.0, 0.0, 0.0))
    flipped = Scene(scene.vertices, scene.triangles[:, ::-1].copy(), -scene.normals, scene.albedo)
    eye = np.array([4.0, 3.0, 5.0])
    pose = CameraPose(position=eye, orientation=rotation_looking_at(-eye), far=100.0)
    for s in (scene, flipped):
        hits = camera_hits(mesh_bvh(s.vertices, s.triangles), position=eye, rotation=pose.rotation,
                           fov_y_deg=pose.fov_y_deg, aspect=pose.aspect, far=pose.far, width=32, height=18)
        valid = hits.triangle >= 0
        assert np.all(np.sum(hits.normal[valid] * (eye - hits.position[valid]), axis=-1) > 0)


def test_nothing_beyond_the_far_plane_is_hit():
    scene = shifted_plane_box((0.0, 0.0, 0.0))
    eye = np.array([0.0, 10.0, 0.0])
    pose = CameraPose(position=eye, orientation=rotation_looking_at([0.0, -1.0, 0.0]), near=0.1, far=9.0)
    hits = camera_hits(mesh_bvh(scene.vertices, scene.triangles), position=eye, rotation=pose.rotation,
                       fov_y_deg=pose.fov_y_deg, aspect=pose.aspect, far=pose.far, width=16, height=16)
    assert np.all(hits.triangle[hits.view_depth > 9.0] < 0)
    assert np.any(hits.triangle >= 0) and np.any(hits.triangle < 0)


@pytest.mark.skipif(wp.get_cuda_device_count() == 0, reason="no CUDA device")
def test_cpu_and_cuda_see_the_same_hits():
    scene = shifted_plane_box((0.0, 0.0, 0.0))
    eye = np.array([6.0, 4.0, 9.0])
    pose = CameraPose(position=eye, orientation=rotation_looking_at(-eye), far=100.0)
    out = [camera_hits(mesh_bvh(scene.vertices, scene.triangles, device=device), position=eye, rotation=pose.rotation,
                       fov_y_deg=pose.fov_y_deg, aspect=pose.aspect, far=pose.far, width=64, height=36)
           for device in ("cpu", "cuda")]
    same = out[0].triangle == out[1].triangle
    assert same.mean() > 0.99
    np.testing.assert_allclose(out[0].view_depth[same], out[1].view_depth[same], rtol=1e-6)
