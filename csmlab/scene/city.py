"""``city``: rings of building blocks around an open plaza, cut by radial streets.

The plaza (radius 24 m) holds the camera's ring road and is furnished with lamp posts and
planters off the ring; buildings start 2 m beyond its edge and fill annular blocks separated by
ring streets and radial streets. Each building is a box whose front faces the origin; its
footprint fits inside its lot's wedge, so streets stay clear.
"""

from __future__ import annotations

import numpy as np

from csmlab.scene.checks import count, positive
from csmlab.scene.core import Scene
from csmlab.scene.layout import clear_of_camera
from csmlab.scene.shapes import Part, height_field, placed, scene_from_parts, unit_box, unit_prism

__all__ = ["PLAZA_RADIUS", "city"]

PLAZA_RADIUS = 24.0
"""Radius of the open plaza at the origin, metres."""
FIRST_BLOCK = PLAZA_RADIUS + 2.0
"""Inner radius of the first ring of blocks (a 2 m pavement round the plaza), metres."""
LOT_GAP = 2.0
"""Gap between neighbouring buildings of one block, metres."""

STONE = (0.45, 0.42, 0.38)
ASPHALT = (0.08, 0.08, 0.09)
PAVEMENT = (0.28, 0.28, 0.27)
METAL = (0.15, 0.15, 0.16)
PLANTER = (0.35, 0.30, 0.25)


def _block_radii(*, half: float, block_depth: float, street_width: float, lot_width: float) -> np.ndarray:
    """Inner radii ``(B,)`` of the rings of blocks that fit on a ground of half side ``half``, metres."""
    pitch = block_depth + street_width
    rings = max(0, int(np.floor((half - lot_width - block_depth - FIRST_BLOCK) / pitch)) + 1)
    return FIRST_BLOCK + pitch * np.arange(rings)


