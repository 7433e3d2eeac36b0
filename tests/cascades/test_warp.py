"""LiSPSM (csmlab.cascades.warp): Wimmer et al.'s n_opt, the perspective's texel density, the ortho
fallback, and lookups, depth maps and ρ through the warped projection against independent oracles."""


import numpy as np
import pytest

from csmlab.camera import CameraPose
from csmlab.cascades import build_cascades
from csmlab.cascades.warp import lispsm_parameter, warp_lispsm, warped_texel_jacobian
from csmlab.geometry import frustum_slice_corners, light_basis, rotation_looking_at
from csmlab.light import direction_from_angles
from csmlab.metrics.aliasing import aliasing_maps
from csmlab.render import clipped_triangles, prepare_scene, render_frame, shadow_maps
from csmlab.settings import ShadowSettings
from csmlab.texels import receiver_lookup, texel_coordinates

from tests.test_render import BOXES, scene_of  # the end-to-end test scene

DOWN = np.array([0.0, -1.0, 0.0])
SCENE_CORNERS = np.array([[x, y, z] for x in (-200, 200) for y in (-5, 30) for z in (-200, 200)], dtype=float)


def _pose(eye, forward, *, near=0.1, far=60.0, aspect=16 / 9):
    return CameraPose(position=np.asarray(eye, float), orientation=rotation_looking_at(np.asarray(forward, float)),
                      aspect=aspect, near=near, far=far)


def _lispsm(pose, light, *, near_hint=1.0, far_hint=100.0, resolution=256, margin=2):
    basis = light_basis(light)
    corners = frustum_slice_corners(position=pose.position, orientation=pose.orientation, fov_y_deg=pose.fov_y_deg,
                                    aspect=pose.aspect, z_near=pose.near, z_far=pose.far) @ basis.T
    return basis, corners, warp_lispsm(basis=basis, volume=corners, pose=pose, resolution=resolution, margin=margin,
                                       z_near=pose.near, z_far=pose.far, near_hint=near_hint, far_hint=far_hint)


def test_n_opt_for_a_view_perpendicular_to_the_light_is_wimmers_zn_plus_sqrt_zn_zf():
    # LiSPSM (Wimmer et al. 2004, eq. for γ = 90°): n_opt = z_n + sqrt(z_n z_f) with no virtual planes
    # (Filament's hints at the camera's own near and far: dzn = dzf = 0).
    pose = _pose((0.0, 2.0, 0.0), (0.0, 0.0, -1.0), near=0.5, far=80.0)
    _, _, warp = _lispsm(pose, DOWN, near_hint=0.0, far_hint=1000.0)
    assert warp.n_opt == pytest.approx(0.5 + np.sqrt(0.5 * 80.0), rel=1e-9)


def test_n_opt_hand_worked_with_filaments_hints():
    # sin γ = 0.5, view depths 0.1..60, δ = 30 m: dzn = 0.9, dzf = 0 (60 < 100), z1 = 0.1 + 15,
    # vz0 = max(0.1, 0.1 + 0.9) = 1, vz1 = min(60, 60, 15.1) = 15.1 → n_opt0 = (0.1 + √15.1) / 0.5;
    # n_opt1 = 0.9 / (2 − 3 · 0.9 / 59.9).
    n = lispsm_parameter(sin_gamma=0.5, z_near=0.1, z_far=60.0, camera_near=0.1, camera_far=60.0, depth_extent=30.0,
                         near_hint=1.0, far_hint=100.0)
    assert n == pytest.approx(max((0.1 + np.sqrt(15.1)) / 0.5, 0.9 / (2.0 - 3.0 * 0.9 / 59.9)), rel=1e-12)


