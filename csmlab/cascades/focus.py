"""What a tight (``stabilization = "none"``) cascade covers: the view slice, or the slice focused on the scene.

``focus = "scene"`` is Filament's tightly bound scene with focus on the shadow casters
(google/filament ``filament/src/ShadowMap.cpp`` @0362f36, ``computeLightFrustumBounds``,
``intersectFrustumWithBox``): the light-space box of the receivers' bounds intersected with the
casters' bounds (csmlab's receivers and casters are the same scene: its light-space box), and the
view slice clipped to that box. The map then covers only the part of the slice where a shadow can
fall; Filament relies on its 1-texel border for what lies outside. The hull's points are the slice
corners inside the box, the box corners inside the slice, and the crossings of each one's edges
with the other's faces — Filament's steps (a)–(d).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from csmlab.registry import check_name, dispatch

__all__ = ["FOCUS_METHODS", "focus_scene", "focus_slice", "focused_volume", "frustum_box_intersection"]

# Corner pairs of an edge and corner quadruples of a face, for the 8 corners of a slice as
# csmlab.geometry.frustum_slice_corners orders them (4 near then 4 far, each counter-clockwise).
_EDGES = np.array([[0, 1], [1, 2], [2, 3], [3, 0], [4, 5], [5, 6], [6, 7], [7, 4], [0, 4], [1, 5], [2, 6], [3, 7]])
_FACES = np.array([[0, 1, 2, 3], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]])
# Filament's tolerance of a point on a plane (intersectFrustumWithBox: 1/8192 m).
_EPSILON = 1.0 / 8192.0


def _box_corners(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """The 8 corners of the box ``[lo, hi]`` in the slice's corner order (so ``_EDGES`` are its edges)."""
    return np.array([[lo[0], lo[1], lo[2]], [hi[0], lo[1], lo[2]], [hi[0], hi[1], lo[2]], [lo[0], hi[1], lo[2]],
                     [lo[0], lo[1], hi[2]], [hi[0], lo[1], hi[2]], [hi[0], hi[1], hi[2]], [lo[0], hi[1], hi[2]]])


def _outward_planes(corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit outward normals ``(6, 3)`` and offsets ``(6,)`` of a hexahedron's faces (``n·p + c ≤ 0`` inside)."""
    centre = corners.mean(axis=0)
    quads = corners[_FACES]
    normals = np.cross(quads[:, 2] - quads[:, 0], quads[:, 1] - quads[:, 0])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    offsets = -np.einsum("fk,fk->f", normals, quads[:, 0])
    flip = normals @ centre + offsets > 0.0
    normals[flip] *= -1.0
    offsets[flip] *= -1.0
    return normals, offsets


def _inside_planes(points: np.ndarray, normals: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    return np.all(points @ normals.T + offsets <= _EPSILON, axis=-1)


def _crossings(segments: np.ndarray, normals: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Points ``(M, 3)`` where segments ``(S, 2, 3)`` cross planes ``n·p + c = 0`` within the segments."""
    a, b = segments[:, 0], segments[:, 1]
    da = a @ normals.T + offsets
    db = b @ normals.T + offsets
    with np.errstate(divide="ignore", invalid="ignore"):
        t = da / (da - db)
    crossing = (da * db < 0.0) & np.isfinite(t)
    s, f = np.nonzero(crossing)
    return a[s] + t[s, f, None] * (b[s] - a[s])


def frustum_box_intersection(corners, lo, hi) -> np.ndarray:
    """Points ``(M, 3)`` whose convex hull is the slice with ``corners`` ``(8, 3)`` clipped to the box ``[lo, hi]``.

    Light-space metres. Empty ``(0, 3)`` when they do not meet.
    """
    corners = np.asarray(corners, dtype=np.float64)
    lo = np.asarray(lo, dtype=np.float64)
    hi = np.asarray(hi, dtype=np.float64)
    box = _box_corners(lo, hi)
    box_normals = np.vstack([-np.eye(3), np.eye(3)])
    box_offsets = np.concatenate([lo, -hi])
    slice_normals, slice_offsets = _outward_planes(corners)
    candidates = np.vstack([
        corners[_inside_planes(corners, box_normals, box_offsets)],
        box[_inside_planes(box, slice_normals, slice_offsets)],
        _crossings(box[_EDGES], slice_normals, slice_offsets),
        _crossings(corners[_EDGES], box_normals, box_offsets),
    ])
    keep = _inside_planes(candidates, box_normals, box_offsets) & _inside_planes(candidates, slice_normals,
                                                                                   slice_offsets)
    return candidates[keep]


def focus_slice(*, corners: np.ndarray, scene_light: np.ndarray) -> np.ndarray:
    """The slice itself: its 8 light-space corners."""
    return corners


def focus_scene(*, corners: np.ndarray, scene_light: np.ndarray) -> np.ndarray:
    """The slice clipped to the scene's light-space box (receivers ∩ casters); the slice where they miss."""
    hull = frustum_box_intersection(corners, scene_light.min(axis=0), scene_light.max(axis=0))
    return hull if hull.shape[0] >= 4 else corners


FOCUS_METHODS: dict[str, Callable[..., np.ndarray]] = {
    "slice": focus_slice,
    "scene": focus_scene,
}
"""What a tight cascade covers (``[shadow] focus``), by name: each returns light-space points ``(M, 3)``."""


def focused_volume(name: str, *, corners, scene_light) -> np.ndarray:
    """Light-space points ``(M, 3)`` of what cascade covers under focus ``name`` (:data:`FOCUS_METHODS`).

    Parameters
    ----------
    name : str
    corners : array_like, shape (8, 3)
        The slice's corners in light space (metres).
    scene_light : array_like, shape (K, 3)
        Points bounding the scene (receivers and casters) in light space.
    """
    return dispatch(FOCUS_METHODS, check_name(name, FOCUS_METHODS, field="focus"), field="focus",
                    corners=np.asarray(corners, dtype=np.float64),
                    scene_light=np.asarray(scene_light, dtype=np.float64))
