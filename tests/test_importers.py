"""csmlab import: engine files in, a method preset out; and every engine's files read back what tune exports.

The fixtures under tests/data/engines/<engine>/ are small files written by hand in each engine's own
format (tests/data/engines/README.md); the values the tests expect are the numbers written in them,
converted by the engine's documented rules. Files the engines and their demo projects wrote
themselves are read from the git-ignored tests/data/engines/vendor/ when present.
"""

from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest

from csmlab.config import load_experiment
from csmlab.engine_export import EXPORT_METHODS, export, split_boundaries
from csmlab.errors import InputError
from csmlab.importers import IMPORT_METHODS, import_settings
from csmlab.importers.reading import engine_settings, toml_name
from csmlab.importers.ron import parse_ron
from csmlab.settings import APPLIES, ShadowSettings

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data" / "engines"
VENDOR = DATA / "vendor"
NEAR, FAR = 0.1, 400.0
SPLIT_FIELDS = {"split", "splits", "lambda_", "distribution_exponent", "first_cascade_far"}
FIXTURES = {
    "godot4": ["godot4/project.godot", "godot4/level.tscn"],
    "unity_urp": ["unity_urp/UniversalRP-HighQuality.asset"],
    "unity_builtin": ["unity_builtin/QualitySettings.asset"],
    "ue5": ["ue5/DefaultEngine.ini", "ue5/DefaultScalability.ini", "ue5/DirectionalLight.t3d"],
    "filament": ["filament/settings.json"],
    "threejs_csm": ["threejs_csm/csm.json"],
    "bevy": ["bevy/sun.scn.ron"],
    "stride": ["stride/MainScene.sdscene"],
}
PRESETS = [("godot4", "godot4"), ("unity_urp", "unity_urp"), ("unity_builtin", "unity_builtin_close"),
           ("unity_builtin", "unity_builtin_stable"), ("ue5", "ue5"), ("filament", "filament"),
           ("threejs_csm", "threejs_csm"), ("bevy", "bevy"), ("stride", "stride")]


def _fixture(engine: str) -> list[Path]:
    return [DATA / name for name in FIXTURES[engine]]


def _round_trip(settings: ShadowSettings, engine: str, folder: Path) -> tuple[ShadowSettings, str]:
    """``import(export(settings))`` through the engine's own files, and the knobs the export names as lacking."""
    snippet = export(settings, near=NEAR, far=FAR, engine=engine)
    paths = []
    for name, text in snippet.files:
        paths.append(folder / name)
        paths[-1].write_text(text, encoding="utf-8")
    return import_settings(paths, engine=engine).settings, " ".join(snippet.lacking)


def _differences(settings: ShadowSettings, back: ShadowSettings, lacking: str) -> list[str]:
    """Fields of ``settings`` (those that apply to it) that came back different and are not named as lacking;
    a split field counts as back when the cascade boundaries are (to 1 cm: Unreal's exponent grid)."""
    wrong = []
    for attribute in ShadowSettings.__dataclass_fields__:
        name = toml_name(attribute)
        if name in APPLIES and not APPLIES[name].holds(settings):
            continue
        mine, theirs = getattr(settings, attribute), getattr(back, attribute)
        if isinstance(mine, (float, tuple)) and np.shape(mine) == np.shape(theirs):
            same = np.allclose(mine, theirs, rtol=1e-9, atol=1e-12)
        else:
            same = mine == theirs
        if same or f"{name} =" in lacking:
            continue
        if attribute in SPLIT_FIELDS and (settings.cascades != back.cascades and "cascades =" in lacking or np.allclose(
                split_boundaries(settings, near=NEAR, far=FAR), split_boundaries(back, near=NEAR, far=FAR), atol=0.01)):
            continue
        wrong.append(f"{name}: {mine!r} → {theirs!r}")
    return wrong


def test_every_importer_has_an_exporter_and_its_files():
    assert set(IMPORT_METHODS) <= set(EXPORT_METHODS)
    for engine in IMPORT_METHODS:
        snippet = export(ShadowSettings(), near=NEAR, far=FAR, engine=engine)
        assert snippet.files, engine


