"""Sweep points as numbers: each point's field values and each method × point's means over frames.

``summary.json``'s ``point_fields`` holds the fields each labelled point of ``metrics.csv`` sets, as
the config typed them (numbers stay numbers, for a numeric axis).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from csmlab.errors import InputError
from csmlab.metric_registry import finite_mean, is_metric_column
from csmlab.report.tables import Columns

__all__ = ["SweepPoints", "sweep_means", "sweep_points"]

@dataclass(frozen=True)
class SweepPoints:
    """The swept fields and each point's values.

    Attributes
    ----------
    fields : tuple of str
        Swept shadow fields, in the experiment's order.
    values : dict of str to dict
        Point label → field → value, typed as in the config.
    """

    fields: tuple[str, ...]
    values: dict


def sweep_points(summary: dict, points: list[str]) -> SweepPoints:
    """Each point's field values, from ``summary["point_fields"]``.

    Raises
    ------
    InputError
        If a point of ``metrics.csv`` is not a point of ``point_fields``.
    """
    known = summary.get("point_fields", {})
    missing = [p for p in points if p not in known]
    if missing:
        raise InputError(f"expected the sweep points of point_fields ({', '.join(known)}), got {', '.join(missing)}",
                         file="summary.json", field="point_fields")
    fields = tuple(dict.fromkeys(f for p in points for f in known[p]))
    return SweepPoints(fields=fields, values={p: known[p] for p in points})


def sweep_means(metrics: Columns, sweep: SweepPoints, *, along: str) -> Columns:
    """A row per method × point of means over frames, for plotting against the field ``along``.

    Returns
    -------
    Columns
        ``method``, ``point``, ``along`` (the field's value: float or str), ``others`` (the other
        fields as ``field=value`` text) and the mean of every metric column of ``metrics``.
    """
    groups = metrics.groups()
    present = [c for c in metrics.names if is_metric_column(c)]
    rows = [metrics.of(m, p) for m, p in groups]
    means = {c: np.array([finite_mean(r[c]) for r in rows]) for c in present}
    return Columns({
        "method": np.array([m for m, _ in groups], dtype=str),
        "point": np.array([p for _, p in groups], dtype=str),
        along: np.array([sweep.values[p][along] for _, p in groups]),
        "others": np.array([", ".join(f"{f}={sweep.values[p][f]}" for f in sweep.fields if f != along)
                            for _, p in groups], dtype=str),
        **means,
    })