def test_n_opt_grows_without_bound_as_the_light_turns_along_the_view_then_falls_back_to_ortho():
    common = dict(z_near=0.1, z_far=60.0, camera_near=0.1, camera_far=60.0, depth_extent=30.0, near_hint=1.0,
                  far_hint=100.0)
    sines = np.array([0.8, 0.4, 0.1, 0.03])
    values = np.array([lispsm_parameter(sin_gamma=s, **common) for s in sines])
    assert np.all(np.diff(values) > 0)
    # n_opt ≥ (z0 + sqrt(vz0 · z0)) / sin γ (vz1 ≥ z0, vz0 = 1 m): it grows as 1 / sin γ.
    assert np.all(values * sines >= 0.1 + np.sqrt(0.1))
    assert lispsm_parameter(sin_gamma=0.019, **common) == np.inf   # Filament's epsilon 0.02
    # and where the virtual near plane passes 2/3 of the depth range (nopt1 would be infinite)
    assert lispsm_parameter(sin_gamma=0.8, **{**common, "near_hint": 45.0}) == np.inf


def test_light_along_the_view_gives_an_orthographic_map_of_the_slice():
    pose = _pose((3.0, 40.0, -2.0), (0.0, -1.0, 0.0))
    basis, corners, warp = _lispsm(pose, DOWN, resolution=128, margin=3)
    assert warp.n_opt == np.inf
    np.testing.assert_array_equal(warp.homography[2], [0.0, 0.0, 1.0])   # affine: no perspective
    texels, _ = warped_texels_of(warp, corners)
    np.testing.assert_allclose(texels.min(axis=0), [3.0, 3.0], atol=1e-9)
    np.testing.assert_allclose(texels.max(axis=0), [125.0, 125.0], atol=1e-9)


def warped_texels_of(warp, light):
    h = warp.homography @ np.column_stack([light[:, :2], np.ones(len(light))]).T
    return (h[:2] / h[2]).T, h[2]


def test_texel_density_falls_as_the_warp_perspective_predicts_along_and_across_the_view():
    # View ⟂ light: the warp axis is the camera's forward, and a ground point at view depth z lies
    # t = n_opt + (z − near) from the warp's eye. A perspective along the axis gives dv/dt ∝ 1/t²
    # and across it du/ds ∝ 1/t; an orthographic map has both constant.
    pose = _pose((0.0, 2.0, 0.0), (0.0, 0.0, -1.0), near=0.1, far=60.0)
    basis, _, warp = _lispsm(pose, DOWN)
    z = np.array([0.5, 2.0, 8.0, 20.0, 45.0])
    points = np.column_stack([np.zeros_like(z), np.zeros_like(z), -z])      # on the view axis, on the ground
    light_xy = points @ basis[:2].T
    forward_xy = basis[:2] @ pose.forward
    right_xy = np.array([forward_xy[1], -forward_xy[0]])
    jac = warped_texel_jacobian(warp.homography, light_xy)
    along = np.linalg.norm(jac @ forward_xy, axis=1)
    across = np.linalg.norm(jac @ right_xy, axis=1)
    t = warp.n_opt + (z - pose.near)
    np.testing.assert_allclose(along * t**2, (along * t**2)[0], rtol=1e-9)
    np.testing.assert_allclose(across * t, (across * t)[0], rtol=1e-9)


def _filament_chain(basis, corners, pose, *, n_opt, resolution, margin):
    """Filament's matrices in 4×4 (ShadowMap.cpp: L, translation(−p), warpFrustum, the focus F), then texels."""
    f_light = basis @ pose.forward
    vp = f_light[:2] / np.linalg.norm(f_light[:2])
    L = np.eye(4)
    L[0, :3] = np.cross(np.array([*vp, 0.0]), [0.0, 0.0, 1.0])
    L[1, :3] = [*vp, 0.0]
    rotated = (L[:3, :3] @ corners.T).T
    n, f = rotated[:, 1].min(), rotated[:, 1].max()
    eye = L[:3, :3] @ (basis @ pose.position)
    Wv = np.eye(4)
    Wv[:3, 3] = -np.array([eye[0], n - n_opt, 0.0])
    near, far = n_opt, n_opt + (f - n)
    Wp = np.array([[near, 0, 0, 0], [0, (far + near) / (far - near), 0, -2 * near * far / (far - near)],
                   [0, 0, near, 0], [0, 1, 0, 0]])
    chain = Wp @ Wv @ L

    def ndc(light):
        h = chain @ np.column_stack([light, np.ones(len(light))]).T
        return (h[:2] / h[3]).T

    lo, hi = ndc(corners).min(axis=0), ndc(corners).max(axis=0)
    return lambda light: margin + (ndc(light) - lo) / (hi - lo) * (resolution - 2 * margin)


