"""Batched triangle primitives that the procedural scenes are assembled from.

A scene generator places hundreds of copies of a few convex unit solids (box, prism, cone,
icosahedron) with one vectorized affine map each, adds a height-field ground, and hands the
pieces to :func:`scene_from_parts`. Every solid is closed and wound counter-clockwise seen from
outside, so :meth:`Scene.from_triangles` gives outward normals; the placement map (positive
scale, rotation about +Y, translation) keeps that orientation.

Units are metres, world Y up.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from csmlab.scene.core import Scene

__all__ = [
    "Part",
    "Solid",
    "height_field",
    "placed",
    "scene_from_parts",
    "unit_box",
    "unit_cone",
    "unit_icosahedron",
    "unit_prism",
]


@dataclass(frozen=True)
class Solid:
    """A closed convex unit shape to be placed many times.

    Attributes
    ----------
    vertices : ndarray, shape (V, 3), float64
        Local coordinates.
    triangles : ndarray, shape (T, 3), int64
        Indices, counter-clockwise seen from outside.
    """

    vertices: np.ndarray
    triangles: np.ndarray


@dataclass(frozen=True)
class Part:
    """A piece of a procedural scene before it becomes a :class:`Scene`.

    Attributes
    ----------
    vertices : ndarray, shape (V, 3), float64
        World positions, metres.
    triangles : ndarray, shape (T, 3), int64
        Indices into ``vertices``, counter-clockwise seen from outside.
    albedo : ndarray, shape (T, 3), float32
        Linear RGB reflectance per triangle.
    """

    vertices: np.ndarray
    triangles: np.ndarray
    albedo: np.ndarray


def _wound_outward(vertices: np.ndarray, triangles: np.ndarray) -> Solid:
    """Reorder each triangle of a convex solid so that its normal points away from the centroid."""
    v = np.asarray(vertices, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64)
    a, b, c = v[t[:, 0]], v[t[:, 1]], v[t[:, 2]]
    inward = np.einsum("ij,ij->i", np.cross(b - a, c - a), (a + b + c) / 3.0 - v.mean(axis=0)) < 0.0
    t = t.copy()
    t[inward] = t[inward][:, ::-1]
    return Solid(v, t)


def _cap(first: int, sides: int) -> np.ndarray:
    """Fan triangles ``(first, first + k, first + k + 1)`` closing a convex ring, shape ``(sides - 2, 3)``."""
    k = np.arange(1, sides - 1)
    return first + np.stack([np.zeros_like(k), k, k + 1], axis=1)


def unit_box() -> Solid:
    """The cube ``[-1, 1]³``: 8 vertices, 12 triangles."""
    corners = np.array([[x, y, z] for z in (-1.0, 1.0) for y in (-1.0, 1.0) for x in (-1.0, 1.0)])
    # Corner index = x_bit + 2 y_bit + 4 z_bit; each face is a quad split along one diagonal.
    quads = np.array([[0, 2, 6, 4], [1, 3, 7, 5], [0, 1, 5, 4], [2, 3, 7, 6], [0, 1, 3, 2], [4, 5, 7, 6]])
    return _wound_outward(corners, np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]]))


def _ring(sides: int, y: float) -> np.ndarray:
    angle = 2.0 * np.pi * np.arange(sides) / sides
    return np.stack([np.cos(angle), np.full(sides, y), np.sin(angle)], axis=1)


def unit_prism(sides: int) -> Solid:
    """A ``sides``-gon prism of circumradius 1 from ``y = 0`` to ``y = 1``, capped: ``4·sides - 4`` triangles."""
    bottom = np.arange(sides)
    top = bottom + sides
    walls = np.concatenate([np.stack([bottom, np.roll(bottom, -1), top], axis=1),
                            np.stack([np.roll(bottom, -1), np.roll(top, -1), top], axis=1)])
    caps = np.concatenate([_cap(0, sides), _cap(sides, sides)])
    return _wound_outward(np.concatenate([_ring(sides, 0.0), _ring(sides, 1.0)]), np.concatenate([walls, caps]))


def unit_cone(sides: int) -> Solid:
    """A ``sides``-gon cone, base circumradius 1 at ``y = 0``, apex at ``y = 1``: ``2·sides - 2`` triangles."""
    base = np.arange(sides)
    walls = np.stack([np.full(sides, sides), base, np.roll(base, -1)], axis=1)
    vertices = np.concatenate([_ring(sides, 0.0), [[0.0, 1.0, 0.0]]])
    return _wound_outward(vertices, np.concatenate([walls, _cap(0, sides)]))


def unit_icosahedron() -> Solid:
    """The regular icosahedron inscribed in the unit sphere: 12 vertices, 20 triangles."""
    p = (1.0 + np.sqrt(5.0)) / 2.0
    v = np.array([[-1, p, 0], [1, p, 0], [-1, -p, 0], [1, -p, 0], [0, -1, p], [0, 1, p], [0, -1, -p], [0, 1, -p],
                  [p, 0, -1], [p, 0, 1], [-p, 0, -1], [-p, 0, 1]], dtype=np.float64)
    faces = [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4], [11, 10, 2],
             [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5], [2, 4, 11],
             [6, 2, 10], [8, 6, 7], [9, 8, 1]]
    return _wound_outward(v / np.linalg.norm(v[0]), faces)


def placed(solid: Solid, *, scale, offset, yaw=0.0, albedo) -> Part:
    """``N`` copies of ``solid``, each scaled, turned about +Y and moved.

    Parameters
    ----------
    solid : Solid
        The unit shape.
    scale : array_like, shape (N, 3) or (3,)
        Positive per-axis scale, metres per local unit.
    offset : array_like, shape (N, 3)
        Where each copy's local origin goes, world metres.
    yaw : array_like, shape (N,) or scalar
        Rotation about +Y in radians, counter-clockwise seen from above (local +X turns toward −Z).
    albedo : array_like, shape (N, 3) or (3,)
        Linear RGB per copy.

    Returns
    -------
    Part
        ``N · V`` vertices and ``N · T`` triangles, copy by copy.
    """
    offset = np.asarray(offset, dtype=np.float64).reshape(-1, 3)
    n = offset.shape[0]
    scale = np.broadcast_to(np.asarray(scale, dtype=np.float64), (n, 3))
    yaw = np.broadcast_to(np.asarray(yaw, dtype=np.float64), (n,))
    local = solid.vertices[None, :, :] * scale[:, None, :]
    c, s = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
    world = np.stack([c * local[..., 0] + s * local[..., 2], local[..., 1], c * local[..., 2] - s * local[..., 0]],
                     axis=-1) + offset[:, None, :]
    nv, nt = solid.vertices.shape[0], solid.triangles.shape[0]
    triangles = solid.triangles[None, :, :] + (nv * np.arange(n, dtype=np.int64))[:, None, None]
    colour = np.broadcast_to(np.asarray(albedo, dtype=np.float32), (n, 3))
    return Part(world.reshape(-1, 3), triangles.reshape(-1, 3), np.repeat(colour, nt, axis=0))


def height_field(x, z, heights, *, albedo) -> Part:
    """A ground surface over a rectilinear grid, two triangles per cell, facing +Y.

    Parameters
    ----------
    x : array_like, shape (NX,)
        Increasing grid abscissae, metres.
    z : array_like, shape (NZ,)
        Increasing grid ordinates, metres.
    heights : array_like, shape (NZ, NX)
        Ground height ``y`` at each grid point, metres.
    albedo : array_like, shape (3,) or (2·(NX−1)·(NZ−1), 3)
        Linear RGB, one triple or one per triangle (cell by cell, row-major in z then x, two
        triangles per cell).

    Returns
    -------
    Part
        ``NX · NZ`` vertices, ``2 (NX − 1)(NZ − 1)`` triangles.
    """
    x = np.asarray(x, dtype=np.float64)
    z = np.asarray(z, dtype=np.float64)
    gx, gz = np.meshgrid(x, z)
    vertices = np.stack([gx, np.asarray(heights, dtype=np.float64).reshape(gx.shape), gz], axis=-1).reshape(-1, 3)
    nx = x.shape[0]
    a = (np.arange(z.shape[0] - 1)[:, None] * nx + np.arange(nx - 1)[None, :]).reshape(-1)
    b, c, d = a + 1, a + nx + 1, a + nx
    # (a, d, c) and (a, c, b) are counter-clockwise seen from +Y for increasing x and z.
    triangles = np.stack([np.stack([a, d, c], axis=1), np.stack([a, c, b], axis=1)], axis=1).reshape(-1, 3)
    colour = np.broadcast_to(np.asarray(albedo, dtype=np.float32), triangles.shape)
    return Part(vertices, triangles.astype(np.int64), np.ascontiguousarray(colour))


def scene_from_parts(parts, *, name: str) -> Scene:
    """Concatenate ``parts`` into one :class:`Scene` whose normals follow the winding."""
    parts = list(parts)
    starts = np.cumsum([0] + [p.vertices.shape[0] for p in parts[:-1]])
    vertices = np.concatenate([p.vertices for p in parts])
    triangles = np.concatenate([p.triangles + s for p, s in zip(parts, starts)])
    albedo = np.concatenate([p.albedo for p in parts])
    return Scene.from_triangles(vertices, triangles, albedo=albedo, name=name)
