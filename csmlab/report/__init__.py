"""The HTML report of a run, drawn from its results files alone.

:func:`write_report` reads ``summary.json``, ``metrics.csv``, ``timings.csv``, ``regress.json``
and the captures of :mod:`csmlab.report.capture` (``cascades.csv``, ``anim/``, ``snapshots/``,
``pixels/``, ``casters.npz``)
and writes ``index.html`` with its figures beside it::

    index.html
    figures/curves.png  figures/cost.png  figures/stabilization__<point>.png
    figures/strip__<point>__f<frame>.webp  figures/view3d__f<frame>.png
    figures/sweep__<parameter>.png  figures/pareto.png
    anim/<method>__<point>.gif
    explore/…   the interactive part (:mod:`csmlab.report.explore`), when the run kept per-pixel records

The strips are lossy WebP (:data:`csmlab.report.png.PICTURE_WEBP`): pictures of pictures, a quarter of their
size as PNG; the plots and the 3D view stay PNG (sharp lines on white, smaller as PNG). The report stays under
a size budget planned in an order (:func:`csmlab.report.explore.budget_plan`): everything else, the
interactive part's every 2nd frame, the animations, its other frames; what it leaves out the page says, and
:class:`WrittenReport` carries for the command line.

The same results give the same ``index.html``, byte for byte, so ``csmlab report DIR``
reproduces what ``csmlab run`` wrote.
"""

from __future__ import annotations

import json
import os
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from csmlab.files import write_atomic
from csmlab.metric_registry import format_number, metric_named
from csmlab.paths.view_check import findings_line
from csmlab.scene.gltf_materials import blend_line
from csmlab.report.animation import write_animation
from csmlab.report.capture import ANIM_WIDTH, capture_stem, read_npz, safe_name
from csmlab.report.explore import BUDGET_BYTES, explore_files, write_explore
from csmlab.report.figures import (PARETO, cost_figure, frame_curves_figure, pareto_figure, stabilization_figure,
                                   sweep_figure)
from csmlab.report.html import render_report_html
from csmlab.report.images import snapshot_strip_figures
from csmlab.report.picture_pool import PicturePool
from csmlab.report.summary_table import full_table, headline_table
from csmlab.report.sweep import sweep_means, sweep_points
from csmlab.report.tables import ResultFiles, read_results
from csmlab.report.video_quality import INSTALL, SEQUENCE_LABELS
from csmlab.report.view3d import view3d_figure

__all__ = ["WrittenReport", "write_report"]


@dataclass(frozen=True)
class WrittenReport:
    """What :func:`write_report` wrote.

    Attributes
    ----------
    page : Path
        ``index.html``.
    kept : str or None
        What the size budget kept of the interactive part and the animations
        (``Explore holds every 2nd frame (60 of 120); animations left out``); None without an interactive part.
    """

    page: Path
    kept: str | None


