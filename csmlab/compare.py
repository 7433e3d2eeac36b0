"""A against B: two runs of the same workload compared, method by method, from their results folders alone.

The question is "what did my change do?" — the same scene, camera path, light and frames run with
two versions of the code or two settings. Two runs of *different* workloads are not comparable
(their frames show different things): :func:`compare_runs` refuses them with an
:class:`~csmlab.errors.InputError` naming what differs, the same identity
(``summary.json``'s ``workload_hash``, :func:`csmlab.config.workload_hash`) that ``csmlab regress``
requires of a baseline.

Methods are matched by name (and sweep point): a method × point in one run only is listed as such.
Every metric's change B − A is marked better or worse by the metric's direction and flagged when it
exceeds the gate's tolerance, by the gate's own judgement (:func:`csmlab.regress.judge`: for a
metric closest to 1, on the ``|ln value|`` scale). Settings that differ are read from both runs'
resolved configs.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from csmlab.errors import InputError
from csmlab.metric_registry import is_per_cascade, number_or_none
from csmlab.regress import judge, tolerance_for
from csmlab.results import read_summary

__all__ = ["Comparison", "MetricDelta", "compare_runs", "flatten", "metric_direction", "workload_differences"]



def metric_direction(metric: str) -> str:
    """Which way a metric is better: a key of :data:`csmlab.metric_registry.BETTER`.

    The regression table's direction (:func:`csmlab.regress.tolerance_for`), so that compare and
    regress agree on what "better" means.
    """
    return tolerance_for(metric).direction


@dataclass(frozen=True)
class MetricDelta:
    """One metric of one method × point in A and in B.

    Attributes
    ----------
    metric : str
    a, b : float or None
        Means over frames (``summary.json``); None when the run has no value.
    delta : float or None
        ``b − a``.
    direction : str
        :func:`metric_direction`.
    verdict : str
        ``better`` or ``worse`` (B against A, by direction), ``same``, ``changed`` (moved, neither
        better nor worse: :class:`csmlab.regress.Judgement`), or ``n/a`` (a value missing).
    beyond_tolerance : bool
        B moved from A, either way, by more than the regression gate allows from ``a``
        (:func:`csmlab.regress.judge`).
    """

    metric: str
    a: float | None
    b: float | None
    delta: float | None
    direction: str
    verdict: str
    beyond_tolerance: bool

    @property
    def per_cascade(self) -> bool:
        return is_per_cascade(self.metric)

    @property
    def relative(self) -> float | None:
        """``(b − a) / |a|``; None when undefined."""
        if self.delta is None or not self.a:
            return None
        return self.delta / abs(self.a)


def _delta(metric: str, a, b) -> MetricDelta:
    a, b = number_or_none(a), number_or_none(b)
    direction = metric_direction(metric)
    if a is None or b is None:
        return MetricDelta(metric, a, b, None, direction, "n/a", False)
    judgement = judge(direction, a, b, tolerance_for(metric).allowed(a))
    return MetricDelta(metric, a, b, b - a, direction, judgement.change, judgement.beyond)


def flatten(document, prefix: str = "") -> dict[str, object]:
    """A config document as ``{"shadow.resolution": 1024, "methods[quantized].levels": 64, …}``.

    Lists of tables with a ``name`` (``[[methods]]``) are keyed by that name, so that the same
    method is compared with itself whatever its position.
    """
    out: dict[str, object] = {}
    if isinstance(document, dict):
        for key, value in document.items():
            out.update(flatten(value, f"{prefix}.{key}" if prefix else str(key)))
    elif (isinstance(document, list) and document and all(isinstance(v, dict) and "name" in v for v in document)):
        for entry in document:
            out.update(flatten({k: v for k, v in entry.items() if k != "name"}, f"{prefix}[{entry['name']}]"))
            out[f"{prefix}[{entry['name']}]"] = "present"
    else:
        out[prefix] = document
    return out


_WORKLOAD_SECTIONS = ("scene", "camera", "light")


def workload_differences(summary_a: dict, summary_b: dict) -> list[str]:
    """What makes two runs' workloads differ, as ``field: A vs B`` phrases.

    Compares the workload's parts as the two summaries record them: the ``scene``, ``camera``
    (without its frame cap) and ``light`` sections and the frames rendered. When the hashes differ
    but no recorded field does, the files those sections name (a mesh, a camera-path file) differ
    in content.
    """
    differences = []
    for section in _WORKLOAD_SECTIONS:
        a = flatten(summary_a.get("config", {}).get(section, {}), section)
        b = flatten(summary_b.get("config", {}).get(section, {}), section)
        a.pop("camera.frames", None)
        b.pop("camera.frames", None)
        for key in list(dict.fromkeys([*a, *b])):
            if a.get(key) != b.get(key):
                differences.append(f"{key}: {a.get(key, '(unset)')!r} vs {b.get(key, '(unset)')!r}")
    if summary_a.get("frames") != summary_b.get("frames"):
        differences.append(f"frames: {summary_a.get('frames')} vs {summary_b.get('frames')}")
    if not differences and summary_a.get("workload_hash") != summary_b.get("workload_hash"):
        differences.append("the content of a file the scene or camera names (mesh, camera path)")
    return differences


@dataclass(frozen=True)
class Comparison:
    """Two runs of one workload, compared.

    Attributes
    ----------
    a, b : Path
        The results folders.
    summary_a, summary_b : dict
        Their ``summary.json``.
    matched : list of (method, point)
        Method × sweep point pairs in both runs, in A's order.
    only_a, only_b : list of (method, point)
        Pairs in one run only.
    deltas : dict
        ``(method, point)`` → list of :class:`MetricDelta`, metrics in A's order then B's extras.
    settings : list of (key, a, b)
        Resolved-config fields (:func:`flatten` keys) whose values differ; ``None`` where unset.
    provenance : list of (key, a, b)
        csmlab version, config hash and environment fields that differ.
    """

    a: Path
    b: Path
    summary_a: dict
    summary_b: dict
    matched: list
    only_a: list
    only_b: list
    deltas: dict
    settings: list
    provenance: list


def _pairs(summary: dict) -> list[tuple[str, str]]:
    return [(m, p) for p, by_method in summary["points"].items() for m in by_method]


def _entry(summary: dict, method: str, point: str) -> dict:
    return summary["points"][point][method]


def _differing(a: dict, b: dict, *, skip=()) -> list[tuple[str, object, object]]:
    return [(k, a.get(k), b.get(k)) for k in dict.fromkeys([*a, *b])
            if a.get(k) != b.get(k) and not k.startswith(skip)]


def compare_runs(run_a, run_b) -> Comparison:
    """Compare the finished runs in ``run_a`` and ``run_b`` (results folders).

    Raises
    ------
    InputError
        If a folder holds no finished run, or the two runs are of different workloads (the
        message names every differing field).
    """
    summary_a, summary_b = read_summary(run_a), read_summary(run_b)
    if summary_a["workload_hash"] != summary_b["workload_hash"]:
        raise InputError(
            f"expected a run of the same workload as {run_a} ({summary_a['workload_hash']}), got workload "
            f"{summary_b['workload_hash']}: {'; '.join(workload_differences(summary_a, summary_b))}",
            file=Path(run_b) / "summary.json", field="workload_hash")
    pairs_a, pairs_b = _pairs(summary_a), _pairs(summary_b)
    matched = [p for p in pairs_a if p in pairs_b]
    deltas = {}
    for method, point in matched:
        entry_a, entry_b = _entry(summary_a, method, point), _entry(summary_b, method, point)
        metrics = [m for m in dict.fromkeys([*entry_a, *entry_b]) if m != "frames"]
        deltas[(method, point)] = [_delta(m, entry_a.get(m), entry_b.get(m)) for m in metrics]
    meta_a = flatten({k: summary_a.get(k) for k in ("csmlab_version", "config_hash", "environment")})
    meta_b = flatten({k: summary_b.get(k) for k in ("csmlab_version", "config_hash", "environment")})
    return Comparison(
        a=Path(run_a), b=Path(run_b), summary_a=summary_a, summary_b=summary_b, matched=matched,
        only_a=[p for p in pairs_a if p not in pairs_b], only_b=[p for p in pairs_b if p not in pairs_a],
        deltas=deltas,
        settings=_differing(flatten(summary_a["config"]), flatten(summary_b["config"]), skip=("name", "description")),
        provenance=_differing(meta_a, meta_b),
    )
