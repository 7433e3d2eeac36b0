"""Temporal anti-aliasing: the blend's variance in closed form, reprojection on a plane by hand, flicker before and
after."""

import numpy as np
import pytest

from csmlab.camera import CameraPose
from csmlab.config import TaaConfig
from csmlab.geometry import rotation_looking_at
from csmlab.kernels.taa import resolve_taa
from csmlab.metrics.taa import halton, halton_jitter, resolve_view, taa_summary
from csmlab.metrics.temporal import temporal_maps, temporal_summary
from csmlab.render import prepare_scene, render_shadow, render_view
from csmlab.scene import make_scene
from csmlab.settings import ShadowSettings

SUN = np.array([0.5, -0.7, 0.35])


def _plane_seen_head_on(width, height, *, eye, distance, fov_y_deg=60.0):
    """World points ``(H, W, 3)`` of the pixel centres of a camera at ``eye`` looking down −z at the plane
    z = eye_z − distance (identity rotation: right +x, up +y), worked out by hand, and their view depth."""
    tan_y = np.tan(np.radians(fov_y_deg) / 2.0)
    step_x, step_y = 2.0 * tan_y * (width / height) / width, 2.0 * tan_y / height
    rows, cols = np.indices((height, width), dtype=np.float64)
    x = (cols + 0.5 - width / 2.0) * step_x * distance
    y = (height / 2.0 - rows - 0.5) * step_y * distance
    points = np.stack([eye[0] + x, eye[1] + y, np.full(x.shape, eye[2] - distance)], axis=-1)
    return points, np.full((height, width), distance, dtype=np.float32), step_x


def test_halton_jitter_is_the_2_3_sequence_less_a_half():
    assert [halton(i, 2) for i in (1, 2, 3, 4)] == [0.5, 0.25, 0.75, 0.125]
    assert [halton(i, 3) for i in (1, 2, 3)] == pytest.approx([1 / 3, 2 / 3, 1 / 9])
    assert halton_jitter(0, phases=8) == pytest.approx((0.0, 1 / 3 - 0.5))
    assert halton_jitter(8, phases=8) == halton_jitter(0, phases=8)
    assert halton_jitter(5, phases=1) == halton_jitter(0, phases=1)


def test_exponential_blend_of_stationary_noise_reaches_alpha_over_two_minus_alpha(device):
    # A static camera (the history is its own pixel, no resampling), no clamp: y_t = (1 − α) y_{t−1} + α x_t
    # with x_t white noise of variance σ² has the stationary variance σ² α / (2 − α). 48 × 48 pixels,
    # frames 60..259 (past 20 time constants of α = 0.2): the sample variance of ~2300 pixels × 200
    # correlated frames is within 5 % (its standard error is ~1 %).
    width = height = 48
    alpha, sigma = 0.2, 0.5
    eye = np.zeros(3)
    points, depth, _ = _plane_seen_head_on(width, height, eye=eye, distance=10.0)
    rng = np.random.default_rng(7)
    history, outputs = None, []
    for t in range(260):
        noise = (0.5 + sigma * rng.standard_normal((height, width))).astype(np.float32)
        if history is None:
            history = noise
            continue
        history, _ = resolve_taa(noise, position=points, history=history, history_depth=depth, eye=eye,
                                 rotation=np.eye(3), fov_y_deg=60.0, aspect=1.0, jitter=(0.0, 0.0), alpha=alpha,
                                 clamp="none", gamma=1.0, depth_tolerance=0.05, device=device)
        if t >= 60:
            outputs.append(history.astype(np.float64))
    variance = np.var(np.stack(outputs))
    assert variance == pytest.approx(sigma ** 2 * alpha / (2.0 - alpha), rel=0.05)


