"""Hard shadow by both reference methods: analytic cases, and the irregular z-buffer against the BVH ray cast."""

import numpy as np
import pytest
import warp as wp

from csmlab.camera import CameraPose
from csmlab.geometry import light_basis, rotation_looking_at
from csmlab.kernels.reference import CHUNK, RAY_OFFSET, REFERENCE_METHODS, hard_shadow
from csmlab.kernels.visibility import camera_hits, mesh_bvh
from csmlab.light import direction_from_angles
from csmlab.scene import Scene, make_scene
from csmlab.scene.plane_box import plane_box

BOX_LO = np.array([-1.0, 0.0, -1.0])
BOX_HI = np.array([1.0, 2.0, 1.0])
METHODS = sorted(REFERENCE_METHODS)
UP = np.float32([0.0, 1.0, 0.0])


def ray_meets_box(points, toward, lo, hi):
    """Whether ``p + s·toward`` (s > 0) passes through the box [lo, hi] (slab test)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (lo - points) / toward
        t2 = (hi - points) / toward
    near = np.nanmax(np.minimum(t1, t2), axis=-1)
    far = np.nanmin(np.maximum(t1, t2), axis=-1)
    return (near <= far) & (far > 0)


def shifted(scene: Scene, offset) -> Scene:
    return Scene(scene.vertices + np.asarray(offset), scene.triangles, scene.normals, scene.albedo)


def quad(corners) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and the two triangles of the planar quad with the four ``corners`` in order."""
    return np.asarray(corners, dtype=np.float64), np.array([[0, 1, 2], [0, 2, 3]])


def plane_and_quad(ground_half: float, quad_corners, offset=(0.0, 0.0, 0.0), *, device):
    """A ground square at y = 0 and one more quad, moved by ``offset``: a MeshBVH."""
    g = ground_half
    ground, tg = quad([[-g, 0.0, -g], [g, 0.0, -g], [g, 0.0, g], [-g, 0.0, g]])
    top, tq = quad(quad_corners)
    vertices = np.concatenate([ground, top]) + np.asarray(offset)
    return mesh_bvh(vertices, np.concatenate([tg, tq + 4]), device=device)


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("offset", [(0.0, 0.0, 0.0), (-3e5, 12.0, 1e5)], ids=["origin", "far"])
@pytest.mark.parametrize("elevation, azimuth", [(35.0, 40.0), (70.0, 40.0), (45.0, 0.0)],
                         ids=["low", "high", "along-faces"])
def test_ground_points_are_shadowed_exactly_where_the_box_blocks_the_light(method, offset, elevation, azimuth, device):
    rng = np.random.default_rng(7)
    d = direction_from_angles(elevation_deg=elevation, azimuth_deg=azimuth)
    scene = shifted(plane_box(plane_size=40.0, box_size=2.0, box_height=2.0), offset)
    ground = np.column_stack([rng.uniform(-4, 4, 4000), np.zeros(4000), rng.uniform(-4, 4, 4000)])
    outside_box = ~np.all((ground > BOX_LO - 1e-3) & (ground < BOX_HI + 1e-3), axis=1)
    ground = ground[outside_box]
    shadowed = ray_meets_box(ground, -d, BOX_LO, BOX_HI)
    # Points within a millimetre of the shadow's edge are not compared (the ray cast is float32).
    robust = shadowed == ray_meets_box(ground, -d, BOX_LO - 1e-3, BOX_HI + 1e-3)
    robust &= shadowed == ray_meets_box(ground, -d, BOX_LO + 1e-3, BOX_HI - 1e-3)
    normals = np.tile(UP, (ground.shape[0], 1))
    lit = hard_shadow(mesh_bvh(scene.vertices, scene.triangles, device=device), points=ground + offset, normals=normals,
                      light_direction=d, method=method)
    assert lit.dtype == np.float32
    assert 0.02 < shadowed[robust].mean() < 0.5
    np.testing.assert_array_equal(lit[robust], np.where(shadowed[robust], 0.0, 1.0))


