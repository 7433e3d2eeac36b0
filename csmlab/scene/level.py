"""A scene as a level the camera moves through: its bounds, its centre and its ground, found by ray casts.

csmlab's procedural scenes are laid out for the camera paths (:mod:`csmlab.scene.layout`: ground at
``y ≈ 0``, a clear ring around the origin). A level from a file is not: its ground may be 5–12 m up
and its centre anywhere. :class:`Level` answers what the path generators
(:func:`csmlab.paths.generators.make_path` with ``level=``) and the view check
(:mod:`csmlab.paths.view_check`) ask of it:

* :meth:`Level.ground_heights` — the ground under points of the horizontal plane: the **lowest
  upward-facing surface** met by a vertical ray cast up from below the level (its back face: a
  surface facing up is met from behind by a ray going up). Downward-facing surfaces on the way (the
  underside of a terrain slab, a bridge's soffit) are passed through. A roof or a floor above the
  terrain is therefore not ground: a walker stays on the terrain, and the view check tells when
  that puts it inside a building.
* :meth:`Level.first_hits` — the first surface along any rays and whether its front or back faces
  the ray (by the triangle's winding normal).

Alpha-tested triangles (leaf cards, fences) are left out of the probes: a card is mostly holes and
neither ground nor a wall. A level made only of them is probed whole.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from csmlab.scene.core import Scene

__all__ = ["FRONT", "BACK", "MISS", "Level", "ProbeHits"]

FRONT, BACK, MISS = 1, -1, 0
"""Which side of the hit triangle a ray meets (:attr:`ProbeHits.facing`)."""

MAX_LAYERS = 16
"""Downward-facing surfaces a ground ray passes through before it gives up (no ground there)."""


@dataclass(frozen=True)
class ProbeHits:
    """First hits of probe rays.

    Attributes
    ----------
    distance : ndarray, shape (N,), float64
        Metres along the ray; +inf on a miss.
    facing : ndarray, shape (N,), int8
        :data:`FRONT` where the ray meets the triangle's front (its winding normal faces the ray),
        :data:`BACK` where it meets its back, :data:`MISS` where it meets nothing.
    normal : ndarray, shape (N, 3), float64
        Unit winding normal of the hit triangle; 0 on a miss.
    """

    distance: np.ndarray
    facing: np.ndarray
    normal: np.ndarray


@dataclass(frozen=True)
class Level:
    """A scene's bounds and its opaque triangles uploaded for probing.

    Build it with :meth:`of`. Attributes: ``bounds`` ``(2, 3)`` min and max corner in world metres,
    ``normals`` ``(K, 3)`` unit normals of the probed triangles, ``bvh`` their
    :class:`~csmlab.kernels.visibility.MeshBVH`.
    """

    bounds: np.ndarray
    normals: np.ndarray = field(repr=False)
    bvh: object = field(repr=False)

    @classmethod
    def of(cls, scene: Scene, *, device: str = "cpu") -> Level:
        """The level of ``scene``: its opaque triangles (all, when every one is masked) on ``device``."""
        from csmlab.kernels import start_warp
        from csmlab.kernels.visibility import mesh_bvh

        start_warp()
        keep = np.ones(scene.triangle_count, dtype=bool)
        if scene.masked:
            keep = scene.vertex_mask[scene.triangles[:, 0]] < 0
            if not np.any(keep):
                keep[:] = True
        bvh = mesh_bvh(scene.vertices, scene.triangles[keep], device=device)
        return cls(bounds=scene.bounds, normals=scene.normals[keep], bvh=bvh)

    @property
    def centre(self) -> np.ndarray:
        """Centre of the bounds ``(3,)``, metres."""
        return 0.5 * (self.bounds[0] + self.bounds[1])

    @property
    def half_extent(self) -> np.ndarray:
        """Half the bounds' size along x and z ``(2,)``, metres."""
        size = self.bounds[1] - self.bounds[0]
        return 0.5 * size[[0, 2]]

    @property
    def diagonal(self) -> float:
        """Length of the bounds' diagonal, metres (at least 1 mm)."""
        return max(float(np.linalg.norm(self.bounds[1] - self.bounds[0])), 1e-3)

    def first_hits(self, origins, directions) -> ProbeHits:
        """The first opaque surface along each ray ``(N, 3)`` from ``origins`` ``(N, 3)`` (world metres)."""
        from csmlab.kernels.rays import ray_hits

        o = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
        d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
        reach = float(np.linalg.norm(o - self.centre, axis=1).max(initial=0.0)) + self.diagonal
        hits = ray_hits(self.bvh, o, d, max_distance=2.0 * reach)
        found = hits.triangle >= 0
        normal = np.zeros(o.shape)
        normal[found] = self.normals[hits.triangle[found]]
        side = np.einsum("ij,ij->i", normal, d)
        facing = np.where(~found, MISS, np.where(side < 0.0, FRONT, BACK)).astype(np.int8)
        return ProbeHits(distance=hits.distance, facing=facing, normal=normal)

    def ground_heights(self, x, z) -> np.ndarray:
        """World ``y`` in metres ``(N,)`` of the ground under each ``(x, z)``; NaN where there is none.

        The ground is the lowest upward-facing opaque surface on the vertical line (the module's
        docstring says why).
        """
        x = np.asarray(x, dtype=np.float64).reshape(-1)
        z = np.asarray(z, dtype=np.float64).reshape(-1)
        if x.shape != z.shape or not (np.all(np.isfinite(x)) and np.all(np.isfinite(z))):
            raise ValueError(f"x, z: expected finite coordinates of one shape, got {x.shape} and {z.shape}")
        start = self.bounds[0, 1] - 0.01 * self.diagonal - 1.0
        step = 1e-5 * self.diagonal
        y = np.full(x.shape, start)
        ground = np.full(x.shape, np.nan)
        open_ = np.arange(x.shape[0])
        up = np.array([0.0, 1.0, 0.0])
        for _ in range(MAX_LAYERS):
            if open_.size == 0:
                break
            hits = self.first_hits(np.stack([x[open_], y[open_], z[open_]], axis=1),
                                   np.broadcast_to(up, (open_.size, 3)))
            found = hits.facing != MISS
            up_facing = found & (hits.normal[:, 1] > 0.0)
            ground[open_[up_facing]] = y[open_[up_facing]] + hits.distance[up_facing]
            onward = found & ~up_facing
            y[open_[onward]] += hits.distance[onward] + step
            open_ = open_[onward]
        return ground
