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
    """:data:`RHO_SUMMARIES` of ``rho`` ``(N,)`` float64, a scratch copy: the percentiles partition it in place."""
    if rho.size == 0:
        return dict.fromkeys(RHO_SUMMARIES, float("nan"))
    # Counted before the partition reorders them; a count over N is the mean of the booleans, exactly.
    below_one = np.count_nonzero(rho < 1.0) / rho.size
    below_half = np.count_nonzero(rho < 0.5) / rho.size
    # Order statistics are the same values whatever order the partition leaves: no copy to partition.
    p05, median, p95 = np.percentile(rho, [5.0, 50.0, 95.0], overwrite_input=True)
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
    selected = maps.cascade >= 0
    # Converted to float64 once; each cascade's values are taken from it before the overall
    # statistics partition it in place.
    rho = maps.rho[selected].astype(np.float64)
    cascade = maps.cascade[selected]
    per_cascade = [_rho_statistics(rho[cascade == c]) for c in range(cascades)]
    out = _rho_statistics(rho)
    sigma = maps.sigma_min[selected].astype(np.float64)
    out["sigma_min_p05"] = float(np.percentile(sigma, 5.0, overwrite_input=True)) if sigma.size else float("nan")
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
    selected = np.where(g.valid, frame.shadow.cascade, -1)
    level = selected[selected >= 0].astype(np.int64)
    xy = light_space(g.position[selected >= 0], clip.basis)[:, :2]
    side = clip.pages_per_side * clip.page_size
    # Texels of the level's box: a point outside it (impossible for a correct choice) is not counted.
    local = np.floor(xy / clip.texel[level][:, None]).astype(np.int64) - clip.origin_page[level] * clip.page_size
    inside = np.all((local >= 0) & (local < side), axis=1)
    looked = np.unique((level[inside] * side + local[inside, 1]) * side + local[inside, 0])
    counts = np.bincount(looked // (side * side), minlength=len(clip)).astype(np.float64)
    resident = np.bincount(pages.keys[:, 0], minlength=len(clip)).astype(np.float64) * clip.page_size ** 2
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(resident > 0, counts / resident, np.nan)


def _warped_utilization(points: np.ndarray, selected: np.ndarray, cascades: CascadeSet) -> np.ndarray:
    """:func:`utilization` of cascades placed by homographies: each one's distinct texels looked up, on the host."""
    out = np.zeros(len(cascades), dtype=np.float64)
    for c, cascade in enumerate(cascades.cascades):
        texel = np.floor(texel_coordinates(cascades, c, points[selected == c]))
        inside = np.all((texel >= 0) & (texel < cascade.resolution), axis=1)
        cells = texel[inside].astype(np.int64)
        out[c] = np.unique(cells[:, 1] * cascade.resolution + cells[:, 0]).size / float(cascade.resolution) ** 2
    return out
