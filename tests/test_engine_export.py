"""Engine snippets: the splits each engine is given reproduce csmlab's, and every missing knob is named."""

from __future__ import annotations

import re

import numpy as np
import pytest

from csmlab.cascades.splits import split_distances
from csmlab.engine_export import EXPORT_METHODS, export, ue_split_fractions
from csmlab.settings import ShadowSettings

NEAR, FAR = 0.1, 400.0


def _numbers(text: str, after: str) -> list[float]:
    rest = next(line for line in text.splitlines() if after in line).split(after, 1)[1]
    rest = rest.split("(", 1)[1] if "(" in rest else rest  # new Vector3(…): the arguments, not the 3
    return [float(v) for v in re.findall(r"-?\d+\.?\d*(?:e-?\d+)?", rest)]


def test_ue_fractions_are_unreals_geometric_sum():
    # Exponent 1 spaces cascades evenly; exponent 2 over 3 cascades: 1/7, 3/7 (1, 2, 4 of 7).
    assert np.allclose(ue_split_fractions(1.0, 4), [0, 0.25, 0.5, 0.75, 1])
    assert np.allclose(ue_split_fractions(2.0, 3), [0, 1 / 7, 3 / 7, 1])


def test_ue_exponent_reproduces_a_geometric_split():
    # A uniform split is Unreal's exponent 1 exactly: nothing about splits is reported missing.
    snippet = export(ShadowSettings(split="uniform"), near=NEAR, far=FAR, engine="ue5")
    assert "CascadeDistributionExponent=1.00" in snippet.text
    assert not any("split distances" in item for item in snippet.lacking)
    practical = export(ShadowSettings(split="practical", lambda_=0.9), near=NEAR, far=FAR, engine="ue5")
    assert any("split distances" in item for item in practical.lacking)


@pytest.mark.parametrize("cascades", [2, 3, 4])
def test_unity_urp_splits_are_fractions_of_the_shadow_distance(cascades):
    settings = ShadowSettings(cascades=cascades, split="practical", lambda_=0.6, shadow_distance=150.0)
    z = split_distances(near=NEAR, far=150.0, count=cascades, method="practical", lambda_=0.6)
    text = export(settings, near=NEAR, far=FAR, engine="unity_urp").text
    fractions = _numbers(text, f"cascade{cascades}Split =")
    assert np.allclose(fractions, z[1:-1] / 150.0, atol=1e-4)
    assert f"mainLightShadowmapResolution = {2 * settings.resolution};" in text


def test_godot_and_bevy_and_threejs_carry_the_same_boundaries():
    settings = ShadowSettings(cascades=4, split="log", shadow_distance=100.0)
    z = split_distances(near=NEAR, far=100.0, count=4, method="log")
    godot = export(settings, near=NEAR, far=FAR, engine="godot4").text
    # Godot's splits are fractions of the range from the near plane: distances[i + 1] = min_distance + split · range.
    assert np.allclose([_numbers(godot, f"directional_shadow_split_{i} =")[0] for i in (1, 2, 3)],
                       (z[1:-1] - NEAR) / (100.0 - NEAR), atol=1e-4)
    bevy = export(settings, near=NEAR, far=FAR, engine="bevy").text
    assert np.allclose(_numbers(bevy, "bounds: vec!")[:4], z[1:], atol=1e-3)
    three = export(settings, near=NEAR, far=FAR, engine="threejs_csm").text
    assert "mode: 'logarithmic'" in three
    half = export(ShadowSettings(split="practical", lambda_=0.5), near=NEAR, far=FAR, engine="threejs_csm").text
    assert "mode: 'practical'" in half and "customSplitsCallback" not in half


@pytest.mark.parametrize("engine", sorted(EXPORT_METHODS))
def test_every_engine_names_the_knobs_it_lacks(engine):
    settings = ShadowSettings(stabilization="quantized", levels=16, fit="scene", selection="map", cascades=6)
    lacking = " ".join(export(settings, near=NEAR, far=FAR, engine=engine).lacking)
    for knob in ("stabilization = 'quantized'", "levels = 16", "fit = 'scene'", "selection = 'map'"):
        assert knob in lacking
    plain = " ".join(export(ShadowSettings(filter="pcf_bilinear"), near=NEAR, far=FAR, engine=engine).lacking)
    assert "stabilization" not in plain and "levels" not in plain


def test_an_unknown_engine_lists_the_known_ones():
    with pytest.raises(ValueError, match="expected one of \\['bevy'"):
        export(ShadowSettings(), near=NEAR, far=FAR, engine="cryengine")


def _engine_preset(name: str, folder) -> ShadowSettings:
    """The settings of ``configs/engines/<name>.toml`` as an experiment that extends it resolves them."""
    from csmlab.config import load_experiment

    path = folder / "uses_engine.toml"
    path.write_text(f'extends = ["engines/{name}"]\n[camera]\npath = "walk"\n')
    return load_experiment(path).methods[0].settings


