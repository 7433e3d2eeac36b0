"""One frame end to end: shadow against the ray-traced reference, PCF across an edge, exact zero flicker."""

import numpy as np
import pytest
import warp as wp
from scipy.spatial import ConvexHull

from csmlab.camera import CameraPose
from csmlab.geometry import rotation_looking_at
from csmlab.light import direction_from_angles
from csmlab.render import LIGHT_SPACE_MESHES, lookup_shadow, prepare_scene, render_frame, render_shadow, render_view
from csmlab.scene import Scene
from csmlab.settings import ShadowSettings
from csmlab.texels import texel_coordinates

BOX_FACES = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1], [2, 3, 7], [2, 7, 6],
                      [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])


def box_corners(lo, hi) -> np.ndarray:
    return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])], float)


def scene_of(boxes, *, plane_half=40.0, quads=()) -> Scene:
    """A ground plane (y = 0), closed boxes ``(lo, hi)`` and horizontal quads ``(x0, x1, y, z0, z1)``."""
    h = plane_half
    vertices = [np.array([[-h, 0, -h], [h, 0, -h], [h, 0, h], [-h, 0, h]], float)]
    triangles = [np.array([[0, 2, 1], [0, 3, 2]])]
    count = 4
    for x0, x1, y, z0, z1 in quads:
        vertices.append(np.array([[x0, y, z0], [x1, y, z0], [x1, y, z1], [x0, y, z1]], float))
        triangles.append(np.array([[0, 2, 1], [0, 3, 2]]) + count)
        count += 4
    for lo, hi in boxes:
        vertices.append(box_corners(lo, hi))
        triangles.append(BOX_FACES + count)
        count += 8
    return Scene.from_triangles(np.concatenate(vertices), np.concatenate(triangles))


# A box on the ground, a box floating above it (its shadow is seen beside it even under a light
# straight down) and, behind the camera, a pole that keeps every visible surface away from zref.
BOXES = [((-1.0, 0.0, -1.0), (1.0, 2.0, 1.0)), ((1.0, 1.6, -4.5), (4.5, 2.0, -1.0)),
         ((18.0, 0.0, 18.0), (18.5, 10.0, 18.5))]


def camera(width, height, eye=(6.0, 1.9, 3.5), target=(2.0, 0.4, -2.0)) -> CameraPose:
    eye = np.asarray(eye, float)
    return CameraPose(position=eye, orientation=rotation_looking_at(np.asarray(target) - eye), aspect=width / height,
                      near=0.1, far=60.0)


def silhouette_distance(cascades, points, boxes) -> np.ndarray:
    """Light-space distance in metres from each point to the nearest box silhouette's outline.

    A box's shadow boundary, seen from the light, is the outline of the convex hull of its eight
    corners projected along the light; for points outside a hull the distance to its supporting
    lines is a lower bound, which only widens the band of points left out.
    """
    xy = points @ cascades.basis[:2].T
    out = np.full(points.shape[0], np.inf)
    for lo, hi in boxes:
        hull = ConvexHull(box_corners(lo, hi) @ cascades.basis[:2].T)
        signed = (xy @ hull.equations[:, :2].T + hull.equations[:, 2]).max(axis=1)
        out = np.minimum(out, np.abs(signed))
    return out


def compare_with_reference(frame, boxes, *, footprints):
    """Pixels more than ``footprints`` texel diagonals from every shadow boundary, and their S and R."""
    g = frame.view.gbuffer
    cascade = frame.shadow.cascade
    keep = g.valid & (cascade >= 0)
    texel = np.array([c.texel_size.max() for c in frame.maps.cascades.cascades])
    points = g.position[keep]
    far = silhouette_distance(frame.maps.cascades, points, boxes) > footprints * np.sqrt(2) * texel[cascade[keep]]
    return frame.shadow.lit[keep][far], frame.view.reference[keep][far]


def test_filter_none_without_bias_equals_the_reference_away_from_the_shadow_boundary(device):
    # Under a light straight down every horizontal receiver has the depth of its texel centre, so
    # zero bias is exact there; walls lie on the boundary and are left out with it.
    settings = ShadowSettings(cascades=2, resolution=256, shadow_distance=40.0, filter="none", bias_constant=0.0,
                              bias_slope=0.0, normal_offset=0.0)
    frame = render_frame(scene_of(BOXES), camera(96, 64), [0.0, -1.0, 0.0], settings, width=96, height=64,
                         device=device)
    lit, reference = compare_with_reference(frame, BOXES, footprints=1.0)
    assert lit.size > 3000 and np.sum(reference == 0) > 100
    np.testing.assert_array_equal(lit, reference)