@pytest.mark.parametrize("offset", [(0.0, 0.0, 0.0), (1e5, 0.0, -1e5)], ids=["origin", "far"])
def test_light_straight_down_shadows_the_closed_footprint_of_a_floating_quad(offset, device):
    # Straight down, light space is a permutation of world x and z: every coordinate below is exact
    # in float64, so the float64 method decides points on the footprint's edge exactly (closed).
    bvh = plane_and_quad(8.0, [[-1.0, 2.0, -1.0], [1.0, 2.0, -1.0], [1.0, 2.0, 1.0], [-1.0, 2.0, 1.0]], offset,
                         device=device)
    step = 2.0 ** -20
    xs = np.array([-1.0 - step, -1.0, -0.5, 0.0, 0.75, 1.0, 1.0 + step, 3.0])
    x, z = np.meshgrid(xs, xs)
    points = np.stack([x, np.zeros_like(x), z], axis=-1) + np.asarray(offset)
    lit = hard_shadow(bvh, points=points, normals=np.broadcast_to(UP, points.shape), light_direction=[0.0, -1.0, 0.0],
                      method="irregular")
    inside = (np.abs(x) <= 1.0) & (np.abs(z) <= 1.0)
    np.testing.assert_array_equal(lit, np.where(inside, 0.0, 1.0))


@pytest.mark.parametrize("method", METHODS)
def test_a_wall_along_the_light_casts_no_shadow_and_its_faces_are_dark(method, device):
    # The wall x = 0 contains the light direction: seen edge-on from the light, it blocks no ray
    # that does not start in its plane, and neither of its faces is turned toward the light.
    d = direction_from_angles(elevation_deg=30.0, azimuth_deg=0.0)
    bvh = plane_and_quad(8.0, [[0.0, 0.0, -1.0], [0.0, 0.0, 1.0], [0.0, 2.0, 1.0], [0.0, 2.0, -1.0]], device=device)
    z = np.linspace(-3.0, 3.0, 25)
    beside = np.concatenate([np.column_stack([np.full_like(z, x), np.zeros_like(z), z]) for x in (-0.05, 0.05)])
    on_wall = np.array([[0.0, 1.0, 0.0], [0.0, 0.5, 0.5]] * 2)
    wall_normals = np.float32([[1, 0, 0], [1, 0, 0], [-1, 0, 0], [-1, 0, 0]])
    lit = hard_shadow(bvh, points=np.concatenate([beside, on_wall]),
                      normals=np.concatenate([np.tile(UP, (beside.shape[0], 1)), wall_normals]), light_direction=d,
                      method=method)
    np.testing.assert_array_equal(lit, np.r_[np.ones(beside.shape[0]), np.zeros(4)])


@pytest.mark.parametrize("method", METHODS)
def test_faces_turned_from_the_light_are_shadowed_and_the_top_is_lit(method, device):
    d = direction_from_angles(elevation_deg=50.0, azimuth_deg=0.0)
    s = plane_box(plane_size=40.0, box_size=2.0, box_height=2.0)
    points = np.array([[0.2, 2.0, 0.3], [0.0, 1.0, -1.0], [0.0, 1.0, 1.0]])
    normals = np.float32([[0, 1, 0], [0, 0, -1], [0, 0, 1]])
    lit = hard_shadow(mesh_bvh(s.vertices, s.triangles, device=device), points=points, normals=normals,
                      light_direction=d, method=method)
    # d = -(0, sin 50°, cos 50°): the light comes from +z, so the -z face is turned away.
    np.testing.assert_array_equal(lit, [1.0, 0.0, 1.0])


