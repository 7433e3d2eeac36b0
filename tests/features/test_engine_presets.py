"""The engine and source-system presets: their defaults, and the temporal promises of the issue.

On a translating camera under a static light every preset that snaps a fixed-extent box gives
same-cascade flicker exactly 0.0 and every one that refits the box each frame more than 0; an SDSM
without hysteresis flickers more than with it; ``exact`` 10⁶ m from the origin stays at 0.0 in
float64 and does not in an engine's float32 cascade math. Tiny: 32×18 pixels, 64² maps, the
terrain cut down.
"""

from __future__ import annotations

import numpy as np
import pytest

from csmlab.cascades import tight_extents
from csmlab.config import CONFIGS_DIR, load_experiment
from csmlab.errors import InputError
from csmlab.experiment import run_experiment
from csmlab.fades import faded
from csmlab.render import clipped_casters

ENGINES = sorted(p.stem for p in (CONFIGS_DIR / "engines").glob("*.toml"))
SEEDS = sorted(p.stem for p in (CONFIGS_DIR / "seeds").glob("*.toml"))
PRESETS = [f"engines/{n}" for n in ENGINES] + [f"seeds/{n}" for n in SEEDS]

TINY = """
extends = [{extends}]

[scene]
kind = "terrain"
resolution = 24
trees = 60
ring_trees = 60
{scene}

[camera]
path = "dolly"
speed = 6.0
frames = {frames}
width = 48
height = 27
far = 400.0

[light]
elevation_deg = 40.0
azimuth_deg = 30.0

[shadow]
resolution = 64
{methods}
"""


def _run(tmp_path, *, extends=(), methods="", scene="", frames=4) -> dict:
    path = tmp_path / "exp.toml"
    path.write_text(TINY.format(extends=", ".join(f'"{e}"' for e in extends), methods=methods, scene=scene,
                                frames=frames))
    return run_experiment(load_experiment(path), out_dir=tmp_path / "out").summary["methods"]


def test_every_engine_and_seed_of_the_issue_has_a_preset():
    assert set(ENGINES) == {"ue5", "ue5_vsm", "unity_builtin_stable", "unity_builtin_close", "unity_urp", "unity_hdrp",
                            "godot4", "filament", "bevy", "threejs_csm", "stride", "mjp"}
    assert set(SEEDS) == {"nvidia_sdk", "ogldev49", "dx_csm11_cascade", "dx_csm11_scene", "dx_vsm11", "unigine_exact",
                          "unigine_quantized", "unigine_best_resolution"}