def test_default_bias_equals_the_reference_away_from_the_shadow_boundary_under_an_oblique_light(device):
    settings = ShadowSettings(cascades=3, resolution=512, shadow_distance=40.0, filter="none")
    light = direction_from_angles(elevation_deg=40.0, azimuth_deg=-150.0)
    frame = render_frame(scene_of(BOXES), camera(96, 64), light, settings, width=96, height=64, device=device)
    lit, reference = compare_with_reference(frame, BOXES, footprints=2.0)
    assert lit.size > 3000 and np.sum(reference == 0) > 1000
    np.testing.assert_array_equal(lit, reference)


@pytest.mark.parametrize("filter,size", [("pcf", 3), ("pcf", 5), ("pcf_bilinear", 1)])
def test_filtered_shadow_is_monotone_across_a_straight_shadow_edge(filter, size, device):
    # A roof at y = 3 over x < 0 casts a half-plane shadow with one straight edge on the ground.
    scene = scene_of([], quads=[(-40.0, 0.0, 3.0, -40.0, 40.0)])
    light = direction_from_angles(elevation_deg=50.0, azimuth_deg=30.0)
    # PCF reads texels up to r away, whose stored ground depth differs by up to (r + 0.71)·texel·tan θ:
    # the slope bias must cover that or the lit side shows acne.
    radius = size // 2 if filter == "pcf" else 1
    settings = ShadowSettings(cascades=1, resolution=256, shadow_distance=20.0, filter=filter, filter_size=size,
                              bias_slope=radius + 1.0)
    pose = camera(32, 32, eye=(4.0, 2.0, 10.0), target=(2.0, 0.0, 0.0))
    frame = render_frame(scene, pose, light, settings, width=32, height=32, device=device)
    cascades = frame.maps.cascades
    right, up, d = cascades.basis
    # The edge seen from the light runs along the world z axis; step across it along its normal
    # in light space, toward the lit side (+x).
    along = np.array([right[2], up[2]])
    normal = np.array([-along[1], along[0]]) / np.linalg.norm(along)
    normal *= np.sign(normal @ [right[0], up[0]])
    edge = np.array([3.0 * d[0] / -d[1], 0.0, 0.0])
    texel = cascades.cascades[0].texel_size[0]
    s = np.linspace(-8.0, 8.0, 801) * texel
    xy = (edge @ cascades.basis[:2].T) + s[:, None] * normal
    # Back from light space to the ground: X = x·right + y·up + t·d with X_y = 0.
    t = -(xy[:, 0] * right[1] + xy[:, 1] * up[1]) / d[1]
    points = xy[:, :1] * right + xy[:, 1:] * up + t[:, None] * d
    assert np.allclose(points[:, 1], 0.0, atol=1e-9)
    normals = np.tile(np.float32([0.0, 1.0, 0.0]), (points.shape[0], 1))
    result = lookup_shadow(frame.maps, points=points, normals=normals, view_depth=pose.view_depth(points),
                           settings=settings, device=device)
    assert np.all(result.cascade == 0)
    lit = result.lit
    assert lit[0] == 0.0 and lit[-1] == 1.0
    assert np.all((lit >= 0.0) & (lit <= 1.0))
    assert np.all(np.diff(lit) >= 0.0)
    assert np.unique(lit).size >= (4 if filter == "pcf" else 20)


def scattered_boxes(seed: int):
    rng = np.random.default_rng(seed)
    boxes = []
    for x, z in rng.uniform(-25.0, 25.0, (40, 2)):
        size = rng.uniform(0.3, 2.0, 3)
        lift = rng.uniform(0.0, 2.0) * (rng.uniform() < 0.3)
        boxes.append(((x, lift, z), (x + size[0], lift + size[1] * 2, z + size[2])))
    return boxes


