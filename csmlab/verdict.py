"""The gate's verdict in the forms a CI system shows: a JUnit XML test report and a Markdown summary.

GitHub Actions, GitLab CI and Jenkins all read JUnit XML; a Markdown summary goes to GitHub's step
summary (``$GITHUB_STEP_SUMMARY``) or a merge-request note. Both are drawn from a
:class:`~csmlab.regress.RegressResult` and the run's ``metrics.csv`` (for the worst frames), and
both are written atomically.

JUnit layout (the attributes every JUnit reader requires, plus counts of skipped cases)::

    <testsuites name="csmlab regress" tests failures errors skipped time>
      <testsuite name="<run>.<method>[@<point>]" tests failures errors skipped time>
        <properties> baseline, workload_hash </properties>
        <testcase name="<metric>" classname="csmlab.regress.<run>.<method>[@<point>]">
          <failure message="one line" type="regression|missing|invariant broken">baseline, value,
            delta, tolerance, direction, worst frames</failure>      (a failing check)
          <skipped message="…"/>                                     (a check that is not judged)
        </testcase>
        <testcase name="flicker_same == 0 (invariant)" …/>           (a promised invariant: its own case)

One test case per method × metric check (per sweep point when the experiment sweeps), in the
order of :func:`csmlab.regress.compare`. The same result gives the same bytes (no time stamps).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

from csmlab.errors import InputError
from csmlab.metric_registry import BETTER, BETTER_TEXT, format_number, is_per_cascade
from csmlab.regress import Check, RegressResult
from csmlab.results import read_metrics, read_summary, write_atomic

__all__ = ["DIRECTION_TEXT", "junit_xml", "markdown_summary", "worst_frames", "write_junit", "write_markdown"]

DIRECTION_TEXT = {**BETTER_TEXT, "either": "not judged", "zero": "must stay exactly 0"}
"""How each :data:`csmlab.metric_registry.BETTER` name (and the invariant's ``zero``) reads in a verdict."""
_SKIPPED = {"n/a": "no value in the baseline or now", "shown": "shown, not judged (no better direction)",
            "new": "no baseline value to compare with"}
_MOVED_ROWS = 8
"""Rows of the Markdown table besides the failures (per-cascade ones are named above it, not tabled):
the largest relative moves within tolerance."""
_WORST = 3
_DIGITS = 4
"""Significant digits of a value in a verdict: one more than a table's, so that a change within tolerance shows."""


def _fmt(value: float | None) -> str:
    return format_number(value, digits=_DIGITS)


def _signed(value: float | None) -> str:
    return "—" if value is None else f"{value:+.4g}".replace("-", "−")


def _suite_name(run: str, check: Check) -> str:
    return f"{run}.{check.method}" + ("" if check.point == "*" else f"@{check.point}")


def _is_invariant(check: Check) -> bool:
    return check.direction == "zero"


def _case_name(check: Check) -> str:
    return f"{check.metric} == 0 (invariant)" if _is_invariant(check) else check.metric


def worst_frames(results_dir, checks, *, count: int = _WORST) -> dict[tuple[str, str, str], list[tuple[str, float]]]:
    """The frames of the run where each check's metric was worst, by its direction.

    Parameters
    ----------
    results_dir : str or Path
        The run's results directory (its ``metrics.csv``).
    checks : iterable of Check
    count : int
        Frames kept per check.

    Returns
    -------
    dict
        ``(method, point, metric)`` → ``[(frame label, value), …]``, worst first: by the registry's score
        (:data:`csmlab.metric_registry.BETTER`): highest of a ``lower`` metric or of the invariant,
        lowest of a ``higher`` one, farthest from 1 of a ``one`` one; none for ``either``. A
        frame label is the frame number, followed by ``@point`` when a method aggregate (point
        ``*``) spans several sweep points.
    """
    path = Path(results_dir) / "metrics.csv"
    if not path.is_file():
        return {}
    header, rows = read_metrics(path)
    points = {r["point"] for r in rows}
    out = {}
    for check in checks:
        key = (check.method, check.point, check.metric)
        if check.metric not in header or BETTER.get(check.direction, max) is None or key in out:
            continue
        values = [(r["frame"] if len(points) == 1 or check.point != "*" else f"{r['frame']}@{r['point']}",
                   float(r[check.metric]))
                  for r in rows if r["method"] == check.method and check.point in ("*", r["point"])
                  and r[check.metric] != ""]
        score = BETTER.get(check.direction, float)
        values.sort(key=lambda fv: score(fv[1]), reverse=True)
        if check.direction == "zero":
            values = [fv for fv in values if fv[1] != 0.0]
        out[key] = values[:count]
    return out


def _frames_text(frames: list[tuple[str, float]]) -> str:
    return ", ".join(f"f{label} ({_fmt(value)})" for label, value in frames) or "—"


def _failure_message(check: Check) -> str:
    where = f"{check.metric} of {check.method}" + ("" if check.point == "*" else f" at {check.point}")
    if check.verdict == "missing":
        return f"{where}: baseline {_fmt(check.baseline)}, no value now"
    if _is_invariant(check):
        return f"{where}: {_fmt(check.now)}, must stay exactly {_fmt(check.baseline)} (promised: {check.why})"
    return (f"{where}: {_fmt(check.now)} vs baseline {_fmt(check.baseline)} (change {_signed(check.delta)}, "
            f"tolerance {_fmt(check.allowed)}, {DIRECTION_TEXT[check.direction]})")


def _failure_text(check: Check, frames: list[tuple[str, float]]) -> str:
    lines = [("baseline", _fmt(check.baseline)), ("value", _fmt(check.now)), ("delta", _signed(check.delta)),
             ("tolerance", _fmt(check.allowed)),
             ("direction", f"{check.direction} ({DIRECTION_TEXT[check.direction]})"),
             ("worst frames", _frames_text(frames))]
    return "".join(f"{name}: {value}\n" for name, value in lines)


def junit_xml(result: RegressResult, *, run: str, frames: dict | None = None) -> str:
    """The JUnit XML text of a regression result (layout in the module docstring).

    Parameters
    ----------
    result : RegressResult
    run : str
        The run's name (the experiment), the first part of every suite's name.
    frames : dict, optional
        :func:`worst_frames` of the failing checks, quoted in their failure text.
    """
    frames = frames or {}
    suites: dict[str, list[Check]] = {}
    for check in result.checks:
        suites.setdefault(_suite_name(run, check), []).append(check)
    root = ET.Element("testsuites", _counts(result.checks, name="csmlab regress"))
    for name, checks in suites.items():
        suite = ET.SubElement(root, "testsuite", _counts(checks, name=name))
        properties = ET.SubElement(suite, "properties")
        for key, value in (("baseline", result.baseline), ("workload_hash", result.workload_hash)):
            ET.SubElement(properties, "property", {"name": key, "value": str(value)})
        for check in checks:
            case = ET.SubElement(suite, "testcase", {"name": _case_name(check), "classname": f"csmlab.regress.{name}",
                                                     "time": "0"})
            if check.failed:
                failure = ET.SubElement(case, "failure", {"message": _failure_message(check), "type": check.verdict})
                failure.text = _failure_text(check, frames.get((check.method, check.point, check.metric), []))
            elif check.verdict in _SKIPPED:
                ET.SubElement(case, "skipped", {"message": _SKIPPED[check.verdict]})
    ET.indent(root)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def _counts(checks: list[Check], *, name: str) -> dict[str, str]:
    return {"name": name, "tests": str(len(checks)), "failures": str(sum(c.failed for c in checks)), "errors": "0",
            "skipped": str(sum(c.verdict in _SKIPPED for c in checks)), "time": "0"}


def _relative(check: Check) -> float:
    if not check.delta:
        return 0.0
    return abs(check.delta) / abs(check.baseline) if check.baseline else math.inf


def _change_text(check: Check) -> str:
    if check.delta is None:
        return "—"
    relative = f" ({check.delta / check.baseline:+.1%})".replace("-", "−") if check.baseline else ""
    return _signed(check.delta) + relative


def _moved(result: RegressResult) -> tuple[list[Check], int]:
    """Failures first, then the largest relative moves within tolerance (per-cascade columns left out)."""
    others = [c for c in result.checks if not c.failed and c.delta not in (None, 0.0)
              and not is_per_cascade(c.metric) and not _is_invariant(c)]
    others.sort(key=_relative, reverse=True)
    failures = [c for c in result.failures if not is_per_cascade(c.metric)] or result.failures
    return failures + others[:_MOVED_ROWS], max(0, len(others) - _MOVED_ROWS)


_MARK = {"regression": "❌ regression", "missing": "❌ missing", "invariant broken": "❌ invariant broken",
         "better": "✅ better", "ok": "within tolerance", "shown": "shown"}


def markdown_summary(result: RegressResult, *, run: str, frames_count: int | None = None,
                     frames: dict | None = None) -> str:
    """A Markdown summary of a regression result, small enough for a pull-request comment.

    The verdict first (pass or fail, and which metric of which method failed), then one table of
    what moved — every failing check, then the largest moves within tolerance — with the frames
    where each metric was worst.

    Parameters
    ----------
    result : RegressResult
    run : str
        The run's name.
    frames_count : int, optional
        Frames in the run, for the header line.
    frames : dict, optional
        :func:`worst_frames` of the checks in the table.
    """
    frames = frames or {}
    failures = result.failures
    counted = f", {frames_count} frames" if frames_count is not None else ""
    lines = [f"### csmlab regress: {'✅ PASS' if result.passed else '❌ FAIL'} — {run}", ""]
    if failures:
        lines.append(f"**{len(failures)} of {len(result.checks)} checks failed**: {_failed_names(failures)}.")
    else:
        lines.append(f"All {len(result.checks)} checks within tolerance.")
    lines += ["", f"Baseline `{result.baseline}`, workload `{result.workload_hash}`{counted}.", ""]
    rows, more = _moved(result)
    if rows:
        lines += ["| verdict | method | metric | baseline | now | change | tolerance | direction | worst frames |",
                  "| --- | --- | --- | ---: | ---: | ---: | ---: | --- | --- |"]
        for c in rows:
            method = c.method + ("" if c.point == "*" else f" @ {c.point}")
            lines.append(f"| {_MARK.get(c.verdict, c.verdict)} | {method} | `{_case_name(c)}` | {_fmt(c.baseline)} | "
                         f"{_fmt(c.now)} | {_change_text(c)} | {_fmt(c.allowed)} | {DIRECTION_TEXT[c.direction]} | "
                         f"{_frames_text(frames.get((c.method, c.point, c.metric), []))} |")
        lines.append("")
    else:
        lines += ["Nothing moved: every value equals the baseline.", ""]
    unchanged = sum(c.delta == 0.0 for c in result.checks)
    tail = f"{more} more moved within tolerance; " if more else ""
    lines.append(f"<sub>{tail}{unchanged} unchanged. Every check: `regress.json` in the results folder.</sub>")
    return "\n".join(lines) + "\n"


def _failed_names(failures: list[Check]) -> str:
    """``method: `a`, `b` (per cascade: `a_c0`)`` for each method (and sweep point) with a failing check."""
    by_method: dict[str, list[str]] = {}
    for c in failures:
        by_method.setdefault(c.method + ("" if c.point == "*" else f" at {c.point}"), []).append(_case_name(c))
    parts = []
    for method, names in by_method.items():
        whole = [f"`{n}`" for n in names if not is_per_cascade(n)]
        cascades = [f"`{n}`" for n in names if is_per_cascade(n)]
        text = ", ".join(whole) + (f" (per cascade: {', '.join(cascades)})" if cascades else "")
        parts.append(f"**{method}**: {text.strip()}")
    return "; ".join(parts)


def _write(path, text: str, *, flag: str) -> Path:
    try:
        return write_atomic(path, text)
    except OSError as exc:
        raise InputError(f"expected a writable file, got {exc.strerror or exc}", file=path, field=flag) from None


def write_junit(result: RegressResult, results_dir, path) -> Path:
    """Write :func:`junit_xml` of ``result`` (the run in ``results_dir``) to ``path`` atomically.

    Raises
    ------
    InputError
        If ``path`` cannot be written (field ``--junit``).
    """
    summary = read_summary(results_dir)
    frames = worst_frames(results_dir, result.failures)
    return _write(path, junit_xml(result, run=summary["name"], frames=frames), flag="--junit")


def write_markdown(result: RegressResult, results_dir, path) -> Path:
    """Write :func:`markdown_summary` of ``result`` (the run in ``results_dir``) to ``path`` atomically.

    Raises
    ------
    InputError
        If ``path`` cannot be written (field ``--markdown``).
    """
    summary = read_summary(results_dir)
    frames = worst_frames(results_dir, _moved(result)[0])
    text = markdown_summary(result, run=summary["name"], frames_count=summary.get("frames"), frames=frames)
    return _write(path, text, flag="--markdown")