def test_unreal_preset_exports_its_own_distribution_exponent(tmp_path):
    # Unreal's geometric sum (ue_split_fractions) is one road, csmlab's exponent split the other: the
    # ue5 preset must come back as exponent 3 with no split error reported.
    settings = _engine_preset("ue5", tmp_path)
    snippet = export(settings, near=NEAR, far=FAR, engine="ue5")
    assert f"CascadeDistributionExponent={settings.distribution_exponent:.2f}" in snippet.text
    assert not any("split distances" in item for item in snippet.lacking)
    assert f"DynamicShadowDistanceMovableLight={settings.shadow_distance * 100:.0f} " in snippet.text
    assert f"ShadowDistanceFadeoutFraction={settings.fade_out:g}" in snippet.text
    tuned = export(settings.replace(distribution_exponent=2.2), near=NEAR, far=FAR, engine="ue5")
    assert "CascadeDistributionExponent=2.20" in tuned.text and not any("split distances" in i for i in tuned.lacking)


def test_bevy_preset_exports_its_first_cascade_bound(tmp_path):
    settings = _engine_preset("bevy", tmp_path)
    text = export(settings, near=NEAR, far=FAR, engine="bevy").text
    assert _numbers(text, "first_cascade_far_bound:")[0] == pytest.approx(settings.first_cascade_far)
    bounds = _numbers(text, "bounds: vec!")[:settings.cascades]
    ratios = np.diff(np.log(bounds))  # geometric after the first bound: equal ratios
    assert bounds[-1] == pytest.approx(settings.shadow_distance) and np.allclose(ratios, ratios[0], atol=1e-3)
    nearer = export(settings.replace(first_cascade_far=6.0), near=NEAR, far=FAR, engine="bevy").text
    assert _numbers(nearer, "bounds: vec!")[0] == pytest.approx(6.0)


def test_per_cascade_resolution_and_a_non_power_of_two_atlas_are_named():
    settings = ShadowSettings(cascades=3, resolution=1182, cascade_resolutions=(1182, 1024, 512))
    for engine in sorted(EXPORT_METHODS):
        lacking = " ".join(export(settings, near=NEAR, far=FAR, engine=engine).lacking)
        assert "cascade_resolutions = [1182, 1024, 512]" in lacking
    urp = export(settings, near=NEAR, far=FAR, engine="unity_urp")
    assert "mainLightShadowmapResolution = 2048;" in urp.text  # 2 × 1182 = 2364 → the power of two below
    assert any("2048 written for 2364" in item for item in urp.lacking)


def test_every_filter_exports_to_every_engine_and_bevy_names_the_kernels_it_lacks():
    from csmlab.lookup_choices import FILTER_METHODS

    for name in sorted(FILTER_METHODS):
        settings = ShadowSettings(filter=name, filter_size=5)
        for engine in sorted(EXPORT_METHODS):
            export(settings, near=NEAR, far=FAR, engine=engine)
        lacking = " ".join(export(settings, near=NEAR, far=FAR, engine="bevy").lacking)
        assert (f"filter = {name!r}" in lacking) == (name not in ("pcf_castano", "pcf_bilinear")), name
    # Bevy's Gaussian is Castaño's 5×5 (sample_shadow_map_castano_thirteen): pcf_castano 5, not a tent.
    castano = export(ShadowSettings(filter="pcf_castano", filter_size=5), near=NEAR, far=FAR, engine="bevy")
    assert "ShadowFilteringMethod::Gaussian" in castano.text
    assert not any("filter" in item for item in castano.lacking)


def test_the_engine_presets_filters_export_as_their_engines_filters():
    from csmlab.engine_export import GODOT_SOFT_LOW, THREEJS_PCF

    godot = export(ShadowSettings(filter="pcf_vogel", poisson_rotation="pixel", **GODOT_SOFT_LOW), near=NEAR,
                   far=FAR, engine="godot4")
    assert "soft_shadow_filter_quality = 2" in godot.text and not any("filter" in i for i in godot.lacking)
    three = export(ShadowSettings(filter="pcf_vogel", poisson_rotation="pixel", vogel_radius=2.0, **THREEJS_PCF),
                   near=NEAR, far=FAR, engine="threejs_csm")
    assert "THREE.PCFShadowMap" in three.text and "light.shadow.radius = 2;" in three.text
    assert not any("filter" in i for i in three.lacking)
    urp = export(ShadowSettings(filter="pcf_bilinear"), near=NEAR, far=FAR, engine="unity_urp")
    assert "supportsSoftShadows = false" in urp.text and not any("filter" in i for i in urp.lacking)
    medium = export(ShadowSettings(filter="pcf_tent_bilinear", filter_size=5), near=NEAR, far=FAR, engine="unity_urp")
    assert "supportsSoftShadows = true" in medium.text and not any("filter" in i for i in medium.lacking)


