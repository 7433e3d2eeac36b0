"""Filament: the viewer's settings JSON read (csmlab.engines.filament)."""

from __future__ import annotations

from tests.engines.engine_cases import DATA

from csmlab.engines import import_settings

FILES = [DATA / "filament/settings.json"]
"""The hand-written fixture (tests/data/engines/README.md)."""


def test_filament_settings_read_range_splits_stable_and_the_biases():
    f = import_settings(FILES, engine="filament").settings
    assert (f.cascades, f.split, f.splits, f.shadow_distance) == (3, "manual_range", (0.1, 0.3, 1.0), 120.0)
    assert f.shadow_distance_from == "fixed"                                   # shadowFar 120 > 0
    # stable = true with "lispsm": false: an orthographic stable map (the file's lispsm read, not the preset's).
    assert (f.stabilization, f.warp, f.bias_constant, f.normal_offset) == ("exact", "none", 0.002, 0.5)
    # The polygon offset is the casters' raster bias, in DEPTH16 steps; nothing on the receiver.
    assert (f.caster_bias_units, f.caster_bias_slope, f.bias_slope, f.bias_depth_range) == (0.5, 2.0, 0.0, 0.0)
    f.validated()


def test_a_zero_shadow_far_is_the_cameras_far_plane_and_lispsm_warps_only_an_unstable_map(tmp_path):
    """ShadowMapManager: shadowFar 0 keeps the camera's far plane; ShadowMap::updateDirectional warps with LiSPSM
    only when the map is not stable."""
    import json

    def read(options):
        path = tmp_path / "settings.json"
        path.write_text(json.dumps({"lighting": {"sunlight": {"shadowOptions": options}}}))
        return import_settings([path], engine="filament").settings.validated()

    assert read({"shadowFar": 0.0}).shadow_distance_from == "camera_far"
    assert (read({"stable": False, "lispsm": True}).warp, read({"stable": True, "lispsm": True}).warp) == \
        ("lispsm", "none")
    assert read({"stable": True}).warp == "none"                      # the preset's lispsm, ignored when stable
