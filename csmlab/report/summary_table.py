"""The report's summary table: headline metrics per method × sweep point, the best of each column marked.

Values are means over frames, NaN cells (frame 0's temporal metrics) left out, read from
``metrics.csv``; time per frame comes from ``timings.csv``. "Best" depends on the metric: lowest
flicker, highest utilization, median ρ closest to the 1:1 ideal (smallest ``|log ρ|``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from csmlab.report.tables import Columns, finite_mean

__all__ = ["HEADLINE", "Headline", "TableCell", "TableRow", "best_mask", "format_value", "full_table", "headline_table"]


@dataclass(frozen=True)
class Headline:
    """One column of the summary table.

    Attributes
    ----------
    key : str
        A ``metrics.csv`` column, or ``ref_error`` (false shadow + false light), ``memory_mib``,
        ``time_ms`` (from ``timings.csv``).
    label, unit : str
        Column title and unit as shown.
    better : str
        ``lower``, ``higher`` or ``one`` (closest to 1 on a log scale).
    scale : float
        Display factor (100 for percentages).
    """

    key: str
    label: str
    unit: str
    better: str
    scale: float = 1.0


HEADLINE = (
    Headline("rho_median", "median ρ", "texels/pixel", "one"),
    Headline("rho_frac_lt1", "ρ < 1", "% pixels", "lower", 100.0),
    Headline("utilization", "utilization", "% texels", "higher", 100.0),
    Headline("flicker_same", "flicker, same cascade", "mean |ΔS|", "lower"),
    Headline("flicker_changed", "flicker, cascade changed", "mean |ΔS|", "lower"),
    Headline("flip_rate", "flip rate", "% pixels", "lower", 100.0),
    Headline("de2000_mean", "mean ΔE2000", "ΔE", "lower"),
    Headline("flip", "ꟻLIP", "mean", "lower"),
    Headline("ssim", "SSIM", "1 = same", "higher"),
    Headline("ref_error", "vs. reference", "% pixels wrong", "lower", 100.0),
    Headline("memory_mib", "memory", "MiB", "lower"),
    Headline("time_ms", "time", "ms / frame", "lower"),
)
"""The summary table's columns, in order."""


@dataclass(frozen=True)
class TableCell:
    """A formatted value; ``best`` marks the best of its column."""

    text: str
    best: bool = False


@dataclass(frozen=True)
class TableRow:
    """One method × sweep point: its labels and one cell per column."""

    method: str
    point: str
    cells: tuple[TableCell, ...]


def format_value(value: float) -> str:
    """Three significant digits (whole numbers from 1000 up); an exact zero stays ``0``; NaN is ``—``.

    Exact's same-cascade flicker is zero, not small, and the table must say so.
    """
    if not np.isfinite(value):
        return "—"
    return f"{value:,.0f}" if abs(value) >= 1000 else f"{value:.3g}"


def best_mask(values, *, better: str) -> np.ndarray:
    """``(N,)`` bool: the rows holding the best finite value; none when fewer than two differ.

    Parameters
    ----------
    values : array_like, shape (N,)
    better : str
        ``lower``, ``higher`` or ``one``.
    """
    values = np.asarray(values, dtype=np.float64)
    finite = np.isfinite(values) & ((values > 0) if better == "one" else True)
    if len(np.unique(values[finite])) < 2:
        return np.zeros(values.shape, dtype=bool)
    if better == "one":
        score = np.abs(np.log(np.where(finite, values, 1.0)))
    else:
        score = values if better == "lower" else -values
    score = np.where(finite, score, np.inf)
    return finite & (score == score.min())


def headline_table(metrics: Columns, timings: Columns | None) -> tuple[list[Headline], list[TableRow]]:
    """The summary table: the headline columns present in the results, and a row per method × point.

    Returns
    -------
    columns : list of Headline
        The columns of :data:`HEADLINE` with a value in the results.
    rows : list of TableRow
        In order of first appearance in ``metrics.csv``.
    """
    groups = metrics.groups()
    means = {key.key: np.array([_headline_mean(key.key, metrics.of(m, p), timings, m, p) for m, p in groups])
             for key in HEADLINE}
    columns = [key for key in HEADLINE if np.any(np.isfinite(means[key.key]))]
    marks = {key.key: best_mask(means[key.key], better=key.better) for key in columns}
    rows = [
        TableRow(method=m, point=p, cells=tuple(
            TableCell(format_value(means[key.key][i] * key.scale), bool(marks[key.key][i])) for key in columns))
        for i, (m, p) in enumerate(groups)
    ]
    return columns, rows


def full_table(metrics: Columns) -> tuple[list[str], list[TableRow]]:
    """Every metric column's mean over frames, a row per method × point (for the report's details)."""
    names = [n for n in metrics.names if n not in ("frame", "time_s", "method", "point")]
    rows = [
        TableRow(method=m, point=p, cells=tuple(
            TableCell(format_value(finite_mean(metrics.of(m, p)[n]))) for n in names))
        for m, p in metrics.groups()
    ]
    return names, rows


def _headline_mean(key: str, rows: Columns, timings: Columns | None, method: str, point: str) -> float:
    if key == "ref_error":
        if "ref_false_shadow" not in rows or "ref_false_light" not in rows:
            return np.nan
        return finite_mean(rows["ref_false_shadow"] + rows["ref_false_light"])
    if key == "memory_mib":
        return finite_mean(rows["memory_bytes"]) / 2**20 if "memory_bytes" in rows else np.nan
    if key == "time_ms":
        return _time_per_frame_ms(timings, method, point)
    return finite_mean(rows[key]) if key in rows else np.nan


def _time_per_frame_ms(timings: Columns | None, method: str, point: str) -> float:
    if timings is None:
        return np.nan
    rows = timings.where((timings["method"] == method) & (timings["point"] == point))
    if len(rows) == 0:
        return np.nan
    return 1000.0 * float(np.sum(rows["seconds"])) / len(np.unique(rows["frame"]))