def write_report(out_dir, *, budget_bytes: int = BUDGET_BYTES, worker: bool | None = None) -> WrittenReport:
    """Write ``index.html`` and its figures into a results directory; return the page's path and what it kept.

    Parameters
    ----------
    out_dir : str or Path
        A directory holding at least ``summary.json`` and ``metrics.csv``.
    budget_bytes : int, keyword-only
        Size budget of the directory with its report: the interactive part thins its frames, and leaves the
        animations out, to stay under it (:func:`csmlab.report.explore.budget_plan`).
    worker : bool or None, keyword-only
        Draw the pictures (strips, 3D view, plots, animations) in a second process while this one
        reads the interactive part's records, and here those the worker has not started by then
        (:class:`~csmlab.report.picture_pool.PicturePool`); None decides by the strips' size and
        the cores available. The files are the same either way.

    Returns
    -------
    WrittenReport
        ``out_dir / "index.html"`` and what the budget kept.

    Raises
    ------
    InputError
        If a required results file is missing or malformed.
    """
    results = read_results(out_dir)
    out = results.directory
    _remove_pictures(out)
    (out / "figures").mkdir(exist_ok=True)
    groups = results.metrics.groups()
    points = list(dict.fromkeys(p for _, p in groups))
    columns, rows = headline_table(results.metrics, results.timings)
    full_names, full_rows = full_table(results.metrics)
    snapshots = {point: _snapshots_of(results, groups, point) for point in points}
    strip_frames = {point: _strip_frames(list(snapshots[point]), len(points)) for point in points}
    if worker is None:
        worker = _cores() > 1 and _strip_pixels(snapshots, strip_frames) >= _WORKER_PIXELS
    with PicturePool(worker=worker) as pool:
        # Every picture is queued before this process reads the interactive part's records. The worker takes
        # pictures from the front: the 3D view first, so that it alone imports PyVista. This process takes them
        # from the back once the records are read: the strips, the largest that are left, last.
        view3d = _view3d(out, snapshots[points[0]], pool)
        stabilization = _stabilization(results, groups, points, pool)
        pool.submit(frame_curves_figure, results.metrics, out / "figures" / "curves.png")
        cost = _cost(results, groups, pool)
        sweep = _sweep(results, points, pool)
        animations = _animations(results, groups, pool)
        strips = _strips(out, snapshots, strip_frames, pool)
        single = len(points) == 1
        labels = [m if single else f"{m} @ {p}" for m, p in groups]
        explore = explore_files(out, groups=groups, labels=labels, metrics=results.metrics, encoding="fast")
        pool.finish()
    # The interactive part once every picture is on disk, so that it knows the size of everything else: its
    # frames are encoded as the budget reads them.
    written = write_explore(out, explore, budget_bytes=budget_bytes, animations=[out / a["src"] for a in animations],
                            compact=True)
    context = {
        **_header(results),
        "groups": groups,
        "glance": _glance(columns, rows),
        "headline_columns": columns,
        "headline_rows": rows,
        "full_names": full_names,
        "full_rows": full_rows,
        "has_cascades": results.cascades is not None,
        "regress": _regress(results.regress),
        "jod": _jod(results.summary, groups),
        "curves": "figures/curves.png",
        "cost": cost,
        "anim_width": ANIM_WIDTH,
        "animations": animations if written is None or written["animations"] else [],
        "animations_note": None if written is None else written["animations_note"],
        "strips": strips,
        "stabilization": stabilization,
        "view3d": _view3d_shown(view3d),
        **sweep,
    }
    context["explore"] = _explore(written)
    return WrittenReport(page=write_atomic(out / "index.html", render_report_html(context)),
                         kept=None if written is None else written["kept_text"])


_WORKER_PIXELS = 200_000
"""Snapshot pixels in the strips (Σ methods × H × W) from which a second process pays for its start (about 1 s).

Measured on 2 cores, one method along 240 frames: at 320×180 (230,400 pixels) the report took
2.9–3.1 s with the worker, 3.3–3.4 s without; at 640×360, 2.7–2.8 s against 3.3–3.6 s.
"""


def _remove_pictures(out: Path) -> None:
    """Remove what an earlier report drew (``figures/``, ``anim/*.gif``): a picture this one does not draw again
    — a strip as PNG, now WebP; an animation the budget leaves out — would outlive its link and count against the
    budget."""
    shutil.rmtree(out / "figures", ignore_errors=True)
    for gif in (out / "anim").glob("*.gif"):
        gif.unlink()


def _cores() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def _strip_pixels(snapshots: dict, strip_frames: dict) -> int:
    return sum(s.height * s.width for point, frames in strip_frames.items() for f in frames
               for s in snapshots[point][f])


def _explore(explore: dict | None) -> dict | None:
    if explore is None:
        return None
    return {**explore, "cell": f"{explore['cell']:.2g}", "size_mib": f"{explore['size'] / 2 ** 20:.1f}",
            "budget_mib": f"{explore['budget'] / 2 ** 20:.0f}"}


def _jod(summary: dict, groups: list[tuple[str, str]]) -> dict:
    """The page's ColorVideoVDP table from ``summary["jod"]`` (:mod:`csmlab.report.video_quality`), in results
    order; with no scores, how to install the metric and score the run."""
    jod = summary.get("jod") or {}
    sequences = jod.get("sequences", {})
    rows = [{"method": m, "point": p,
             "cells": [f"{sequences[n][capture_stem(m, p)]:.2f}" if capture_stem(m, p) in sequences[n] else "—"
                       for n in sequences]}
            for m, p in groups if any(capture_stem(m, p) in by_stem for by_stem in sequences.values())]
    return {"rows": rows, "sequences": [SEQUENCE_LABELS.get(n, n) for n in sequences], "metric": jod.get("metric", ""),
            "display": jod.get("display", ""), "install": INSTALL}


def _header(results: ResultFiles) -> dict:
    summary = results.summary
    config = summary.get("config", {})
    return {
        "name": summary.get("name", results.directory.name),
        "version": summary.get("csmlab_version", "?"),
        "config_hash": str(summary.get("config_hash", "?"))[:12],
        "frames": len(np.unique(results.metrics["frame"])),
        "scene": _describe(config.get("scene", {}), ("kind", "file", "seed")),
        "camera": _describe(config.get("camera", {}), ("path", "file", "frames", "width", "height")),
        "light": _light(config.get("light", {}), summary.get("light_colour")),
        "config_text": json.dumps(config, indent=2, sort_keys=True),
        "recording": summary.get("recording"),
        "taa": _taa(config.get("taa") or {}),
        "view_check": findings_line(summary.get("view_check")),
        "blend": blend_line(summary.get("blend_materials")),
    }


