"""Temporal shadow change: summaries by hand counts, the previous light's reference in closed form, and whole-path
properties."""

import numpy as np
import pytest

from csmlab.camera import CameraPose
from csmlab.geometry import rotation_looking_at
from csmlab.metrics import measure_frame, metric_columns
from csmlab.light import direction_from_angles
from csmlab.metrics.temporal import temporal_maps, temporal_summary
from csmlab.paths import make_path
from csmlab.render import prepare_scene, render_shadow, render_view
from csmlab.scene import make_scene
from csmlab.scene.shapes import placed, scene_from_parts, unit_icosahedron
from csmlab.settings import ShadowSettings

LIGHT = np.array([0.3, -1.0, 0.2])
SUN = np.array([0.5, -0.7, 0.35])


def _box_shadow(points, toward_light, *, half=1.0, height=2.0, margin=0.0):
    """Whether the ray from each point toward the light meets plane_box's box grown by ``margin`` (slabs, float64)."""
    lo = np.array([-half, 0.0, -half]) - margin
    hi = np.array([half, height, half]) + margin
    with np.errstate(divide="ignore", invalid="ignore"):
        a, b = (lo - points) / toward_light, (hi - points) / toward_light
    enter = np.nanmax(np.minimum(a, b), axis=-1)
    leave = np.nanmin(np.maximum(a, b), axis=-1)
    return (leave >= np.maximum(enter, 0.0)) & (leave > 0.0)


def _sun(i):
    return direction_from_angles(elevation_deg=50.0 - 3.0 * i, azimuth_deg=30.0 + 6.0 * i)


def test_previous_reference_is_the_shadow_of_the_previous_light_at_the_current_points():
    # plane_box's 2 m cube, a camera moving past its shadow and a sun moving 3° in elevation and
    # 6° in azimuth: at every ground point of frame 1, R_{t-1} is the box's shadow under frame 0's
    # sun (closed form), not frame 0's image sampled near the point.
    dscene = prepare_scene(make_scene("plane_box", plane_size=40.0, box_size=2.0))
    eye = np.array([-4.63, 3.0, 1.79])
    pose = CameraPose(position=eye, orientation=rotation_looking_at(np.array([-1.0, 0.0, -1.5]) - eye),
                      aspect=96 / 54, far=100.0)
    view = render_view(dscene, pose, _sun(1), width=96, height=54, index=1, previous_light_direction=_sun(0))
    g = view.gbuffer
    ground = g.valid & (g.normal[..., 1] == 1.0) & (np.abs(g.position[..., 1]) < 1e-9)
    points = np.where(ground[..., None], g.position, 0.0)
    inside = _box_shadow(points, -_sun(0), margin=-1e-3)
    clear = ~_box_shadow(points, -_sun(0), margin=1e-3)
    decided = ground & (inside | clear)
    assert decided.sum() > 0.6 * g.valid.sum() and np.count_nonzero(ground & inside) > 100
    np.testing.assert_array_equal(view.previous_reference[decided], np.where(inside, 0.0, 1.0)[decided])
    np.testing.assert_array_equal(view.previous_light_direction, _sun(0))
    assert np.count_nonzero(view.previous_reference[decided] != view.reference[decided]) > 20


def test_exact_has_zero_same_cascade_flicker_under_a_moving_sun_and_a_moving_camera():
    # A convex icosahedron (no cast shadows, so exact's maps agree with the ray-traced reference)
    # seen from an orbiting camera under a sun that turns faces away from it: S changes exactly as
    # R does, and subtracting R_t - R_{t-1} cast at frame t's points leaves exactly 0.
    solid = placed(unit_icosahedron(), scale=[3.0, 3.0, 3.0], offset=[[0.0, 0.0, 0.0]], albedo=[0.6, 0.6, 0.6])
    dscene = prepare_scene(scene_from_parts([solid], name="icosahedron"))
    settings = ShadowSettings(cascades=2, resolution=256, shadow_distance=20.0, stabilization="exact")
    previous, light_before, raw = None, None, []
    for i in range(7):
        angle = np.radians(20.0 + 9.0 * i)
        eye = np.array([9.0 * np.sin(angle), 4.0 + 0.3 * i, 9.0 * np.cos(angle)])
        pose = CameraPose(position=eye, orientation=rotation_looking_at(-eye), aspect=96 / 54, far=100.0)
        light = direction_from_angles(elevation_deg=35.0 + 4.0 * i, azimuth_deg=10.0 + 8.0 * i)
        view = render_view(dscene, pose, light, width=96, height=54, index=i, previous_light_direction=light_before)
        frame = render_shadow(dscene, view, settings)
        if previous is not None:
            maps = temporal_maps(frame, previous)
            summary = temporal_summary(maps)
            assert maps.light_moved and maps.same_cascade.sum() > 300
            assert summary["flicker_same"] == 0.0 and summary["flip_same"] == 0.0
            raw.append(np.abs(frame.shadow.lit - maps.previous_lit)[maps.same_cascade].mean())
        previous, light_before = frame, light
    assert max(raw) > 0.02


