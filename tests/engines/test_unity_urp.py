"""Unity URP: its pipeline asset read, the splits and atlas its snippet carries (csmlab.engines.unity_urp)."""

from __future__ import annotations

import numpy as np
import pytest
from tests.engines.engine_cases import DATA, FAR, NEAR, numbers

from csmlab.cascades.splits import split_distances
from csmlab.engines import export, import_settings
from csmlab.settings import ShadowSettings

FILES = [DATA / "unity_urp/UniversalRP-HighQuality.asset"]
"""The hand-written fixture (tests/data/engines/README.md)."""


@pytest.mark.parametrize("cascades", [2, 3, 4])
def test_unity_urp_splits_are_fractions_of_the_shadow_distance(cascades):
    settings = ShadowSettings(cascades=cascades, split="practical", lambda_=0.6, shadow_distance=150.0)
    z = split_distances(near=NEAR, far=150.0, count=cascades, method="practical", lambda_=0.6)
    text = export(settings, near=NEAR, far=FAR, engine="unity_urp").text
    fractions = numbers(text, f"cascade{cascades}Split =")
    assert np.allclose(fractions, z[1:-1] / 150.0, atol=1e-4)
    assert f"mainLightShadowmapResolution = {2 * settings.resolution};" in text


def test_unity_urp_asset_reads_three_cascades_and_medium_soft_shadows():
    imported = import_settings(FILES, engine="unity_urp")
    s = imported.settings
    assert (s.cascades, s.splits, s.shadow_distance, s.fade_out) == (3, (0.1, 0.3, 1.0), 100.0, 0.1)
    assert (s.resolution, s.filter, s.filter_size) == (2048, "pcf_tent_bilinear", 5)  # 4096 atlas: 2048 tiles
    assert any("m_ConservativeEnclosingSphere = 1" in item for item in imported.unmodelled)
