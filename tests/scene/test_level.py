"""Paths that fit the level: the ground found by ray casts, and every generator placed on it.

Oracles: analytic planes (the ground of ``y = a + b·x`` is known everywhere), hand-built stacks of
surfaces whose lowest upward-facing one is known, and the generators' own output without a level
(a fitted path is that path moved to the level's centre and lifted onto the ground, so its
horizontal motion and orientations must be the same).
"""

from __future__ import annotations

import numpy as np
import pytest

from csmlab.kernels.rays import ray_hits
from csmlab.paths.generators import LEVEL_RING_SHARE, PATH_GENERATORS, make_path
from csmlab.scene.core import Scene
from csmlab.scene.gltf_writer import box
from csmlab.scene.level import BACK, FRONT, MISS, Level

SLOPE, BASE = 0.1, 5.0
CENTRE = np.array([100.0, 0.0, -50.0])
HALF = np.array([30.0, 20.0])


def _quad(y_of, *, centre=CENTRE, half=HALF, up=True) -> tuple[np.ndarray, np.ndarray]:
    x = centre[0] + np.array([-1.0, 1.0, 1.0, -1.0]) * half[0]
    z = centre[2] + np.array([-1.0, -1.0, 1.0, 1.0]) * half[1]
    vertices = np.stack([x, y_of(x), z], axis=1)
    return vertices, (np.array([[0, 2, 1], [0, 3, 2]]) if up else np.array([[0, 1, 2], [0, 2, 3]]))


def _slope(x):
    return BASE + SLOPE * (x - CENTRE[0])


def _sloped_level() -> Level:
    return Level.of(Scene.from_triangles(*_quad(_slope)))


def test_ray_hits_are_the_analytic_distances_to_a_plane_and_miss_beside_it():
    level = _sloped_level()
    origins = np.array([[100.0, 20.0, -50.0], [110.0, 20.0, -45.0], [200.0, 20.0, -50.0]])
    down = np.tile([0.0, -1.0, 0.0], (3, 1))
    hits = ray_hits(level.bvh, origins, down * 3.0, max_distance=100.0)
    np.testing.assert_allclose(hits.distance[:2], 20.0 - _slope(origins[:2, 0]), rtol=1e-6)
    assert hits.triangle[2] == -1 and np.isinf(hits.distance[2])


def test_ground_heights_follow_a_sloped_plane_and_are_nan_off_it():
    level = _sloped_level()
    x = np.array([75.0, 100.0, 125.0, 140.0])
    z = np.array([-60.0, -50.0, -35.0, -50.0])
    ground = level.ground_heights(x, z)
    np.testing.assert_allclose(ground[:3], _slope(x[:3]), atol=1e-4)
    assert np.isnan(ground[3])


def test_the_ground_is_the_lowest_upward_facing_surface_not_a_roof_and_not_a_slab_underside():
    terrain = Scene.from_triangles(*_quad(lambda x: np.zeros_like(x)))
    roof = Scene.from_triangles(*_quad(lambda x: np.full_like(x, 6.0), half=np.array([5.0, 5.0])))
    # A closed slab under y = 0 … −2: its bottom faces down (passed through), its top faces up.
    corners, triangles = box((8.0, 2.0, 8.0))
    slab = Scene.from_triangles(corners + [90.0, -2.0, -50.0], triangles)
    level = Level.of(terrain.merged(roof).merged(slab))
    ground = level.ground_heights([100.0, 90.0], [-50.0, -50.0])
    np.testing.assert_allclose(ground, [0.0, 0.0], atol=1e-4)


def test_probe_hits_tell_the_front_from_the_back_of_a_surface():
    level = _sloped_level()
    origins = np.array([[100.0, 10.0, -50.0], [100.0, 0.0, -50.0], [100.0, 10.0, -50.0]])
    directions = np.array([[0.0, -1.0, 0.0], [0.0, 1.0, 0.0], [0.0, 1.0, 0.0]])
    assert level.first_hits(origins, directions).facing.tolist() == [FRONT, BACK, MISS]


def test_masked_triangles_are_left_out_of_the_probes():
    from csmlab.scene.core import AlphaMask

    ground = Scene.from_triangles(*_quad(lambda x: np.zeros_like(x)))
    card_v, card_t = _quad(lambda x: np.full_like(x, 3.0), half=np.array([4.0, 4.0]))
    card = Scene(card_v, card_t, np.tile([0.0, 1.0, 0.0], (2, 1)), np.full((2, 3), 0.5, np.float32),
                 uv=np.zeros((4, 2)), vertex_mask=np.zeros(4, np.int32), alpha=(AlphaMask(np.ones((2, 2))),))
    level = Level.of(ground.merged(card))
    hits = level.first_hits([[100.0, 10.0, -50.0]], [[0.0, -1.0, 0.0]])
    np.testing.assert_allclose(hits.distance, [10.0], atol=1e-4)