@pytest.mark.parametrize("preset, defaults", [
    # DirectionalLightComponent.h: DynamicShadowCascades 3, CascadeDistributionExponent 3.0,
    # CascadeTransitionFraction 0.1, ShadowDistanceFadeoutFraction 0.1, 20000 cm.
    ("engines/ue5", dict(cascades=3, split="exponent", distribution_exponent=3.0, blend_band=0.1,
                         transition="forward", fade_out=0.1,
                         shadow_distance=200.0, stabilization="exact")),
    # Unity QualitySettings: shadowCascade4Split (0.06666667, 0.2, 0.46666667), shadowDistance 150.
    # Built-in: Internal-ScreenSpaceShadows frag_pcf5x5 -> UnitySampleShadowmap_PCF5x5Tent; one 2×2 shadowmap;
    # getCascadeWeights_splitSpheres: the first split sphere holding the point.
    ("engines/unity_builtin_stable", dict(cascades=4, splits=(0.06666667, 0.2, 0.46666667, 1.0), shadow_distance=150.0,
                                          fade="radial",
                                          stabilization="exact", selection="sphere", filter="pcf_tent_bilinear",
                                          filter_size=7,
                                          storage="atlas", atlas_layout="2x2")),
    ("engines/unity_builtin_close", dict(cascades=4, splits=(0.06666667, 0.2, 0.46666667, 1.0), stabilization="none",
                                         filter="pcf_tent_bilinear", filter_size=7, storage="atlas")),
    # UniversalRenderPipelineAsset: m_ShadowDistance 50, m_Cascade4Split (0.067, 0.2, 0.467), m_CascadeBorder 0.2;
    # m_SoftShadowQuality Medium = SampleShadow_ComputeSamples_Tent_5x5; 2×2 atlas; k_ShadowmapBufferBits = 16,
    # each tile rendered with its slice's projection (RenderShadowSlice); ComputeCascadeIndex: split spheres.
    ("engines/unity_urp", dict(shadow_distance=50.0, splits=(0.067, 0.2, 0.467, 1.0), fade_out=0.2,
                               fade="squared_radial", filter="pcf_bilinear", selection="sphere", cull="back",
                               storage="atlas", atlas_layout="2x2", depth_format="unorm16",
                               depth_quantization="cascade")),
    # HDRP 10.10.1 DefaultSettingsVolumeProfile.asset: maxShadowDistance 150, splits 0.05/0.15/0.3;
    # HDShadowInitParameters Medium → SampleShadow_PCF_Tent_7x7, Depth32; the light's shadow resolution 512, 4 cascades
    # as 2×2 atlas tiles.
    # EvalShadow_GetSplitIndex: the first culling sphere holding the point; Lit's ShadowCaster pass culls back faces.
    ("engines/unity_hdrp", dict(cascades=4, splits=(0.05, 0.15, 0.3, 1.0), shadow_distance=150.0,
                                selection="sphere_dither", cascade_borders=(0.13333334, 0.06666666, 0.0, 0.0),
                                cull="back",
                                blend_band=0.0, fade_out=0.0, filter="pcf_tent_bilinear", filter_size=7,
                                storage="atlas", atlas_layout="2x2", depth_format="float32", resolution=512)),
    # DirectionalLight3D: splits 0.1/0.2/0.5, max distance 100, fade_start 0.8, pancake_size 20, blend off;
    # soft_shadow_filter_quality 2 (SOFT_LOW): directional_soft_shadow_samples = 4, quality radius 2.0, a
    # Vogel disk rotated per pixel (and per frame under TAA: taa_frame_count); directional_shadow/16_bits = true,
    # each split over its own z range; 4 splits as quadrants of one atlas; the light node's basis (a roll-free
    # node: a look-at with +Y up).
    ("engines/godot4", dict(split="manual_range", splits=(0.1, 0.2, 0.5, 1.0), shadow_distance=100.0, fade_out=0.2,
                            fade="smoothstep", extent="centroid", snap="nearest2", pancake=20.0,
                            depth_range="sphere", depth_clamp=True, blend_band=0.0, filter="pcf_vogel",
                            vogel_taps=4, vogel_radius=2.0, vogel_angle=2.4, vogel_scale="first_split",
                            poisson_rotation="pixel_taa", storage="atlas", light_basis="world_y",
                            depth_format="unorm16", depth_quantization="cascade")),
    # ShadowOptions: shadowCascades 1, practical splits lambda 0.5, stable false, lispsm true with
    # shadowNearHint 1 and shadowFarHint 100; focus_shadowcasters; ShadowType::PCF =
    # ShadowSample_PCF_Low, "hardware assisted PCF + 3x3 gaussian filter" (Castaño 2013).
    ("engines/filament", dict(cascades=1, split="practical", lambda_=0.5, stabilization="none",
                              shadow_distance_from="camera_far",
                              focus="scene", warp="lispsm", lispsm_near_hint=1.0, lispsm_far_hint=100.0,
                              filter="pcf_castano", filter_size=3)),
    # CascadeShadowConfigBuilder::default(): 4, 0.1, 150, first bound 10, overlap 0.2;
    # ShadowFilteringMethod::Gaussian = sample_shadow_map_castano_thirteen, weights (4 - 3s, 7, 1 + 3s) over 5 texels;
    # calculate_cascade: texel cascade_diameter / cascade_texture_size, the centre floored to it.
    ("engines/bevy", dict(cascades=4, split="geometric", first_cascade_far=10.0, shadow_distance=150.0,
                          blend_band=0.2, transition="far_bound", extent="diagonal", snap="centre_full",
                          outside="lit", filter="pcf_castano", filter_size=5)),
    # CSM.js: cascades 3, mode 'practical', lightMargin 200, lightNear 1, lightFar 2000, fade false; renderer
    # default PCFShadowMap; CSMFrustum.split lerps the slices; lookAt(+Y); unrounded diagonal, texel width / size.
    ("engines/threejs_csm", dict(cascades=3, split="practical", lambda_=0.5, pancake=200.0, fade_out=0.0,
                                 fit="cascade_lerp", depth_range="light_camera", light_near=1.0, light_far=2000.0,
                                 light_basis="world_y", snap="centre_full",
                                 extent="diagonal_unrounded", filter="pcf_vogel", vogel_taps=5, vogel_radius=1.0,
                                 poisson_rotation="pixel", outside="lit")),
    # LightDirectionalShadowMap: FourCascades, PSSMFactor 0.5, StabilizationMode ProjectionSnapping,
    # DepthRange.IsAutomatic true (held: DepthIncreaseThreshold 1.1, DepthDecreaseThreshold 2.0),
    # IsBlendingCascades true (overlap 0.2); PCF 5×5 in the shadow atlas.
    ("engines/stride", dict(cascades=4, lambda_=0.5, bounds="sdsm", hold="stepped", stabilization="exact",
                            shadow_distance_from="farthest_visible",
                            extent="centroid", snap="centre_nearest", blend_band=0.2, blend_curve="smoothstep",
                            depth_range="sphere", depth_clamp=True,
                            transition="backward", filter="pcf_castano", filter_size=5, outside="last",
                            storage="atlas")),
    # TheRealMJP/Shadows AppSettings.cs: SplitDistance0..3 0.05/0.15/0.5/1.0, StabilizeCascades = false,
    # ShadowMode FixedSizePCF with FixedFilterSize Filter2x2, DepthBufferFormat DB32Float.
    ("engines/mjp", dict(cascades=4, split="manual_range", splits=(0.05, 0.15, 0.5, 1.0),
                         shadow_distance_from="camera_far", max_shadow_distance=0.0,
                         depth_range="slice", depth_clamp=True, pancake=0.0, stabilization="none",
                         filter="pcf_bilinear", outside="last",
                         depth_format="float32")),
    # Seed 001: m_cascadeEnd = {zNear, 25.0, 90.0, zFar}; slice AABB, its own depth only.
    ("seeds/ogldev49", dict(cascades=3, splits=(25.0, 90.0, 200.0), stabilization="none", depth_range="slice",
                            depth_clamp=False)),
    ("seeds/nvidia_sdk", dict(split="practical", lambda_=0.75, stabilization="none")),
    # Seed 002/004: "create a kernel (such as a Gaussian) for an N × N grid ... The CascadedShadowMaps11 sample
    # uses this approach"; VarianceShadows11 "use[s] texture arrays instead of a texture atlas" (CSM11: an atlas).
    # CascadedShadowsManager::InitFrame FIT_TO_CASCADES with m_bMoveLightTexelSize: tight, padded, floored per frame.
    ("seeds/dx_csm11_cascade", dict(fit="cascade", selection="interval", stabilization="tight_snapped",
                                    filter="pcf_bilinear_box", filter_size=3,
                                    storage="atlas", atlas_layout="1x4")),
    ("seeds/dx_csm11_scene", dict(fit="scene", selection="map", blend_band=0.0, cascades=3,
                                  splits=(19.995, 59.985, 239.94), filter="pcf_bilinear_box",
                                  storage="atlas")),
    # Seed 003, 4.1.2: 64 levels; 4.1.1: "Packing CSMs into an atlas texture ... our project uses this strategy".
    ("seeds/unigine_quantized", dict(stabilization="quantized", levels=64, storage="atlas", atlas_layout="unigine")),
    ("seeds/unigine_exact", dict(stabilization="exact", storage="atlas", atlas_layout="unigine")),
    ("seeds/unigine_best_resolution", dict(selection="best_resolution", storage="atlas")),
])
def test_preset_holds_its_sources_defaults(tmp_path, preset, defaults):
    path = tmp_path / "exp.toml"
    path.write_text(f'extends = ["{preset}"]\n[camera]\npath = "walk"\n')
    (method,) = load_experiment(path).methods
    assert method.name == preset.split("/")[1]
    for field, value in defaults.items():
        assert getattr(method.settings, field) == value, field


