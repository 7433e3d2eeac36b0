"""Time the report of a run: per-frame captures, their files, and ``write_report``.

    .venv/bin/python benchmarks/bench_report.py [--frames 120] [--methods 3] [--width 640 --height 360]
        [--cascades 4] [--resolution 1024]
    .venv/bin/python benchmarks/bench_report.py --results reports/default [--repeat 2]

Without ``--results`` it builds a results directory the size of the default run (120 frames ×
3 methods, 640×360, 4 cascades) in a temporary folder: real cascades (``build_cascades``) along
a walking camera over a ground plane, synthetic per-pixel maps of the right shapes and dtypes,
and a ``metrics.csv`` / ``timings.csv`` / ``summary.json`` of that size. It prints the time of
:func:`capture_frame` per frame (done in the workers, in parallel with rendering), of
:func:`write_captures` for all methods and of :func:`write_report` — the last two are what the
report adds to a run's wall time. With ``--results DIR`` it works on copies of a real run's
results directory (``DIR`` is left as it is): the CPU and wall time of each part of the report
drawn one after the other in this process; then, each in a fresh interpreter on a fresh copy
(best of ``--repeat``), the wall time of ``write_report`` with every picture drawn in its own
process, with the pictures in a worker process and as it chooses, and of the whole
``csmlab report DIR`` command; and the directory's size before and after.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import csmlab.report as report
from csmlab import results
from csmlab.camera import CameraPose
from csmlab.cascades import build_cascades
from csmlab.frame import Frame, GBuffer, ShadowLookup, ShadowMaps, View
from csmlab.kernels.visibility import CameraHits
from csmlab.geometry import rotation_looking_at
from csmlab.light import direction_from_angles
from csmlab.metric_registry import metric_columns
from csmlab.report import write_report
from csmlab.report.capture import capture_frame, default_snapshot_frames, write_captures
from csmlab.report.figures import frame_curves_figure
from csmlab.report.tables import read_results
from csmlab.settings import ShadowSettings

LIGHT = direction_from_angles(elevation_deg=40.0, azimuth_deg=30.0)
SCENE_CORNERS = np.array([[x, y, z] for x in (-200, 200) for y in (-5, 30) for z in (-200, 200)], dtype=float)
METHODS = ("exact", "quantized", "none")


@dataclass(frozen=True)
class Measures:
    """What :func:`capture_frame` reads of :class:`csmlab.metrics.FrameMeasures`."""

    values: dict
    pixels: dict


def _ground_hits(pose: CameraPose, width: int, height: int) -> np.ndarray:
    """World points ``(H, W, 3)`` where pixel rays meet the plane y = 0; NaN above the horizon."""
    ty = np.tan(np.radians(pose.fov_y_deg) / 2)
    u = ((np.arange(width) + 0.5) / width * 2 - 1) * ty * pose.aspect
    v = (1 - (np.arange(height) + 0.5) / height * 2) * ty
    rays = np.stack(np.broadcast_arrays(u[None, :], v[:, None], -1.0), axis=-1) @ pose.rotation.T
    t = -pose.position[1] / rays[..., 1]
    hits = pose.position + t[..., None] * rays
    return np.where((t > 0)[..., None], hits, np.nan)


def synthetic_frame(index: int, method: str, *, width: int, height: int, cascades: int, resolution: int):
    """A frame of ``method`` with real cascades and synthetic per-pixel maps of the real shapes and dtypes."""
    rng = np.random.default_rng(index)
    pose = CameraPose(position=np.array([1.4 * index / 30, 1.7, 0.0]),
                      orientation=rotation_looking_at([np.sin(index / 40), -0.15, -1.0]),
                      aspect=width / height, time_s=index / 30)
    settings = ShadowSettings(cascades=cascades, resolution=resolution, stabilization=method)
    cascade_set = build_cascades(pose=pose, light_direction=LIGHT, scene_corners=SCENE_CORNERS, settings=settings)
    position = _ground_hits(pose, width, height)
    valid = np.isfinite(position[..., 0])
    depth = np.where(valid, pose.view_depth(np.nan_to_num(position)), np.inf)
    lit = np.where(valid, (np.sin(position[..., 0]) + np.sin(position[..., 2]) > 0).astype(np.float32), np.nan)
    cascade = np.where(valid, np.searchsorted(cascade_set.splits, depth) - 1, -1).clip(-1, cascades - 1)
    gbuffer = GBuffer(hits=CameraHits(position=position, normal=np.zeros((height, width, 3), np.float32),
                                      triangle=np.where(valid, 0, -1).astype(np.int32),
                                      view_depth=depth.astype(np.float32)),
                      albedo=np.full((height, width, 3), 0.4, np.float32))
    view = View(index=index, pose=pose, light_direction=LIGHT, gbuffer=gbuffer, reference=lit)
    frame = Frame(view=view, settings=settings,
                  maps=ShadowMaps(cascades=cascade_set, depth=np.zeros((cascades, 1, 1), np.float32),
                                  texels_rasterized=0),
                  shadow=ShadowLookup(lit=lit, cascade=cascade.astype(np.int8), blend=np.zeros_like(valid)))
    change = np.where(valid, np.abs(rng.normal(0, 0.05, valid.shape)) * (method != "exact"), np.nan)
    shaded = np.where(valid[..., None], 0.2 + 0.6 * np.nan_to_num(lit)[..., None] * np.array([0.5, 0.6, 0.3]), np.nan)
    pixels = {"dS": change if index else np.full(valid.shape, np.nan), "shaded": shaded,
              "rho": np.where(valid, 2.0 ** rng.normal(0, 1, valid.shape), np.nan).astype(np.float32),
              "ref_diff": np.where(rng.random(valid.shape) < 0.01, 1, 0).astype(np.int8)}
    return frame, Measures(values={}, pixels=pixels)


def synthesize_results(out: Path, *, frames: int, methods: tuple[str, ...], width: int, height: int, cascades: int,
                       resolution: int) -> dict:
    """Write a results directory of the given size; return seconds spent in capture_frame and write_captures."""
    snapshots = set(default_snapshot_frames(frames))
    columns = metric_columns(cascades)
    rng = np.random.default_rng(0)
    rows, timings, captures = [], [], {m: [] for m in methods}
    capture_seconds = {"frame": 0.0, "snapshot": 0.0}
    for index in range(frames):
        for method in methods:
            frame, measures = synthetic_frame(index, method, width=width, height=height, cascades=cascades,
                                              resolution=resolution)
            began = time.perf_counter()
            captures[method].append(capture_frame(frame, measures, snapshot=index in snapshots))
            capture_seconds["snapshot" if index in snapshots else "frame"] += time.perf_counter() - began
            values = {c: float(rng.random()) for c in columns}
            values["memory_bytes"] = 4.0 * cascades * resolution ** 2
            rows.append(results.MetricRow(index, index / 30, method, "base", values))
            timings += [results.TimingRow(index, method, "base", stage, float(rng.random()) * 0.1)
                        for stage in ("raster", "shadow")]
    order = {(m, "base"): k for k, m in enumerate(methods)}
    out.mkdir(parents=True, exist_ok=True)
    results.write_metrics(out / "metrics.csv", ([r for r in rows if r.method == m] for m in methods), columns=columns)
    results.write_timings(out / "timings.csv", [timings], order=order)
    (out / "summary.json").write_text(json.dumps({
        "name": "bench", "config_hash": "0" * 16, "csmlab_version": "bench",
        "config": {"scene": {"kind": "plane"}, "camera": {"fps": 30, "frames": frames, "width": width,
                                                          "height": height}}}))
    began = time.perf_counter()
    for method in methods:
        write_captures(out, method=method, point="base", captures=captures[method])
    return {"capture_frame_ms": 1000 * capture_seconds["frame"] / max(1, (frames - len(snapshots)) * len(methods)),
            "capture_snapshot_ms": 1000 * capture_seconds["snapshot"] / max(1, len(snapshots) * len(methods)),
            "write_captures_s": time.perf_counter() - began}


class _TimedPool:
    """Stands in for :class:`csmlab.report.picture_pool.PicturePool`: draws each picture at once, timing it."""

    def __init__(self):
        self.parts: list[tuple[str, float, float]] = []

    def submit(self, function, /, *args, **kwargs):
        self.parts.append(_timed(function.__name__, function, *args, **kwargs)[1])


def _timed(name: str, function, *args, **kwargs):
    cpu, wall = time.process_time(), time.perf_counter()
    value = function(*args, **kwargs)
    return value, (name, time.process_time() - cpu, time.perf_counter() - wall)


def _size(folder: Path) -> int:
    return sum(p.stat().st_size for p in folder.rglob("*") if p.is_file())


def report_parts(out: Path) -> list[tuple[str, float, float]]:
    """``(part, CPU s, wall s)`` of each part of :func:`write_report`, drawn one after the other here."""
    loaded, read = _timed("read results", read_results, out)
    groups = loaded.metrics.groups()
    points = list(dict.fromkeys(p for _, p in groups))
    snapshots = {point: report._snapshots_of(loaded, groups, point) for point in points}
    strip_frames = {point: report._strip_frames(list(snapshots[point]), len(points)) for point in points}
    pool = _TimedPool()
    report._view3d(out, snapshots[points[0]], pool)
    report._strips(out, snapshots, strip_frames, pool)
    report._stabilization(loaded, groups, points, pool)
    pool.submit(frame_curves_figure, loaded.metrics, out / "figures" / "curves.png")
    report._cost(loaded, groups, pool)
    report._animations(loaded, groups, pool)
    labels = [m if len(points) == 1 else f"{m} @ {p}" for m, p in groups]
    files, made = _timed("explore_files", report.explore_files, out, groups=groups, labels=labels,
                         metrics=loaded.metrics)
    _, written = _timed("write_explore", report.write_explore, out, files)
    return [read, *pool.parts, made, written]


_FRESH = """
import sys, time
from csmlab.report import write_report
began = time.perf_counter()
write_report(sys.argv[1], worker={worker})
print(time.perf_counter() - began)
"""


def _fresh_report(copy: Path, *, worker: bool | None) -> float:
    """Seconds of ``write_report`` in a fresh interpreter that has imported csmlab.report, as ``csmlab run`` has."""
    done = subprocess.run([sys.executable, "-c", _FRESH.format(worker=worker), str(copy)], check=True,
                          capture_output=True, text=True)
    return float(done.stdout.split()[-1])


def _fresh_command(copy: Path) -> float:
    """Wall seconds of ``csmlab report DIR``, interpreter start and imports included."""
    began = time.perf_counter()
    subprocess.run([sys.executable, "-m", "csmlab.cli", "report", str(copy)], check=True, capture_output=True)
    return time.perf_counter() - began


def time_results(source: Path, *, repeat: int) -> None:
    """Print the parts of ``source``'s report, then ``write_report`` and ``csmlab report`` each in a fresh process."""
    with tempfile.TemporaryDirectory() as tmp:
        copy = Path(tmp) / "results"
        shutil.copytree(source, copy)
        before = _size(copy)
        (copy / "figures").mkdir(exist_ok=True)
        print(f"{'part (one after the other)':26s} {'CPU s':>6s} {'wall s':>7s}")
        for name, cpu, wall in report_parts(copy):
            print(f"{name:26s} {cpu:6.2f} {wall:7.2f}")
        runs = (("write_report, pictures here", lambda: _fresh_report(copy, worker=False)),
                ("write_report, pictures in a worker", lambda: _fresh_report(copy, worker=True)),
                ("write_report (its own choice)", lambda: _fresh_report(copy, worker=None)),
                ("csmlab report DIR (command)", lambda: _fresh_command(copy)))
        for name, run in runs:
            walls = []
            for _ in range(repeat):
                shutil.rmtree(copy)
                shutil.copytree(source, copy)
                walls.append(run())
            print(f"{name + ':':36s} {min(walls):5.2f} s wall (best of {repeat})")
        print(f"results directory: {before / 2**20:.1f} MiB as given, {_size(copy) / 2**20:.1f} MiB with this report")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--results", type=Path, help="time the report of this results directory (on copies) instead")
    parser.add_argument("--repeat", type=int, default=2, help="with --results: runs of write_report, best kept")
    parser.add_argument("--frames", type=int, default=120)
    parser.add_argument("--methods", type=int, default=3, choices=range(1, len(METHODS) + 1))
    parser.add_argument("--width", type=int, default=640)
    parser.add_argument("--height", type=int, default=360)
    parser.add_argument("--cascades", type=int, default=4)
    parser.add_argument("--resolution", type=int, default=1024)
    args = parser.parse_args()
    if args.results is not None:
        time_results(args.results, repeat=args.repeat)
        return
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "bench"
        stats = synthesize_results(out, frames=args.frames, methods=METHODS[:args.methods], width=args.width,
                                   height=args.height, cascades=args.cascades, resolution=args.resolution)
        began = time.perf_counter()
        write_report(out)
        report_s = time.perf_counter() - began
        size = _size(out) / 2**20
    print(f"{args.frames} frames × {args.methods} methods, {args.width}×{args.height}, {args.cascades} cascades")
    print(f"capture_frame (in the workers): {stats['capture_frame_ms']:.1f} ms a frame, "
          f"{stats['capture_snapshot_ms']:.1f} ms a snapshot frame")
    print(f"write_captures (parent):        {stats['write_captures_s']:.2f} s")
    print(f"write_report:                   {report_s:.2f} s")
    print(f"report beyond the run:          {stats['write_captures_s'] + report_s:.2f} s ({size:.1f} MiB on disk)")


if __name__ == "__main__":
    main()
