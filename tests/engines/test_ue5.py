"""Unreal Engine 5: its ini files and light read, the exponent its snippet carries (csmlab.engines.ue5)."""

from __future__ import annotations

import numpy as np
import pytest
from tests.engines.engine_cases import DATA, FAR, NEAR, engine_preset

from csmlab.cascades.splits import ue_split_fractions
from csmlab.engines import export, import_settings
from csmlab.settings import ShadowSettings

FILES = [DATA / "ue5/DefaultEngine.ini", DATA / "ue5/DefaultScalability.ini", DATA / "ue5/DirectionalLight.t3d"]
"""The hand-written fixture (tests/data/engines/README.md)."""


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


def test_unreal_preset_exports_its_own_distribution_exponent(tmp_path):
    # Unreal's geometric sum (ue_split_fractions) is one road, csmlab's exponent split the other: the
    # ue5 preset must come back as exponent 3 with no split error reported.
    settings = engine_preset("ue5", tmp_path)
    snippet = export(settings, near=NEAR, far=FAR, engine="ue5")
    assert f"CascadeDistributionExponent={settings.distribution_exponent:.2f}" in snippet.text
    assert not any("split distances" in item for item in snippet.lacking)
    assert f"DynamicShadowDistanceMovableLight={settings.shadow_distance * 100:.0f} " in snippet.text
    assert f"ShadowDistanceFadeoutFraction={settings.fade_out:g}" in snippet.text
    tuned = export(settings.replace(distribution_exponent=2.2), near=NEAR, far=FAR, engine="ue5")
    assert "CascadeDistributionExponent=2.20" in tuned.text and not any("split distances" in i for i in tuned.lacking)


def test_unreal_takes_the_light_the_epic_scalability_level_and_the_ini():
    imported = import_settings(FILES, engine="ue5")
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
