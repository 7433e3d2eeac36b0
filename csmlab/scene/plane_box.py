"""``plane_box``: a square ground plane and one axis-aligned box — the scene of the analytic tests."""

from __future__ import annotations

import numpy as np

from csmlab.scene.checks import count, positive
from csmlab.scene.core import Scene
from csmlab.scene.shapes import height_field, placed, scene_from_parts, unit_box

__all__ = ["plane_box"]

PLANE_ALBEDO = (0.5, 0.5, 0.5)
BOX_ALBEDO = (0.7, 0.35, 0.2)


def plane_box(*, plane_size: float = 200.0, plane_divisions: int = 1, box_size: float = 2.0,
              box_height: float | None = None, box_center=(0.0, 0.0)) -> Scene:
    """A square ground plane with one axis-aligned box standing on it (analytic cases); exact geometry.

    Parameters
    ----------
    plane_size : float
        Side of the square plane, metres.
    plane_divisions : int
        Cells per side of the plane; each cell is two triangles.
    box_size : float
        Side of the box's square footprint, metres.
    box_height : float, optional
        Height of the box, metres; ``None`` makes a cube of side ``box_size``.
    box_center : (float, float)
        ``(x, z)`` of the footprint's centre, metres.

    Returns
    -------
    Scene
        With ``s = plane_size``, ``d = plane_divisions``, ``b = box_size``, ``h = box_height``,
        ``(cx, cz) = box_center``:

        * plane: ``x, z ∈ [−s/2, s/2]`` at ``y = 0``, on the grid ``−s/2 + k s/d``; ``2 d²`` triangles,
          normal ``+Y``, albedo (0.5, 0.5, 0.5); triangles ``0 … 2d² − 1``;
        * box: closed, ``x ∈ [cx − b/2, cx + b/2]``, ``y ∈ [0, h]``, ``z ∈ [cz − b/2, cz + b/2]``;
          12 triangles with outward axis normals (its bottom face lies on the plane), albedo
          (0.7, 0.35, 0.2); the last 12 triangles.

        Bounds: ``min(−s/2, cx − b/2), 0, min(−s/2, cz − b/2)`` to
        ``max(s/2, cx + b/2), h, max(s/2, cz + b/2)``.

    Notes
    -----
    Unlike the other procedural scenes, the default box stands at the origin, inside the clear
    disc of :mod:`csmlab.scene.layout`: analytic cases want it there. Place it elsewhere with
    ``box_center`` for camera paths that cross the origin.
    """
    size = positive(plane_size, field="plane_size")
    divisions = count(plane_divisions, field="plane_divisions", minimum=1)
    side = positive(box_size, field="box_size")
    height = side if box_height is None else positive(box_height, field="box_height")
    center = np.asarray(box_center, dtype=np.float64)
    if center.shape != (2,) or not np.all(np.isfinite(center)):
        raise ValueError(f"box_center: expected two finite numbers (x, z) in metres, got {box_center!r}")
    grid = np.linspace(-size / 2.0, size / 2.0, divisions + 1)
    plane = height_field(grid, grid, np.zeros((divisions + 1, divisions + 1)), albedo=PLANE_ALBEDO)
    half = np.array([side / 2.0, height / 2.0, side / 2.0])
    box = placed(unit_box(), scale=half, offset=[[center[0], height / 2.0, center[1]]], albedo=BOX_ALBEDO)
    return scene_from_parts([plane, box], name="plane_box")
