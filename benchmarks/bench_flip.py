"""LDR-ꟻLIP per frame by each of ``FLIP_METHODS``: the whole image and the changed windows.

    .venv/bin/python benchmarks/bench_flip.py [--device cpu|cuda] [--width 640 --height 360] [--repeats 3]

A shaded frame of the ``plane_box`` scene against itself with the shadow flipped at 1 % of the
pixels scattered over the image (like ``none``, whose windows cover most of the image), and at
the pixels where the shadow moved when the light turned slightly (edges: like ``quantized``), and
at a few dozen of those (like ``exact``). Prints, per method, the best of ``--repeats`` timed runs in
milliseconds of :func:`csmlab.metrics.perceptual.flip_map` on the whole image and on the changed
windows, ns per pixel of the whole image, and the largest difference from ``flip-evaluator``; on
a GPU also how many pixels of the warp method's whole-image map differ from the CPU's (few expected: exp
and pow are the C library's on the CPU and correctly rounded on CUDA, see :func:`csmlab.kernels.flip.libm_pow`: they
differ on ~0.06 % of inputs). Every thread pool (ꟻLIP's OpenMP, NumPy's BLAS) is held to one thread, as in a csmlab run.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

# Run as a script, this file's folder comes first on sys.path: put the checkout it belongs to
# before any installed csmlab (as benchmarks/bench_metrics.py does).
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from csmlab.camera import CameraPose
from csmlab.geometry import rotation_looking_at
from csmlab.kernels import checked_device
from csmlab.metrics.perceptual import FLIP_METHODS, flip_map
from csmlab.metrics.shading import shaded_rgb
from csmlab.render import prepare_scene, render_frame
from csmlab.scene import make_scene
from csmlab.settings import ShadowSettings


def _frames(width: int, height: int, device: str) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Per case, the previous and the current frame's linear RGB ``(H, W, 3)`` and the changed pixels ``(H, W)``."""
    scene = prepare_scene(make_scene("plane_box", plane_size=60.0, box_size=4.0), device=device)
    pose = CameraPose(position=[8.0, 9.0, 12.0], orientation=rotation_looking_at([-8.0, -9.0, -12.0]),
                      aspect=width / height)
    settings = ShadowSettings(cascades=2, resolution=1024, shadow_distance=60.0)
    light = [0.3, -0.8, -0.5]
    frame = render_frame(scene, pose, light, settings, width=width, height=height)
    g = frame.view.gbuffer
    lit = np.where(g.valid, frame.shadow.lit, 0.0)
    turned = render_frame(scene, pose, [0.32, -0.8, -0.48], settings, width=width, height=height).shadow.lit
    edges = g.valid & (np.where(g.valid, turned, 0.0) != lit)
    few = np.zeros_like(edges)
    rows, cols = np.nonzero(edges)
    few[rows[:: max(rows.size // 40, 1)], cols[:: max(rows.size // 40, 1)]] = True
    scattered = g.valid & (np.random.default_rng(0).random(lit.shape) < 0.01)
    current = shaded_rgb(g.albedo, g.normal, lit, light_direction=light, ambient=0.25)
    cases = {}
    for name, changed in (("scattered", scattered), ("edges", edges), ("few", few)):
        previous_lit = np.where(changed, 1.0 - lit, lit)
        cases[name] = (shaded_rgb(g.albedo, g.normal, previous_lit, light_direction=light, ambient=0.25), current,
                       changed)
    return cases


def _best(repeats: int, call) -> tuple[float, np.ndarray]:
    result = call()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        result = call()
        times.append(time.perf_counter() - start)
    return min(times), result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--device", default="cpu", help="Warp device of the warp method: cpu or cuda")
    parser.add_argument("--width", type=int, default=640)
    parser.add_argument("--height", type=int, default=360)
    parser.add_argument("--repeats", type=int, default=3, help="timed runs; the best is reported")
    args = parser.parse_args()
    device = checked_device(args.device)
    cases = _frames(args.width, args.height, device)
    pixels = args.width * args.height
    print(f"{args.width}×{args.height}, device {device}; changed pixels: "
          + ", ".join(f"{name} {changed.sum()}" for name, (_, _, changed) in cases.items()))
    print(f"{'method':16s} {'whole ms':>9s} {'ns/px':>6s} " + " ".join(f"{name + ' ms':>12s}" for name in cases)
          + "  max |Δ| vs flip-evaluator")
    previous, current, _ = cases["scattered"]
    with threadpool_limits(limits=1):
        oracle = flip_map(previous, current, method="flip-evaluator")
        for method in sorted(FLIP_METHODS, reverse=True):
            whole, error = _best(args.repeats,
                                 lambda method=method: flip_map(previous, current, method=method, device=device))
            windowed = [_best(args.repeats, lambda a=a, b=b, c=c, method=method:
                              flip_map(a, b, changed=c, method=method, device=device))[0]
                        for a, b, c in cases.values()]
            print(f"{method:16s} {whole * 1e3:9.1f} {whole / pixels * 1e9:6.0f} "
                  + " ".join(f"{t * 1e3:12.2f}" for t in windowed) + f"  {np.abs(error - oracle).max():.2e}")
        if device != "cpu":
            on_device = flip_map(previous, current, method="warp", device=device)
            on_cpu = flip_map(previous, current, method="warp", device="cpu")
            print(f"warp on {device} vs the CPU: {np.count_nonzero(on_device != on_cpu)} of {pixels} pixels differ, "
                  f"max |Δ| {np.abs(on_device - on_cpu).max():.2e}")

if __name__ == "__main__":
    main()