@pytest.mark.parametrize("name", ["walk", "dolly", "pan", "jitter", "dueling", "zoom"])
def test_fitted_ground_level_paths_are_the_plain_ones_moved_to_the_centre_and_lifted_onto_the_ground(name):
    level = _sloped_level()
    radius = LEVEL_RING_SHARE * HALF.min()
    scaled = {"walk": {"radius": radius}, "dueling": {"radius": radius}, "jitter": {"position": (radius, 1.7, 0.0)},
              "dolly": {"start": (0.95 * radius, 1.7, 0.3 * radius)},
              "zoom": {"start": (0.95 * radius, 1.7, 0.3 * radius)}, "pan": {}}[name]
    light = (0.3, -1.0, 0.2)
    fitted = make_path(name, frames=40, level=level, light_direction=light)
    plain = make_path(name, frames=40, light_direction=light, **scaled)
    np.testing.assert_allclose(fitted.positions[:, [0, 2]], plain.positions[:, [0, 2]] + CENTRE[[0, 2]], atol=1e-9)
    np.testing.assert_allclose(fitted.positions[:, 1] - _slope(fitted.positions[:, 0]), plain.positions[:, 1],
                               atol=1e-4)
    np.testing.assert_array_equal(fitted.orientations, plain.orientations)


def test_fitted_orbit_circles_the_centre_at_orbit_height_above_the_highest_ground_under_its_circle():
    level = _sloped_level()
    path = make_path("orbit", frames=50, level=level, orbit_height=4.0, angular_speed_deg=90.0)
    radius = LEVEL_RING_SHARE * HALF.min()
    np.testing.assert_allclose(np.hypot(path.positions[:, 0] - CENTRE[0], path.positions[:, 2] - CENTRE[2]), radius,
                               atol=1e-9)
    np.testing.assert_allclose(path.positions[:, 1], _slope(CENTRE[0] + radius) + 4.0, atol=1e-4)
    # It looks at the centre on the ground.
    target = np.array([CENTRE[0], _slope(CENTRE[0]), CENTRE[2]])
    toward = (target - path.positions) / np.linalg.norm(target - path.positions, axis=1, keepdims=True)
    np.testing.assert_allclose([p.forward for p in path.poses()], toward, atol=1e-6)


def test_fitted_flyover_crosses_the_longer_axis_over_the_run_above_the_highest_ground():
    level = _sloped_level()
    path = make_path("flyover", frames=31, fps=10.0, level=level, flight_height=12.0)
    np.testing.assert_allclose(path.positions[[0, -1], 0], CENTRE[0] + np.array([-HALF[0], HALF[0]]), atol=1e-9)
    np.testing.assert_allclose(path.positions[:, 2], CENTRE[2], atol=1e-9)
    np.testing.assert_allclose(path.positions[:, 1], _slope(CENTRE[0] + HALF[0]) + 12.0, atol=1e-4)


def test_without_a_level_orbit_height_is_the_world_height_and_flight_height_the_start_height():
    orbit = make_path("orbit", frames=3, orbit_height=7.5)
    np.testing.assert_array_equal(orbit.positions[:, 1], 7.5)
    flyover = make_path("flyover", frames=3, flight_height=12.0)
    np.testing.assert_array_equal(flyover.positions[:, 1], 12.0)
    np.testing.assert_array_equal(flyover.positions[0], [-50.0, 12.0, 0.0])


@pytest.mark.parametrize("name", sorted(PATH_GENERATORS))
def test_without_a_level_every_generator_gives_what_it_gave_before(name):
    light = (0.3, -1.0, 0.2)
    direct = PATH_GENERATORS[name](frames=20, **({"light_direction": light} if name == "dueling" else {}))
    made = make_path(name, frames=20, light_direction=light)
    np.testing.assert_array_equal(made.positions, direct.positions)
    np.testing.assert_array_equal(made.orientations, direct.orientations)


def test_a_height_field_for_another_generator_is_refused_naming_it():
    with pytest.raises(ValueError, match="orbit_height: expected only with path = 'orbit'"):
        make_path("walk", frames=3, orbit_height=2.0)
    with pytest.raises(ValueError, match="unknown parameter"):
        make_path("walk", frames=3, level=_sloped_level(), height_above=2.0)


def _experiment(tmp_path, camera: str):
    path = tmp_path / "x.toml"
    path.write_text(f'[scene]\nkind = "plane_box"\n[camera]\n{camera}\nframes = 3\nwidth = 32\nheight = 18\n'
                    '[[methods]]\nname = "exact"\n')
    return path


def test_orbit_height_is_a_camera_field_the_image_height_keeps_its_name(tmp_path):
    from csmlab.config import load_experiment
    from csmlab.experiment import build_workload

    workload = build_workload(load_experiment(_experiment(tmp_path, 'path = "orbit"\norbit_height = 7.5')))
    np.testing.assert_array_equal(workload.path.positions[:, 1], 7.5)
    assert workload.height == 18


@pytest.mark.parametrize("camera, field", [
    ('path = "walk"\norbit_height = 2.0', "camera.orbit_height"),
    ('path = "orbit"\nflight_height = 2.0', "camera.flight_height"),
    ('file = "run.txt"\nformat = "tum"\nfit_level = true', "camera.fit_level"),
    ('path = "walk"\nview_check = "loud"', "camera.view_check")])
def test_the_level_fields_are_refused_where_they_do_not_apply(tmp_path, camera, field):
    from csmlab.config import load_experiment
    from csmlab.errors import InputError

    (tmp_path / "run.txt").write_text("0 0 1.7 0 0 0 0 1\n1 0 1.7 -1 0 0 0 1\n")
    with pytest.raises(InputError) as caught:
        load_experiment(_experiment(tmp_path, camera))
    assert caught.value.field == field
