"""Procedural scenes against independent oracles: analytic volumes and bounds, brute-force ray casts,
the camera-area rules written out here from the issue (ring road 20 ± 2 m, disc 4 m, ground ±0.3 m
inside 45 m), and counts the issue asks for."""

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from csmlab.scene import SCENE_KINDS, make_scene
from csmlab.scene.city import city
from csmlab.scene.fence import fence
from csmlab.scene.plane_box import plane_box
from csmlab.scene.shapes import (Part, height_field, placed, scene_from_parts, unit_box, unit_cone, unit_icosahedron,
                                  unit_prism)
from csmlab.scene.terrain import terrain

SMALL = {
    "terrain": dict(resolution=24, trees=60, ring_trees=40),
    "city": dict(ground_divisions=8),
    "fence": dict(inner_fences=2, outer_fences=2),
}


@pytest.fixture(scope="module")
def defaults():
    """Each camera-area scene at its default size, built once."""
    return {"terrain": terrain(), "city": city(), "fence": fence()}


def _signed_volume(scene) -> float:
    """Volume enclosed by a closed mesh by the divergence theorem; positive when wound outward."""
    a, b, c = (scene.vertices[scene.triangles[:, k]] for k in range(3))
    return float(np.einsum("ij,ij->", a, np.cross(b, c)) / 6.0)


def _first_hits(scene, origins, directions):
    """Brute-force Möller–Trumbore: index of the first triangle each ray hits, −1 for none."""
    a, b, c = (scene.vertices[scene.triangles[:, k]] for k in range(3))
    e1, e2 = b - a, c - a
    hits = np.full(len(origins), -1)
    for i, (o, d) in enumerate(zip(origins, directions)):
        p = np.cross(d, e2)
        det = np.einsum("ij,ij->i", e1, p)
        ok = np.abs(det) > 1e-12
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        s = o - a
        u = np.einsum("ij,ij->i", s, p) * inv
        q = np.cross(s, e1)
        v = (q @ d) * inv
        t = np.einsum("ij,ij->i", e2, q) * inv
        t = np.where(ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 1e-9), t, np.inf)
        if np.isfinite(t.min()):
            hits[i] = int(np.argmin(t))
    return hits


def _footprint_distance_range(scene):
    """Per triangle: min and max horizontal distance from the origin over its x–z footprint."""
    p = scene.vertices[scene.triangles][:, :, [0, 2]]
    far = np.linalg.norm(p, axis=2).max(axis=1)
    near = np.full(len(p), np.inf)
    for k in range(3):
        a, b = p[:, k], p[:, (k + 1) % 3]
        ab = b - a
        t = np.clip(-np.einsum("ij,ij->i", a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-30), 0.0, 1.0)
        near = np.minimum(near, np.linalg.norm(a + t[:, None] * ab, axis=1))
    # Origin inside the footprint: all three edge cross products share a sign.
    cross = [(p[:, (k + 1) % 3, 0] - p[:, k, 0]) * -p[:, k, 1] - (p[:, (k + 1) % 3, 1] - p[:, k, 1]) * -p[:, k, 0]
             for k in range(3)]
    inside = np.all(np.stack(cross) >= 0, axis=0) | np.all(np.stack(cross) <= 0, axis=0)
    return np.where(inside, 0.0, near), far


def _casters(scene):
    """Mask of triangles rising above 0.3 m, and their footprint distance ranges."""
    near, far = _footprint_distance_range(scene)
    return scene.vertices[scene.triangles][:, :, 1].max(axis=1) > 0.3, near, far


@pytest.mark.parametrize("solid, volume", [
    (unit_box(), 8.0),
    (unit_prism(6), 6 / 2 * np.sin(2 * np.pi / 6)),
    (unit_cone(8), 8 / 2 * np.sin(2 * np.pi / 8) / 3),
    # Regular icosahedron of circumradius 1: edge 4 / sqrt(10 + 2 sqrt 5), volume 5 (3 + sqrt 5) edge³ / 12.
    (unit_icosahedron(), 5 * (3 + np.sqrt(5)) / 12 * (4 / np.sqrt(10 + 2 * np.sqrt(5))) ** 3),
])
def test_placed_solids_are_closed_wound_outward_and_keep_their_volume(solid, volume):
    rng = np.random.default_rng(3)
    scale = rng.uniform(0.5, 3.0, (5, 3))
    part = placed(solid, scale=scale, offset=rng.uniform(-50, 50, (5, 3)), yaw=rng.uniform(0, 7, 5), albedo=(1, 1, 1))
    edges = np.concatenate([solid.triangles[:, [0, 1]], solid.triangles[:, [1, 2]], solid.triangles[:, [2, 0]]])
    directed = set(map(tuple, edges))
    assert len(directed) == len(edges) and all((b, a) in directed for a, b in directed)
    nt = solid.triangles.shape[0]
    for k in range(5):
        one = scene_from_parts([Part(part.vertices, part.triangles[k * nt:(k + 1) * nt], part.albedo[:nt])],
                               name="solid")
        assert _signed_volume(one) == pytest.approx(volume * np.prod(scale[k]), rel=1e-9)