def test_the_filter_tables_name_only_csmlab_filters_and_hard_follows_the_record():
    from csmlab.engine_export import BEVY_EXACT, BEVY_FILTERING, UE5_FILTER, URP_FILTER
    from csmlab.lookup_choices import FILTER_METHODS

    assert set(BEVY_FILTERING) | set(BEVY_EXACT) | {UE5_FILTER[0], URP_FILTER[0]} <= set(FILTER_METHODS)
    hard = [name for name, record in FILTER_METHODS.items() if record.hard]
    assert hard == ["none"]
    for name in FILTER_METHODS:
        godot = export(ShadowSettings(filter=name), near=NEAR, far=FAR, engine="godot4").text
        # Godot's Hard is one comparison through the linear compare sampler: pcf_bilinear, or csmlab's one texel.
        assert ("soft_shadow_filter_quality = 0" in godot) == (name in hard + ["pcf_bilinear"]), name


def test_each_engine_names_a_band_or_fade_of_another_shape():
    # Unreal's band lies past the split (forward), Bevy's is a proportion of the far bound; Godot fades with a
    # smoothstep, URP linearly in the squared distance.
    band = ShadowSettings(blend_band=0.1, fade_out=0.1)
    assert any("transition = 'backward'" in i for i in export(band, near=NEAR, far=FAR, engine="ue5").lacking)
    assert any("transition = 'backward'" in i for i in export(band, near=NEAR, far=FAR, engine="bevy").lacking)
    assert any("fade = 'linear'" in i for i in export(band, near=NEAR, far=FAR, engine="godot4").lacking)
    assert any("fade = 'linear'" in i for i in export(band, near=NEAR, far=FAR, engine="unity_urp").lacking)
    assert not any("transition" in i or "fade =" in i
                   for i in export(band.replace(transition="forward"), near=NEAR, far=FAR, engine="ue5").lacking)
    assert not any("transition" in i for i in export(band.replace(transition="far_bound"), near=NEAR, far=FAR,
                                                     engine="bevy").lacking)
    assert not any("fade =" in i for i in export(band.replace(fade="smoothstep"), near=NEAR, far=FAR,
                                                 engine="godot4").lacking)


def _stride_cascade_ends(text: str, *, near: float) -> np.ndarray:
    """Where Stride ends each cascade for an exported scene with a manual depth range: LightDirectionalShadowMapRenderer
    .ComputeCascadeSplits (stride3d/stride @34c7f40f) written out again from the C# source."""
    def member(name, default=None):
        found = re.search(rf"^\s*{name}: (\S+)$", text, re.M)
        return default if found is None else found.group(1)

    count = {"OneCascade": 1, "TwoCascades": 2, "FourCascades": 4}[member("CascadeCount", "FourCascades")]
    assert member("IsAutomatic") == "false"
    lo, hi = near + float(member("ManualMinDistance", 0.0)), near + float(member("ManualMaxDistance", 50.0))
    if "PartitionLogarithmic" in text:
        log_ratio = min(max(1.0 - float(member("PSSMFactor", 0.5)), 0.0), 1.0)
        distrib = np.arange(1, count + 1) / count
        return (lo + (hi - lo) * distrib) * (1.0 - log_ratio) + lo * (hi / lo) ** distrib * log_ratio
    used = {1: [1], 2: [1, 3], 4: [0, 1, 2, 3]}[count]
    return np.array([lo + float(member(f"SplitDistance{k}")) * hi for k in used])


@pytest.mark.parametrize("settings", [
    ShadowSettings(cascades=4, split="practical", lambda_=0.8, shadow_distance=120.0),
    ShadowSettings(cascades=2, split="exponent", distribution_exponent=2.5, shadow_distance=90.0),
    ShadowSettings(cascades=4, split="manual", splits=(5.0, 15.0, 40.0, 100.0), shadow_distance=100.0),
    ShadowSettings(cascades=1, split="uniform", shadow_distance=30.0),
])
def test_stride_places_the_exported_cascades_where_csmlab_does(settings):
    snippet = export(settings, near=NEAR, far=FAR, engine="stride")
    assert not any(item.startswith(("split", "cascades", "shadow_distance")) for item in snippet.lacking)
    np.testing.assert_allclose(_stride_cascade_ends(snippet.text, near=NEAR),
                               split_distances(near=NEAR, far=settings.shadow_distance, count=settings.cascades,
                                               method=settings.split, lambda_=settings.lambda_,
                                               splits=settings.splits,
                                               distribution_exponent=settings.distribution_exponent)[1:],
                               rtol=1e-9)
