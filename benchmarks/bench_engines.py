"""Per engine preset: the raster and shadow lookup in the preset's own precision against the same preset in float64.

    .venv/bin/python benchmarks/bench_engines.py [--device cpu|cuda] [--frames 6] [--threads 1]
        [--presets ue5,godot4,...] [--resolution R] [--clock wall|cpu] [--raster-only --passes 2]

Every cascaded method of ``experiments/engines.toml`` (terrain, the walk, 640×360) is run over the
first ``--frames`` frames of the walk as a run renders them: one view per frame, each method's maps
scrolled from its previous frame's where its path allows (:func:`csmlab.render.render_shadow`). The
first frame compiles and fills the caches and is not counted; the table gives each stage's mean
milliseconds per frame over the rest, from the frames' own ``timings``, for the preset as shipped
(``engine_precision`` float32 or camera_relative, Filament's warp) and for the same preset with
``engine_precision = "float64"``, and their ratio; then the float64 preset's raster with every frame's maps made
anew (``f64 whole``: none scrolled from the previous frame's, as the engines and the float32 paths make them) and
the preset's raster against it — what its precision costs on the same work. ``--threads`` CPU threads per frame,
as a run with that many cores per process (``csmlab run --jobs 2`` on 2 cores gives each process 1).
``--clock cpu`` times the stages in CPU seconds of the process (:func:`time.process_time`) instead
of wall-clock seconds: on a machine shared with other work, the work itself rather than the waits
for a core (every thread's CPU time summed, so use it with ``--threads 1``).

``--raster-only`` times the depth maps alone (:func:`csmlab.render.shadow_maps`, each frame's from the
previous frame's maps) over frames 1 .. ``--frames − 1``, the cascades built first and no view rendered:
the best of ``--passes`` passes, for A/B runs on a shared machine.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
import types
from pathlib import Path

import warp as wp

from csmlab.cascades import build_cascades
from csmlab.config import load_experiment
from csmlab.experiment import build_workload
from csmlab.kernels import checked_device, start_warp
from csmlab import render
from csmlab.render import prepare_scene, render_shadow, render_view

EXPERIMENT = Path(__file__).resolve().parent.parent / "experiments" / "engines.toml"
STAGES = ("raster", "shadow")


def stage_means(dscene, workload, settings, frames: int, device: str, *, scroll: bool = True) -> dict:
    """Mean seconds per frame of each of :data:`STAGES` over frames 1 .. ``frames − 1`` (frame 0 warms up);
    without ``scroll`` every frame's maps are made anew, none from the previous frame's."""
    sums = dict.fromkeys(STAGES, 0.0)
    previous = None
    for i in range(frames):
        view = render_view(dscene, workload.path.pose(i), workload.light.direction(i), width=workload.width,
                           height=workload.height, index=i, reference=False)
        frame = render_shadow(dscene, view, settings, scroll_from=previous if scroll else None)
        wp.synchronize_device(device)
        previous = frame.maps
        if i:
            for stage in STAGES:
                sums[stage] += frame.timings[stage]
    return {stage: sums[stage] / (frames - 1) for stage in STAGES}


def raster_means(dscene, workload, settings, frames: int, passes: int, clock, device: str, *,
                 scroll: bool = True) -> dict:
    """Seconds per frame of :func:`csmlab.render.shadow_maps` over frames 1 .. ``frames − 1``, best of ``passes``;
    without ``scroll`` every frame's maps are made anew."""
    sets = [build_cascades(pose=workload.path.pose(i), light_direction=workload.light.direction(i),
                           scene_corners=dscene.corners, settings=settings) for i in range(frames)]
    render.shadow_maps(dscene, sets[0], settings)  # compiles and fills the caches
    best = float("inf")
    for _ in range(passes):
        previous = render.shadow_maps(dscene, sets[0], settings)
        start = clock()
        for cascades in sets[1:]:
            previous = render.shadow_maps(dscene, cascades, settings, scroll_from=previous if scroll else None)
        wp.synchronize_device(device)
        best = min(best, (clock() - start) / (frames - 1))
    return {"raster": best}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--device", default="cpu", help="Warp device: cpu or cuda")
    parser.add_argument("--frames", type=int, default=6, help="frames of the walk, the first not counted")
    parser.add_argument("--threads", type=int, default=1, help="CPU threads per frame")
    parser.add_argument("--presets", default="", help="comma-separated method names (default: every cascaded one)")
    parser.add_argument("--resolution", type=int, default=0, help="texels per side (default: each preset's own)")
    parser.add_argument("--clock", choices=("wall", "cpu"), default="wall",
                        help="wall: wall-clock seconds; cpu: the process's CPU seconds")
    parser.add_argument("--raster-only", action="store_true", help="time only the depth maps (no view, no lookup)")
    parser.add_argument("--passes", type=int, default=2, help="with --raster-only: passes, the best kept")
    args = parser.parse_args()
    if args.frames < 2:
        parser.error("--frames: expected at least 2 (the first only warms up)")
    if args.passes < 1:
        parser.error("--passes: expected at least 1")

    if args.clock == "cpu":
        # The frames' own timings read render's clock: CPU seconds there, nowhere else.
        render.time = types.SimpleNamespace(perf_counter=time.process_time)
    start_warp()
    try:
        checked_device(args.device)
    except ValueError as error:
        parser.error(str(error))
    experiment = load_experiment(EXPERIMENT)
    workload = build_workload(experiment)
    dscene = prepare_scene(workload.scene, device=args.device, threads=args.threads)
    chosen = [name for name in args.presets.split(",") if name]
    methods = [m for m in experiment.methods if m.settings.shadow_map != "virtual_clipmap"
               and (not chosen or m.name in chosen)]
    print(f"experiments/engines.toml: {workload.scene.triangle_count:,} triangles, view {workload.width}x"
          f"{workload.height}; device {args.device}, {args.threads} thread(s); mean {args.clock} ms/frame over "
          f"frames 1..{args.frames - 1} (frame 0 warms up)" + (f", depth maps only, best of {args.passes} passes"
                                                             if args.raster_only else ""))
    stages = ("raster",) if args.raster_only else STAGES
    print(f"{'preset':<22} {'precision':<16} {'R':>5}"
          + "".join(f" {stage:>9} {'f64':>9} {'ratio':>6}" for stage in stages)
          + f" {'f64 whole':>9} {'ratio':>6}")
    clock = time.process_time if args.clock == "cpu" else time.perf_counter
    for method in methods:
        settings = method.settings
        if args.resolution:
            settings = dataclasses.replace(settings, resolution=args.resolution)
        wide_settings = dataclasses.replace(settings, engine_precision="float64")
        if args.raster_only:
            own, wide, whole = (raster_means(dscene, workload, s, args.frames, args.passes, clock, args.device,
                                             scroll=scroll)
                                for s, scroll in ((settings, True), (wide_settings, True), (wide_settings, False)))
        else:
            own, wide, whole = (stage_means(dscene, workload, s, args.frames, args.device, scroll=scroll)
                                for s, scroll in ((settings, True), (wide_settings, True), (wide_settings, False)))
        cells = "".join(f" {own[s] * 1e3:9.1f} {wide[s] * 1e3:9.1f} {own[s] / wide[s]:6.2f}" for s in stages)
        cells += f" {whole['raster'] * 1e3:9.1f} {own['raster'] / whole['raster']:6.2f}"
        print(f"{method.name:<22} {settings.engine_precision:<16} {settings.resolution:>5}{cells}", flush=True)


if __name__ == "__main__":
    main()
