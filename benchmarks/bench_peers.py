"""csmlab's kernels beside Open3D's Embree ray caster on the same scene, cascades and rays.

    .venv/bin/python benchmarks/bench_peers.py [--sizes 136k,1m] [--resolutions 1024,2048]
        [--width 640 --height 360] [--repeats 5] [--json bench.json] [--experiment] [--dask] [--long]

Per scene size (the ``terrain`` scene with its ground grid scaled to ~136k and ~1M triangles) and
shadow-map resolution, at frame 60 of the default experiment's walk, it times:

- ``gbuffer raster`` and ``gbuffer ray``: csmlab's camera G-buffer (first hit, position, normal) by
  each of :data:`csmlab.kernels.visibility.VISIBILITY_METHODS`, on one core and (``, 2 threads``)
  on two, all against one measurement of Open3D ``RaycastingScene.cast_rays`` on the same
  pixel-centre rays;
- ``shadow irregular`` and ``shadow ray``: csmlab's ray-traced reference by each of
  :data:`csmlab.kernels.reference.REFERENCE_METHODS`, on one core and on two, all against one
  measurement of Open3D ``test_occlusions`` on the same rays (visible points facing the light, toward the light);
  ``shadow irregular, new light`` is the first with the scene's light-space vertices transformed
  anew each time, as for a light that moves every frame (a static light transforms them once);
- ``depth maps``: csmlab's cascade pass (fixed-point conversion + rasterization of 4 cascades)
  against ``cast_rays`` along the light through every texel centre of the same cascades; ``depth
  maps, 2 threads`` the same pass on both cores (:attr:`csmlab.render.DeviceScene.threads`), and
  ``depth maps, scrolled`` the pass of an exact box scrolled from frame 59's maps, as a run does
  (:mod:`csmlab.scrolling`);
- ``lookup``: csmlab's shadow lookup at every visible pixel (no peer);
- ``memcpy``: a copy of the depth maps (the memory-bandwidth floor the depth maps are compared to).

Then, on the default scene (265k triangles), frame 60 of the walk against frame 59, the metrics of
one frame × method for ``exact``, ``quantized`` and ``none`` (``metrics`` rows). Every time is the
minimum of ``--repeats`` runs after a warm-up, taken in rounds: each round runs every row of a scene
and resolution and its peers once (:func:`best_in_rounds`), so that a slow spell of the shared
machine meets csmlab and Open3D alike and the minimum is the least disturbed run of each. Open3D is
optional (``pip install csmlab[bench]``); without it the peer columns print ``n/a``.

``--experiment`` also runs the default experiment (``csmlab run``) and reports its wall time and the
peak RSS of its largest process; ``--dask`` runs a 240-frame walk of ``exact`` on a local Dask
cluster of 1 and of 2 workers, each twice in turn (:data:`DASK_REPEATS`), and reports the speed-up of
the wall time and of the frames phase ``csmlab run`` prints (the report after it is the parent's work
either way); ``--long`` runs ``benchmarks/long_walk.toml`` (two methods, a 64×36 view) for 1,000 and
10,000 frames and reports the peak RSS of each: a flat peak means nothing grows with the path.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

# Run as a script, this file's folder comes first on sys.path: put the checkout it belongs to
# before any installed csmlab.
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from csmlab.cascades import build_cascades
from csmlab.config import load_experiment
from csmlab.experiment import build_workload
from csmlab.kernels import start_warp
from csmlab.kernels.reference import RAY_OFFSET, REFERENCE_METHODS, hard_shadow
from csmlab.kernels.visibility import VISIBILITY_METHODS, camera_hits
from csmlab.metrics import measure_frame
from csmlab.render import lookup_shadow, prepare_scene, render_shadow, render_view, shadow_maps
from csmlab.scene import make_scene
from csmlab.settings import ShadowSettings

ROOT = Path(__file__).resolve().parents[1]
SIZES = {"136k": 196, "265k": 320, "1m": 680}
"""Scene sizes by label: the terrain's ground grid cells per side (2·n² ground triangles + ~60k of trees)."""
FRAME = 60