def test_lookups_match_filaments_matrix_chain_projected_by_brute_force():
    light = direction_from_angles(elevation_deg=35.0, azimuth_deg=60.0)
    pose = _pose((4.0, 1.8, 6.0), (0.3, -0.2, -1.0), near=0.1, far=50.0)
    settings = ShadowSettings(cascades=2, resolution=512, stabilization="none", warp="lispsm", shadow_distance=50.0)
    cascades = build_cascades(pose=pose, light_direction=light, scene_corners=SCENE_CORNERS, settings=settings)
    rng = np.random.default_rng(3)
    for c, cascade in enumerate(cascades.cascades):
        corners = frustum_slice_corners(position=pose.position, orientation=pose.orientation,
                                        fov_y_deg=pose.fov_y_deg, aspect=pose.aspect, z_near=cascade.slice_near,
                                        z_far=cascade.slice_far)
        weights = rng.dirichlet(np.ones(8), size=200)
        points = weights @ corners                                           # inside the slice
        expected = _filament_chain(cascades.basis, corners @ cascades.basis.T, pose, n_opt=cascade.warp.n_opt,
                                   resolution=512, margin=settings.margin_texels)(points @ cascades.basis.T)
        np.testing.assert_allclose(texel_coordinates(cascades, c, points), expected, atol=1e-7)
        normals = np.tile([0.0, 1.0, 0.0], (len(points), 1))
        coords, depth, _ = receiver_lookup(cascades, points, normals, bits=8, normal_offset=0.0, bias_constant=0.0,
                                           bias_slope=0.0)
        np.testing.assert_allclose(coords[c] / 256.0, expected, atol=0.5 / 256.0 + 1e-9)
        np.testing.assert_allclose(depth[c], points @ cascades.basis[2] - cascades.zref, rtol=1e-6)


