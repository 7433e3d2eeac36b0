"""``foliage``: trees of alpha-tested leaf cards and chain-link fences — the cut-out casters of real games.

Players report shimmer most often from foliage and fences: their shadows are the holes of an
alpha mask (:class:`~csmlab.scene.core.AlphaMask`), thinner than a shadow texel, cut out in the
depth pass. This scene puts both beside the ring road of the default paths
(:mod:`csmlab.scene.layout`):

- **trees** 6–14 m inside and outside the ring: an opaque trunk (an 8-sided prism) and a crown of
  leaf cards — 0.7 m quads turned at random about the crown's centre, two-sided (both windings,
  so that a face cull keeps one), each showing a mask of a few leaves (ellipses) drawn once per seed;
- **chain-link fences**, chords of circles 8–12 m inside and 7–12 m outside the ring: one 2 m
  high two-sided quad per fence whose texture coordinates repeat a diamond mesh of ``mesh_cell``
  (5 cm wires of 4 mm by default, finer than any cascade's texel), on opaque posts every 3 m.

Every mask and placement comes from the seed (NumPy's generator, one stream per use), so a scene is
the same for the same parameters. The masks' texels are 0 or 1 and the cutoff 0.5 (glTF's default).
"""

from __future__ import annotations

import numpy as np

from csmlab.scene.alpha_files import read_alpha_mask
from csmlab.scene.checks import count, positive
from csmlab.scene.core import AlphaMask, Scene
from csmlab.scene.layout import RING_RADIUS
from csmlab.scene.shapes import height_field, placed, scene_from_parts, unit_box, unit_prism

__all__ = ["chain_link_mask", "foliage", "leaf_mask"]

GROUND = (0.30, 0.36, 0.22)
BARK = (0.30, 0.22, 0.14)
LEAF = (0.16, 0.34, 0.10)
WIRE = (0.55, 0.56, 0.58)
POST = (0.40, 0.40, 0.42)
FENCE_HEIGHT = 2.0
POST_SPACING = 3.0
TREE_BANDS = ((RING_RADIUS - 14.0, RING_RADIUS - 6.0), (RING_RADIUS + 6.0, RING_RADIUS + 14.0))
"""Distances from the origin of the trees inside and outside the ring road, metres."""
FENCE_BANDS = ((RING_RADIUS - 12.0, RING_RADIUS - 8.0), (RING_RADIUS + 7.0, RING_RADIUS + 12.0))
"""Distances from the origin of the inner and outer fences' chords, metres."""
TRUNK_RADIUS = 0.12
CROWN_RADIUS = 1.6
MASK_TEXELS = 64


def leaf_mask(rng: np.random.Generator, *, texels: int = MASK_TEXELS, leaves: int = 7) -> np.ndarray:
    """A ``(texels, texels)`` mask of ``leaves`` elliptic leaves at random places and angles, 1 inside, 0 outside."""
    j, i = np.mgrid[0:texels, 0:texels]
    x, y = (i + 0.5) / texels, (j + 0.5) / texels
    alpha = np.zeros((texels, texels), dtype=np.float32)
    for _ in range(leaves):
        cx, cy = rng.uniform(0.2, 0.8, 2)
        angle = rng.uniform(0.0, np.pi)
        length, width = rng.uniform(0.18, 0.3), rng.uniform(0.06, 0.11)
        u = (x - cx) * np.cos(angle) + (y - cy) * np.sin(angle)
        v = -(x - cx) * np.sin(angle) + (y - cy) * np.cos(angle)
        alpha[(u / length) ** 2 + (v / width) ** 2 <= 1.0] = 1.0
    return alpha


def chain_link_mask(*, texels: int = MASK_TEXELS, wire: float = 0.08) -> np.ndarray:
    """One chain-link diamond ``(texels, texels)``: 1 within ``wire`` (a fraction of the cell) of a diagonal."""
    j, i = np.mgrid[0:texels, 0:texels]
    x, y = (i + 0.5) / texels, (j + 0.5) / texels
    # The two diagonals of the unit cell, repeated: |x − y| and |x + y − 1| measured across the cell's wrap.
    d1 = np.abs(((x - y) + 0.5) % 1.0 - 0.5)
    d2 = np.abs(((x + y) + 0.5) % 1.0 - 0.5)
    return (np.minimum(d1, d2) * np.sqrt(0.5) <= wire / 2.0).astype(np.float32)