@pytest.mark.slow
@pytest.mark.parametrize("preset", PRESETS)
def test_snapping_presets_are_flicker_free_and_refitting_ones_are_not(tmp_path, preset):
    """A translating camera (dolly) under a static light: same-cascade flicker 0.0 exactly iff the box is snapped.

    A filter rotated per screen pixel (Godot's disk) moves with the screen, not the world: that preset
    flickers through its filter alone, and without the rotation it is flicker-free like the others.
    An engine's float32 pipeline (``engine_precision``) rounds its matrix where the box lies: at the
    origin that moves a rare vertex or receiver by one sub-texel step (flicker well below that of the same
    pipeline refitted every frame: 1.2·10⁻⁴ for Unity built-in with its caster bias, against 2–3·10⁻³), and in
    csmlab's float64 math the same preset is flicker-free.
    """
    summary = _run(tmp_path, extends=[preset])
    (values,) = summary.values()
    (method,) = load_experiment(tmp_path / "exp.toml").methods
    if method.settings.stabilization == "none":
        assert values["flicker_same"] > 0.0
        return
    rotated = method.settings.filter in ("pcf_poisson", "pcf_vogel") and method.settings.poisson_rotation != "none"
    float32 = method.settings.engine_precision != "float64"
    if rotated:
        assert values["flicker_same"] > 0.0
    elif float32:
        # A rare sub-texel tip, not a swim: below half of what a box refitted every frame gives here (2–3·10⁻³).
        assert values["flicker_same"] < 1e-3
    else:
        assert values["flicker_same"] == 0.0
    changes = ('poisson_rotation = "none"\n' if rotated else "") + ('engine_precision = "float64"\n' if float32 else "")
    if changes:
        locked = _run(tmp_path, extends=[preset], methods=f'[[methods]]\nname = "{method.name}"\n' + changes)
        assert locked[method.name]["flicker_same"] == 0.0


def test_sdsm_without_hysteresis_flickers_more_than_with_it(tmp_path):
    methods = """
[[methods]]
name = "sdsm"
bounds = "sdsm"

[[methods]]
name = "sdsm_hysteresis"
bounds = "sdsm"
hysteresis = 0.3
"""
    summary = _run(tmp_path, methods=methods, frames=8)
    assert summary["sdsm"]["flicker_same"] > summary["sdsm_hysteresis"]["flicker_same"]


def test_extent_hysteresis_holds_the_tight_boxes_texel_size_on_a_turning_camera(tmp_path):
    """``none`` with and without extent hysteresis on an orbit: the held boxes change size on fewer frames.

    Both still swim (the origin follows the camera), so both flicker; the figures are in the run's summary.
    """
    methods = """
[[methods]]
name = "none"
stabilization = "none"

[[methods]]
name = "none_held"
stabilization = "none"
extent_hysteresis = 0.5
"""
    path = tmp_path / "exp.toml"
    orbit = TINY.format(extends="", methods=methods, scene="", frames=6)
    path.write_text(orbit.replace('path = "dolly"\nspeed = 6.0', 'path = "orbit"\nangular_speed_deg = 30.0'))
    experiment = load_experiment(path)
    summary = run_experiment(experiment, out_dir=tmp_path / "out").summary["methods"]
    assert summary["none"]["flicker_same"] > 0.0 and summary["none_held"]["flicker_same"] > 0.0

    from csmlab.experiment import _held_extents, build_workload

    workload = build_workload(experiment)
    variants = tuple(experiment.variants())
    held = _held_extents(workload, variants, {}, device="cpu")[("none_held", variants[1].point)]
    tight = np.array([tight_extents(pose=workload.path.pose(i), light_direction=workload.light.direction(i),
                                    settings=variants[1].settings) for i in range(len(workload.path))])
    assert np.all(held >= tight)
    changes = lambda e: int(np.count_nonzero(np.any(np.diff(e, axis=0) != 0.0, axis=2)))  # noqa: E731
    assert changes(held) < changes(tight)


def test_extent_hysteresis_on_a_snapped_box_exits_2_naming_the_field(tmp_path):
    path = tmp_path / "exp.toml"
    path.write_text('[[methods]]\nname = "held"\nstabilization = "exact"\nextent_hysteresis = 0.3\n')
    with pytest.raises(InputError, match="extent_hysteresis"):
        load_experiment(path)


def test_float32_engine_math_swims_far_from_the_origin_and_float64_does_not(tmp_path):
    methods = """
[[methods]]
name = "exact"
stabilization = "exact"

[[methods]]
name = "exact_float32"
stabilization = "exact"
engine_precision = "float32"
"""
    summary = _run(tmp_path, methods=methods, scene="offset = [1000000.0, 0.0, 1000000.0]")
    assert summary["exact"]["flicker_same"] == 0.0
    assert summary["exact_float32"]["flicker_same"] > 0.0


def test_without_pancaking_casters_wholly_in_front_are_clipped():
    depth = np.array([-5.0, -4.0, -3.0, 1.0, 2.0, 3.0])
    triangles = np.array([[0, 1, 2], [2, 3, 4], [3, 4, 5]])
    np.testing.assert_array_equal(clipped_casters(depth, triangles, near=0.0), triangles[1:])


