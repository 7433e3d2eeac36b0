"""Each measure's cost per frame × method: the metrics stage of a run, taken apart.

    .venv/bin/python benchmarks/bench_metrics.py [--device cpu|cuda] [--experiment default]
        [--frames 12] [--skip 2] [--clock wall|cpu]

Renders the experiment's first ``--frames`` frames in this process as a run's worker does (the
view, then every method with the previous frame's maps to scroll from) and times, for every frame
after the first ``--skip`` (the first loads the kernels and the libraries), each measure that
:func:`csmlab.metrics.measure_frame` composes, called the way it calls them, and the whole
``measure_frame`` of the same frame. Prints one row per measure and a total per method, mean
milliseconds per frame. The per-measure rows are the parts; ``measure_frame`` is the stage the
run's ``timings.csv`` records (its ``metrics`` rows). Every thread pool is held to one thread,
as in a csmlab run.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

# Run as a script, this file's folder comes first on sys.path: put the checkout it belongs to
# before any installed csmlab.
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from csmlab.config import find_experiment, load_experiment
from csmlab.experiment import build_workload, shadow_light
from csmlab.kernels import checked_device, start_warp
from csmlab.metric_registry import finite_mean
from csmlab.metrics import measure_frame
from csmlab.metrics.aliasing import aliasing_maps, aliasing_summary, utilization
from csmlab.metrics.cost import cost_summary
from csmlab.metrics.perceptual import (JND_CIEDE2000, _SSIM_MIN_SIDE, flip_map, perceptual_maps, ssim_map)
from csmlab.metrics.reference import bias_errors, reference_maps, reference_summary, seam_error
from csmlab.metrics.shading import AMBIENT
from csmlab.metrics.temporal import temporal_maps, temporal_summary
from csmlab.render import prepare_scene, render_shadow, render_view

MEASURES = ("aliasing_maps", "aliasing_summary", "utilization", "reference_maps", "reference_summary",
            "bias_errors", "seam_error", "cost_summary", "temporal_maps", "temporal_summary", "perceptual_maps",
            "de2000_summary", "ssim", "flip")


CLOCKS = {"wall": time.perf_counter, "cpu": time.process_time}
"""``--clock``: wall-clock seconds, as a run's ``timings.csv`` records them, or this process's CPU seconds,
which other work on a shared machine disturbs far less (every pool is held to one thread)."""

_clock = time.perf_counter


def _timed(costs: dict, name: str, compute):
    began = _clock()
    out = compute()
    costs[name] += _clock() - began
    return out


def measure_costs(frame, previous, *, device: str) -> dict[str, float]:
    """Seconds of each of :data:`MEASURES` on ``frame`` (``previous``: frame t−1, or None at the first)."""
    costs = defaultdict(float)
    alias = _timed(costs, "aliasing_maps", lambda: aliasing_maps(frame, device=device))
    _timed(costs, "aliasing_summary", lambda: aliasing_summary(alias, cascades=len(frame.maps.cascades)))
    _timed(costs, "utilization", lambda: utilization(frame, device=device))
    errors = _timed(costs, "reference_maps", lambda: reference_maps(frame))
    _timed(costs, "reference_summary", lambda: reference_summary(errors, view=frame.view))
    _timed(costs, "bias_errors", lambda: bias_errors(frame, errors))
    _timed(costs, "seam_error", lambda: seam_error(frame))
    _timed(costs, "cost_summary", lambda: cost_summary(frame))
    if previous is not None:
        temporal = _timed(costs, "temporal_maps", lambda: temporal_maps(frame, previous, device=device))
        _timed(costs, "temporal_summary", lambda: temporal_summary(temporal))
        maps = _timed(costs, "perceptual_maps", lambda: perceptual_maps(frame, temporal.previous_lit,
                                                                        ambient=AMBIENT))
        compared = maps.compared
        changed = compared & (maps.lit != maps.previous_lit)

        def de2000_summary():
            de = maps.de2000[compared]
            return finite_mean(de), np.count_nonzero(de > JND_CIEDE2000) / de.size, np.percentile(de, 99.0)

        _timed(costs, "de2000_summary", de2000_summary)
        if min(maps.lit.shape) >= _SSIM_MIN_SIDE:
            _timed(costs, "ssim", lambda: ssim_map(maps.previous_lit, maps.lit, changed=changed, compared=compared,
                                                   device=device))
        _timed(costs, "flip", lambda: flip_map(maps.previous_shaded, maps.shaded, changed=changed,
                                               compared=compared, device=device))
    return costs


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--device", default="cpu", help="Warp device: cpu or cuda")
    parser.add_argument("--experiment", default="default", help="experiment file or built-in name")
    parser.add_argument("--frames", type=int, default=12, help="frames rendered from the start of the path")
    parser.add_argument("--skip", type=int, default=2, help="first frames rendered but not timed")
    parser.add_argument("--clock", choices=sorted(CLOCKS), default="wall", help="wall or this process's CPU time")
    args = parser.parse_args()
    global _clock
    _clock = CLOCKS[args.clock]
    if args.frames <= args.skip + 1:
        parser.error(f"--frames: expected more than --skip + 1 = {args.skip + 1}, got {args.frames}")

    start_warp()
    try:
        checked_device(args.device)
    except ValueError as error:
        parser.error(str(error))
    experiment = load_experiment(find_experiment(args.experiment), frames=args.frames)
    workload = build_workload(experiment)
    variants = tuple(experiment.variants())
    scene = prepare_scene(workload.scene, device=args.device)
    parts = {(v.method, v.point): defaultdict(float) for v in variants}
    stage = dict.fromkeys(parts, 0.0)
    timed = 0
    previous = {}
    with threadpool_limits(limits=1):
        for index in range(args.frames):
            view = render_view(scene, workload.path.pose(index), workload.light.direction(index),
                               width=workload.width, height=workload.height, index=index,
                               previous_light_direction=workload.light.direction(index - 1) if index else None)
            counted = index >= args.skip
            timed += counted
            for variant in variants:
                key = (variant.method, variant.point)
                frame = render_shadow(scene, view, variant.settings,
                                      scroll_from=previous[key].maps if key in previous else None,
                                      light_direction=shadow_light(workload, variant.settings, index))
                # What the view shares between methods (View.shared) is computed by the first method
                # that needs it: the parts and the stage each start from the state a run's stage sees.
                shared = dict(view.derived)
                costs = measure_costs(frame, previous.get(key), device=args.device)
                view.derived.clear()
                view.derived.update(shared)
                began = _clock()
                measure_frame(frame, previous.get(key), device=args.device)
                seconds = _clock() - began
                if counted:
                    for name, value in costs.items():
                        parts[key][name] += value
                    stage[key] += seconds
                previous[key] = frame
    print(f"experiment {experiment.name!r}: {workload.width}x{workload.height}, frames {args.skip}..{args.frames - 1} "
          f"timed ({timed}), device {args.device}; mean ms per frame ({args.clock} clock)")
    names = [f"{method}" + ("" if point == "base" else f"/{point}") for method, point in parts]
    print(f"{'measure':<18}" + "".join(f"{name:>12}" for name in names))
    for measure in MEASURES:
        print(f"{measure:<18}" + "".join(f"{parts[key][measure] / timed * 1e3:12.2f}" for key in parts))
    print(f"{'sum of parts':<18}" + "".join(f"{sum(parts[key].values()) / timed * 1e3:12.2f}" for key in parts))
    print(f"{'measure_frame':<18}" + "".join(f"{stage[key] / timed * 1e3:12.2f}" for key in parts))


if __name__ == "__main__":
    main()
