"""Texel-to-pixel ratio and utilization against analytic cases and hand counts."""

from dataclasses import replace

import numpy as np
import pytest

from csmlab.camera import CameraPose
from csmlab.geometry import light_basis, rotation_looking_at
from csmlab.light import direction_from_angles
from csmlab.metrics.aliasing import AliasingMaps, aliasing_maps, aliasing_summary, utilization
from csmlab.paths import make_path
from csmlab.render import prepare_scene, render_frame, render_shadow, render_view
from csmlab.scene import Scene, make_scene
from csmlab.settings import ShadowSettings

WIDTH, HEIGHT = 64, 48


def _plane(normal, *, size=400.0):
    """A square of side ``size`` through the origin with unit ``normal`` (two triangles)."""
    n = np.asarray(normal, dtype=float) / np.linalg.norm(normal)
    u = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 0.0, 1.0])
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    h = size / 2
    corners = np.array([-u - v, u - v, u + v, -u + v]) * h
    return Scene.from_triangles(corners, [[0, 1, 2], [0, 2, 3]])


def _pixel_rays(pose, width, height):
    """World directions ``(H, W, 3)`` of the rays through the pixel centres ``(col + ½, row + ½)``,
    one extra column and row included (the neighbours of the last pixel)."""
    tan_y = np.tan(np.radians(pose.fov_y_deg) / 2.0)
    col, row = np.meshgrid(np.arange(width + 1) + 0.5, np.arange(height + 1) + 0.5)
    view = np.stack([(2 * col / width - 1) * tan_y * pose.aspect, (1 - 2 * row / height) * tan_y,
                     -np.ones_like(col)], axis=-1)
    return view @ pose.rotation.T


def _closed_form_jacobian(pose, normal, basis, texel):
    """J per pixel from exact float64 ray–plane intersections: the plane is its own tangent plane."""
    n = np.asarray(normal, dtype=float) / np.linalg.norm(normal)
    rays = _pixel_rays(pose, WIDTH, HEIGHT)
    hit = pose.position - (pose.position @ n) / (rays @ n)[..., None] * rays
    du = hit[:-1, 1:] - hit[:-1, :-1]
    dv = hit[1:, :-1] - hit[:-1, :-1]
    to_texels = basis[:2] / texel[:, None]
    return np.stack([du @ to_texels.T, dv @ to_texels.T], axis=-1)


def test_rho_looking_straight_down_with_light_straight_down_is_texels_per_metre_over_pixels_per_metre():
    height_above = 7.0
    pose = CameraPose(position=[0.3, height_above, -0.2], orientation=rotation_looking_at([0.0, -1.0, 0.0]),
                      aspect=WIDTH / HEIGHT, far=100.0)
    settings = ShadowSettings(cascades=1, resolution=256, shadow_distance=20.0)
    frame = render_frame(_plane([0.0, 1.0, 0.0]), pose, [0.0, -1.0, 0.0], settings, width=WIDTH, height=HEIGHT)
    rho = aliasing_maps(frame).rho
    pixels_per_metre = HEIGHT / (2.0 * height_above * np.tan(np.radians(pose.fov_y_deg) / 2.0))
    texels_per_metre = 1.0 / frame.maps.cascades.cascades[0].texel_size[0]
    assert np.all(frame.shadow.cascade == 0)
    np.testing.assert_allclose(rho, texels_per_metre / pixels_per_metre, rtol=1e-3)


@pytest.mark.parametrize("tilt_deg", [35.0, 70.0])
def test_rho_and_sigma_min_on_a_tilted_plane_match_the_closed_form_jacobian(tilt_deg):
    tilt = np.radians(tilt_deg)
    normal = [0.0, np.cos(tilt), np.sin(tilt)]
    light = [0.3, -0.8, -0.5]
    pose = CameraPose(position=[2.0, 6.0, 9.0], orientation=rotation_looking_at([-2.0, -6.0, -9.0]),
                      aspect=WIDTH / HEIGHT, far=100.0)
    settings = ShadowSettings(cascades=1, resolution=512, shadow_distance=40.0)
    frame = render_frame(_plane(normal), pose, light, settings, width=WIDTH, height=HEIGHT)
    maps = aliasing_maps(frame)
    jac = _closed_form_jacobian(pose, normal, light_basis(light), frame.maps.cascades.cascades[0].texel_size)
    s = np.linalg.svd(jac, compute_uv=False)
    selected = maps.cascade == 0
    assert selected.mean() > 0.5
    np.testing.assert_allclose(maps.rho[selected], np.sqrt(s[..., 0] * s[..., 1])[selected], rtol=1e-3)
    np.testing.assert_allclose(maps.sigma_min[selected], s[..., 1][selected], rtol=1e-3)


