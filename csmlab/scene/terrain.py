"""``terrain``: a height field with hills beyond the camera's area, scattered with low-poly trees.

The ground is flat to within ±0.15 m inside 50 m of the origin (:mod:`csmlab.scene.layout` asks
for ±0.3 m inside 45 m) and rises into hills farther out, which gives the far cascades long
slopes and deep depth ranges. Trees are a hexagonal trunk with either a conifer crown (an
octagonal cone) or a broadleaf crown (an icosahedron stretched to an ellipsoid); none stands on
the clear ring road or disc, and an extra batch stands 2–15 m from the ring.
"""

from __future__ import annotations

import numpy as np

from csmlab.scene.checks import count, non_negative, positive
from csmlab.scene.core import Scene
from csmlab.scene.layout import RING_HALF_WIDTH, RING_RADIUS, clear_of_camera
from csmlab.scene.shapes import Part, height_field, placed, scene_from_parts, unit_cone, unit_icosahedron, unit_prism

__all__ = ["terrain"]

BUMP_HEIGHT = 0.15
"""Amplitude of the ground's small undulation everywhere, metres."""
HILLS_START = 50.0
"""Horizontal distance from the origin where hills begin to rise, metres."""
HILLS_FULL = 110.0
"""Distance from which hills have their full height, metres."""
TRUNK_SINK = 0.3
"""How far a trunk reaches below the ground under it, so no gap opens on a slope, metres."""

GRASS = np.array([0.16, 0.27, 0.08])
ROCK = np.array([0.34, 0.31, 0.27])
BARK = (0.22, 0.14, 0.08)
CONIFER = np.array([0.05, 0.16, 0.06])
BROADLEAF = np.array([0.12, 0.26, 0.07])


def _waves(rng: np.random.Generator, *, count: int, wavelengths: tuple[float, float]):
    """Random plane waves: wave vectors ``(count, 2)`` in rad/m and phases ``(count,)``."""
    angle = rng.uniform(0.0, 2.0 * np.pi, count)
    k = 2.0 * np.pi / rng.uniform(*wavelengths, count)
    return np.stack([np.cos(angle), np.sin(angle)], axis=1) * k[:, None], rng.uniform(0.0, 2.0 * np.pi, count)


def _wave_mean(x, z, waves) -> np.ndarray:
    """Mean of ``cos(k · (x, z) + phase)`` over the waves, in [−1, 1], shape of ``x``."""
    k, phase = waves
    return np.mean(np.cos(x[..., None] * k[:, 0] + z[..., None] * k[:, 1] + phase), axis=-1)


def _ground_height(x, z, *, bumps, hills, hill_height: float) -> np.ndarray:
    """Ground height ``y`` in metres at world ``(x, z)`` (arrays of any shape)."""
    t = np.clip((np.hypot(x, z) - HILLS_START) / (HILLS_FULL - HILLS_START), 0.0, 1.0)
    rise = t * t * (3.0 - 2.0 * t)
    return BUMP_HEIGHT * _wave_mean(x, z, bumps) + hill_height * rise * (0.5 + 0.5 * _wave_mean(x, z, hills))


def _tree_sites(rng: np.random.Generator, n: int, *, draw_xz, crown_radius: tuple[float, float], half: float):
    """``n`` tree positions ``(n, 2)`` and crown radii ``(n,)``: on the ground, off the clear zones.

    ``draw_xz(m)`` proposes ``m`` positions; proposals whose footprint leaves the square ground of
    half side ``half`` or touches a clear zone are redrawn, up to a bounded number of rounds.
    """
    xz, radius = np.empty((0, 2)), np.empty(0)
    for _ in range(64):
        if xz.shape[0] >= n:
            break
        batch = 2 * (n - xz.shape[0]) + 16
        cand = draw_xz(batch)
        r = rng.uniform(*crown_radius, batch)
        keep = clear_of_camera(cand[:, 0], cand[:, 1], radius=r) & (np.abs(cand).max(axis=1) + r <= half)
        xz, radius = np.concatenate([xz, cand[keep]]), np.concatenate([radius, r[keep]])
    if xz.shape[0] < n:
        raise ValueError(f"trees: expected a larger size or fewer trees; only {xz.shape[0]} of {n} fit on a "
                         f"{2.0 * half:g} m ground away from the clear ring road and disc")
    return xz[:n], radius[:n]


