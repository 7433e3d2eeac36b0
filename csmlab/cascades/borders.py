"""Unity HDRP's dithered cascade borders: the split sphere a receiver is shaded from, per pixel.

HDRP (``HDShadowAlgorithms.hlsl`` 10.10.1, ``EvalShadow_GetSplitIndex`` and
``EvalShadow_CascadedDepth_Dither_SplitIndex``, the directional filter of the default Medium quality)
selects the first culling sphere ``i`` with ``0 < |X − c_i|² / r_i² ≤ 1`` and, within the sphere's
border, takes the next cascade instead where the pixel's interleaved gradient noise is at most the
border weight::

    alpha = saturate((d² / r² − (1 − border_i)) / border_i)          (0 where border_i ≤ 0)
    alpha = lerp(alpha, 0, saturate(dot(viewDir, wposDir) · (8 + 512 · smoothstep(1, 0.7, border_i))))
    next  = min(i + 1, count − 1);  take next where next ≠ i, alpha > 0 and IGN(pixel) ≤ alpha

``viewDir`` is the unit vector from the point toward the camera and ``wposDir`` the unit vector from
the sphere's centre to the point, so the border only dithers on the sphere's far side from the
camera. A dither, not a blend: each pixel reads one cascade, and TAA averages them. The selection is
``selection = "sphere_dither"`` with ``cascade_borders`` (HDRP ``cascadeShadowBorder0..3``).
"""

from __future__ import annotations

import numpy as np

__all__ = ["border_weights", "dithered_sphere_cascades"]


def _smoothstep(edge0: float, edge1: float, x) -> np.ndarray:
    """HLSL ``smoothstep``: ``t² (3 − 2t)`` with ``t = saturate((x − edge0) / (edge1 − edge0))``."""
    t = np.clip((np.asarray(x, dtype=np.float64) - edge0) / (edge1 - edge0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def border_weights(cascade, points, *, centres, radii, borders, eye) -> np.ndarray:
    """HDRP's border weight ``alpha`` ``(N,)`` of each point in its split sphere (0 where it has none).

    Parameters
    ----------
    cascade : array_like, shape (N,), int
        Each point's first split sphere holding it, −1 where none.
    points : array_like, shape (N, 3)
        World positions, metres.
    centres : array_like, shape (C, 3)
        The split spheres' centres, world metres.
    radii : array_like, shape (C,)
        Their radii, metres.
    borders : array_like, shape (C,)
        Each sphere's border as a fraction of its squared radius, in [0, 1].
    eye : array_like, shape (3,)
        The camera's world position, metres.
    """
    c = np.asarray(cascade, dtype=np.int64)
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    held = c >= 0
    i = np.where(held, c, 0)
    border = np.asarray(borders, dtype=np.float64)[i]
    offset = p - np.asarray(centres, dtype=np.float64)[i]
    dist_sq = np.sum(offset * offset, axis=1)
    relative = dist_sq / np.asarray(radii, dtype=np.float64)[i] ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        alpha = np.where(border > 0.0, np.clip((relative - (1.0 - border)) / border, 0.0, 1.0), 0.0)
        outward = offset / np.sqrt(dist_sq)[:, None]
        view = np.asarray(eye, dtype=np.float64) - p
        view = view / np.linalg.norm(view, axis=1, keepdims=True)
    sharpness = 8.0 + 512.0 * _smoothstep(1.0, 0.7, border)
    facing = np.clip(np.sum(view * outward, axis=1) * sharpness, 0.0, 1.0)
    alpha = alpha * (1.0 - facing)
    return np.where(held & np.isfinite(alpha), alpha, 0.0)


def dithered_sphere_cascades(cascade, points, *, centres, radii, borders, eye, noise) -> np.ndarray:
    """The cascade ``(N,)`` int32 each point is shaded from: its split sphere's, or the next where ``noise ≤ alpha``.

    ``noise`` ``(N,)`` is each point's interleaved gradient noise in [0, 1) (HDRP
    ``InterleavedGradientNoise(positionSS, _TaaFrameInfo.z)``); the other parameters as
    :func:`border_weights`. −1 stays −1 (no sphere holds the point).
    """
    c = np.asarray(cascade, dtype=np.int64)
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    rows = _border_rows(c, p, centres=centres, radii=radii, borders=borders)
    # border_weights is row by row: on the rows alone it has the bits it has there on every point.
    alpha = border_weights(c[rows], p[rows], centres=centres, radii=radii, borders=borders, eye=eye)
    take = rows[(alpha > 0.0) & (np.asarray(noise, dtype=np.float64)[rows] <= alpha)]
    out = c.astype(np.int32)
    out[take] += 1
    return out


def _border_rows(cascade: np.ndarray, points: np.ndarray, *, centres, radii, borders) -> np.ndarray:
    """The rows ``(M,)`` whose ``alpha`` may be above 0 and that have a next cascade: in a sphere that is not the
    last, whose border is above 0, about past ``1 − border`` of its squared radius (``alpha``'s numerator above 0).

    A superset of those rows, never fewer: the squared distance is summed a coordinate at a time (not as
    :func:`border_weights` sums it) and the threshold lowered by a relative 10⁻⁹, far more than the two
    sums' few ulps apart; :func:`border_weights` then computes ``alpha`` on these rows exactly.
    """
    border = np.asarray(borders, dtype=np.float64)
    rows = np.flatnonzero((cascade >= 0) & (cascade < len(np.asarray(radii)) - 1))
    rows = rows[border[cascade[rows]] > 0.0]
    i = cascade[rows]
    centre = np.asarray(centres, dtype=np.float64)
    dist_sq = np.zeros(rows.size)
    for axis in range(3):
        offset = points[rows, axis] - centre[i, axis]
        dist_sq += offset * offset
    with np.errstate(divide="ignore", invalid="ignore"):
        relative = dist_sq / np.asarray(radii, dtype=np.float64)[i] ** 2
    return rows[relative > (1.0 - border[i]) * (1.0 - 1e-9)]
