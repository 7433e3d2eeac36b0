"""The view stage (:func:`csmlab.render.render_view`) of an experiment's walk: CPU ms a frame, per stage and kernel.

    .venv/bin/python benchmarks/bench_view.py [EXPERIMENT] [--frames 20] [--threads 1] [--repeats 2]

Renders ``EXPERIMENT``'s view (default ``experiments/default.toml``) as a run's worker does —
its G-buffer and its ray-traced reference — for frame 0 untimed (the kernels' build, the light's
cached light-space vertices), then for frames 1..``--frames``, ``--repeats`` times. It prints the
best of the repeats, in ms a frame: the process's CPU time of ``render_view``, each stage's time
from ``View.timings`` (wall), and each Warp kernel's CPU time on the launching thread (with
``--threads`` 1, as in each of a run's processes, the whole of the kernel's work). ``digest`` hashes
every frame's G-buffer (position, normal, triangle, view depth, albedo) and reference, so that a
faster path is checked to give the same bits as the one it replaces.
"""

from __future__ import annotations

import argparse
import collections
import hashlib
import sys
import time
from pathlib import Path

import numpy as np

# Run as a script, this file's folder comes first on sys.path: put the checkout it belongs to
# before any installed csmlab.
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("experiment", nargs="?", default="experiments/default.toml")
    parser.add_argument("--frames", type=int, default=20, help="timed frames, 1..FRAMES")
    parser.add_argument("--threads", type=int, default=1, help="concurrent CPU launches (a run's processes use 1)")
    parser.add_argument("--repeats", type=int, default=2, help="timed passes over the frames; the best is reported")
    args = parser.parse_args()

    import warp as wp
    from warp._src import context

    from csmlab.config import load_experiment
    from csmlab.experiment import build_workload
    from csmlab.kernels import start_warp
    from csmlab.render import prepare_scene, render_view

    start_warp()
    kernels = collections.defaultdict(float)
    launch = context.launch

    def timed_launch(kernel, *a, **k):
        began = time.thread_time()
        result = launch(kernel, *a, **k)
        kernels[getattr(kernel, "key", str(kernel))] += time.thread_time() - began
        return result

    context.launch = wp.launch = timed_launch
    workload = build_workload(load_experiment(args.experiment).with_frames(args.frames + 1))
    scene = prepare_scene(workload.scene, device="cpu", threads=args.threads)

    def view(index: int):
        return render_view(scene, workload.path.pose(index), workload.light.direction(index), width=workload.width,
                           height=workload.height, index=index,
                           previous_light_direction=workload.light.direction(index - 1) if index else None,
                           light_colour=workload.light.colour)

    view(0)
    best: dict[str, float] = {}
    for _ in range(args.repeats):
        kernels.clear()
        stages = collections.defaultdict(float)
        digest = hashlib.sha256()
        for index in range(1, args.frames + 1):
            began = time.process_time()
            v = view(index)
            stages["render_view (CPU)"] += time.process_time() - began
            for stage, seconds in v.timings.items():
                stages[f"stage {stage}"] += seconds
            g = v.gbuffer
            for a in (g.position, g.normal, g.triangle, g.view_depth, g.albedo, v.reference, v.previous_reference):
                if a is not None:
                    digest.update(np.ascontiguousarray(a).tobytes())
        for name, seconds in [*stages.items(), *kernels.items()]:
            best[name] = min(best.get(name, np.inf), seconds)
    print(f"digest {digest.hexdigest()[:16]}  frames 1..{args.frames}  threads {args.threads}  best of {args.repeats}")
    for name, seconds in sorted(best.items(), key=lambda item: (not item[0].startswith(("render", "stage")),
                                                                -item[1])):
        print(f"{seconds * 1000 / args.frames:8.2f} ms/frame  {name}")


if __name__ == "__main__":
    main()
