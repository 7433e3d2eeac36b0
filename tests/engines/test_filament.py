"""Filament: the viewer's settings JSON read (csmlab.engines.filament)."""

from __future__ import annotations

from engine_cases import DATA

from csmlab.engines import import_settings

FILES = [DATA / "filament/settings.json"]
"""The hand-written fixture (tests/data/engines/README.md)."""


def test_filament_settings_read_range_splits_stable_and_the_biases():
    f = import_settings(FILES, engine="filament").settings
    assert (f.cascades, f.split, f.splits, f.shadow_distance) == (3, "manual_range", (0.1, 0.3, 1.0), 120.0)
    assert (f.stabilization, f.bias_constant, f.normal_offset, f.bias_slope) == ("exact", 0.002, 0.5, 2.0)
    assert f.bias_depth_range == 0.5 / 65536