def _buildings(rng: np.random.Generator, *, radii: np.ndarray, streets: int, street_angle0: float,
               street_width: float, block_depth: float, lot_width: float, towers: int) -> Part:
    """One box per lot over every block, as a :class:`Part`."""
    inner, angle, half_width = [], [], []
    for r_in in radii:
        # Wedge between two radial streets, narrowed so the street strip is clear at r_in (and so beyond).
        margin = np.arcsin(min(1.0, street_width / 2.0 / r_in))
        span = 2.0 * np.pi / streets - 2.0 * margin
        if span <= 0.0:
            continue
        lots = max(1, int(span * r_in // lot_width))
        step = span / lots
        centres = (street_angle0 + margin + step * (np.arange(lots) + 0.5))[None, :] \
            + 2.0 * np.pi / streets * np.arange(streets)[:, None]
        width = r_in * np.tan(step / 2.0) - LOT_GAP / 2.0
        if width <= 1.0:
            continue
        inner.append(np.full(centres.size, r_in))
        angle.append(centres.reshape(-1))
        half_width.append(np.full(centres.size, width))
    if not inner:
        return Part(np.empty((0, 3)), np.empty((0, 3), dtype=np.int64), np.empty((0, 3), dtype=np.float32))
    inner, angle, half_width = np.concatenate(inner), np.concatenate(angle), np.concatenate(half_width)
    n = inner.size
    setback = rng.uniform(0.0, 1.5, n)
    depth = (block_depth - setback) * rng.uniform(0.5, 1.0, n)
    height = np.clip(rng.lognormal(np.log(14.0), 0.45, n), 5.0, 45.0)
    tall = rng.choice(n, size=min(towers, n), replace=False)
    height[tall] = rng.uniform(60.0, 110.0, tall.size)
    centre = inner + setback + depth / 2.0
    grey = rng.uniform(0.25, 0.55, (n, 1)) * np.stack([np.ones(n), rng.uniform(0.9, 1.0, n),
                                                       rng.uniform(0.8, 1.0, n)], axis=1)
    # Local +X becomes the radial direction at angle α when yaw = −α (see shapes.placed).
    return placed(unit_box(), scale=np.stack([depth / 2.0, height / 2.0, half_width], axis=1),
                  offset=np.stack([centre * np.cos(angle), height / 2.0, centre * np.sin(angle)], axis=1),
                  yaw=-angle, albedo=grey)


def _plaza_furniture(rng: np.random.Generator) -> list[Part]:
    """Lamp posts inside the ring and along the plaza's edge, and planters inside the ring."""
    lamp_angle = np.concatenate([np.linspace(0.0, 2.0 * np.pi, 8, endpoint=False),
                                 np.linspace(0.0, 2.0 * np.pi, 16, endpoint=False)]) + rng.uniform(0.0, 0.4)
    lamp_r = np.concatenate([np.full(8, 13.5), np.full(16, PLAZA_RADIUS + 0.5)])
    lamps = placed(unit_prism(8), scale=[0.1, 5.0, 0.1],
                   offset=np.stack([lamp_r * np.cos(lamp_angle), np.zeros(24), lamp_r * np.sin(lamp_angle)], axis=1),
                   albedo=METAL)
    angle = rng.uniform(0.0, 2.0 * np.pi, 40)
    r = rng.uniform(7.0, 15.0, 40)
    x, z = r * np.cos(angle), r * np.sin(angle)
    keep = np.flatnonzero(clear_of_camera(x, z, radius=np.hypot(1.5, 0.6)))[:10]
    planters = placed(unit_box(), scale=[1.5, 0.45, 0.6], offset=np.stack([x[keep], np.full(keep.size, 0.45),
                                                                             z[keep]], axis=1),
                      yaw=rng.uniform(0.0, np.pi, keep.size), albedo=PLANTER)
    return [lamps, planters]


def _ground_albedo(x: np.ndarray, z: np.ndarray, *, radii: np.ndarray, street_angles: np.ndarray,
                   street_width: float, block_depth: float) -> np.ndarray:
    """Albedo ``(N, 3)`` of ground cells centred at ``(x, z)``: plaza stone, street asphalt, pavement."""
    r = np.hypot(x, z)
    direction = np.stack([np.cos(street_angles), np.sin(street_angles)])
    along = x[:, None] * direction[0] + z[:, None] * direction[1]
    across = np.abs(-x[:, None] * direction[1] + z[:, None] * direction[0])
    on_radial = np.any((along > 0.0) & (across < street_width / 2.0), axis=1)
    pitch = block_depth + street_width
    in_ring_street = (r > radii[0] + block_depth) & ((r - radii[0]) % pitch > block_depth) if radii.size else False
    albedo = np.broadcast_to(np.asarray(PAVEMENT, dtype=np.float32), (r.size, 3)).copy()
    albedo[(on_radial | in_ring_street) & (r >= PLAZA_RADIUS)] = ASPHALT
    albedo[r < PLAZA_RADIUS] = STONE
    return albedo


def city(*, seed: int = 1, size: float = 400.0, streets: int = 8, street_width: float = 10.0,
         block_depth: float = 24.0, lot_width: float = 16.0, towers: int = 6, ground_divisions: int = 160) -> Scene:
    """Building blocks on a flat ground with a plaza, ring streets and radial streets.

    Parameters
    ----------
    seed : int
        Seed of the NumPy generator (building sizes, tower lots, street rotation, furniture).
    size : float
        Side of the square ground centred at the origin at ``y = 0``, metres.
    streets : int
        Number of radial streets, evenly spaced in angle.
    street_width : float
        Width of radial and ring streets, metres.
    block_depth : float
        Radial depth of a ring of blocks, metres; blocks start at 26 m from the origin.
    lot_width : float
        Target frontage of one building at its block's inner radius, metres.
    towers : int
        Buildings raised to 60–110 m; the others are 5–45 m tall.
    ground_divisions : int
        Ground cells per side (two triangles each), coloured as plaza, street or pavement.

    Returns
    -------
    Scene
        Ground first, then buildings (closed boxes, 12 triangles each), then 24 lamp posts
        (5 m, radius 0.1 m) and up to 10 planters (3 × 0.9 × 1.2 m).
    """
    seed = count(seed, field="seed")
    size = positive(size, field="size")
    streets = count(streets, field="streets", minimum=1)
    street_width = positive(street_width, field="street_width")
    block_depth = positive(block_depth, field="block_depth")
    lot_width = positive(lot_width, field="lot_width")
    towers = count(towers, field="towers")
    divisions = count(ground_divisions, field="ground_divisions", minimum=1)
    layout_rng, building_rng, furniture_rng = [np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(3)]
    street_angle0 = layout_rng.uniform(0.0, 2.0 * np.pi / streets)
    street_angles = street_angle0 + 2.0 * np.pi / streets * np.arange(streets)
    radii = _block_radii(half=size / 2.0, block_depth=block_depth, street_width=street_width, lot_width=lot_width)

    grid = np.linspace(-size / 2.0, size / 2.0, divisions + 1)
    mid = (grid[:-1] + grid[1:]) / 2.0
    cx, cz = np.meshgrid(mid, mid)
    albedo = _ground_albedo(cx.reshape(-1), cz.reshape(-1), radii=radii, street_angles=street_angles,
                            street_width=street_width, block_depth=block_depth)
    ground = height_field(grid, grid, np.zeros((divisions + 1, divisions + 1)), albedo=np.repeat(albedo, 2, axis=0))
    buildings = _buildings(building_rng, radii=radii, streets=streets, street_angle0=street_angle0,
                           street_width=street_width, block_depth=block_depth, lot_width=lot_width, towers=towers)
    return scene_from_parts([ground, buildings, *_plaza_furniture(furniture_rng)], name="city")
