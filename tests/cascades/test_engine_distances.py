"""Where each engine's shadow ends and where it switches cascade, written out from its source at two far planes.

Each formula below is the engine's, typed from its source (cited beside it), not from csmlab; the
cascades csmlab builds for the engine's preset must reproduce it with the camera's far plane at 400 m
(csmlab's default camera) and at 1000 m (a glTF camera's ``zfar``, a recorded path's far plane).
"""

from __future__ import annotations

import numpy as np
import pytest

from csmlab.camera import CameraPose
from csmlab.cascades import build_cascades
from csmlab.cascades.bounds import shadow_end
from csmlab.config import load_experiment
from csmlab.errors import InputError
from csmlab.geometry import rotation_looking_at
from csmlab.paths import read_path
from csmlab.scene.gltf_writer import GltfBuilder
from csmlab.settings import ShadowSettings

FARS = (400.0, 1000.0)
NEAR = 0.1
LIGHT = np.array([0.3, -0.8, 0.5])
SCENE = np.array([[x, y, z] for x in (-2e3, 2e3) for y in (-50, 50) for z in (-2e3, 2e3)], dtype=float)


def _pose(far: float, near: float = NEAR) -> CameraPose:
    return CameraPose(position=np.array([3.0, 2.0, -5.0]), orientation=rotation_looking_at([0.2, -0.1, -1.0]),
                      fov_y_deg=60.0, aspect=16 / 9, near=near, far=far)


def _preset(tmp_path, name: str, camera_far: float = 400.0, extra: str = "") -> ShadowSettings:
    path = tmp_path / "exp.toml"
    path.write_text(f'extends = ["engines/{name}"]\n[camera]\npath = "walk"\nfar = {camera_far}\n{extra}')
    (method,) = load_experiment(path).methods
    return method.settings


def _threejs_breaks(cascades: int, near: float, camera_far: float, max_far: float = 100000.0) -> np.ndarray:
    """CSM.js getBreaks, mode 'practical': far = min(camera.far, maxFar); breaks lerp uniform and log with 0.5."""
    far = min(camera_far, max_far)
    uniform = [(near + (far - near) * i / cascades) / far for i in range(1, cascades)]
    log = [(near * (far / near) ** (i / cascades)) / far for i in range(1, cascades)]
    return np.array([u + (lg - u) * 0.5 for u, lg in zip(uniform, log)] + [1.0])


@pytest.mark.parametrize("far", FARS)
def test_threejs_splits_are_its_breaks_times_the_camera_far_and_it_selects_at_breaks_times_far_less_near(
        tmp_path, far):
    settings = _preset(tmp_path, "threejs_csm", camera_far=far)
    cascades = build_cascades(pose=_pose(far), light_direction=LIGHT, scene_corners=SCENE, settings=settings)
    breaks = _threejs_breaks(3, NEAR, far)
    np.testing.assert_allclose(cascades.splits[1:], breaks * far, rtol=1e-12)
    # CSMShader.js: linearDepth = vViewPosition.z / (shadowFar - cameraNear) in [breaks[i-1], breaks[i]).
    np.testing.assert_allclose(cascades.switch_depths[1:], breaks * (far - NEAR), rtol=1e-12)
    # CSMFrustum.split: each slice lerped from the near plane, near + b (far - near).
    for c, b in zip(cascades.cascades[:-1], breaks[:-1]):
        assert c.slice_far == pytest.approx(NEAR + b * (far - NEAR), rel=1e-12)


def test_threejs_caps_the_camera_far_at_max_far(tmp_path):
    settings = _preset(tmp_path, "threejs_csm", camera_far=1000.0).replace(max_shadow_distance=600.0)
    cascades = build_cascades(pose=_pose(1000.0), light_direction=LIGHT, scene_corners=SCENE, settings=settings)
    np.testing.assert_allclose(cascades.splits[1:], _threejs_breaks(3, NEAR, 1000.0, 600.0) * 600.0, rtol=1e-12)