def best_in_rounds(calls: dict, rounds: int, *, fewer: frozenset = frozenset()) -> dict:
    """Minimum wall-clock seconds of each of ``calls`` (name → function) over ``rounds`` rounds.

    Each function runs once untimed, then once per round, the rounds one after another: every call
    meets the machine in the same states (a shared machine drifts between fast and slow spells of
    seconds, longer than a row's back-to-back repeats), so their ratios are fair. The calls named in
    ``fewer`` (Open3D's texel rays, seconds each) run only in the first half of the rounds.
    """
    for fn in calls.values():
        fn()
    best = dict.fromkeys(calls, np.inf)
    for k in range(rounds):
        for name, fn in calls.items():
            if name in fewer and k >= max(1, rounds // 2):
                continue
            start = time.perf_counter()
            fn()
            best[name] = min(best[name], time.perf_counter() - start)
    return best


def open3d_scene(scene):
    """An Open3D RaycastingScene of ``scene`` (float32 vertices relative to the bounds centre), or None."""
    try:
        import open3d as o3d
    except ImportError:
        return None, None
    anchor = 0.5 * (scene.vertices.min(axis=0) + scene.vertices.max(axis=0))
    rc = o3d.t.geometry.RaycastingScene()
    rc.add_triangles(o3d.core.Tensor((scene.vertices - anchor).astype(np.float32)),
                     o3d.core.Tensor(scene.triangles.astype(np.uint32)))
    rc.cast_rays(o3d.core.Tensor(np.zeros((1, 6), np.float32)))  # builds the BVH
    return rc, anchor


def pixel_rays(pose, width: int, height: int, anchor) -> np.ndarray:
    """``(H·W, 6)`` float32 rays through the pixel centres (origin relative to ``anchor``)."""
    tan_y = np.tan(np.radians(pose.fov_y_deg) / 2.0)
    sx = ((np.arange(width) + 0.5) / width * 2.0 - 1.0) * tan_y * pose.aspect
    sy = (1.0 - (np.arange(height) + 0.5) / height * 2.0) * tan_y
    r = pose.rotation
    d = (-r[:, 2])[None, None] + sx[None, :, None] * r[:, 0] + sy[:, None, None] * r[:, 1]
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    o = np.broadcast_to(pose.position - anchor, d.shape)
    return np.concatenate([o, d], axis=-1).reshape(-1, 6).astype(np.float32)


def shadow_rays(view, anchor, diagonal: float) -> np.ndarray:
    """``(N, 6)`` float32 rays of csmlab's reference: visible points facing the light, offset along n, toward it."""
    g = view.gbuffer
    toward = -view.light_direction
    valid = g.valid & (g.normal.astype(np.float64) @ toward > 0.0)
    start = g.position[valid] - anchor + g.normal[valid] * (RAY_OFFSET * diagonal)
    return np.concatenate([start, np.broadcast_to(toward, start.shape)], axis=1).astype(np.float32)


def texel_rays(cascades, anchor) -> np.ndarray:
    """``(C·R², 6)`` float32 rays along the light through every texel centre of every cascade."""
    basis = cascades.basis
    rays = []
    for c in cascades.cascades:
        r = c.resolution
        centres = (c.origin[:, None] + np.arange(r) + 0.5) * c.texel_size[:, None]
        x, y = np.meshgrid(centres[0], centres[1])
        start = (x[..., None] * basis[0] + y[..., None] * basis[1] + (c.depth_near - 1.0) * basis[2]).reshape(-1, 3)
        rays.append(np.concatenate([start - anchor, np.broadcast_to(basis[2], start.shape)], axis=1))
    return np.concatenate(rays).astype(np.float32)


def peer_calls(name: str, rc, rays: np.ndarray, *, occlusion: bool) -> dict:
    """Open3D on ``rays`` with 2 threads and with 1 thread, as ``{(name, threads): function}`` (none without Open3D)."""
    if rc is None:
        return {}
    import open3d as o3d

    tensor = o3d.core.Tensor(rays)
    call = rc.test_occlusions if occlusion else rc.cast_rays
    return {(name, n): (lambda n=n: call(tensor, nthreads=n)) for n in (2, 1)}


THREADS = ((1, ""), (2, ", 2 threads"))
"""Thread counts of the G-buffer and reference rows (:attr:`csmlab.render.DeviceScene.threads`) and their labels."""


def bench_kernels(label: str, resolution: int, *, width: int, height: int, repeats: int, pose, light,
                  previous_pose) -> list[dict]:
    scene = make_scene("terrain", seed=1, resolution=SIZES[label])
    dscene = prepare_scene(scene, device="cpu")
    both_cores = prepare_scene(scene, device="cpu", threads=2)
    rc, anchor = open3d_scene(scene)
    anchor = dscene.bvh.anchor if anchor is None else anchor
    settings = ShadowSettings(cascades=4, resolution=resolution, filter="pcf", filter_size=3)
    view = render_view(dscene, pose, light, width=width, height=height)
    cascades = build_cascades(pose=pose, light_direction=light, scene_corners=scene.corners(), settings=settings)
    g = view.gbuffer
    maps = shadow_maps(dscene, cascades, settings)
    # The same method one frame earlier, what an exact box scrolls from (csmlab.scrolling).
    earlier = shadow_maps(dscene, build_cascades(pose=previous_pose, light_direction=light,
                                                 scene_corners=scene.corners(), settings=settings), settings)
    depth_copy = np.empty_like(maps.depth)
    texels = maps.depth.size
    pixels = width * height
    occluders = shadow_rays(view, anchor, dscene.bvh.diagonal)
    b = dscene.bvh
    peers = {**peer_calls("camera", rc, pixel_rays(pose, width, height, anchor), occlusion=False),
             **peer_calls("shadow", rc, occluders, occlusion=True),
             **peer_calls("texel", rc, texel_rays(cascades, anchor), occlusion=False)}
    rows = [
        (f"gbuffer {method}{label}", pixels, "Mrays/s",
         lambda method=method, threads=threads: camera_hits(
             b, position=pose.position, rotation=pose.rotation, fov_y_deg=pose.fov_y_deg, aspect=pose.aspect,
             far=pose.far, width=width, height=height, method=method, threads=threads),
         "camera")
        for method in VISIBILITY_METHODS for threads, label in THREADS
    ] + [
        (f"shadow {method}{label}", len(occluders), "Mrays/s",
         lambda method=method, threads=threads: hard_shadow(b, points=g.position, normals=g.normal,
                                                            light_direction=light, method=method, threads=threads),
         "shadow")
        for method in REFERENCE_METHODS for threads, label in THREADS
    ] + [
        ("shadow irregular, new light", len(occluders), "Mrays/s",
         lambda: (b.light_space.clear(), hard_shadow(b, points=g.position, normals=g.normal, light_direction=light)),
         "shadow"),
        ("depth maps", texels, "Mtexels/s", lambda: shadow_maps(dscene, cascades, settings), "texel"),
        ("depth maps, 2 threads", texels, "Mtexels/s", lambda: shadow_maps(both_cores, cascades, settings), "texel"),
        ("depth maps, scrolled", texels, "Mtexels/s",
         lambda: shadow_maps(dscene, cascades, settings, scroll_from=earlier), "texel"),
        ("lookup", pixels, "Mpix/s",
         lambda: lookup_shadow(maps, points=g.position, normals=g.normal, view_depth=g.view_depth,
                               settings=settings), None),
    ]
    best = best_in_rounds({**{stage: ours for stage, _, _, ours, _ in rows}, **peers,
                           "memcpy": lambda: np.copyto(depth_copy, maps.depth)}, repeats,
                          fewer=frozenset(k for k in peers if k[0] == "texel"))
    floor = best["memcpy"]
    out = []
    for stage, count, unit, _, peer in rows:
        two, one = (best.get((peer, n), float("nan")) for n in (2, 1))
        out.append(dict(scene=label, triangles=scene.triangle_count, resolution=resolution, stage=stage,
                        count=count, unit=unit, csmlab_s=best[stage], open3d_2t_s=two, open3d_1t_s=one,
                        memcpy_s=floor if stage.startswith("depth maps") else float("nan")))
    out.append(dict(scene=label, triangles=scene.triangle_count, resolution=resolution, stage="memcpy",
                    count=texels, unit="Mtexels/s", csmlab_s=floor, open3d_2t_s=float("nan"),
                    open3d_1t_s=float("nan"), memcpy_s=floor))
    return out


def bench_metrics(*, repeats: int) -> list[dict]:
    experiment = load_experiment(ROOT / "experiments" / "default.toml")
    workload = build_workload(experiment)
    dscene = prepare_scene(workload.scene, device="cpu")
    views = [render_view(dscene, workload.path.pose(i), workload.light.direction(i), width=workload.width,
                         height=workload.height, index=i) for i in (FRAME - 1, FRAME)]
    frames = {variant: tuple(render_shadow(dscene, v, variant.settings) for v in views)
              for variant in experiment.variants()}
    # As in a run's worker (csmlab.experiment.run_chunk): one thread per library pool. A fresh copy of
    # the view each time, so that the view-only work (View.shared) is timed too, as if the method ran
    # alone; a run shares it among its methods.
    with threadpool_limits(limits=1):
        best = best_in_rounds({variant: (lambda before=before, now=now: measure_frame(
            dataclasses.replace(now, view=dataclasses.replace(now.view)), before))
            for variant, (before, now) in frames.items()}, repeats)
    return [dict(scene="265k", triangles=workload.scene.triangle_count, resolution=variant.settings.resolution,
                 stage=f"metrics {variant.method}", count=workload.width * workload.height, unit="Mpix/s",
                 csmlab_s=seconds, open3d_2t_s=float("nan"), open3d_1t_s=float("nan"), memcpy_s=float("nan"))
            for variant, seconds in best.items()]


_MEASURED = ("import resource, subprocess, sys; subprocess.run(sys.argv[1:], check=True); "
             "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)")
"""Runs a command in a fresh process, passing its output on, and prints the peak RSS (KiB) of its largest
process, workers included: each command's peak is its own, not the largest of every command this benchmark ran."""

_PHASES = re.compile(r"frames × .* in ([0-9.]+) s .*; report in ([0-9.]+) s", re.DOTALL)
"""What ``csmlab run`` prints of its two phases: the frames (start-up, workers and results written) and the report."""


def run_command(args: list[str]) -> dict:
    """Wall seconds of a ``csmlab run`` command, the seconds of its frames and report phases as it prints
    them, and the peak RSS (MiB) of its largest process."""
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", _MEASURED, *args], check=True, cwd=ROOT, capture_output=True,
                          text=True)
    wall = time.perf_counter() - start
    phases = _PHASES.search(done.stdout)
    return dict(wall_s=wall, run_s=float(phases[1]) if phases else float("nan"),
                report_s=float(phases[2]) if phases else float("nan"),
                peak_rss_mib=int(done.stdout.split()[-1]) / 1024.0)


