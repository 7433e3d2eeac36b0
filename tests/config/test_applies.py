"""A written ``[shadow]`` field that does not apply to its method is an input error naming it and why."""

from __future__ import annotations

import tomllib

import pytest

from csmlab.config import experiment_toml, load_experiment, method_preset_toml
from csmlab.errors import InputError
from csmlab.registry import parameters
from csmlab.settings import APPLIES, ShadowSettings

BASE = """
[scene]
kind = "plane_box"
[camera]
path = "walk"
frames = 2
"""

# Each conditional field: a value other than its default, and the fields that make it apply.
CASES = {
    "lambda": ("0.5", {}),
    "splits": ("[0.2, 0.5, 1.0]", {"split": '"manual"', "cascades": "3"}),
    "distribution_exponent": ("2.0", {"split": '"exponent"'}),
    "first_cascade_far": ("5.0", {"split": '"geometric"'}),
    "shadow_distance": ("150.0", {}),
    "max_shadow_distance": ("100000.0", {"shadow_distance_from": '"camera_far"'}),
    "cascade_borders": ("[0.1, 0.05, 0.0, 0.0]", {"selection": '"sphere_dither"'}),
    "levels": ("16", {"stabilization": '"quantized"'}),
    "quantized_base": ('"frustum"', {"stabilization": '"quantized"'}),
    "extent": ('"diagonal"', {}),
    "snap": ('"centre"', {}),
    "zoom_policy": ('"min_fov"', {}),
    "min_fov_deg": ("70.0", {"zoom_policy": '"min_fov"'}),
    "sun_update_frames": ("8", {"sun_policy": '"every_n"'}),
    "sun_step_deg": ("2.0", {"sun_policy": '"quantized"'}),
    "extent_hysteresis": ("0.2", {"stabilization": '"none"'}),
    "focus": ('"scene"', {"stabilization": '"none"'}),
    "lispsm_near_hint": ("2.0", {"stabilization": '"none"', "warp": '"lispsm"'}),
    "lispsm_far_hint": ("50.0", {"stabilization": '"none"', "warp": '"lispsm"'}),
    "rebase_distance": ("1024.0", {"engine_precision": '"camera_relative"'}),
    "vertex_snap": ('"window"', {}),
    "pancake": ("5.0", {"depth_range": '"slice"'}),
    "depth_clamp": ("false", {"depth_range": '"slice"'}),
    "light_near": ("2.0", {"depth_range": '"light_camera"'}),
    "light_far": ("900.0", {"depth_range": '"light_camera"'}),
    "hysteresis": ("0.2", {"bounds": '"sdsm"'}),
    "hold": ('"stepped"', {"bounds": '"sdsm"'}),
    "transition": ('"forward"', {"blend_band": "0.1"}),
    "blend_curve": ('"smoothstep"', {"blend_band": "0.1"}),
    "fade": ('"smoothstep"', {"fade_out": "0.1"}),
    "depth_quantization": ('"cascade"', {"depth_format": '"unorm16"'}),
    "atlas_layout": ('"1x4"', {"storage": '"atlas"'}),
    "filter_size": ("5", {}),
    "filter_sigma": ("2.0", {"filter": '"pcf_gaussian"'}),
    "filter_width_m": ("0.5", {"filter": '"pcf_tent"'}),
    "poisson_taps": ("8", {"filter": '"pcf_poisson"'}),
    "poisson_seed": ("3", {"filter": '"pcf_poisson"'}),
    "poisson_rotation": ('"pixel"', {"filter": '"pcf_poisson"'}),
    "vogel_taps": ("4", {"filter": '"pcf_vogel"'}),
    "vogel_radius": ("2.0", {"filter": '"pcf_vogel"'}),
    "vogel_angle": ("2.4", {"filter": '"pcf_vogel"'}),
    "vogel_scale": ('"first_split"', {"filter": '"pcf_vogel"'}),
    "light_size_deg": ("1.0", {"filter": '"pcss"'}),
    "moment_blur": ("3", {"filter": '"vsm"'}),
    "evsm_exponents": ("[20.0, 5.0]", {"filter": '"evsm2"'}),
    "vsm_min_variance": ("0.001", {"filter": '"evsm4"'}),
    "vsm_power": ("2.0", {"filter": '"vsm"'}),
    "vsm_bleed": ("0.2", {"filter": '"vsm"'}),
    "msm_moment_bias": ("3e-5", {"filter": '"msm"'}),
    "msm_depth_bias": ("0.001", {"filter": '"msm"'}),
    "moment_mips": ("true", {"filter": '"vsm"'}),
    "lod": ('"analytic"', {"filter": '"vsm"', "moment_mips": "true"}),
    "max_lod": ("2", {"filter": '"evsm2"', "moment_mips": "true"}),
    "anisotropy": ("4", {"filter": '"evsm4"', "moment_mips": "true"}),
    "virtual_resolution": ("1024", {"shadow_map": '"virtual_clipmap"'}),
    "page_size": ("64", {"shadow_map": '"virtual_clipmap"'}),
    "clipmap_first_level": ("4", {"shadow_map": '"virtual_clipmap"'}),
    "clipmap_last_level": ("20", {"shadow_map": '"virtual_clipmap"'}),
    "lod_bias": ("-1.5", {"shadow_map": '"virtual_clipmap"'}),
    "physical_pages": ("512", {"shadow_map": '"virtual_clipmap"'}),
}
# Where each does not apply: the defaults, but for the fields that the defaults make apply.
NOT_THERE = {"lambda": {"split": '"log"'}, "shadow_distance": {"shadow_distance_from": '"camera_far"'},
             "extent": {"stabilization": '"none"'}, "snap": {"stabilization": '"none"'},
             "filter_size": {"filter": '"pcf_bilinear"'},
             "vertex_snap": {"engine_precision": '"float32"'},
             "zoom_policy": {"shadow_map": '"virtual_clipmap"'}}