@pytest.mark.parametrize("far", FARS)
def test_mjp_cascades_are_fractions_of_its_clip_range(tmp_path, far):
    """MeshRenderer::RenderShadowMap: MinDistance + SplitDistance_i · MaxDistance of (FarClip − NearClip), from
    NearClip, MaxCascadeDistance 1.0 (AppSettings.cs)."""
    settings = _preset(tmp_path, "mjp", camera_far=far)
    cascades = build_cascades(pose=_pose(far), light_direction=LIGHT, scene_corners=SCENE, settings=settings)
    expected = NEAR + np.array([0.05, 0.15, 0.5, 1.0]) * (far - NEAR)
    np.testing.assert_allclose(cascades.splits[1:], expected, rtol=1e-12)


@pytest.mark.parametrize("far", FARS)
def test_an_engine_with_a_fixed_distance_stops_there_whatever_the_far_plane(tmp_path, far):
    """Godot 4: directional_shadow_max_distance 100, min with the camera far (renderer_scene_cull.cpp); its splits
    min_distance + s · (max − min_distance) with split offsets 0.1 / 0.2 / 0.5 (light_3d.cpp)."""
    settings = _preset(tmp_path, "godot4", camera_far=far)
    cascades = build_cascades(pose=_pose(far), light_direction=LIGHT, scene_corners=SCENE, settings=settings)
    np.testing.assert_allclose(cascades.splits[1:], NEAR + np.array([0.1, 0.2, 0.5, 1.0]) * (100.0 - NEAR),
                               rtol=1e-12)


def test_shadow_end_follows_each_frames_far_plane_visible_depth_and_cap():
    ends = {far: shadow_end(method="camera_far", shadow_distance=200.0, max_shadow_distance=0.0, camera_far=far)
            for far in FARS}
    assert ends == {400.0: 400.0, 1000.0: 1000.0}
    assert shadow_end(method="fixed", shadow_distance=200.0, max_shadow_distance=0.0, camera_far=1000.0) == 200.0
    assert shadow_end(method="fixed", shadow_distance=200.0, max_shadow_distance=0.0, camera_far=150.0) == 150.0
    assert shadow_end(method="camera_far", shadow_distance=200.0, max_shadow_distance=600.0, camera_far=1000.0) == 600.0
    # Stride: the farthest visible object, beyond any distance setting and beyond the camera far when the
    # held range has grown past it; the camera far while nothing is visible.
    assert shadow_end(method="farthest_visible", shadow_distance=200.0, max_shadow_distance=0.0, camera_far=400.0,
                      visible=(2.0, 380.0)) == 380.0
    assert shadow_end(method="farthest_visible", shadow_distance=200.0, max_shadow_distance=0.0, camera_far=400.0,
                      visible=(2.0, 418.0)) == 418.0
    assert shadow_end(method="farthest_visible", shadow_distance=200.0, max_shadow_distance=0.0, camera_far=400.0,
                      visible=None) == 400.0


def test_farthest_visible_cascades_reach_a_view_beyond_the_fixed_distance():
    settings = ShadowSettings(bounds="sdsm", shadow_distance_from="farthest_visible", split="practical",
                              lambda_=0.5)
    cascades = build_cascades(pose=_pose(400.0), light_direction=LIGHT, scene_corners=SCENE, settings=settings,
                              visible_depth=(1.5, 380.0))
    assert (cascades.splits[0], cascades.splits[-1]) == (1.5, 380.0)


def test_a_gltf_cameras_zfar_is_where_a_camera_far_shadow_ends(tmp_path):
    b = GltfBuilder()
    eye = b.add_node(name="eye", camera=b.add_camera(name="lens", yfov_rad=np.radians(50.0), znear=0.25, zfar=1000.0,
                                                     aspect=2.0))
    b.add_animation([(eye, "translation", [0.0, 1.0], [[0, 2, 0], [0, 2, -10]], "LINEAR")])
    path = read_path(b.save(tmp_path / "camera.glb", roots=[eye]), fps=4.0)
    settings = ShadowSettings(shadow_distance_from="camera_far", split="manual_range", splits=(0.05, 0.15, 0.5, 1.0))
    cascades = build_cascades(pose=path.pose(2), light_direction=LIGHT, scene_corners=SCENE, settings=settings)
    np.testing.assert_allclose(cascades.splits, 0.25 + np.array([0.0, 0.05, 0.15, 0.5, 1.0]) * (1000.0 - 0.25),
                               rtol=1e-12)


