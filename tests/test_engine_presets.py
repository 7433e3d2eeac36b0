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
from csmlab.render import clipped_casters, faded

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
    assert set(ENGINES) == {"ue5", "unity_builtin_stable", "unity_builtin_close", "unity_urp", "godot4", "filament",
                            "bevy", "threejs_csm", "stride", "mjp"}
    assert set(SEEDS) == {"nvidia_sdk", "ogldev49", "dx_csm11_cascade", "dx_csm11_scene", "dx_vsm11", "unigine_exact",
                          "unigine_quantized", "unigine_best_resolution"}


@pytest.mark.parametrize("preset, defaults", [
    # DirectionalLightComponent.h: DynamicShadowCascades 3, CascadeDistributionExponent 3.0,
    # CascadeTransitionFraction 0.1, ShadowDistanceFadeoutFraction 0.1, 20000 cm.
    ("engines/ue5", dict(cascades=3, split="exponent", distribution_exponent=3.0, blend_band=0.1, fade_out=0.1,
                         shadow_distance=200.0, stabilization="exact")),
    # Unity QualitySettings: shadowCascade4Split (0.067, 0.2, 0.467), shadowDistance 150.
    # Built-in: Internal-ScreenSpaceShadows frag_pcf5x5 -> UnitySampleShadowmap_PCF5x5Tent; one 2×2 shadowmap.
    ("engines/unity_builtin_stable", dict(cascades=4, splits=(0.067, 0.2, 0.467, 1.0), shadow_distance=150.0,
                                          stabilization="exact", selection="map", filter="pcf_tent", filter_size=5,
                                          storage="atlas", atlas_layout="2x2")),
    ("engines/unity_builtin_close", dict(cascades=4, splits=(0.067, 0.2, 0.467, 1.0), stabilization="none",
                                         filter="pcf_tent", filter_size=5, storage="atlas")),
    # UniversalRenderPipelineAsset: m_ShadowDistance 50, m_Cascade4Split (0.067, 0.2, 0.467), m_CascadeBorder 0.2;
    # m_SoftShadowQuality Medium = SampleShadow_ComputeSamples_Tent_5x5; 2×2 atlas; k_ShadowmapBufferBits = 16.
    ("engines/unity_urp", dict(shadow_distance=50.0, splits=(0.067, 0.2, 0.467, 1.0), fade_out=0.2, filter="pcf_tent",
                               filter_size=5, storage="atlas", atlas_layout="2x2", depth_format="unorm16")),
    # DirectionalLight3D: splits 0.1/0.2/0.5, max distance 100, fade_start 0.8, pancake_size 20, blend off;
    # soft_shadow_filter_quality 2 (SOFT_LOW): directional_soft_shadow_samples = 4, quality radius 2.0, a
    # Vogel disk rotated per pixel; directional_shadow/16_bits = true; 4 splits as quadrants of one atlas.
    ("engines/godot4", dict(splits=(0.1, 0.2, 0.5, 1.0), shadow_distance=100.0, fade_out=0.2, pancake=20.0,
                            depth_range="slice", depth_clamp=True, blend_band=0.0, filter="pcf_poisson",
                            poisson_taps=4, filter_size=5, poisson_rotation="pixel", storage="atlas",
                            depth_format="unorm16")),
    # ShadowOptions: shadowCascades 1, practical splits lambda 0.5, stable false; ShadowType::PCF =
    # ShadowSample_PCF_Low, "hardware assisted PCF + 3x3 gaussian filter" (Castaño 2013).
    ("engines/filament", dict(cascades=1, split="practical", lambda_=0.5, stabilization="none", filter="pcf_tent",
                              filter_size=3)),
    # CascadeShadowConfigBuilder::default(): 4, 0.1, 150, first bound 10, overlap 0.2;
    # ShadowFilteringMethod::Gaussian = sample_shadow_map_castano_thirteen, weights (4 - 3s, 7, 1 + 3s) over 5 texels.
    ("engines/bevy", dict(cascades=4, split="geometric", first_cascade_far=10.0, shadow_distance=150.0,
                          blend_band=0.2, extent="diagonal", snap="centre", filter="pcf_tent", filter_size=5)),
    # CSM.js: cascades 3, mode 'practical', lightMargin 200, fade false; renderer default PCFShadowMap.
    ("engines/threejs_csm", dict(cascades=3, split="practical", lambda_=0.5, pancake=200.0, fade_out=0.0,
                                 extent="diagonal", filter="pcf", filter_size=3)),
    # LightDirectionalShadowMap: FourCascades, PSSMFactor 0.5, StabilizationMode ProjectionSnapping,
    # DepthRange.IsAutomatic true (held: DepthIncreaseThreshold 1.1, DepthDecreaseThreshold 2.0),
    # IsBlendingCascades true (overlap 0.2); PCF 5×5 in the shadow atlas.
    ("engines/stride", dict(cascades=4, lambda_=0.5, bounds="sdsm", hysteresis=0.5, stabilization="exact",
                            extent="sphere", snap="centre", blend_band=0.2, filter="pcf", filter_size=5,
                            storage="atlas")),
    # TheRealMJP/Shadows AppSettings.cs: SplitDistance0..3 0.05/0.15/0.5/1.0, StabilizeCascades = false,
    # ShadowMode FixedSizePCF with FixedFilterSize Filter2x2, DepthBufferFormat DB32Float.
    ("engines/mjp", dict(cascades=4, splits=(0.05, 0.15, 0.5, 1.0), stabilization="none", filter="pcf_bilinear",
                         depth_format="float32")),
    # Seed 001: m_cascadeEnd = {zNear, 25.0, 90.0, zFar}; slice AABB, its own depth only.
    ("seeds/ogldev49", dict(cascades=3, splits=(25.0, 90.0, 200.0), stabilization="none", depth_range="slice",
                            depth_clamp=False)),
    ("seeds/nvidia_sdk", dict(split="practical", lambda_=0.75, stabilization="none")),
    # Seed 002/004: "create a kernel (such as a Gaussian) for an N × N grid ... The CascadedShadowMaps11 sample
    # uses this approach"; VarianceShadows11 "use[s] texture arrays instead of a texture atlas" (CSM11: an atlas).
    ("seeds/dx_csm11_cascade", dict(fit="cascade", selection="interval", extent="diagonal", filter="pcf_gaussian",
                                    storage="atlas", atlas_layout="1x4")),
    ("seeds/dx_csm11_scene", dict(fit="scene", selection="map", blend_band=0.1, filter="pcf_gaussian",
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


@pytest.mark.parametrize("preset", PRESETS)
def test_snapping_presets_are_flicker_free_and_refitting_ones_are_not(tmp_path, preset):
    """A translating camera (dolly) under a static light: same-cascade flicker 0.0 exactly iff the box is snapped.

    A filter rotated per screen pixel (Godot's disk) moves with the screen, not the world: that preset
    flickers through its filter alone, and without the rotation it is flicker-free like the others.
    """
    summary = _run(tmp_path, extends=[preset])
    (values,) = summary.values()
    (method,) = load_experiment(tmp_path / "exp.toml").methods
    if method.settings.stabilization == "none":
        assert values["flicker_same"] > 0.0
    elif method.settings.filter == "pcf_poisson" and method.settings.poisson_rotation == "pixel":
        assert values["flicker_same"] > 0.0
        unrotated = _run(tmp_path, extends=[preset], methods=f'[[methods]]\nname = "{method.name}"\n'
                                                             'poisson_rotation = "none"\n')
        assert unrotated[method.name]["flicker_same"] == 0.0
    else:
        assert values["flicker_same"] == 0.0


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


def test_report_draws_methods_with_different_cascade_counts(tmp_path):
    """Filament's one cascade beside Unreal's three and the base four: every figure is written."""
    from csmlab.report import write_report

    _run(tmp_path, extends=["engines/filament", "engines/ue5", "methods/exact"], frames=2)
    index = write_report(tmp_path / "out")
    assert index.is_file() and any((tmp_path / "out" / "figures").glob("*stabilization*"))
