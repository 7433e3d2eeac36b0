"""Sun and zoom policies: the shadow's light held or quantized, the cascades fitted to a minimum field of view."""

from __future__ import annotations

import numpy as np
import pytest

from csmlab.camera import CameraPose
from csmlab.cascades import build_cascades
from csmlab.config import Variant, load_experiment
from csmlab.errors import InputError
from csmlab.geometry import normalized, rotation_looking_at
from csmlab.invariants import summary_invariants
from csmlab.light import LightPath, direction_from_angles
from csmlab.metric_registry import DERIVED, metric_values, run_value
from csmlab.metrics.temporal import temporal_maps, temporal_summary
from csmlab.render import prepare_scene, render_shadow, render_view
from csmlab.scene import make_scene
from csmlab.settings import ShadowSettings
from csmlab.shadow_policies import shadow_fov_deg, shadow_light_direction, sun_angles_deg


def _held_sun_frames(settings: ShadowSettings, sun: LightPath):
    """Every frame's temporal maps of ``settings`` under ``sun``, seen from a static camera over plane_box."""
    dscene = prepare_scene(make_scene("plane_box", plane_size=40.0, box_size=2.0))
    eye = np.array([-6.0, 4.0, 5.0])
    pose = CameraPose(position=eye, orientation=rotation_looking_at(np.array([1.0, 0.0, -1.0]) - eye),
                      aspect=96 / 54, far=100.0)
    previous, out = None, []
    for i in range(len(sun)):
        view = render_view(dscene, pose, sun.direction(i), width=96, height=54, index=i,
                           previous_light_direction=sun.direction(i - 1) if i else None)
        shadow_light = normalized(shadow_light_direction(sun.directions, i, policy=settings.sun_policy,
                                                         update_frames=settings.sun_update_frames,
                                                         step_deg=settings.sun_step_deg))
        frame = render_shadow(dscene, view, settings, light_direction=shadow_light)
        if previous is not None:
            out.append((frame, temporal_maps(frame, previous)))
        previous = frame
    return out


def test_a_sun_updated_every_n_frames_stands_still_between_updates_and_pops_once_at_each():
    # The true sun sinks 1.5° a frame (the shading's and the reference's light); the shadow's is
    # updated at frames 0, 3, 6. Between updates exact's maps are the same bits: S does not
    # change anywhere and its flicker is exactly 0; each update changes S (a pop) beyond the
    # reference's one-frame change.
    sun = LightPath.sun(elevation_deg=45.0, azimuth_deg=20.0, elevation_end_deg=33.0, azimuth_end_deg=20.0,
                        frames=9)
    settings = ShadowSettings(cascades=2, resolution=256, shadow_distance=30.0, stabilization="exact",
                              sun_policy="every_n", sun_update_frames=3)
    popped = []
    for frame, maps in _held_sun_frames(settings, sun):
        summary = temporal_summary(maps)
        update = frame.view.index % 3 == 0
        assert maps.same_cascade.sum() > 1000
        assert maps.light_moved == update
        changed = np.abs(frame.shadow.lit - maps.previous_lit)[maps.counted]
        if update:
            popped.append(frame.view.index)
            assert np.count_nonzero(changed) > 20 and summary["flicker_same"] > 0.0 and summary["flip_same"] > 0.0
        else:
            assert np.count_nonzero(changed) == 0
            assert summary["flicker_same"] == 0.0 and summary["flip_same"] == 0.0 and summary["flicker"] == 0.0
    assert popped == [3, 6]


