"""The report's summary tables: headline metrics per method × sweep point, the best of each column marked.

Values are means over frames (a peak, ``flicker_peak``, the largest frame's), NaN cells (frame 0's temporal metrics)
left out, read from ``metrics.csv``; time per frame comes from ``timings.csv``. Labels, units, display factors and
which way is better come from :data:`csmlab.metric_registry.METRICS` (and ``DERIVED``): lowest flicker, highest
utilization, median ρ closest to the 1:1 ideal (smallest ``|ln ρ|``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from csmlab.metric_registry import HEADLINE as HEADLINE_METRICS
from csmlab.metric_registry import (DERIVED, METRICS, Metric, best_mask, finite_mean, format_number, metric_of,
                                    metric_values, run_value)
from csmlab.report.tables import Columns
from csmlab.results import KEY_COLUMNS

__all__ = ["HEADLINE", "Headline", "TableCell", "TableRow", "full_table", "headline_table"]


@dataclass(frozen=True)
class Headline:
    """One column of the summary table.

    Attributes
    ----------
    key : str
        A ``metrics.csv`` column, a derived metric (:data:`csmlab.metric_registry.DERIVED`:
        ``ref_error``), or ``time_ms`` (from ``timings.csv``).
    label, unit : str
        Column title and unit as shown.
    better : str
        A key of :data:`csmlab.metric_registry.BETTER`.
    scale : float
        Display factor (100 for percentages).
    """

    key: str
    label: str
    unit: str
    better: str
    scale: float = 1.0

    @classmethod
    def of(cls, metric: Metric) -> Headline:
        """The column of a registered metric."""
        return cls(metric.name, metric.label, metric.unit, metric.better, metric.scale)


HEADLINE = (
    *(Headline.of(m) for m in HEADLINE_METRICS),
    Headline.of(DERIVED["ref_error"]),
    # The bias's share of that error, beside it rather than among the headline metrics' column order.
    Headline.of(METRICS["acne"]),
    Headline.of(METRICS["peter_panning"]),
    Headline.of(DERIVED["flicker_peak"]),
    Headline("time_ms", "time", "ms / frame", "lower"),
)
"""The summary table's columns, in order: the registry's headline metrics, then the error against the
reference (derived) with its acne and peter-panning, the largest frame flicker (derived), then the time per frame."""


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
            TableCell(format_number(means[key.key][i] * key.scale), bool(marks[key.key][i])) for key in columns))
        for i, (m, p) in enumerate(groups)
    ]
    return columns, rows


def full_table(metrics: Columns) -> tuple[list[str], list[TableRow]]:
    """Every metric column's mean over frames, a row per method × point, the best of each column marked
    where the registry says which way is better (for the report's details)."""
    names = [n for n in metrics.names if n not in KEY_COLUMNS]
    groups = metrics.groups()
    means = {n: np.array([finite_mean(metrics.of(m, p)[n]) for m, p in groups]) for n in names}
    marks = {n: best_mask(means[n], better=metric.better) if (metric := metric_of(n)) else np.zeros(len(groups), bool)
             for n in names}
    rows = [
        TableRow(method=m, point=p, cells=tuple(
            TableCell(format_number(means[n][i]), bool(marks[n][i])) for n in names))
        for i, (m, p) in enumerate(groups)
    ]
    return names, rows


def _headline_mean(key: str, rows: Columns, timings: Columns | None, method: str, point: str) -> float:
    if key == "time_ms":
        return _time_per_frame_ms(timings, method, point)
    values = metric_values(key, rows)
    return np.nan if values is None else run_value(key, values)


def _time_per_frame_ms(timings: Columns | None, method: str, point: str) -> float:
    if timings is None:
        return np.nan
    rows = timings.where((timings["method"] == method) & (timings["point"] == point))
    if len(rows) == 0:
        return np.nan
    return 1000.0 * float(np.sum(rows["seconds"])) / len(np.unique(rows["frame"]))