def bench_experiment() -> dict:
    with tempfile.TemporaryDirectory() as out:
        return run_command([sys.executable, "-m", "csmlab.cli", "run", "--out", out])


DASK_REPEATS = 2
"""Runs of each Dask configuration, 1 and 2 workers taking turns so that both meet the machine alike;
each keeps its fastest (wall time), as the kernel rows keep the fastest of ``--repeats``."""


def bench_dask(repeats: int = DASK_REPEATS) -> dict:
    experiment = ROOT / "benchmarks" / "dask_walk.toml"
    runs = {}
    for _ in range(repeats):
        for jobs in (1, 2):
            with tempfile.TemporaryDirectory() as out:
                run = run_command([sys.executable, "-m", "csmlab.cli", "run", str(experiment), "--out", out,
                                   "--scheduler", "local", "--jobs", str(jobs)])
            if jobs not in runs or run["wall_s"] < runs[jobs]["wall_s"]:
                runs[jobs] = run
    speedup = runs[1]["wall_s"] / runs[2]["wall_s"]
    return dict(one_worker_s=runs[1]["wall_s"], two_workers_s=runs[2]["wall_s"], speedup=speedup,
                efficiency=speedup / 2.0, one_worker_run_s=runs[1]["run_s"], two_workers_run_s=runs[2]["run_s"],
                run_speedup=runs[1]["run_s"] / runs[2]["run_s"], report_s=runs[2]["report_s"],
                peak_rss_mib=max(r["peak_rss_mib"] for r in runs.values()))