def test_warped_depth_map_holds_the_light_depth_of_the_surface_each_texel_ray_meets():
    # A ground plane and a floating slab: every texel centre's ray (the inverse homography) is cast
    # against both analytically; the map must hold the nearer's d·X − zref.
    slab = (-3.0, 3.0, 2.0, -8.0, -2.0)
    scene = scene_of([], plane_half=60.0, quads=[slab])
    dscene = prepare_scene(scene)
    light = direction_from_angles(elevation_deg=55.0, azimuth_deg=20.0)
    pose = _pose((0.0, 3.0, 4.0), (0.0, -0.3, -1.0), near=0.1, far=40.0)
    settings = ShadowSettings(cascades=1, resolution=128, stabilization="none", warp="lispsm", shadow_distance=40.0)
    cascades = build_cascades(pose=pose, light_direction=light, scene_corners=dscene.corners, settings=settings)
    depth = shadow_maps(dscene, cascades, settings).depth[0]
    assert np.isfinite(cascades.cascades[0].warp.n_opt)
    b = cascades.basis
    inverse = np.linalg.inv(cascades.cascades[0].homography)
    i, j = np.meshgrid(np.arange(128) + 0.5, np.arange(128) + 0.5)
    h = np.einsum("kl,lij->kij", inverse, np.stack([i, j, np.ones_like(i)]))
    x, y = h[0] / h[2], h[1] / h[2]
    base = x[..., None] * b[0] + y[..., None] * b[1]                        # the ray X = base + s·d
    expected = np.full(i.shape, np.inf)
    for height, inside in ((0.0, lambda p: np.all(np.abs(p[..., [0, 2]]) < 60.0, axis=-1)),
                           (slab[2], lambda p: (p[..., 0] > slab[0]) & (p[..., 0] < slab[1])
                            & (p[..., 2] > slab[3]) & (p[..., 2] < slab[4]))):
        s = (height - base[..., 1]) / b[2, 1]
        hit = base + s[..., None] * b[2]
        expected = np.where(inside(hit), np.minimum(expected, s - cascades.zref), expected)
    finite = np.isfinite(expected)
    # Texels whose ray passes within two texels of the slab's outline may go either way (coverage rule).
    s = (slab[2] - base[..., 1]) / b[2, 1]
    hit = base + s[..., None] * b[2]
    metres = np.linalg.norm(np.linalg.inv(warped_texel_jacobian(cascades.cascades[0].homography,
                                                                np.stack([x, y], axis=-1))), axis=-2).max(axis=-1)
    step = 2.0 * metres / abs(b[2, 1])

    def within(grow):
        return (hit[..., 0] > slab[0] - grow) & (hit[..., 0] < slab[1] + grow) & (hit[..., 2] > slab[3] - grow) \
            & (hit[..., 2] < slab[4] + grow)

    near_outline = within(step) & ~within(-step)
    check = finite & ~near_outline
    assert check.sum() > 0.8 * check.size
    # Vertices snap to 1/256 texel, which moves the plane by up to half a step times its depth change per texel.
    gy, gx = np.gradient(np.where(finite, expected, 0.0))
    tolerance = (np.abs(gx) + np.abs(gy)) / 256.0 + 4e-6 * np.abs(expected)
    assert np.all(np.abs(depth[check] - expected[check]) <= tolerance[check])


def test_clipping_keeps_exactly_the_part_of_each_triangle_on_the_kept_side():
    attributes = np.array([[0.0, 0.0], [2.0, 0.0], [0.0, 2.0]])
    triangle = np.array([[0, 1, 2]])

    def area(values, tris):
        p = values[tris][..., :2]
        u, v = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
        return 0.5 * np.abs(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]).sum()

    for column, sign, expected in ((0, 1.0, 0.5), (0, -1.0, 1.5)):
        values = np.column_stack([attributes, sign * attributes[:, column]])
        new, kept = clipped_triangles(values, triangle, column=2, threshold=sign * 1.0)
        assert area(new, kept) == pytest.approx(expected, rel=1e-12)
        assert np.all(new[kept.ravel(), 2] >= sign * 1.0 - 1e-12)
    _, kept = clipped_triangles(np.column_stack([attributes, [5.0, 5.0, 5.0]]), triangle, column=2, threshold=1.0)
    np.testing.assert_array_equal(kept, triangle)


def test_lispsm_raises_the_near_cascades_worst_texel_density_and_still_matches_the_ray_traced_shadow():
    # The LiSPSM paper's case: the view perpendicular to the light (a sun overhead, a level camera).
    # An orthographic map's texels per pixel fall as 1/z over each slice; the warp spends texels on
    # the near part, so that ρ on the ground is higher where it was lowest and more even over depth.
    scene = scene_of(BOXES)
    pose = _pose((6.0, 1.9, 3.5), (-4.0, 0.0, -5.5), far=60.0, aspect=160 / 90)
    out = {}
    for warp in ("none", "lispsm"):
        settings = ShadowSettings(cascades=2, resolution=256, stabilization="none", shadow_distance=60.0, warp=warp)
        frame = render_frame(scene, pose, DOWN, settings, width=160, height=90)
        g = frame.view.gbuffer
        ok = g.valid & (frame.shadow.cascade >= 0)
        agree = np.mean((frame.shadow.lit[ok] > 0.5) == (frame.view.reference[ok] > 0.5))
        assert agree > 0.99
        rho = aliasing_maps(frame).rho
        ground = g.valid & (g.normal[..., 1] > 0.99) & (frame.shadow.cascade == 0)
        out[warp] = np.percentile(rho[ground], [5.0, 50.0, 95.0])
    none, lispsm = out["none"], out["lispsm"]
    assert lispsm[0] > 1.3 * none[0] and lispsm[1] > none[1]
    assert lispsm[2] / lispsm[0] < 0.5 * (none[2] / none[0])