def test_temporal_maps_refuse_a_moved_camera_and_light_without_the_previous_cast():
    dscene = prepare_scene(make_scene("plane_box", plane_size=40.0, box_size=2.0))
    settings = ShadowSettings(cascades=1, resolution=64)
    frames = []
    for i, x in enumerate([4.0, 4.2]):
        eye = np.array([x, 3.0, 5.0])
        pose = CameraPose(position=eye, orientation=rotation_looking_at(-eye), aspect=96 / 54, far=100.0)
        frames.append(render_shadow(dscene, render_view(dscene, pose, _sun(i), width=32, height=18, index=i), settings))
    with pytest.raises(ValueError, match="frame 1: expected its view rendered with previous_light_direction"):
        temporal_maps(frames[1], frames[0])


def _walk_summaries(kind, **params):
    """Temporal summaries of exact, none and quantized over a 60-frame walk with a static light."""
    dscene = prepare_scene(make_scene(kind, seed=1, **params))
    path = make_path("walk", frames=60, fps=30, seed=1, aspect=96 / 54, far=150.0)
    methods = {m: ShadowSettings(cascades=3, resolution=256, stabilization=m, shadow_distance=60.0)
               for m in ("exact", "none", "quantized")}
    previous = dict.fromkeys(methods)
    summaries = {m: [] for m in methods}
    for i, pose in enumerate(path.poses()):
        view = render_view(dscene, pose, SUN, width=96, height=54, index=i)
        for method, settings in methods.items():
            frame = render_shadow(dscene, view, settings)
            if previous[method] is not None:
                summaries[method].append(temporal_summary(temporal_maps(frame, previous[method])))
            previous[method] = frame
    return {m: {key: np.array([s[key] for s in rows]) for key in rows[0]} for m, rows in summaries.items()}


@pytest.mark.parametrize("kind, params", [
    ("terrain", dict(size=120.0, resolution=24, trees=120, ring_trees=40)),
    ("fence", dict(size=90.0, inner_fences=2, outer_fences=1, poles=2)),
])
def test_exact_has_zero_same_cascade_flicker_on_a_walk_where_none_flickers(kind, params):
    summary = _walk_summaries(kind, **params)
    exact, none, quantized = summary["exact"], summary["none"], summary["quantized"]
    assert np.all(exact["flicker_same"] == 0.0)
    assert np.all(exact["flip_same"] == 0.0)
    assert np.nanmean(none["flicker_same"]) > 0.0
    assert np.nanmean(quantized["flicker_same"]) <= np.nanmean(none["flicker_same"])
    assert np.nanmean(quantized["flicker"]) <= np.nanmean(none["flicker"])


@pytest.mark.parametrize("filter", ["none", "pcf"])
def test_light_rotating_under_a_static_camera_flickers_only_as_the_reference_does(filter):
    # One 8192² cascade over plane_box, hard lookups and the default 3×3 PCF; the light turns 2° per
    # frame about the vertical. Most of the raw change |ΔS| is the shadow moving, which the
    # reference's own change removes; PCF stays free of acne thanks to the receiver-plane bias.
    dscene = prepare_scene(make_scene("plane_box", plane_size=40.0, box_size=2.0))
    eye = np.array([4.0, 4.0, 4.0])
    pose = CameraPose(position=eye, orientation=rotation_looking_at(np.array([1.5, 0.0, -1.5]) - eye),
                      aspect=96 / 54, far=100.0)
    settings = ShadowSettings(cascades=1, resolution=8192, shadow_distance=20.0, filter=filter)
    previous = None
    for i, angle in enumerate(np.radians([0.0, 2.0, 4.0])):
        turn = np.array([[np.cos(angle), 0.0, np.sin(angle)], [0.0, 1.0, 0.0], [-np.sin(angle), 0.0, np.cos(angle)]])
        frame = render_shadow(dscene, render_view(dscene, pose, turn @ [0.7, -0.6, -0.4], width=96, height=54,
                                                  index=i), settings)
        if previous is not None:
            maps = temporal_maps(frame, previous)
            raw = np.mean(np.abs(frame.shadow.lit - maps.previous_lit)[maps.counted])
            assert maps.light_moved and maps.counted.mean() > 0.8
            assert raw > 2e-3
            assert temporal_summary(maps)["flicker"] < 1e-3
        previous = frame