def _two_sided_quads(corners: np.ndarray, uv: np.ndarray, *, albedo, mask: int) -> tuple:
    """Quads ``(N, 4, 3)`` with coordinates ``(N, 4, 2)`` as vertices, triangles of both windings, albedo and masks."""
    n = corners.shape[0]
    vertices = corners.reshape(-1, 3)
    base = 4 * np.arange(n)[:, None]
    front = np.array([[0, 1, 2], [0, 2, 3]])
    back = front[:, ::-1]
    triangles = np.concatenate([base[:, None, :] + front[None], base[:, None, :] + back[None]], axis=1).reshape(-1, 3)
    colour = np.broadcast_to(np.asarray(albedo, dtype=np.float32), (triangles.shape[0], 3))
    return vertices, triangles, uv.reshape(-1, 2), colour, np.full(vertices.shape[0], mask, np.int32)


def _masked_scene(pieces, masks, *, name: str) -> Scene:
    """One :class:`Scene` of masked quads ``pieces`` (from :func:`_two_sided_quads`), normals from the winding."""
    starts = np.cumsum([0] + [p[0].shape[0] for p in pieces[:-1]])
    vertices = np.concatenate([p[0] for p in pieces])
    triangles = np.concatenate([p[1] + s for p, s in zip(pieces, starts)])
    cross = np.cross(vertices[triangles[:, 1]] - vertices[triangles[:, 0]],
                     vertices[triangles[:, 2]] - vertices[triangles[:, 0]])
    return Scene(vertices, triangles, cross / np.linalg.norm(cross, axis=1, keepdims=True),
                 np.concatenate([p[3] for p in pieces]), name=name, uv=np.concatenate([p[2] for p in pieces]),
                 vertex_mask=np.concatenate([p[4] for p in pieces]), alpha=tuple(masks))


def _ring_places(rng: np.random.Generator, n: int, bands) -> np.ndarray:
    """``n`` points ``(n, 2)`` (x, z) alternately in each band of distances, spread evenly in angle with jitter."""
    which = np.arange(n) % len(bands)
    lo = np.array([b[0] for b in bands])[which]
    hi = np.array([b[1] for b in bands])[which]
    r = rng.uniform(lo, hi)
    angle = rng.uniform(0.0, 2.0 * np.pi) + 2.0 * np.pi * np.arange(n) / max(n, 1) + rng.uniform(-0.1, 0.1, n)
    return np.stack([r * np.cos(angle), r * np.sin(angle)], axis=1)


