"""SDSM bounds, hysteresis, extents, snapping and depth ranges, each against a hand-worked case."""

import math

import numpy as np
import pytest

from csmlab.camera import CameraPose
from csmlab.cascades import build_cascades
from csmlab.cascades.bounds import held_depth_ranges, split_range, visible_depth_range
from csmlab.cascades.extent import extent_diagonal
from csmlab.cascades.stabilize import SliceFootprint, held_extents, snap_centre, snap_origin, snap_view, stabilize_none
from csmlab.geometry import frustum_slice_corners, light_basis, rotation_looking_at
from csmlab.settings import ShadowSettings

LIGHT = np.array([0.3, -1.0, 0.2])
SCENE = np.array([[x, y, z] for x in (-300, 300) for y in (-5, 30) for z in (-300, 300)], dtype=float)


def test_visible_depth_range_ignores_misses():
    z = np.array([[np.inf, 3.0], [7.5, np.nan]])
    assert visible_depth_range(z) == (3.0, 7.5)
    assert visible_depth_range(np.full((2, 2), np.inf)) is None


def test_held_range_grows_at_once_and_shrinks_only_past_the_threshold():
    # h = 0.2: the far end falls only below 0.8 × held; the near end rises only beyond held / 0.8.
    visible = [(2.0, 100.0), (2.1, 90.0), (2.0, 120.0), (2.4, 97.0), (2.6, 95.0), (1.5, 60.0)]
    held = held_depth_ranges(visible, hysteresis=0.2)
    np.testing.assert_array_equal(held, [(2.0, 100.0), (2.0, 100.0), (2.0, 120.0), (2.0, 120.0), (2.6, 95.0),
                                         (1.5, 60.0)])
    np.testing.assert_array_equal(held_depth_ranges(visible, hysteresis=0.0), visible)


def test_sdsm_splits_divide_the_visible_range_clamped_to_the_frustum():
    assert split_range(near=0.1, far=200.0, visible=(3.0, 80.0), method="sdsm") == (3.0, 80.0)
    assert split_range(near=0.1, far=200.0, visible=(0.01, 900.0), method="sdsm") == (0.1, 200.0)
    assert split_range(near=0.1, far=200.0, visible=(3.0, 80.0), method="frustum") == (0.1, 200.0)
    pose = CameraPose(position=np.zeros(3), orientation=rotation_looking_at([0.0, -0.2, -1.0]), aspect=16 / 9)
    cascades = build_cascades(pose=pose, light_direction=LIGHT, scene_corners=SCENE, visible_depth=(3.0, 80.0),
                              settings=ShadowSettings(bounds="sdsm", split="uniform", cascades=4))
    np.testing.assert_allclose(cascades.splits, [3.0, 22.25, 41.5, 60.75, 80.0])


def test_diagonal_extent_is_bevys_ceiled_largest_diagonal():
    # fov 90°, aspect 1: half-extents equal the depth. Slice [1, 3]: near (±1, ±1), far (±3, ±3).
    # Body diagonal sqrt(4² + 4² + 2²) = 6, far-plane diagonal 2·sqrt(18) ≈ 8.49 → ceil 9 m, radius 4.5.
    pose = CameraPose(position=np.array([5.0, 2.0, -3.0]), orientation=rotation_looking_at([1.0, -0.3, 0.2]),
                      fov_y_deg=90.0, aspect=1.0)
    basis = light_basis(LIGHT)
    corners = frustum_slice_corners(position=pose.position, orientation=pose.orientation, fov_y_deg=90.0, aspect=1.0,
                                    z_near=1.0, z_far=3.0) @ basis.T
    centre, radius = extent_diagonal(pose=pose, basis=basis, z_near=1.0, z_far=3.0, corners=corners)
    assert radius == 4.5
    np.testing.assert_allclose(centre, 0.5 * (corners[:, :2].min(axis=0) + corners[:, :2].max(axis=0)))


