"""``fence``: long picket fences with slats thinner than a shadow texel — the shimmer torture test.

At the default settings (4 cascades, 1024², practical split over 200 m) the first cascade's
texels are about 2–3 cm wide and the others far wider, so 2 cm slats with 4 cm gaps alias in every
cascade and any sub-texel motion of the shadow map makes their shadows crawl.

Fences are straight chords of circles round the origin, on both sides of the camera's 20 m ring
road: inner fences lie 6–15 m inside it (5–14 m from the origin), outer ones 6–15 m outside
(26–35 m). Each has square posts every 2.4 m, two rails behind the slats, and a few tall thin
poles stand between them.
"""

from __future__ import annotations

import numpy as np

from csmlab.scene.checks import count, positive
from csmlab.scene.core import Scene
from csmlab.scene.layout import RING_RADIUS
from csmlab.scene.shapes import Part, height_field, placed, scene_from_parts, unit_box, unit_prism

__all__ = ["fence"]

INNER_BAND = (RING_RADIUS - 15.0, RING_RADIUS - 6.0)
"""Distances from the origin that inner fences stay within, metres."""
OUTER_BAND = (RING_RADIUS + 6.0, RING_RADIUS + 15.0)
"""Distances from the origin that outer fences stay within, metres."""
POST_SPACING = 2.4
POST_SIDE = 0.1
RAIL_HEIGHT = 0.08
RAIL_DEPTH = 0.03
END_GAP = 1.0
"""Gap left between the ends of neighbouring fences of one ring, metres."""

GRAVEL = (0.50, 0.48, 0.44)
WOOD = (0.36, 0.23, 0.12)
POLE = (0.18, 0.18, 0.19)


def _chords(rng: np.random.Generator, n: int, band: tuple[float, float]):
    """``n`` chords inside the annulus ``band``: normal angle, distance from origin, half length (each ``(n,)``).

    Chords are spread evenly in angle and shortened so that neighbours do not meet and both
    ends stay inside the band's outer radius.
    """
    normal = rng.uniform(0.0, 2.0 * np.pi) + 2.0 * np.pi * np.arange(n) / n + rng.uniform(-0.1, 0.1, n)
    distance = rng.uniform(band[0] + 1.0, band[0] + 0.35 * (band[1] - band[0]), n)
    reach = np.sqrt(band[1] ** 2 - distance**2)
    # Two chords at distance d whose normals differ by Δ meet at d·tan(Δ/2) along each.
    # Jitter can bring neighbours 0.2 rad closer than 2π/n.
    neighbour = distance * np.tan(min(np.pi / n - 0.1, 1.4)) - END_GAP if n > 1 else reach
    return normal, distance, np.maximum(np.minimum(reach, neighbour) * rng.uniform(0.8, 1.0, n), POST_SPACING)


def _fence_parts(normal, distance, half_length, height, *, slat_width: float, slat_gap: float,
                 slat_thickness: float) -> list[Part]:
    """Slats, posts and rails of straight fences given as chords, all ``(n,)`` arrays in radians/metres."""
    centre = np.stack([np.cos(normal), np.sin(normal)], axis=1) * distance[:, None]
    along = np.stack([-np.sin(normal), np.cos(normal)], axis=1)
    # Local +X runs along the fence when yaw = −(angle of `along`) (see shapes.placed).
    yaw = -np.arctan2(along[:, 1], along[:, 0])

    def points(spacing):
        counts = np.floor(2.0 * half_length / spacing).astype(int) + 1
        fence = np.repeat(np.arange(normal.size), counts)
        first = np.cumsum(counts) - counts
        s = (np.arange(counts.sum()) - np.repeat(first, counts)) * spacing - np.repeat((counts - 1) * spacing / 2.0,
                                                                                     counts)
        return fence, centre[fence] + along[fence] * s[:, None]

    slat_fence, slat_xz = points(slat_width + slat_gap)
    slats = placed(unit_box(), scale=np.stack([np.full(slat_fence.size, slat_width / 2.0), height[slat_fence] / 2.0,
                                               np.full(slat_fence.size, slat_thickness / 2.0)], axis=1),
                   offset=np.stack([slat_xz[:, 0], height[slat_fence] / 2.0, slat_xz[:, 1]], axis=1),
                   yaw=yaw[slat_fence], albedo=WOOD)
    post_fence, post_xz = points(POST_SPACING)
    post_height = height[post_fence] + 0.1
    posts = placed(unit_box(), scale=np.stack([np.full(post_fence.size, POST_SIDE / 2.0), post_height / 2.0,
                                               np.full(post_fence.size, POST_SIDE / 2.0)], axis=1),
                   offset=np.stack([post_xz[:, 0], post_height / 2.0, post_xz[:, 1]], axis=1),
                   yaw=yaw[post_fence], albedo=WOOD)
    # Rails run behind the slats (on the side away from the origin), at a quarter and four fifths up.
    behind = centre + np.stack([np.cos(normal), np.sin(normal)], axis=1) * (slat_thickness + RAIL_DEPTH) / 2.0
    rails = [placed(unit_box(), scale=np.stack([half_length, np.full(normal.size, RAIL_HEIGHT / 2.0),
                                                np.full(normal.size, RAIL_DEPTH / 2.0)], axis=1),
                    offset=np.stack([behind[:, 0], level * height, behind[:, 1]], axis=1), yaw=yaw, albedo=WOOD)
             for level in (0.25, 0.8)]
    return [slats, posts, *rails]


