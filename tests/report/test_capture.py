"""The report's per-frame captures: what they keep, checked against brute force and geometry."""

import csv
from dataclasses import dataclass

import numpy as np
import pytest

from csmlab.camera import CameraPose
from csmlab.cascades import build_cascades
from csmlab.frame import Frame, GBuffer, ShadowLookup, ShadowMaps, View
from csmlab.kernels.visibility import CameraHits
from csmlab.geometry import rotation_looking_at
from csmlab.light import direction_from_angles
from csmlab.report.capture import (
    ANIM_WIDTH,
    CASCADE_COLUMNS,
    capture_frame,
    decode_u8,
    default_snapshot_frames,
    read_npz,
    write_captures,
)
from csmlab.settings import ShadowSettings

LIGHT = direction_from_angles(elevation_deg=35.0, azimuth_deg=20.0)
SCENE_CORNERS = np.array([[x, y, z] for x in (-100, 100) for y in (0, 20) for z in (-100, 100)], dtype=float)


@dataclass(frozen=True)
class Measures:
    """Stands in for :class:`csmlab.metrics.FrameMeasures`: capture reads ``pixels`` only."""

    values: dict
    pixels: dict


def _frame(index, *, height=6, width=2 * ANIM_WIDTH + 5, seed=0, position=(3.0, 2.0, 1.0)):
    rng = np.random.default_rng(seed + index)
    pose = CameraPose(position=np.asarray(position, float) + [0.37 * index, 0, 0],
                      orientation=rotation_looking_at([0.2, -0.3, -1.0]), aspect=width / height, time_s=index / 30)
    settings = ShadowSettings(cascades=3, resolution=64, shadow_distance=50.0, stabilization="none")
    cascades = build_cascades(pose=pose, light_direction=LIGHT, scene_corners=SCENE_CORNERS, settings=settings)
    valid = rng.random((height, width)) > 0.2
    position = np.where(valid[..., None], rng.normal(size=(height, width, 3)) * 10, np.nan)
    gbuffer = GBuffer(hits=CameraHits(position=position, normal=np.zeros((height, width, 3), np.float32),
                                      triangle=np.where(valid, 1, -1).astype(np.int32),
                                      view_depth=np.where(valid, 5.0, np.inf).astype(np.float32)),
                      albedo=np.full((height, width, 3), 0.5, np.float32))
    lit = np.where(valid, rng.random((height, width)), np.nan).astype(np.float32)
    cascade = np.where(valid, rng.integers(0, 3, (height, width)), -1).astype(np.int8)
    view = View(index=index, pose=pose, light_direction=LIGHT, gbuffer=gbuffer,
                reference=np.where(valid, lit > 0.5, np.nan).astype(np.float32))
    frame = Frame(view=view, settings=settings,
                  maps=ShadowMaps(cascades=cascades, depth=np.zeros((3, 64, 64), np.float32), texels_rasterized=0),
                  shadow=ShadowLookup(lit=lit, cascade=cascade, blend=np.zeros((height, width), bool)))
    dS = np.where(valid & (rng.random((height, width)) > 0.3), rng.random((height, width)) ** 4, np.nan)
    pixels = {"dS": dS, "rho": rng.random((height, width)).astype(np.float32) * 3,
              "shaded": rng.random((height, width, 3)),
              "ref_diff": rng.integers(-1, 2, (height, width)).astype(np.int8)}
    return frame, Measures(values={}, pixels=pixels)


@pytest.mark.parametrize("n", [1, 2, 3, 7, 120])
def test_default_snapshot_frames_are_few_distinct_in_range_and_avoid_frame_0(n):
    frames = default_snapshot_frames(n)
    assert frames == sorted(set(frames))
    assert 1 <= len(frames) <= 3
    assert all(0 <= f < n for f in frames)
    if n > 1:
        assert 0 not in frames and n - 1 in frames


def test_default_snapshot_frames_refuses_an_empty_run():
    with pytest.raises(ValueError, match="n_frames"):
        default_snapshot_frames(0)


