"""Unity's built-in pipeline: QualitySettings.asset read (csmlab.engines.unity_builtin)."""

from __future__ import annotations

from tests.engines.engine_cases import DATA

from csmlab.engines import import_settings
from csmlab.engines.reading import engine_settings

FILES = [DATA / "unity_builtin/QualitySettings.asset"]
"""The hand-written fixture (tests/data/engines/README.md)."""


def test_unity_builtin_reads_the_current_level_and_its_projection():
    imported = import_settings(FILES, engine="unity_builtin")
    s = imported.settings
    # Level 1 "Ultra": Close Fit (projection 0), 2 cascades split at 0.25 of 120 m, High resolution (one halving).
    assert imported.preset == "unity_builtin_close" and s.stabilization == "none"
    assert (s.cascades, s.splits, s.shadow_distance) == (2, (0.25, 1.0), 120.0)
    assert s.resolution == engine_settings("unity_builtin_close").resolution // 2
