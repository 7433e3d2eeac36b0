"""Compare a run's summary with a baseline under per-metric tolerances: the stabilization gate.

A baseline is a summary taken deliberately (``csmlab baseline DIR --out FILE``). It is tied to a
*workload* — scene, camera path, light and frame count (:func:`csmlab.config.workload_hash`): a
baseline of another workload is an input error, never a silent pass. Changed shadow settings and
changed code are exactly what the gate judges.

Each metric has a direction and a tolerance, declared once in :data:`csmlab.metric_registry.METRICS`
(``better`` and ``tolerance``; per-cascade columns such as ``utilization_c2`` take their metric's).
A change is a regression when it goes the wrong way by more than ``allowed = max(abs, rel · |baseline|)``:

- ``lower`` is better (flicker, errors, memory): a rise beyond ``allowed`` regresses;
- ``higher`` is better (utilization, SSIM, ρ's 5th percentile): a fall beyond ``allowed`` regresses;
- ``one``, closest to 1 is better (median ρ, texels per pixel): a move away from 1 regresses when
  ``|ln now| − |ln baseline| > ln(1 + allowed / |baseline|)``, i.e. when ``now`` is farther from 1
  than ``baseline`` by more than the factor ``allowed`` permits (on either side of 1: a median ρ of
  0.9 falling to 0.8 or rising to 1.25 moves away from 1:1 about equally);
- ``either``: shown, not judged.

That judgement is :func:`judge`, the one ``csmlab compare`` makes of run B against run A too.

Every metric is deterministic (same inputs, same bits), so tolerances only leave room for
code changes that move numbers by rounding. Aliasing and utilization follow the box sizes smoothly
and get tight tolerances: a quantized method whose levels drop from 64 to 4 loses about 2 % of its
texels per pixel (measured on the gate), and the gate must see it. An experiment's ``[regress]``
table and ``--tolerances FILE`` override ``abs`` and ``rel`` per metric, in that order.

Two more rules make a verdict:

- a metric with a baseline value and none now (or a method that vanished) is ``missing``: a failure;
- **the invariants**: what a method promises, derived from its settings and recorded in the run's
  ``summary.json`` (``invariants``, :mod:`csmlab.invariants`; the baseline's record when the run
  has none), is held exactly (tolerance 0) whatever the baseline says — today zero same-cascade
  flicker for world-locked methods. A method that promises nothing is held to its tolerances only.

Methods are compared on their aggregates (``summary["methods"]``) and, when the experiment has a
sweep, at every sweep point (``summary["points"]``).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from pathlib import Path

import csmlab
from csmlab.errors import InputError
from csmlab.metric_registry import BETTER, METRICS, metric_of, number_or_none
from csmlab.results import json_text, read_json, read_summary, write_atomic

__all__ = ["TOLERANCES", "Check", "Judgement", "RegressResult", "Tolerance", "compare", "judge", "make_baseline",
           "read_baseline", "regress", "tolerance_for", "write_baseline"]


@dataclass(frozen=True)
class Tolerance:
    """How far a metric may move the wrong way: ``max(abs, rel · |baseline|)`` in its own units."""

    direction: str
    """A key of :data:`csmlab.metric_registry.BETTER`: ``lower``, ``higher``, ``one`` (closest to 1) or ``either``."""
    abs: float = 0.0
    """Allowed change in the metric's units."""
    rel: float = 0.0
    """Allowed change as a fraction of the baseline value."""

    def allowed(self, baseline: float) -> float:
        """The allowed change from ``baseline``."""
        return max(self.abs, self.rel * abs(baseline))


@dataclass(frozen=True)
class Judgement:
    """How a value moved from a baseline, by its metric's direction.

    Attributes
    ----------
    change : str
        ``better`` or ``worse`` (the score of :data:`csmlab.metric_registry.BETTER` fell or rose),
        ``same`` (the value did not move), or ``changed`` (it moved, but no nearer to or farther
        from the better side: a metric with none, or ρ from 0.5 to 2).
    beyond : bool
        The score moved, either way, by more than the tolerance allows.
    """

    change: str
    beyond: bool


