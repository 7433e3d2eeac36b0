"""Cascades on the host: what each stabilization method promises, over many camera poses."""

import numpy as np
import pytest

from csmlab.camera import CameraPose
from csmlab.cascades import build_cascades
from csmlab.cascades.cascade_set import radius_rounded_up
from csmlab.geometry import frustum_slice_corners, rotation_looking_at
from csmlab.light import direction_from_angles
from csmlab.settings import ShadowSettings

LIGHT = direction_from_angles(elevation_deg=40.0, azimuth_deg=30.0)
SCENE_CORNERS = np.array([[x, y, z] for x in (-200, 200) for y in (-5, 30) for z in (-200, 200)], dtype=float)


def _random_poses(seed, count, *, spread=50.0):
    rng = np.random.default_rng(seed)
    poses = []
    for _ in range(count):
        forward = rng.normal(size=3)
        q = rotation_looking_at(forward)
        poses.append(CameraPose(position=rng.uniform(-spread, spread, 3), orientation=q, aspect=16 / 9,
                                near=0.1, far=400.0))
    return poses


def _cascades(pose, **settings):
    return build_cascades(pose=pose, light_direction=LIGHT, scene_corners=SCENE_CORNERS,
                          settings=ShadowSettings(**settings))


def test_exact_extent_is_bit_identical_and_origin_moves_by_whole_texels():
    sets = [_cascades(p, stabilization="exact") for p in _random_poses(0, 100)]
    for c in range(4):
        texels = np.array([s.cascades[c].texel_size for s in sets])
        origins = np.array([s.cascades[c].origin for s in sets])
        assert np.all(texels == texels[0]), "extent must not change by a single bit"
        assert np.all(origins == np.round(origins)), "origin must be a whole texel index"
        steps = np.diff(origins, axis=0)
        assert np.all(steps == np.round(steps))


def _dolly(frames=200):
    forward = np.array([1.0, -0.1, -0.4])
    q = rotation_looking_at(forward)
    return [CameraPose(position=np.array([0.0, 2.0, 0.0]) + 0.35 * i * forward / np.linalg.norm(forward),
                       orientation=q, aspect=16 / 9) for i in range(frames)]


def _dolly_with_turn(frames=200):
    poses = []
    for i in range(frames):
        yaw = 0.6 * np.sin(i / 25.0)
        forward = np.array([np.sin(yaw), -0.15, -np.cos(yaw)])
        poses.append(CameraPose(position=np.array([0.2 * i, 1.7, -0.1 * i]), orientation=rotation_looking_at(forward),
                                aspect=16 / 9))
    return poses


@pytest.mark.parametrize("levels", [64, 16])
def test_quantized_extent_takes_few_values_never_below_the_tight_fit(levels):
    poses = _dolly_with_turn()
    quantized = [_cascades(p, stabilization="quantized", levels=levels) for p in poses]
    tight = [_cascades(p, stabilization="none") for p in poses]
    for c in range(4):
        extents = np.array([s.cascades[c].extent for s in quantized])
        assert len(np.unique(extents[:, 0])) <= levels and len(np.unique(extents[:, 1])) <= levels
        assert len(np.unique(extents[:, 0])) > 1, "a turning camera should use more than one level"
        origins = np.array([s.cascades[c].origin for s in quantized])
        assert np.all(origins == np.round(origins))
        margin = quantized[0].margin_texels
        for q, t in zip(quantized, tight):
            # The tight fit's slice extent (its box less the margins) never exceeds the quantized box's.
            slice_extent = t.cascades[c].texel_size * (t.cascades[c].resolution - 2 * margin)
            assert np.all(q.cascades[c].texel_size * (q.cascades[c].resolution - 2 * margin - 1)
                          >= slice_extent * (1 - 1e-12))


def test_none_follows_the_camera_continuously():
    sets = [_cascades(p, stabilization="none") for p in _dolly(20)]
    origins = np.array([s.cascades[1].origin for s in sets])
    assert np.any(origins != np.round(origins)), "an unstabilized origin is not snapped"
    assert len(np.unique(np.array([s.cascades[1].texel_size[0] for s in _map_rotating()]))) > 1


