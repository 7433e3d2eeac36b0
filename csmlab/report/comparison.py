"""The A/B comparison report of two runs of one workload: ``csmlab compare RUN_A RUN_B``.

Drawn from the two results folders alone (``summary.json``, ``metrics.csv``, ``anim/*.npz``,
``snapshots/*.npz``; nothing is re-rendered) into a folder of its own::

    index.html
    figures/curves.png            per-frame curves of A (solid) and B (dashed) on shared axes
    figures/frame__f<frame>.png   a chosen frame: A, B and B − A per method (shaded, |ΔS|, ρ)

The frames shown side by side are those where B's image differs most from A's (mean absolute
difference of the shaded sRGB views), among the frames both runs keep full-resolution snapshots
of (``[report] snapshot_frames``, by default three spread over the run). Every frame's difference
is also plotted, from the downsampled shadow animations: mean |S_B − S_A| per frame, so that a
larger difference at a frame without snapshots is not hidden.
"""

from __future__ import annotations

import json
from pathlib import Path

import jinja2
import numpy as np
from matplotlib.cm import ScalarMappable
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from csmlab.compare import Comparison, MetricDelta, compare_runs
from csmlab.metric_registry import BETTER_TEXT, finite_mean, format_number
from csmlab.report.capture import capture_stem, decode_u8, read_npz
from csmlab.report.figures import CURVES
from csmlab.report.images import (CATEGORY_COLOURS, CHANGE_CMAP, DIFFERENCE_CMAP, RHO_CMAP, change_image, change_norm,
                                  difference_image, difference_norm, rho_image, rho_norm, rho_ratio_image,
                                  rho_ratio_norm, shaded_image)
from csmlab.report.png import save_figure
from csmlab.report.tables import Columns, read_columns
from csmlab.results import write_atomic
from csmlab.srgb import srgb_encoded

__all__ = ["FRAMES_SHOWN", "write_comparison_report"]

FRAMES_SHOWN = 2
"""Snapshot frames shown side by side: those where B differs most from A."""
SHADED_LIMIT = 0.5
"""Shaded-view difference (sRGB, 0–1) shown at full colour."""
CHANGE_LIMIT = 0.5
"""|ΔS| difference (lit fraction) shown at full colour."""
_TEMPLATES = Path(__file__).parent / "templates"


def write_comparison_report(run_a, run_b, out_dir) -> Path:
    """Compare two runs and write the comparison report into ``out_dir``; return ``index.html``'s path.

    Parameters
    ----------
    run_a, run_b : str or Path
        Results folders of two finished runs of the same workload (A the reference, B the change).
    out_dir : str or Path
        Where the report goes (created); neither results folder is written to.

    Raises
    ------
    InputError
        If a folder holds no finished run or the workloads differ (:func:`csmlab.compare.compare_runs`).
    """
    comparison = compare_runs(run_a, run_b)
    metrics_a = read_columns(comparison.a / "metrics.csv", required=("frame", "method", "point"))
    metrics_b = read_columns(comparison.b / "metrics.csv", required=("frame", "method", "point"))
    out = Path(out_dir)
    (out / "figures").mkdir(parents=True, exist_ok=True)
    labels = _labels(comparison)
    scores = _snapshot_scores(comparison)
    chosen = sorted(scores, key=lambda f: (-scores[f], f))[:FRAMES_SHOWN]
    animated = _animation_differences(comparison)
    _curves_figure(comparison, metrics_a, metrics_b, animated, chosen, labels, out / "figures" / "curves.png")
    frames = []
    for frame in chosen:
        name = f"figures/frame__f{frame}.png"
        title = _frame_figure(comparison, frame, labels, out / name)
        frames.append({"src": name, "title": title, "score": f"{scores[frame]:.3g}"})
    context = {
        **_header(comparison),
        "methods": [_method_row(comparison, pair, labels) for pair in comparison.matched],
        "only_a": [_label(p, comparison) for p in comparison.only_a],
        "only_b": [_label(p, comparison) for p in comparison.only_b],
        "columns": [labels[p] for p in comparison.matched],
        "metric_rows": _metric_rows(comparison, per_cascade=False),
        "cascade_rows": _metric_rows(comparison, per_cascade=True),
        "settings": [(k, _setting(a), _setting(b)) for k, a, b in comparison.settings],
        "provenance": [(k, _setting(a), _setting(b)) for k, a, b in comparison.provenance],
        "curves": "figures/curves.png",
        "frames": frames,
        "snapshot_frames": sorted(scores),
        "largest": _largest(animated, chosen),
    }
    return write_atomic(out / "index.html", _render(context))