def test_pancaking_flattens_casters_in_front_onto_the_near_side():
    """A slice box with clamping stores max(z, near): a caster far in front still shadows, at the near side."""
    from csmlab.camera import CameraPose
    from csmlab.geometry import rotation_looking_at
    from csmlab.render import render_frame
    from csmlab.scene import make_scene
    from csmlab.settings import ShadowSettings

    scene = make_scene("plane_box")
    pose = CameraPose(position=np.array([0.0, 6.0, 8.0]), orientation=rotation_looking_at([0.0, -0.6, -1.0]),
                      aspect=16 / 9)
    light = np.array([0.2, -1.0, 0.1])
    common = dict(cascades=2, resolution=64, shadow_distance=30.0, filter="none")
    kw = dict(width=32, height=18)
    scene_wide = render_frame(scene, pose, light, ShadowSettings(**common), **kw)
    clamped = render_frame(scene, pose, light, ShadowSettings(depth_range="slice", depth_clamp=True, **common), **kw)
    for c, cascade in enumerate(clamped.maps.cascades.cascades):
        near = np.float32(cascade.depth_near - clamped.maps.cascades.zref)
        assert np.all(clamped.maps.depth[c] >= near)
        np.testing.assert_array_equal(clamped.maps.depth[c], np.maximum(scene_wide.maps.depth[c], near))


def test_fade_out_reaches_lit_at_the_shadow_distance():
    # far 100, fade 0.2: weight 0 up to 80 m, 0.5 at 90 m, 1 at 100 m.
    lit, fading = faded(np.zeros(4, dtype=np.float32), np.array([50.0, 80.0, 90.0, 100.0]), far=100.0, fade_out=0.2)
    np.testing.assert_allclose(lit, [0.0, 0.0, 0.5, 1.0])
    np.testing.assert_array_equal(fading, [False, False, True, True])


@pytest.mark.slow
def test_report_draws_methods_with_different_cascade_counts(tmp_path):
    """Filament's one cascade beside Unreal's three and the base four: every figure is written."""
    from csmlab.report import write_report

    _run(tmp_path, extends=["engines/filament", "engines/ue5", "methods/exact"], frames=2)
    index = write_report(tmp_path / "out").page
    assert index.is_file() and any((tmp_path / "out" / "figures").glob("*stabilization*"))


# --- Each preset's cascades against its engine's formula, written out here from the engine's source ---
# A hand-worked pose: at (3, 2, -5) looking down -z (identity orientation), fov 60°, 16:9, near 0.1,
# far 400; the sun of lights/sun_40. Light space is csmlab's basis (a separate choice).

POSE_AT = np.array([3.0, 2.0, -5.0])
SUN = np.array([-0.383, -0.643, -0.663])


def _preset(preset: str, tmp_path):
    from csmlab.camera import CameraPose

    path = tmp_path / "exp.toml"
    path.write_text(f'extends = ["{preset}"]\n[camera]\npath = "walk"\n')
    (method,) = load_experiment(path).methods
    pose = CameraPose(position=POSE_AT, orientation=[0.0, 0.0, 0.0, 1.0], fov_y_deg=60.0, aspect=16.0 / 9.0,
                      near=0.1, far=400.0)
    return method.settings, pose


def _build(settings, pose, **kw):
    from csmlab.cascades import build_cascades

    scene = np.array([[x, y, z] for x in (-300.0, 300.0) for y in (-20.0, 60.0) for z in (-300.0, 300.0)])
    return build_cascades(pose=pose, light_direction=SUN, scene_corners=scene, settings=settings, **kw)


def _corners(z0: float, z1: float) -> np.ndarray:
    """The 8 world corners of the view slice [z0, z1] of the hand-worked pose."""
    ty = np.tan(np.radians(30.0))
    tx = ty * 16.0 / 9.0
    return np.array([POSE_AT + [sx * z * tx, sy * z * ty, -z] for z in (z0, z1) for sx in (-1, 1) for sy in (-1, 1)])


def _blend_weights(settings, cascades, depths) -> tuple[np.ndarray, np.ndarray]:
    """The selection kernel's cascade and next-cascade weight at view ``depths``, every box holding the point."""
    from csmlab.cascades.fit import BLEND_CURVES, transition_bands
    from csmlab.kernels.shadow import select_cascades

    count, n, bits = len(cascades), len(depths), 8
    select, start = transition_bands(cascades.splits, blend_band=settings.blend_band, transition=settings.transition)
    chosen, weight, _ = select_cascades(
        np.full((count, 16, 16), np.inf, np.float32), np.full((count, n, 2), 8 << bits, np.int64),
        np.zeros((count, n), np.float32), np.asarray(depths, np.float64), splits=select,
        texel_area=np.ones(count), selection="interval", radius=1, margin=1, blend_band=settings.blend_band,
        band_start=start, blend_curve=BLEND_CURVES[settings.blend_curve][0], bits=bits)
    return chosen, weight


