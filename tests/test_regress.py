"""The regression gate: direction-aware tolerances, the exact invariant, workload checks, the real gate."""

from __future__ import annotations

import json
import math

import pytest
from typer.testing import CliRunner

from csmlab.cli import app
from csmlab.config import EXPERIMENTS_DIR, load_experiment, load_tolerances
from csmlab.errors import InputError
from csmlab.experiment import build_workload, run_experiment
from csmlab.regress import TOLERANCES, compare, make_baseline, regress, tolerance_for, write_baseline

GATE = EXPERIMENTS_DIR / "gate.toml"
COMMITTED = EXPERIMENTS_DIR.parent / "reports" / "baselines" / "gate.json"
GATE_FRAMES = 4

STABILIZATION = {"exact": {"base": "exact"}, "none": {"base": "none"}}


def promise(promised: bool, why: str = "") -> dict:
    return {"flicker_same_zero": {"promised": promised, "metric": "flicker_same", "value": 0.0, "why": why}}


def summary(values: dict, *, promised=("exact",)) -> dict:
    methods = {m: {**v, "frames": 10} for m, v in values.items()}
    return {"methods": methods, "points": {"base": methods}, "light_moves": False,
            "point_fields": {"base": {}}, "stabilization": STABILIZATION,
            "invariants": {m: {"base": promise(m in promised, "world-locked")} for m in values}}


def verdicts(now: dict, base: dict, **kwargs) -> dict:
    return {(c.method, c.metric, c.direction): c.verdict for c in compare(summary(now), summary(base), **kwargs)}


def test_flicker_may_fall_but_not_rise_beyond_tolerance():
    base = {"none": {"flicker": 0.010}}
    allowed = TOLERANCES["flicker"].allowed(0.010)
    assert verdicts({"none": {"flicker": 0.010 + 1.01 * allowed}}, base)[("none", "flicker", "lower")] == "regression"
    assert verdicts({"none": {"flicker": 0.010 + 0.99 * allowed}}, base)[("none", "flicker", "lower")] == "ok"
    assert verdicts({"none": {"flicker": 0.001}}, base)[("none", "flicker", "lower")] == "better"


def test_median_rho_may_not_move_away_from_one_and_memory_may_not_grow():
    base = {"none": {"rho_median": 1.0, "memory_bytes": 4096.0, "rho_median_c1": 2.0, "rho_median_c2": 0.5}}
    now = {"none": {"rho_median": 0.99, "memory_bytes": 4097.0, "rho_median_c1": 2.5, "rho_median_c2": 0.6}}
    got = verdicts(now, base)
    assert got[("none", "rho_median", "one")] == "regression"
    assert got[("none", "memory_bytes", "lower")] == "regression"
    # Above 1 a rise is a move away from the 1:1 ideal (wasted resolution), below 1 a rise is a move toward it.
    assert got[("none", "rho_median_c1", "one")] == "regression"
    assert got[("none", "rho_median_c2", "one")] == "better"
    toward = verdicts({"none": {"rho_median": 1.5}}, {"none": {"rho_median": 2.0}})
    assert toward[("none", "rho_median", "one")] == "better"
    across = verdicts({"none": {"rho_median": 1.1}}, {"none": {"rho_median": 0.9}})
    assert across[("none", "rho_median", "one")] == "better"


def test_rho_p95_is_judged_by_its_distance_from_one():
    got = verdicts({"none": {"rho_p95": 3.5}, "exact": {"rho_p95": 1.5}},
                   {"none": {"rho_p95": 3.0}, "exact": {"rho_p95": 2.0}})
    assert got[("none", "rho_p95", "one")] == "regression" and got[("exact", "rho_p95", "one")] == "better"