def _map_rotating():
    return [_cascades(CameraPose(position=[0, 2, 0], orientation=rotation_looking_at([np.sin(a), -0.2, -np.cos(a)]),
                                 aspect=16 / 9), stabilization="none") for a in np.linspace(0, 1, 10)]


@pytest.mark.parametrize("stabilization", ["none", "exact", "quantized"])
@pytest.mark.parametrize("fit", ["cascade", "scene"])
def test_every_slice_corner_lies_inside_its_box_with_the_filter_margin(stabilization, fit):
    for pose in _random_poses(3, 25):
        s = _cascades(pose, stabilization=stabilization, fit=fit, blend_band=0.1)
        for c in s.cascades:
            corners = frustum_slice_corners(position=pose.position, orientation=pose.orientation,
                                            fov_y_deg=pose.fov_y_deg, aspect=pose.aspect, z_near=c.slice_near,
                                            z_far=c.slice_far) @ s.basis.T
            margin = s.margin_texels * c.texel_size
            assert np.all(corners[:, :2] >= c.box_min + margin * (1 - 1e-9) - 1e-9)
            assert np.all(corners[:, :2] <= c.box_max - margin * (1 - 1e-9) + 1e-9)
            assert np.all(corners[:, 2] >= c.depth_near) and np.all(corners[:, 2] <= c.depth_far)


def test_scene_fit_captures_every_caster_in_the_box_depth_range():
    rng = np.random.default_rng(4)
    vertices = rng.uniform(-200, 200, size=(5000, 3)) * [1, 0.08, 1]
    corners = np.array([[x, y, z] for x in (-200, 200) for y in (-16, 16) for z in (-200, 200)], dtype=float)
    for pose in _random_poses(5, 10):
        s = build_cascades(pose=pose, light_direction=LIGHT, scene_corners=corners,
                           settings=ShadowSettings(fit="scene"))
        light = vertices @ s.basis.T
        for c in s.cascades:
            inside = np.all((light[:, :2] >= c.box_min) & (light[:, :2] <= c.box_max), axis=1)
            assert np.all(light[inside, 2] >= c.depth_near) and np.all(light[inside, 2] <= c.depth_far)


def _covers_from_the_camera_near_plane(pose, s, c: int) -> bool:
    """Cascade c's box holds the whole view frustum from the camera's near plane to its split's far end."""
    corners = frustum_slice_corners(position=pose.position, orientation=pose.orientation, fov_y_deg=pose.fov_y_deg,
                                    aspect=pose.aspect, z_near=pose.near, z_far=s.splits[c + 1]) @ s.basis.T
    box = s.cascades[c]
    return bool(np.all(corners[:, :2] >= box.box_min - 1e-9) and np.all(corners[:, :2] <= box.box_max + 1e-9))


@pytest.mark.parametrize("fit, stabilization", [("scene", "none"), ("scene", "exact"), ("scene", "quantized"),
                                                ("cascade", "none")])
def test_only_scene_fit_boxes_hold_the_frustum_from_the_camera_near_plane(fit, stabilization):
    # The oracle is the camera's frustum from its own near plane, not the slice the fit reports. A
    # tight "cascade" fit box covers only its own slice and must miss that somewhere among the poses
    # (exact's bounding sphere is wide enough to cover it by accident, so it proves nothing here).
    covered = [_covers_from_the_camera_near_plane(pose, s, c)
               for pose in _random_poses(6, 10)
               for s in [_cascades(pose, fit=fit, stabilization=stabilization)]
               for c in range(len(s.cascades))]
    assert all(covered) == (fit == "scene")


@pytest.mark.parametrize("direction", [(0, -1, 0), (0.0, -0.2, -1.0)])
def test_light_straight_down_or_along_the_view_is_valid(direction):
    pose = CameraPose(position=[10, 2, 5], orientation=rotation_looking_at((0, -0.2, -1)), aspect=16 / 9)
    s = build_cascades(pose=pose, light_direction=direction, scene_corners=SCENE_CORNERS,
                       settings=ShadowSettings(stabilization="exact"))
    for c in s.cascades:
        assert np.all(np.isfinite(c.texel_size)) and np.all(c.texel_size > 0)


