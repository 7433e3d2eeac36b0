"""What every engine promises, parametrized over the engines (each engine's own properties: test_<engine>.py).

Engine snippets: the splits each engine is given reproduce csmlab's, and every missing knob is named.
csmlab import: engine files in, a method preset out; and every engine's files read back what tune exports.
The fixtures under tests/data/engines/<engine>/ are small files written by hand in each engine's own
format (tests/data/engines/README.md); the values the tests expect are the numbers written in them,
converted by the engine's documented rules. Files the engines and their demo projects wrote
themselves are read from the git-ignored tests/data/engines/vendor/ when present.
"""

from __future__ import annotations

import re
import subprocess
import sys
import tomllib

import numpy as np
import pytest
from tests.engines.engine_cases import DATA, FAR, NEAR, ROOT, VENDOR, differences, numbers, round_trip

from csmlab.cascades.splits import split_distances
from csmlab.config import load_experiment
from csmlab.engines import ENGINES, EXPORT_METHODS, IMPORT_METHODS, export, import_settings
from csmlab.engines.reading import engine_settings
from csmlab.errors import InputError
from csmlab.settings import SETTING_GROUPS, ShadowSettings

PRESETS = [(engine, preset) for engine, record in IMPORT_METHODS.items() for preset in record.presets]
"""Every engine with its files and each preset they are written against."""


def test_every_engine_module_is_registered_under_its_own_name_with_its_presets():
    # A module declaring an ENGINE that csmlab/engines/__init__.py leaves out of ENGINES would be tested by nothing.
    declared = {path.stem for path in (ROOT / "csmlab" / "engines").glob("*.py") if "\nENGINE = " in path.read_text()}
    assert declared == set(ENGINES)
    for name, engine in ENGINES.items():
        assert engine.name == name and engine.export.__module__ == f"csmlab.engines.{name}"
        presets = engine.files.presets if engine.files is not None else ()
        assert all((ROOT / "configs" / "engines" / f"{preset}.toml").is_file() for preset in presets), name
        assert all(engine.files.preset(engine_settings(preset)) == preset for preset in presets), name


def test_every_importer_has_an_exporter_and_its_files():
    assert set(IMPORT_METHODS) <= set(EXPORT_METHODS)
    for engine in IMPORT_METHODS:
        snippet = export(ShadowSettings(), near=NEAR, far=FAR, engine=engine)
        assert snippet.files, engine


@pytest.mark.parametrize("engine,preset", PRESETS)
def test_an_engine_preset_comes_back_field_by_field_through_its_engines_files(engine, preset, tmp_path):
    settings = engine_settings(preset)
    back, lacking = round_trip(settings, engine, tmp_path)
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
        back, lacking = round_trip(settings, engine, tmp_path)
        assert not differences(settings, back, lacking), (engine, settings)


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


def _csmlab(*args, cwd=ROOT):
    return subprocess.run([sys.executable, "-m", "csmlab.cli", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd, timeout=300)


def test_cli_import_writes_a_commented_preset_an_experiment_extends(tmp_path):
    out = tmp_path / "my_bevy.toml"
    done = _csmlab("import", "bevy", *[DATA / "bevy/sun.scn.ron"], "--out", out)
    assert done.returncode == 0, done.stderr
    text = out.read_text()
    assert 'first_cascade_far = 8.0' in text and "# from sun.scn.ron: CascadeShadowConfig.bounds[0] = 8.0" in text
    assert "engine default (configs/engines/bevy.toml)" in text
    assert "# not modelled: sun.scn.ron: CascadeShadowConfig.minimum_distance = 0.1" in text
    experiment = tmp_path / "uses.toml"
    experiment.write_text('extends = ["my_bevy.toml"]\n[camera]\npath = "walk"\n')
    method = load_experiment(experiment).methods[0]
    assert method.name == "my_bevy"
    imported = import_settings([DATA / "bevy/sun.scn.ron"], engine="bevy").settings
    assert not differences(imported, method.settings, lacking="")


@pytest.mark.slow
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


def test_godot_and_bevy_and_threejs_carry_the_same_boundaries():
    settings = ShadowSettings(cascades=4, split="log", shadow_distance=100.0)
    z = split_distances(near=NEAR, far=100.0, count=4, method="log")
    godot = export(settings, near=NEAR, far=FAR, engine="godot4").text
    # Godot's splits are fractions of the range from the near plane: distances[i + 1] = min_distance + split · range.
    assert np.allclose([numbers(godot, f"directional_shadow_split_{i} =")[0] for i in (1, 2, 3)],
                       (z[1:-1] - NEAR) / (100.0 - NEAR), atol=1e-4)
    bevy = export(settings, near=NEAR, far=FAR, engine="bevy").text
    assert np.allclose(numbers(bevy, "bounds: vec!")[:4], z[1:], atol=1e-3)
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
    from csmlab.engines.godot4 import GODOT_SOFT_LOW
    from csmlab.engines.threejs_csm import THREEJS_PCF

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
    from csmlab.engines.bevy import BEVY_EXACT, BEVY_FILTERING
    from csmlab.engines.ue5 import UE5_FILTER
    from csmlab.engines.unity_urp import URP_FILTER
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


MANY_LACKING = ShadowSettings(cascades=3, cascade_resolutions=(2048, 1024, 512), stabilization="none", fit="sphere",
                              selection="map", depth_format="float16", filter="pcf_vogel", blend_band=0.1,
                              bias_slope=2.0, storage="array")
"""A setting that no engine holds whole: knobs of many groups lacking at once."""


@pytest.mark.parametrize("engine", sorted(EXPORT_METHODS))
def test_lacking_lines_come_group_by_group_in_the_documented_order(engine):
    # The oracle: the position in docs/design.md's order (group by group) of the first [shadow] field a line names.
    documented = [name for group in SETTING_GROUPS for name in group.fields]
    lacking = export(MANY_LACKING, near=NEAR, far=FAR, engine=engine).lacking
    places = [next((documented.index(word) for word in re.findall(r"\b[a-z_]+(?= = )", item) if word in documented),
                   len(documented)) for item in lacking]
    assert len(lacking) >= 3 and places == sorted(places), (engine, lacking)
