"""The box-filter shadow lookup (:func:`csmlab.kernels.shadow.shadow_lookup_world`) on a run's own arguments.

    .venv/bin/python benchmarks/bench_lookup.py capture [EXPERIMENT] [--frames 3] [--out DIR]
    .venv/bin/python benchmarks/bench_lookup.py time [--out DIR] [--repeats 15] [--save] [--filter pcf --radius 1 ...]

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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("action", choices=("capture", "time"))
    parser.add_argument("experiment", nargs="?", default="experiments/default.toml", help="capture: the experiment")
    parser.add_argument("--frames", type=int, default=3, help="capture: frames of the run")
    parser.add_argument("--calls", type=int, default=2, help="capture: lookups to keep")
    parser.add_argument("--out", type=Path, default=Path("/tmp/bench_lookup"), help="the captured calls' folder")
    parser.add_argument("--repeats", type=int, default=15, help="time: timed calls; the best is reported")
    parser.add_argument("--save", action="store_true", help="time: write the outputs as the reference")
    parser.add_argument("--filter", help="time: a box filter in place of the captured one")
    parser.add_argument("--radius", type=int, help="time: the filter's radius in place of the captured one")
    parser.add_argument("--selection", help="time: a selection in place of the captured one")
    parser.add_argument("--plane", type=int, choices=(0, 1), help="time: receiver-plane bias off (0) or on (1)")
    args = parser.parse_args()
    if args.action == "capture":
        capture(args.experiment, frames=args.frames, calls=args.calls, out=args.out)
        return
    changes = {key: value for key, value in (("filter", args.filter), ("radius", args.radius),
                                             ("selection", args.selection)) if value is not None}
    if args.plane is not None:
        changes["receiver_plane_bias"] = bool(args.plane)
    sys.exit(time_calls(args.out, repeats=args.repeats, save=args.save, changes=changes))


if __name__ == "__main__":
    main()