def _margin(direction: str, baseline: float, allowed: float) -> float:
    """The allowed change on the score's scale: ``allowed`` itself, or for ``one`` the factor
    ``ln(1 + allowed / baseline)`` on the ``|ln value|`` scale."""
    return math.log1p(allowed / baseline) if direction == "one" and baseline > 0 else allowed


def judge(direction: str, baseline: float, now: float, allowed: float) -> Judgement:
    """Judge ``now`` against ``baseline`` under a tolerance of ``allowed`` (in the metric's units).

    The score is :data:`csmlab.metric_registry.BETTER`'s (the value, its negative, or ``|ln value|``);
    a metric with no better side (``either``) is compared by its value, and only ``changed`` or ``same``.

    Notes
    -----
    Median ρ under ``rel = 0.05``: 1.6 → 2.0 moves the score by ``ln 2.0 − ln 1.6 = 0.223`` against
    a margin of ``ln(1 + 0.08 / 1.6) = 0.049``: worse, beyond; 1.0 → 0.9 by ``|ln 0.9| = 0.105``
    against ``ln 1.05``: worse, beyond; 0.9 → 1.1 by ``0.095 − 0.105 < 0``: better, within.
    """
    score = BETTER[direction]
    moved = "same" if now == baseline else "changed"
    if score is None:
        return Judgement(moved, abs(now - baseline) > allowed)
    step = score(now) - score(baseline)
    change = "worse" if step > 0 else "better" if step < 0 else moved
    return Judgement(change, abs(step) > _margin(direction, baseline, allowed))


TOLERANCES: dict[str, Tolerance] = {m.name: Tolerance(m.better, *m.tolerance) for m in METRICS.values()}
"""Default direction and tolerance of each metric, from :data:`csmlab.metric_registry.METRICS`."""

_FAILING = ("regression", "missing", "invariant broken")


def tolerance_for(metric: str, overrides: dict | None = None) -> Tolerance:
    """The tolerance of ``metric``: its entry of :data:`TOLERANCES` (per-cascade columns take their
    metric's), with ``overrides[metric]`` (``{"abs": …, "rel": …}``) applied; unknown metrics are
    shown, not judged."""
    declared = metric_of(metric)
    tolerance = TOLERANCES[declared.name] if declared is not None else Tolerance("either")
    base_name = metric if declared is None else declared.name
    override = (overrides or {}).get(metric) or (overrides or {}).get(base_name) or {}
    return Tolerance(tolerance.direction, float(override.get("abs", tolerance.abs)),
                     float(override.get("rel", tolerance.rel)))


@dataclass(frozen=True)
class Check:
    """One metric of one method (at one sweep point) against the baseline.

    ``verdict`` is ``ok``, ``better``, ``regression``, ``missing`` (a value in the baseline, none now),
    ``new`` (no baseline value), ``shown`` (not judged), ``n/a`` (no value in either), or — for
    an invariant (direction ``zero``; ``baseline`` is the promised value) — ``invariant`` /
    ``invariant broken``. ``delta`` is ``now − baseline``; ``allowed`` the change the tolerance
    permits; ``why`` what makes an invariant hold (empty for other checks).
    """

    method: str
    point: str
    metric: str
    baseline: float | None
    now: float | None
    delta: float | None
    allowed: float | None
    direction: str
    verdict: str
    why: str = ""

    @property
    def failed(self) -> bool:
        return self.verdict in _FAILING


def _judge(metric: str, baseline, now, tolerance: Tolerance) -> tuple[float | None, float | None, str]:
    baseline, now = number_or_none(baseline), number_or_none(now)
    if baseline is None:
        return None, None, "n/a" if now is None else "new"
    if now is None:
        return None, tolerance.allowed(baseline), "missing"
    delta, allowed = now - baseline, tolerance.allowed(baseline)
    if tolerance.direction == "either":
        return delta, None, "shown"
    judgement = judge(tolerance.direction, baseline, now, allowed)
    if judgement.change == "worse" and judgement.beyond:
        return delta, allowed, "regression"
    return delta, allowed, "better" if judgement.change == "better" else "ok"