def test_closest_to_one_tolerance_is_a_relative_step_on_either_side():
    allowed = TOLERANCES["rho_median"].allowed(0.5)
    assert verdicts({"none": {"rho_median": 0.5 - 0.9 * allowed}}, {"none": {"rho_median": 0.5}})[
        ("none", "rho_median", "one")] == "ok"
    assert verdicts({"none": {"rho_median": 0.5 - 1.1 * allowed}}, {"none": {"rho_median": 0.5}})[
        ("none", "rho_median", "one")] == "regression"
    allowed = TOLERANCES["rho_median"].allowed(2.0)
    assert verdicts({"none": {"rho_median": 2.0 + 0.9 * allowed}}, {"none": {"rho_median": 2.0}})[
        ("none", "rho_median", "one")] == "ok"
    assert verdicts({"none": {"rho_median": 2.0 + 1.1 * allowed}}, {"none": {"rho_median": 2.0}})[
        ("none", "rho_median", "one")] == "regression"


def test_per_cascade_columns_take_their_metric_row_and_overrides_apply():
    assert tolerance_for("utilization_c3") == TOLERANCES["utilization"]
    assert tolerance_for("flicker", {"flicker": {"abs": 0.5}}).abs == 0.5
    assert tolerance_for("unheard_of").direction == "either"
    loose = verdicts({"none": {"flicker": 0.4}}, {"none": {"flicker": 0.1}}, tolerances={"flicker": {"abs": 0.5}})
    assert loose[("none", "flicker", "lower")] == "ok"


def test_a_vanished_metric_or_method_is_a_failure():
    got = verdicts({"none": {}}, {"none": {"flicker": 0.1}, "exact": {"flicker": 0.0}})
    assert got[("none", "flicker", "lower")] == "missing"
    assert got[("exact", "flicker", "lower")] == "missing"
    assert verdicts({"none": {"flicker": None}}, {"none": {"flicker": None}})[("none", "flicker", "lower")] == "n/a"


def test_a_promised_invariant_is_held_exactly_whatever_the_baseline_and_nothing_else_is():
    tiny = 1e-12
    got = verdicts({"exact": {"flicker_same": tiny}, "none": {"flicker_same": 0.2}},
                   {"exact": {"flicker_same": tiny}, "none": {"flicker_same": 0.2}})
    assert got[("exact", "flicker_same", "lower")] == "ok"
    assert got[("exact", "flicker_same", "zero")] == "invariant broken"
    assert ("none", "flicker_same", "zero") not in got
    # A method named and stabilized exact that promises nothing (e.g. a per-pixel rotated filter) is not held.
    checks = compare(summary({"exact": {"flicker_same": tiny}}, promised=()),
                     summary({"exact": {"flicker_same": tiny}}))
    assert all(c.direction != "zero" for c in checks)


def test_the_runs_promise_is_held_and_the_baselines_when_the_run_records_none():
    now, base = summary({"exact": {"flicker_same": 0.0}}), summary({"exact": {"flicker_same": 0.0}}, promised=())
    (held,) = [c for c in compare(now, base) if c.direction == "zero"]
    assert (held.verdict, held.why, held.baseline, held.allowed) == ("invariant", "world-locked", 0.0, 0.0)
    older = {k: v for k, v in summary({"exact": {"flicker_same": 0.1}}).items() if k != "invariants"}
    assert [c.verdict for c in compare(older, now) if c.direction == "zero"] == ["invariant broken"]


def test_a_method_aggregate_promises_only_what_every_sweep_point_promises():
    points = {"filter=pcf": {"exact": {"flicker_same": 0.0}}, "filter=pcf_poisson": {"exact": {"flicker_same": 0.3}}}
    run = {"methods": {"exact": {"flicker_same": 0.15}}, "points": points,
           "invariants": {"exact": {"filter=pcf": promise(True), "filter=pcf_poisson": promise(False)}}}
    held = {(c.point, c.verdict) for c in compare(run, run) if c.direction == "zero"}
    assert held == {("filter=pcf", "invariant")}


