"""A game-size glTF level end to end: generate ~3M instanced triangles, load them, run 120 frames.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_gltf_level.py --out /tmp/gltf_bench \
        [--triangles 3000000] [--frames 120] [--width 640 --height 360] [--resolution 1024] [--jobs 2]

Writes ``level.glb`` (never committed: it is made here each time) and ``level.toml`` into ``--out``:
a 1 km hilly terrain (one height-field mesh) with trees (a cone crown and a trunk, one mesh drawn by
``EXT_mesh_gpu_instancing`` thousands of times) and stepped buildings (likewise), a
``KHR_lights_punctual`` sun and a camera rig walking through the woods (LINEAR translation, the eye
looking about with a CUBICSPLINE rotation). The instance counts are set so that the level holds
``--triangles`` in all. The experiment reads nothing but the file (``[light] from_scene = true``).

Then it measures, and prints as one JSON object:

- ``load_s``: reading the file into a Scene (:func:`csmlab.scene.load_mesh`: parse, place every
  instance, normals) and the camera path, in this process;
- the run, ``csmlab run level.toml --jobs J`` under ``/usr/bin/time -v`` in a child process: its wall
  time, GNU time's maximum resident set size (the largest single process) and the peak of the summed
  resident set size of the whole process tree (sampled every 0.2 s with psutil: the pool's workers
  each hold the scene);
- per-frame seconds from the run's ``timings.csv`` (the sum over stages and methods of each frame:
  median, p95, max) and wall seconds per frame.

The shared machine is busy: run it alone when the numbers matter, and say which card and load.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

from csmlab.scene.gltf_writer import GltfBuilder, box

TERRAIN_HALF = 500.0
"""Half the terrain's side, metres."""


def _height(x, z):
    """The terrain's height (m) at world ``x``, ``z``: rolling hills, flat enough to walk."""
    return 6.0 * np.sin(x / 57.0) * np.cos(z / 43.0) + 2.5 * np.sin((x + z) / 19.0)


def _terrain(cells: int) -> tuple[np.ndarray, np.ndarray]:
    axis = np.linspace(-TERRAIN_HALF, TERRAIN_HALF, cells + 1)
    x, z = np.meshgrid(axis, axis, indexing="ij")
    points = np.stack([x.ravel(), _height(x, z).ravel(), z.ravel()], axis=1)
    i, j = np.meshgrid(np.arange(cells), np.arange(cells), indexing="ij")
    a = (i * (cells + 1) + j).ravel()
    b, c, d = a + 1, a + cells + 2, a + cells + 1
    return points, np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])