@pytest.mark.parametrize("method", METHODS)
def test_points_that_are_not_receivers_give_nan_and_keep_their_shape(method, device):
    s = plane_box(plane_size=40.0)
    points = np.full((2, 3, 3), np.nan)
    points[0, 1] = [5.0, 0.0, 5.0]
    points[1, 2] = [6.0, 0.0, 5.0]
    normals = np.zeros((2, 3, 3), dtype=np.float32)
    normals[0, 1] = [0, 1, 0]
    normals[1, 2] = [0, -1, 0]
    lit = hard_shadow(mesh_bvh(s.vertices, s.triangles, device=device), points=points, normals=normals,
                      light_direction=[0, -1, 0], method=method)
    assert lit.shape == (2, 3)
    assert lit[0, 1] == 1.0 and lit[1, 2] == 0.0 and np.isnan(lit).sum() == 4


@pytest.mark.parametrize("method", METHODS)
def test_no_receiver_at_all_gives_all_nan(method, device):
    s = plane_box(plane_size=40.0)
    lit = hard_shadow(mesh_bvh(s.vertices, s.triangles, device=device), points=np.full((4, 3), np.nan),
                      normals=np.zeros((4, 3), np.float32), light_direction=[0.2, -1, 0], method=method)
    assert lit.shape == (4,) and np.all(np.isnan(lit))


def ambiguous_in_float32(scene: Scene, starts, d, tolerance: float) -> np.ndarray:
    """Whether each ray start (world, float64) lies within ``tolerance`` metres (light space) of a decision.

    That is, of the boundary of a triangle's light-space projection whose plane is not behind the
    start by more than ``tolerance``, or of the plane of a triangle whose projection contains it.
    """
    basis = light_basis(d)
    tri = scene.vertices[scene.triangles] @ basis.T
    out = []
    for s in np.asarray(starts) @ basis.T:
        a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
        e1, e2 = b - a, c - a
        area = e1[:, 0] * e2[:, 1] - e2[:, 0] * e1[:, 1]
        flat = np.abs(area) < 1e-12
        with np.errstate(divide="ignore", invalid="ignore"):
            wb = ((s[0] - a[:, 0]) * e2[:, 1] - (s[1] - a[:, 1]) * e2[:, 0]) / area
            wc = ((s[1] - a[:, 1]) * e1[:, 0] - (s[0] - a[:, 0]) * e1[:, 1]) / area
            along = s[2] - (a[:, 2] + wb * e1[:, 2] + wc * e2[:, 2])
        inside = (wb >= 0) & (wc >= 0) & (wb + wc <= 1) & ~flat
        edge = np.full(len(tri), np.inf)
        for p, q in ((a, b), (b, c), (c, a)):
            pq = q[:, :2] - p[:, :2]
            t = np.clip(np.einsum("ij,ij->i", s[:2] - p[:, :2], pq) / np.maximum(np.einsum("ij,ij->i", pq, pq), 1e-300),
                        0, 1)
            edge = np.minimum(edge, np.linalg.norm(s[:2] - p[:, :2] - t[:, None] * pq, axis=1))
        near_edge = (edge < tolerance) & ~(along < -tolerance)
        out.append(np.any(near_edge) or np.any(inside & (np.abs(along) < tolerance)))
    return np.array(out, dtype=bool)


