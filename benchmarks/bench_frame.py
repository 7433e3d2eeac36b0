"""Per-stage time of one frame: 4 cascades × R² over the terrain and a W×H view.

    .venv/bin/python benchmarks/bench_frame.py [--device cpu|cuda] [--resolution 2048]
        [--width 1280 --height 720] [--repeats 3]

Prints one row per stage (visibility, reference, cascades, raster, shadow) with the best of
``--repeats`` timed runs in milliseconds and the throughput: Mtexels/s of depth map for ``raster``,
Mpixels/s for the per-pixel stages. A first run compiles the kernels and is not timed.
The scene is ``csmlab.scene.make_scene("terrain", seed=1)`` (265k triangles).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import warp as wp

from csmlab.camera import CameraPose
from csmlab.geometry import rotation_looking_at
from csmlab.kernels import checked_device, start_warp
from csmlab.light import direction_from_angles
from csmlab.render import prepare_scene, render_shadow, render_view
from csmlab.scene import make_scene
from csmlab.settings import ShadowSettings

STAGES = ("visibility", "reference", "cascades", "raster", "shadow")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--device", default="cpu", help="Warp device: cpu or cuda")
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
    scene = make_scene("terrain", seed=1)
    dscene = prepare_scene(scene, device=args.device)
    pose = CameraPose(position=np.array([-60.0, 25.0, 80.0]), orientation=rotation_looking_at([0.6, -0.18, -0.8]),
                      aspect=args.width / args.height, near=0.1, far=400.0)
    light = direction_from_angles(elevation_deg=40.0, azimuth_deg=30.0)
    settings = ShadowSettings(cascades=args.cascades, resolution=args.resolution, filter="pcf", filter_size=3)

    def one_frame():
        view = render_view(dscene, pose, light, width=args.width, height=args.height)
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
    work = {"visibility": (pixels, "Mpixels/s"), "reference": (pixels, "Mpixels/s"), "cascades": (0, ""),
            "raster": (args.cascades * args.resolution**2, "Mtexels/s"), "shadow": (pixels, "Mpixels/s")}
    print(f"scene {scene.name!r}: {scene.triangle_count:,} triangles; device {args.device}; "
          f"{args.cascades} cascades x {args.resolution}^2; view {args.width}x{args.height}; "
          f"best of {args.repeats} after a warm-up")
    print(f"{'stage':<11} {'ms':>9} {'throughput':>20}")
    for stage in STAGES:
        seconds = best[stage]
        count, unit = work[stage]
        rate = f"{count / seconds / 1e6:9.1f} {unit}" if count else "-"
        print(f"{stage:<11} {seconds * 1e3:9.1f} {rate:>20}")
    print(f"{'frame':<11} {total * 1e3:9.1f}")
    print(f"texels rasterized (coverage tests passed): {frame.maps.texels_rasterized:,}")


if __name__ == "__main__":
    main()