def test_godot4_splits_sphere_snap_and_fade_are_godots(tmp_path):
    settings, pose = _preset("engines/godot4", tmp_path)
    cs = _build(settings, pose)
    # renderer_scene_cull.cpp, _light_instance_setup_directional_shadow: min_distance = z_near,
    # max_distance = min(shadow max distance, z_far), range = max - min;
    # distances[i + 1] = min_distance + split_offset_i * range.
    near, far = 0.1, min(100.0, 400.0)
    distances = [near] + [near + s * (far - near) for s in (0.1, 0.2, 0.5)] + [far]
    np.testing.assert_allclose(cs.splits, distances, rtol=1e-12)
    np.testing.assert_allclose(cs.splits[1:4], [10.09, 20.08, 50.05])
    margin = cs.margin_texels
    for i, cascade in enumerate(cs.cascades):
        # blend_splits = false: split i's frustum is [distances[i], distances[i + 1]].
        endpoints = _corners(distances[i], distances[i + 1])
        center = endpoints.sum(axis=0) / 8.0                                   # center /= 8.0
        radius = max(np.linalg.norm(e - center) for e in endpoints)
        # Godot's map of T texels; csmlab lays the filter's margin outside Godot's box: T = R - 2m.
        size = cascade.resolution - 2 * margin
        radius *= size / (size - 2.0)                                          # add a texel by each side
        texel = radius * 2.0 / size                                            # shadow_texel_size
        unit = radius * 4.0 / size
        def snapped(v, s):                                                     # Math::snapped
            return np.floor(v / s + 0.5) * s

        x_min = np.array([snapped(axis @ center - radius, unit) for axis in cs.basis[:2]])
        np.testing.assert_allclose(cascade.texel_size, [texel, texel], rtol=2.0 ** -11)
        # The same edge on the same 2-texel grid (csmlab's radius is rounded up by < 2^-12, its texel with it).
        np.testing.assert_array_equal(cascade.origin + margin, np.rint(x_min / texel))
        assert np.all(np.rint(x_min / texel) % 2 == 0)
        np.testing.assert_allclose(cascade.box_min + margin * cascade.texel_size, x_min, rtol=2.0 ** -11)
        # z_min_cam = z_vec.dot(center) - radius; z_max = z_vec.dot(center) + radius + pancake_size, z_vec
        # toward the light (csmlab's depth grows away from it). Godot's radius is the widened one (< 0.1 %).
        depth = cs.basis[2] @ center
        np.testing.assert_allclose([cascade.depth_near, cascade.depth_far], [depth - radius - 20.0, depth + radius],
                                   rtol=0, atol=2e-3 * radius)
    # light_storage.cpp: fade_from = -split_offsets[3] * min(fade_start, 0.999), fade_to = -split_offsets[3];
    # scene_forward_clustered.glsl: shadow = mix(shadow, 1.0, smoothstep(fade_from, fade_to, vertex.z)).
    fade_from, fade_to = far * 0.8, far
    depths = np.array([85.0, 90.0, 95.0])
    t = np.clip((depths - fade_from) / (fade_to - fade_from), 0.0, 1.0)
    godot = t * t * (3.0 - 2.0 * t)                                           # GLSL smoothstep
    lit, _ = faded(np.zeros(3, np.float32), depths, far=float(cs.splits[-1]), fade_out=settings.fade_out,
                   fade=settings.fade)
    np.testing.assert_allclose(lit, godot, rtol=1e-6)
    np.testing.assert_allclose(lit, [0.15625, 0.5, 0.84375], rtol=1e-6)


def test_unity_urp_fade_is_linear_in_squared_distance(tmp_path):
    settings, pose = _preset("engines/unity_urp", tmp_path)
    cs = _build(settings, pose)
    # ShadowUtils.GetScaleAndBiasForLinearDistanceFade(fadeDistance = maxShadowDistance², border):
    # border = 1 - border; border *= border; distanceFadeNear = border * fadeDistance;
    # scale = 1 / (fadeDistance - distanceFadeNear); bias = -distanceFadeNear / (fadeDistance - distanceFadeNear).
    fade_distance = 50.0 ** 2
    border = (1.0 - 0.2) ** 2
    fade_near = border * fade_distance
    scale, bias = 1.0 / (fade_distance - fade_near), -fade_near / (fade_distance - fade_near)
    # Points off the view axis, so that their distance is not their view depth.
    directions = np.array([[0.3, 0.1, -1.0]] * 3)
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    points = POSE_AT + directions * np.array([[42.5], [45.0], [47.5]])
    cam_to_pixel = points - POSE_AT
    urp = np.clip(np.einsum("ij,ij->i", cam_to_pixel, cam_to_pixel) * scale + bias, 0.0, 1.0)  # GetMainLightShadowFade
    lit, _ = faded(np.zeros(3, np.float32), pose.view_depth(points), far=float(cs.splits[-1]),
                   fade_out=settings.fade_out, fade=settings.fade, distance=np.linalg.norm(points - cs.eye, axis=1))
    np.testing.assert_allclose(lit, urp, rtol=1e-6)
    np.testing.assert_allclose(lit, [0.229167, 0.472222, 0.729167], rtol=1e-5)


def test_unity_builtin_stable_fit_fades_with_the_distance_to_the_camera(tmp_path):
    settings, pose = _preset("engines/unity_builtin_stable", tmp_path)
    cs = _build(settings, pose)
    # UnityShadowLibrary.cginc: UnityComputeShadowFadeDistance = distance(wpos, fade centre) (Stable Fit),
    # UnityComputeShadowFade = saturate(fadeDist * _LightShadowData.z + _LightShadowData.w), linear; the centre
    # (native) taken as the camera, the fade over the last 0.1 of 150 m.
    r = np.array([137.5, 142.5, 147.5])
    points = POSE_AT + np.array([0.6, 0.0, -0.8]) * r[:, None]
    unity = np.clip((np.linalg.norm(points - POSE_AT, axis=1) - 135.0) / 15.0, 0.0, 1.0)
    lit, _ = faded(np.zeros(3, np.float32), pose.view_depth(points), far=float(cs.splits[-1]),
                   fade_out=settings.fade_out, fade=settings.fade, distance=np.linalg.norm(points - cs.eye, axis=1))
    np.testing.assert_allclose(lit, unity, rtol=1e-6)
    np.testing.assert_allclose(lit, [1 / 6, 0.5, 5 / 6], rtol=1e-6)