def test_height_field_faces_up_with_two_triangles_per_cell():
    rng = np.random.default_rng(5)
    x, z = np.sort(rng.uniform(-10, 10, 7)), np.sort(rng.uniform(-10, 10, 5))
    scene = scene_from_parts([height_field(x, z, rng.uniform(-0.2, 0.2, (5, 7)), albedo=(0.5, 0.5, 0.5))], name="hf")
    assert scene.triangle_count == 2 * 6 * 4
    assert np.all(scene.normals[:, 1] > 0)


def test_plane_box_defaults_match_the_documented_geometry():
    scene = plane_box()
    assert scene.triangle_count == 2 + 12
    np.testing.assert_array_equal(scene.bounds, [[-100, 0, -100], [100, 2, 100]])
    np.testing.assert_array_equal(scene.normals[:2], [[0, 1, 0], [0, 1, 0]])
    box = scene.vertices[np.unique(scene.triangles[2:])]
    expected = {(x, y, z) for x in (-1.0, 1.0) for y in (0.0, 2.0) for z in (-1.0, 1.0)}
    assert set(map(tuple, box)) == expected


def test_plane_box_parameters_move_and_size_the_box_exactly():
    scene = plane_box(plane_size=50.0, plane_divisions=3, box_size=4.0, box_height=1.5, box_center=(5.0, -7.0))
    assert scene.triangle_count == 2 * 9 + 12
    plane = scene.vertices[np.unique(scene.triangles[:18])]
    np.testing.assert_array_equal(np.unique(plane[:, 0]), [-25, -25 + 50 / 3, -25 + 100 / 3, 25])
    assert np.all(plane[:, 1] == 0)
    box_tris = scene.triangles[18:]
    box = scene.vertices[np.unique(box_tris)]
    assert set(map(tuple, box)) == {(x, y, z) for x in (3.0, 7.0) for y in (0.0, 1.5) for z in (-9.0, -5.0)}
    normals = scene.normals[18:]
    centroid = scene.vertices[box_tris].mean(axis=1) - np.array([5.0, 0.75, -7.0])
    assert np.all(np.abs(normals).max(axis=1) == 1.0) and np.all(np.einsum("ij,ij->i", normals, centroid) > 0)


@pytest.mark.parametrize("kind", ["terrain", "city", "fence"])
def test_same_seed_gives_identical_arrays_and_another_seed_differs(kind):
    a = make_scene(kind, seed=7, **SMALL[kind])
    b = make_scene(kind, seed=7, **SMALL[kind])
    c = make_scene(kind, seed=8, **SMALL[kind])
    for name in ("vertices", "triangles", "normals", "albedo"):
        assert np.array_equal(getattr(a, name), getattr(b, name))
    assert a.vertices.shape != c.vertices.shape or not np.array_equal(a.vertices, c.vertices)


def test_terrain_default_has_at_least_200k_triangles(defaults):
    assert defaults["terrain"].triangle_count >= 200_000


def test_terrain_ground_does_not_depend_on_the_trees(defaults):
    bare = terrain(trees=0, ring_trees=0)
    n = bare.triangle_count
    np.testing.assert_array_equal(defaults["terrain"].triangles[:n], bare.triangles)
    np.testing.assert_array_equal(defaults["terrain"].vertices[:bare.vertices.shape[0]], bare.vertices)


@pytest.mark.parametrize("kind", ["terrain", "city", "fence"])
def test_normals_are_unit_and_face_whoever_looks_at_them(kind):
    scene = make_scene(kind, seed=2, **SMALL[kind])
    np.testing.assert_allclose(np.linalg.norm(scene.normals, axis=1), 1.0, atol=1e-12)
    rng = np.random.default_rng(11)
    # From above: the topmost surface faces up (ground, roofs, crowns).
    xz = rng.uniform(-40, 40, (60, 2))
    above = np.column_stack([xz[:, 0], np.full(60, 500.0), xz[:, 1]])
    down = _first_hits(scene, above, np.tile([0.0, -1.0, 0.0], (60, 1)))
    assert np.all(down >= 0) and np.all(scene.normals[down, 1] > 0)
    # From the camera's ring at eye height, looking around: every surface hit faces the ray.
    angle = rng.uniform(0, 2 * np.pi, 60)
    heading = rng.uniform(0, 2 * np.pi, 60)
    origins = np.column_stack([20 * np.cos(angle), np.full(60, 1.7), 20 * np.sin(angle)])
    directions = np.column_stack([np.cos(heading), np.full(60, -0.05), np.sin(heading)])
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    hits = _first_hits(scene, origins, directions)
    hit = hits >= 0
    assert hit.sum() > 30
    assert np.all(np.einsum("ij,ij->i", scene.normals[hits[hit]], directions[hit]) < 0)


