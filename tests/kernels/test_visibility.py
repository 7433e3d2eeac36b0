"""Camera G-buffer of both methods against analytic ray casts on ``plane_box`` (a plane and an axis-aligned
box) and NumPy brute force, and the raster against the ray cast (its independent float32 oracle)."""

import numpy as np
import pytest
import warp as wp

from csmlab.camera import CameraPose
from csmlab.geometry import rotation_looking_at
from csmlab.kernels.threads import split_range
from csmlab.kernels.visibility import VISIBILITY_METHODS, camera_hits, camera_hits_raster, mesh_bvh
from csmlab.scene import Scene, make_scene
from csmlab.scene.plane_box import plane_box

PLANE_HALF = 20.0
BOX_LO = np.array([-1.0, 0.0, -1.0])
BOX_HI = np.array([1.0, 2.0, 1.0])


METHODS = sorted(VISIBILITY_METHODS)


def shifted_plane_box(offset, divisions: int = 1) -> Scene:
    s = plane_box(plane_size=2 * PLANE_HALF, plane_divisions=divisions, box_size=2.0, box_height=2.0)
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


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("offset, eye, look, divisions", [
    ((0.0, 0.0, 0.0), (6.0, 4.0, 9.0), (-6.0, -3.5, -9.0), 1),
    ((1e5, 30.0, -2e5), (6.0, 4.0, 9.0), (-6.0, -3.5, -9.0), 1),
    # Standing on a divided plane and looking ahead: the 10 m triangles under the eye cross the
    # camera plane and fill the bottom of the image.
    ((0.0, 0.0, 0.0), (0.3, 1.7, 4.7), (-0.1, -0.15, -1.0), 4),
], ids=["origin", "far", "standing"])
def test_view_depth_equals_analytic_ray_plane_intersection(method, offset, eye, look, divisions, device):
    width, height = 64, 40
    eye = np.array(eye) + offset
    pose = CameraPose(position=eye, orientation=rotation_looking_at(np.array(look)), aspect=width / height, far=100.0)
    scene = shifted_plane_box(offset, divisions)
    hits = camera_hits(mesh_bvh(scene.vertices, scene.triangles, device=device), position=pose.position,
                       rotation=pose.rotation, fov_y_deg=pose.fov_y_deg, aspect=pose.aspect, far=pose.far, width=width,
                       height=height, method=method)
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
    if divisions > 1:
        depth = (scene.vertices - eye) @ pose.forward
        crossing = np.flatnonzero((depth[scene.triangles].min(axis=1) < 0) & (depth[scene.triangles].max(axis=1) > 0))
        assert np.isin(crossing, hits.triangle).sum() >= 3


@pytest.mark.parametrize("method", METHODS)
def test_normals_face_the_camera_whatever_the_winding(method, device):
    scene = shifted_plane_box((0.0, 0.0, 0.0))
    flipped = Scene(scene.vertices, scene.triangles[:, ::-1].copy(), -scene.normals, scene.albedo)
    eye = np.array([4.0, 3.0, 5.0])
    pose = CameraPose(position=eye, orientation=rotation_looking_at(-eye), far=100.0)
    for s in (scene, flipped):
        hits = camera_hits(mesh_bvh(s.vertices, s.triangles, device=device), position=eye, rotation=pose.rotation,
                           fov_y_deg=pose.fov_y_deg, aspect=pose.aspect, far=pose.far, width=32, height=18,
                           method=method)
        valid = hits.triangle >= 0
        assert np.all(np.sum(hits.normal[valid] * (eye - hits.position[valid]), axis=-1) > 0)


@pytest.mark.parametrize("method", METHODS)
def test_nothing_beyond_the_far_plane_is_hit(method, device):
    scene = shifted_plane_box((0.0, 0.0, 0.0))
    eye = np.array([0.0, 10.0, 0.0])
    pose = CameraPose(position=eye, orientation=rotation_looking_at([0.0, -1.0, 0.0]), near=0.1, far=9.0)
    hits = camera_hits(mesh_bvh(scene.vertices, scene.triangles, device=device), position=eye, rotation=pose.rotation,
                       fov_y_deg=pose.fov_y_deg, aspect=pose.aspect, far=pose.far, width=16, height=16, method=method)
    assert np.all(hits.triangle[hits.view_depth > 9.0] < 0)
    assert np.any(hits.triangle >= 0) and np.any(hits.triangle < 0)


