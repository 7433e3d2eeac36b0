"""Screen-space derivatives per 2×2 pixel quad, as hardware takes them, and the level of detail they give.

A GPU shades pixels in 2×2 quads and takes a derivative as the difference of a value between
lanes of the quad: *coarse* derivatives, one per quad, ``ddx = v(x₀ + 1, y₀) − v(x₀, y₀)`` and
``ddy = v(x₀, y₀ + 1) − v(x₀, y₀)`` with ``(x₀, y₀)`` the quad's top-left pixel (Direct3D 11 GPUs;
seed 002, "Derivative-Based Offset"). Lanes whose pixel the triangle does not cover still run as
helpers, evaluating the triangle's plane at their pixel centre. :func:`quad_lanes` rebuilds that:
for each pixel, where the rays through the four pixel centres of its quad meet the plane of the
pixel's own triangle (the pixel's own lane is its G-buffer point, unchanged).

A mipmapped moment map is sampled at a level of detail from the derivatives of the texel
coordinates (:func:`csmlab.kernels.moments.moment_mip_lookup`). Each lane selects its own
cascade, so where a quad straddles a split boundary its lanes' texel coordinates belong to two
different shadow maps and their difference is meaningless: the level of detail jumps to the
coarsest level and a *seam* appears along the boundary (seed 003, "Filtering across splits",
Figures 4.1.11–4.1.12; seed 002, "Gradients with CSMs", Figure 17). PCF filters after the depth
comparison and takes no derivative, so it shows no such seam. :data:`LOD_METHODS`, the choices:

- ``quad`` — what hardware does: each lane's texel coordinates in its own cascade.
- ``quad_consistent`` — PSVSM's trick (Lauritzen 2007; seed 003, Listing 4.1.6): the quad's
  lanes agree on one split index, the lowest selected in the quad (the listing finds it from
  ``ddx(2^split)``), and the pixel is looked up in that cascade (its own when that box does not
  hold the pixel's filter taps).
- ``analytic`` — derivatives of a cascade-independent position, scaled into the selected cascade
  (seed 003, Listing 4.1.7; seed 002: ``ddx(vShadowMapTextureCoordViewSpace) * m_vCascadeScale``):
  here the lanes' light-space differences in the pixel's own cascade's texels, which in the fixed
  point of :mod:`csmlab.texels` is the lanes' coordinates in that one cascade.

In a blend band the second sample, at cascade i + 1, takes the lanes' differences in cascade
i + 1's texels whatever the choice (the cascade-independent footprint carried across).

The temporal metric (:mod:`csmlab.metrics.temporal`) looks frame t−1's maps up at frame t's
quads, each lane with frame t−1's own cascade selection: a same-cascade pixel then keeps its
footprint, and what changes is the maps and which cascade every lane selects. Under ``quad`` a
lane that changes cascade beside a pixel that does not moves the seam, a change the metric counts.

References
----------
- Lauritzen, "Parallel-Split Variance Shadow Maps" (PSVSM), 2007; in Zhang, Zaprjagaev, Bentham,
  "Practical Cascaded Shadow Maps", ShaderX7 (seed 003).
- Microsoft, "Cascaded Shadow Maps" (seed 002), "Derivative-Based Offset", "Gradients with CSMs".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from csmlab.camera import CameraPose
from csmlab.registry import check_name

__all__ = ["LOD_METHODS", "Quads", "quad_derivatives", "quad_lanes"]

LOD_METHODS: dict[str, str] = {
    "quad": "coarse derivatives of each lane's texel coordinates in its own cascade (hardware; a seam at splits)",
    "quad_consistent": "the quad's lowest cascade for all four lanes (PSVSM, seed 003 Listing 4.1.6)",
    "analytic": ("the lanes' light-space differences in the selected cascade's texels (seed 003 Listing 4.1.7, "
                 "seed 002)"),
}
"""Where a mipmapped lookup's level of detail comes from, by name (the ``[shadow] lod`` values)."""


@dataclass(frozen=True)
class Quads:
    """Each pixel's 2×2 quad: its four lanes' points on the pixel's triangle plane.

    Attributes
    ----------
    position : ndarray, shape (..., 4, 3), float64
        World points of lanes (x₀, y₀), (x₀ + 1, y₀), (x₀, y₀ + 1), (x₀ + 1, y₀ + 1), metres.
    slot : ndarray, shape (...), int8
        Which lane is the pixel itself.
    """

    position: np.ndarray
    slot: np.ndarray

    def __getitem__(self, index) -> Quads:
        return Quads(position=self.position[index], slot=self.slot[index])