@pytest.mark.parametrize("engine,preset", PRESETS)
def test_an_engine_preset_comes_back_field_by_field_through_its_engines_files(engine, preset, tmp_path):
    settings = engine_settings(preset)
    back, lacking = _round_trip(settings, engine, tmp_path)
    for attribute in ShadowSettings.__dataclass_fields__:
        mine, theirs = getattr(settings, attribute), getattr(back, attribute)
        if isinstance(mine, (float, tuple)):
            assert np.allclose(mine, theirs, rtol=1e-9, atol=1e-12), (attribute, mine, theirs)
        else:
            assert mine == theirs, (attribute, mine, theirs)


def _tuned_settings() -> list[ShadowSettings]:
    """Settings tune_default's search can recommend: its method with each [tune] field at its low, middle and
    high value (choices in turn)."""
    path = ROOT / "experiments" / "tune_default.toml"
    space = {k: v for k, v in tomllib.loads(path.read_text())["tune"].items() if k not in (
        "memory_budget", "max_flicker", "flicker_metric", "trials", "objectives")}
    base = load_experiment(path).methods[0].settings
    tuned = []
    for pick in range(3):
        fields = {}
        for name, spec in space.items():
            if isinstance(spec, dict):
                fields[name] = spec["min"] + (spec["max"] - spec["min"]) * (0.13 + 0.37 * pick)
            else:
                fields[name] = spec[(pick * 2 + 1) % len(spec)]
        fields["lambda_"] = fields.pop("lambda")
        tuned.append(base.replace(**fields))
    return tuned


@pytest.mark.parametrize("engine", sorted(IMPORT_METHODS))
def test_a_tuned_setting_comes_back_or_is_named_lacking(engine, tmp_path):
    for settings in _tuned_settings():
        back, lacking = _round_trip(settings, engine, tmp_path)
        assert not _differences(settings, back, lacking), (engine, settings)


def test_a_knob_the_files_cannot_hold_is_named_even_when_no_exporter_rule_names_it():
    # Godot has no extent knob: a diagonal extent must be reported, with Godot's own.
    snippet = export(engine_settings("godot4").replace(extent="diagonal"), near=NEAR, far=FAR, engine="godot4")
    assert "extent = 'diagonal' (the engine's is 'centroid')" in snippet.lacking


def test_godot_files_set_their_fields_and_leave_the_rest_at_the_preset():
    imported = import_settings(_fixture("godot4"), engine="godot4")
    s, base = imported.settings, engine_settings("godot4")
    # level.tscn: splits 0.05/0.15/0.4 of the range, 150 m, fade start 0.9, pancake 30, shadow_bias 0.05
    # (× 0.02 of the depth range), normal bias 1.5 texels, blur 1.5 × Soft Low's radius 2; project.godot: an
    # 8192 atlas halved for 4 splits, 32-bit depth.
    assert (s.split, s.splits, s.shadow_distance) == ("manual_range", (0.05, 0.15, 0.4, 1.0), 150.0)
    assert (s.fade_out, s.pancake, s.normal_offset, s.vogel_radius) == (0.1, 30.0, 1.5, 3.0)
    assert s.bias_depth_range == pytest.approx(0.001)
    assert (s.resolution, s.depth_format, s.cascades) == (4096, "float32", 4)
    assert (s.extent, s.snap, s.filter, s.cull) == (base.extent, base.snap, base.filter, base.cull)
    assert imported.origins["shadow_distance"] == "level.tscn: Sun.directional_shadow_max_distance = 150.0"


def test_a_light_with_nothing_changed_is_the_engine_preset(tmp_path):
    scene = tmp_path / "bare.tscn"
    scene.write_text('[gd_scene format=3]\n\n[node name="Sun" type="DirectionalLight3D"]\nshadow_enabled = true\n')
    assert import_settings([scene], engine="godot4").settings == engine_settings("godot4")


def test_unity_urp_asset_reads_three_cascades_and_medium_soft_shadows():
    imported = import_settings(_fixture("unity_urp"), engine="unity_urp")
    s = imported.settings
    assert (s.cascades, s.splits, s.shadow_distance, s.fade_out) == (3, (0.1, 0.3, 1.0), 100.0, 0.1)
    assert (s.resolution, s.filter, s.filter_size) == (2048, "pcf_tent_bilinear", 5)  # 4096 atlas: 2048 tiles
    assert any("m_ConservativeEnclosingSphere = 1" in item for item in imported.unmodelled)