@pytest.fixture(scope="module")
def gate_runs(tmp_path_factory):
    """The gate at 4 frames: unchanged twice, quantized at 4 levels, exact switched to none."""
    root = tmp_path_factory.mktemp("gate")
    variants = {
        "unchanged": "",
        "levels4": '[[methods]]\nname = "quantized"\nlevels = 4\n',
        "none": '[[methods]]\nname = "exact"\nstabilization = "none"\n',
    }
    runs = {}
    for name, extra in variants.items():
        path = root / f"{name}.toml"
        path.write_text(f'extends = ["{GATE.as_posix()}"]\n{extra}')
        runs[name] = run_experiment(load_experiment(path, frames=GATE_FRAMES), out_dir=root / name)
    runs["again"] = run_experiment(load_experiment(root / "unchanged.toml", frames=GATE_FRAMES), out_dir=root / "again")
    write_baseline(root / "unchanged", root / "baseline.json")
    return root, runs


def test_two_gate_runs_give_identical_summaries(gate_runs):
    root, _ = gate_runs
    assert (root / "again" / "summary.json").read_bytes() == (root / "unchanged" / "summary.json").read_bytes()


def test_gate_passes_on_the_unchanged_config(gate_runs):
    root, _ = gate_runs
    result = regress(root / "again", root / "baseline.json")
    assert result.passed and not result.failures
    written = json.loads((root / "again" / "regress.json").read_text())
    assert written["status"] == "pass" and list(written["rows"][0])[-1] == "verdict"


@pytest.mark.parametrize("variant, method, metric", [
    ("levels4", "quantized", "rho_p05"),
    ("none", "exact", "flicker_same"),
])
def test_gate_fails_with_exit_1_naming_metric_and_method(gate_runs, variant, method, metric):
    root, _ = gate_runs
    outcome = CliRunner().invoke(app, ["regress", str(root / variant), "--baseline", str(root / "baseline.json")])
    assert outcome.exit_code == 1, outcome.output
    assert f"{metric} of {method}" in outcome.output
    assert json.loads((root / variant / "regress.json").read_text())["status"] == "fail"
    assert (root / variant / "index.html").is_file()


def test_baseline_of_another_workload_exits_2(gate_runs, tmp_path):
    root, _ = gate_runs
    other = json.loads((root / "baseline.json").read_text())
    other.update(workload_hash="0123456789abcdef", name="another", frames=99)
    (tmp_path / "other.json").write_text(json.dumps(other))
    outcome = CliRunner().invoke(app, ["regress", str(root / "again"), "--baseline", str(tmp_path / "other.json")])
    assert outcome.exit_code == 2
    assert "baseline is for workload 0123456789abcdef" in outcome.output and "other.json" in outcome.output
    with pytest.raises(InputError, match="workload_hash"):
        regress(root / "again", tmp_path / "other.json")


def test_baseline_command_writes_what_regress_reads(gate_runs, tmp_path):
    root, _ = gate_runs
    outcome = CliRunner().invoke(app, ["baseline", str(root / "unchanged"), "--out", str(tmp_path / "b.json")])
    assert outcome.exit_code == 0
    assert json.loads((tmp_path / "b.json").read_text()) == make_baseline(root / "unchanged")


def test_committed_gate_baseline_is_for_the_committed_gate_workload():
    baseline = json.loads(COMMITTED.read_text())
    workload = build_workload(load_experiment(GATE))
    assert baseline["workload_hash"] == workload.key and baseline["frames"] == len(workload.path)
    assert baseline["methods"]["exact"]["flicker_same"] == 0.0
    assert baseline["methods"]["none"]["flicker_same"] > 0.0
    assert all(not (isinstance(v, float) and math.isnan(v)) for m in baseline["methods"].values() for v in m.values())


def test_tolerances_file_overrides_the_defaults(gate_runs, tmp_path):
    root, _ = gate_runs
    loose = tmp_path / "loose.toml"
    metrics = ("rho_median", "rho_p05", "sigma_min_p05", "rho_frac_lt1", "rho_frac_lt05", "utilization",
               "flicker", "flicker_changed", "flip_rate", "flip_changed", "ref_false_shadow", "ref_false_light",
               "ref_boundary_px", "flip", "de2000_mean", "de2000_p99", "de2000_frac_jnd", "texels_rasterized")
    loose.write_text("".join(f"{m} = {{ rel = 10.0, abs = 10.0 }}\n" for m in metrics))
    assert regress(root / "levels4", root / "baseline.json", tolerances=load_tolerances(loose)).passed