def test_lispsm_needs_a_tight_box():
    with pytest.raises(ValueError, match="warp"):
        ShadowSettings(stabilization="exact", warp="lispsm").validated()


def test_the_report_draws_a_warped_cascade_at_its_maps_corners():
    from csmlab.report.pixels import box_corners

    light = direction_from_angles(elevation_deg=35.0, azimuth_deg=60.0)
    pose = _pose((4.0, 1.8, 6.0), (0.3, -0.2, -1.0), near=0.1, far=50.0)
    settings = ShadowSettings(cascades=2, resolution=128, stabilization="none", warp="lispsm", shadow_distance=50.0)
    cascades = build_cascades(pose=pose, light_direction=light, scene_corners=SCENE_CORNERS, settings=settings)
    corners = box_corners(cascades)
    grid = ((np.arange(8)[:, None] >> np.arange(2)) & 1) * 128.0
    for c in range(2):
        np.testing.assert_allclose(texel_coordinates(cascades, c, corners[c]), grid, atol=1e-6)


@pytest.mark.parametrize("warp", ["none", "lispsm"])
def test_the_general_4x4_projection_gives_each_cascades_texels_and_light_depth(warp):
    # Ortho is the special case (w = 1); the warped one divides by w, its z / w times w the light depth.
    light = direction_from_angles(elevation_deg=35.0, azimuth_deg=60.0)
    pose = _pose((4.0, 1.8, 6.0), (0.3, -0.2, -1.0), near=0.1, far=50.0)
    settings = ShadowSettings(cascades=2, resolution=128, stabilization="none", warp=warp, shadow_distance=50.0)
    cascades = build_cascades(pose=pose, light_direction=light, scene_corners=SCENE_CORNERS, settings=settings)
    points = np.random.default_rng(5).uniform([-5, 0, -40], [10, 3, 0], size=(50, 3))
    for c in range(2):
        clip = np.column_stack([points, np.ones(50)]) @ cascades.projection(c).T
        if warp == "none":
            np.testing.assert_array_equal(clip[:, 3], 1.0)
        np.testing.assert_allclose(clip[:, :2] / clip[:, 3:], texel_coordinates(cascades, c, points), atol=1e-8)
        np.testing.assert_allclose(clip[:, 2], points @ cascades.basis[2] - cascades.zref, atol=1e-9)


@pytest.mark.parametrize("filter_name", ["pcf", "pcf_castano"])
def test_a_bare_lit_plane_stays_lit_through_a_warped_maps_filter_taps(filter_name):
    # Texels grow across a warped map: a tap one texel away must compare against the receiver
    # plane's depth there, from the homography's Jacobian at the receiver, or the plane shadows itself
    # (not the one texel size at the camera). The default slope bias
    # of one texel covers the plane's curvature in texel space (the homography is not linear).
    scene = scene_of([], plane_half=80.0)
    pose = _pose((0.0, 2.0, 0.0), (0.2, -0.35, -1.0), far=70.0, aspect=160 / 90)
    light = direction_from_angles(elevation_deg=35.0, azimuth_deg=50.0)
    settings = ShadowSettings(cascades=1, resolution=256, stabilization="none", warp="lispsm", shadow_distance=70.0,
                              filter=filter_name)
    frame = render_frame(scene, pose, light, settings, width=96, height=54)
    ok = frame.view.gbuffer.valid & (frame.shadow.cascade >= 0)
    assert np.isfinite(frame.maps.cascades.cascades[0].warp.n_opt) and ok.mean() > 0.5
    assert np.all(frame.shadow.lit[ok] == 1.0)
