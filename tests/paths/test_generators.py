"""Path generators: deterministic, smooth, and where their docstrings say they are.

Oracles are the geometric properties each motion must have (distance to the ring's axis,
constant speed, collinearity, view direction toward a target or the sun), computed here from
the returned positions and rotation matrices with plain NumPy.
"""

from __future__ import annotations

import numpy as np
import pytest

from csmlab.geometry import quat_to_matrix
from csmlab.paths import PATH_GENERATORS, make_path

SUN = np.array([0.3, -0.8, 0.5])


def _forward(path) -> np.ndarray:
    return -quat_to_matrix(path.orientations)[:, :, 2]


def _up(path) -> np.ndarray:
    return quat_to_matrix(path.orientations)[:, :, 1]


def _angle_deg(a, b) -> np.ndarray:
    a = a / np.linalg.norm(a, axis=-1, keepdims=True)
    b = b / np.linalg.norm(b, axis=-1, keepdims=True)
    return np.degrees(np.arccos(np.clip(np.sum(a * b, axis=-1), -1.0, 1.0)))


def test_every_generator_is_bit_identical_for_the_same_arguments():
    for name in PATH_GENERATORS:
        a = make_path(name, frames=40, seed=5, light_direction=SUN)
        b = make_path(name, frames=40, seed=5, light_direction=SUN)
        for field in ("times", "positions", "orientations", "fov_y_deg"):
            assert np.array_equal(getattr(a, field), getattr(b, field)), (name, field)
        assert a.name == name


def test_seeded_generators_change_with_the_seed():
    for name in ("walk", "jitter"):
        a = make_path(name, frames=40, seed=1)
        b = make_path(name, frames=40, seed=2)
        assert not np.array_equal(a.orientations, b.orientations), name


def test_every_generator_is_smooth_except_jitter():
    # 30 fps: no step longer than 0.5 m (flyover at 10 m/s moves 0.33 m) nor a turn above 1°.
    for name in sorted(set(PATH_GENERATORS) - {"jitter"}):
        path = make_path(name, frames=90, light_direction=SUN)
        assert np.max(np.linalg.norm(np.diff(path.positions, axis=0), axis=1)) < 0.5, name
        assert np.max(_angle_deg(_forward(path)[1:], _forward(path)[:-1])) < 1.0, name
        np.testing.assert_allclose(np.diff(path.times), 1 / 30, rtol=1e-12, err_msg=name)


def test_walk_stays_on_the_ring_road_at_eye_height():
    path = make_path("walk", frames=600, seed=3)
    r = np.hypot(path.positions[:, 0], path.positions[:, 2])
    assert np.all(np.abs(r - 20.0) <= 1.0)
    assert np.all((path.positions[:, 1] >= 1.5) & (path.positions[:, 1] <= 2.0))


def test_walk_bobs_about_3_cm_at_2_hz_and_moves_at_walking_speed():
    path = make_path("walk", frames=250, fps=50.0)   # 5 s
    y = path.positions[1:, 1] - 1.7
    assert 0.05 < np.ptp(y) <= 0.06 + 1e-12
    y = y[np.abs(y) > 1e-9]                          # samples that fall on a zero have no sign
    crossings = np.count_nonzero(np.sign(y[1:]) != np.sign(y[:-1]))
    assert crossings == 19              # a 2 Hz sine crosses zero at t = k/4 s: k = 1 … 19 in (0, 4.98]
    angle = np.unwrap(np.arctan2(-path.positions[:, 2], path.positions[:, 0]))
    np.testing.assert_allclose((angle[-1] - angle[0]) * 20.0 / (path.times[-1] - path.times[0]), 1.4, rtol=1e-2)


def test_walk_looks_mostly_along_the_tangent_and_looks_around():
    path = make_path("walk", frames=900, seed=4)   # 30 s
    p = path.positions
    tangent = np.stack([-p[:, 2], np.zeros(len(p)), p[:, 0]], axis=1) * -1.0   # counter-clockwise from above
    f = _forward(path)
    horizontal = f * np.array([1.0, 0.0, 1.0])
    off = _angle_deg(horizontal, tangent)
    assert np.max(off) <= 20.0 + 0.5           # look-around amplitude
    assert np.mean(off) < 12.0
    assert np.std(off) > 1.0                   # it does turn
    assert np.all(np.degrees(np.arcsin(f[:, 1])) <= 0.5)   # pitch -5 ± 5°


def test_dolly_moves_straight_at_constant_speed_along_its_view():
    path = make_path("dolly", frames=200)
    steps = np.diff(path.positions, axis=0)
    np.testing.assert_allclose(np.linalg.norm(steps, axis=1), 1.5 / 30, rtol=1e-9)
    np.testing.assert_allclose(steps / np.linalg.norm(steps, axis=1, keepdims=True), _forward(path)[1:], atol=1e-12)
    r = np.hypot(path.positions[:, 0], path.positions[:, 2])
    assert np.all((r >= 18.0) & (r <= 22.0))   # 200 frames = 10 m of the 17 m on the ring road


