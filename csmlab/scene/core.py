"""The :class:`Scene` record: an indexed triangle mesh with per-triangle normals and albedo."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Scene"]


@dataclass(frozen=True)
class Scene:
    """Geometry lit by the directional light and seen by the camera.

    Attributes
    ----------
    vertices : ndarray, shape (V, 3), float64
        World positions in metres (Y up).
    triangles : ndarray, shape (T, 3), int32
        Vertex indices, counter-clockwise seen from the side the normal points to.
    normals : ndarray, shape (T, 3), float64
        Unit geometric normal of each triangle.
    albedo : ndarray, shape (T, 3), float32
        Linear RGB reflectance in [0, 1] per triangle.
    name : str
        Where the scene came from (generator name or file).

    Raises
    ------
    ValueError
        On an empty scene, non-finite vertices, out-of-range indices, or no triangle of
        non-zero area; the message names the scene and what was expected.
    """

    vertices: np.ndarray
    triangles: np.ndarray
    normals: np.ndarray
    albedo: np.ndarray
    name: str = "scene"

    def __post_init__(self) -> None:
        v = np.ascontiguousarray(self.vertices, dtype=np.float64)
        t = np.ascontiguousarray(self.triangles, dtype=np.int32)
        if v.ndim != 2 or v.shape[1] != 3 or v.shape[0] == 0:
            raise ValueError(f"{self.name}: vertices: expected a non-empty (V, 3) array, got shape {v.shape}")
        if t.ndim != 2 or t.shape[1] != 3 or t.shape[0] == 0:
            raise ValueError(f"{self.name}: triangles: expected at least one triangle, got shape {t.shape}")
        if not np.all(np.isfinite(v)):
            raise ValueError(f"{self.name}: vertices: expected finite coordinates, found NaN or inf")
        if t.min() < 0 or t.max() >= v.shape[0]:
            raise ValueError(f"{self.name}: triangles: expected indices in [0, {v.shape[0]}), got [{t.min()}, {t.max()}]")
        n = np.ascontiguousarray(self.normals, dtype=np.float64)
        a = np.ascontiguousarray(self.albedo, dtype=np.float32)
        if n.shape != t.shape or a.shape != t.shape:
            raise ValueError(f"{self.name}: normals and albedo: expected shape {t.shape}, got {n.shape} and {a.shape}")
        for name, value in (("vertices", v), ("triangles", t), ("normals", n), ("albedo", a)):
            value.setflags(write=False)
            object.__setattr__(self, name, value)

    @classmethod
    def from_triangles(cls, vertices, triangles, *, albedo=(0.6, 0.6, 0.6), name: str = "scene") -> "Scene":
        """Build a scene, computing each triangle's normal from its winding.

        Degenerate (zero-area) triangles are dropped; a scene left with none raises ``ValueError``.
        ``albedo`` is one RGB triple or a ``(T, 3)`` array.
        """
        v = np.asarray(vertices, dtype=np.float64)
        t = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
        alb = np.broadcast_to(np.asarray(albedo, dtype=np.float32), t.shape)
        if v.ndim != 2 or v.shape[-1] != 3 or v.shape[0] == 0 or t.shape[0] == 0:
            raise ValueError(f"{name}: expected vertices (V, 3) and at least one triangle, got {v.shape} and {t.shape}")
        if not np.all(np.isfinite(v)):
            raise ValueError(f"{name}: vertices: expected finite coordinates, found NaN or inf")
        if t.min() < 0 or t.max() >= v.shape[0]:
            raise ValueError(f"{name}: triangles: expected indices in [0, {v.shape[0]}), got [{t.min()}, {t.max()}]")
        cross = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
        length = np.linalg.norm(cross, axis=1)
        scale = max(float(np.ptp(v, axis=0).max()), 1e-30)
        keep = length > 1e-12 * scale * scale
        if not np.any(keep):
            raise ValueError(f"{name}: triangles: expected at least one triangle of non-zero area, all {t.shape[0]} are degenerate")
        return cls(v, t[keep], cross[keep] / length[keep, None], alb[keep], name=name)

    @property
    def triangle_count(self) -> int:
        return self.triangles.shape[0]

    @property
    def bounds(self) -> np.ndarray:
        """Axis-aligned bounds ``(2, 3)``: min and max corner in metres."""
        return np.stack([self.vertices.min(axis=0), self.vertices.max(axis=0)])

    def corners(self) -> np.ndarray:
        """The eight corners ``(8, 3)`` of :attr:`bounds`."""
        lo, hi = self.bounds
        return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])

    def merged(self, other: "Scene", *, name: str | None = None) -> "Scene":
        """This scene and ``other`` as one."""
        return Scene(
            np.concatenate([self.vertices, other.vertices]),
            np.concatenate([self.triangles, other.triangles + self.vertices.shape[0]]),
            np.concatenate([self.normals, other.normals]),
            np.concatenate([self.albedo, other.albedo]),
            name=name or self.name,
        )