def test_unity_builtin_reads_the_current_level_and_its_projection():
    imported = import_settings(_fixture("unity_builtin"), engine="unity_builtin")
    s = imported.settings
    # Level 1 "Ultra": Close Fit (projection 0), 2 cascades split at 0.25 of 120 m, High resolution (one halving).
    assert imported.preset == "unity_builtin_close" and s.stabilization == "none"
    assert (s.cascades, s.splits, s.shadow_distance) == (2, (0.25, 1.0), 120.0)
    assert s.resolution == engine_settings("unity_builtin_close").resolution // 2


def test_unreal_takes_the_light_the_epic_scalability_level_and_the_ini():
    imported = import_settings(_fixture("ue5"), engine="ue5")
    s = imported.settings
    assert (s.cascades, s.split, s.distribution_exponent, s.shadow_distance) == (4, "exponent", 2.5, 150.0)
    assert (s.blend_band, s.fade_out, s.resolution) == (0.2, 0.15, 4096)
    assert any("r.Shadow.Virtual.Enable = 0" in item for item in imported.unmodelled)
    assert any("ShadowBias = 0.600000" in item for item in imported.unmodelled)


def test_unreal_caps_cascades_and_scales_distance_at_a_lower_shadow_quality(tmp_path):
    engine_ini = tmp_path / "DefaultEngine.ini"
    engine_ini.write_text("[ScalabilityGroups]\nsg.ShadowQuality=2\n")
    files = [engine_ini, DATA / "ue5/DefaultScalability.ini", DATA / "ue5/DirectionalLight.t3d"]
    s = import_settings(files, engine="ue5").settings
    assert (s.cascades, s.shadow_distance) == (2, pytest.approx(150.0 * 0.85))


def test_filament_three_js_and_bevy_fixtures():
    f = import_settings(_fixture("filament"), engine="filament").settings
    assert (f.cascades, f.split, f.splits, f.shadow_distance) == (3, "manual_range", (0.1, 0.3, 1.0), 120.0)
    assert (f.stabilization, f.bias_constant, f.normal_offset, f.bias_slope) == ("exact", 0.002, 0.5, 2.0)
    assert f.bias_depth_range == 0.5 / 65536
    t = import_settings(_fixture("threejs_csm"), engine="threejs_csm").settings
    # shadowBias left at CSM's 1e-6 of lightFar - lightNear = 4999 m, away from the light.
    assert (t.cascades, t.resolution, t.pancake, t.split, t.lambda_) == (4, 1024, 100.0, "practical", 0.5)
    assert t.bias_constant == pytest.approx(-0.004999)
    b = import_settings(_fixture("bevy"), engine="bevy").settings
    # Bounds 8, 20, 50, 125: ratio 2.5 after the first, the builder's geometric series.
    assert (b.split, b.first_cascade_far, b.shadow_distance, b.cascades) == ("geometric", 8.0, 125.0, 4)
    assert (b.filter, b.resolution, b.blend_band) == ("pcf_bilinear", 4096, 0.2)


def test_stride_scene_reads_the_enabled_suns_shadow_map():
    imported = import_settings(_fixture("stride"), engine="stride")
    s = imported.settings
    # The Moon's light is disabled; the Sun's TwoCascades, XLarge (1024 · 2), ViewSnapping, a PCF of the
    # default Filter3x3, no blending.
    assert (s.cascades, s.resolution, s.stabilization, s.snap) == (2, 2048, "exact", "view")
    assert (s.filter, s.filter_size, s.blend_band) == ("pcf_castano", 3, 0.0)
    # Manual range from the camera's 0.5 m near plane: cascades end at 0.5 + s · (0.5 + 60) for s = 0.2, 0.9.
    assert (s.bounds, s.split) == ("frustum", "manual_range")
    np.testing.assert_allclose(s.splits, (0.2 / 0.9, 1.0), rtol=1e-12)
    assert s.shadow_distance == pytest.approx(0.5 + 0.9 * 60.5)
    assert s.bias_depth_range == 0.001 and s.normal_offset_m == pytest.approx(2 * 4.0 / 4096)
    # Untouched by the file: the preset's.
    assert (s.extent, s.depth_range, s.storage) == ("centroid", "sphere", "atlas")
    assert "Sun.Shadow.StabilizationMode" in imported.origins["snap"]
    assert not imported.unmodelled