def _light(light: dict, colour: list | None = None) -> str:
    """The header's light: the scene file's sun when it comes from there, else its direction or angles; its
    colour (linear RGB) when it is not white."""
    source = ("the scene file's sun (KHR_lights_punctual)" if light.get("from_scene")
              else _describe(light, ("elevation_deg", "azimuth_deg", "direction")))
    if not colour:
        return source
    return f"{source}, colour {', '.join(f'{c:.3g}' for c in colour)} (linear RGB)"


def _taa(taa: dict) -> str | None:
    """The summary's line on temporal anti-aliasing (``[taa]``) when the run had it on; None otherwise."""
    if not taa.get("enabled"):
        return None
    clamp = f"{taa.get('clamp', '?')} clamp" + (f" (γ = {taa['gamma']})" if taa.get("clamp") == "variance" else "")
    return (f"{taa.get('phases', '?')} jitter phases (Halton 2, 3), α = {taa.get('alpha', '?')}, {clamp}, "
            f"disocclusion depth tolerance {taa.get('depth_tolerance', '?')}")


def _describe(section: dict, keys: tuple[str, ...]) -> str:
    parts = [f"{k}={section[k]}" for k in keys if k in section]
    return ", ".join(parts) if parts else "?"


def _glance(columns, rows) -> list[str]:
    lines = []
    for k, column in enumerate(columns):
        metric = metric_named(column.key)
        best = [r for r in rows if r.cells[k].best]
        if metric is not None and metric.glance and best:
            names = ", ".join(r.method if len({x.point for x in rows}) == 1 else f"{r.method} @ {r.point}"
                              for r in best)
            lines.append(f"{metric.glance}: {names} ({best[0].cells[k].text} {column.unit})")
    return lines


def _regress(regress) -> dict | None:
    if regress is None:
        return None
    rows = regress.get("rows", [])
    status = regress.get("status", "?")
    names = list(dict.fromkeys(k for row in rows for k in row))
    return {"status": str(status), "columns": names,
            "rows": [[_cell(row.get(k, "")) for k in names] for row in rows]}