def load(tmp_path, text: str):
    path = tmp_path / "exp.toml"
    path.write_text(BASE + text)
    return load_experiment(path)


def lines(fields: dict) -> str:
    return "".join(f"{key} = {value}\n" for key, value in fields.items())


def test_every_conditional_field_is_a_setting_tested_over_settings_and_has_a_case():
    names = ShadowSettings.field_names()
    assert set(APPLIES) <= set(names) and set(CASES) == set(APPLIES)
    for rule in APPLIES.values():
        assert set(parameters(rule.test)) <= set(names) and rule.when


@pytest.mark.parametrize("key", sorted(CASES))
def test_a_method_field_that_does_not_apply_is_refused_naming_it_and_where_it_applies(tmp_path, key):
    value, context = CASES[key]
    where = load(tmp_path, "[[methods]]\nname = \"m\"\n" + lines({**context, key: value}))
    assert where.methods[0].settings != ShadowSettings()
    with pytest.raises(InputError) as caught:
        load(tmp_path, "[[methods]]\nname = \"m\"\n" + lines({**NOT_THERE.get(key, {}), key: value}))
    assert caught.value.field == f"methods.m.{key}" and caught.value.file == str(tmp_path / "exp.toml")
    assert f"expected {key} only with {APPLIES[key].when}, got " in caught.value.detail


def test_a_base_field_that_applies_to_one_method_or_sweep_point_passes_and_to_none_is_refused(tmp_path):
    load(tmp_path, '[shadow]\nmoment_blur = 3\n[[methods]]\nname = "a"\n[[methods]]\nname = "b"\nfilter = "vsm"\n')
    load(tmp_path, '[shadow]\nmoment_blur = 3\n[sweep]\nfilter = ["pcf", "evsm2"]\n')
    with pytest.raises(InputError) as caught:
        load(tmp_path, '[shadow]\nmoment_blur = 3\n[[methods]]\nname = "a"\n[[methods]]\nname = "b"\n'
                       'filter = "pcf_tent"\n')
    assert caught.value.field == "shadow.moment_blur"
    assert caught.value.detail.endswith('got filter = "pcf" or "pcf_tent" in every method')


def test_a_method_field_may_apply_at_one_sweep_point_only(tmp_path):
    load(tmp_path, '[[methods]]\nname = "a"\nlevels = 8\n[sweep]\nstabilization = ["exact", "quantized"]\n')
    with pytest.raises(InputError, match="at every sweep point"):
        load(tmp_path, '[[methods]]\nname = "a"\nlevels = 8\n[sweep]\nstabilization = ["exact", "none"]\n')


def test_a_swept_field_that_applies_nowhere_is_refused(tmp_path):
    with pytest.raises(InputError) as caught:
        load(tmp_path, "[sweep]\npoisson_taps = [4, 8]\n")
    assert caught.value.field == "sweep.poisson_taps"


def test_a_field_written_at_its_default_passes_and_the_resolved_experiment_loads_back(tmp_path):
    experiment = load(tmp_path, '[shadow]\nmoment_blur = 5\n[[methods]]\nname = "a"\nlevels = 64\n')
    assert experiment.methods[0].settings == ShadowSettings()
    resolved = tmp_path / "resolved.toml"
    resolved.write_text(experiment_toml(experiment))
    assert load_experiment(resolved).methods == experiment.methods


def test_a_presets_field_that_does_not_apply_names_the_preset(tmp_path):
    (tmp_path / "mine.toml").write_text('[[methods]]\nname = "m"\nfilter = "pcf"\nlight_size_deg = 2.0\n')
    (tmp_path / "uses.toml").write_text('extends = ["mine.toml"]\n' + BASE)
    with pytest.raises(InputError) as caught:
        load_experiment(tmp_path / "uses.toml")
    assert caught.value.file == str(tmp_path / "mine.toml") and caught.value.field == "methods.m.light_size_deg"
    assert caught.value.line == 4 and 'filter = "pcss"' in caught.value.detail


def test_a_tuned_field_must_apply_to_some_candidate(tmp_path):
    load(tmp_path, "[tune]\nlevels = [4, 16]\nstabilization = [\"exact\", \"quantized\"]\n")
    with pytest.raises(InputError) as caught:
        load(tmp_path, "[tune]\nlambda = { min = 0.5, max = 0.9 }\nsplit = [\"log\", \"exponent\"]\n")
    assert caught.value.field == "tune.lambda" and "in every candidate of base" in caught.value.detail


def test_a_method_preset_leaves_out_what_does_not_apply_and_extends_back_to_the_same_behaviour(tmp_path):
    settings = ShadowSettings(split="exponent", lambda_=0.3, filter="pcf_bilinear", filter_size=7, moment_blur=9)
    text = method_preset_toml("tuned", settings, description="a tune's pick")
    written = tomllib.loads(text)["methods"][0]
    assert {"lambda", "filter_size", "moment_blur", "levels"}.isdisjoint(written)
    assert written["distribution_exponent"] == 3.0 and written["filter"] == "pcf_bilinear"
    (tmp_path / "tuned.toml").write_text(text)
    (tmp_path / "uses.toml").write_text('extends = ["tuned.toml"]\n' + BASE)
    loaded = load_experiment(tmp_path / "uses.toml").methods[0].settings
    assert loaded == settings.replace(lambda_=0.75, filter_size=3, moment_blur=5)