@pytest.mark.parametrize("elevation, azimuth", [(40.0, 30.0), (8.0, 200.0), (75.0, -60.0)])
def test_irregular_z_buffer_matches_the_ray_cast_on_a_terrain_with_trees(elevation, azimuth, device):
    width, height = 160, 90
    scene = make_scene("terrain", seed=1, resolution=24, trees=300, ring_trees=40)
    eye = np.array([20.0, 1.7, -1.0])
    pose = CameraPose(position=eye, orientation=rotation_looking_at([-0.35, -0.09, -1.0]), aspect=width / height,
                      far=400.0)
    bvh = mesh_bvh(scene.vertices, scene.triangles, device=device)
    hits = camera_hits(bvh, position=pose.position, rotation=pose.rotation, fov_y_deg=pose.fov_y_deg,
                       aspect=pose.aspect, far=pose.far, width=width, height=height)
    d = direction_from_angles(elevation_deg=elevation, azimuth_deg=azimuth)
    ray, irregular = (hard_shadow(bvh, points=hits.position, normals=hits.normal, light_direction=d, method=m)
                      for m in ("ray", "irregular"))
    np.testing.assert_array_equal(np.isnan(irregular), np.isnan(ray))
    rays = irregular[~np.isnan(irregular)]
    assert 0.05 < (rays == 0).mean() < 0.95
    differ = (irregular != ray) & ~np.isnan(ray)
    # The ray cast decides in float32 (vertices and starts relative to the anchor, ~1e-5 m here):
    # it may differ only at starts within that rounding of an edge or a plane.
    starts = hits.position[differ] + hits.normal[differ] * (RAY_OFFSET * bvh.diagonal)
    assert differ.mean() < 1e-3
    assert np.all(ambiguous_in_float32(scene, starts, d, tolerance=1e-6 * bvh.diagonal))


def test_a_light_that_comes_back_gives_the_same_shadow_as_at_first(device):
    # Light-space vertices are kept per direction: alternating lights must not mix them up.
    scene = shifted(plane_box(plane_size=40.0, box_size=2.0, box_height=2.0), (50.0, 0.0, -20.0))
    bvh = mesh_bvh(scene.vertices, scene.triangles, device=device)
    rng = np.random.default_rng(3)
    points = np.column_stack([rng.uniform(46, 54, 500), np.zeros(500), rng.uniform(-24, -16, 500)])
    normals = np.tile(UP, (500, 1))
    lights = [direction_from_angles(elevation_deg=e, azimuth_deg=a) for e, a in ((30, 10), (50, 120), (20, 250))]
    first = [hard_shadow(mesh_bvh(scene.vertices, scene.triangles, device=device), points=points, normals=normals,
                         light_direction=d) for d in lights]
    assert all(0.0 < np.mean(f == 0) < 0.5 for f in first)
    for d, expected in zip(lights * 2, first * 2):
        np.testing.assert_array_equal(hard_shadow(bvh, points=points, normals=normals, light_direction=d), expected)
    assert len(bvh.light_space) <= 2


def test_unknown_method_is_refused_with_the_valid_names(device):
    s = plane_box(plane_size=40.0)
    with pytest.raises(ValueError, match=r"method: expected one of \['irregular', 'ray'\], got 'rays'"):
        hard_shadow(mesh_bvh(s.vertices, s.triangles, device=device), points=np.zeros((1, 3)),
                    normals=np.zeros((1, 3), np.float32), light_direction=[0, -1, 0], method="rays")