def _render(context: dict) -> str:
    environment = jinja2.Environment(loader=jinja2.FileSystemLoader(_TEMPLATES), autoescape=True,
                                     undefined=jinja2.StrictUndefined, trim_blocks=True, lstrip_blocks=True,
                                     keep_trailing_newline=True)
    return environment.get_template("compare.html").render(**context)


def _label(pair: tuple[str, str], comparison: Comparison) -> str:
    points = {p for _, p in [*comparison.matched, *comparison.only_a, *comparison.only_b]}
    method, point = pair
    return method if points == {"base"} else f"{method} @ {point}"


def _labels(comparison: Comparison) -> dict:
    return {pair: _label(pair, comparison) for pair in comparison.matched}


def _header(comparison: Comparison) -> dict:
    a, b = comparison.summary_a, comparison.summary_b
    config = a.get("config", {})
    return {
        "name_a": a["name"], "name_b": b["name"], "dir_a": str(comparison.a), "dir_b": str(comparison.b),
        "workload_hash": a["workload_hash"], "frame_count": a.get("frames"),
        "scene": _describe(config.get("scene", {}), ("kind", "file", "seed")),
        "camera": _describe(config.get("camera", {}), ("path", "file", "width", "height")),
        "light": _describe(config.get("light", {}), ("elevation_deg", "azimuth_deg", "direction")),
    }


def _describe(section: dict, keys: tuple[str, ...]) -> str:
    return ", ".join(f"{k}={section[k]}" for k in keys if k in section) or "?"


def _setting(value) -> str:
    if value is None:
        return "(unset)"
    return value if isinstance(value, str) else json.dumps(value, ensure_ascii=False)


def _counts(deltas: list[MetricDelta]) -> dict:
    judged = [d for d in deltas if not d.per_cascade]
    return {v: sum(d.verdict == v for d in judged) for v in ("better", "worse", "same", "changed")} | {
        "beyond_worse": [d.metric for d in judged if d.verdict == "worse" and d.beyond_tolerance],
        "beyond_better": [d.metric for d in judged if d.verdict == "better" and d.beyond_tolerance]}


def _method_row(comparison: Comparison, pair, labels) -> dict:
    return {"label": labels[pair], **_counts(comparison.deltas[pair])}


def _signed(value: float) -> str:
    return format_number(value) if value == 0 else ("+" if value > 0 else "−") + format_number(abs(value))


def _cell(delta: MetricDelta | None) -> dict:
    if delta is None:
        return {"a": "—", "b": "—", "change": "—", "verdict": "n/a", "beyond": False, "title": "not in this method"}
    change = "—" if delta.delta is None else _signed(delta.delta)
    if delta.relative is not None and delta.delta:
        change += f" ({'+' if delta.relative > 0 else '−'}{abs(delta.relative):.1%})"
    title = BETTER_TEXT[delta.direction]
    if delta.beyond_tolerance:
        title += "; beyond the regression gate's tolerance"
    return {"a": format_number(np.nan if delta.a is None else delta.a),
            "b": format_number(np.nan if delta.b is None else delta.b), "change": change, "verdict": delta.verdict,
            "beyond": delta.beyond_tolerance, "title": title}


def _metric_rows(comparison: Comparison, *, per_cascade: bool) -> list[dict]:
    by_pair = {pair: {d.metric: d for d in deltas} for pair, deltas in comparison.deltas.items()}
    names = list(dict.fromkeys(d.metric for deltas in comparison.deltas.values() for d in deltas
                               if d.per_cascade == per_cascade))
    return [{"metric": name, "cells": [_cell(by_pair[pair].get(name)) for pair in comparison.matched]}
            for name in names]


def _snapshot_paths(directory: Path, pair) -> dict[int, Path]:
    stem = capture_stem(*pair)
    return {int(p.stem.rsplit("__f", 1)[1]): p for p in sorted((directory / "snapshots").glob(f"{stem}__f*.npz"))}


def _common_snapshot_frames(comparison: Comparison) -> dict[int, list]:
    """Frame → matched pairs with a snapshot at that frame in both runs; frames where every such pair has one."""
    frames: dict[int, list] = {}
    pairs = []
    for pair in comparison.matched:
        common = set(_snapshot_paths(comparison.a, pair)) & set(_snapshot_paths(comparison.b, pair))
        if common:
            pairs.append(pair)
            for frame in common:
                frames.setdefault(frame, []).append(pair)
    return {f: v for f, v in sorted(frames.items()) if len(v) == len(pairs)}


