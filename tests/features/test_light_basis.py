"""Light space's right and up (``[shadow] light_basis``): the engines' look-at, and world-locked texels in any basis."""

from __future__ import annotations

import numpy as np
import pytest

from csmlab.camera import CameraPose
from csmlab.cascades import build_cascades
from csmlab.geometry import LIGHT_BASIS_METHODS, light_basis_world_y, rotation_looking_at
from csmlab.light import direction_from_angles
from csmlab.render import lookup_shadow, prepare_scene, render_shadow, render_view
from csmlab.scene import Scene
from csmlab.settings import ShadowSettings

LIGHTS = [direction_from_angles(elevation_deg=e, azimuth_deg=a) for e, a in ((40.0, 30.0), (10.0, 200.0),
                                                                           (75.0, -120.0), (35.0, 90.0))]


def _normalized(v):
    return np.asarray(v, float) / np.linalg.norm(v)


def threejs_look_at_rows(direction):
    """three.js ``Matrix4.lookAt(eye = origin, target = direction, up = +Y)``: z = eye − target, x = up × z, y = z ×
    x."""
    z = _normalized(-np.asarray(direction, float))
    x = _normalized(np.cross([0.0, 1.0, 0.0], z))
    return x, np.cross(z, x), z


@pytest.mark.parametrize("d", LIGHTS)
def test_world_y_is_threejs_lookat_with_depth_along_the_light(d):
    x, y, z = threejs_look_at_rows(d)
    basis = light_basis_world_y(d)
    np.testing.assert_allclose(basis[0], x, atol=1e-12)
    np.testing.assert_allclose(basis[1], y, atol=1e-12)
    np.testing.assert_allclose(basis[2], -z, atol=1e-12)


@pytest.mark.parametrize("d", LIGHTS)
def test_world_y_is_strides_side_and_up(d):
    """Stride: side = Normalize(Cross(UnitY, direction)), up = Normalize(Cross(direction, side)), the view
    LookAtRH(eye, eye + direction, up) whose +X is up × (−direction) = −side."""
    side = _normalized(np.cross([0.0, 1.0, 0.0], d))
    up = _normalized(np.cross(d, side))
    basis = light_basis_world_y(d)
    np.testing.assert_allclose(basis[1], up, atol=1e-12)
    np.testing.assert_allclose(basis[0], _normalized(np.cross(up, -np.asarray(d))), atol=1e-12)


def test_world_y_takes_plus_x_as_right_for_a_light_along_y_as_threejs_nudges_it():
    """three.js's lookAt with z ∥ up nudges z.z by 1e-4: x = up × z is then +X for a light up or down."""
    for d in ([0.0, -1.0, 0.0], [0.0, 1.0, 0.0]):
        z = -np.asarray(d)
        z = _normalized(z + [0.0, 0.0, 1e-4])
        x = _normalized(np.cross([0.0, 1.0, 0.0], z))
        np.testing.assert_allclose(light_basis_world_y(d)[0], x, atol=1e-7)
        np.testing.assert_allclose(light_basis_world_y(d)[1], np.cross(z, x), atol=1e-4)


@pytest.mark.parametrize("name", sorted(LIGHT_BASIS_METHODS))
def test_every_basis_is_orthonormal_with_the_light_as_depth_axis(name):
    for d in [*LIGHTS, np.array([0.0, -1.0, 0.0]), np.array([1.0, 0.0, 0.0])]:
        basis = LIGHT_BASIS_METHODS[name](d)
        np.testing.assert_allclose(basis @ basis.T, np.eye(3), atol=1e-12)
        np.testing.assert_allclose(basis[2], _normalized(d), atol=1e-15)