def terrain_receivers(width: int = 96, height: int = 54):
    """The terrain-with-trees scene and the G-buffer points and normals of a walking camera (misses NaN)."""
    scene = make_scene("terrain", seed=1, resolution=24, trees=300, ring_trees=40)
    pose = CameraPose(position=np.array([20.0, 1.7, -1.0]), orientation=rotation_looking_at([-0.35, -0.09, -1.0]),
                      aspect=width / height, far=400.0)
    hits = camera_hits(mesh_bvh(scene.vertices, scene.triangles), position=pose.position, rotation=pose.rotation,
                       fov_y_deg=pose.fov_y_deg, aspect=pose.aspect, far=pose.far, width=width, height=height)
    return scene, hits.position, hits.normal


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("elevation, azimuth", [(40.0, 30.0), (8.0, 200.0)])
def test_every_thread_count_gives_the_shadow_of_one_thread(method, elevation, azimuth, device):
    scene, points, normals = terrain_receivers()
    assert 0.0 < np.isnan(points[..., 0]).mean() < 0.5
    d = direction_from_angles(elevation_deg=elevation, azimuth_deg=azimuth)
    one = hard_shadow(mesh_bvh(scene.vertices, scene.triangles, device=device), points=points, normals=normals,
                      light_direction=d, method=method)
    assert 0.05 < np.nanmean(one == 0) < 0.95
    for threads in (2, 3, 7):
        # A new MeshBVH each time: its light-space vertices are transformed by the split too.
        lit = hard_shadow(mesh_bvh(scene.vertices, scene.triangles, device=device), points=points, normals=normals,
                          light_direction=d, method=method, threads=threads)
        np.testing.assert_array_equal(lit, one)


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("receivers", [0, 1, 2])
def test_fewer_receivers_than_threads_get_the_shadow_of_one_thread(method, receivers, device):
    bvh = plane_and_quad(8.0, [[-1.0, 2.0, -1.0], [1.0, 2.0, -1.0], [1.0, 2.0, 1.0], [-1.0, 2.0, 1.0]], device=device)
    # Under the quad (shadowed), beside it (lit), then a point that is not a receiver.
    points = np.array([[0.0, 0.0, 0.0], [4.0, 0.0, 0.0], [np.nan] * 3])[:receivers]
    normals = np.tile(UP, (receivers, 1))
    for threads in (1, 2, 3):
        lit = hard_shadow(bvh, points=points, normals=normals, light_direction=[0.0, -1.0, 0.0], method=method,
                          threads=threads)
        np.testing.assert_array_equal(lit, np.array([0.0, 1.0, np.nan], np.float32)[:receivers])


@pytest.mark.parametrize("method", METHODS)
def test_receivers_all_turned_from_the_light_are_dark_for_every_thread_count(method, device):
    s = plane_box(plane_size=40.0)
    points = np.column_stack([np.linspace(-5.0, 5.0, 9), np.zeros(9), np.zeros(9)])
    for threads in (1, 2, 3):
        lit = hard_shadow(mesh_bvh(s.vertices, s.triangles, device=device), points=points, normals=np.tile(-UP, (9, 1)),
                          light_direction=[0.2, -1.0, 0.0], method=method, threads=threads)
        np.testing.assert_array_equal(lit, np.zeros(9, np.float32))


def floating_squares(rng, count: int, *, area: float, height: float) -> tuple[np.ndarray, np.ndarray]:
    """``count`` horizontal squares (two triangles each) of side 0.5–3 at ``height`` over ``[0, area]²``
    (x, z), and their ``(x0, x1, z0, z1)`` extents, in the order drawn."""
    lo = rng.uniform(0.0, area, (count, 2))
    hi = lo + rng.uniform(0.5, 3.0, (count, 2))
    x0, z0, x1, z1 = lo[:, 0], lo[:, 1], hi[:, 0], hi[:, 1]
    y = np.full(count, height)
    corners = np.stack([np.column_stack(c) for c in ((x0, y, z0), (x1, y, z0), (x1, y, z1), (x0, y, z1))], axis=1)
    first = 4 * np.arange(count)[:, None]
    triangles = np.concatenate([first + [0, 1, 2], first + [0, 2, 3]], axis=1).reshape(-1, 3)
    return corners.reshape(-1, 3), triangles, np.column_stack([x0, x1, z0, z1])