@pytest.mark.parametrize("kind", ["terrain", "city", "fence"])
def test_no_caster_rises_over_the_ring_road_or_the_central_disc(defaults, kind):
    caster, near, far = _casters(defaults[kind])
    touches_ring = (near <= 22.0) & (far >= 18.0)
    touches_disc = near < 4.0
    assert not np.any(caster & (touches_ring | touches_disc))


@pytest.mark.parametrize("kind", ["terrain", "city", "fence"])
def test_plenty_of_casters_stand_2_to_15_m_from_the_ring_on_both_sides(defaults, kind):
    caster, near, far = _casters(defaults[kind])
    inside = caster & (near >= 5.0) & (far <= 18.0)
    outside = caster & (near >= 22.0) & (far <= 35.0)
    assert inside.sum() >= 100 and outside.sum() >= 100


def test_plane_box_keeps_the_ring_road_clear():
    caster, near, far = _casters(plane_box())
    assert not np.any(caster & (near <= 22.0) & (far >= 18.0))


def test_terrain_ground_stays_within_30_cm_of_zero_inside_45_m():
    ground = terrain(trees=0, ring_trees=0)
    near, _ = _footprint_distance_range(ground)
    # A planar triangle lies between its vertices' heights.
    assert np.all(np.abs(ground.vertices[ground.triangles[near < 45.0]][:, :, 1]) <= 0.3)


@pytest.mark.parametrize("kind", ["city", "fence"])
def test_flat_ground_is_the_lowest_surface_inside_45_m(kind):
    scene = make_scene(kind, seed=4)
    rng = np.random.default_rng(13)
    r, angle = 45.0 * np.sqrt(rng.random(50)), rng.uniform(0, 2 * np.pi, 50)
    origins = np.column_stack([r * np.cos(angle), np.full(50, -50.0), r * np.sin(angle)])
    # Looking up from below, the first surface is the ground's underside (nothing lies lower).
    hits = _first_hits(scene, origins, np.tile([0.0, 1.0, 0.0], (50, 1)))
    assert np.all(hits >= 0)
    assert np.all(np.abs(scene.vertices[scene.triangles[hits]][:, :, 1]) <= 0.3)


def test_fence_has_many_slats_narrower_than_3_cm_and_at_least_1_m_tall():
    scene = fence(inner_fences=1, outer_fences=1, poles=0)
    t = scene.triangles
    n = scene.vertices.shape[0]
    rows = np.concatenate([t[:, 0], t[:, 1], t[:, 2]])
    cols = np.concatenate([t[:, 1], t[:, 2], t[:, 0]])
    count, label = connected_components(coo_matrix((np.ones(rows.size), (rows, cols)), shape=(n, n)), directed=False)
    low, high = np.full(count, np.inf), np.full(count, -np.inf)
    np.minimum.at(low, label, scene.vertices[:, 1])
    np.maximum.at(high, label, scene.vertices[:, 1])
    # Footprint diameter (largest horizontal distance between two vertices) bounds the width from above.
    diameter = [np.linalg.norm(xz[:, None] - xz[None], axis=2).max()
                for xz in (scene.vertices[label == k][:, [0, 2]] for k in np.flatnonzero(high - low >= 1.0))]
    assert sum(d < 0.03 for d in diameter) >= 200


def test_make_scene_rejects_unknown_names_listing_the_valid_ones():
    with pytest.raises(ValueError, match=r"scene: expected one of \['city', 'fence', 'foliage', 'mesh', 'plane_box', "
                                         r"'terrain'\], got 'forest'"):
        make_scene("forest")
    with pytest.raises(ValueError, match="unknown parameter.*resolutio.*expected some of.*resolution"):
        make_scene("terrain", resolutio=10)
    with pytest.raises(ValueError, match="expected parameter.*file"):
        make_scene("mesh")
    assert set(SCENE_KINDS) == {"plane_box", "terrain", "city", "fence", "foliage", "mesh"}


@pytest.mark.parametrize("kind, params, field", [
    ("terrain", dict(resolution=0), "resolution"),
    ("terrain", dict(size=-1.0), "size"),
    ("city", dict(streets=2.5), "streets"),
    ("fence", dict(slat_width=float("nan")), "slat_width"),
    ("fence", dict(size=50.0), "size"),
    ("plane_box", dict(box_center=(1.0, 2.0, 3.0)), "box_center"),
    ("terrain", dict(size=10.0, trees=5, ring_trees=0), "trees"),
])
def test_bad_generator_values_name_the_keyword(kind, params, field):
    with pytest.raises(ValueError, match=f"^{field}: expected"):
        make_scene(kind, **params)