def test_the_cascades_take_the_chosen_basis_and_world_y_turns_the_grid_about_the_light_only():
    d = direction_from_angles(elevation_deg=40.0, azimuth_deg=30.0)
    pose = CameraPose(position=np.array([3.0, 2.0, 5.0]), orientation=rotation_looking_at(np.array([0.2, -0.1, -1.0])),
                      aspect=16 / 9, near=0.1, far=100.0)
    corners = np.array([[x, y, z] for x in (-50, 50) for y in (-5, 20) for z in (-50, 50)], float)
    sets = {name: build_cascades(pose=pose, light_direction=d, scene_corners=corners,
                                 settings=ShadowSettings(shadow_distance=60.0, light_basis=name))
            for name in LIGHT_BASIS_METHODS}
    np.testing.assert_array_equal(sets["world_y"].basis, light_basis_world_y(d))
    # The same light axis and light depths; only the grid's axes turn (20.36° + 90° here).
    np.testing.assert_array_equal(sets["world_y"].basis[2], sets["least_aligned"].basis[2])
    angle = np.degrees(np.arccos(abs(np.dot(sets["world_y"].basis[1], sets["least_aligned"].basis[1]))))
    assert 60.0 < angle < 80.0
    for a, b in zip(sets["world_y"].cascades, sets["least_aligned"].cascades):
        assert a.depth_near == pytest.approx(b.depth_near) and a.depth_far == pytest.approx(b.depth_far)


def _scene(rng) -> Scene:
    """A 120 m ground plane and 30 scattered boxes (closed, wound outward)."""
    faces = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1], [2, 3, 7], [2, 7, 6],
                      [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    vertices = [np.array([[-60, 0, -60], [60, 0, -60], [60, 0, 60], [-60, 0, 60]], float)]
    triangles = [np.array([[0, 2, 1], [0, 3, 2]])]
    for k, (x, z) in enumerate(rng.uniform(-25.0, 25.0, (30, 2))):
        size = rng.uniform(0.3, 2.0, 3)
        lo, hi = (x, 0.0, z), (x + size[0], size[1] * 2, z + size[2])
        vertices.append(np.array([[a, b, c] for a in (lo[0], hi[0]) for b in (lo[1], hi[1]) for c in (lo[2], hi[2])]))
        triangles.append(faces + 4 + 8 * k)
    return Scene.from_triangles(np.concatenate(vertices), np.concatenate(triangles))


def _camera(eye, target) -> CameraPose:
    eye = np.asarray(eye, float)
    return CameraPose(position=eye, orientation=rotation_looking_at(np.asarray(target, float) - eye), aspect=64 / 40,
                      near=0.1, far=60.0)


def test_exact_stabilization_in_the_world_y_basis_keeps_S_bit_identical_at_fixed_points(device):
    """Snapping is in light space and the basis depends on d alone: a translating camera changes no lit
    value at a fixed world point that stays in its cascade (same-cascade flicker 0)."""
    dscene = prepare_scene(_scene(np.random.default_rng(3)), device=device)
    light = direction_from_angles(elevation_deg=35.0, azimuth_deg=120.0)
    settings = ShadowSettings(cascades=3, resolution=256, shadow_distance=50.0, light_basis="world_y",
                              filter="pcf", filter_size=3)
    before = _camera((-3.0, 6.0, 14.0), (2.0, 0.0, -4.0))
    after = _camera((-2.37, 6.11, 13.2), (2.63, 0.11, -4.8))
    previous = render_shadow(dscene, render_view(dscene, before, light, width=64, height=40), settings)
    current = render_shadow(dscene, render_view(dscene, after, light, width=64, height=40), settings)
    np.testing.assert_array_equal(current.maps.cascades.basis, light_basis_world_y(light))
    g = current.view.gbuffer
    points = g.position[g.valid]
    earlier = lookup_shadow(previous.maps, points=points, normals=g.normal[g.valid],
                            view_depth=before.view_depth(points), settings=settings, device=device)
    now = current.shadow.lit[g.valid]
    same = (earlier.cascade == current.shadow.cascade[g.valid]) & (earlier.cascade >= 0)
    assert same.sum() > 1000 and 0.05 < np.mean(now[same] < 1.0) < 0.95
    assert any(np.any(a.origin != b.origin) for a, b in zip(previous.maps.cascades.cascades,
                                                             current.maps.cascades.cascades))
    np.testing.assert_array_equal(now[same], earlier.lit[same])