@pytest.mark.cuda
@pytest.mark.skipif(wp.get_cuda_device_count() == 0, reason="no CUDA device")
@pytest.mark.parametrize("method", METHODS)
def test_cpu_and_cuda_see_the_same_hits(method):
    scene = shifted_plane_box((0.0, 0.0, 0.0))
    eye = np.array([6.0, 4.0, 9.0])
    pose = CameraPose(position=eye, orientation=rotation_looking_at(-eye), far=100.0)
    out = [camera_hits(mesh_bvh(scene.vertices, scene.triangles, device=device), position=eye, rotation=pose.rotation,
                       fov_y_deg=pose.fov_y_deg, aspect=pose.aspect, far=pose.far, width=64, height=36,
                       method=method)
           for device in ("cpu", "cuda:0")]
    if method == "raster":
        # float64 ray tests per pixel centre, no fused multiply-add on either device: the same bits.
        assert_same_hits(out[1], out[0])
    same = out[0].triangle == out[1].triangle
    assert same.mean() > 0.99
    np.testing.assert_allclose(out[0].view_depth[same], out[1].view_depth[same], rtol=1e-6)


def camera_frame(pose: CameraPose):
    """World → camera-space rows ``(right, up, forward)`` of the kernels' pixel rays ``(x, y, 1)``."""
    return np.stack([pose.rotation[:, 0], pose.rotation[:, 1], -pose.rotation[:, 2]])


def edge_distance_px(points, pose: CameraPose, width: int, height: int):
    """Pixels from every pixel centre to the image-plane line of every edge: ``(H, W, T, 3)``.

    ``points`` are the triangles' vertices in camera space, shape (T, 3, 3).
    """
    tan_y = np.tan(np.radians(pose.fov_y_deg) / 2)
    step = 2 * tan_y / height
    row, col = np.mgrid[0:height, 0:width].astype(np.float64)
    rays = np.stack([(col + 0.5 - width / 2) * 2 * tan_y * pose.aspect / width, (height / 2 - row - 0.5) * step,
                     np.ones_like(col)], axis=-1)
    planes = np.cross(points, np.roll(points, -1, axis=1))
    return np.abs(rays @ planes.reshape(-1, 3).T).reshape(height, width, -1, 3) / (
        np.hypot(planes[..., 0], planes[..., 1]) * step)