def _compare_entries(method: str, point: str, baseline: dict, now: dict | None, overrides: dict) -> list[Check]:
    checks = []
    for metric, base_value in baseline.items():
        if metric == "frames":
            continue
        tolerance = tolerance_for(metric, overrides)
        now_value = None if now is None else now.get(metric)
        delta, allowed, verdict = _judge(metric, base_value, now_value, tolerance)
        checks.append(Check(method=method, point=point, metric=metric, baseline=number_or_none(base_value),
                            now=number_or_none(now_value), delta=delta, allowed=allowed, direction=tolerance.direction,
                            verdict=verdict))
    return checks


def _promises(summary: dict, baseline: dict) -> dict[tuple[str, str], list[dict]]:
    """``(method, point)`` → the invariants promised there, each ``{promised, metric, value, why}``.

    Read from the run's ``invariants`` (:func:`csmlab.invariants.summary_invariants`), or the
    baseline's when the run records none. A method's aggregate (point ``*``) promises what every one
    of its points promises, for the reason its first point gives.
    """
    recorded = summary.get("invariants") or baseline.get("invariants") or {}
    out = {}
    for method, by_point in recorded.items():
        for point, promises in by_point.items():
            out[(method, point)] = [p for p in promises.values() if p["promised"]]
        names = set.intersection(*({n for n, p in promises.items() if p["promised"]} for promises in by_point.values()))
        first = next(iter(by_point.values()))
        out[(method, "*")] = [first[n] for n in first if n in names]
    return out


def _invariant(method: str, point: str, promise: dict, now: dict | None) -> Check:
    metric, promised = promise["metric"], float(promise["value"])
    value = None if now is None else number_or_none(now.get(metric))
    verdict = "n/a" if value is None else ("invariant" if value == promised else "invariant broken")
    return Check(method=method, point=point, metric=metric, baseline=promised, now=value,
                 delta=None if value is None else value - promised, allowed=0.0, direction="zero", verdict=verdict,
                 why=promise["why"])


def compare(summary: dict, baseline: dict, *, tolerances: dict | None = None) -> list[Check]:
    """Every check of ``summary`` against ``baseline`` (both summary-shaped dicts).

    Parameters
    ----------
    summary, baseline : dict
        ``methods`` (and ``points``) aggregates as ``summary.json`` holds them.
    tolerances : dict, optional
        Per-metric ``{"abs", "rel"}`` overrides of :data:`TOLERANCES`.

    Returns
    -------
    list of Check
        Method aggregates first (point ``*``), then sweep points; the invariants' checks last.
    """
    checks = []
    for method, entry in baseline["methods"].items():
        checks += _compare_entries(method, "*", entry, summary["methods"].get(method), tolerances or {})
    swept = set(baseline.get("points", {})) - {"base"}
    for point in sorted(swept, key=list(baseline["points"]).index):
        for method, entry in baseline["points"][point].items():
            now = summary.get("points", {}).get(point, {}).get(method)
            checks += _compare_entries(method, point, entry, now, tolerances or {})
    for (method, point), promises in _promises(summary, baseline).items():
        if point == "*" or point in swept:
            entry = (summary["methods"].get(method) if point == "*"
                     else summary.get("points", {}).get(point, {}).get(method))
            checks += [_invariant(method, point, promise, entry) for promise in promises]
    return checks


def make_baseline(results_dir) -> dict:
    """A baseline of the run in ``results_dir``: its summary's aggregates, hashes, config and promised invariants."""
    summary = read_summary(results_dir)
    return {
        "kind": "csmlab-baseline",
        "name": summary["name"],
        "workload_hash": summary["workload_hash"],
        "config_hash": summary.get("config_hash"),
        "csmlab_version": summary.get("csmlab_version"),
        "frames": summary.get("frames"),
        "config": summary["config"],
        "invariants": summary.get("invariants", {}),
        "methods": summary["methods"],
        "points": summary["points"],
    }