def test_the_toml_string_names_the_camera_far_and_a_number_stays_a_fixed_distance(tmp_path):
    assert _preset(tmp_path, "mjp").shadow_distance_from == "camera_far"
    fixed = _preset(tmp_path, "mjp", extra='[[methods]]\nname = "mjp"\nshadow_distance = 150.0\n')
    assert (fixed.shadow_distance_from, fixed.shadow_distance) == ("fixed", 150.0)


@pytest.mark.parametrize("text, field", [
    ('shadow_distance = "camera_farr"', "shadow.shadow_distance"),
    ('shadow_distance = "farthest_visible"', "shadow.shadow_distance_from"),
    ('shadow_distance = "camera_far"\nmax_shadow_distance = 0.05', "shadow.max_shadow_distance"),
])
def test_a_bad_shadow_distance_names_its_field(tmp_path, text, field):
    path = tmp_path / "exp.toml"
    path.write_text(f'[camera]\npath = "walk"\n[shadow]\n{text}\n')
    with pytest.raises(InputError) as caught:
        load_experiment(path)
    assert caught.value.field == field and caught.value.file == str(path)


def test_godots_normal_offset_moves_a_lit_ground_receiver_its_whole_bias_across_the_light():
    """scene_forward_clustered.glsl: base_normal_bias = N (1 − max(0, dot(light_dir, −N))), light_dir toward the
    light (light_storage.cpp: the light's +Z), then its part along light_dir removed; on flat ground under a 40°
    sun that is 2 texels · sin(50°) = 1.53 texels across the light (the depth unchanged)."""
    from csmlab.cascades import Cascade, CascadeSet
    from csmlab.geometry import light_basis
    from csmlab.texels import receiver_lookup

    elevation = np.radians(40.0)
    d = np.array([np.cos(elevation), -np.sin(elevation), 0.0])
    texel, bits = 0.5, 12
    cascade = Cascade(split_near=0.1, split_far=50.0, slice_near=0.1, slice_far=50.0, texel_size=np.array([texel] * 2),
                      origin=np.array([-64.0, -64.0]), resolution=256, depth_near=-1e3, depth_far=1e3)
    cs = CascadeSet(basis=light_basis(d), zref=-10.0, splits=np.array([0.1, 50.0]), cascades=(cascade,),
                    margin_texels=2)
    point, up = np.array([[1.0, 0.0, 2.0]]), np.array([[0.0, 1.0, 0.0]])
    args = dict(bits=bits, bias_constant=0.0, bias_slope=0.0, normal_scale="one_minus_cos_lateral")
    moved, depth, _ = receiver_lookup(cs, point, up, normal_offset=2.0, **args)
    still, still_depth, _ = receiver_lookup(cs, point, up, normal_offset=0.0, **args)
    lateral = np.hypot(*((moved - still)[0, 0] / 2.0**bits))
    assert lateral == pytest.approx(2.0 * np.sin(np.radians(50.0)), abs=2.0**-bits * 2)
    assert depth[0, 0] == still_depth[0, 0]


def test_godots_soft_shadow_levels_are_its_vogel_disks():
    """RendererSceneRenderRD::directional_soft_shadow_filter_set_quality: (samples, quality radius) per level;
    get_vogel_disk: r = sqrt(i + 0.5) / sqrt(n), θ = 2.4 i; soft_shadow_scale = shadow_blur · quality radius."""
    from csmlab.lookup_choices import godot_soft_shadow_fields, vogel_disk

    godot = {0: (0, 1.0), 1: (1, 1.5), 2: (4, 2.0), 3: (8, 2.0), 4: (16, 3.0), 5: (32, 4.0)}
    assert godot_soft_shadow_fields(0) == {"filter": "pcf_bilinear"}
    for quality, (samples, radius) in godot.items():
        if samples == 0:
            continue
        fields = godot_soft_shadow_fields(quality, blur=1.5)
        settings = ShadowSettings(**fields).validated()
        assert (settings.filter, settings.vogel_taps, settings.vogel_radius) == ("pcf_vogel", samples, radius * 1.5)
        i = np.arange(samples)
        kernel = np.column_stack([np.cos(i * 2.4), np.sin(i * 2.4)]) * (np.sqrt(i + 0.5) / np.sqrt(samples))[:, None]
        np.testing.assert_allclose(vogel_disk(settings.vogel_taps, angle=settings.vogel_angle), kernel, atol=1e-15)
    with pytest.raises(ValueError, match="soft_shadow_filter_quality"):
        godot_soft_shadow_fields(6)