def _trees(rng: np.random.Generator, xz: np.ndarray, crown: np.ndarray, ground) -> list[Part]:
    """Trunks and crowns for trees at ``xz`` (n, 2) with crown radii ``crown`` (n,), metres."""
    n = xz.shape[0]
    trunk_radius = rng.uniform(0.15, 0.35, n)
    trunk_height = rng.uniform(2.0, 4.5, n)
    conifer = rng.random(n) < 0.5
    yaw = rng.uniform(0.0, 2.0 * np.pi, n)
    tint = rng.uniform(0.8, 1.2, (n, 1))
    # Lowest ground under the trunk, sampled at its centre and four rim points.
    rim = np.array([[0.0, 0.0], [1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])
    sample = xz[:, None, :] + rim[None] * trunk_radius[:, None, None]
    base = ground(sample[..., 0], sample[..., 1]).min(axis=1) - TRUNK_SINK
    top = ground(xz[:, 0], xz[:, 1]) + trunk_height
    parts = [placed(unit_prism(6), scale=np.stack([trunk_radius, top - base, trunk_radius], axis=1),
                    offset=np.stack([xz[:, 0], base, xz[:, 1]], axis=1), yaw=yaw, albedo=BARK)]
    cone_height = crown[conifer] * rng.uniform(2.5, 4.0, int(conifer.sum()))
    cone_base = top[conifer] - 0.3 * trunk_height[conifer]
    parts.append(placed(unit_cone(8), scale=np.stack([crown[conifer], cone_height, crown[conifer]], axis=1),
                        offset=np.stack([xz[conifer, 0], cone_base, xz[conifer, 1]], axis=1), yaw=yaw[conifer],
                        albedo=np.clip(CONIFER * tint[conifer], 0.0, 1.0)))
    broad = ~conifer
    vertical = crown[broad] * rng.uniform(0.8, 1.3, int(broad.sum()))
    parts.append(placed(unit_icosahedron(), scale=np.stack([crown[broad], vertical, crown[broad]], axis=1),
                        offset=np.stack([xz[broad, 0], top[broad] + 0.6 * vertical, xz[broad, 1]], axis=1),
                        yaw=yaw[broad], albedo=np.clip(BROADLEAF * tint[broad], 0.0, 1.0)))
    return parts


def terrain(*, seed: int = 1, size: float = 400.0, resolution: int = 320, hill_height: float = 30.0,
            trees: int = 1500, ring_trees: int = 120) -> Scene:
    """Hilly ground beyond 50 m with about 1,600 low-poly trees: ≥ 200k triangles by default.

    Parameters
    ----------
    seed : int
        Seed of the NumPy generator; the ground and the trees draw from independent streams, so
        changing ``trees`` leaves the ground as it was.
    size : float
        Side of the square ground centred at the origin, metres.
    resolution : int
        Grid cells per side: the ground has ``2 · resolution²`` triangles (204,800 by default).
    hill_height : float
        Height of the highest hills, which rise between 50 m and 110 m from the origin, metres.
    trees : int
        Trees scattered uniformly over the ground (off the clear zones).
    ring_trees : int
        Extra trees 2–15 m from the 20 m ring road, on both sides.

    Returns
    -------
    Scene
        Ground triangles first (grass, turning to rock with height), then trunks (20 triangles
        each, hexagonal, closed), conifer crowns (14 each) and broadleaf crowns (20 each). The
        default has ≈ 265,000 triangles. Crown radii are 1.2–2.8 m, trunks 2–4.5 m tall.
    """
    seed = count(seed, field="seed")
    size = positive(size, field="size")
    resolution = count(resolution, field="resolution", minimum=1)
    hill_height = non_negative(hill_height, field="hill_height")
    n_scattered = count(trees, field="trees")
    n_ring = count(ring_trees, field="ring_trees")
    ground_rng, scatter_rng, ring_rng, shape_rng = [np.random.default_rng(s)
                                                    for s in np.random.SeedSequence(seed).spawn(4)]
    bumps = _waves(ground_rng, count=6, wavelengths=(6.0, 20.0))
    hills = _waves(ground_rng, count=6, wavelengths=(90.0, 260.0))

    def ground(x, z):
        return _ground_height(x, z, bumps=bumps, hills=hills, hill_height=hill_height)

    grid = np.linspace(-size / 2.0, size / 2.0, resolution + 1)
    heights = ground(*np.meshgrid(grid, grid))
    cell = (heights[:-1, :-1] + heights[1:, 1:] + heights[:-1, 1:] + heights[1:, :-1]) / 4.0
    rockiness = np.clip((cell - 6.0) / 18.0, 0.0, 1.0).reshape(-1, 1)
    albedo = np.repeat(GRASS + (ROCK - GRASS) * rockiness, 2, axis=0)
    parts = [height_field(grid, grid, heights, albedo=albedo)]

    half = size / 2.0
    scattered = _tree_sites(scatter_rng, n_scattered, crown_radius=(1.2, 2.8), half=half,
                            draw_xz=lambda m: scatter_rng.uniform(-half, half, (m, 2)))

    def near_ring(m):
        offset = ring_rng.uniform(RING_HALF_WIDTH, 15.0, m) * ring_rng.choice([-1.0, 1.0], m)
        angle = ring_rng.uniform(0.0, 2.0 * np.pi, m)
        return (RING_RADIUS + offset)[:, None] * np.stack([np.cos(angle), np.sin(angle)], axis=1)

    ringside = _tree_sites(ring_rng, n_ring, crown_radius=(1.2, 2.8), half=half, draw_xz=near_ring)
    xz = np.concatenate([scattered[0], ringside[0]])
    crown = np.concatenate([scattered[1], ringside[1]])
    if xz.shape[0]:
        parts += _trees(shape_rng, xz, crown, ground)
    return scene_from_parts(parts, name="terrain")
