"""Temporal shadow change: summaries by hand counts, reprojection of the reference, and whole-path properties."""

import numpy as np
import pytest

from csmlab.camera import CameraPose
from csmlab.cascades import build_cascades
from csmlab.frame import Frame, GBuffer, ShadowLookup, ShadowMaps, View
from csmlab.geometry import rotation_looking_at
from csmlab.metrics import measure_frame, metric_columns
from csmlab.metrics.temporal import TemporalMaps, previous_reference_at, temporal_maps, temporal_summary
from csmlab.paths import make_path
from csmlab.render import prepare_scene, render_shadow, render_view
from csmlab.scene import make_scene
from csmlab.settings import ShadowSettings

LIGHT = np.array([0.3, -1.0, 0.2])
SUN = np.array([0.5, -0.7, 0.35])


def _ground_view(position, target, *, width=64, height=48, reference_of=lambda p: (p[..., 0] > 1.0)):
    """An analytic view of the ground plane y = 0; triangle id 0 for z < 0, 1 for z >= 0."""
    pose = CameraPose(position=position, orientation=rotation_looking_at(np.subtract(target, position)),
                      aspect=width / height)
    tan_y = np.tan(np.radians(pose.fov_y_deg) / 2.0)
    col, row = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    rays = np.stack([(2 * col / width - 1) * tan_y * pose.aspect, (1 - 2 * row / height) * tan_y,
                     -np.ones_like(col)], axis=-1) @ pose.rotation.T
    distance = -pose.position[1] / rays[..., 1]
    hit = distance > 0
    position = np.where(hit[..., None], pose.position + distance[..., None] * rays, np.nan)
    triangle = np.where(hit, (position[..., 2] >= 0).astype(np.int32), -1)
    reference = np.where(hit, reference_of(position), np.nan).astype(np.float32)
    zeros3 = np.zeros((height, width, 3), np.float32)
    gbuffer = GBuffer(position=position, normal=zeros3, triangle=triangle, view_depth=zeros3[..., 0], dpdx=zeros3,
                      dpdy=zeros3, albedo=zeros3)
    return View(index=0, pose=pose, light_direction=LIGHT, gbuffer=gbuffer, reference=reference)


def _frame(view):
    settings = ShadowSettings(cascades=1, resolution=32)
    cascades = build_cascades(pose=view.pose, light_direction=LIGHT, scene_corners=np.zeros((1, 3)), settings=settings)
    shape = view.gbuffer.shape
    return Frame(view=view, settings=settings,
                 maps=ShadowMaps(cascades=cascades, depth=np.zeros((1, 32, 32), np.float32), texels_rasterized=0),
                 shadow=ShadowLookup(lit=np.ones(shape, np.float32), cascade=np.zeros(shape, np.int8),
                                     blend=np.zeros(shape, bool)))


def test_temporal_summary_means_over_each_subset():
    change = np.array([[0.5, -0.25, np.nan], [0.0, 1.0, np.nan]])
    counted = np.isfinite(change)
    same = np.array([[True, True, False], [False, False, False]])
    flipped = np.array([[True, False, False], [False, True, False]])
    maps = TemporalMaps(previous_lit=np.zeros((2, 3), np.float32), change=change, flipped=flipped, counted=counted,
                        same_cascade=same, light_moved=False)
    summary = temporal_summary(maps)
    assert summary == {"flicker": pytest.approx(1.75 / 4), "flicker_same": 0.375, "flicker_changed": 0.5,
                       "flip_rate": 0.5, "flip_same": 0.5, "flip_changed": 0.5}


def test_temporal_summary_of_an_empty_subset_is_nan():
    maps = TemporalMaps(previous_lit=np.zeros((1, 2), np.float32), change=np.zeros((1, 2)),
                        flipped=np.zeros((1, 2), bool), counted=np.ones((1, 2), bool),
                        same_cascade=np.ones((1, 2), bool), light_moved=False)
    summary = temporal_summary(maps)
    assert summary["flicker_same"] == 0.0 and summary["flip_same"] == 0.0
    assert np.isnan(summary["flicker_changed"]) and np.isnan(summary["flip_changed"])


def test_previous_reference_of_an_unmoved_camera_is_the_previous_image():
    view = _ground_view([0.0, 5.0, 8.0], [0.0, 0.0, 0.0])
    earlier = _ground_view([0.0, 5.0, 8.0], [0.0, 0.0, 0.0], reference_of=lambda p: p[..., 2] > 0.5)
    np.testing.assert_array_equal(previous_reference_at(_frame(view), _frame(earlier)), earlier.reference)


def test_previous_reference_of_a_moved_camera_is_right_away_from_the_boundary():
    # R_{t-1}(X) = [x > 1]: the reprojected value must equal it wherever the previous pixel's
    # footprint cannot straddle x = 1; misses are unknown (NaN).
    view = _ground_view([0.3, 5.0, 8.0], [0.0, 0.0, 0.0])
    earlier = _ground_view([0.0, 5.5, 9.0], [0.5, 0.0, -0.5])
    found = previous_reference_at(_frame(view), _frame(earlier))
    x = view.gbuffer.position[..., 0]
    far_from_edge = np.abs(x - 1.0) > 0.5
    known = np.isfinite(found)
    assert known.mean() > 0.5
    np.testing.assert_array_equal(found[known & far_from_edge], (x > 1.0)[known & far_from_edge])
    assert np.all(np.isnan(found[~view.gbuffer.valid]))


def test_previous_reference_is_unknown_where_the_previous_camera_saw_another_triangle():
    view = _ground_view([0.0, 5.0, 8.0], [0.0, 0.0, 0.0])
    earlier = _ground_view([0.0, 5.0, 8.2], [0.0, 0.0, 0.0])
    occluded = earlier.gbuffer.triangle.copy()
    occluded[:, :10] = 9
    earlier = View(index=0, pose=earlier.pose, light_direction=LIGHT, reference=earlier.reference,
                   gbuffer=GBuffer(**{**earlier.gbuffer.__dict__, "triangle": occluded}))
    found = previous_reference_at(_frame(view), _frame(earlier))
    assert np.all(np.isnan(found[:, :8]))
    assert np.isfinite(found[:, 20:]).mean() > 0.9


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
