"""Bevy: a .scn.ron scene read (RON, csmlab.engines.ron), the bounds its snippet carries (csmlab.engines.bevy)."""

from __future__ import annotations

import numpy as np
import pytest
from tests.engines.engine_cases import DATA, FAR, NEAR, engine_preset, numbers

from csmlab.engines import export, import_settings
from csmlab.engines.ron import parse_ron
from csmlab.errors import InputError

FILES = [DATA / "bevy/sun.scn.ron"]
"""The hand-written fixture (tests/data/engines/README.md)."""


def test_bevy_preset_exports_its_first_cascade_bound(tmp_path):
    settings = engine_preset("bevy", tmp_path)
    text = export(settings, near=NEAR, far=FAR, engine="bevy").text
    assert numbers(text, "first_cascade_far_bound:")[0] == pytest.approx(settings.first_cascade_far)
    bounds = numbers(text, "bounds: vec!")[:settings.cascades]
    ratios = np.diff(np.log(bounds))  # geometric after the first bound: equal ratios
    assert bounds[-1] == pytest.approx(settings.shadow_distance) and np.allclose(ratios, ratios[0], atol=1e-3)
    nearer = export(settings.replace(first_cascade_far=6.0), near=NEAR, far=FAR, engine="bevy").text
    assert numbers(nearer, "bounds: vec!")[0] == pytest.approx(6.0)


def test_bevy_scene_reads_the_builders_geometric_bounds_and_hardware_filtering():
    b = import_settings(FILES, engine="bevy").settings
    # Bounds 8, 20, 50, 125: ratio 2.5 after the first, the builder's geometric series.
    assert (b.split, b.first_cascade_far, b.shadow_distance, b.cascades) == ("geometric", 8.0, 125.0, 4)
    assert (b.filter, b.resolution, b.blend_band) == ("pcf_bilinear", 4096, 0.2)


def test_ron_reads_structs_tuples_maps_and_variants_and_locates_errors():
    value = parse_ron('// scene\n(a: [1, 2.5e1, -3], b: Some((x: "q")), c: None, d: {"k": Srgba((red: 1.0))},)')
    assert value == {"a": [1, 25.0, -3], "b": {"Some": {"x": "q"}}, "c": "None", "d": {"k": {"Srgba": {"red": 1.0}}}}
    with pytest.raises(InputError) as caught:
        parse_ron("(\n  a: [1, 2\n)", file="x.ron")
    assert caught.value.line == 3