def bench_long(frames: tuple[int, ...] = (1000, 10000)) -> list[dict]:
    """Peak RSS and wall time of ``benchmarks/long_walk.toml`` (a small view) at each path length."""
    experiment = ROOT / "benchmarks" / "long_walk.toml"
    runs = []
    for count in frames:
        with tempfile.TemporaryDirectory() as out:
            run = run_command([sys.executable, "-m", "csmlab.cli", "run", str(experiment), "--out", out,
                               "--frames", str(count)])
        runs.append(dict(frames=count, **run))
    return runs


def _ms(seconds: float) -> str:
    return "n/a" if not np.isfinite(seconds) else f"{seconds * 1e3:,.1f}"


def _ratio(a: float, b: float) -> str:
    return "n/a" if not (np.isfinite(a) and np.isfinite(b)) else f"{a / b:.2f}x"


def print_table(rows: list[dict]) -> None:
    print("| scene | tris | R | stage | csmlab ms | rate | Open3D 2T ms | Open3D 1T ms | csmlab/2T | csmlab/1T "
          "| csmlab/memcpy |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for r in rows:
        rate = f"{r['count'] / r['csmlab_s'] / 1e6:,.1f} {r['unit']}"
        print(f"| {r['scene']} | {r['triangles']:,} | {r['resolution']} | {r['stage']} | {_ms(r['csmlab_s'])} "
              f"| {rate} | {_ms(r['open3d_2t_s'])} | {_ms(r['open3d_1t_s'])} "
              f"| {_ratio(r['csmlab_s'], r['open3d_2t_s'])} | {_ratio(r['csmlab_s'], r['open3d_1t_s'])} "
              f"| {_ratio(r['csmlab_s'], r['memcpy_s'])} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", default="136k,1m", help=f"scene sizes, comma-separated, of {sorted(SIZES)}")
    parser.add_argument("--resolutions", default="1024,2048", help="texels per cascade side, comma-separated")
    parser.add_argument("--width", type=int, default=640)
    parser.add_argument("--height", type=int, default=360)
    parser.add_argument("--repeats", type=int, default=5, help="timed runs per stage; the minimum is reported")
    parser.add_argument("--json", type=Path, help="also write the results to this JSON file")
    parser.add_argument("--no-metrics", action="store_true", help="skip the per-method metrics rows")
    parser.add_argument("--experiment", action="store_true", help="also time the default experiment (csmlab run)")
    parser.add_argument("--dask", action="store_true", help="also time 1 vs 2 local Dask workers on 240 frames")
    parser.add_argument("--long", action="store_true",
                        help="also measure the peak RSS of a 1,000- and a 10,000-frame walk (small view; ~6 min)")
    args = parser.parse_args()
    sizes = [s.strip() for s in args.sizes.split(",")]
    if any(s not in SIZES for s in sizes):
        parser.error(f"--sizes: expected labels of {sorted(SIZES)}, got {args.sizes!r}")
    resolutions = [int(r) for r in args.resolutions.split(",")]

    start_warp()
    experiment = load_experiment(ROOT / "experiments" / "default.toml")
    workload = build_workload(experiment)
    pose, light = workload.path.pose(FRAME), workload.light.direction(FRAME)
    previous_pose = workload.path.pose(FRAME - 1)
    rows = []
    for label in sizes:
        for resolution in resolutions:
            rows += bench_kernels(label, resolution, width=args.width, height=args.height, repeats=args.repeats,
                                  pose=pose, light=light, previous_pose=previous_pose)
    if not args.no_metrics:
        rows += bench_metrics(repeats=args.repeats)
    try:
        import open3d  # noqa: F401
        peer = "Open3D " + open3d.__version__
    except ImportError:
        peer = "Open3D absent (pip install csmlab[bench])"
    print(f"csmlab on cpu ({os.cpu_count()} cores), view {args.width}x{args.height}, 4 cascades, frame {FRAME} of "
          f"the default walk; min of {args.repeats} runs; peer: {peer}")
    print_table(rows)
    result = {"kernels": rows}
    if args.experiment:
        result["experiment"] = bench_experiment()
        print(f"default experiment (csmlab run): {result['experiment']['wall_s']:.1f} s wall, "
              f"peak RSS {result['experiment']['peak_rss_mib']:.0f} MiB")
    if args.dask:
        result["dask"] = bench_dask()
        d = result["dask"]
        print(f"dask 240 frames: 1 worker {d['one_worker_s']:.1f} s, 2 workers {d['two_workers_s']:.1f} s wall, "
              f"speed-up {d['speedup']:.2f}x (efficiency {d['efficiency']:.0%}); frames phase "
              f"{d['one_worker_run_s']:.1f} / {d['two_workers_run_s']:.1f} s, {d['run_speedup']:.2f}x (the report, "
              f"{d['report_s']:.1f} s, is the parent's work either way); best of {DASK_REPEATS} each; peak RSS "
              f"{d['peak_rss_mib']:.0f} MiB")
    if args.long:
        result["long"] = bench_long()
        for run in result["long"]:
            print(f"long walk {run['frames']:,} frames: {run['wall_s']:.1f} s wall, "
                  f"peak RSS {run['peak_rss_mib']:.0f} MiB")
    if args.json:
        args.json.write_text(json.dumps(result, indent=1, default=float))


if __name__ == "__main__":
    main()