def test_animation_frames_are_block_mean_of_lit_and_block_max_of_change():
    frame, measures = _frame(1)
    record = capture_frame(frame, measures, snapshot=False)
    k = 3  # ceil((2 * 320 + 5) / 320)
    lit = frame.shadow.lit.astype(np.float64)
    dS = measures.pixels["dS"]
    h, w = lit.shape[0] // k, lit.shape[1] // k
    assert record.shadow.shape == record.dS.shape == (h, w)
    for i in range(h):
        for j in range(w):
            block = lit[i * k:(i + 1) * k, j * k:(j + 1) * k]
            change = dS[i * k:(i + 1) * k, j * k:(j + 1) * k]
            got_lit, got_change = decode_u8(record.shadow[i, j]), decode_u8(record.dS[i, j])
            if np.all(np.isnan(block)):
                assert np.isnan(got_lit)
            else:
                assert abs(got_lit - np.nanmean(block)) <= 0.5 / 254 + 1e-7
            if np.all(np.isnan(change)):
                assert np.isnan(got_change)
            else:
                assert abs(got_change - np.nanmax(change)) <= 0.5 / 254 + 1e-7


def test_cascade_rows_hold_each_cascades_texel_origin_extent_and_split():
    frame, measures = _frame(2)
    rows = capture_frame(frame, measures, snapshot=False).cascades
    assert rows.shape == (3, len(CASCADE_COLUMNS))
    for row, c in zip(rows, frame.maps.cascades.cascades):
        named = dict(zip(CASCADE_COLUMNS, row))
        assert (named["texel_x"], named["texel_y"]) == tuple(c.texel_size)
        assert (named["origin_x"], named["origin_y"]) == tuple(c.origin)
        np.testing.assert_allclose([named["extent_x"], named["extent_y"]], c.texel_size * 64, rtol=1e-15)
        assert (named["split_near"], named["split_far"]) == (c.split_near, c.split_far)


def test_snapshot_box_corners_are_the_cascade_boxes_in_light_space():
    frame, measures = _frame(1)
    snap = capture_frame(frame, measures, snapshot=True).snapshot
    cascades = frame.maps.cascades
    for corners, c in zip(snap["box_corners"], cascades.cascades):
        light = cascades.to_light(corners)
        expected = {(x, y, z) for x in (c.box_min[0], c.box_max[0]) for y in (c.box_min[1], c.box_max[1])
                    for z in (c.depth_near, c.depth_far)}
        for corner in light:
            assert min(np.max(np.abs(corner - np.array(e))) for e in expected) < 1e-9
        assert len({tuple(np.round(p, 6)) for p in light}) == 8


def test_snapshot_frustum_corners_lie_at_the_split_depths():
    frame, measures = _frame(1)
    snap = capture_frame(frame, measures, snapshot=True).snapshot
    for corners, c in zip(snap["frustum_corners"], frame.maps.cascades.cascades):
        depth = frame.view.pose.view_depth(corners)
        np.testing.assert_allclose(depth[:4], c.split_near, rtol=1e-12)
        np.testing.assert_allclose(depth[4:], c.split_far, rtol=1e-12)


def test_snapshot_points_are_the_visible_pixels_on_a_stride():
    frame, measures = _frame(1)
    snap = capture_frame(frame, measures, snapshot=True).snapshot
    valid = frame.view.gbuffer.valid[::4, ::4]
    assert snap["points"].shape == (int(valid.sum()), 3)
    np.testing.assert_array_equal(snap["points"], frame.view.gbuffer.position[::4, ::4][valid].astype(np.float32))
    np.testing.assert_array_equal(snap["point_cascade"], frame.shadow.cascade[::4, ::4][valid])


def _captures(method_seed, frames, snapshots=()):
    return [capture_frame(*_frame(i, seed=method_seed), snapshot=i in snapshots) for i in frames]


def _tree_bytes(root):
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def test_write_captures_gives_the_same_bytes_whatever_the_order_of_pairs(tmp_path):
    a, b = _captures(0, range(3), snapshots={1}), _captures(5, range(3), snapshots={2})
    write_captures(tmp_path / "one", method="exact", point="base", captures=a)
    write_captures(tmp_path / "one", method="none", point="base", captures=b)
    write_captures(tmp_path / "two", method="none", point="base", captures=b)
    write_captures(tmp_path / "two", method="exact", point="base", captures=a)
    one, two = _tree_bytes(tmp_path / "one"), _tree_bytes(tmp_path / "two")
    assert one == two
    assert set(one) == {"cascades.csv", "anim/exact__base.npz", "anim/none__base.npz",
                        "snapshots/exact__base__f1.npz", "snapshots/none__base__f2.npz"}