def _tree(segments: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """A closed tree, ``10 · segments`` triangles: a trunk (radius 0.2 m, 1.2 m) under a cone crown to 5 m."""
    angle = 2 * np.pi * np.arange(segments) / segments
    ring = np.stack([np.cos(angle), np.zeros(segments), np.sin(angle)], axis=1)
    # Rings bottom to top, the surface's profile: trunk foot, trunk top, crown rim, two crown rings; then the tip.
    rings = [(0.2, 0.0), (0.2, 1.2), (1.6, 1.0), (1.1, 2.3), (0.6, 3.6)]
    points = np.concatenate([ring * radius + [0.0, y, 0.0] for radius, y in rings]
                            + [np.array([[0.0, 0.0, 0.0], [0.0, 5.0, 0.0]])])
    bottom, tip = len(points) - 2, len(points) - 1
    k = np.arange(segments)
    n = (k + 1) % segments

    def band(lo: int, hi: int) -> np.ndarray:
        """Quads between consecutive profile rings, counter-clockwise seen from outside."""
        return np.concatenate([np.stack([lo * segments + k, hi * segments + n, lo * segments + n], 1),
                               np.stack([lo * segments + k, hi * segments + k, hi * segments + n], 1)])

    caps = [np.stack([np.full(segments, bottom), k, n], 1),
            np.stack([np.full(segments, tip), 4 * segments + n, 4 * segments + k], 1)]
    return points, np.concatenate([band(0, 1), band(1, 2), band(2, 3), band(3, 4), *caps])


def _building(floors: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """``floors`` boxes of 3 m stacked with setbacks: ``12 · floors`` triangles."""
    points, tris = [], []
    for f in range(floors):
        p, t = box((12.0 - f, 3.0, 12.0 - f))
        tris.append(t + 8 * f)
        points.append(p + [0.0, 3.0 * f, 0.0])
    return np.concatenate(points), np.concatenate(tris)


def _quat_y(deg) -> np.ndarray:
    half = np.radians(np.asarray(deg, dtype=float)) / 2
    return np.stack([np.zeros_like(half), np.sin(half), np.zeros_like(half), np.cos(half)], axis=-1)


def write_level(file: Path, *, triangles: int, seconds: float, seed: int = 3) -> dict:
    """Write the level; returns its triangle counts by part."""
    rng = np.random.default_rng(seed)
    cells = max(8, int(np.sqrt(0.1 * triangles / 2)))  # a tenth of the triangles in the terrain
    terrain = _terrain(cells)
    tree, building = _tree(), _building()
    rest = max(triangles - terrain[1].shape[0], 0)
    trees = int(0.65 * rest / tree[1].shape[0])
    buildings = int((rest - trees * tree[1].shape[0]) / building[1].shape[0])
    builder = GltfBuilder()
    roots = [builder.add_node(name="terrain", mesh=builder.add_mesh(*terrain, name="terrain"))]
    # Trees anywhere but the walk's corridor (|x| < 6); buildings in a town to the east.
    xz = rng.uniform(-TERRAIN_HALF + 20, TERRAIN_HALF - 20, (trees * 2, 2))
    xz = xz[np.abs(xz[:, 0]) > 6.0][:trees]
    roots.append(builder.add_node(name="trees", mesh=builder.add_mesh(*tree, name="tree"), instances={
        "TRANSLATION": np.column_stack([xz[:, 0], _height(xz[:, 0], xz[:, 1]) - 0.2, xz[:, 1]]),
        "ROTATION": _quat_y(rng.uniform(0, 360, len(xz))),
        "SCALE": np.repeat(rng.uniform(0.7, 1.6, (len(xz), 1)), 3, axis=1)}))
    side = int(np.ceil(np.sqrt(buildings)))
    grid = np.array([(i, j) for i in range(side) for j in range(side)][:buildings], dtype=float)
    bx, bz = 40.0 + grid[:, 0] * 18.0, -TERRAIN_HALF + 30.0 + grid[:, 1] * 18.0
    bx, bz = bx % (TERRAIN_HALF - 60.0) + 20.0, (bz + TERRAIN_HALF) % (2 * TERRAIN_HALF - 60.0) - TERRAIN_HALF + 30
    roots.append(builder.add_node(name="town", mesh=builder.add_mesh(*building, name="building"), instances={
        "TRANSLATION": np.column_stack([bx, _height(bx, bz) - 1.0, bz]),
        "SCALE": np.column_stack([np.ones(len(bx)), rng.uniform(0.5, 1.5, len(bx)), np.ones(len(bx))])}))
    pitch = np.radians(-38.0) / 2
    sun = builder.add_light(name="sun")
    roots.append(builder.add_node(name="sun", light=sun, rotation=[np.sin(pitch) * np.cos(np.radians(20)),
                                                                   np.cos(pitch) * np.sin(np.radians(20)),
                                                                   -np.sin(pitch) * np.sin(np.radians(20)),
                                                                   np.cos(pitch) * np.cos(np.radians(20))]))
    eye = builder.add_node(name="eye", camera=builder.add_camera(name="eye", yfov_rad=float(np.radians(60.0)),
                                                                  znear=0.1, zfar=400.0, aspect=16 / 9),
                           translation=(0.0, 1.7, 0.0))
    rig = builder.add_node(name="rig", children=[eye])
    roots.append(rig)
    keys = np.linspace(0.0, seconds, 5)
    walk_z = np.linspace(60.0, 60.0 - 1.4 * seconds, 5)
    spline = np.concatenate([np.zeros((5, 1, 4)), _quat_y([0.0, 20.0, -10.0, 15.0, 0.0])[:, None], np.zeros((5, 1, 4))],
                            axis=1).reshape(-1, 4)
    builder.add_animation([
        (rig, "translation", keys, np.column_stack([np.zeros(5), _height(0.0, walk_z), walk_z]), "LINEAR"),
        (eye, "rotation", keys, spline, "CUBICSPLINE")], name="walk")
    builder.save(file, roots=roots)
    return {"terrain": int(terrain[1].shape[0]), "trees": trees, "tree_triangles": int(tree[1].shape[0]),
            "buildings": int(len(bx)), "building_triangles": int(building[1].shape[0]),
            "triangles": int(terrain[1].shape[0] + trees * tree[1].shape[0] + len(bx) * building[1].shape[0])}


EXPERIMENT = """\
name = "gltf_level_bench"
description = "benchmarks/bench_gltf_level.py: a generated instanced glTF level"

[scene]
kind = "mesh"
file = "level.glb"

[camera]
file = "level.glb"
camera = "eye"
fps = 30.0
frames = {frames}
width = {width}
height = {height}

[light]
from_scene = true

[shadow]
cascades = 4
resolution = {resolution}
shadow_distance = 150.0

[[methods]]
name = "exact"
stabilization = "exact"

[[methods]]
name = "none"
stabilization = "none"
"""


def _tree_rss(pid: int) -> int:
    import psutil

    try:
        root = psutil.Process(pid)
        processes = [root, *root.children(recursive=True)]
    except psutil.NoSuchProcess:
        return 0
    total = 0
    for process in processes:
        try:
            total += process.memory_info().rss
        except psutil.NoSuchProcess:
            pass
    return total


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, required=True, help="folder for level.glb, level.toml and the run")
    parser.add_argument("--triangles", type=int, default=3_000_000)
    parser.add_argument("--frames", type=int, default=120)
    parser.add_argument("--width", type=int, default=640)
    parser.add_argument("--height", type=int, default=360)
    parser.add_argument("--resolution", type=int, default=1024)
    parser.add_argument("--jobs", type=int, default=2)
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    level = args.out / "level.glb"
    started = time.perf_counter()
    counts = write_level(level, triangles=args.triangles, seconds=(args.frames - 1) / 30.0)
    write_s = time.perf_counter() - started
    experiment = args.out / "level.toml"
    experiment.write_text(EXPERIMENT.format(frames=args.frames, width=args.width, height=args.height,
                                            resolution=args.resolution))

    from csmlab.config import load_experiment
    from csmlab.experiment import build_workload

    started = time.perf_counter()
    workload = build_workload(load_experiment(experiment))
    load_s = time.perf_counter() - started
    triangles = workload.scene.triangle_count
    del workload

    run_dir = args.out / "run"
    command = ["/usr/bin/time", "-v", sys.executable, "-m", "csmlab.cli", "run", str(experiment), "--out",
               str(run_dir), "--jobs", str(args.jobs)]
    peak, done = [0], threading.Event()
    child = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=os.environ)

    def sample():
        while not done.is_set():
            peak[0] = max(peak[0], _tree_rss(child.pid))
            time.sleep(0.2)

    sampler = threading.Thread(target=sample, daemon=True)
    sampler.start()
    started = time.perf_counter()
    stdout, stderr = child.communicate()
    run_s = time.perf_counter() - started
    done.set()
    sampler.join()
    if child.returncode != 0:
        sys.exit(f"csmlab run failed ({child.returncode}):\n{stdout}\n{stderr}")
    max_rss_kib = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", stderr).group(1))
    rows = np.genfromtxt(run_dir / "timings.csv", delimiter=",", names=True, dtype=None, encoding="utf-8")
    frames = np.unique(rows["frame"])
    per_frame = np.array([rows["seconds"][rows["frame"] == f].sum() for f in frames])
    print(json.dumps({
        "level": {**counts, "file_mib": round(level.stat().st_size / 2**20, 1), "write_s": round(write_s, 2)},
        "scene_triangles": triangles, "load_s": round(load_s, 2),
        "run": {"frames": int(frames.size), "jobs": args.jobs, "width": args.width, "height": args.height,
                "resolution": args.resolution, "methods": 2, "wall_s": round(run_s, 1),
                "wall_s_per_frame": round(run_s / frames.size, 2),
                "gnu_time_max_rss_gib": round(max_rss_kib / 2**20, 2),
                "process_tree_peak_rss_gib": round(peak[0] / 2**30, 2)},
        "frame_s": {"median": round(float(np.median(per_frame)), 3),
                    "p95": round(float(np.percentile(per_frame, 95)), 3), "max": round(float(per_frame.max()), 3)},
        "load_average": os.getloadavg(),
    }, indent=1))


if __name__ == "__main__":
    main()
