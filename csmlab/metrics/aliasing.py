"""Perspective aliasing: shadow texels per screen pixel (ρ, σ_min) and texel utilization.

Definitions (docs/design.md, "Metrics", a contract):

- ρ = sqrt|det J| with J the 2×2 Jacobian from screen pixels to the selected cascade's texels at
  the pixel centre, from exact ray differentials (the derivative of the hit point with respect to
  the pixel coordinates, on the hit point's tangent plane; not a finite difference). ρ = 1 is one texel per
  pixel; ρ < 1 under-samples (blocky shadows); ρ ≫ 1 wastes resolution. σ_min(J) is the texel
  density along the worst screen direction.
- Utilization of cascade c: the fraction of its R² texels that contain the surface point of at
  least one visible pixel that selects c. A pixel is counted at the texel its point falls in,
  not at every filter tap, so that a wide PCF kernel does not pass for resolution that is used.

References
----------
- Lloyd, Govindaraju, Molnar, Manocha, "Warping and Partitioning for Low Error Shadow Maps",
  EGSR 2006 — perspective aliasing as the texel-to-pixel ratio.
- Valient, "Stable Rendering of Cascaded Shadow Maps", ShaderX6 — why the bounding sphere wastes texels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from csmlab.cascades import CascadeSet
from csmlab.clipmaps import light_space
from csmlab.frame import Frame
from csmlab.kernels.footprint import surface_differentials, texel_footprint, warped_texel_footprint
from csmlab.kernels.usage import looked_up_texels
from csmlab.metric_registry import linear_percentiles
from csmlab.texels import texel_coordinates

__all__ = ["AliasingMaps", "RHO_SUMMARIES", "aliasing_maps", "aliasing_summary", "texel_axes", "utilization"]


@dataclass(frozen=True)
class AliasingMaps:
    """Per-pixel footprint of one frame.

    Attributes
    ----------
    rho : ndarray, shape (H, W), float32
        sqrt|det J|, shadow texels per screen pixel (linear); NaN where no cascade was selected.
    sigma_min : ndarray, shape (H, W), float32
        Smallest singular value of J, texels per pixel; NaN where no cascade was selected.
    cascade : ndarray, shape (H, W), int8
        The selected cascade (-1 where none), as in :attr:`csmlab.frame.ShadowLookup.cascade`.
    """

    rho: np.ndarray
    sigma_min: np.ndarray
    cascade: np.ndarray


RHO_SUMMARIES: tuple[str, ...] = ("rho_median", "rho_p05", "rho_p95", "rho_frac_lt1", "rho_frac_lt05")
"""The ρ summaries reported overall and, with a ``_c{i}`` suffix, per cascade."""


def texel_axes(cascades: CascadeSet) -> np.ndarray:
    """World directions of light-space x and y in texels per metre, ``(C, 2, 3)`` float64.

    Row ``[c, k]`` is ``basis[k] / texel_size[c][k]``: the linear part of the map from world
    metres to cascade c's texel coordinates (an orthographic projection).
    """
    return np.stack([cascades.basis[:2] / c.texel_size[:, None] for c in cascades.cascades])


def aliasing_maps(frame: Frame, *, device: str = "cpu") -> AliasingMaps:
    """ρ and σ_min of every visible pixel of ``frame`` in the cascade it selected.

    Parameters
    ----------
    frame : Frame
        Its G-buffer's ``position`` and ``normal``, its camera and its shadow's ``cascade`` are used.
    device : str
        Warp device of the footprint kernel.

    Returns
    -------
    AliasingMaps
    """
    g = frame.view.gbuffer
    cascade = np.where(g.valid, frame.shadow.cascade, -1).astype(np.int8)
    pose = frame.view.pose
    dpdu, dpdv = frame.view.shared(("surface_differentials", device), lambda: surface_differentials(
        g.position, g.normal, eye=pose.position, rotation=pose.rotation, fov_y_deg=pose.fov_y_deg,
        aspect=pose.aspect, device=device))
    cascades = frame.maps.cascades
    if cascades.warped:
        rho, sigma_min = warped_texel_footprint(g.position, dpdu, dpdv, cascade, basis=cascades.basis,
                                                homographies=[c.homography for c in cascades.cascades],
                                                device=device)
    else:
        rho, sigma_min = texel_footprint(dpdu, dpdv, cascade, texel_axes=texel_axes(cascades), device=device)
    return AliasingMaps(rho=rho, sigma_min=sigma_min, cascade=cascade)


def _rho_statistics(rho: np.ndarray) -> dict[str, float]:
    """:data:`RHO_SUMMARIES` of ``rho`` ``(N,)`` float32 or float64, a scratch copy: the percentiles partition it
    in place."""
    if rho.size == 0:
        return dict.fromkeys(RHO_SUMMARIES, float("nan"))
    # A count over N is the mean of the booleans, exactly. 1 and ½ are float32 values: the comparisons are those of
    # the float64 values.
    below_one = np.count_nonzero(rho < 1.0) / rho.size
    below_half = np.count_nonzero(rho < 0.5) / rho.size
    p05, median, p95 = linear_percentiles(rho, (5.0, 50.0, 95.0))
    return {
        "rho_median": float(median),
        "rho_p05": float(p05),
        "rho_p95": float(p95),
        "rho_frac_lt1": float(below_one),
        "rho_frac_lt05": float(below_half),
    }


def aliasing_summary(maps: AliasingMaps, *, cascades: int) -> dict[str, float]:
    """ρ summaries overall and per cascade, and the 5th percentile of σ_min.

    Parameters
    ----------
    maps : AliasingMaps
    cascades : int
        Number of cascades C: keys ``…_c0`` to ``…_c{C-1}`` are always present.

    Returns
    -------
    dict of str to float
        ``rho_median, rho_p05, rho_p95, rho_frac_lt1, rho_frac_lt05, sigma_min_p05`` over every
        pixel with a cascade, and each ρ key with suffix ``_c{i}`` over the pixels selecting
        cascade i. Percentiles are linear-interpolated (NumPy's default) in float64; a key is NaN
        when no pixel contributes to it.
    """
    # Each group's values by a mask of the image, the same values a mask of the selected pixels keeps, as they are
    # (float32): the percentiles interpolate the order statistics in float64 (linear_percentiles), which do not
    # depend on the values' order.
    cascade = maps.cascade
    per_cascade = [_rho_statistics(maps.rho[cascade == c]) for c in range(cascades)]
    selected = cascade >= 0
    out = _rho_statistics(maps.rho[selected])
    out["sigma_min_p05"] = float(linear_percentiles(maps.sigma_min[selected], (5.0,))[0])
    for c, per in enumerate(per_cascade):
        out.update({f"{key}_c{c}": value for key, value in per.items()})
    return out


def utilization(frame: Frame, *, device: str = "cpu") -> np.ndarray:
    """Fraction of each cascade's texels that some visible pixel selecting it looks up, ``(C,)`` float64.

    A pixel looks up the texel that contains its surface point (``floor`` of its texel
    coordinates from :func:`csmlab.texels.texel_coordinates`); the count of distinct such texels
    (:func:`csmlab.kernels.usage.looked_up_texels`) is divided by R². Points outside the R×R grid
    (impossible for a correct selection) are not counted.

    A virtual clipmap (:mod:`csmlab.clipmaps`) allocates only its resident pages: there the count of
    each level is divided by the texels of its resident pages (NaN for a level with none), not by
    the level's virtual R².
    """
    g = frame.view.gbuffer
    cascades = frame.maps.cascades
    if frame.maps.pages is not None:
        return _resident_utilization(frame)
    selected = np.where(g.valid, frame.shadow.cascade, -1).reshape(-1)
    sides = np.array([c.resolution for c in cascades.cascades])
    if cascades.warped:
        return _warped_utilization(g.position.reshape(-1, 3), selected, cascades)
    counts = looked_up_texels(g.position.reshape(-1, 3), selected, basis=cascades.basis,
                              texel_size=np.stack([c.texel_size for c in cascades.cascades]),
                              origin=np.stack([c.origin for c in cascades.cascades]), resolution=sides, device=device)
    return counts / (sides.astype(np.float64) ** 2)


def _resident_utilization(frame: Frame) -> np.ndarray:
    """:func:`utilization` of a virtual clipmap: distinct texels looked up per level over its resident texels,
    ``(L,)``."""
    g = frame.view.gbuffer
    pages = frame.maps.pages
    clip = pages.clipmap
    # The selected pixels by flat index (a boolean mask over 3 channels gathers on NumPy's slow path).
    rows = np.flatnonzero((np.where(g.valid, frame.shadow.cascade, -1) >= 0).reshape(-1))
    level = np.take(frame.shadow.cascade.reshape(-1), rows).astype(np.int64)
    xy = light_space(np.take(g.position.reshape(-1, 3), rows, axis=0), clip.basis)[:, :2]
    side = clip.pages_per_side * clip.page_size
    # Texels of the level's box: a point outside it (impossible for a correct choice) is not counted.
    local = np.floor(xy / clip.texel[level][:, None]).astype(np.int64) - clip.origin_page[level] * clip.page_size
    inside = np.flatnonzero(np.all((local >= 0) & (local < side), axis=1))
    level, local = level[inside], np.take(local, inside, axis=0)
    slot = pages.table[level, local[:, 1] // clip.page_size, local[:, 0] // clip.page_size].astype(np.int64)
    counts = _resident_texels(pages, slot, local) + _other_texels(clip, level, local, slot < 0)
    resident = np.bincount(pages.keys[:, 0], minlength=len(clip)).astype(np.float64) * clip.page_size ** 2
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(resident > 0, counts / resident, np.nan)


def _resident_texels(pages, slot: np.ndarray, local: np.ndarray) -> np.ndarray:
    """Distinct texels ``(L,)`` float64 of each level that the points in resident pages look up.

    ``slot`` ``(N,)``: each point's resident page (−1 for none, not counted here); ``local`` ``(N, 2)`` int64: its
    texel in its level's box. The texels are marked in a bitmap of the resident pages (3 MiB: 180 pages of 128² at
    Unreal's default, against 16k² virtual texels a level) and counted, not sorted out of the virtual texels
    (``np.unique``: 53 ms a frame there); a level's pages are consecutive in the page table's key order.
    """
    size = pages.clipmap.page_size
    resident = np.flatnonzero(slot >= 0)
    texel = np.take(local, resident, axis=0) % size
    marked = np.zeros((len(pages.keys), size * size), dtype=bool)
    marked[np.take(slot, resident), texel[:, 1] * size + texel[:, 0]] = True
    bounds = np.searchsorted(pages.keys[:, 0], np.arange(len(pages.clipmap) + 1))
    return np.array([np.count_nonzero(marked[bounds[k]:bounds[k + 1]]) for k in range(len(pages.clipmap))],
                    dtype=np.float64)


def _other_texels(clip, level: np.ndarray, local: np.ndarray, outside: np.ndarray) -> np.ndarray:
    """Distinct texels ``(L,)`` float64 of each level that the points outside the resident pages (``outside``
    ``(N,)`` bool) look up: none where every page a pixel looks up is resident, as the marking makes it."""
    side = clip.pages_per_side * clip.page_size
    level, local = level[outside], local[outside]
    looked = np.unique((level * side + local[:, 1]) * side + local[:, 0])
    return np.bincount(looked // (side * side), minlength=len(clip)).astype(np.float64)


def _warped_utilization(points: np.ndarray, selected: np.ndarray, cascades: CascadeSet) -> np.ndarray:
    """:func:`utilization` of cascades placed by homographies: each one's distinct texels looked up, on the host."""
    out = np.zeros(len(cascades), dtype=np.float64)
    for c, cascade in enumerate(cascades.cascades):
        # The cascade's points by flat index (a boolean mask over 3 channels gathers on NumPy's slow path): the
        # same rows in the same order.
        texel = np.floor(texel_coordinates(cascades, c, np.take(points, np.flatnonzero(selected == c), axis=0)))
        out[c] = _distinct_texels(texel, cascade.resolution) / float(cascade.resolution) ** 2
    return out


def _distinct_texels(texel: np.ndarray, resolution: int) -> int:
    """How many distinct texels of an ``resolution``² map the floored texel coordinates ``(N, 2)`` hold, those
    outside it not counted: marked in a bitmap of the map and counted, not sorted out (``np.unique``)."""
    inside = np.flatnonzero(np.all((texel >= 0) & (texel < resolution), axis=1))
    cells = np.take(texel, inside, axis=0).astype(np.int64)
    marked = np.zeros(resolution * resolution, dtype=bool)
    marked[cells[:, 1] * resolution + cells[:, 0]] = True
    return int(np.count_nonzero(marked))