def brute_force_hits(points, pose: CameraPose, width: int, height: int, far: float):
    """Nearest triangle of each pixel ray by Möller–Trumbore over every triangle (camera space): (H, W) index, depth."""
    tan_y = np.tan(np.radians(pose.fov_y_deg) / 2)
    row, col = np.mgrid[0:height, 0:width].astype(np.float64)
    d = np.stack([(col + 0.5 - width / 2) * 2 * tan_y * pose.aspect / width, (height / 2 - row - 0.5) * 2 * tan_y
                  / height, np.ones_like(col)], axis=-1)[:, :, None]
    a, e1, e2 = points[:, 0], points[:, 1] - points[:, 0], points[:, 2] - points[:, 0]
    p = np.cross(d, e2)
    det = np.sum(e1 * p, axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.sum(-a * p, axis=-1) / det
        q = np.cross(-a, e1)
        v = np.sum(d * q, axis=-1) / det
        t = np.sum(e2 * q, axis=-1) / det
    hit = (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0) & (t <= far)
    t = np.where(hit, t, np.inf)
    return np.where(np.isfinite(t.min(axis=-1)), t.argmin(axis=-1), -1), t.min(axis=-1)


def test_raster_equals_brute_force_rays_with_triangles_crossing_the_camera_plane(device):
    rng = np.random.default_rng(5)
    width, height = 48, 32
    pose = CameraPose(position=np.array([3.0, -2.0, 7.0]), orientation=rotation_looking_at([0.3, 0.2, -1.0]),
                      aspect=width / height, far=30.0)
    # Large triangles around the eye, many reaching behind it: the camera plane cuts them.
    camera_space = rng.uniform(-6.0, 6.0, (40, 3, 3)) + np.array([0.0, 0.0, 3.0])
    vertices = pose.position + camera_space.reshape(-1, 3) @ camera_frame(pose)
    triangles = np.arange(vertices.shape[0]).reshape(-1, 3)
    hits = camera_hits(mesh_bvh(vertices, triangles, device=device), position=pose.position, rotation=pose.rotation,
                       fov_y_deg=pose.fov_y_deg, aspect=pose.aspect, far=pose.far, width=width, height=height,
                       method="raster")
    expected, depth = brute_force_hits(camera_space, pose, width, height, pose.far)
    robust = edge_distance_px(camera_space, pose, width, height).min(axis=(-1, -2)) > 1e-6
    assert robust.mean() > 0.95
    np.testing.assert_array_equal(hits.triangle[robust], expected[robust])
    hit = robust & (expected >= 0)
    np.testing.assert_allclose(hits.view_depth[hit], depth[hit], rtol=1e-6)
    crossing = np.flatnonzero((camera_space[..., 2].min(axis=1) < 0) & (camera_space[..., 2].max(axis=1) > 0))
    assert np.isin(crossing, hits.triangle).sum() >= 3


def dyadic_grid(cells: int, rng):
    """A triangulated grid whose vertices lie on pixel-centre rays two pixels apart, every coordinate dyadic.

    Camera at the origin looking down −z with ``tan(fov/2) = 0.75``, a square image of
    ``2·cells + 2`` pixels: every centre inside the grid lies on an edge or a vertex, and every
    camera-space product of the raster is exact. Vertices sit at random depths 1–3 m along their
    rays (a bumpy surface projecting to the same grid); diagonals and windings alternate.
    """
    size = 2 * cells + 2
    step = 1.5 / size
    k = np.arange(cells + 1) * 2
    sx, sy = np.meshgrid((k + 0.5 - size / 2) * step, (size / 2 - k - 0.5) * step)
    depth = rng.choice([1.0, 1.5, 2.0, 3.0], sx.shape)
    vertices = np.stack([sx * depth, sy * depth, -depth], axis=-1).reshape(-1, 3)
    triangles = []
    for j in range(cells):
        for i in range(cells):
            a, b = j * (cells + 1) + i, j * (cells + 1) + i + 1
            c, d = (j + 1) * (cells + 1) + i, (j + 1) * (cells + 1) + i + 1
            pair = [(a, b, d), (a, d, c)] if (i + j) % 2 else [(a, b, c), (b, d, c)]
            triangles += [t[::-1] if (i * 3 + j) % 2 else t for t in pair]
    fov = 73.73979529168804
    assert np.tan(np.radians(fov) / 2) == 0.75
    return vertices, np.array(triangles), size, fov


def test_each_centre_on_a_shared_edge_or_vertex_is_covered_exactly_once(device):
    vertices, triangles, size, fov = dyadic_grid(5, np.random.default_rng(2))
    kwargs = dict(position=np.zeros(3), rotation=np.eye(3), fov_y_deg=fov, aspect=1.0, far=10.0, width=size,
                  height=size, method="raster")
    # One mesh per triangle, the vertex array (and so the indices) unchanged: how many cover each centre.
    count = sum(camera_hits(mesh_bvh(vertices, triangles[k:k + 1], device=device), **kwargs).triangle >= 0
                for k in range(len(triangles)))
    np.testing.assert_array_equal(count[1:-2, 1:-2], 1)
    assert count.max() == 1
    assert np.all(camera_hits(mesh_bvh(vertices, triangles, device=device), **kwargs).triangle[1:-2, 1:-2] >= 0)


@pytest.mark.parametrize("atomic", [False, True], ids=["serial", "atomic"])
def test_equal_depths_go_to_the_lower_triangle_index(atomic, device):
    scene = shifted_plane_box((0.0, 0.0, 0.0), divisions=4)
    count = len(scene.triangles)
    # Every triangle twice: a copy (in reversed order) under indices 0..T−1, the original under T..2T−1.
    doubled = np.concatenate([scene.triangles[::-1], scene.triangles])
    eye = np.array([4.0, 3.0, 5.0])
    pose = CameraPose(position=eye, orientation=rotation_looking_at(-eye), far=100.0)
    once, twice = (camera_hits_raster(mesh_bvh(scene.vertices, t, device=device), position=eye, rotation=pose.rotation,
                                      fov_y_deg=pose.fov_y_deg, aspect=pose.aspect, far=pose.far, width=40, height=24,
                                      atomic=atomic) for t in (scene.triangles, doubled))
    valid = once.triangle >= 0
    assert valid.mean() > 0.5
    np.testing.assert_array_equal(twice.triangle >= 0, valid)
    np.testing.assert_array_equal(count - 1 - twice.triangle[valid], once.triangle[valid])


def walk_scene_and_pose(width: int, height: int):
    scene = make_scene("terrain", seed=1, resolution=24, trees=300, ring_trees=40)
    eye = np.array([20.0, 1.7, -1.0])
    pose = CameraPose(position=eye, orientation=rotation_looking_at([-0.35, -0.09, -1.0]), aspect=width / height,
                      far=400.0)
    return scene, pose


def test_atomic_resolve_gives_the_pixels_of_the_serial_one(device):
    scene, pose = walk_scene_and_pose(96, 54)
    bvh = mesh_bvh(scene.vertices, scene.triangles, device=device)
    out = [camera_hits_raster(bvh, position=pose.position, rotation=pose.rotation, fov_y_deg=pose.fov_y_deg,
                              aspect=pose.aspect, far=pose.far, width=96, height=54, atomic=atomic)
           for atomic in (False, True)]
    for a, b in zip(vars(out[0]).values(), vars(out[1]).values()):
        np.testing.assert_array_equal(a, b)


def test_raster_matches_the_ray_cast_on_a_walk_through_trees(device):
    width, height = 96, 54
    scene, pose = walk_scene_and_pose(width, height)
    bvh = mesh_bvh(scene.vertices, scene.triangles, device=device)
    ray, raster = (camera_hits(bvh, position=pose.position, rotation=pose.rotation, fov_y_deg=pose.fov_y_deg,
                               aspect=pose.aspect, far=pose.far, width=width, height=height, method=m)
                   for m in ("ray", "raster"))
    assert 0.3 < (raster.triangle >= 0).mean() < 1.0 and len(np.unique(raster.triangle)) > 100
    differ = ray.triangle != raster.triangle
    # The ray cast tests coverage in float32: it may pick a neighbour (or fall through a crack)
    # only within its rounding of an edge of the raster's triangle, a small fraction of a pixel.
    rows, cols = np.nonzero(differ & (raster.triangle >= 0))
    points = (scene.vertices[scene.triangles[raster.triangle[rows, cols]]] - pose.position) @ camera_frame(pose).T
    near_edge = [edge_distance_px(p[None], pose, width, height)[r, c].min() < 1e-3
                 for p, r, c in zip(points, rows, cols)]
    assert all(near_edge)
    assert differ.mean() < 1e-3 and not np.any(differ & (raster.triangle < 0) & (ray.triangle >= 0))
    same = ~differ & (ray.triangle >= 0)
    np.testing.assert_allclose(raster.position[same], ray.position[same], rtol=0, atol=1e-9)
    np.testing.assert_array_equal(raster.view_depth[~differ], ray.view_depth[~differ])
    np.testing.assert_array_equal(raster.normal[~differ], ray.normal[~differ])


def test_unknown_method_is_refused_with_the_valid_names(device):
    scene = shifted_plane_box((0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match=r"method: expected one of \['raster', 'ray'\], got 'rays' \(did you mean"):
        camera_hits(mesh_bvh(scene.vertices, scene.triangles, device=device), position=np.ones(3), rotation=np.eye(3),
                    fov_y_deg=60.0, aspect=1.0, far=10.0, width=4, height=4, method="rays")


def assert_same_hits(a, b):
    for name in ("position", "normal", "triangle", "view_depth"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


def threaded_scenes():
    """Scenes and views for the thread-count tests: name → (vertices, triangles, camera keywords)."""
    scenes = {}
    # Centres on shared edges and vertices everywhere (exact arithmetic): the top-left rule decides.
    vertices, triangles, size, fov = dyadic_grid(5, np.random.default_rng(2))
    scenes["shared edges"] = (vertices, triangles, dict(position=np.zeros(3), rotation=np.eye(3), fov_y_deg=fov,
                                                        aspect=1.0, far=10.0, width=size, height=size))
    # Large triangles around the eye, many reaching behind it: the camera plane cuts them.
    pose = CameraPose(position=np.array([3.0, -2.0, 7.0]), orientation=rotation_looking_at([0.3, 0.2, -1.0]),
                      aspect=48 / 31, far=30.0)
    camera_space = np.random.default_rng(5).uniform(-6.0, 6.0, (40, 3, 3)) + np.array([0.0, 0.0, 3.0])
    scenes["camera plane"] = (pose.position + camera_space.reshape(-1, 3) @ camera_frame(pose),
                              np.arange(120).reshape(-1, 3),
                              dict(position=pose.position, rotation=pose.rotation, fov_y_deg=pose.fov_y_deg,
                                   aspect=pose.aspect, far=pose.far, width=48, height=31))
    # Standing on a plane of 10 m triangles: each spans many rows, those underfoot cross the camera plane.
    scene = shifted_plane_box((0.0, 0.0, 0.0), divisions=4)
    pose = CameraPose(position=np.array([0.3, 1.7, 4.7]), orientation=rotation_looking_at([-0.1, -0.15, -1.0]),
                      aspect=64 / 41, far=100.0)
    scenes["standing"] = (scene.vertices, scene.triangles, dict(
        position=pose.position, rotation=pose.rotation, fov_y_deg=pose.fov_y_deg, aspect=pose.aspect, far=pose.far,
        width=64, height=41))
    scene, pose = walk_scene_and_pose(96, 54)
    scenes["walk through trees"] = (scene.vertices, scene.triangles, dict(
        position=pose.position, rotation=pose.rotation, fov_y_deg=pose.fov_y_deg, aspect=pose.aspect, far=pose.far,
        width=96, height=54))
    return scenes


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("scene", ["shared edges", "camera plane", "standing", "walk through trees"])
def test_every_thread_count_gives_the_hits_of_one_thread(method, scene, device):
    vertices, triangles, camera = threaded_scenes()[scene]
    bvh = mesh_bvh(vertices, triangles, device=device)
    one = camera_hits(bvh, **camera, method=method)
    assert (one.triangle >= 0).mean() > 0.3 and len(np.unique(one.triangle)) >= 4
    threads = (2, 3, 7)
    # Some triangle covers pixels on both sides of a boundary between the bands of rows of a split.
    first_rows = {lo for t in threads for lo, _ in split_range(camera["height"], t)} - {0}
    assert any(np.isin(np.setdiff1d(one.triangle[r], [-1]), one.triangle[r - 1]).any() for r in first_rows)
    for t in threads:
        assert_same_hits(camera_hits(bvh, **camera, method=method, threads=t), one)


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("width, height", [(5, 2), (3, 1), (1, 1)])
def test_images_with_fewer_rows_than_threads_get_the_hits_of_one_thread(method, width, height, device):
    scene = shifted_plane_box((0.0, 0.0, 0.0), divisions=2)
    eye = np.array([0.5, 2.0, 1.5])
    pose = CameraPose(position=eye, orientation=rotation_looking_at([0.0, -1.0, -0.4]), aspect=width / height,
                      far=100.0)
    kwargs = dict(position=eye, rotation=pose.rotation, fov_y_deg=pose.fov_y_deg, aspect=pose.aspect, far=pose.far,
                  width=width, height=height, method=method)
    bvh = mesh_bvh(scene.vertices, scene.triangles, device=device)
    one = camera_hits(bvh, **kwargs)
    assert np.all(one.triangle >= 0)
    for threads in (2, 3):
        assert_same_hits(camera_hits(bvh, **kwargs, threads=threads), one)


@pytest.mark.parametrize("method", METHODS)
def test_a_view_of_nothing_is_all_misses_for_every_thread_count(method, device):
    scene = shifted_plane_box((0.0, 0.0, 0.0))
    # Looking up from above everything.
    pose = CameraPose(position=np.array([0.0, 5.0, 0.0]), orientation=rotation_looking_at([0.2, 1.0, 0.1]),
                      aspect=1.5, far=100.0)
    for threads in (1, 2, 3):
        hits = camera_hits(mesh_bvh(scene.vertices, scene.triangles, device=device), position=pose.position,
                           rotation=pose.rotation, fov_y_deg=pose.fov_y_deg, aspect=pose.aspect, far=pose.far,
                           width=12, height=8, method=method, threads=threads)
        assert np.all(hits.triangle == -1) and np.all(np.isnan(hits.position)) and np.all(hits.view_depth == np.inf)


@pytest.mark.parametrize("atomic", [False, True], ids=["serial", "atomic"])
@pytest.mark.parametrize("threads", [2, 3])
def test_equal_depths_go_to_the_lower_triangle_index_across_threads(atomic, threads, device):
    # Each triangle and its copy: with an odd count the two fall to different launches' buffers.
    scene = shifted_plane_box((0.0, 0.0, 0.0), divisions=4)
    triangles = scene.triangles[:-1]
    count = len(triangles)
    assert count % 2 == 1 and count % 3 != 0
    doubled = np.concatenate([triangles[::-1], triangles])
    eye = np.array([4.0, 3.0, 5.0])
    pose = CameraPose(position=eye, orientation=rotation_looking_at(-eye), far=100.0)
    kwargs = dict(position=eye, rotation=pose.rotation, fov_y_deg=pose.fov_y_deg, aspect=pose.aspect, far=pose.far,
                  width=40, height=24, atomic=atomic)
    once = camera_hits_raster(mesh_bvh(scene.vertices, triangles, device=device), **kwargs)
    twice = camera_hits_raster(mesh_bvh(scene.vertices, doubled, device=device), **kwargs, threads=threads)
    valid = once.triangle >= 0
    assert valid.mean() > 0.5
    np.testing.assert_array_equal(twice.triangle >= 0, valid)
    np.testing.assert_array_equal(count - 1 - twice.triangle[valid], once.triangle[valid])


@pytest.mark.parametrize("threads", [0, -2, 1.5, True, "2", None])
def test_threads_must_be_a_positive_integer(threads, device):
    scene = shifted_plane_box((0.0, 0.0, 0.0))
    for method in METHODS:
        with pytest.raises(ValueError, match=r"threads: expected an integer >= 1"):
            camera_hits(mesh_bvh(scene.vertices, scene.triangles, device=device), position=np.ones(3),
                        rotation=np.eye(3), fov_y_deg=60.0, aspect=1.0, far=10.0, width=4, height=4, method=method,
                        threads=threads)


@pytest.mark.parametrize("look, far", [((-0.35, -0.09, -1.0), 400.0), ((0.9, -0.2, 0.3), 60.0),
                                       ((0.0, -1.0, 0.01), 400.0)])
def test_the_chunks_left_out_of_the_view_hold_only_triangles_the_out_codes_cull(look, far, device):
    """A chunk is dropped only when every triangle in it has its three vertices outside one of the six half-spaces,
    as the kernel's out-codes find them (the oracle here: the same planes in NumPy, per vertex)."""
    from csmlab.kernels.visibility import CHUNK, NEAR_FRACTION, _pinhole, chunks_in_view

    scene = make_scene("terrain", seed=1, resolution=24, trees=300, ring_trees=40)
    pose = CameraPose(position=np.array([20.0, 1.7, -1.0]), orientation=rotation_looking_at(look), aspect=96 / 54,
                      far=far)
    bvh = mesh_bvh(scene.vertices, scene.triangles, device=device)
    eye, right, up, forward, step_x, step_y = _pinhole(bvh, pose.position, pose.rotation, pose.fov_y_deg,
                                                       pose.aspect, far, 96, 54)
    # The image's sides at unit depth, padded by a pixel, as camera_hits_raster pads them.
    frustum = [-49.0 * float(step_x), 49.0 * float(step_x), -28.0 * float(step_y), 28.0 * float(step_y)]
    near = NEAR_FRACTION * far
    kept = chunks_in_view(bvh, eye=eye, right=right, up=up, forward=forward, frustum=wp.vec4d(*frustum), near=near,
                          far=far)
    p = bvh.vertices.numpy() - np.array(eye, dtype=np.float64)
    x, y, z = (p @ np.array(a, dtype=np.float64) for a in (right, up, forward))
    code = ((z < near) * 1 | (z > far) * 2 | (x < frustum[0] * z) * 4 | (x > frustum[1] * z) * 8
            | (y < frustum[2] * z) * 16 | (y > frustum[3] * z) * 32)
    tri = scene.triangles
    seen = (code[tri[:, 0]] & code[tri[:, 1]] & code[tri[:, 2]]) == 0
    needed = np.unique(np.flatnonzero(seen) // CHUNK)
    assert np.isin(needed, kept).all()
    assert 0 < len(kept) < 0.8 * -(-len(tri) // CHUNK)
