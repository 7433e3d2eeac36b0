"""Write data/meshes/jacksboro_patch.obj: a real terrain patch for experiments/level_parts.toml.

The source is matplotlib's sample data ``jacksboro_fault_dem.npz`` (a USGS DEM of the Jacksboro fault,
Tennessee, 3 arc-second posts; shipped with matplotlib, matplotlib's licence): the 24 × 24-post window
whose elevations vary most (standard deviation, windows every 8 posts), as a height field in metres —
x east, y up, z south, post spacing from the DEM's 3″ at its mean latitude, the window's centre at
x = z = 0 and its lowest post at y = 0 — in two triangles per cell, counter-clockwise seen from above.
Run from the project root: ``PYTHONPATH=. python data/meshes/make_jacksboro_patch.py``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib import cbook

POSTS = 24
STEP = 8
EARTH_RADIUS = 6_371_000.0


def patch() -> tuple[np.ndarray, np.ndarray]:
    """Vertices ``(POSTS², 3)`` in metres and triangles ``(2 (POSTS − 1)², 3)`` of the steepest window."""
    dem = cbook.get_sample_data("jacksboro_fault_dem.npz")
    z = dem["elevation"].astype(np.float64)
    starts = [(i, j) for i in range(0, z.shape[0] - POSTS + 1, STEP) for j in range(0, z.shape[1] - POSTS + 1, STEP)]
    i0, j0 = max(starts, key=lambda s: (z[s[0]:s[0] + POSTS, s[1]:s[1] + POSTS].std(), s))
    window = z[i0:i0 + POSTS, j0:j0 + POSTS]
    latitude = np.radians(0.5 * (float(dem["ymin"]) + float(dem["ymax"])))
    east = np.radians(float(dem["dx"])) * EARTH_RADIUS * np.cos(latitude)
    south = np.radians(float(dem["dy"])) * EARTH_RADIUS
    rows, cols = np.meshgrid(np.arange(POSTS), np.arange(POSTS), indexing="ij")
    vertices = np.stack([(cols - (POSTS - 1) / 2) * east, window - window.min(), (rows - (POSTS - 1) / 2) * south],
                        axis=-1).reshape(-1, 3)
    a = (rows[:-1, :-1] * POSTS + cols[:-1, :-1]).ravel()
    b, c, d = a + POSTS, a + POSTS + 1, a + 1
    # Seen from +Y (x east, z south), a → b (south) → c (south-east) turns counter-clockwise.
    return vertices, np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])


def write_patch(path) -> Path:
    vertices, triangles = patch()
    lines = ["# Jacksboro fault DEM window (matplotlib sample data), metres, Y up: data/meshes/make_jacksboro_patch.py"]
    lines += [f"v {x:.3f} {y:.3f} {z:.3f}" for x, y, z in vertices]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in triangles]
    path = Path(path)
    path.write_text("\n".join(lines) + "\n")
    return path


if __name__ == "__main__":
    print(write_patch(Path(__file__).with_name("jacksboro_patch.obj")))