def test_every_frame_is_the_true_sun_and_every_n_the_sun_of_the_last_update():
    sun = LightPath.sun(elevation_deg=40.0, azimuth_deg=0.0, elevation_end_deg=10.0, azimuth_end_deg=60.0, frames=11)
    for i in range(11):
        np.testing.assert_array_equal(shadow_light_direction(sun.directions, i, policy="every_frame"),
                                      sun.directions[i])
        np.testing.assert_array_equal(shadow_light_direction(sun.directions, i, policy="every_n", update_frames=4),
                                      sun.directions[4 * (i // 4)])


def test_a_quantized_sun_is_constant_while_the_true_sun_stays_inside_a_step():
    # A sun drifting inside the 1° cell about (elevation 30°, azimuth 20°) gives one direction bit
    # for bit, that of the cell's centre (direction_from_angles); past elevation 30.5° the next.
    inside = LightPath.sun(elevation_deg=29.6, azimuth_deg=19.55, elevation_end_deg=30.45, azimuth_end_deg=20.45,
                           frames=12)
    held = np.array([shadow_light_direction(inside.directions, i, policy="quantized", step_deg=1.0)
                     for i in range(12)])
    assert len(np.unique(held, axis=0)) == 1
    np.testing.assert_allclose(held[0], direction_from_angles(elevation_deg=30.0, azimuth_deg=20.0), atol=1e-15)
    crossing = LightPath.sun(elevation_deg=30.1, azimuth_deg=20.0, elevation_end_deg=31.2, azimuth_end_deg=20.0,
                             frames=12)
    elevations = 30.1 + 1.1 * np.linspace(0.0, 1.0, 12)
    steps = [shadow_light_direction(crossing.directions, i, policy="quantized", step_deg=1.0) for i in range(12)]
    for direction, elevation in zip(steps, elevations):
        expected = direction_from_angles(elevation_deg=30.0 if elevation < 30.5 else 31.0, azimuth_deg=20.0)
        np.testing.assert_allclose(direction, expected, atol=1e-15)
    # A coarser step about the up axis: the azimuth rounds to multiples of 15°.
    one = LightPath.static(direction_from_angles(elevation_deg=52.0, azimuth_deg=-97.0), 1)
    np.testing.assert_allclose(shadow_light_direction(one.directions, 0, policy="quantized", step_deg=15.0),
                               direction_from_angles(elevation_deg=45.0, azimuth_deg=-90.0), atol=1e-15)


def test_sun_angles_invert_direction_from_angles():
    rng = np.random.default_rng(3)
    for elevation, azimuth in zip(rng.uniform(-89.0, 89.0, 50), rng.uniform(-179.0, 179.0, 50)):
        got = sun_angles_deg(direction_from_angles(elevation_deg=elevation, azimuth_deg=azimuth))
        np.testing.assert_allclose(got, (elevation, azimuth), atol=1e-9)


def _pose(fov_y_deg: float) -> CameraPose:
    eye = np.array([3.0, 1.7, 8.0])
    return CameraPose(position=eye, orientation=rotation_looking_at(np.array([0.0, 0.5, -4.0]) - eye),
                      fov_y_deg=fov_y_deg, aspect=16 / 9, far=300.0)


def _boxes(cascades) -> list[np.ndarray]:
    return [np.concatenate([c.texel_size, c.origin, [c.split_near, c.split_far, c.depth_near, c.depth_far]])
            for c in cascades.cascades]


@pytest.mark.parametrize("stabilization", ["exact", "quantized", "none"])
def test_cascades_are_identical_for_every_fov_below_the_minimum_and_those_of_a_camera_at_it(stabilization):
    # Godot's minimum FOV: every camera narrower than 55° gets the cascades of the same camera at
    # 55° (the oracle: build_cascades of that camera with the camera's own field of view); a wider
    # camera keeps its own.
    light = direction_from_angles(elevation_deg=35.0, azimuth_deg=25.0)
    corners = np.array([[x, y, z] for x in (-60.0, 60.0) for y in (0.0, 10.0) for z in (-60.0, 60.0)])
    floored = ShadowSettings(cascades=3, resolution=512, shadow_distance=80.0, stabilization=stabilization,
                             zoom_policy="min_fov", min_fov_deg=55.0)
    own = floored.replace(zoom_policy="camera")

    def boxes(fov, settings):
        return _boxes(build_cascades(pose=_pose(fov), light_direction=light, scene_corners=corners, settings=settings))

    at_minimum = boxes(55.0, own)
    for fov in (12.0, 20.0, 37.5, 54.9):
        np.testing.assert_array_equal(np.array(boxes(fov, floored)), np.array(at_minimum))
        assert not np.array_equal(np.array(boxes(fov, own)), np.array(at_minimum))
    np.testing.assert_array_equal(np.array(boxes(70.0, floored)), np.array(boxes(70.0, own)))
    assert shadow_fov_deg(30.0, policy="min_fov", min_fov_deg=55.0) == 55.0
    assert shadow_fov_deg(30.0, policy="camera", min_fov_deg=55.0) == 30.0


def test_exact_promises_zero_same_cascade_flicker_on_a_zoom_only_below_its_minimum_fov():
    zoom = np.geomspace(60.0, 15.0, 5)
    variants = [Variant("own", "base", ShadowSettings()),
                Variant("floored", "base", ShadowSettings(zoom_policy="min_fov", min_fov_deg=60.0)),
                Variant("low_floor", "base", ShadowSettings(zoom_policy="min_fov", min_fov_deg=30.0))]
    promised = {method: points["base"]["flicker_same_zero"]["promised"]
                for method, points in summary_invariants(variants, light_static=True, fov_y_deg=zoom).items()}
    assert promised == {"own": False, "floored": True, "low_floor": False}
    moving_sun = summary_invariants(variants[1:2], light_static=False, fov_y_deg=zoom)
    assert not moving_sun["floored"]["base"]["flicker_same_zero"]["promised"]


def test_the_largest_frame_flicker_is_a_peak_over_frames_not_a_mean():
    peak = DERIVED["flicker_peak"]
    assert peak.peak_of == "flicker" and peak.better == "lower"
    columns = {"flicker": np.array([np.nan, 0.0, 0.0, 0.3, 0.0, 0.1])}
    assert metric_values("flicker_peak", columns) is columns["flicker"]
    assert run_value("flicker_peak", columns["flicker"]) == 0.3 and run_value("flicker", columns["flicker"]) == 0.08
    assert metric_values("flicker_peak", {}) is None and np.isnan(run_value("flicker_peak", [np.nan]))


BASE = """
[scene]
kind = "plane_box"
[camera]
path = "walk"
frames = 2
[light]
elevation_deg = 40.0
elevation_end_deg = 30.0
[[methods]]
name = "m"
"""


@pytest.mark.parametrize("line, field, expected", [
    ('sun_policy = "sometimes"', "sun_policy", "expected one of ['every_frame', 'every_n', 'quantized']"),
    ('sun_policy = "every_n"\nsun_update_frames = 0', "sun_update_frames", "a positive whole number of frames"),
    ('sun_policy = "every_n"\nsun_update_frames = 2.5', "sun_update_frames", "expected"),
    ('sun_policy = "quantized"\nsun_step_deg = -1.0', "sun_step_deg", "an angle in (0, 90] degrees"),
    ('zoom_policy = "wide"', "zoom_policy", "expected one of ['camera', 'min_fov']"),
    ('zoom_policy = "min_fov"\nmin_fov_deg = 200.0', "min_fov_deg", "a field of view in (0, 180) degrees"),
])
def test_bad_policy_values_are_input_errors_naming_the_field(tmp_path, line, field, expected):
    path = tmp_path / "exp.toml"
    path.write_text(BASE + line + "\n")
    with pytest.raises(InputError) as caught:
        load_experiment(path)
    assert caught.value.field == f"methods.m.{field}" and caught.value.file == str(path)
    assert expected in caught.value.detail


def test_a_bad_policy_exits_2_with_one_line_naming_file_and_field(tmp_path):
    from typer.testing import CliRunner

    from csmlab.cli import app

    path = tmp_path / "exp.toml"
    path.write_text(BASE + 'sun_policy = "every_n"\nsun_update_frames = -3\n')
    outcome = CliRunner().invoke(app, ["run", str(path), "--out", str(tmp_path / "out")])
    assert outcome.exit_code == 2, outcome.output
    message = outcome.stderr.strip()
    assert len(message.splitlines()) == 1 and "Traceback" not in outcome.output
    assert str(path) in message and "methods.m.sun_update_frames" in message
    assert not (tmp_path / "out" / "metrics.csv").exists()
