"""Plots of numbers (matplotlib, Agg): per-frame curves, cascade motion, cost, sweeps and the Pareto plot.

Every function draws one PNG from :class:`~csmlab.report.tables.Columns` and returns nothing.
Methods keep one Okabe–Ito colour across every figure (``CATEGORY_COLOURS[i]`` for the i-th
method in ``metrics.csv``), sweep points a line style, cascades the colours of the cascade
overlay. Every axis names its quantity and unit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from matplotlib.cm import ScalarMappable
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

from csmlab.metric_registry import METRICS, Metric
from csmlab.report.images import CATEGORY_COLOURS, RHO_CMAP, RHO_LOG2_LIMIT, rho_norm
from csmlab.report.png import save_figure
from csmlab.report.tables import Columns

__all__ = [
    "CURVES",
    "FIELD_UNITS",
    "PARETO",
    "SWEPT",
    "Series",
    "cost_figure",
    "frame_curves_figure",
    "pareto_figure",
    "pareto_optimal",
    "series_of",
    "stabilization_figure",
    "sweep_figure",
]

CURVES: tuple[Metric, ...] = tuple(m for m in METRICS.values() if "frames" in m.plots)
"""Per-frame curves, from the registry: metrics drawn in the ``frames`` plot, in column order."""
SWEPT: tuple[Metric, ...] = tuple(m for m in METRICS.values() if "sweep" in m.plots)
"""Metrics plotted against each swept field, from the registry."""
PARETO = ("memory_bytes", "flicker", "rho_median")
"""The Pareto plot's metrics: memory (x), flicker (y), median ρ (colour)."""
_LINE_STYLES = ("-", "--", ":", "-.")
_PANEL_COLUMNS = 6
"""Most methods side by side in the cascade-motion figure before it wraps."""
FIELD_UNITS = {
    "cascades": "count", "resolution": "texels per side", "lambda": "PSSM blend, 0 uniform … 1 log",
    "shadow_distance": "m", "levels": "extent steps", "filter_size": "taps per side", "bias_constant": "m",
    "bias_slope": "texels", "normal_offset": "texels", "blend_band": "fraction of cascade depth",
    "subtexel_bits": "bits", "depth_bytes": "bytes per texel",
}
"""Units of the swept shadow fields, for axis labels; other fields are names (split, fit, filter…)."""


@dataclass(frozen=True)
class Series:
    """How one method × sweep point is drawn: its label, colour and line style."""

    method: str
    point: str
    label: str
    colour: tuple
    style: str