def test_reprojection_of_a_translating_camera_over_a_plane_returns_the_history_exactly(device):
    # The camera steps sideways by exactly 3 pixels' width at the plane's distance: pixel (row, col) of
    # frame t sees frame t−1's point at (row, col + 3). Where that lies inside frame t−1's image the
    # history comes back bit for bit (a point within 1e-9 pixel of a centre reads that pixel alone);
    # where it lies outside, the point was not seen: disoccluded.
    width, height, distance, k = 40, 24, 10.0, 3
    before = np.array([1.0, -2.0, 5.0])
    _, depth, step_x = _plane_seen_head_on(width, height, eye=before, distance=distance)
    after = before + np.array([k * step_x * distance, 0.0, 0.0])
    points, _, _ = _plane_seen_head_on(width, height, eye=after, distance=distance)
    history = np.random.default_rng(3).random((height, width)).astype(np.float32)
    current = np.full((height, width), 0.5, dtype=np.float32)
    _, reprojected = resolve_taa(current, position=points, history=history, history_depth=depth, eye=before,
                                 rotation=np.eye(3), fov_y_deg=60.0, aspect=width / height, jitter=(0.0, 0.0),
                                 alpha=0.1, clamp="minmax", gamma=1.0, depth_tolerance=0.05,
                                 device=device)
    np.testing.assert_array_equal(reprojected[:, :width - k], history[:, k:])
    assert np.all(np.isnan(reprojected[:, width - k:]))


def test_a_point_hidden_in_the_previous_frame_drops_its_history(device):
    # Frame t−1 saw something 20 % nearer at every pixel: every tap fails the depth test, the output is
    # the current frame and nothing is reprojected.
    width, height = 16, 12
    eye = np.zeros(3)
    points, depth, _ = _plane_seen_head_on(width, height, eye=eye, distance=10.0)
    current = np.full((height, width), 0.25, dtype=np.float32)
    out, reprojected = resolve_taa(current, position=points, history=np.ones((height, width), np.float32),
                                   history_depth=depth * np.float32(0.8), eye=eye, rotation=np.eye(3),
                                   fov_y_deg=60.0, aspect=width / height, jitter=(0.0, 0.0), alpha=0.1,
                                   clamp="none", gamma=1.0, depth_tolerance=0.05, device=device)
    np.testing.assert_array_equal(out, current)
    assert np.all(np.isnan(reprojected))


def _static_camera_summaries(settings, *, frames=6, phases=1):
    """Before- and after-TAA temporal summaries of ``settings`` under a static camera over plane_box's shadow."""
    dscene = prepare_scene(make_scene("plane_box", plane_size=40.0, box_size=2.0))
    eye = np.array([6.0, 5.0, 8.0])
    pose = CameraPose(position=eye, orientation=rotation_looking_at(np.array([-1.0, 0.0, -1.5]) - eye),
                      aspect=96 / 54, far=100.0)
    taa = TaaConfig(enabled=True, phases=phases)
    before, after = [], []
    previous = previous_view = shadow = reference = None
    for i in range(frames):
        view = render_view(dscene, pose, SUN, width=96, height=54, index=i, jitter=halton_jitter(i, phases=phases))
        frame = render_shadow(dscene, view, settings)
        shadow = resolve_view(frame.shadow.lit, view, previous_view, shadow, taa=taa)
        reference = resolve_view(view.reference, view, previous_view, reference, taa=taa)
        if previous is not None:
            maps = temporal_maps(frame, previous)
            before.append(temporal_summary(maps))
            after.append(taa_summary(shadow, reference, maps))
        previous, previous_view = frame, view
    return ({key: np.array([s[key] for s in before]) for key in before[0]},
            {key: np.array([s[key] for s in after]) for key in after[0]})


SNAPPED = ShadowSettings(cascades=2, resolution=512, shadow_distance=30.0, stabilization="exact")


def test_a_static_camera_with_a_snapped_preset_gives_zero_flicker_after_taa():
    # One jitter phase: every frame samples the same points, so the resolve's input never changes and
    # neither does its output (with several phases the jitter's own residual is measured instead).
    before, after = _static_camera_summaries(SNAPPED)
    assert np.all(before["flicker_same"] == 0.0)
    assert np.all(after["flicker_taa"] == 0.0)
    assert np.all(after["flip_rate_taa"] == 0.0)


def test_a_per_pixel_and_frame_rotation_flickers_before_taa_and_much_less_after():
    # Godot's 4-tap disk (pcf_vogel) rotated per pixel and per frame (Bevy's temporal noise) under a static
    # camera: before TAA its same-cascade flicker is the rotation's (the unrotated disk's is 0); after TAA
    # the blend averages the rotations, leaving a fraction of it.
    disk = SNAPPED.replace(filter="pcf_vogel", vogel_taps=4, vogel_radius=2.0, vogel_angle=2.4)
    still_before, still_after = _static_camera_summaries(disk)
    turning_before, turning_after = _static_camera_summaries(disk.replace(poisson_rotation="pixel_frame"), frames=10)
    assert np.all(still_before["flicker_same"] == 0.0) and np.all(still_after["flicker_same_taa"] == 0.0)
    assert np.all(turning_before["flicker_same"] > 0.0)
    assert np.mean(turning_after["flicker_same_taa"][3:]) < 0.5 * np.mean(turning_before["flicker_same"][3:])