def test_stride_members_without_a_csmlab_knob_are_listed_and_a_null_filter_is_one_bilinear_compare(tmp_path):
    text = (DATA / "stride/MainScene.sdscene").read_text()
    for old, new in (("IsAutomatic: false", "IsAutomatic: false\n" + " " * 36 + "ManualMinDistance: 2.0"),
                     ("ComputeTransmittance: false\n                                BiasParameters:\n",
                      "ComputeTransmittance: true\n                                BiasParameters:\n"),
                     ("Filter: !LightShadowMapFilterTypePcf {}\n" + " " * 32, "")):
        assert old in text
        text = text.replace(old, new, 1)
    path = tmp_path / "changed.sdscene"
    path.write_text(text)
    imported = import_settings([path], engine="stride")
    assert imported.settings.filter == "pcf_bilinear"
    listed = " ".join(imported.unmodelled)
    assert "Sun.Shadow.DepthRange.ManualMinDistance = 2.0" in listed
    assert "Sun.Shadow.ComputeTransmittance = True" in listed


@pytest.mark.parametrize("engine,text,name,key", [
    ("godot4", '{"cascades": 3}', "sun.tscn", "gd_scene"),
    ("godot4", "[gd_scene format=3]\n\n[node name=\"Sun\" type=\"DirectionalLight3D\"]\n"
               "directional_shadow_mode = 7\n", "sun.tscn", "Sun.directional_shadow_mode"),
    ("godot4", "[gd_scene format=3]\n[node name=\"Box\" type=\"MeshInstance3D\"]\n", "sun.tscn", "DirectionalLight3D"),
    ("unity_urp", "%YAML 1.1\n%TAG !u! tag:unity3d.com,2011:\n--- !u!47 &1\nQualitySettings:\n  m_CurrentQuality: 0\n",
     "UniversalRP.asset", "m_ShadowCascadeCount"),
    ("unity_urp", "m_ShadowDistance: 50\n", "UniversalRP.asset", "%YAML"),
    ("unity_builtin", "%YAML 1.1\n%TAG !u! tag:unity3d.com,2011:\n--- !u!114 &11400000\nMonoBehaviour:\n"
                      "  m_ShadowCascadeCount: 4\n", "QualitySettings.asset", "m_QualitySettings"),
    ("ue5", "Begin Map\nEnd Map\n", "Light.t3d", "Begin Actor"),
    ("filament", "{\"view\": {}}", "settings.json", "lighting"),
    ("filament", "{\"lighting\": {\"sunlight\": {\"shadowOptions\": {\"mapSize\": -4}}}}", "settings.json",
     "lighting.sunlight.shadowOptions.mapSize"),
    ("threejs_csm", "{\"mode\": \"cubic\"}", "csm.json", "mode"),
    ("bevy", "(resources: {}, entities: {1: (components: {\"a::B\": ()})})", "scene.scn.ron", "CascadeShadowConfig"),
    ("bevy", "(entities: {1: (components: {\"bevy_light::cascade::CascadeShadowConfig\": (bounds: [5.0, 2.0])})})",
     "scene.scn.ron", "CascadeShadowConfig.bounds"),
    ("stride", "!PrefabAsset\nId: 1\n", "level.sdscene", "Hierarchy.Parts"),
    ("stride", "Hierarchy:\n    Parts: []\n", "level.sdscene", "!SceneAsset"),
    ("stride", "!SceneAsset\nHierarchy:\n    Parts:\n        -   Entity:\n                Name: Sun\n"
               "                Components:\n                    ab: !LightComponent\n"
               "                        Type: !LightDirectional\n                            Shadow:\n"
               "                                CascadeCount: ThreeCascades\n", "level.sdscene",
     "Sun.Shadow.CascadeCount"),
    ("stride", "!SceneAsset\nHierarchy:\n    Parts: []\n", "level.sdscene", "LightDirectional"),
])
def test_a_malformed_or_foreign_file_names_the_file_and_key(engine, text, name, key, tmp_path):
    path = tmp_path / name
    path.write_text(text)
    with pytest.raises(InputError) as caught:
        import_settings([path], engine=engine)
    assert caught.value.file == str(path) and caught.value.field == key