def _crown_cards(rng: np.random.Generator, centres: np.ndarray, cards: int,
                 size: float) -> tuple[np.ndarray, np.ndarray]:
    """Leaf cards ``(N·cards, 4, 3)`` around crown ``centres`` ``(N, 3)``, turned at random, and their coordinates."""
    n = centres.shape[0] * cards
    # Uniform in the crown's ball, each card facing a random direction.
    direction = rng.normal(size=(n, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    at = np.repeat(centres, cards, axis=0) + direction * (CROWN_RADIUS * rng.uniform(0.0, 1.0, (n, 1)) ** (1 / 3))
    normal = rng.normal(size=(n, 3))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    helper = np.where(np.abs(normal[:, 1:2]) < 0.9, [[0.0, 1.0, 0.0]], [[1.0, 0.0, 0.0]])
    s = np.cross(normal, helper)
    s /= np.linalg.norm(s, axis=1, keepdims=True)
    t = np.cross(normal, s)
    h = size / 2.0
    corners = np.stack([at - h * s - h * t, at + h * s - h * t, at + h * s + h * t, at - h * s + h * t], axis=1)
    uv = np.broadcast_to(np.array([[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]]), (n, 4, 2))
    return corners, uv


def foliage(*, seed: int = 1, size: float = 200.0, trees: int = 16, cards_per_tree: int = 40,
            card_size: float = 0.7, fences: int = 4, mesh_cell: float = 0.05, wire: float = 0.004,
            cutoff: float = 0.5, leaf_mask_file: str = "") -> Scene:
    """Ground with trees of alpha-tested leaf cards and chain-link fences on both sides of the ring road.

    Parameters
    ----------
    seed : int
        Seed of the NumPy generator (the leaf mask, tree and fence placement, the cards).
    size : float
        Side of the square ground centred at the origin at ``y = 0``, metres; at least 80 m.
    trees : int
        Trees, alternately 6–14 m inside and outside the ring road.
    cards_per_tree : int
        Leaf cards in each crown.
    card_size : float
        Side of a leaf card, metres.
    fences : int
        Chain-link fences, alternately inside and outside the ring, each a chord about 10 m long.
    mesh_cell : float
        Side of one diamond of the chain-link mesh (the fence texture's repeat), metres.
    wire : float
        Thickness of the mesh's wire, metres (less than ``mesh_cell / 2``).
    cutoff : float
        The masks' alpha cutoff, in (0, 1].
    leaf_mask_file : str
        An image whose alpha channel (or luminance) is the leaf cards' mask instead of the drawn
        one (:func:`csmlab.scene.alpha_files.read_alpha_mask`), a path as given (relative: to the
        working directory); "" draws the mask.

    Returns
    -------
    Scene
        The ground, trunks and fence posts (opaque), then the leaf cards (mask 0) and the fences'
        mesh (mask 1), four triangles a quad (two each way).

    Raises
    ------
    ValueError
        On a bad keyword, naming it.
    InputError
        ``leaf_mask_file`` missing or not an image (naming the file and ``scene.leaf_mask_file``).
    """
    seed = count(seed, field="seed")
    size = positive(size, field="size")
    if size < 80.0:
        raise ValueError(f"size: expected at least 80 m so the outer trees and fences stand on the ground, "
                         f"got {size!r}")
    n_trees = count(trees, field="trees")
    n_cards = count(cards_per_tree, field="cards_per_tree", minimum=1)
    card_size = positive(card_size, field="card_size")
    n_fences = count(fences, field="fences")
    mesh_cell = positive(mesh_cell, field="mesh_cell")
    wire = positive(wire, field="wire")
    if wire >= mesh_cell / 2.0:
        raise ValueError(f"wire: expected less than half of mesh_cell ({mesh_cell / 2.0:g} m), got {wire!r}")
    cutoff = positive(cutoff, field="cutoff")
    if cutoff > 1.0:
        raise ValueError(f"cutoff: expected a value in (0, 1], got {cutoff!r}")
    mask_rng, tree_rng, card_rng, fence_rng = [np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(4)]
    leaf = (read_alpha_mask(leaf_mask_file, cutoff=cutoff, field="scene.leaf_mask_file") if leaf_mask_file
            else AlphaMask(leaf_mask(mask_rng), cutoff, source="foliage leaf"))
    masks = (leaf,
             AlphaMask(chain_link_mask(wire=wire / mesh_cell), cutoff, source="foliage chain-link"))

    half = size / 2.0
    parts = [height_field([-half, half], [-half, half], np.zeros((2, 2)), albedo=GROUND)]
    pieces = []
    if n_trees:
        xz = _ring_places(tree_rng, n_trees, TREE_BANDS)
        height = tree_rng.uniform(3.0, 5.0, n_trees)
        parts.append(placed(unit_prism(8), scale=np.stack([np.full(n_trees, TRUNK_RADIUS), height,
                                                           np.full(n_trees, TRUNK_RADIUS)], axis=1),
                            offset=np.stack([xz[:, 0], np.zeros(n_trees), xz[:, 1]], axis=1), albedo=BARK))
        crowns = np.stack([xz[:, 0], height + 0.4 * CROWN_RADIUS, xz[:, 1]], axis=1)
        corners, uv = _crown_cards(card_rng, crowns, n_cards, card_size)
        pieces.append(_two_sided_quads(corners, uv, albedo=LEAF, mask=0))
    if n_fences:
        middle = _ring_places(fence_rng, n_fences, FENCE_BANDS)
        along = np.stack([-middle[:, 1], middle[:, 0]], axis=1) / np.linalg.norm(middle, axis=1, keepdims=True)
        half_length = fence_rng.uniform(4.0, 6.0, n_fences)
        a, b = middle - along * half_length[:, None], middle + along * half_length[:, None]
        y0, y1 = np.zeros(n_fences), np.full(n_fences, FENCE_HEIGHT)
        corners = np.stack([np.stack([a[:, 0], y0, a[:, 1]], 1), np.stack([b[:, 0], y0, b[:, 1]], 1),
                            np.stack([b[:, 0], y1, b[:, 1]], 1), np.stack([a[:, 0], y1, a[:, 1]], 1)], axis=1)
        u = 2.0 * half_length / mesh_cell
        v = np.full(n_fences, FENCE_HEIGHT / mesh_cell)
        zero = np.zeros(n_fences)
        uv = np.stack([np.stack([zero, v], 1), np.stack([u, v], 1), np.stack([u, zero], 1),
                       np.stack([zero, zero], 1)], axis=1)
        pieces.append(_two_sided_quads(corners, uv, albedo=WIRE, mask=1))
        posts = np.concatenate([a[k] + (b[k] - a[k]) * np.linspace(0.0, 1.0, int(np.ceil(2 * half_length[k]
                                                                                       / POST_SPACING)) + 1)[:, None]
                                for k in range(n_fences)])
        parts.append(placed(unit_box(), scale=[0.03, FENCE_HEIGHT / 2.0 + 0.05, 0.03],
                            offset=np.stack([posts[:, 0], np.full(len(posts), FENCE_HEIGHT / 2.0 + 0.05),
                                             posts[:, 1]], axis=1), albedo=POST))
    opaque = scene_from_parts(parts, name="foliage")
    if not pieces:
        return opaque
    return opaque.merged(_masked_scene(pieces, masks, name="foliage"), name="foliage")