@pytest.mark.parametrize("far", FARS)
def test_godots_blend_splits_mix_the_next_split_in_over_its_last_tenth(far):
    """scene_forward_clustered.glsl light_process with blend_splits: in split i, pssm_blend =
    smoothstep(z_i+1 − 0.1 z_i+1, z_i+1, depth_z), none in the last split."""
    from csmlab.cascades.fit import GODOT_BLEND_SPLITS, transition_bands

    settings = ShadowSettings(split="manual_range", splits=(0.1, 0.2, 0.5, 1.0), shadow_distance=far,
                              **GODOT_BLEND_SPLITS).validated()
    z = build_cascades(pose=_pose(far), light_direction=LIGHT, scene_corners=SCENE, settings=settings).splits
    select, start = transition_bands(z, blend_band=settings.blend_band, transition=settings.transition)
    np.testing.assert_array_equal(select, z)
    np.testing.assert_allclose(start[:-1], z[1:-1] - 0.1 * z[1:-1], rtol=1e-15)
    assert start[-1] == np.inf
    for i in range(3):
        depth = np.linspace(start[i], z[i + 1], 7)
        t = np.clip((depth - (z[i + 1] - z[i + 1] * 0.1)) / (z[i + 1] * 0.1), 0.0, 1.0)
        godot = t * t * (3.0 - 2.0 * t)
        w = (depth - start[i]) / (select[i + 1] - start[i])
        np.testing.assert_allclose(w * w * (3.0 - 2.0 * w), godot, atol=1e-12)    # csmlab's smoothstep curve


@pytest.mark.parametrize("far", FARS)
def test_unity_builtin_splits_are_the_stored_fractions_of_its_150_m(tmp_path, far):
    """QualitySettings.asset: shadowCascade4Split (0.06666667, 0.2, 0.46666667) of shadowDistance 150 (1/15, 3/15,
    7/15 in float32): the splits at 10 m, 30 m and 70 m to within float32's rounding, whatever the far plane."""
    settings = _preset(tmp_path, "unity_builtin_close", camera_far=far)
    cascades = build_cascades(pose=_pose(far), light_direction=LIGHT, scene_corners=SCENE, settings=settings)
    np.testing.assert_allclose(cascades.splits[1:], np.float32([1 / 15, 3 / 15, 7 / 15, 1.0]) * 150.0, rtol=1e-7)
    np.testing.assert_allclose(cascades.splits[1:], [10.0, 30.0, 70.0, 150.0], atol=1e-5)


@pytest.mark.parametrize("far", FARS)
def test_filament_ends_its_one_cascade_at_the_camera_far_plane(tmp_path, far):
    """ShadowMapManager: shadowFar = 0 keeps the camera's far plane (cameraInfo.zf replaced only when > 0)."""
    settings = _preset(tmp_path, "filament", camera_far=far)
    assert shadow_end(method=settings.shadow_distance_from, shadow_distance=settings.shadow_distance,
                      max_shadow_distance=settings.max_shadow_distance, camera_far=far) == far


@pytest.mark.parametrize("far", FARS)
def test_stride_splits_its_held_visible_range_uncapped(tmp_path, far):
    """LightDirectionalShadowMapRenderer.ComputeCascadeSplits (IsAutomatic): PSSM 0.5 over [minDistance,
    maxDistance] of the visible objects, no distance cap: a view reaching 0.95 of the far plane keeps it all."""
    settings = _preset(tmp_path, "stride", camera_far=far)
    visible = (2.0, 0.95 * far)
    cascades = build_cascades(pose=_pose(far), light_direction=LIGHT, scene_corners=SCENE, settings=settings,
                              visible_depth=visible)
    n, f = visible
    i = np.arange(1, 5) / 4
    stride = 0.5 * (n * (f / n) ** i) + 0.5 * (n + (f - n) * i)          # lerp(uniform, log, 1 − PSSMFactor 0.5)
    np.testing.assert_allclose(cascades.splits[1:], stride, rtol=1e-12)
