"""The shadow lookup on a run's own arguments: the box-filter kernel, or every method's whole lookup.

    .venv/bin/python benchmarks/bench_lookup.py capture [EXPERIMENT] [--frames 3] [--out DIR]
    .venv/bin/python benchmarks/bench_lookup.py time [--out DIR] [--repeats 15] [--save] [--filter pcf --radius 1 ...]
    .venv/bin/python benchmarks/bench_lookup.py methods [EXPERIMENT] [--frames 3] [--out DIR] [--repeats 5] [--save]

``capture`` runs ``EXPERIMENT`` (default ``experiments/default.toml``) in one process for
``--frames`` frames with :func:`csmlab.filters.shadow_lookup_world` wrapped, and pickles the
arguments of its first ``--calls`` calls (a frame's own lookup, then the previous frame's maps at
the current receivers) to ``DIR/call<i>.pkl``. ``time`` calls the lookup on each captured call,
once untimed (the kernel build), then ``--repeats`` times, and prints the best time in ms of
the whole call and of its kernel launch (CPU time of this process, so that the other
processes of a shared machine count less), and ns per receiver. ``--save`` writes the outputs
(lit, cascade, blend) to ``DIR/call<i>.npz``; without it, existing ``.npz`` files are the
reference that the outputs must equal bit for bit (NaN where NaN), so a faster kernel is checked
against the outputs of the one it replaces. ``--filter``, ``--radius``, ``--selection`` and
``--plane 0|1`` replace the captured call's filter, its radius, its selection (``sphere`` needs
a sphere per receiver, not captured) and its receiver-plane bias.

``methods`` renders ``EXPERIMENT``'s first ``--frames`` frames in this process as a run's worker
does and, at the last frame t, times every method's two lookups (:func:`csmlab.filters.lookup_shadow`
as called there): its shadow S_t (``render_shadow``) and the temporal metric's S_{t−1}, frame t−1's
maps at frame t's points (``temporal_maps``). It prints the best CPU time of ``--repeats`` calls in
ms and ns per receiver; ``--save`` writes the outputs to ``DIR/<method>_<lookup>.npz``, and without it
those files are the reference the outputs must equal bit for bit.
"""

from __future__ import annotations

import argparse
import pickle
import sys
import time
from pathlib import Path

import numpy as np
import warp as wp

# Run as a script, this file's folder comes first on sys.path: put the checkout it belongs to
# before any installed csmlab.
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from csmlab.kernels import start_warp  # noqa: E402


def capture(experiment: str, *, frames: int, calls: int, out: Path) -> None:
    """Run ``experiment`` for ``frames`` frames in-process and pickle the first ``calls`` lookups' arguments."""
    import csmlab.filters
    from csmlab.cli import main as cli_main

    lookup = csmlab.filters.shadow_lookup_world
    out.mkdir(parents=True, exist_ok=True)
    seen = []

    def recorded(*args, **kwargs):
        if len(seen) < calls:
            seen.append(None)
            with open(out / f"call{len(seen)}.pkl", "wb") as f:
                pickle.dump((args, kwargs), f)
        return lookup(*args, **kwargs)

    csmlab.filters.shadow_lookup_world = recorded
    argv = sys.argv
    sys.argv = ["csmlab", "run", experiment, "--frames", str(frames), "--jobs", "1", "--out", str(out / "run")]
    try:
        cli_main()
    except SystemExit as done:
        if done.code:
            raise
    finally:
        sys.argv = argv
        csmlab.filters.shadow_lookup_world = lookup
    print(f"captured {len(seen)} call(s) in {out}")


def time_calls(out: Path, *, repeats: int, save: bool, changes: dict) -> int:
    """Time each captured call; returns 1 where an output differs from its saved reference, else 0."""
    import csmlab.kernels.shadow as shadow

    start_warp()
    launch = wp.launch
    spent = {}

    def timed_launch(*args, **kwargs):
        began = time.process_time()
        result = launch(*args, **kwargs)
        spent["launch"] = time.process_time() - began
        return result

    paths = sorted(out.glob("call*.pkl"))
    if not paths:
        print(f"{out}: no call*.pkl (run the capture first)", file=sys.stderr)
        return 2
    failed = 0
    print(f"{'call':<10} {'receivers':>9} {'call ms':>8} {'launch ms':>9} {'ns/receiver':>11}  outputs")
    for path in paths:
        with open(path, "rb") as f:
            args, kwargs = pickle.load(f)
        kwargs.update(changes)
        outputs = shadow.shadow_lookup_world(*args, **kwargs)
        best = {"call": np.inf, "launch": np.inf}
        shadow.wp.launch = timed_launch
        try:
            for _ in range(repeats):
                began = time.process_time()
                shadow.shadow_lookup_world(*args, **kwargs)
                best["call"] = min(best["call"], time.process_time() - began)
                best["launch"] = min(best["launch"], spent["launch"])
        finally:
            shadow.wp.launch = launch
        reference = path.with_suffix(".npz")
        if save:
            np.savez(reference, *outputs)
            verdict = f"saved to {reference.name}"
        elif reference.exists():
            with np.load(reference) as held:
                same = all(np.array_equal(held[f"arr_{i}"], o, equal_nan=True) for i, o in enumerate(outputs))
            verdict = "identical to " + reference.name if same else "DIFFER from " + reference.name
            failed |= not same
        else:
            verdict = "no reference (--save writes one)"
        n = np.shape(args[3])[0]
        print(f"{path.stem:<10} {n:>9} {best['call'] * 1e3:8.2f} {best['launch'] * 1e3:9.2f} "
              f"{best['call'] / n * 1e9:11.1f}  {verdict}")
    return failed


