"""The tune report: the Pareto front over memory, aliasing and flicker, the start and every engine preset
on the same axes, the recommended setting and its engine snippets (``templates/tune.html``).

Written by ``csmlab tune`` into its output folder as ``index.html`` with ``pareto.png`` beside it;
the page depends on the tune's records only, so the same tune gives byte-identical HTML.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

import csmlab
from csmlab.engines.common import lacking_by_group
from csmlab.metric_registry import METRICS, format_number
from csmlab.report.html import render_report_html
from csmlab.report.images import CATEGORY_COLOURS
from csmlab.report.png import save_figure
from csmlab.results import write_atomic
from csmlab.settings import SETTING_GROUPS

__all__ = ["TABLE_COLUMNS", "space_rows", "tune_figure", "write_tune_report"]

TABLE_COLUMNS = tuple(METRICS[name] for name in ("memory_bytes", "rho_p05", "rho_median", "flicker_same", "flicker",
                                                  "flip_rate"))
"""Columns of the tables, in order; label, unit and display factor from the registry."""
_DIGITS = 4
"""Significant digits of a table cell: tuned settings differ in the third."""


def _value(candidate, metric: str):
    if metric == "memory_bytes":
        return float(candidate.memory_bytes)
    if candidate.values is None or candidate.values.get(metric) is None:
        return None
    return float(candidate.values[metric])


def space_rows(space: dict) -> list[tuple[str, str, str]]:
    """The search space ``{field: spec}`` (csmlab.tune.parse_space's) as ``(group title, field, values in words)``
    rows, group by group and field by field in the documented order (:data:`~csmlab.settings.SETTING_GROUPS`)."""
    rows = []
    for group in SETTING_GROUPS:
        for field in (name for name in group.fields if name in space):
            spec = space[field]
            values = (", ".join(map(str, spec[1])) if spec[0] == "choice" else
                      f"{spec[1]} … {spec[2]}{' (log)' if spec[3] else ''}")
            rows.append((group.title, field, values))
    return rows


def tune_figure(result, path) -> None:
    """Write the Pareto plot: ρ p05 against memory and against flicker, every trial, the front joined,
    the start and the engine presets marked, the budgets drawn, the recommendation ringed."""
    flicker = result.budgets.flicker_metric
    fig = Figure(figsize=(11.5, 4.8), dpi=100, layout="constrained")
    axes = fig.subplots(1, 2, sharey=True)
    measured = [c for c in result.trials if c.values is not None and _value(c, "rho_p05") is not None]
    front = [c for c in measured if c.label in result.front]
    memory, aliasing = METRICS["memory_bytes"], METRICS["rho_p05"]
    for ax, (metric, label, scale) in zip(axes, (
            ("memory_bytes", f"shadow-map {memory.label} ({memory.unit}, log scale)", memory.scale),
            (flicker, f"{METRICS[flicker].label} ({METRICS[flicker].unit} per frame)", METRICS[flicker].scale))):
        def xy(items, metric=metric, scale=scale):
            pairs = [(_value(c, metric), _value(c, "rho_p05")) for c in items]
            pairs = [(x * scale, y) for x, y in pairs if x is not None and y is not None]
            return np.array(pairs, dtype=np.float64).reshape(-1, 2)

        grey = xy([c for c in measured if c.feasible])
        ax.scatter(grey[:, 0], grey[:, 1], s=22, color="0.55", label="trial within budgets")
        over = xy([c for c in measured if not c.feasible])
        ax.scatter(over[:, 0], over[:, 1], s=22, marker="x", color="0.7", label="trial over a budget")
        ring = xy(front)
        ax.scatter(ring[:, 0], ring[:, 1], s=90, facecolors="none", edgecolors="black", linewidths=1.1,
                   label="Pareto front (memory, ρ p05, flicker)")
        for k, ref in enumerate(result.references):
            point = xy([ref])
            if len(point):
                marker = "*" if ref.kind == "start" else "D"
                ax.scatter(point[:, 0], point[:, 1], s=140 if ref.kind == "start" else 60, marker=marker,
                           color=CATEGORY_COLOURS[k % len(CATEGORY_COLOURS)], edgecolors="0.2", linewidths=0.6,
                           label=ref.label, zorder=3)
        if result.recommended is not None:
            best = xy([result.recommended])
            ax.scatter(best[:, 0], best[:, 1], s=260, facecolors="none", edgecolors="#b34700", linewidths=2.2,
                       label=f"recommended ({result.recommended.label})", zorder=4)
        limit = result.budgets.memory_bytes if metric == "memory_bytes" else result.budgets.max_flicker
        if limit is not None:
            ax.axvline(limit * scale, color="#b34700", linestyle="--", linewidth=1.0, label="budget")
        if metric == "memory_bytes":
            ax.set_xscale("log", base=2)
        ax.set_xlabel(label)
        ax.grid(True, alpha=0.3)
    axes[0].set_ylabel(f"{aliasing.label} ({aliasing.unit}, higher is sharper)")
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside right center", fontsize=8)
    save_figure(fig, path)


def _memory_text(memory_bytes: int) -> str:
    """A memory budget in the registry's unit, and in bytes."""
    memory = METRICS["memory_bytes"]
    return f"{memory_bytes * memory.scale:g} {memory.unit} ({memory_bytes} bytes)"


def _row(candidate, *, mark: str = "") -> dict:
    cells = []
    for metric in TABLE_COLUMNS:
        value = _value(candidate, metric.name)
        cells.append(format_number(None if value is None else value * metric.scale, digits=_DIGITS))
    setting = ", ".join(f"{k} = {v:.4g}" if isinstance(v, float) else f"{k} = {v}"
                        for k, v in candidate.params.items()) or "as the experiment has it"
    over = [name for name, v in candidate.violations.items() if v > 0]
    status = "not run (over the memory budget)" if candidate.values is None else (
        f"over {', '.join(over)} budget" if over else "within budgets")
    return {"label": candidate.label, "mark": mark, "setting": setting, "cells": cells, "status": status,
            "feasible": candidate.feasible}


def write_tune_report(out_dir, result, *, snippets, preset_file: str) -> Path:
    """Write ``index.html`` and ``pareto.png`` of a tune into ``out_dir``; return the page's path.

    Parameters
    ----------
    out_dir : path
    result : csmlab.tune.TuneResult
    snippets : sequence of csmlab.engines.common.Snippet
        Of the recommended setting (empty when there is none).
    preset_file : str
        The recommended setting's preset file name ("" when there is none).
    """
    out = Path(out_dir)
    tune_figure(result, out / "pareto.png")
    recommended = result.recommended
    headline = ([_row(recommended, mark="recommended")] if recommended else []) + [
        _row(c, mark=c.kind) for c in result.references]
    front = [_row(c, mark="recommended" if c is recommended else "") for c in result.trials if c.label in result.front]
    budgets = result.budgets
    context = {
        "name": result.name,
        "version": csmlab.__version__,
        "method": result.method,
        "frames": result.frames,
        "sampler": {"tpe": "TPE (constrained)", "nsga2": "NSGA-II (constrained domination)",
                    "grid": "exhaustive grid"}[result.sampler],
        "seed": result.seed,
        "trials": len(result.trials),
        "runs_computed": result.runs_computed,
        "objectives": ", ".join(f"{m} ({d})" for m, d in result.objectives),
        "memory_budget": "none" if budgets.memory_bytes is None else _memory_text(budgets.memory_bytes),
        "flicker_budget": ("none" if budgets.max_flicker is None
                           else f"{budgets.flicker_metric} ≤ {budgets.max_flicker:.6g}"),
        "space": space_rows(result.space),
        "columns": [(m.label, m.unit) for m in TABLE_COLUMNS],
        "headline": headline,
        "front": front,
        "all_trials": [_row(c) for c in result.trials],
        "recommended": recommended.label if recommended else None,
        "preset_file": preset_file,
        "snippets": [(snippet, lacking_by_group(snippet.lacking)) for snippet in snippets],
    }
    return write_atomic(out / "index.html", render_report_html(context, template="tune.html"))