def test_pixel_taa_rotation_turns_per_frame_only_under_taa():
    from csmlab.filters import noise_frame

    settings = ShadowSettings(filter="pcf_vogel", poisson_rotation="pixel_taa")
    assert [noise_frame(settings, frame=f, taa=False) for f in (0, 5, 70)] == [0, 0, 0]
    assert [noise_frame(settings, frame=f, taa=True) for f in (0, 5, 70)] == [0, 5, 6]
    assert noise_frame(settings.replace(poisson_rotation="pixel_frame"), frame=70, taa=False) == 6
    assert noise_frame(settings.replace(poisson_rotation="pixel"), frame=70, taa=True) == 0


@pytest.mark.parametrize("text, field", [
    ("alpha = 0.0", "taa.alpha"),
    ("alpha = 1.5", "taa.alpha"),
    ("phases = 0", "taa.phases"),
    ('clamp = "aabb"', "taa.clamp"),
    ("gamma = -1.0", "taa.gamma"),
    ("depth_tolerance = 1.0", "taa.depth_tolerance"),
    ('enabled = "yes"', "taa.enabled"),
    ("history = 3", "taa.history"),
])
def test_bad_taa_values_exit_2_naming_the_field(tmp_path, text, field):
    import subprocess
    import sys

    experiment = tmp_path / "bad.toml"
    experiment.write_text('extends = ["scenes/plane_box", "methods/exact"]\n[camera]\npath = "dolly"\nframes = 2\n'
                          "[taa]\n" + ("" if text.startswith("enabled") else "enabled = true\n") + f"{text}\n",
                          encoding="utf-8")
    result = subprocess.run([sys.executable, "-m", "csmlab.cli", "show", str(experiment)], capture_output=True,
                            text=True)
    assert result.returncode == 2
    assert field in result.stderr and "bad.toml" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize("method", ["raster", "ray"])
def test_a_jittered_camera_hits_the_ground_where_the_moved_pixel_ray_meets_it(method, device):
    # plane_box's ground (y = 0) under a camera looking down at it: pixel (row, col) with jitter (x, y)
    # must hit the ground where the ray through (col + ½ + x, row + ½ + y) meets y = 0, in closed form;
    # the box hides a few pixels, which are left out.
    from csmlab.kernels.visibility import camera_hits, mesh_bvh

    scene = make_scene("plane_box", plane_size=200.0, box_size=2.0)
    bvh = mesh_bvh(scene.vertices, scene.triangles, device=device)
    eye = np.array([3.0, 12.0, 9.0])
    width, height, jitter = 40, 24, (0.3125, -0.4375)
    rotation = CameraPose(position=eye, orientation=rotation_looking_at(np.array([-2.0, 0.0, -6.0]) - eye),
                          aspect=width / height, far=400.0).rotation
    hits = camera_hits(bvh, position=eye, rotation=rotation, fov_y_deg=60.0, aspect=width / height, far=400.0,
                       width=width, height=height, method=method, jitter=jitter)
    tan_y = np.tan(np.radians(30.0))
    rows, cols = np.indices((height, width), dtype=np.float64)
    x = (cols + 0.5 + jitter[0] - width / 2.0) * (2.0 * tan_y * (width / height) / width)
    y = (height / 2.0 - rows - 0.5 - jitter[1]) * (2.0 * tan_y / height)
    direction = rotation[:, 0] * x[..., None] + rotation[:, 1] * y[..., None] - rotation[:, 2]
    ground = eye - direction * (eye[1] / direction[..., 1])[..., None]
    on_ground = np.abs(hits.position[..., 1]) < 1e-6
    assert on_ground.sum() > 0.9 * width * height
    np.testing.assert_allclose(hits.position[on_ground], ground[on_ground], atol=1e-4)
    unjittered = camera_hits(bvh, position=eye, rotation=rotation, fov_y_deg=60.0, aspect=width / height, far=400.0,
                             width=width, height=height, method=method)
    assert np.max(np.abs(unjittered.position[on_ground] - ground[on_ground])) > 1e-3