def test_an_unchanged_frame_does_not_flicker():
    dscene = prepare_scene(make_scene("plane_box", plane_size=40.0, box_size=2.0))
    eye = np.array([4.0, 4.0, 4.0])
    pose = CameraPose(position=eye, orientation=rotation_looking_at(-eye), aspect=96 / 54, far=100.0)
    frame = render_shadow(dscene, render_view(dscene, pose, SUN, width=96, height=54),
                          ShadowSettings(cascades=2, resolution=256, stabilization="none"))
    summary = temporal_summary(temporal_maps(frame, frame))
    assert summary["flicker"] == 0.0 and summary["flip_rate"] == 0.0 and np.isnan(summary["flicker_changed"])


def _plane_box_frames(stabilization):
    """Two consecutive frames of a camera stepping sideways past plane_box's box, rendered afresh."""
    dscene = prepare_scene(make_scene("plane_box", plane_size=40.0, box_size=2.0))
    settings = ShadowSettings(cascades=2, resolution=256, stabilization=stabilization, shadow_distance=30.0)
    frames = []
    for i, x in enumerate([4.0, 4.05]):
        eye = np.array([x, 3.0, 5.0])
        pose = CameraPose(position=eye, orientation=rotation_looking_at(-eye), aspect=96 / 54, far=100.0)
        frames.append(render_shadow(dscene, render_view(dscene, pose, SUN, width=96, height=54, index=i), settings))
    return frames


def test_measure_frame_fills_every_column_and_leaves_between_frame_ones_nan_at_the_first_frame():
    first, second = _plane_box_frames("none")
    start, step = measure_frame(first), measure_frame(second, first)
    assert tuple(start.values) == metric_columns(2) == tuple(step.values)
    between = ("flicker", "flicker_same", "flicker_changed", "flip_rate", "flip_same", "flip_changed",
               "de2000_mean", "de2000_p99", "de2000_frac_jnd", "ssim", "flip")
    assert all(np.isnan(start.values[key]) for key in between)
    assert all(np.isfinite(step.values[key]) for key in between if key not in ("flicker_changed", "flip_changed"))
    assert step.values["memory_bytes"] == 2 * 256 * 256 * 4
    assert start.pixels["shaded"].shape == (54, 96, 3) and start.pixels["ref_diff"].dtype == np.int8
    assert np.all(np.isnan(start.pixels["dS"]))
    np.testing.assert_array_equal(np.isfinite(step.pixels["dS"]), np.isfinite(step.pixels["de2000"]))


def test_measure_frame_against_itself_reads_no_change():
    frame, _ = _plane_box_frames("none")
    values = measure_frame(frame, frame).values
    assert values["flicker"] == 0.0 and values["flip_rate"] == 0.0
    assert values["de2000_mean"] == 0.0 and values["flip"] == 0.0
    assert values["ssim"] == pytest.approx(1.0, abs=1e-12)


def test_measure_frame_is_bit_identical_on_frames_rendered_twice():
    first = measure_frame(*reversed(_plane_box_frames("quantized"))).values
    again = measure_frame(*reversed(_plane_box_frames("quantized"))).values
    np.testing.assert_array_equal(np.array(list(first.values())), np.array(list(again.values())))


def test_measure_frame_refuses_a_previous_frame_of_another_method():
    first, _ = _plane_box_frames("none")
    _, second = _plane_box_frames("exact")
    with pytest.raises(ValueError, match="previous: expected frame t-1 of the same method"):
        measure_frame(second, first)


def test_a_measured_view_keeps_no_earlier_view_alive():
    import gc
    import weakref

    dscene = prepare_scene(make_scene("terrain", seed=1, size=60.0, resolution=12, trees=20, ring_trees=0))
    path = make_path("walk", frames=3, fps=30, seed=1, aspect=48 / 32, far=100.0)
    settings = ShadowSettings(cascades=2, resolution=64, shadow_distance=40.0)
    frames = [render_shadow(dscene, render_view(dscene, pose, SUN, width=48, height=32, index=i), settings)
              for i, pose in enumerate(path.poses())]
    measure_frame(frames[1], frames[0])
    measure_frame(frames[2], frames[1])
    first = weakref.ref(frames[0].view)
    del frames[:2]
    gc.collect()
    # What frame 2's view keeps of frame 1 (its points' depth from frame 1's camera) holds no view.
    assert first() is None
    assert any(key[0] == "view_depth_from" for key in frames[0].view.derived)
