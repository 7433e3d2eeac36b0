"""The engines' box choices, each against its engine's formula written out: three.js's lerped slices, unrounded
diagonal, full-map centre snap and light camera; Bevy's full-map centre snap; DirectX CSM11's fit to cascade."""

from __future__ import annotations

import numpy as np
import pytest

from csmlab.camera import CameraPose
from csmlab.cascades import build_cascades
from csmlab.cascades.bounds import DEPTH_RANGE_METHODS
from csmlab.cascades.extent import extent_diagonal, extent_diagonal_unrounded
from csmlab.cascades.fit import slice_intervals
from csmlab.cascades.stabilize import SliceFootprint, snap_centre_full, stabilize_tight_snapped
from csmlab.geometry import frustum_slice_corners, light_basis_world_y, rotation_looking_at
from csmlab.light import direction_from_angles
from csmlab.settings import ShadowSettings


def test_cascade_lerp_ends_each_slice_where_csmfrustum_split_lerps_the_vertices():
    """CSMFrustum.split: cascade i's near vertices lerp(near_j, far_j, breaks[i - 1]) (the near plane for i = 0),
    its far vertices lerp(near_j, far_j, breaks[i]) (the far plane for the last); breaks = z_i / far."""
    near, far = 0.1, 400.0
    splits = np.array([near, 20.0, 90.0, far])
    breaks = splits[1:] / far
    ends = [near] + [near + b * (far - near) for b in breaks[:-1]] + [far]
    expected = np.column_stack([ends[:-1], ends[1:]])
    np.testing.assert_allclose(slice_intervals(splits, method="cascade_lerp"), expected, rtol=0, atol=1e-12)


def test_diagonal_unrounded_is_the_longer_of_threejs_two_diagonals():
    """CSM._updateShadowBounds: far vertex 0 to far vertex 2, or to near vertex 2 if that is farther."""
    pose = CameraPose(position=np.array([1.0, 2.0, 3.0]), orientation=rotation_looking_at(np.array([0.3, -0.2, -1.0])),
                      aspect=16 / 9, fov_y_deg=50.0, near=0.1, far=500.0)
    basis = np.eye(3)
    for z0, z1 in ((0.1, 9.7), (9.7, 60.3), (60.3, 400.0)):
        corners = frustum_slice_corners(position=pose.position, orientation=pose.orientation,
                                        fov_y_deg=pose.fov_y_deg, aspect=pose.aspect, z_near=z0, z_far=z1)
        point1 = corners[4]  # a far corner (-x, -y); its opposites are far corner 6 and near corner 2
        width = max(np.linalg.norm(point1 - corners[6]), np.linalg.norm(point1 - corners[2]))
        _, half = extent_diagonal_unrounded(pose=pose, basis=basis, z_near=z0, z_far=z1, corners=corners @ basis.T)
        assert 2.0 * half == pytest.approx(width, rel=1e-12)
        _, rounded = extent_diagonal(pose=pose, basis=basis, z_near=z0, z_far=z1, corners=corners @ basis.T)
        assert 2.0 * rounded == np.ceil(2.0 * half)


@pytest.mark.parametrize("resolution", [256, 2048])
def test_centre_full_floors_the_centre_to_texels_of_the_whole_map(resolution):
    """three.js update(): texelWidth = width / shadowMapSize, centre = floor(c / texelWidth) · texelWidth, the
    camera ±width / 2 about it; Bevy: cascade_diameter / cascade_texture_size, the centre floored alike."""
    rng = np.random.default_rng(2)
    for _ in range(50):
        radius = rng.uniform(1.0, 300.0)
        centre = rng.uniform(-5e3, 5e3, 2)
        fp = SliceFootprint(lo=centre - radius, hi=centre + radius, centre=centre, radius=radius,
                            frustum_extent=np.array([1.0, 1.0]))
        texel, origin = snap_centre_full(fp, resolution=resolution, margin=7)
        t = 2.0 * radius / resolution
        np.testing.assert_array_equal(texel, [t, t])
        snapped = np.floor(centre / t) * t
        np.testing.assert_allclose(origin * texel, snapped - 0.5 * 2.0 * radius, rtol=0, atol=1e-9 * radius)
        np.testing.assert_allclose((origin + resolution) * texel, snapped + radius, rtol=0, atol=1e-9 * radius)
        assert np.all(origin == np.round(origin))


def test_light_camera_spans_light_near_to_light_far_in_front_of_the_light():
    """CSM.update(): the light lightMargin toward the light from the slice's nearest corner; its camera
    near = lightNear, far = lightFar."""
    slice_depth = np.array([40.0, 55.5, 12.25, 80.0])
    near, far = DEPTH_RANGE_METHODS["light_camera"].box_depth(slice_depth, np.array([-1e4, 1e4]), pancake=200.0,
                                                             light_near=1.0, light_far=2000.0)
    assert (near, far) == (12.25 - 200.0 + 1.0, 12.25 - 200.0 + 2000.0)


