"""Per-stage time of one frame: 4 cascades × R² over the terrain and a W×H view.

    .venv/bin/python benchmarks/bench_frame.py [--device cpu|cuda] [--raster walk|tiled] [--threads 1]
        [--resolution 2048] [--width 1280 --height 720] [--repeats 3]

Prints one row per stage (visibility, reference, cascades, raster, shadow) with the best of
``--repeats`` timed runs in milliseconds and the throughput: Gtexels/s of depth map for ``raster``
(every texel of the four maps, whichever triangles cover it), Mpixels/s for the per-pixel stages.
A first run compiles the kernels and is not timed. ``--raster`` picks the depth rasterizer
(:mod:`csmlab.kernels.raster.dispatch`; default the device's: the walk on the CPU, the tiles on
CUDA), so both are timed on one device. The scene is ``csmlab.scene.make_scene("terrain", seed=1)``
(265k triangles).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import warp as wp

from csmlab.camera import CameraPose
from csmlab.geometry import rotation_looking_at
from csmlab.kernels import checked_device, start_warp
from csmlab.kernels.raster.dispatch import RASTERIZERS, device_rasterizer, rasterizer_chosen
from csmlab.light import direction_from_angles
from csmlab.render import prepare_scene, render_shadow, render_view
from csmlab.scene import make_scene
from csmlab.settings import ShadowSettings

STAGES = ("visibility", "reference", "cascades", "raster", "shadow")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--device", default="cpu", help="Warp device: cpu or cuda")
    parser.add_argument("--raster", choices=RASTERIZERS, default=None,
                        help="depth rasterizer (default: the device's, walk on the CPU, tiled on CUDA)")
    parser.add_argument("--threads", type=int, default=1, help="concurrent CPU launches (ignored on CUDA)")
    parser.add_argument("--resolution", type=int, default=2048, help="texels per side of each cascade")
    parser.add_argument("--cascades", type=int, default=4)
    parser.add_argument("--width", type=int, default=1280)
    parser.add_argument("--height", type=int, default=720)
    parser.add_argument("--repeats", type=int, default=3, help="timed runs; the best is reported")
    args = parser.parse_args()

    start_warp()
    try:
        checked_device(args.device)
    except ValueError as error:
        parser.error(str(error))
    raster = args.raster or device_rasterizer(args.device)
    scene = make_scene("terrain", seed=1)
    dscene = prepare_scene(scene, device=args.device, threads=args.threads)
    pose = CameraPose(position=np.array([-60.0, 25.0, 80.0]), orientation=rotation_looking_at([0.6, -0.18, -0.8]),
                      aspect=args.width / args.height, near=0.1, far=400.0)
    light = direction_from_angles(elevation_deg=40.0, azimuth_deg=30.0)
    settings = ShadowSettings(cascades=args.cascades, resolution=args.resolution, filter="pcf", filter_size=3)

    def one_frame():
        view = render_view(dscene, pose, light, width=args.width, height=args.height)
        with rasterizer_chosen(raster):
            frame = render_shadow(dscene, view, settings)
        wp.synchronize_device(args.device)
        return {**view.timings, **frame.timings}, frame

    one_frame()
    best = dict.fromkeys(STAGES, np.inf)
    total = np.inf
    for _ in range(args.repeats):
        start = time.perf_counter()
        timings, frame = one_frame()
        total = min(total, time.perf_counter() - start)
        for stage in STAGES:
            best[stage] = min(best[stage], timings[stage])

    pixels = args.width * args.height
    work = {"visibility": (pixels, 1e6, "Mpixels/s"), "reference": (pixels, 1e6, "Mpixels/s"),
            "cascades": (0, 1.0, ""), "raster": (args.cascades * args.resolution**2, 1e9, "Gtexels/s"),
            "shadow": (pixels, 1e6, "Mpixels/s")}
    print(f"scene {scene.name!r}: {scene.triangle_count:,} triangles; device {args.device}; raster {raster}; "
          f"threads {args.threads}; {args.cascades} cascades x {args.resolution}^2; view {args.width}x{args.height}; "
          f"best of {args.repeats} after a warm-up")
    print(f"{'stage':<11} {'ms':>9} {'throughput':>20}")
    for stage in STAGES:
        seconds = best[stage]
        count, scale, unit = work[stage]
        rate = f"{count / seconds / scale:9.3f} {unit}" if count else "-"
        print(f"{stage:<11} {seconds * 1e3:9.1f} {rate:>20}")
    print(f"{'frame':<11} {total * 1e3:9.1f}")
    print(f"texels rasterized (coverage tests passed): {frame.maps.texels_rasterized:,}")


if __name__ == "__main__":
    main()
