"""Stride: a .sdscene read, and its exported cascades placed as Stride places them (csmlab.engines.stride)."""

from __future__ import annotations

import re

import numpy as np
import pytest
from tests.engines.engine_cases import DATA, FAR, NEAR

from csmlab.cascades.splits import split_distances
from csmlab.engines import export, import_settings
from csmlab.settings import ShadowSettings

FILES = [DATA / "stride/MainScene.sdscene"]
"""The hand-written fixture (tests/data/engines/README.md)."""


def test_stride_scene_reads_the_enabled_suns_shadow_map():
    imported = import_settings(FILES, engine="stride")
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


def _stride_cascade_ends(text: str, *, near: float) -> np.ndarray:
    """Where Stride ends each cascade for an exported scene with a manual depth range: LightDirectionalShadowMapRenderer
    .ComputeCascadeSplits (stride3d/stride @34c7f40f) written out again from the C# source."""
    def member(name, default=None):
        found = re.search(rf"^\s*{name}: (\S+)$", text, re.M)
        return default if found is None else found.group(1)

    count = {"OneCascade": 1, "TwoCascades": 2, "FourCascades": 4}[member("CascadeCount", "FourCascades")]
    assert member("IsAutomatic") == "false"
    lo, hi = near + float(member("ManualMinDistance", 0.0)), near + float(member("ManualMaxDistance", 50.0))
    if "PartitionLogarithmic" in text:
        log_ratio = min(max(1.0 - float(member("PSSMFactor", 0.5)), 0.0), 1.0)
        distrib = np.arange(1, count + 1) / count
        return (lo + (hi - lo) * distrib) * (1.0 - log_ratio) + lo * (hi / lo) ** distrib * log_ratio
    used = {1: [1], 2: [1, 3], 4: [0, 1, 2, 3]}[count]
    return np.array([lo + float(member(f"SplitDistance{k}")) * hi for k in used])


@pytest.mark.parametrize("settings", [
    ShadowSettings(cascades=4, split="practical", lambda_=0.8, shadow_distance=120.0),
    ShadowSettings(cascades=2, split="exponent", distribution_exponent=2.5, shadow_distance=90.0),
    ShadowSettings(cascades=4, split="manual", splits=(5.0, 15.0, 40.0, 100.0), shadow_distance=100.0),
    ShadowSettings(cascades=1, split="uniform", shadow_distance=30.0),
])
def test_stride_places_the_exported_cascades_where_csmlab_does(settings):
    snippet = export(settings, near=NEAR, far=FAR, engine="stride")
    assert not any(item.startswith(("split", "cascades", "shadow_distance")) for item in snippet.lacking)
    np.testing.assert_allclose(_stride_cascade_ends(snippet.text, near=NEAR),
                               split_distances(near=NEAR, far=settings.shadow_distance, count=settings.cascades,
                                               method=settings.split, lambda_=settings.lambda_,
                                               splits=settings.splits,
                                               distribution_exponent=settings.distribution_exponent)[1:],
                               rtol=1e-9)