def write_baseline(results_dir, out_file) -> Path:
    """Write :func:`make_baseline` of ``results_dir`` to ``out_file`` (JSON)."""
    return write_atomic(out_file, json_text(make_baseline(results_dir)))


def read_baseline(file) -> dict:
    """A baseline file written by :func:`write_baseline`.

    Raises
    ------
    InputError
        If the file is missing, not JSON or not a baseline.
    """
    if not Path(file).is_file():
        raise InputError("expected a baseline file (csmlab baseline DIR --out FILE writes one), got no such file",
                         file=file, field="--baseline")
    baseline = read_json(file, required=("kind", "workload_hash", "methods"))
    if baseline["kind"] != "csmlab-baseline":
        raise InputError(f"expected kind 'csmlab-baseline', got {baseline['kind']!r}", file=file, field="kind")
    if not isinstance(baseline["methods"], dict) or not all(isinstance(v, dict) for v in baseline["methods"].values()):
        raise InputError("expected methods: {METHOD: {METRIC: value}}", file=file, field="methods")
    return baseline


@dataclass(frozen=True)
class RegressResult:
    """The outcome of :func:`regress`.

    Attributes
    ----------
    passed : bool
        No check failed.
    checks : list of Check
    baseline : str
        The baseline file.
    workload_hash : str
    """

    passed: bool
    checks: list
    baseline: str
    workload_hash: str

    @property
    def failures(self) -> list:
        return [c for c in self.checks if c.failed]


def _row(check: Check) -> dict:
    """One row of ``regress.json`` (and of the report's regression table): the verdict last."""
    row = asdict(check)
    row["verdict"] = row.pop("verdict")
    return row


def regress(results_dir, baseline_file, *, tolerances: dict | None = None) -> RegressResult:
    """Compare the run in ``results_dir`` with ``baseline_file`` and write ``regress.json`` there.

    Parameters
    ----------
    results_dir : str or Path
        A finished run (its ``summary.json``).
    baseline_file : str or Path
    tolerances : dict, optional
        ``--tolerances`` overrides, applied over the experiment's ``[regress]`` table.

    Returns
    -------
    RegressResult

    Raises
    ------
    InputError
        If a file is missing or malformed, or the baseline is for another workload.
    """
    summary = read_summary(results_dir)
    baseline = read_baseline(baseline_file)
    if baseline["workload_hash"] != summary["workload_hash"]:
        raise InputError(
            f"baseline is for workload {baseline['workload_hash']} ({baseline.get('name')!r}, "
            f"{baseline.get('frames')} frames), these results are for workload {summary['workload_hash']} "
            f"({summary['name']!r}, {summary.get('frames')} frames): scene, camera path, light or frame count differ",
            file=baseline_file, field="workload_hash")
    merged = {**summary["config"].get("regress", {}), **(tolerances or {})}
    checks = compare(summary, baseline, tolerances=merged)
    result = RegressResult(passed=not any(c.failed for c in checks), checks=checks, baseline=str(baseline_file),
                           workload_hash=summary["workload_hash"])
    write_atomic(Path(results_dir) / "regress.json", json_text({
        "baseline": str(baseline_file),
        "baseline_config_hash": baseline.get("config_hash"),
        "config_hash": summary.get("config_hash"),
        "workload_hash": summary["workload_hash"],
        "csmlab_version": csmlab.__version__,
        "status": "pass" if result.passed else "fail",
        "failures": len(result.failures),
        "tolerances": {m: asdict(tolerance_for(m, merged)) for m in sorted({c.metric for c in checks})},
        "rows": [_row(c) for c in sorted(checks, key=lambda c: not c.failed)],
    }))
    return result