@pytest.mark.parametrize("order", ["drawn", "along-x"])
def test_receivers_in_separate_patches_are_shadowed_exactly_under_scattered_squares(order, device):
    # Receivers in three patches of a 100 m field leave most of the light-space grid's cells empty,
    # and 600 small squares lie over the patches, across their borders and over the empty cells between:
    # the chunks of triangles and the triangles passed as reaching no ray (by their rectangles and
    # the cells' ray counts) must shadow exactly the points under a square. Drawn at random, a chunk's
    # squares are far apart; sorted along x, a chunk's lie together and most chunks are passed whole.
    rng = np.random.default_rng(11)
    vertices, triangles, squares = floating_squares(rng, 600, area=100.0, height=3.0)
    if order == "along-x":
        triangles = triangles[np.argsort(vertices[triangles[:, 0], 0], kind="stable")]
    ground, tg = quad([[-10.0, 0.0, -10.0], [110.0, 0.0, -10.0], [110.0, 0.0, 110.0], [-10.0, 0.0, 110.0]])
    bvh = mesh_bvh(np.concatenate([vertices, ground]), np.concatenate([triangles, tg + vertices.shape[0]]),
                   device=device)
    centres = np.array([[15.0, 20.0], [70.0, 30.0], [40.0, 85.0]])
    xz = np.concatenate([c + rng.uniform(-8.0, 8.0, (2000, 2)) for c in centres])
    d = direction_from_angles(elevation_deg=55.0, azimuth_deg=25.0)
    # Where the ray toward the light crosses the squares' height.
    at = xz + 3.0 * np.array([-d[0], -d[2]]) / -d[1]
    gap = np.stack([at[:, None, 0] - squares[:, 0], squares[:, 1] - at[:, None, 0],
                    at[:, None, 1] - squares[:, 2], squares[:, 3] - at[:, None, 1]])
    shadowed = np.any(np.all(gap > 0.0, axis=0), axis=1)
    # Points within a millimetre of a square's edge are not compared.
    robust = np.all(np.abs(gap).min(axis=0) > 1e-3, axis=1)
    points = np.column_stack([xz[:, 0], np.zeros(len(xz)), xz[:, 1]])
    assert 0.1 < shadowed[robust].mean() < 0.7
    for threads in (1, 2):
        lit = hard_shadow(bvh, points=points, normals=np.tile(UP, (len(xz), 1)), light_direction=d,
                          threads=threads)
        np.testing.assert_array_equal(lit[robust], np.where(shadowed[robust], 0.0, 1.0))


def test_the_order_of_the_triangles_does_not_change_the_shadow(device):
    # Chunks of consecutive triangles are passed whole by their joined rectangle: shuffled, every
    # chunk spans the scene, and the shadow must stay the same, bit for bit; a last chunk is partial.
    scene, points, normals = terrain_receivers()
    triangles = scene.triangles[:len(scene.triangles) // CHUNK * CHUNK - 27]
    d = direction_from_angles(elevation_deg=40.0, azimuth_deg=30.0)
    one = hard_shadow(mesh_bvh(scene.vertices, triangles, device=device), points=points, normals=normals,
                      light_direction=d)
    assert 0.05 < np.nanmean(one == 0) < 0.95
    shuffled = triangles[np.random.default_rng(5).permutation(len(triangles))]
    for threads in (1, 2):
        lit = hard_shadow(mesh_bvh(scene.vertices, shuffled, device=device), points=points, normals=normals,
                          light_direction=d, threads=threads)
        np.testing.assert_array_equal(lit, one)


@pytest.mark.parametrize("threads", [0, -1, 2.0, True, "3", None])
def test_threads_must_be_a_positive_integer(threads, device):
    s = plane_box(plane_size=40.0)
    for method in METHODS:
        with pytest.raises(ValueError, match=r"threads: expected an integer >= 1"):
            hard_shadow(mesh_bvh(s.vertices, s.triangles, device=device), points=np.zeros((4, 3)),
                        normals=np.tile(UP, (4, 1)), light_direction=[0, -1, 0], method=method, threads=threads)


@pytest.mark.cuda
@pytest.mark.skipif(wp.get_cuda_device_count() == 0, reason="no CUDA device")
def test_cpu_and_cuda_cast_the_same_irregular_shadow_bit_for_bit():
    """The float64 irregular z-buffer decides every receiver alike on both devices (no fused multiply-add on either)."""
    scene, points, normals = terrain_receivers()
    d = direction_from_angles(elevation_deg=40.0, azimuth_deg=30.0)
    cpu, cuda = (hard_shadow(mesh_bvh(scene.vertices, scene.triangles, device=device), points=points, normals=normals,
                             light_direction=d, method="irregular") for device in ("cpu", "cuda:0"))
    np.testing.assert_array_equal(cuda, cpu)