@pytest.mark.parametrize("snap", [snap_origin, snap_centre, snap_view])
@pytest.mark.parametrize("resolution", [64, 65])
def test_snapped_boxes_hold_the_sphere_inside_their_margins(snap, resolution):
    rng = np.random.default_rng(3)
    for _ in range(200):
        fp = SliceFootprint(lo=np.zeros(2), hi=np.zeros(2), centre=rng.uniform(-1e3, 1e3, 2), radius=7.25,
                            frustum_extent=np.zeros(2))
        texel, origin = snap(fp, resolution=resolution, margin=2)
        assert np.all(origin == np.round(origin))
        assert np.all((origin + 2) * texel <= fp.centre - fp.radius + 1e-9)
        assert np.all((origin + resolution - 2) * texel >= fp.centre + fp.radius - 1e-9)


def test_snap_centre_hand_worked():
    # R = 64, margin 2: h = 32, t = r / (h - m - 1) = 29 / 29 = 1 m; centre (10.4, -3.2) → k = (10, -4).
    fp = SliceFootprint(lo=np.zeros(2), hi=np.zeros(2), centre=np.array([10.4, -3.2]), radius=29.0,
                        frustum_extent=np.zeros(2))
    texel, origin = snap_centre(fp, resolution=64, margin=2)
    np.testing.assert_array_equal(texel, [1.0, 1.0])
    np.testing.assert_array_equal(origin, [10 - 32, -4 - 32])


def test_snap_view_hand_worked():
    # Stride ViewSnapping: centre to ceil(c / 4t) · 4t. R = 64, margin 2: h = 32, t = r / (h - m - 4) = 26 / 26
    # = 1 m; centre (10.4, -3.2) → k = (ceil(2.6) · 4, ceil(-0.8) · 4) = (12, 0) texels.
    fp = SliceFootprint(lo=np.zeros(2), hi=np.zeros(2), centre=np.array([10.4, -3.2]), radius=26.0,
                        frustum_extent=np.zeros(2))
    texel, origin = snap_view(fp, resolution=64, margin=2)
    np.testing.assert_array_equal(texel, [1.0, 1.0])
    np.testing.assert_array_equal(origin, [12 - 32, 0 - 32])


def test_held_extent_grows_at_once_and_shrinks_only_past_the_threshold():
    # h = 0.2 (shrink below 0.8 × held): 10 → 12 grows; 11 and 10.5 ≥ 9.6 hold 12; 8 < 9.6 falls to 8; 9 grows.
    tight = np.array([10.0, 12.0, 11.0, 10.5, 8.0, 9.0]).reshape(-1, 1, 1) * np.ones((1, 2, 2))
    held = held_extents(tight, hysteresis=0.2)
    np.testing.assert_array_equal(held[:, 0, 0], [10.0, 12.0, 12.0, 12.0, 8.0, 9.0])
    np.testing.assert_array_equal(held_extents(tight, hysteresis=0.0), tight)
    # Each axis and cascade on its own: y shrinking past the threshold does not release x.
    axes = np.array([[[10.0, 10.0]], [[9.0, 7.0]]])
    np.testing.assert_array_equal(held_extents(axes, hysteresis=0.2)[1, 0], [10.0, 7.0])