def test_write_captures_replaces_a_pairs_rows_and_stale_snapshots(tmp_path):
    write_captures(tmp_path, method="exact", point="resolution=512", captures=_captures(0, range(4), snapshots={3}))
    write_captures(tmp_path, method="none", point="resolution=512", captures=_captures(1, range(4)))
    again = _captures(2, range(2), snapshots={1})
    write_captures(tmp_path, method="exact", point="resolution=512", captures=again)
    with open(tmp_path / "cascades.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    exact = [r for r in rows if r["method"] == "exact"]
    assert sorted({int(r["frame"]) for r in exact}) == [0, 1]
    assert len([r for r in rows if r["method"] == "none"]) == 4 * 3
    assert [float(r["origin_x"]) for r in exact if r["cascade"] == "0"] == [c.cascades[0, 2] for c in again]
    assert sorted(p.name for p in (tmp_path / "snapshots").iterdir()) == ["exact__resolution=512__f1.npz"]


def test_anim_file_holds_the_frames_in_order_and_round_trips(tmp_path):
    captures = _captures(0, [2, 3, 5])
    write_captures(tmp_path, method="m/1", point="base", captures=captures)
    anim = read_npz(tmp_path / "anim" / "m_1__base.npz")
    assert anim["method"] == "m/1" and anim["point"] == "base"
    np.testing.assert_array_equal(anim["frame"], [2, 3, 5])
    np.testing.assert_array_equal(anim["shadow"], np.stack([c.shadow for c in captures]))
    np.testing.assert_array_equal(anim["dS"], np.stack([c.dS for c in captures]))


def test_write_captures_refuses_frames_out_of_order(tmp_path):
    with pytest.raises(ValueError, match="increasing frame numbers"):
        write_captures(tmp_path, method="exact", point="base", captures=_captures(0, [1, 0]))


def _blocky_image(height, width, seed):
    """Values in [0, 1] with NaN, ±inf and a whole undefined block in the top-left corner."""
    rng = np.random.default_rng(seed)
    values = rng.random((height, width)) ** 3
    values[rng.random((height, width)) < 0.3] = np.nan
    values[rng.random((height, width)) < 0.02] = np.inf
    values[rng.random((height, width)) < 0.02] = -np.inf
    values[:10, :10] = np.nan
    return values


@pytest.mark.parametrize("width", [ANIM_WIDTH, 2 * ANIM_WIDTH + 5, 7 * ANIM_WIDTH + 1, 8 * ANIM_WIDTH + 1])
def test_block_mean_and_max_equal_a_block_by_block_loop_over_the_defined_values(width):
    from csmlab.report.capture import _block_max, _block_mean

    values = _blocky_image(23, width, seed=width)
    k = -(-width // ANIM_WIDTH)
    mean, largest = _block_mean(values), _block_max(np.abs(values))
    assert mean.shape == largest.shape == (23 // k, width // k)
    for i in range(mean.shape[0]):
        for j in range(mean.shape[1]):
            block = values[i * k:(i + 1) * k, j * k:(j + 1) * k]
            defined = [float(v) for v in block.ravel() if np.isfinite(v)]
            if not defined:
                assert np.isnan(mean[i, j]) and np.isnan(largest[i, j])
                continue
            assert mean[i, j] == pytest.approx(sum(defined) / len(defined), rel=1e-14)
            assert largest[i, j] == max(abs(v) for v in defined)


@pytest.mark.parametrize("width", [2 * ANIM_WIDTH, 3 * ANIM_WIDTH, 8 * ANIM_WIDTH, 10 * ANIM_WIDTH + 3])
def test_block_mean_keeps_the_bits_of_a_numpy_reduction_over_the_blocks_axes(width):
    from csmlab.report.capture import _block_mean

    values = _blocky_image(17, width, seed=width)
    k = -(-width // ANIM_WIDTH)
    blocks = values[: 17 // k * k, : width // k * k].reshape(17 // k, k, width // k, k)
    defined = np.isfinite(blocks)
    count = defined.sum(axis=(1, 3))
    expected = np.where(count > 0, np.where(defined, blocks, 0.0).sum(axis=(1, 3)) / np.maximum(count, 1), np.nan)
    np.testing.assert_array_equal(_block_mean(values).view(np.int64), expected.view(np.int64))
