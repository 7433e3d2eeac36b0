"""Godot 4: project.godot and a scene read, the knobs its files cannot hold named (csmlab.engines.godot4)."""

from __future__ import annotations

import pytest
from tests.engines.engine_cases import DATA, FAR, NEAR, round_trip

from csmlab.engines import export, import_settings
from csmlab.engines.reading import engine_settings

FILES = [DATA / "godot4/project.godot", DATA / "godot4/level.tscn"]
"""The hand-written fixture (tests/data/engines/README.md)."""


def test_a_knob_the_files_cannot_hold_is_named_even_when_no_exporter_rule_names_it():
    # Godot has no extent knob: a diagonal extent must be reported, with Godot's own.
    snippet = export(engine_settings("godot4").replace(extent="diagonal"), near=NEAR, far=FAR, engine="godot4")
    assert "extent = 'diagonal' (the engine's is 'centroid')" in snippet.lacking


def test_godot_files_set_their_fields_and_leave_the_rest_at_the_preset():
    imported = import_settings(FILES, engine="godot4")
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


@pytest.mark.parametrize("quality, taps, radius", [(1, 1, 1.5), (2, 4, 2.0), (3, 8, 2.0), (4, 16, 3.0), (5, 32, 4.0)])
def test_every_soft_shadow_level_is_its_vogel_disk_times_the_lights_blur(tmp_path, quality, taps, radius):
    """directional_soft_shadow_filter_set_quality: (samples, quality radius) per level; soft_shadow_scale =
    shadow_blur · quality radius; Hard (0) is one hardware compare."""
    project = tmp_path / "project.godot"
    project.write_text("config_version=5\n\n[rendering]\n\n"
                       f"lights_and_shadows/directional_shadow/soft_shadow_filter_quality={quality}\n")
    scene = tmp_path / "sun.tscn"
    scene.write_text('[gd_scene format=3]\n\n[node name="Sun" type="DirectionalLight3D"]\nshadow_enabled = true\n'
                     'shadow_blur = 1.5\n')
    imported = import_settings([project, scene], engine="godot4")
    s = imported.settings.validated()
    assert (s.filter, s.vogel_taps, s.vogel_radius, s.vogel_angle) == ("pcf_vogel", taps, radius * 1.5, 2.4)
    assert not imported.unmodelled
    back, lacking = round_trip(s, "godot4", tmp_path)
    assert (back.vogel_taps, back.vogel_radius) == (taps, radius * 1.5) and "filter" not in lacking


def test_blend_splits_are_godots_band_and_hard_is_one_compare(tmp_path):
    """scene_forward_clustered.glsl light_process: blend_splits mixes split i + 1 in over the last tenth of split i
    (smoothstep) and leaves the disk unscaled by the first split."""
    from csmlab.cascades.fit import GODOT_BLEND_SPLITS

    scene = tmp_path / "sun.tscn"
    scene.write_text('[gd_scene format=3]\n\n[node name="Sun" type="DirectionalLight3D"]\nshadow_enabled = true\n'
                     'directional_shadow_blend_splits = true\n')
    imported = import_settings([scene], engine="godot4")
    s = imported.settings.validated()
    assert {k: getattr(s, k) for k in GODOT_BLEND_SPLITS} == GODOT_BLEND_SPLITS and s.vogel_scale == "none"
    assert not imported.unmodelled
    project = tmp_path / "project.godot"
    project.write_text("config_version=5\n\n[rendering]\n\nlights_and_shadows/directional_shadow/"
                       "soft_shadow_filter_quality=0\n")
    assert import_settings([project], engine="godot4").settings.filter == "pcf_bilinear"