def _shown_srgb(snapshot: dict) -> np.ndarray:
    """The shaded view as displayed, ``(H, W, 3)`` float64 sRGB; NaN where there is no shading."""
    shaded = np.asarray(snapshot["shaded"], dtype=np.float64)
    defined = np.asarray(snapshot["valid"], dtype=bool) & np.all(np.isfinite(shaded), axis=-1)
    return np.where(defined[..., None], srgb_encoded(np.nan_to_num(shaded)), np.nan)


def _shaded_difference(snap_a: dict, snap_b: dict) -> np.ndarray:
    """Mean over channels of the displayed sRGB difference B − A, ``(H, W)``; NaN where either has none."""
    return np.mean(_shown_srgb(snap_b) - _shown_srgb(snap_a), axis=-1)


def _snapshot(directory: Path, pair, frame: int) -> dict:
    return read_npz(_snapshot_paths(directory, pair)[frame])


def _snapshot_scores(comparison: Comparison) -> dict[int, float]:
    """Frame → mean over methods of the mean |shaded B − shaded A| (sRGB), at frames both runs keep."""
    scores = {}
    for frame, pairs in _common_snapshot_frames(comparison).items():
        values = [finite_mean(np.abs(_shaded_difference(_snapshot(comparison.a, p, frame),
                                                        _snapshot(comparison.b, p, frame)))) for p in pairs]
        scores[frame] = float(np.nanmean(values)) if np.any(np.isfinite(values)) else 0.0
    return scores


def _animation_differences(comparison: Comparison) -> dict:
    """Pair → (frames (N,), mean |S_B − S_A| per frame (N,)) from the animations, where both runs have one."""
    out = {}
    for pair in comparison.matched:
        paths = [d / "anim" / f"{capture_stem(*pair)}.npz" for d in (comparison.a, comparison.b)]
        if not all(p.is_file() for p in paths):
            continue
        anim_a, anim_b = (read_npz(p) for p in paths)
        if anim_a["shadow"].shape != anim_b["shadow"].shape or not np.array_equal(anim_a["frame"], anim_b["frame"]):
            continue
        difference = np.abs(decode_u8(anim_b["shadow"]) - decode_u8(anim_a["shadow"]))
        out[pair] = (anim_a["frame"], np.array([finite_mean(d) for d in difference]))
    return out


def _largest(animated: dict, chosen: list[int]) -> dict | None:
    """Where the animations differ most over every frame, and whether that frame is among those shown."""
    if not animated:
        return None
    frames = next(iter(animated.values()))[0]
    mean = np.nanmean(np.stack([v for _, v in animated.values()]), axis=0)
    if not np.any(np.isfinite(mean)):
        return None
    k = int(np.nanargmax(mean))
    return {"frame": int(frames[k]), "value": f"{mean[k]:.3g}", "shown": int(frames[k]) in chosen}


def _colour(comparison: Comparison, method: str):
    methods = list(dict.fromkeys(m for m, _ in comparison.matched))
    return CATEGORY_COLOURS[methods.index(method) % len(CATEGORY_COLOURS)]


def _curves_figure(comparison: Comparison, metrics_a: Columns, metrics_b: Columns, animated: dict,
                   chosen: list[int], labels: dict, path: Path) -> None:
    """Per-frame curves: a panel per metric of :data:`CURVES` with a value in either run, then |S_B − S_A|."""
    curves = [m for m in CURVES if m.name in metrics_a and m.name in metrics_b
              and np.any(np.isfinite(np.concatenate([metrics_a[m.name], metrics_b[m.name]])))]
    panels = len(curves) + bool(animated)
    fig = Figure(figsize=(10, 1.9 * panels + 0.9), dpi=100, layout="constrained")
    axes = fig.subplots(panels, 1, sharex=True, squeeze=False)[:, 0]
    for ax, metric in zip(axes, curves):
        for pair in comparison.matched:
            colour = _colour(comparison, pair[0])
            for rows, style in ((metrics_a.of(*pair), "-"), (metrics_b.of(*pair), "--")):
                ax.plot(rows["frame"], rows[metric.name] * metric.scale, color=colour, linestyle=style, linewidth=1.3)
        ax.set_ylabel(f"{metric.label}\n({metric.unit})", fontsize=9)
        if metric.better == "one":
            ax.axhline(metric.scale, color="0.3", linestyle=":", linewidth=1.0)
    if animated:
        ax = axes[-1]
        for pair, (frames, values) in animated.items():
            ax.plot(frames, values, color=_colour(comparison, pair[0]), linewidth=1.3)
        ax.set_ylabel("mean |S_B − S_A|\n(lit fraction, downsampled)", fontsize=9)
    for ax in axes:
        ax.grid(True, alpha=0.3)
        for frame in chosen:
            ax.axvline(frame, color="0.45", linestyle=":", linewidth=1.0)
    handles = [Line2D([], [], color=_colour(comparison, p[0]), label=labels[p]) for p in comparison.matched]
    handles += [Line2D([], [], color="0.3", linestyle="-", label=f"A: {comparison.summary_a['name']}"),
                Line2D([], [], color="0.3", linestyle="--", label=f"B: {comparison.summary_b['name']}")]
    if chosen:
        handles.append(Line2D([], [], color="0.45", linestyle=":", label="frames shown below"))
    axes[0].legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=9, frameon=False)
    axes[-1].set_xlabel("frame number")
    save_figure(fig, path)