def fence(*, seed: int = 1, size: float = 200.0, inner_fences: int = 3, outer_fences: int = 5,
          slat_width: float = 0.02, slat_gap: float = 0.04, slat_thickness: float = 0.015, poles: int = 6) -> Scene:
    """Ground with long picket fences of 2 cm slats on both sides of the ring road, and a few poles.

    Parameters
    ----------
    seed : int
        Seed of the NumPy generator (fence placement, heights, poles).
    size : float
        Side of the square ground centred at the origin at ``y = 0``, metres; at least 80 m so
        the outer fences stand on it.
    inner_fences, outer_fences : int
        Number of fences 5–14 m and 26–35 m from the origin.
    slat_width : float
        Width of a slat along the fence, metres (2 cm: thinner than a texel at typical settings).
    slat_gap : float
        Gap between neighbouring slats, metres.
    slat_thickness : float
        Slat thickness across the fence, metres.
    poles : int
        Free-standing poles (radius 5 cm, 6 m tall) between the fences, off the clear zones.

    Returns
    -------
    Scene
        Ground (two triangles, gravel), then per fence: slats (boxes ``slat_width`` ×
        1.0–1.8 m × ``slat_thickness``), 10 cm square posts every 2.4 m, two rails; then poles.
        Every solid is closed; 12 triangles per box, 28 per pole.
    """
    seed = count(seed, field="seed")
    size = positive(size, field="size")
    if size < 2.0 * (OUTER_BAND[1] + 5.0):
        raise ValueError(f"size: expected at least {2.0 * (OUTER_BAND[1] + 5.0):g} m so the outer fences stand on "
                         f"the ground, got {size!r}")
    n_inner = count(inner_fences, field="inner_fences")
    n_outer = count(outer_fences, field="outer_fences")
    slat_width = positive(slat_width, field="slat_width")
    slat_gap = positive(slat_gap, field="slat_gap")
    slat_thickness = positive(slat_thickness, field="slat_thickness")
    n_poles = count(poles, field="poles")
    layout_rng, pole_rng = [np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(2)]

    half = size / 2.0
    parts = [height_field([-half, half], [-half, half], np.zeros((2, 2)), albedo=GRAVEL)]
    chords = [_chords(layout_rng, n, band) for n, band in ((n_inner, INNER_BAND), (n_outer, OUTER_BAND)) if n]
    if chords:
        normal, distance, half_length = (np.concatenate(c) for c in zip(*chords))
        height = layout_rng.uniform(1.0, 1.8, normal.size)
        parts += _fence_parts(normal, distance, half_length, height, slat_width=slat_width, slat_gap=slat_gap,
                              slat_thickness=slat_thickness)
    if n_poles:
        # Alternately inside and outside the ring, clear of it and of the disc by construction.
        inside = np.arange(n_poles) % 2 == 0
        r = np.where(inside, pole_rng.uniform(7.0, 12.0, n_poles), pole_rng.uniform(24.5, 30.0, n_poles))
        angle = pole_rng.uniform(0.0, 2.0 * np.pi, n_poles)
        x, z = r * np.cos(angle), r * np.sin(angle)
        parts.append(placed(unit_prism(8), scale=[0.05, 6.0, 0.05], offset=np.stack([x, np.zeros(n_poles), z], axis=1),
                            albedo=POLE))
    return scene_from_parts(parts, name="fence")