def series_of(groups: list[tuple[str, str]]) -> list[Series]:
    """A :class:`Series` per ``(method, point)``: colour by method, line style by point.

    The label is the method's name, followed by ``@ point`` when the run has several points. With
    more methods than colours (the engine and source-system runs draw 11–17), each further round of
    the colours takes the next line style, so that no two methods of one point draw alike for up to
    32 methods.
    """
    methods = list(dict.fromkeys(m for m, _ in groups))
    points = list(dict.fromkeys(p for _, p in groups))
    return [
        Series(method=m, point=p, label=m if len(points) == 1 else f"{m} @ {p}",
               colour=tuple(CATEGORY_COLOURS[methods.index(m) % len(CATEGORY_COLOURS)]),
               style=_LINE_STYLES[(points.index(p) + methods.index(m) // len(CATEGORY_COLOURS)) % len(_LINE_STYLES)])
        for m, p in groups
    ]


def frame_curves_figure(metrics: Columns, path) -> None:
    """Write the per-frame curves of :data:`CURVES` against time, one line per method × point, shared x axis.

    A metric that is best at 1 (median ρ) gets the line ρ = 1 for reference.
    """
    curves = [m for m in CURVES if m.name in metrics]
    series = series_of(metrics.groups())
    # Tall enough for the legend of every series beside the plots (about 0.19 inch per entry).
    fig = Figure(figsize=(10, max(1.9 * len(curves) + 0.8, 0.19 * len(series) + 1.0)), dpi=100, layout="constrained")
    axes = fig.subplots(len(curves), 1, sharex=True, squeeze=False)[:, 0]
    for k, (ax, metric) in enumerate(zip(axes, curves)):
        for s in series:
            rows = metrics.of(s.method, s.point)
            ax.plot(_time_axis(rows), rows[metric.name] * metric.scale, color=s.colour, linestyle=s.style,
                    linewidth=1.3, label=s.label)
        ax.set_ylabel(f"{metric.label}\n({metric.unit})", fontsize=9)
        ax.grid(True, alpha=0.3)
        if metric.better == "one":
            ideal = ax.axhline(metric.scale, color="0.3", linestyle=":", linewidth=1.0,
                               label=f"{metric.label} = 1, the 1:1 ideal")
            if k > 0:
                ax.legend(handles=[ideal], loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=9, frameon=False)
    # One legend for the whole figure, outside the axes, so a long list of methods does not squeeze a plot.
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside right upper", fontsize=9, frameon=False)
    axes[-1].set_xlabel("time (s)")
    save_figure(fig, path)


def _time_axis(rows: Columns) -> np.ndarray:
    return rows["time_s"] if "time_s" in rows and np.all(np.isfinite(rows["time_s"])) else rows["frame"]


def stabilization_figure(cascades: Columns, *, point: str, methods: list[str], path) -> None:
    """Write how each cascade's box moved, a column per method at one sweep point.

    ``cascades`` holds ``cascades.csv``'s columns; ``methods`` are drawn in the order given.

    Rows: the box extent in metres (constant for exact, steps for quantized, drifting for none);
    the origin's motion since the first frame, in texels; and its sub-texel phase
    ``|origin - round(origin)|`` in texels — 0 when the box is snapped to the texel grid, which is
    what keeps shadow texels fixed in the world. x solid, y dashed; cascades in overlay colours.
    """
    rows_of_point = cascades.where(cascades["point"] == point)
    count = int(np.max(rows_of_point["cascade"])) + 1
    # At most _PANEL_COLUMNS methods side by side; more wrap into further bands of three rows.
    columns = min(len(methods), _PANEL_COLUMNS)
    bands = -(-len(methods) // columns)
    fig = Figure(figsize=(3.6 * columns + 1.6, 7.5 * bands), dpi=100, layout="constrained")
    grid = fig.subplots(3 * bands, columns, sharex=True, squeeze=False)
    axes = np.concatenate([grid[3 * b:3 * b + 3] for b in range(bands)], axis=1)
    for ax in axes[:, len(methods):].ravel():
        ax.set_visible(False)
    for row in range(3):
        for ax in axes[row, 1:len(methods)]:
            ax.sharey(axes[row, 0])
    for col, method in enumerate(methods):
        rows = rows_of_point.where(rows_of_point["method"] == method)
        for c in range(count):
            one = rows.where(rows["cascade"] == c)
            if len(one["frame"]) == 0:
                continue  # this method has fewer cascades than the widest one
            one = one.where(np.argsort(one["frame"], kind="stable"))
            colour = CATEGORY_COLOURS[c % len(CATEGORY_COLOURS)]
            for axis, style in (("x", "-"), ("y", "--")):
                origin = one[f"origin_{axis}"]
                axes[0, col].plot(one["frame"], one[f"extent_{axis}"], color=colour, linestyle=style, linewidth=1.2)
                axes[1, col].plot(one["frame"], origin - origin[0], color=colour, linestyle=style, linewidth=1.2)
                axes[2, col].plot(one["frame"], np.abs(origin - np.round(origin)), color=colour, linestyle=style,
                                  linewidth=1.2)
        axes[0, col].set_title(method)
        axes[0, col].set_yscale("log")
        axes[0, col].yaxis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
        axes[0, col].yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
        axes[0, col].yaxis.set_minor_formatter(NullFormatter())
        axes[2, col].set_xlabel("frame number")
    for first in range(0, bands * columns, columns):
        axes[0, first].set_ylabel("box extent (m)")
        axes[1, first].set_ylabel("origin moved since\nfirst frame (texels)")
        axes[2, first].set_ylabel("sub-texel phase of\norigin (texels)")
    axes[2, 0].set_ylim(-0.02, 0.52)
    for ax in axes.ravel():
        ax.grid(True, alpha=0.3)
    handles = [Line2D([], [], color=CATEGORY_COLOURS[c % len(CATEGORY_COLOURS)], label=f"cascade {c}")
               for c in range(count)]
    handles += [Line2D([], [], color="0.3", linestyle="-", label="light-space x"),
                Line2D([], [], color="0.3", linestyle="--", label="light-space y")]
    axes[0, columns - 1].legend(handles=handles, loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8,
                                frameon=False)
    save_figure(fig, path)


def cost_figure(timings: Columns, groups: list[tuple[str, str]], path) -> None:
    """Write the mean wall-clock time per frame of each stage, stacked, one bar per method × point.

    Stages timed with an empty method and point (the view, rendered once for all methods) get a
    bar of their own.
    """
    stages = list(dict.fromkeys(timings["stage"].tolist()))
    bars = [(s.label, s.method, s.point) for s in series_of(groups)]
    if np.any(timings["method"] == ""):
        bars.insert(0, ("view (shared)", "", ""))
    fig = Figure(figsize=(9, 0.45 * len(bars) + 1.4), dpi=100, layout="constrained")
    ax = fig.subplots()
    left = np.zeros(len(bars))
    for k, stage in enumerate(stages):
        ms = np.array([_stage_ms(timings, method, point, stage) for _, method, point in bars])
        ax.barh(np.arange(len(bars)), ms, left=left, color=CATEGORY_COLOURS[k % len(CATEGORY_COLOURS)],
                label=stage)
        left += ms
    ax.set_yticks(np.arange(len(bars)), labels=[label for label, _, _ in bars])
    ax.invert_yaxis()
    ax.set_xlabel("wall-clock time per frame (ms)")
    ax.set_ylabel("method")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False, title="stage")
    ax.grid(True, axis="x", alpha=0.3)
    save_figure(fig, path)


def _stage_ms(timings: Columns, method: str, point: str, stage: str) -> float:
    group = (timings["method"] == method) & (timings["point"] == point)
    frames = len(np.unique(timings["frame"][group]))
    seconds = timings["seconds"][group & (timings["stage"] == stage)]
    return 1000.0 * float(np.sum(seconds)) / frames if frames else 0.0


def sweep_figure(means: Columns, parameter: str, path) -> None:
    """Write metric-vs-parameter plots for one sweep parameter, a line per method (and other parameters).

    Parameters
    ----------
    means : Columns
        A row per method × point: ``method``, ``point``, ``parameter`` (numbers), ``others``
        (text: the other swept fields of the point) and metric columns (means over frames); one
        panel per metric of :data:`SWEPT` among them.
    parameter : str
        The swept field on the x axis.
    path : str or Path
    """
    metrics = [m for m in SWEPT if m.name in means]
    fig = Figure(figsize=(3.4 * len(metrics) + 1.8, 3.4), dpi=100, layout="constrained")
    axes = fig.subplots(1, len(metrics), squeeze=False)[0]
    methods = list(dict.fromkeys(means["method"].tolist()))
    lines = list(dict.fromkeys(zip(means["method"].tolist(), means["others"].tolist())))
    others = list(dict.fromkeys(means["others"].tolist()))
    for ax, metric in zip(axes, metrics):
        for method, other in lines:
            rows = means.where((means["method"] == method) & (means["others"] == other))
            order = np.argsort(rows[parameter], kind="stable")
            ax.plot(rows[parameter][order], rows[metric.name][order] * metric.scale, marker="o",
                    color=CATEGORY_COLOURS[methods.index(method) % len(CATEGORY_COLOURS)],
                    linestyle=_LINE_STYLES[others.index(other) % len(_LINE_STYLES)],
                    label=method if len(others) == 1 else f"{method}, {other}")
        ax.set_xlabel(f"{parameter} ({FIELD_UNITS.get(parameter, 'setting')})")
        ax.set_ylabel(metric.title, fontsize=9)
        ax.grid(True, alpha=0.3)
        if _spans_octaves(means[parameter]):
            ax.set_xscale("log", base=2)
    axes[-1].legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8, frameon=False)
    save_figure(fig, path)


def _spans_octaves(values: np.ndarray) -> bool:
    """Positive numbers spanning a factor 8 or more (resolutions 512…4096) read best on a log2 axis."""
    return values.dtype.kind in "iuf" and bool(np.all(values > 0)) and values.max() >= 8 * values.min()


def pareto_optimal(objectives: np.ndarray) -> np.ndarray:
    """``(N,)`` bool: rows of ``objectives`` ``(N, K)`` (all minimised) that no other row dominates.

    A row dominates another when it is no worse in every objective and better in one. Rows with a
    NaN objective are never optimal.
    """
    objectives = np.asarray(objectives, dtype=np.float64)
    finite = np.all(np.isfinite(objectives), axis=1)
    no_worse = np.all(objectives[:, None, :] <= objectives[None, :, :], axis=2)
    better = np.any(objectives[:, None, :] < objectives[None, :, :], axis=2)
    dominated = np.any(no_worse & better & finite[:, None], axis=0)
    return finite & ~dominated


def pareto_figure(means: Columns, path) -> None:
    """Write the Pareto plot: memory against flicker, coloured by median ρ, optimal points ringed.

    ``means`` holds a row per method × point with ``method``, ``point`` and the :data:`PARETO`
    columns (means over frames). Optimal means no other point is at least as good in all three —
    each judged the way the registry says (:meth:`csmlab.metric_registry.Metric.score`: less memory,
    less flicker, median ρ closer to 1 on a log scale) — and strictly better in one.
    """
    memory_metric, flicker_metric, rho_metric = (METRICS[name] for name in PARETO)
    memory = means[memory_metric.name] * memory_metric.scale
    flicker = means[flicker_metric.name] * flicker_metric.scale
    rho = means[rho_metric.name]
    optimal = pareto_optimal(np.column_stack([[m.score(v) for v in means[m.name].tolist()]
                                              for m in (memory_metric, flicker_metric, rho_metric)]))
    methods = list(dict.fromkeys(means["method"].tolist()))
    markers = ("o", "s", "^", "D", "v", "P", "X", "*")
    fig = Figure(figsize=(8.5, 5.2), dpi=100, layout="constrained")
    ax = fig.subplots()
    for k, method in enumerate(methods):
        mine = means["method"] == method
        ax.scatter(memory[mine], flicker[mine], c=np.log2(rho[mine]), cmap=RHO_CMAP, norm=rho_norm(),
                   marker=markers[k % len(markers)], s=70, edgecolors="0.4", linewidths=0.6)
    ax.scatter(memory[optimal], flicker[optimal], s=220, facecolors="none", edgecolors="black", linewidths=1.4)
    for p, x, y in zip(means["point"], memory, flicker):
        ax.annotate(p, (x, y), textcoords="offset points", xytext=(6, 4), fontsize=7)
    ax.set_xscale("log", base=2)
    ax.set_xlabel(f"shadow-map {memory_metric.label} ({memory_metric.unit}, log scale)")
    ax.set_ylabel(flicker_metric.title)
    ax.grid(True, alpha=0.3)
    handles = [Line2D([], [], linestyle="none", marker=markers[k % len(markers)], markersize=8, color="0.6",
                      markeredgecolor="0.4", label=method) for k, method in enumerate(methods)]
    handles.append(Line2D([], [], linestyle="none", marker="o", markersize=14, markerfacecolor="none",
                          markeredgecolor="black", label="Pareto-optimal"))
    ax.legend(handles=handles, fontsize=8, loc="best")
    bar = fig.colorbar(ScalarMappable(norm=rho_norm(), cmap=RHO_CMAP), ax=ax)
    ticks = np.arange(-RHO_LOG2_LIMIT, RHO_LOG2_LIMIT + 1, 2)
    bar.set_ticks(ticks, labels=[f"{2.0 ** t:g}" for t in ticks])
    bar.set_label(f"{rho_metric.label} ({rho_metric.unit}, log scale)")
    save_figure(fig, path)