def test_rho_doubles_exactly_when_the_cascade_resolution_doubles():
    # Doubling R over the same box halves the texel size; through the pipeline the margins of
    # stabilization make the box itself change, so the property is checked on the same boxes.
    pose = CameraPose(position=[2.0, 6.0, 9.0], orientation=rotation_looking_at([-2.0, -6.0, -9.0]),
                      aspect=WIDTH / HEIGHT)
    settings = ShadowSettings(cascades=3, resolution=128, shadow_distance=40.0)
    frame = render_frame(_plane([0.0, 1.0, 0.2]), pose, [0.3, -0.8, -0.5], settings, width=WIDTH, height=HEIGHT)
    cascades = frame.maps.cascades
    doubled = replace(cascades, cascades=tuple(
        replace(c, texel_size=c.texel_size / 2, origin=c.origin * 2, resolution=c.resolution * 2)
        for c in cascades.cascades))
    finer = replace(frame, maps=replace(frame.maps, cascades=doubled))
    rho, rho_finer = aliasing_maps(frame).rho, aliasing_maps(finer).rho
    assert len(np.unique(frame.shadow.cascade[frame.view.gbuffer.valid])) >= 2
    np.testing.assert_array_equal(rho_finer, 2.0 * rho)


def test_aliasing_summary_is_numpy_percentiles_overall_and_per_cascade():
    rng = np.random.default_rng(8)
    rho = rng.lognormal(0.0, 0.7, size=(30, 40)).astype(np.float32)
    cascade = rng.integers(-1, 2, size=(30, 40)).astype(np.int8)
    rho[cascade < 0] = np.nan
    summary = aliasing_summary(AliasingMaps(rho=rho, sigma_min=rho / 2, cascade=cascade), cascades=3)
    for suffix, subset in (("", cascade >= 0), ("_c0", cascade == 0), ("_c1", cascade == 1)):
        values = rho[subset].astype(np.float64)
        assert summary[f"rho_median{suffix}"] == np.median(values)
        assert summary[f"rho_p05{suffix}"] == np.percentile(values, 5)
        assert summary[f"rho_p95{suffix}"] == np.percentile(values, 95)
        assert summary[f"rho_frac_lt1{suffix}"] == np.count_nonzero(values < 1) / values.size
        assert summary[f"rho_frac_lt05{suffix}"] == np.count_nonzero(values < 0.5) / values.size
    assert summary["sigma_min_p05"] == np.percentile(rho[cascade >= 0].astype(np.float64) / 2, 5)
    assert np.isnan(summary["rho_median_c2"])


def test_utilization_of_a_plane_seen_straight_down_is_its_visible_area_in_texels():
    # Pixels (7 cm) much finer than texels (≈ 0.4 m): every texel that the visible rectangle
    # covers is looked up, so the count is the rectangle's area in texels up to its border.
    height_above = 5.0
    pose = CameraPose(position=[0.1, height_above, 0.3], orientation=rotation_looking_at([0.0, -1.0, 0.0]),
                      aspect=WIDTH / HEIGHT, far=100.0)
    settings = ShadowSettings(cascades=1, resolution=32, shadow_distance=10.0)
    frame = render_frame(_plane([0.0, 1.0, 0.0]), pose, [0.0, -1.0, 0.0], settings, width=WIDTH, height=HEIGHT)
    texel = frame.maps.cascades.cascades[0].texel_size[0]
    side_y = 2.0 * height_above * np.tan(np.radians(pose.fov_y_deg) / 2.0)
    side_x = side_y * pose.aspect
    count = utilization(frame)[0] * 32 * 32
    assert abs(count - side_x * side_y / texel**2) <= 2 * (side_x + side_y) / texel + 4


def test_utilization_of_exact_is_below_none_on_the_default_scene():
    # The default experiment's terrain, walk and 40° sun, scaled down; with more pixels than
    # texels, utilization is the share of each box that visible ground fills, and the bounding
    # sphere's box is the larger one.
    scene = make_scene("terrain", seed=1, size=200.0, resolution=32, trees=150, ring_trees=40)
    dscene = prepare_scene(scene)
    pose = make_path("walk", frames=1, seed=1, aspect=160 / 90).pose(0)
    view = render_view(dscene, pose, direction_from_angles(elevation_deg=40.0, azimuth_deg=30.0), width=160, height=90)
    shares = {method: utilization(render_shadow(dscene, view, ShadowSettings(cascades=4, resolution=64,
                                                                             stabilization=method)))
              for method in ("exact", "none")}
    for share in shares.values():
        assert np.all((share > 0.0) & (share <= 1.0))
    assert shares["exact"].mean() < shares["none"].mean()