def test_a_moving_sun_is_not_counted_as_flicker_after_taa():
    # Static camera, the sun turning 1° per frame about the vertical: the shadow of plane_box's box really
    # moves, so S's output changes; with hard lookups at 4096² S follows R, R's output changes the same way,
    # and the error's change (the *_taa columns) is a fraction of S's own (measured: 0.20).
    dscene = prepare_scene(make_scene("plane_box", plane_size=40.0, box_size=2.0))
    eye = np.array([6.0, 5.0, 8.0])
    pose = CameraPose(position=eye, orientation=rotation_looking_at(np.array([-1.0, 0.0, -1.5]) - eye),
                      aspect=96 / 54, far=100.0)
    taa = TaaConfig(enabled=True, phases=1)
    settings = SNAPPED.replace(resolution=4096, filter="none")
    turn = [np.array([[np.cos(a), 0.0, np.sin(a)], [0.0, 1.0, 0.0], [-np.sin(a), 0.0, np.cos(a)]])
            for a in np.radians(np.arange(8.0))]
    sun = [r @ SUN for r in turn]
    own, error = [], []
    previous = previous_view = shadow = reference = None
    for i, light in enumerate(sun):
        view = render_view(dscene, pose, light, width=96, height=54, index=i, jitter=halton_jitter(i, phases=1),
                           previous_light_direction=sun[i - 1] if i else None)
        frame = render_shadow(dscene, view, settings)
        shadow = resolve_view(frame.shadow.lit, view, previous_view, shadow, taa=taa)
        reference = resolve_view(view.reference, view, previous_view, reference, taa=taa)
        if previous is not None:
            summary = taa_summary(shadow, reference, temporal_maps(frame, previous))
            error.append(summary["flicker_taa"])
            own.append(np.nanmean(np.abs(shadow.out.astype(np.float64) - shadow.reprojected)))
        previous, previous_view = frame, view
    assert np.mean(own) > 0.0
    assert np.mean(error) < 0.25 * np.mean(own)


def test_a_taa_run_does_not_depend_on_chunk_frames_and_fills_the_taa_columns_from_frame_1(tmp_path):
    # The history runs from frame 0: a run with [taa] is one unit of work whatever chunk_frames says, so
    # chunk_frames = 1 (which would restart a history at every frame) gives the same metrics.csv bytes.
    import csv

    from csmlab.config import load_experiment
    from csmlab.experiment import run_experiment

    outputs = []
    for chunk in (1, 5):
        path = tmp_path / f"chunk{chunk}.toml"
        path.write_text(f'extends = ["scenes/terrain", "paths/walk", "methods/exact", "methods/none"]\n'
                        f"chunk_frames = {chunk}\n[scene]\nresolution = 24\ntrees = 20\nring_trees = 20\n"
                        "[camera]\nframes = 4\nwidth = 32\nheight = 18\n[shadow]\nresolution = 64\n"
                        "[taa]\nenabled = true\n", encoding="utf-8")
        run_experiment(load_experiment(path), out_dir=tmp_path / f"run{chunk}")
        outputs.append((tmp_path / f"run{chunk}" / "metrics.csv").read_bytes())
    assert outputs[0] == outputs[1]
    rows = list(csv.DictReader(outputs[0].decode().splitlines()))
    assert [row["flicker_taa"] == "" for row in rows] == [True, False, False, False] * 2


@pytest.mark.parametrize("device, message", [("tpu", "device: expected 'cpu' or 'cuda'"),
                                             ("cuda:99", "device: .*'cuda:99'")])
def test_resolve_taa_refuses_a_device_warp_cannot_use_by_name(device, message):
    frame = np.zeros((2, 3), np.float32)
    with pytest.raises(ValueError, match=message):
        resolve_taa(frame, position=np.zeros((2, 3, 3)), history=frame, history_depth=frame, eye=np.zeros(3),
                    rotation=np.eye(3), fov_y_deg=60.0, aspect=1.5, jitter=(0.0, 0.0), alpha=0.1, clamp="none",
                    gamma=1.0, depth_tolerance=0.1, device=device)