def test_pan_stands_still_and_turns_at_the_given_rate():
    path = make_path("pan", frames=60, yaw_rate_deg=15.0)
    assert np.all(path.positions == path.positions[0])
    assert np.hypot(path.positions[0, 0], path.positions[0, 2]) < 4.0
    np.testing.assert_allclose(_angle_deg(_forward(path)[1:], _forward(path)[:-1]), 15.0 / 30, rtol=1e-6)
    np.testing.assert_allclose(_up(path)[:, 1], 1.0, atol=1e-12)


def test_orbit_circles_the_target_looking_at_it():
    path = make_path("orbit", frames=120, target=(1.0, 0.5, -2.0), radius=12.0, height=3.0)
    offset = path.positions - np.array([1.0, 0.5, -2.0])
    np.testing.assert_allclose(np.hypot(offset[:, 0], offset[:, 2]), 12.0, rtol=1e-12)
    np.testing.assert_allclose(path.positions[:, 1], 3.0)
    np.testing.assert_allclose(np.cross(_forward(path), -offset), 0.0, atol=1e-9)
    assert np.all(np.sum(_forward(path) * -offset, axis=1) > 0)


def test_flyover_crosses_the_scene_high_up_looking_down():
    path = make_path("flyover", frames=300)    # 10 s at 10 m/s
    assert np.all((path.positions[:, 1] >= 30.0) & (path.positions[:, 1] <= 60.0))
    down = -np.degrees(np.arcsin(_forward(path)[:, 1]))
    assert np.all((down >= 30.0) & (down <= 45.0))
    assert path.positions[0, 0] < 0.0 < path.positions[-1, 0]


def test_jitter_moves_by_sub_millimetre_and_hundredth_degree_steps():
    path = make_path("jitter", frames=100, seed=9)
    base = np.array([20.0, 1.7, 0.0])
    moved = np.abs(path.positions - base)
    assert np.all(moved <= 1e-3) and np.all(np.max(moved, axis=0) > 5e-4)
    turned = _angle_deg(_forward(path), np.array([0.0, 0.0, -1.0]))
    assert np.all(turned <= np.sqrt(2) * 0.01 + 1e-9) and np.max(turned) > 0.005
    assert np.all(np.any(np.diff(path.positions, axis=0) != 0, axis=1))


@pytest.mark.parametrize("light", [SUN, (-1.0, -0.2, 0.0), (0.0, -1.0, 0.0)])
def test_dueling_faces_the_sun_horizontally(light):
    path = make_path("dueling", frames=60, light_direction=light)
    f = _forward(path)
    np.testing.assert_allclose(f[:, 1], 0.0, atol=1e-12)
    toward_sun = -np.asarray(light, float) * np.array([1.0, 0.0, 1.0])
    if np.linalg.norm(toward_sun) > 0:         # straight down: any horizontal direction is valid
        np.testing.assert_allclose(_angle_deg(f, np.broadcast_to(toward_sun, f.shape)), 0.0, atol=1e-5)
    r = np.hypot(path.positions[:, 0], path.positions[:, 2])
    np.testing.assert_allclose(r, 20.0)
    assert np.linalg.norm(path.positions[-1] - path.positions[0]) > 0.5   # 2 s at 0.5 m/s


def test_dueling_without_a_light_names_the_missing_field():
    with pytest.raises(ValueError, match="light_direction"):
        make_path("dueling", frames=10)


def test_make_path_sets_the_projection():
    path = make_path("orbit", frames=5, fov_y_deg=45.0, aspect=1.5, near=0.5, far=300.0)
    assert np.all(path.fov_y_deg == 45.0)
    assert (path.aspect, path.near, path.far) == (1.5, 0.5, 300.0)


@pytest.mark.parametrize("name, kwargs, message", [
    ("spiral", {}, r"path: expected one of \['dolly', 'dueling', 'flyover', 'jitter', 'orbit', 'pan', 'walk', "
                   r"'zoom'\]"),
    ("walk", {"radus": 3.0}, r"walk: unknown parameter\(s\) \['radus'\]; expected some of .*'radius'"),
    ("walk", {"frames": 0}, "frames: expected a whole number ≥ 1"),
    ("pan", {"fps": 0.0}, "fps: expected a positive frame rate"),
    ("orbit", {"radius": float("nan")}, "radius: expected finite"),
    ("dolly", {"speed": -1.0}, "speed: expected metres per second ≥ 0"),
    ("jitter", {"position": (0.0, 1.0)}, "position: expected 3 finite coordinates"),
])
def test_make_path_refuses_bad_arguments_naming_them(name, kwargs, message):
    kwargs = {"frames": 10, **kwargs}
    with pytest.raises(ValueError, match=message):
        make_path(name, **kwargs)


def test_zoom_narrows_the_field_of_view_geometrically():
    # Magnification zoom^s: at s = 1/2 with zoom 4, tan(fov/2) is halved; at the end quartered.
    path = make_path("zoom", frames=3, fps=1.0, fov_y_deg=60.0, zoom=4.0)
    t = np.tan(np.radians(path.fov_y_deg) / 2.0)
    np.testing.assert_allclose(t / np.tan(np.radians(30.0)), [1.0, 0.5, 0.25], rtol=1e-12)
    assert np.all(np.diff(path.positions[:, 2]) < 0)