def _frame_figure(comparison: Comparison, frame: int, labels: dict, path: Path) -> str:
    """Write one chosen frame: per method rows A, B and B − A; columns shaded view, |ΔS| and ρ. Returns its title."""
    pairs = _common_snapshot_frames(comparison)[frame]
    snaps = [(pair, _snapshot(comparison.a, pair, frame), _snapshot(comparison.b, pair, frame)) for pair in pairs]
    height, width = snaps[0][1]["valid"].shape
    panel_w = float(np.clip(width / 100.0, 3.0, 4.4))
    panel_h = panel_w * height / width
    rows = 3 * len(snaps)
    fig = Figure(figsize=(3 * panel_w + 1.0, rows * (panel_h + 0.25) + 2.4), dpi=100, layout="constrained")
    grid = fig.add_gridspec(rows + 2, 3, height_ratios=[panel_h + 0.25] * rows + [0.5, 0.5])
    title = f"frame {frame}, t = {float(snaps[0][1]['time_s']):.2f} s"
    fig.suptitle(f"{title} — A: {comparison.summary_a['name']}, B: {comparison.summary_b['name']}")
    for k, (pair, a, b) in enumerate(snaps):
        images = [
            ("A", (shaded_image(a["shaded"], a["valid"]), change_image(a["dS"]), rho_image(a["rho"]))),
            ("B", (shaded_image(b["shaded"], b["valid"]), change_image(b["dS"]), rho_image(b["rho"]))),
            ("B − A", (difference_image(_shaded_difference(a, b), limit=SHADED_LIMIT),
                       difference_image(np.abs(b["dS"]) - np.abs(a["dS"]), limit=CHANGE_LIMIT),
                       rho_ratio_image(a["rho"], b["rho"]))),
        ]
        for r, (which, row) in enumerate(images):
            for c, image in enumerate(row):
                ax = fig.add_subplot(grid[3 * k + r, c])
                ax.imshow(image, interpolation="antialiased")
                ax.set_xticks([])
                ax.set_yticks([])
                if k == 0 and r == 0:
                    ax.set_title(("shaded view", "|ΔS| since the previous frame", "ρ (texels / pixel)")[c],
                                 fontsize=10)
                if c == 0:
                    ax.set_ylabel(f"{labels[pair]}\n{which}", fontsize=10)
    bars = [
        (rows, 1, change_norm(), CHANGE_CMAP, "|ΔS| (lit fraction, square-root scale)"),
        (rows, 2, rho_norm(), RHO_CMAP, "log2 ρ: < 0 blocky, > 0 wasted"),
        (rows + 1, 0, difference_norm(SHADED_LIMIT), DIFFERENCE_CMAP, "shaded B − A (sRGB): orange B darker"),
        (rows + 1, 1, difference_norm(CHANGE_LIMIT), DIFFERENCE_CMAP, "|ΔS_B| − |ΔS_A|: purple B flickers more"),
        (rows + 1, 2, rho_ratio_norm(), RHO_CMAP, "log2(ρ_B / ρ_A): red B blockier"),
    ]
    fig.add_subplot(grid[rows, 0]).axis("off")
    for r, c, norm, cmap, text in bars:
        bar = fig.colorbar(ScalarMappable(norm=norm, cmap=cmap), cax=fig.add_subplot(grid[r, c]),
                           orientation="horizontal")
        bar.set_label(text, fontsize=8)
        bar.ax.tick_params(labelsize=7)
    save_figure(fig, path)
    return title