def time_methods(experiment: str, *, frames: int, repeats: int, out: Path, save: bool) -> int:
    """Time each method's S_t and S_{t−1} lookups at frame ``frames − 1``; returns 1 where an output differs from
    its saved reference, else 0."""
    from threadpoolctl import threadpool_limits

    import csmlab.metrics.temporal as temporal
    import csmlab.render as render
    from csmlab.config import find_experiment, load_experiment
    from csmlab.experiment import build_workload, shadow_light

    start_warp()
    loaded = load_experiment(find_experiment(experiment), frames=frames)
    workload = build_workload(loaded)
    variants = tuple(loaded.variants())
    scene = render.prepare_scene(workload.scene, device="cpu")
    calls = {}
    label = {}

    def recorded(kind, lookup):
        def call(maps, **kwargs):
            if label:
                calls[(label["method"], kind)] = (maps, kwargs)
            return lookup(maps, **kwargs)
        return call

    lookups = (render.lookup_shadow, temporal.lookup_shadow)
    render.lookup_shadow = recorded("S_t", lookups[0])
    temporal.lookup_shadow = recorded("S_t-1", lookups[1])
    previous = {}
    try:
        with threadpool_limits(limits=1):
            for index in range(frames):
                view = render.render_view(scene, workload.path.pose(index), workload.light.direction(index),
                                          width=workload.width, height=workload.height, index=index,
                                          previous_light_direction=(workload.light.direction(index - 1) if index
                                                                    else None))
                for variant in variants:
                    key = (variant.method, variant.point)
                    name = variant.method + ("" if variant.point == "base" else f"/{variant.point}")
                    if index == frames - 1:
                        label["method"] = name
                    frame = render.render_shadow(scene, view, variant.settings,
                                                 scroll_from=previous[key].maps if key in previous else None,
                                                 light_direction=shadow_light(workload, variant.settings, index))
                    if index == frames - 1 and key in previous:
                        temporal.temporal_maps(frame, previous[key], device="cpu")
                    label.clear()
                    previous[key] = frame
    finally:
        render.lookup_shadow, temporal.lookup_shadow = lookups
    out.mkdir(parents=True, exist_ok=True)
    failed = 0
    print(f"{'method':<24} {'lookup':<6} {'receivers':>9} {'ms':>8} {'ns/receiver':>11}  outputs")
    with threadpool_limits(limits=1):
        for (name, kind), (maps, kwargs) in calls.items():
            outputs = lookups[0](maps, **kwargs)
            best = np.inf
            for _ in range(repeats):
                began = time.process_time()
                lookups[0](maps, **kwargs)
                best = min(best, time.process_time() - began)
            fields = (outputs.lit, outputs.cascade, outputs.blend)
            reference = out / f"{name.replace('/', '_')}_{kind}.npz"
            if save:
                np.savez(reference, *fields)
                verdict = f"saved to {reference.name}"
            elif reference.exists():
                with np.load(reference) as held:
                    same = all(np.array_equal(held[f"arr_{i}"], o, equal_nan=True) for i, o in enumerate(fields))
                verdict = "identical to " + reference.name if same else "DIFFER from " + reference.name
                failed |= not same
            else:
                verdict = "no reference (--save writes one)"
            n = int(np.count_nonzero(outputs.cascade >= 0))
            print(f"{name:<24} {kind:<6} {n:>9} {best * 1e3:8.2f} {best / max(n, 1) * 1e9:11.1f}  {verdict}")
    return failed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("action", choices=("capture", "time", "methods"))
    parser.add_argument("experiment", nargs="?", default="experiments/default.toml",
                        help="capture, methods: the experiment")
    parser.add_argument("--frames", type=int, default=3, help="capture, methods: frames of the run")
    parser.add_argument("--calls", type=int, default=2, help="capture: lookups to keep")
    parser.add_argument("--out", type=Path, default=Path("/tmp/bench_lookup"), help="the captured calls' folder")
    parser.add_argument("--repeats", type=int, default=15, help="time, methods: timed calls; the best is reported")
    parser.add_argument("--save", action="store_true", help="time, methods: write the outputs as the reference")
    parser.add_argument("--filter", help="time: a box filter in place of the captured one")
    parser.add_argument("--radius", type=int, help="time: the filter's radius in place of the captured one")
    parser.add_argument("--selection", help="time: a selection in place of the captured one")
    parser.add_argument("--plane", type=int, choices=(0, 1), help="time: receiver-plane bias off (0) or on (1)")
    args = parser.parse_args()
    if args.action == "capture":
        capture(args.experiment, frames=args.frames, calls=args.calls, out=args.out)
        return
    if args.action == "methods":
        if args.frames < 2:
            parser.error(f"--frames: methods times frame t and t − 1's maps, so at least 2, got {args.frames}")
        sys.exit(time_methods(args.experiment, frames=args.frames, repeats=args.repeats, out=args.out, save=args.save))
    changes = {key: value for key, value in (("filter", args.filter), ("radius", args.radius),
                                             ("selection", args.selection)) if value is not None}
    if args.plane is not None:
        changes["receiver_plane_bias"] = bool(args.plane)
    sys.exit(time_calls(args.out, repeats=args.repeats, save=args.save, changes=changes))


if __name__ == "__main__":
    main()