def _cell(value) -> str:
    if value is None:
        return "—"
    return format_number(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else str(value)


def _cost(results: ResultFiles, groups, pool: PicturePool) -> str | None:
    if results.timings is None or len(results.timings) == 0:
        return None
    pool.submit(cost_figure, results.timings, groups, results.directory / "figures" / "cost.png")
    return "figures/cost.png"


def _fps(results: ResultFiles) -> float:
    fps = results.summary.get("config", {}).get("camera", {}).get("fps")
    if fps:
        return float(fps)
    times = np.unique(results.metrics["time_s"]) if "time_s" in results.metrics else np.array([])
    steps = np.diff(times[np.isfinite(times)])
    return float(1.0 / np.median(steps)) if steps.size and np.median(steps) > 0 else 30.0


def _animations(results: ResultFiles, groups, pool: PicturePool) -> list[dict]:
    out = results.directory
    fps = _fps(results)
    animations = []
    for method, point in groups:
        stem = capture_stem(method, point)
        source = out / "anim" / f"{stem}.npz"
        if source.is_file():
            pool.submit(_draw_animation, source, out / "anim" / f"{stem}.gif", fps=fps)
            label = method if len({p for _, p in groups}) == 1 else f"{method} @ {point}"
            animations.append({"label": label, "src": f"anim/{stem}.gif"})
    return animations


def _draw_animation(source: Path, path: Path, *, fps: float) -> None:
    anim = read_npz(source)
    write_animation(path, shadow=anim["shadow"], dS=anim["dS"], fps=fps)


@dataclass(frozen=True)
class _Snapshot:
    """A snapshot file of one method, with what the page's text needs of it (the arrays stay on disk)."""

    method: str
    path: Path
    time_s: float
    height: int
    width: int


def _snapshots_of(results: ResultFiles, groups, point: str) -> dict[int, list[_Snapshot]]:
    """Snapshot frame → its snapshots at one point, methods in results order, frames present for all."""
    by_frame: dict[int, list[_Snapshot]] = {}
    methods = [m for m, p in groups if p == point]
    for method in methods:
        for path in sorted((results.directory / "snapshots").glob(f"{capture_stem(method, point)}__f*.npz")):
            # An .npz loads its arrays one by one, when asked: the pictures read the rest where they are drawn.
            with np.load(path, allow_pickle=False) as snap:
                frame, time_s, shape = int(snap["frame"]), float(snap["time_s"]), snap["valid"].shape
            by_frame.setdefault(frame, []).append(_Snapshot(method, path, time_s, *shape))
    return {f: v for f, v in sorted(by_frame.items()) if len(v) == len(methods)}


def _frame_title(frame: int, snaps: list[_Snapshot]) -> str:
    return f"frame {frame}, t = {snaps[0].time_s:.2f} s"


def _strip_frames(frames: list[int], points: int) -> list[int]:
    """Every snapshot frame's strip; in a sweep only the middle snapshot frame of each point, to stay short."""
    return frames if points == 1 else frames[len(frames) // 2:][:1]


def _strips(directory: Path, snapshots: dict, strip_frames: dict, pool: PicturePool) -> list[dict]:
    """Submit the strips of each point to ``pool`` (one picture a point: they share a figure); return src and title."""
    strips = []
    for point, frames in strip_frames.items():
        drawn = []
        for frame in frames:
            snaps = snapshots[point][frame]
            name = f"figures/strip__{safe_name(point)}__f{frame}.webp"
            title = _frame_title(frame, snaps) + (f", point {point}" if len(strip_frames) > 1 else "")
            drawn.append(([s.path for s in snaps], directory / name, title))
            strips.append({"src": name, "title": title})
        if drawn:
            pool.submit(_draw_strips, drawn, [s.method for s in snapshots[point][frames[0]]])
    return strips


def _draw_strips(strips: list[tuple[list[Path], Path, str]], labels: list[str]) -> None:
    snapshot_strip_figures([([read_npz(p) for p in paths], path, title) for paths, path, title in strips], labels)


def _stabilization(results: ResultFiles, groups, points, pool: PicturePool) -> list[dict]:
    if results.cascades is None or len(results.cascades) == 0:
        return []
    present = set(zip(results.cascades["method"].tolist(), results.cascades["point"].tolist()))
    figures = []
    for point in points:
        methods = [m for m, p in groups if p == point and (m, p) in present]
        if methods:
            name = f"figures/stabilization__{safe_name(point)}.png"
            pool.submit(stabilization_figure, results.cascades.where(results.cascades["point"] == point), point=point,
                        methods=methods, path=results.directory / name)
            figures.append({"point": point, "src": name})
    return figures


def _view3d(directory: Path, snapshots: dict[int, list[_Snapshot]], pool: PicturePool) -> dict | None:
    """Submit the 3D view of the middle snapshot frame to ``pool``; ``picture`` gives None or why it failed."""
    if not snapshots:
        return None
    frames = list(snapshots)
    frame = frames[len(frames) // 2]
    snaps = snapshots[frame]
    title = _frame_title(frame, snaps)
    name = f"figures/view3d__f{frame}.png"
    picture = pool.submit(_draw_view3d, [s.path for s in snaps], [s.method for s in snaps], directory / name,
                          title=title)
    return {"src": name, "title": title, "picture": picture}


def _draw_view3d(paths: list[Path], labels: list[str], path: Path, *, title: str) -> str | None:
    """Render the 3D view; return None, or why it could not be rendered (no OpenGL, no PyVista)."""
    try:
        view3d_figure([read_npz(p) for p in paths], labels, path, title=title)
    except (RuntimeError, OSError, ImportError) as error:
        return f"{type(error).__name__}: {error}"
    return None


def _view3d_shown(view3d: dict | None) -> dict | None:
    if view3d is None:
        return None
    error = view3d["picture"].result()
    return {"src": None if error else view3d["src"], "title": view3d["title"], "error": error}


def _sweep(results: ResultFiles, points, pool: PicturePool) -> dict:
    if len(points) < 2:
        return {"sweep": [], "pareto": None}
    sweep = sweep_points(results.summary, points)
    figures = []
    for parameter in sweep.fields:
        means = sweep_means(results.metrics, sweep, along=parameter)
        name = f"figures/sweep__{safe_name(parameter)}.png"
        pool.submit(sweep_figure, means, parameter, results.directory / name)
        figures.append({"parameter": parameter, "src": name})
    means = sweep_means(results.metrics, sweep, along=sweep.fields[0])
    pareto = None
    if all(k in means for k in PARETO):
        pool.submit(pareto_figure, means, results.directory / "figures" / "pareto.png")
        pareto = "figures/pareto.png"
    return {"sweep": figures, "pareto": pareto}
