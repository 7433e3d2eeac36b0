"""The check of every frame's view against the level: views no player would see (``[camera] view_check``).

A path that does not fit its level gives metrics for views of nothing: a camera inside a house,
under the terrain, or with its near plane cutting through a wall. :func:`check_views` finds them
by probe rays (:meth:`csmlab.scene.level.Level.first_hits`) from every frame's eye:

* **inside geometry** — more than half of a sparse grid of view rays (:data:`GRID_COLUMNS` across,
  rows by the aspect) meet the back of a surface first: the eye is inside a closed solid (a house
  modelled with outward normals). A room modelled with inward normals is not flagged.
* **below the ground** — the first surface straight above the eye faces up (the ray meets its
  back) and no upward-facing surface lies straight below it: the eye is under the terrain.
* **near plane clips the view** — more than half of the view rays meet a surface nearer than the
  near plane (view depth < ``near``): the picture is mostly clipped geometry.

The rays ignore alpha masks (a leaf card is not a wall; :mod:`csmlab.scene.level`). Findings name
frames as ranges (``3–6, 10``); ``[camera] view_check`` (:data:`csmlab.config.records.VIEW_CHECK_MODES`)
warns, refuses (exit 2, for CI) or skips the check; :func:`findings_line` is the one-line warning, and
:meth:`ViewFindings.as_dict` what ``summary.json`` keeps under ``view_check``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from csmlab.camera import CameraPath
from csmlab.geometry import quat_to_matrix
from csmlab.scene.level import BACK, FRONT, MISS, Level

__all__ = ["CHECKS", "FRAMES_PER_CAST", "GRID_COLUMNS", "MOST", "ViewFindings", "check_views", "findings_line",
           "frame_ranges"]

GRID_COLUMNS = 32
"""View rays across the image; rows follow the aspect (at least 2)."""

MOST = 0.5
"""Share of the view rays above which a frame is flagged."""

FRAMES_PER_CAST = 256
"""Frames whose view rays go to the BVH at once (bounds the memory of a 10,000-frame path's check)."""

CHECKS = {
    "inside_geometry": "camera inside geometry",
    "below_ground": "camera below the ground",
    "near_clipped": "near plane clips most of the view",
}
"""Finding keys (``summary.json``) and their words."""


@dataclass(frozen=True)
class ViewFindings:
    """The frames each check flagged.

    Attributes
    ----------
    frames : int
        Frames checked.
    inside_geometry, below_ground, near_clipped : tuple of int
        Flagged frames, ascending.
    """

    frames: int
    inside_geometry: tuple[int, ...] = ()
    below_ground: tuple[int, ...] = ()
    near_clipped: tuple[int, ...] = ()

    @property
    def clean(self) -> bool:
        """No frame was flagged."""
        return not (self.inside_geometry or self.below_ground or self.near_clipped)

    def as_dict(self) -> dict:
        """``{"frames": n, key: [[first, last], …] for each of CHECKS}``: flagged frames as inclusive ranges."""
        return {"frames": self.frames, **{key: [list(r) for r in frame_ranges(getattr(self, key))] for key in CHECKS}}


def frame_ranges(frames) -> list[tuple[int, int]]:
    """Consecutive runs ``(first, last)`` (inclusive) of the ascending frame numbers ``frames``."""
    out: list[tuple[int, int]] = []
    for f in frames:
        if out and f == out[-1][1] + 1:
            out[-1] = (out[-1][0], int(f))
        else:
            out.append((int(f), int(f)))
    return out


def _ranges_text(ranges) -> str:
    return ", ".join(str(a) if a == b else f"{a}–{b}" for a, b in ranges)


def findings_line(summary: dict | None) -> str | None:
    """The one-line warning of a :meth:`ViewFindings.as_dict` (from ``summary.json``); None when nothing was flagged."""
    if not summary:
        return None
    parts = [f"{words} in frame(s) {_ranges_text(summary.get(key) or [])}" for key, words in CHECKS.items()
             if summary.get(key)]
    if not parts:
        return None
    return f"view check ({summary.get('frames', '?')} frames): " + "; ".join(parts)


def _view_directions(path: CameraPath, rows: int) -> np.ndarray:
    """Unit world directions ``(N, rows·GRID_COLUMNS, 3)`` of each frame's grid of rays through cell centres, row-major
    from the top."""
    u = (np.arange(GRID_COLUMNS) + 0.5) / GRID_COLUMNS * 2.0 - 1.0
    v = 1.0 - (np.arange(rows) + 0.5) / rows * 2.0
    uu, vv = np.meshgrid(u, v)
    tan_y = np.tan(np.radians(path.fov_y_deg) / 2.0)[:, None]
    camera = np.stack([uu.reshape(1, -1) * tan_y * path.aspect, vv.reshape(1, -1) * tan_y,
                       -np.ones((1, uu.size)) * np.ones_like(tan_y)], axis=-1)
    camera /= np.linalg.norm(camera, axis=-1, keepdims=True)
    return np.einsum("nij,nkj->nki", quat_to_matrix(path.orientations), camera)


def check_views(level: Level, path: CameraPath) -> ViewFindings:
    """Flag the frames of ``path`` whose view does not fit ``level`` (the module's docstring lists the checks).

    Parameters
    ----------
    level : Level
    path : CameraPath
        In the level's world (after any ``[scene] offset``).

    Returns
    -------
    ViewFindings
    """
    n = len(path)
    rows = max(2, int(round(GRID_COLUMNS / path.aspect)))
    inside = np.zeros(n, dtype=bool)
    clipped = np.zeros(n, dtype=bool)
    for start in range(0, n, FRAMES_PER_CAST):
        frames = slice(start, min(start + FRAMES_PER_CAST, n))
        inside[frames], clipped[frames] = _view_flags(level, path, frames, rows)
    up = np.broadcast_to([0.0, 1.0, 0.0], (n, 3))
    above = level.first_hits(path.positions, up)
    below = level.first_hits(path.positions, -up)
    under_a_ground = (above.facing == BACK) & (above.normal[:, 1] > 0.0)
    ground_below = (below.facing == FRONT) & (below.normal[:, 1] > 0.0)
    return ViewFindings(frames=n, inside_geometry=_frames(inside), below_ground=_frames(under_a_ground & ~ground_below),
                        near_clipped=_frames(clipped))


def _view_flags(level: Level, path: CameraPath, frames: slice, rows: int) -> tuple[np.ndarray, np.ndarray]:
    """Inside-geometry and near-clipped flags ``(F,)`` of the path's ``frames`` from their grids of view rays."""
    part = dataclasses.replace(path, times=path.times[frames], positions=path.positions[frames],
                               orientations=path.orientations[frames], fov_y_deg=path.fov_y_deg[frames])
    directions = _view_directions(part, rows)
    f, k = directions.shape[:2]
    view = level.first_hits(np.repeat(part.positions, k, axis=0), directions.reshape(-1, 3))
    facing = view.facing.reshape(f, k)
    # View depth of a hit: its distance times the cosine to the view axis.
    forward = -quat_to_matrix(part.orientations)[:, :, 2]
    depth = view.distance.reshape(f, k) * np.einsum("nki,ni->nk", directions, forward)
    return np.mean(facing == BACK, axis=1) > MOST, np.mean((facing != MISS) & (depth < path.near), axis=1) > MOST


def _frames(mask: np.ndarray) -> tuple[int, ...]:
    return tuple(int(i) for i in np.flatnonzero(mask))
