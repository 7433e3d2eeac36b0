"""The experiment schema: preset merging, sweep expansion, hashes, the resolved TOML, located errors."""

from __future__ import annotations

import re
import tomllib

import pytest

from csmlab.config import (CONFIGS_DIR, CameraConfig, LightConfig, ReportConfig, config_hash, experiment_toml,
                           find_experiment, list_experiments, list_presets, load_experiment, load_tolerances,
                           sweep_points, workload_hash)
from csmlab.errors import InputError
from csmlab.settings import ShadowSettings

BASE = """
[scene]
kind = "plane_box"
[camera]
path = "walk"
frames = 4
"""


def write(tmp_path, text: str, name: str = "exp.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_presets_merge_in_order_and_methods_merge_by_name(tmp_path):
    path = write(tmp_path, 'extends = ["methods/exact", "methods/quantized", "methods/none"]\n' + BASE + """
[[methods]]
name = "quantized"
levels = 16
[[methods]]
name = "extra"
filter = "none"
""")
    experiment = load_experiment(path)
    assert [m.name for m in experiment.methods] == ["exact", "quantized", "none", "extra"]
    quantized = experiment.methods[1].settings
    assert (quantized.stabilization, quantized.levels) == ("quantized", 16)
    assert experiment.methods[3].settings == ShadowSettings(filter="none")


def test_then_extends_merges_presets_after_the_file_in_memory_as_a_file_extending_both_would(tmp_path):
    path = write(tmp_path, 'name = "mine"\nextends = ["methods/exact"]\n' + BASE + '[shadow]\nresolution = 512\n'
                           '[[methods]]\nname = "exact"\nfilter = "none"\n')
    preset = write(tmp_path, '[shadow]\ncascades = 3\n[[methods]]\nname = "exact"\nlevels = 8\n'
                             'stabilization = "quantized"\n[[methods]]\nname = "late"\nfilter = "pcf_tent"\n',
                   name="late.toml")
    both = write(tmp_path, f'extends = ["{path.name}", "{preset.name}"]\n', name="both.toml")
    loaded, expected = load_experiment(path, then_extends=(preset,)), load_experiment(both)
    assert loaded.methods == expected.methods and loaded.shadow == expected.shadow
    assert [m.name for m in loaded.methods] == ["exact", "late"] and loaded.shadow.cascades == 3
    assert loaded.name == "mine"  # the file keeps its own name


def test_later_preset_wins_and_the_experiment_wins_over_all(tmp_path):
    path = write(tmp_path, 'extends = ["scenes/terrain", "scenes/city", "lights/sun_40", "lights/low_sun"]\n' + """
[camera]
path = "walk"
[light]
azimuth_deg = 5.0
""")
    experiment = load_experiment(path)
    assert experiment.scene.kind == "city"
    assert (experiment.light.elevation_deg, experiment.light.azimuth_deg) == (12.0, 5.0)


def test_name_and_description_are_not_inherited_from_presets(tmp_path):
    path = write(tmp_path, 'extends = ["methods/exact"]\n' + BASE, name="mine.toml")
    experiment = load_experiment(path)
    assert (experiment.name, experiment.description) == ("mine", "")


def test_presets_are_read_afresh_not_changed_by_a_load(tmp_path):
    overriding = write(tmp_path, 'extends = ["methods/quantized"]\n' + BASE
                       + '[[methods]]\nname = "quantized"\nlevels = 2\n')
    plain = write(tmp_path, 'extends = ["methods/quantized"]\n' + BASE, name="plain.toml")
    preset_text = (CONFIGS_DIR / "methods" / "quantized.toml").read_text()
    assert load_experiment(overriding).methods[0].settings.levels == 2
    assert load_experiment(plain).methods[0].settings.levels == 64
    assert (CONFIGS_DIR / "methods" / "quantized.toml").read_text() == preset_text


def test_sweep_is_the_cartesian_product_last_field_fastest(tmp_path):
    path = write(tmp_path, BASE + '[[methods]]\nname = "m"\nresolution = 999\n'
                 '[sweep]\nresolution = [64, 128]\nlambda = [0.5, 1.0, 0.25]\n')
    experiment = load_experiment(path)
    labels = [label for label, _ in experiment.points()]
    assert labels == [f"resolution={r}/lambda={lam!r}" for r in (64, 128) for lam in (0.5, 1.0, 0.25)]
    settings = [(v.settings.resolution, v.settings.lambda_) for v in experiment.variants()]
    assert settings == [(r, lam) for r in (64, 128) for lam in (0.5, 1.0, 0.25)]


def test_no_sweep_is_one_base_point_and_no_methods_is_one_base_method(tmp_path):
    experiment = load_experiment(write(tmp_path, BASE))
    assert sweep_points({}) == [("base", {})]
    assert [(v.method, v.point) for v in experiment.variants()] == [("base", "base")]


def test_config_hash_follows_shadow_settings_but_workload_hash_does_not(tmp_path):
    first = load_experiment(write(tmp_path, 'extends = ["methods/exact"]\n' + BASE))
    second = load_experiment(write(tmp_path, 'extends = ["methods/exact"]\n' + BASE + "[shadow]\nresolution = 512\n",
                                   name="b.toml"))
    assert config_hash(first) == config_hash(load_experiment(tmp_path / "exp.toml"))
    assert config_hash(first) != config_hash(second)
    assert workload_hash(first, frames=4) == workload_hash(second, frames=4)


def test_workload_hash_follows_scene_camera_light_and_frame_count(tmp_path):
    base = load_experiment(write(tmp_path, BASE))
    key = workload_hash(base, frames=4)
    assert workload_hash(base, frames=5) != key
    for extra in ('[light]\nelevation_deg = 41.0\n', ):
        assert workload_hash(load_experiment(write(tmp_path, BASE + extra, name="l.toml")), frames=4) != key
    moved = BASE.replace('path = "walk"', 'path = "walk"\nseed = 2')
    assert workload_hash(load_experiment(write(tmp_path, moved, name="c.toml")), frames=4) != key
    scene = BASE.replace('kind = "plane_box"', 'kind = "plane_box"\nbox_size = 3.0')
    assert workload_hash(load_experiment(write(tmp_path, scene, name="s.toml")), frames=4) != key


def test_resolved_toml_loads_back_to_the_same_experiment(tmp_path):
    original = load_experiment(find_experiment("recorded_teapot"))
    text = experiment_toml(original)
    tomllib.loads(text)
    again = load_experiment(write(tmp_path, text, name="resolved.toml"))
    assert config_hash(again) == config_hash(original)
    assert again.methods == original.methods and again.camera == original.camera


def test_frames_override_replaces_the_cap(tmp_path):
    assert load_experiment(write(tmp_path, BASE), frames=2).camera.frames == 2


def test_every_preset_and_experiment_loads_and_is_described():
    presets, experiments = list_presets(), list_experiments()
    assert {"methods/exact", "methods/quantized", "methods/none"} <= set(presets)
    assert {"default", "gate", "dueling", "fence_shimmer", "sweep_resolution"} <= set(experiments)
    assert all(presets.values()) and all(experiments.values())
    for name in experiments:
        load_experiment(find_experiment(name))


def test_default_experiment_is_the_one_the_issue_asks_for():
    experiment = load_experiment(find_experiment(None))
    assert [m.name for m in experiment.methods] == ["exact", "quantized", "none"]
    assert (experiment.scene.kind, experiment.camera.path, experiment.camera.frames) == ("terrain", "walk", 120)
    assert (experiment.shadow.cascades, experiment.shadow.resolution) == (4, 1024)
    assert (experiment.camera.width, experiment.camera.height) == (640, 360)


@pytest.mark.parametrize("text, field, words", [
    ('[scene]\nkind = "plane_box"\n[camera]\npath = "walk"\nfov_y_degs = 50.0\n', "camera.fov_y_degs", "fov_y_deg"),
    ('[camera]\npath = "walk"\nframes = "ten"\n', "camera.frames", "an integer"),
    ('[camera]\npath = "walk"\nframes = 0\n', "camera.frames", "at least 1"),
    ('[camera]\npath = "walky"\n', "camera.path", "walk"),
    ('[scene]\nkind = "terain"\n[camera]\npath = "walk"\n', "scene.kind", "terrain"),
    ('[camera]\npath = "walk"\n[light]\ndirection = [0.0, 0.0, 0.0]\n', "light.direction", "non-zero"),
    ('[camera]\nfile = "nowhere.txt"\n', "camera.file", "existing file"),
    ('[camera]\npath = "walk"\n[shadow]\nlevels = 0\n', "shadow.levels", "positive integer"),
    ('[camera]\npath = "walk"\n[[methods]]\nname = "a"\nfilter = "box"\n', "methods.a.filter", "pcf"),
    ('[camera]\npath = "walk"\n[sweep]\nresolution = []\n', "sweep.resolution", "non-empty list"),
    ('[camera]\npath = "walk"\n[regress]\nflickr = { abs = 0.1 }\n', "regress.flickr", "flicker"),
])
def test_bad_field_names_file_line_field_and_expectation(tmp_path, text, field, words):
    path = write(tmp_path, text)
    with pytest.raises(InputError) as caught:
        load_experiment(path)
    error = caught.value
    assert error.file == str(path.resolve()) and error.field == field and words in str(error)
    key = field.split(".")[-1]
    assert error.line is not None and key in path.read_text().splitlines()[error.line - 1]


def test_malformed_toml_names_its_line(tmp_path):
    path = write(tmp_path, '[camera]\npath = "walk"\nframes = = 3\n')
    with pytest.raises(InputError, match="valid TOML") as caught:
        load_experiment(path)
    assert caught.value.line == 3


def test_error_in_a_preset_names_the_preset_file(tmp_path):
    write(tmp_path, '[[methods]]\nname = "bad"\nlevels = -1\n', name="preset.toml")
    path = write(tmp_path, 'extends = ["preset.toml"]\n[camera]\npath = "walk"\n')
    with pytest.raises(InputError) as caught:
        load_experiment(path)
    assert caught.value.file == str(tmp_path / "preset.toml") and caught.value.field == "methods.bad.levels"


def test_unknown_preset_and_cycles_are_refused(tmp_path):
    with pytest.raises(InputError, match="methods/exact"):
        load_experiment(write(tmp_path, 'extends = ["methods/exakt"]\n'))
    write(tmp_path, 'extends = ["b.toml"]\n', name="a.toml")
    write(tmp_path, 'extends = ["a.toml"]\n', name="b.toml")
    with pytest.raises(InputError, match="cycle"):
        load_experiment(tmp_path / "a.toml")


def test_tolerances_file_is_validated(tmp_path):
    good = write(tmp_path, "[regress]\nflicker_same = { abs = 0.0, rel = 0.0 }\n", name="tol.toml")
    assert load_tolerances(good) == {"flicker_same": {"abs": 0.0, "rel": 0.0}}
    with pytest.raises(InputError, match="non-negative"):
        load_tolerances(write(tmp_path, "rho_median = { rel = -1 }\n", name="bad.toml"))


@pytest.mark.parametrize("record, field, message", [
    (CameraConfig(frames=0), "frames", "expected at least 1 frame, got 0"),
    (LightConfig(elevation_deg=95.0), "elevation_deg", "expected an angle in [-90, 90] degrees, got 95.0"),
    (ReportConfig(snapshot_frames=(3, -1)), "snapshot_frames", "expected frame numbers >= 0, got [3, -1]"),
])
def test_a_record_made_in_python_is_held_to_the_checks_its_table_is(record, field, message):
    with pytest.raises(ValueError, match=re.escape(f"{field}: {message}")):
        record.validated()
    assert CameraConfig().validated() == CameraConfig()