def test_ron_reads_structs_tuples_maps_and_variants_and_locates_errors():
    value = parse_ron('// scene\n(a: [1, 2.5e1, -3], b: Some((x: "q")), c: None, d: {"k": Srgba((red: 1.0))},)')
    assert value == {"a": [1, 25.0, -3], "b": {"Some": {"x": "q"}}, "c": "None", "d": {"k": {"Srgba": {"red": 1.0}}}}
    with pytest.raises(InputError) as caught:
        parse_ron("(\n  a: [1, 2\n)", file="x.ron")
    assert caught.value.line == 3


def _csmlab(*args, cwd=ROOT):
    return subprocess.run([sys.executable, "-m", "csmlab.cli", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd, timeout=300)


def test_cli_import_writes_a_commented_preset_an_experiment_extends(tmp_path):
    out = tmp_path / "my_bevy.toml"
    done = _csmlab("import", "bevy", *_fixture("bevy"), "--out", out)
    assert done.returncode == 0, done.stderr
    text = out.read_text()
    assert 'first_cascade_far = 8.0' in text and "# from sun.scn.ron: CascadeShadowConfig.bounds[0] = 8.0" in text
    assert "engine default (configs/engines/bevy.toml)" in text
    assert "# not modelled: sun.scn.ron: CascadeShadowConfig.minimum_distance = 0.1" in text
    experiment = tmp_path / "uses.toml"
    experiment.write_text('extends = ["my_bevy.toml"]\n[camera]\npath = "walk"\n')
    method = load_experiment(experiment).methods[0]
    assert method.name == "my_bevy"
    imported = import_settings(_fixture("bevy"), engine="bevy").settings
    assert not _differences(imported, method.settings, lacking="")


def test_cli_import_of_a_bad_file_exits_2_with_one_line(tmp_path):
    bad = tmp_path / "broken.json"
    bad.write_text("{ not json")
    done = _csmlab("import", "threejs_csm", bad, "--out", tmp_path / "x.toml")
    assert done.returncode == 2 and done.stderr.count("\n") == 1 and str(bad) in done.stderr
    assert not (tmp_path / "x.toml").exists()
    near = tmp_path / "near.asset"
    near.write_text((DATA / "unity_urp/UniversalRP-HighQuality.asset").read_text().replace(
        "m_ShadowDistance: 100", "m_ShadowDistance: 0.05"))
    refused = _csmlab("import", "unity_urp", near, "--out", tmp_path / "x.toml")
    assert refused.returncode == 2 and f"{near}: m_ShadowDistance: expected a distance greater than near" in \
        refused.stderr
    unknown = _csmlab("import", "cryengine", bad, "--out", tmp_path / "x.toml")
    assert unknown.returncode == 2 and "expected one of ['bevy'" in unknown.stderr


REAL = {
    # One split (directional_shadow_mode = 0) fills Godot's default 4096 atlas: one 4096 map.
    "godot4": (["godot4/project.godot", "godot4/test.tscn"], {"cascades": 1, "shadow_distance": 32.0,
                                                              "resolution": 4096, "storage": "array"}),
    "unity_urp": (["unity_urp/SamplesPipelineAsset.asset"], {"splits": (0.16, 0.32, 0.64, 1.0), "fade_out": 0.1}),
    "unity_builtin": (["unity_builtin/QualitySettings.asset"], {"cascades": 4, "shadow_distance": 150.0}),
    # VRSandbox's sun: XLarge, a manual depth range of 20 m past the camera's default 0.1 m near plane.
    "stride": (["stride/VRSandbox.sdscene"], {"bounds": "frustum", "shadow_distance": 20.1, "resolution": 2048,
                                              "bias_depth_range": 0.001, "filter_size": 5}),
}
"""Files the engines wrote (tests/data/engines/README.md: repository, commit, path), and values they hold."""


@pytest.mark.parametrize("engine", sorted(REAL))
def test_files_the_engines_wrote_import(engine):
    names, expected = REAL[engine]
    paths = [VENDOR / name for name in names]
    missing = [str(p.relative_to(ROOT)) for p in paths if not p.is_file()]
    if missing:
        pytest.skip(f"{', '.join(missing)} absent: copy it from the repository tests/data/engines/README.md names")
    settings = import_settings(paths, engine=engine).settings
    for attribute, value in expected.items():
        assert getattr(settings, attribute) == value, attribute