@pytest.mark.parametrize("stabilization", ["exact", "none"])
def test_exact_stabilization_keeps_S_bit_identical_at_fixed_points_when_the_camera_moves(stabilization, device):
    dscene = prepare_scene(scene_of(scattered_boxes(3), plane_half=60.0), device=device)
    light = direction_from_angles(elevation_deg=35.0, azimuth_deg=120.0)
    settings = ShadowSettings(cascades=3, resolution=256, shadow_distance=50.0, stabilization=stabilization,
                              filter="pcf", filter_size=3)
    before = camera(64, 40, eye=(-3.0, 6.0, 14.0), target=(2.0, 0.0, -4.0))
    after = camera(64, 40, eye=(-2.37, 6.11, 13.2), target=(2.6, 0.0, -4.5))
    previous = render_shadow(dscene, render_view(dscene, before, light, width=64, height=40), settings)
    current = render_shadow(dscene, render_view(dscene, after, light, width=64, height=40), settings)
    g = current.view.gbuffer
    points = g.position[g.valid]
    earlier = lookup_shadow(previous.maps, points=points, normals=g.normal[g.valid],
                            view_depth=before.view_depth(points), settings=settings, device=device)
    now = current.shadow.lit[g.valid]
    same = (earlier.cascade == current.shadow.cascade[g.valid]) & (earlier.cascade >= 0)
    assert same.sum() > 1000 and 0.05 < np.mean(now[same] < 1.0) < 0.95
    pairs = zip(previous.maps.cascades.cascades, current.maps.cascades.cascades)
    assert any(np.any(a.origin != b.origin) for a, b in pairs)
    if stabilization == "exact":
        assert np.array_equal(now[same], earlier.lit[same])
    else:
        assert np.sum(now[same] != earlier.lit[same]) > 0


def test_the_gbuffer_albedo_is_the_hit_triangles_and_positive_zero_on_a_miss():
    scene = scene_of(BOXES)
    light = direction_from_angles(elevation_deg=40.0, azimuth_deg=30.0)
    view = render_view(prepare_scene(scene), camera(48, 32), light, width=48, height=32, reference=False)
    g = view.gbuffer
    assert g.albedo.dtype == np.float32 and g.albedo.shape == (32, 48, 3)
    assert 0 < np.count_nonzero(g.valid) < g.valid.size
    np.testing.assert_array_equal(g.albedo[g.valid], np.asarray(scene.albedo, dtype=np.float32)[g.triangle[g.valid]])
    assert np.all(g.albedo[~g.valid] == 0.0) and not np.any(np.signbit(g.albedo[~g.valid]))


def test_the_view_is_shared_across_methods_and_every_stage_is_timed_and_repeatable():
    dscene = prepare_scene(scene_of(BOXES))
    pose = camera(48, 32)
    light = direction_from_angles(elevation_deg=40.0, azimuth_deg=30.0)
    view = render_view(dscene, pose, light, width=48, height=32, index=7)
    a = render_shadow(dscene, view, ShadowSettings(resolution=128, stabilization="exact"))
    b = render_shadow(dscene, view, ShadowSettings(resolution=128, stabilization="quantized", selection="map"))
    assert a.view is view and b.view is view and view.index == 7
    assert set(view.timings) == {"visibility", "reference"}
    assert set(a.timings) == {"cascades", "raster", "shadow"}
    assert a.maps.depth.shape == (4, 128, 128) and a.maps.texels_rasterized > 0
    assert a.shadow.lit.shape == (32, 48) and a.shadow.cascade.dtype == np.int8
    g = view.gbuffer
    np.testing.assert_array_equal(g.albedo[~g.valid], 0.0)
    assert np.all(np.isnan(a.shadow.lit[~g.valid])) and np.all(a.shadow.cascade[~g.valid] == -1)
    again = render_frame(dscene, pose, light, ShadowSettings(resolution=128, stabilization="exact"), width=48,
                         height=32)
    for x, y in ((again.maps.depth, a.maps.depth), (again.shadow.lit, a.shadow.lit),
                 (again.view.gbuffer.position, g.position), (again.view.reference, view.reference),
                 (again.view.gbuffer.normal, g.normal)):
        assert np.array_equal(x, y, equal_nan=True)