def quad_lanes(pose: CameraPose, points, normals, *, width: int, height: int) -> Quads:
    """The quad lanes of every pixel of an image, on the plane of the pixel's own triangle.

    Parameters
    ----------
    pose : CameraPose
        The camera the image was taken with.
    points : array_like, shape (H, W, 3), float64
        G-buffer positions, metres; NaN on a miss.
    normals : array_like, shape (H, W, 3)
        G-buffer geometric normals.
    width, height : int
        Image size in pixels (``W``, ``H``); pixel ``(row, col)`` has its centre at ``(col + ½, row + ½)``.

    Returns
    -------
    Quads
        ``position`` of shape ``(H, W, 4, 3)``. A lane whose ray meets the plane behind the camera
        or not at all (an edge-on triangle) takes the pixel's own point: a zero difference.
    """
    p = np.asarray(points, dtype=np.float64)
    n = np.asarray(normals, dtype=np.float64)
    if p.shape != (height, width, 3) or n.shape != p.shape:
        raise ValueError(f"points, normals: expected shape ({height}, {width}, 3), got {p.shape}, {n.shape}")
    rows, cols = np.indices((height, width))
    slot = ((cols & 1) + 2 * (rows & 1)).astype(np.int8)
    lane = np.arange(4)
    lane_cols = (cols & ~1)[..., None] + (lane & 1)
    lane_rows = (rows & ~1)[..., None] + (lane >> 1)
    # The camera rays of camera_hits (csmlab.kernels.visibility): unit forward component.
    tan_y = np.tan(np.radians(pose.fov_y_deg) / 2.0)
    r = pose.rotation
    sx = (lane_cols + 0.5 - 0.5 * width) * (2.0 * tan_y * pose.aspect / width)
    sy = (0.5 * height - lane_rows - 0.5) * (2.0 * tan_y / height)
    direction = -r[:, 2] + sx[..., None] * r[:, 0] + sy[..., None] * r[:, 1]
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.sum(n * (p - pose.position), axis=-1)[..., None] / np.sum(n[..., None, :] * direction, axis=-1)
    lanes = pose.position + t[..., None] * direction
    keep = (t > 0) & np.isfinite(t)
    lanes = np.where(keep[..., None], lanes, p[..., None, :])
    lanes[rows, cols, slot] = p
    return Quads(position=lanes, slot=slot)


def quad_derivatives(lane_coords, lane_cascade, own, *, method: str, bits: int,
                     holds=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The cascade a pixel is looked up in and its quad's coarse derivatives under ``method``.

    Parameters
    ----------
    lane_coords : array_like, shape (C, N, 4, 2), int64
        Every lane's fixed-point texel coordinates in every cascade (``2**-bits`` texels).
    lane_cascade : array_like, shape (N, 4), int
        The cascade each lane selects, −1 for none (such a lane counts as the pixel's own cascade).
    own : array_like, shape (N,), int
        The pixel's own selection, −1 for none.
    method : str
        A key of :data:`LOD_METHODS`.
    bits : int
        Sub-texel bits of ``lane_coords``.
    holds : array_like, shape (C, N), bool, optional
        ``quad_consistent``: which boxes hold the pixel's filter taps (None: every box).

    Returns
    -------
    cascade : ndarray, shape (N,), int32
        The cascade looked up (−1 where ``own`` is −1).
    ddx, ddy : ndarray, shape (2, N, 2), float64
        Coarse derivatives in level-0 texels per pixel: row 0 in ``cascade``'s texels as
        ``method`` takes them, row 1 the lanes' differences in cascade ``cascade + 1``'s (the
        last cascade's where there is none), for a blend band.
    """
    check_name(method, LOD_METHODS, field="lod")
    xy = np.asarray(lane_coords, dtype=np.int64)
    lanes = np.asarray(lane_cascade, dtype=np.int64)
    own = np.asarray(own, dtype=np.int64)
    count, n = xy.shape[0], own.shape[0]
    if xy.shape != (count, n, 4, 2) or lanes.shape != (n, 4):
        raise ValueError(f"lane_coords, lane_cascade, own: expected shapes (C, N, 4, 2), (N, 4), (N,); "
                         f"got {xy.shape}, {lanes.shape}, {own.shape}")
    base = np.maximum(own, 0)
    lanes = np.where(lanes >= 0, lanes, base[:, None])
    cascade = own.copy()
    if method == "quad_consistent":
        lowest = lanes.min(axis=1)
        ok = np.ones(n, dtype=bool) if holds is None else np.asarray(holds, dtype=bool)[lowest, np.arange(n)]
        cascade = np.where((own >= 0) & ok, lowest, own)
    index = np.arange(n)
    used = np.maximum(cascade, 0)
    if method != "quad":
        lanes = np.repeat(used[:, None], 4, axis=1)
    unit = float(2**bits)

    def differences(lane_of):
        at = xy[lane_of, index[:, None], np.arange(4)[None, :]]  # (N, 4, 2)
        return (at[:, 1] - at[:, 0]) / unit, (at[:, 2] - at[:, 0]) / unit

    ddx0, ddy0 = differences(lanes)
    nxt = np.repeat(np.minimum(used + 1, count - 1)[:, None], 4, axis=1)
    ddx1, ddy1 = differences(nxt)
    return cascade.astype(np.int32), np.stack([ddx0, ddx1]), np.stack([ddy0, ddy1])