def test_camera_far_from_the_origin_keeps_exact_extent_and_whole_texels():
    base = np.array([1e6, 30.0, -1e6])
    poses = [CameraPose(position=base + [0.37 * i, 0, 0.11 * i], orientation=rotation_looking_at((1, -0.3, 0.2 * i)),
                        aspect=16 / 9) for i in range(20)]
    corners = SCENE_CORNERS + base
    sets = [build_cascades(pose=p, light_direction=LIGHT, scene_corners=corners, settings=ShadowSettings())
            for p in poses]
    texels = np.array([s.cascades[0].texel_size for s in sets])
    origins = np.array([s.cascades[0].origin for s in sets])
    assert np.all(texels == texels[0]) and np.all(origins == np.round(origins))


def test_radius_is_rounded_up_to_a_stable_quantum():
    r = radius_rounded_up(13.3)
    assert r >= 13.3 and r - 13.3 < 13.3 * 2.0 ** -11
    assert radius_rounded_up(13.3 * (1 + 1e-15)) == r


@pytest.mark.parametrize("direction", [(0, 0, 0), (np.nan, -1, 0)])
def test_zero_or_nan_light_direction_is_bad_input(direction):
    with pytest.raises(ValueError, match="light direction"):
        _cascades_with(direction)


def _cascades_with(direction):
    pose = CameraPose(position=[0, 2, 0], orientation=(0, 0, 0, 1))
    return build_cascades(pose=pose, light_direction=direction, scene_corners=SCENE_CORNERS, settings=ShadowSettings())


@pytest.mark.parametrize("field, value", [("stabilization", "wobbly"), ("fit", "tight"), ("split", "pssm")])
def test_unknown_method_names_list_the_valid_ones(field, value):
    with pytest.raises(ValueError, match=field):
        _cascades(_random_poses(7, 1)[0], **{field: value})


def test_quantized_frustum_base_rounds_the_tight_extent_up_to_steps_of_the_whole_frustum():
    from csmlab.cascades.stabilize import SliceFootprint, stabilize_quantized

    # Hand-worked: the frustum's box is 100 × 80 m, 10 levels → steps of 10 × 8 m; the slice's tight
    # box is 21.7 × 16 m → rounded up to 30 × 16 m; 64 texels less 2 × 2 margin less 1 for the snap.
    def footprint(radius):
        return SliceFootprint(lo=np.array([3.2, -5.0]), hi=np.array([24.9, 11.0]), centre=np.zeros(2),
                              radius=radius, frustum_extent=np.array([100.0, 80.0]))

    texel, origin = stabilize_quantized(footprint(40.0), resolution=64, margin=2, levels=10, quantized_base="frustum")
    np.testing.assert_allclose(texel, np.array([30.0, 16.0]) / 59, rtol=1e-15)
    np.testing.assert_array_equal(origin, np.floor(np.array([3.2, -5.0]) / texel) - 2)
    # The frustum base ignores the bounding sphere; the sphere base (80 m → steps of 8 m) does not.
    again, _ = stabilize_quantized(footprint(55.0), resolution=64, margin=2, levels=10, quantized_base="frustum")
    np.testing.assert_array_equal(again, texel)
    sphere, _ = stabilize_quantized(footprint(40.0), resolution=64, margin=2, levels=10, quantized_base="sphere")
    np.testing.assert_allclose(sphere, np.array([24.0, 16.0]) / 59, rtol=1e-15)


def test_quantized_frustum_base_in_a_cascade_set_steps_by_the_frustum_box():
    poses = _dolly_with_turn(60)
    for pose in poses[::10]:
        s = _cascades(pose, stabilization="quantized", quantized_base="frustum", levels=16)
        frustum = frustum_slice_corners(position=pose.position, orientation=pose.orientation, fov_y_deg=pose.fov_y_deg,
                                        aspect=pose.aspect, z_near=pose.near, z_far=s.splits[-1]) @ s.basis.T
        step = (frustum[:, :2].max(axis=0) - frustum[:, :2].min(axis=0)) / 16
        for c in s.cascades:
            box_extent = c.texel_size * (c.resolution - 2 * s.margin_texels - 1)
            np.testing.assert_allclose(box_extent / step, np.round(box_extent / step), atol=1e-9)