def test_ue5_transition_extends_each_cascade_forward_past_its_split(tmp_path):
    settings, pose = _preset("engines/ue5", tmp_path)
    cs = _build(settings, pose)
    # GetSplitDistance (CascadeDistributionExponent 3): near + (far - near) (e^i - 1) / (e^C - 1).
    near, far, e = 0.1, 200.0, 3.0
    z = [near + (far - near) * (e ** i - 1.0) / (e ** 3 - 1.0) for i in range(4)]
    np.testing.assert_allclose(cs.splits, z, rtol=1e-12)
    # The transition: FadePlaneOffset = SplitFar; SplitFar += CascadeTransitionFraction * (SplitFar - SplitNear);
    # FadePlaneLength = SplitFar - FadePlaneOffset; cascade i fades out (i + 1 in) over it, linearly.
    fade_offset = z[1]
    split_far = z[1] + 0.1 * (z[1] - z[0])
    assert cs.cascades[0].slice_far == pytest.approx(split_far, rel=1e-12)
    assert cs.cascades[1].slice_near == pytest.approx(z[1], rel=1e-12)
    depths = fade_offset + np.array([0.25, 0.5, 0.75]) * (split_far - fade_offset)
    unreal = (depths - fade_offset) / (split_far - fade_offset)
    chosen, weight = _blend_weights(settings, cs, depths)
    np.testing.assert_array_equal(chosen, [0, 0, 0])
    np.testing.assert_allclose(weight, unreal, rtol=1e-9)
    # Before the split there is no band: cascade 0 alone.
    chosen, weight = _blend_weights(settings, cs, [z[1] - 0.5])
    assert chosen[0] == 0 and weight[0] == 0.0


def test_bevy_overlap_is_a_proportion_of_the_far_bound(tmp_path):
    settings, pose = _preset("engines/bevy", tmp_path)
    cs = _build(settings, pose)
    # cascade.rs calculate_cascade_bounds: base = (max / first)^(1 / (n - 1)); bounds[i] = first * base^i.
    base = (150.0 / 10.0) ** (1.0 / 3.0)
    far_bounds = [10.0 * base ** i for i in range(4)]
    np.testing.assert_allclose(cs.splits[1:], far_bounds, rtol=1e-12)
    # build_directional_light_cascades: near_bounds = [minimum_distance] + (1 - overlap_proportion) * far_bounds.
    near_bounds = [0.1] + [0.8 * b for b in far_bounds[:-1]]
    np.testing.assert_allclose([c.slice_near for c in cs.cascades], near_bounds, rtol=1e-12)
    # shadows.wesl fetch_directional_shadow: next_near_bound = (1 - overlap) * this_far_bound;
    # mix(shadow, next_shadow, (-view_z - next_near_bound) / (this_far_bound - next_near_bound)).
    this_far = far_bounds[1]
    next_near = 0.8 * this_far
    depths = next_near + np.array([0.25, 0.5, 0.75]) * (this_far - next_near)
    chosen, weight = _blend_weights(settings, cs, depths)
    np.testing.assert_array_equal(chosen, [1, 1, 1])
    np.testing.assert_allclose(weight, (depths - next_near) / (this_far - next_near), rtol=1e-9)