def test_tight_box_with_a_held_extent_keeps_the_slice_centred_at_the_held_texel_size():
    # Slice x ∈ [2, 6], y ∈ [0, 10]; held (8, 10) m; R = 20, margin 1 → t = (8/18, 10/18), box centred on (4, 5).
    fp = SliceFootprint(lo=np.array([2.0, 0.0]), hi=np.array([6.0, 10.0]), centre=np.zeros(2), radius=1.0,
                        frustum_extent=np.zeros(2))
    texel, origin = stabilize_none(fp, resolution=20, margin=1, held_extent=np.array([8.0, 10.0]))
    np.testing.assert_allclose(texel, [8.0 / 18, 10.0 / 18])
    np.testing.assert_allclose((origin + 1) * texel, [0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose((origin + 19) * texel, [8.0, 10.0])
    tight_texel, tight_origin = stabilize_none(fp, resolution=20, margin=1)
    np.testing.assert_allclose(tight_texel, [4.0 / 18, 10.0 / 18])
    np.testing.assert_allclose((tight_origin + 1) * tight_texel, [2.0, 0.0])


def test_slice_depth_range_takes_the_slice_less_the_pancake():
    pose = CameraPose(position=np.array([0.0, 2.0, 0.0]), orientation=rotation_looking_at([0.0, -0.3, -1.0]),
                      aspect=16 / 9)
    settings = ShadowSettings(depth_range="slice", pancake=20.0)
    cascades = build_cascades(pose=pose, light_direction=LIGHT, scene_corners=SCENE, settings=settings)
    basis = light_basis(LIGHT)
    for c in cascades.cascades:
        corners = frustum_slice_corners(position=pose.position, orientation=pose.orientation, fov_y_deg=pose.fov_y_deg,
                                        aspect=pose.aspect, z_near=c.slice_near, z_far=c.slice_far) @ basis.T
        assert c.depth_near == pytest.approx(corners[:, 2].min() - 20.0, abs=1e-9)
        assert c.depth_far == pytest.approx(corners[:, 2].max(), abs=1e-9)
    scene_wide = build_cascades(pose=pose, light_direction=LIGHT, scene_corners=SCENE, settings=ShadowSettings())
    assert all(c.depth_near == pytest.approx((SCENE @ basis.T)[:, 2].min()) for c in scene_wide.cascades)


def test_sphere_depth_range_is_the_centroid_sphere_less_pancake():
    from csmlab.cascades.bounds import DEPTH_RANGE_METHODS

    # A 2 × 2 × 4 m box of corners about (1, 2, 10): centroid depth 10, radius sqrt(1 + 1 + 4).
    corners = np.array([[1 + sx, 2 + sy, 10 + 2 * sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float)
    sphere = DEPTH_RANGE_METHODS["sphere"]
    near, far = sphere.box_depth(corners[:, 2], corners[:, 2], pancake=5.0, corners=corners)
    r = np.sqrt(6.0)
    assert (near, far) == pytest.approx((10 - r - 5.0, 10 + r), rel=1e-12)
    assert near <= corners[:, 2].min() and far >= corners[:, 2].max() and sphere.cuts_casters


def test_stepped_hold_is_strides_log_ceiling_steps():
    from csmlab.cascades.bounds import stepped_depth_ranges

    # LightDirectionalShadowMapRenderer.ComputeCascadeSplits: max = LogCeiling(max / current, 1.1 or 2.0) · current;
    # range stepped likewise against current max - current min; min = max - stepped range (at least near).
    def log_ceiling(v, b):
        return b ** math.ceil(math.log(v, b))

    visible = [(1.0, 100.0), (1.0, 104.0), (1.0, 120.0), (1.0, 60.0), (1.0, 40.0), (10.0, 50.0), (40.0, 50.0)]
    held = stepped_depth_ranges(visible, near=0.1)
    # By hand: 104 > 100 -> 1.1 · 100 = 110; 120 > 110 -> 121; 60 <= 121 / 2 -> 60.5; 40 > 60.5 / 2 -> held;
    # (40, 50): depth 20.5 <= (60.5 - 1) / 2 -> 60.5 - 59.5 / 2 = 30.75.
    np.testing.assert_allclose(held, [(1, 100), (1, 110), (1, 121), (1, 60.5), (1, 60.5), (1, 60.5), (30.75, 60.5)],
                               rtol=1e-12)
    lo, hi = visible[0]
    for (z0, z1), (h0, h1) in zip(visible[1:], held[1:]):
        hi = log_ceiling(z1 / hi, 1.1 if z1 > hi else 2.0) * hi
        depth, held_depth = hi - z0, hi - lo
        lo = max(hi - log_ceiling(depth / held_depth, 1.1 if depth > held_depth else 2.0) * held_depth, 0.1)
        assert (h0, h1) == pytest.approx((lo, hi), rel=1e-12)