def test_methods_of_other_lights_keep_their_light_space_meshes_and_the_same_maps():
    # Two lights in turn, as methods with their own light bases are rendered in turn by one worker: each
    # keeps its mesh (the same object again), and the maps equal those of a scene that never saw the other.
    dscene = prepare_scene(scene_of(BOXES))
    pose = camera(32, 24)
    lights = [direction_from_angles(elevation_deg=40.0 + k, azimuth_deg=30.0) for k in range(LIGHT_SPACE_MESHES + 2)]
    settings = ShadowSettings(cascades=2, resolution=64, stabilization="exact")
    first = render_frame(dscene, pose, lights[0], settings, width=32, height=24)
    kept = dict(dscene.light_space)
    second = render_frame(dscene, pose, lights[1], settings, width=32, height=24)
    again = render_frame(dscene, pose, lights[0], settings, width=32, height=24)
    assert len(dscene.light_space) == 2 and all(dscene.light_space[k] is m for k, m in kept.items())
    assert np.array_equal(again.maps.depth, first.maps.depth)
    alone = render_frame(prepare_scene(scene_of(BOXES)), pose, lights[1], settings, width=32, height=24)
    assert np.array_equal(second.maps.depth, alone.maps.depth)
    # More lights than are kept: the least recently used (lights[1], then lights[0]) go first.
    for light in lights[2:]:
        render_frame(dscene, pose, light, settings, width=32, height=24)
    assert len(dscene.light_space) == LIGHT_SPACE_MESHES == len(dscene.ordered_vertices)
    assert not set(kept) & set(dscene.light_space)


def test_light_space_meshes_over_the_byte_bound_are_dropped_oldest_first_the_newest_always_kept(monkeypatch):
    from csmlab import render

    dscene = prepare_scene(scene_of(BOXES))
    pose = camera(32, 24)
    settings = ShadowSettings(cascades=2, resolution=64, stabilization="exact")
    lights = [direction_from_angles(elevation_deg=40.0 + k, azimuth_deg=30.0) for k in range(3)]
    first = render_frame(dscene, pose, lights[0], settings, width=32, height=24)
    (key, mesh), = dscene.light_space.items()
    one = render._light_space_bytes(mesh, dscene.ordered_vertices[key])
    monkeypatch.setattr(render, "LIGHT_SPACE_BYTES", 2 * one)
    render_frame(dscene, pose, lights[1], settings, width=32, height=24)
    assert len(dscene.light_space) == 2
    render_frame(dscene, pose, lights[2], settings, width=32, height=24)
    assert len(dscene.light_space) == 2 == len(dscene.ordered_vertices) and key not in dscene.light_space
    monkeypatch.setattr(render, "LIGHT_SPACE_BYTES", 0)
    again = render_frame(dscene, pose, lights[0], settings, width=32, height=24)
    assert list(dscene.light_space) == list(dscene.ordered_vertices) == [key]
    assert np.array_equal(again.maps.depth, first.maps.depth)


def test_texel_coordinates_locate_each_pixel_in_the_texel_it_looked_up():
    settings = ShadowSettings(cascades=2, resolution=128, filter="none", normal_offset=0.0)
    frame = render_frame(scene_of(BOXES), camera(48, 32), [0.0, -1.0, 0.0], settings, width=48, height=32)
    g = frame.view.gbuffer
    for c in range(2):
        chosen = frame.shadow.cascade == c
        tc = texel_coordinates(frame.maps.cascades, c, g.position[chosen])
        assert np.all((tc >= 0) & (tc < 128))


@pytest.mark.cuda
@pytest.mark.skipif(wp.get_cuda_device_count() == 0, reason="no CUDA device")
def test_cpu_and_cuda_give_the_same_depth_maps_and_shadow():
    scene = scene_of(scattered_boxes(5), plane_half=60.0)
    light = direction_from_angles(elevation_deg=35.0, azimuth_deg=120.0)
    settings = ShadowSettings(cascades=3, resolution=256, shadow_distance=50.0, filter="pcf_bilinear")
    pose = camera(64, 40, eye=(-3.0, 6.0, 14.0), target=(2.0, 0.0, -4.0))
    cpu = render_frame(scene, pose, light, settings, width=64, height=40, device="cpu")
    cuda = render_frame(scene, pose, light, settings, width=64, height=40, device="cuda")
    finite = np.isfinite(cpu.maps.depth)
    np.testing.assert_array_equal(finite, np.isfinite(cuda.maps.depth))
    np.testing.assert_allclose(cuda.maps.depth[finite], cpu.maps.depth[finite], rtol=1e-6)
    g = cpu.view.gbuffer
    on_cuda = lookup_shadow(cuda.maps, points=g.position, normals=g.normal, view_depth=g.view_depth, settings=settings,
                            device="cuda")
    np.testing.assert_array_equal(on_cuda.cascade, cpu.shadow.cascade)
    differ = ~np.isclose(on_cuda.lit, cpu.shadow.lit, rtol=0, atol=1e-6, equal_nan=True)
    assert differ.mean() < 1e-3
