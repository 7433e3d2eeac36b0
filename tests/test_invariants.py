"""The invariants a method promises, derived from its settings; a run records them and the gate holds them.

A rotated filter (Godot 4's per-pixel disk) on exact boxes promises nothing: its same-cascade flicker
is above 0 on a translating camera, so the gate must not hold it at 0. Tiny: the dolly of
``test_engine_presets`` (48×27 pixels, 64² maps, the terrain cut down), 4 frames.
"""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from csmlab.cascades.extent import EXTENT_METHODS
from csmlab.cascades.stabilize import SNAP_METHODS
from csmlab.cli import app
from csmlab.config import load_experiment
from csmlab.experiment import run_experiment
from csmlab.invariants import (FIXED_EXTENTS, FLICKER_SAME_ZERO, SCREEN_READS, WHOLE_TEXEL_SNAPS,
                               WORLD_LOCKED_DEPTH_FORMATS, WORLD_LOCKED_READS, WorkloadFacts, promised_invariants)
from csmlab.lookup_choices import FILTER_METHODS
from csmlab.settings import ShadowSettings
from csmlab.storage import DEPTH_FORMATS

STILL = WorkloadFacts(light_static=True, fov_fixed=True)

TINY = """
extends = ["engines/godot4", "methods/exact"]

[scene]
kind = "terrain"
resolution = 24
trees = 60
ring_trees = 60

[camera]
path = "dolly"
speed = 6.0
frames = 4
width = 48
height = 27
far = 400.0

[light]
elevation_deg = 40.0
azimuth_deg = 30.0

[shadow]
resolution = 64
"""


def promise(settings=ShadowSettings(), workload=STILL):
    return promised_invariants(settings, workload=workload)[FLICKER_SAME_ZERO]


def test_exact_with_a_fixed_extent_float64_and_a_world_locked_lookup_promises_zero_flicker():
    kept = promise()
    assert kept.promised and (kept.metric, kept.value) == ("flicker_same", 0.0)
    assert "static light" in kept.why
    for snap in WHOLE_TEXEL_SNAPS:
        for extent in FIXED_EXTENTS:
            for depth_format in WORLD_LOCKED_DEPTH_FORMATS:
                assert promise(ShadowSettings(snap=snap, extent=extent, depth_format=depth_format)).promised


@pytest.mark.parametrize("changes, workload, named", [
    ({}, WorkloadFacts(light_static=False, fov_fixed=True), "the light moves"),
    ({}, WorkloadFacts(light_static=True, fov_fixed=False), "field of view changes"),
    ({"stabilization": "quantized"}, STILL, "stabilization = 'quantized'"),
    ({"stabilization": "none"}, STILL, "stabilization = 'none'"),
    ({"bounds": "sdsm"}, STILL, "bounds = 'sdsm'"),
    ({"engine_precision": "float32"}, STILL, "engine_precision = 'float32'"),
    ({"engine_precision": "camera_relative"}, STILL, "engine_precision = 'camera_relative'"),
    ({"filter": "pcf_poisson", "filter_size": 5, "poisson_rotation": "pixel"}, STILL, "screen pixel"),
    ({"filter": "vsm", "moment_mips": True}, STILL, "pixel quad"),
    ({"depth_range": "slice", "pancake": 20.0}, STILL, "depth_range = 'slice'"),
    ({"depth_range": "slice", "depth_clamp": False}, STILL, "depth_range = 'slice'"),
])
def test_each_condition_that_fails_withdraws_the_promise_and_is_named(changes, workload, named):
    withdrawn = promise(ShadowSettings(**changes), workload)
    assert not withdrawn.promised and named in withdrawn.why


def test_every_failing_condition_is_named():
    why = promise(ShadowSettings(stabilization="none", engine_precision="float32", depth_range="slice")).why
    assert why.count(";") == 2 and "stabilization" in why and "float32" in why and "slice" in why


def test_the_promises_choices_are_reviewed_against_every_registered_choice():
    """A snap, extent, depth format or filter input added fails here until it is judged world-locked or not."""
    assert set(WHOLE_TEXEL_SNAPS) == set(SNAP_METHODS)
    assert set(FIXED_EXTENTS) == set(EXTENT_METHODS)
    assert set(WORLD_LOCKED_DEPTH_FORMATS) == set(DEPTH_FORMATS)
    reads = set()
    for record in FILTER_METHODS.values():
        for rotation in ("none", "pixel"):
            for mips in (False, True):
                reads |= record.reads_of(ShadowSettings(poisson_rotation=rotation, moment_mips=mips))
    assert reads == set(WORLD_LOCKED_READS) | set(SCREEN_READS)


@pytest.mark.parametrize("filter", sorted(FILTER_METHODS))
def test_every_filter_without_screen_input_keeps_the_promise(filter):
    assert promise(ShadowSettings(filter=filter, filter_size=5)).promised

@pytest.fixture(scope="module")
def godot4_run(tmp_path_factory):
    root = tmp_path_factory.mktemp("godot4")
    (root / "exp.toml").write_text(TINY)
    run_experiment(load_experiment(root / "exp.toml"), out_dir=root / "run")
    return root


def test_the_run_records_each_methods_promise_and_why(godot4_run):
    recorded = json.loads((godot4_run / "run" / "summary.json").read_text())["invariants"]
    assert set(recorded) == {"godot4", "exact"}
    (godot4,) = recorded["godot4"].values()
    (exact,) = recorded["exact"].values()
    assert not godot4[FLICKER_SAME_ZERO]["promised"] and exact[FLICKER_SAME_ZERO]["promised"]
    assert "filter = 'pcf_vogel' reads each receiver's screen pixel" in godot4[FLICKER_SAME_ZERO]["why"]
    assert "depth_range = 'sphere'" in godot4[FLICKER_SAME_ZERO]["why"]


def test_a_rotated_filter_on_exact_boxes_passes_the_gate_against_its_own_baseline(godot4_run):
    """Before the promise was derived from the settings, ``exact`` stabilization alone promised zero
    flicker and this run failed against its own baseline (exit 1, "invariant broken")."""
    summary = json.loads((godot4_run / "run" / "summary.json").read_text())
    assert summary["methods"]["godot4"]["flicker_same"] > 0.0
    baseline = godot4_run / "baseline.json"
    made = CliRunner().invoke(app, ["baseline", str(godot4_run / "run"), "--out", str(baseline)])
    assert made.exit_code == 0, made.output
    outcome = CliRunner().invoke(app, ["regress", str(godot4_run / "run"), "--baseline", str(baseline)])
    assert outcome.exit_code == 0, outcome.output
    rows = json.loads((godot4_run / "run" / "regress.json").read_text())["rows"]
    held = [(r["method"], r["verdict"]) for r in rows if r["direction"] == "zero"]
    assert held == [("exact", "invariant")]