def test_stride_sphere_is_from_points_and_its_blend_a_smoothstep(tmp_path):
    settings, pose = _preset("engines/stride", tmp_path)
    cs = _build(settings, pose, visible_depth=(1.0, 120.0))
    # LightDirectionalShadowMapRenderer.ComputeCascadeSplits: logRatio = 1 - PSSMFactor (0.5);
    # logZ = min * (max / min)^d, uniformZ = min + (max - min) * d, distance = lerp(uniformZ, logZ, logRatio).
    lo, hi = 1.0, 120.0
    d = np.arange(5) / 4.0
    stride = (lo + (hi - lo) * d) * 0.5 + lo * (hi / lo) ** d * 0.5
    np.testing.assert_allclose(cs.splits, stride, rtol=1e-12)
    margin = cs.margin_texels
    for cascade in cs.cascades:
        # BoundingSphere.FromPoints: the centre is the points' average, the radius the largest distance to it.
        points = _corners(cascade.slice_near, cascade.slice_far)
        centre = points.mean(axis=0)
        radius = max(np.linalg.norm(p - centre) for p in points)
        # snap = "centre_nearest": the box is 2 (R / 2 - m - 1) texels of the radius plus the margins.
        held = cascade.texel_size[0] * (cascade.resolution // 2 - margin - 1)
        assert held == pytest.approx(radius, rel=2.0 ** -11)
        # ProjectionSnapping: the projection's translation rounded to whole pixels, the centre to the nearest texel.
        box_centre = 0.5 * (cascade.box_min + cascade.box_max)
        assert np.all(np.abs(box_centre - cs.basis[:2] @ centre) <= 0.5 * cascade.texel_size * (1 + 1e-9))
        # LookAtRH(target - direction * r, target), nearClip 0, farClip 2r: the sphere's centre ± r along the light.
        depth = cs.basis[2] @ centre
        np.testing.assert_allclose([cascade.depth_near, cascade.depth_far], [depth - radius, depth + radius],
                                   rtol=1e-12)
    # ShadowMapReceiverDirectional.sdsl: splitDist = (nextSplit - DepthVS) / splitSize; if (splitDist < 0.2)
    # { lerpAmt = smoothstep(0.0, 0.2, splitDist); shadow = lerp(nextShadow, shadow, lerpAmt); }
    z0, z1 = stride[1], stride[2]
    depths = z1 - np.array([0.15, 0.1, 0.05]) * (z1 - z0)
    split_dist = (z1 - depths) / (z1 - z0)
    u = np.clip(split_dist / 0.2, 0.0, 1.0)
    next_weight = 1.0 - u * u * (3.0 - 2.0 * u)
    chosen, weight = _blend_weights(settings, cs, depths)
    np.testing.assert_array_equal(chosen, [1, 1, 1])
    np.testing.assert_allclose(weight, next_weight, rtol=1e-9)
    np.testing.assert_allclose(weight, [0.15625, 0.5, 0.84375], rtol=1e-9)


def test_mjp_cascades_cover_the_clip_range_with_each_slices_own_depth(tmp_path):
    settings, pose = _preset("engines/mjp", tmp_path)
    cs = _build(settings, pose)
    # MeshRenderer.cpp: splits over the whole clip range; view-depth split
    # camera.NearClip() + splitDist * (FarClip - NearClip), MinCascadeDistance 0, MaxCascadeDistance 1.
    near, far = 0.1, 400.0
    np.testing.assert_allclose(cs.splits, [near] + [near + s * (far - near) for s in (0.05, 0.15, 0.5, 1.0)],
                               rtol=1e-12)
    for cascade in cs.cascades:
        # OrthographicCamera(..., 0.0, cascadeExtents.z): the slice corners' own light depth.
        depth = _corners(cascade.slice_near, cascade.slice_far) @ cs.basis[2]
        assert cascade.depth_near == pytest.approx(depth.min(), abs=1e-9)
        assert cascade.depth_far == pytest.approx(depth.max(), abs=1e-9)


@pytest.mark.parametrize("preset", ["seeds/dx_csm11_cascade", "seeds/dx_csm11_scene"])
def test_dx_csm11_has_the_samples_three_partitions_and_no_blend(tmp_path, preset):
    settings, pose = _preset(preset, tmp_path)
    cs = _build(settings, pose)
    # CascadedShadowMaps11.cpp: m_nCascadeLevels = 3, partitions {5, 15, 60} of m_iCascadePartitionsMax = 100;
    # CascadedShadowsManager.cpp: fIntervalEnd = partition / 100 * (far - near), from view depth 0.
    near, far = 0.1, 400.0
    np.testing.assert_allclose(cs.splits[1:], [p / 100.0 * (far - near) for p in (5, 15, 60)], rtol=1e-12)
    assert settings.blend_band == 0.0                                          # m_iBlurBetweenCascades(0)


# --- Each preset's filter and bias in its engine's own terms (configs/*: the file and function of each) ---

FILTER_AND_BIAS = {
    # name: (filter fields, bias fields) — csmlab's field values as each engine's source sets them.
    "engines/godot4": ({"filter": "pcf_vogel", "vogel_taps": 4, "vogel_radius": 2.0, "vogel_angle": 2.4,
                        "vogel_scale": "first_split", "poisson_rotation": "pixel_taa"},
                       {"bias_depth_range": 0.1 / 100.0 * 2.0, "bias_slope": 0.0, "normal_offset": 2.0,
                        "normal_offset_scale": "one_minus_cos_lateral", "receiver_plane_bias": False}),
    "engines/threejs_csm": ({"filter": "pcf_vogel", "vogel_taps": 5, "vogel_radius": 1.0,
                             "vogel_angle": 2.399963229728653, "poisson_rotation": "pixel"},
                            {"bias_constant": -1e-6 * (2000.0 - 1.0), "bias_slope": 0.0, "normal_offset": 0.0,
                             "receiver_plane_bias": False}),
    "engines/filament": ({"filter": "pcf_castano", "filter_size": 3},
                         {"bias_constant": 0.001, "bias_depth_range": 0.0, "bias_slope": 0.0, "caster_bias_units": 0.5,
                          "caster_bias_slope": 2.0, "normal_offset": 0.5, "normal_offset_scale": "sin",
                          "receiver_plane_bias": False}),
    "engines/bevy": ({"filter": "pcf_castano", "filter_size": 5},
                     {"bias_constant": 0.02, "bias_slope": 0.0, "normal_offset": 1.8, "receiver_plane_bias": False}),
    "engines/stride": ({"filter": "pcf_castano", "filter_size": 5},
                       {"bias_depth_range": 0.01, "bias_slope": 0.0, "normal_offset": 0.0,
                        "normal_offset_m": 2.0 * 10.0 / 4096.0, "normal_offset_scale": "one_minus_cos",
                        "receiver_plane_bias": False}),
    "engines/mjp": ({"filter": "pcf_bilinear"},
                    {"bias_constant": 0.0, "bias_slope": 0.0, "normal_offset": 0.0, "receiver_plane_offset": 0.01,
                     "receiver_plane_bias": False}),
    "engines/unity_urp": ({"filter": "pcf_bilinear"},
                          {"bias_texels": 0.0, "bias_depth_range": 0.0, "bias_slope": 0.0, "caster_bias_texels": 1.0,
                           "caster_bias_units": 1.0, "caster_bias_slope": 2.5, "normal_offset": 1.0,
                           "normal_offset_scale": "one_minus_cos", "receiver_plane_bias": False}),
    "engines/unity_hdrp": ({"filter": "pcf_tent_bilinear", "filter_size": 7},
                           {"bias_depth_range": 1.0 / 2**16, "bias_slope": 0.0, "caster_bias_units": 1.0,
                            "caster_bias_slope": 2.5, "normal_offset": 0.75,
                            "normal_offset_scale": "none", "receiver_plane_bias": False}),
    "engines/unity_builtin_stable": ({"filter": "pcf_tent_bilinear", "filter_size": 7},
                                     {"bias_slope": 0.0, "caster_bias_units": 1.0, "caster_bias_slope": 1.0,
                                      "receiver_plane_bias": False}),
    "engines/unity_builtin_close": ({"filter": "pcf_tent_bilinear", "filter_size": 7},
                                    {"bias_slope": 0.0, "caster_bias_units": 1.0, "caster_bias_slope": 1.0,
                                     "receiver_plane_bias": False}),
    "engines/ue5": ({"filter": "pcf_bilinear_box", "filter_size": 5}, {"receiver_plane_bias": False}),
    "seeds/dx_csm11_cascade": ({"filter": "pcf_bilinear_box", "filter_size": 3},
                               {"bias_depth_range": 0.002, "bias_slope": 0.0, "caster_bias_slope": 1.0,
                                "caster_bias_units": 0.0, "normal_offset": 0.0, "receiver_plane_bias": False}),
    "seeds/dx_csm11_scene": ({"filter": "pcf_bilinear_box", "filter_size": 3},
                             {"bias_depth_range": 0.002, "bias_slope": 0.0, "caster_bias_slope": 1.0,
                              "caster_bias_units": 0.0, "normal_offset": 0.0, "receiver_plane_bias": False}),
}


@pytest.mark.parametrize("preset", sorted(FILTER_AND_BIAS))
def test_preset_filter_and_bias_are_its_engines(preset, tmp_path):
    settings, pose = _preset(preset, tmp_path)
    filter_fields, bias_fields = FILTER_AND_BIAS[preset]
    for field, value in {**filter_fields, **bias_fields}.items():
        assert getattr(settings, field) == (value if isinstance(value, (str, bool)) else pytest.approx(value)), field


def test_receiver_plane_bias_is_on_only_where_the_engine_uses_it(tmp_path):
    # Only MJP's sample turns it on by default (AppSettings.cs UsePlaneDepthBias = true), and for its 2×2
    # filter as one static offset (Mesh.hlsl SampleShadowMapFixedSizePCF), not per-tap planes.
    # A virtual clipmap's page lookup (ue5_vsm) compares every tap with the receiver's own depth: no plane.
    on = [preset for preset in PRESETS if (_preset(preset, tmp_path)[0].receiver_plane_bias
                                           and _preset(preset, tmp_path)[0].shadow_map == "cascades")
          or _preset(preset, tmp_path)[0].receiver_plane_offset > 0]
    assert on == ["engines/mjp"]
    assert not _preset("engines/mjp", tmp_path)[0].receiver_plane_bias


def test_godot4_bias_at_a_receiver_is_godots(tmp_path):
    """light_storage.cpp update_light_buffers: shadow_bias[j] = SHADOW_BIAS / 100 · (z_max − z_min_cam) ·
    soft_shadow_scale (0.1 / 100 · depth range · 2.0), toward the light; the receiver's compared depth is its own
    light depth less that bias (normal offset left out: normal_offset = 0 here)."""
    from csmlab.filters import _cascade_bias
    from csmlab.texels import receiver_lookup

    settings, pose = _preset("engines/godot4", tmp_path)
    cs = _build(settings, pose)
    godot = np.array([0.1 / 100.0 * (c.depth_far - c.depth_near) * (1.0 * 2.0) for c in cs.cascades])
    np.testing.assert_allclose(_cascade_bias(cs, settings), godot, rtol=1e-12)
    point = POSE_AT + np.array([0.5, -1.0, -8.0])
    normal = -cs.basis[2]                                                      # facing the light: tan θ = 0
    _, depth, _ = receiver_lookup(cs, point[None], normal[None], bits=8, normal_offset=0.0,
                                  bias_constant=_cascade_bias(cs, settings), bias_slope=settings.bias_slope)
    np.testing.assert_allclose(depth[:, 0], point @ cs.basis[2] - cs.zref - godot, rtol=1e-6)


def test_dx_csm11_fit_to_scene_box_is_the_body_diagonal_of_corners_0_and_6(tmp_path):
    settings, pose = _preset("seeds/dx_csm11_scene", tmp_path)
    cs = _build(settings, pose)
    margin = cs.margin_texels
    for cascade in cs.cascades:
        # CascadedShadowsManager::InitFrame, FIT_TO_SCENE: vDiagonal = vFrustumPoints[0] - vFrustumPoints[6]
        # (point 0 right-top-near, 6 left-bottom-far, CreateFrustumPointsFromCascadeInterval); the box is padded
        # to its length about the AABB's centre: vBoarderOffset = (diagonal - (max - min)) / 2.
        ty = np.tan(np.radians(30.0))
        tx = ty * 16.0 / 9.0
        zn, zf = cascade.slice_near, cascade.slice_far
        p0 = np.array([zn * tx, zn * ty, -zn])
        p6 = np.array([-zf * tx, -zf * ty, -zf])
        diagonal = np.linalg.norm(p0 - p6)
        light = _corners(zn, zf) @ cs.basis[:2].T
        centre = 0.5 * (light.min(axis=0) + light.max(axis=0))
        # csmlab's texel keeps the filter's margins and one spare texel: diagonal / (R - 2m - 1), DX's diagonal / R.
        assert cascade.texel_size[0] == pytest.approx(diagonal / (cascade.resolution - 2 * margin - 1), rel=1e-12)
        # Floored to whole texels (min = floor(min / t) * t): the box's lower edge within a texel of the padded one.
        lower = centre - 0.5 * diagonal
        assert np.all((cascade.box_min + margin * cascade.texel_size <= lower + 1e-9)
                      & (cascade.box_min + (margin + 1) * cascade.texel_size > lower - 1e-9))


def test_urp_filament_and_unity_builtin_caster_offsets_are_their_engines(tmp_path):
    """The metres each cascade's casters are pushed from the light, from the engines' formulas: URP
    ShadowUtils.GetShadowBias texelSize = frustumSize / shadowResolution × m_ShadowDepthBias 1 plus
    SetGlobalDepthBias's 1 unit of D16 over the tile's near/far; Filament's polygonOffsetConstant 0.5 unit of
    DEPTH16; Unity built-in's 1 unit (float32 here: 2^-24 of the range)."""
    from csmlab.render import caster_offsets

    for preset, expected in (
            ("engines/unity_urp", lambda c: c.extent[0] / c.resolution + (c.depth_far - c.depth_near) / 65535.0),
            ("engines/filament", lambda c: 0.5 * (c.depth_far - c.depth_near) / 65535.0),
            ("engines/unity_builtin_stable", lambda c: (c.depth_far - c.depth_near) * 2.0**-24)):
        settings, pose = _preset(preset, tmp_path)
        cs = _build(settings, pose)
        np.testing.assert_allclose(caster_offsets(cs, settings), [expected(c) for c in cs.cascades], rtol=1e-12,
                                   err_msg=preset)