def test_the_threejs_box_choices_build_world_locked_boxes_of_the_same_size_every_frame():
    """Translating the camera keeps each box's texel size bit-identical and moves it by whole texels."""
    d = direction_from_angles(elevation_deg=40.0, azimuth_deg=30.0)
    settings = ShadowSettings(cascades=3, resolution=2048, lambda_=0.5, shadow_distance=400.0, fit="cascade_lerp",
                              extent="diagonal_unrounded", snap="centre_full", light_basis="world_y",
                              depth_range="light_camera", pancake=200.0, depth_clamp=False)
    corners = np.array([[x, y, z] for x in (-1e3, 1e3) for y in (-1e3, 1e3) for z in (-1e3, 1e3)])
    sets = []
    for shift in (0.0, 0.37, 5.1):
        pose = CameraPose(position=np.array([shift, 1.7, -2.0 * shift]),
                          orientation=rotation_looking_at(np.array([0.4, -0.1, -1.0])), aspect=16 / 9, near=0.1,
                          far=400.0)
        sets.append(build_cascades(pose=pose, light_direction=d, scene_corners=corners, settings=settings))
    for a, b in zip(sets, sets[1:]):
        for ca, cb in zip(a.cascades, b.cascades):
            np.testing.assert_array_equal(ca.texel_size, cb.texel_size)
            assert np.all(cb.origin == np.round(cb.origin))


def test_tight_snapped_is_directx_fit_to_cascade_with_the_light_moved_in_texel_steps():
    """CascadedShadowsManager::InitFrame, FIT_TO_CASCADES: vBoarderOffset = (max − min) · 0.5 ·
    (m_iPCFBlurSize · 2 + 1) / m_iBufferSize; vWorldUnitsPerTexel = (max − min) / m_iBufferSize after padding;
    m_bMoveLightTexelSize: min = floor(min / t) · t, max = floor(max / t) · t."""
    rng = np.random.default_rng(4)
    blur, size = 3, 1024
    for _ in range(100):
        lo = rng.uniform(-3e3, 3e3, 2)
        hi = lo + rng.uniform(0.5, 400.0, 2)
        border = (hi - lo) * 0.5 * (blur * 2 + 1) / size
        dx_min, dx_max = lo - border, hi + border
        t = (dx_max - dx_min) / size
        dx_min, dx_max = np.floor(dx_min / t) * t, np.floor(dx_max / t) * t
        fp = SliceFootprint(lo=lo, hi=hi, centre=0.5 * (lo + hi), radius=1.0, frustum_extent=np.array([1.0, 1.0]))
        texel, origin = stabilize_tight_snapped(fp, resolution=size, margin=blur)
        np.testing.assert_allclose(texel, t, rtol=1e-12)
        np.testing.assert_allclose(origin * texel, dx_min, rtol=0, atol=1e-9 * np.abs(dx_min).max())
        np.testing.assert_allclose((origin + size) * texel, dx_max, rtol=0, atol=1e-6 * np.abs(dx_max).max())
        assert np.all(origin * texel <= lo) and np.all((origin + size) * texel >= hi)


def _clipped_polygon(polygon, axis, bound, keep_below):
    """Sutherland–Hodgman: the part of ``polygon`` (list of light-space points) on one side of ``p[axis] = bound``."""
    out = []
    for k, p in enumerate(polygon):
        q = polygon[(k + 1) % len(polygon)]
        p_in = p[axis] <= bound if keep_below else p[axis] >= bound
        q_in = q[axis] <= bound if keep_below else q[axis] >= bound
        if p_in:
            out.append(p)
        if p_in != q_in:
            out.append(p + (bound - p[axis]) / (q[axis] - p[axis]) * (q - p))
    return out


def compute_near_and_far(aabb_light, lo, hi):
    """DirectX CascadedShadowsManager::ComputeNearAndFar: the AABB's 12 triangles (iAABBTriIndexes) clipped
    against the ortho box's min/max x and y, near and far the min and max z of what is left."""
    indexes = [0, 1, 2, 1, 2, 3, 4, 5, 6, 5, 6, 7, 0, 2, 4, 2, 4, 6,
               1, 3, 5, 3, 5, 7, 0, 1, 4, 1, 4, 5, 2, 3, 6, 3, 6, 7]
    near, far = np.inf, -np.inf
    for t in range(12):
        polygon = [aabb_light[i] for i in indexes[3 * t:3 * t + 3]]
        for axis, bound, below in ((0, lo[0], False), (0, hi[0], True), (1, lo[1], False), (1, hi[1], True)):
            polygon = _clipped_polygon(polygon, axis, bound, below) if polygon else polygon
        for p in polygon:
            near, far = min(near, p[2]), max(far, p[2])
    return near, far


def test_scene_clipped_is_directx_compute_near_and_far():
    rng = np.random.default_rng(8)
    for _ in range(60):
        d = direction_from_angles(elevation_deg=rng.uniform(5, 89), azimuth_deg=rng.uniform(0, 360))
        basis = np.stack([*light_basis_world_y(d)[:2], d])
        lo_w = rng.uniform(-100, 0, 3)
        hi_w = lo_w + rng.uniform(5, 200, 3)
        # DirectX's vSceneAABBPointsLightSpace: corners in the order of its index list (x fastest, then y, then z).
        corners = np.array([[(hi_w if k & 1 else lo_w)[0], (hi_w if k & 2 else lo_w)[1], (hi_w if k & 4 else lo_w)[2]]
                            for k in range(8)])
        light = corners @ basis.T
        centre = light[:, :2].mean(axis=0) + rng.uniform(-60, 60, 2)
        half = rng.uniform(2, 80, 2)
        lo, hi = centre - half, centre + half
        expected = compute_near_and_far(light, lo, hi)
        got = DEPTH_RANGE_METHODS["scene_clipped"].box_depth(light[:, 2], light[:, 2], scene_corners=corners,
                                                             basis=basis, box_lo=lo, box_hi=hi)
        if np.isfinite(expected[0]):
            np.testing.assert_allclose(got, expected, rtol=0, atol=1e-9)
        else:
            assert got == (light[:, 2].min(), light[:, 2].max())
