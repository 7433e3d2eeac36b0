"""Perceptual change between two shadow evaluations of the same frame: CIEDE2000, SSIM and ꟻLIP.

The two evaluations are frame t's shadow S_t and frame t−1's shadow S_{t−1} at frame t's visible
points (see :mod:`csmlab.metrics.temporal`). Both are shaded with frame t's albedo, normals and
light (:func:`csmlab.metrics.shading.shaded_rgb`), so that only the shadow differs. A pixel is
*compared* where it is visible and both S are defined; the others are filled with the same value
in both images (frame t's value where it has one, 0 elsewhere) so that they add no difference,
and are left out of every mean.

- ΔE2000: linear sRGB (D65) → CIE XYZ → CIELAB (D65 white) → CIEDE2000, all by colour-science.
  Mean, 99th percentile, and the fraction of compared pixels above :data:`JND_CIEDE2000`.
- SSIM: scikit-image's ``structural_similarity`` between the two shadow images S (not the shaded
  images: the shadow is what the method controls), ``data_range=1`` since S ∈ [0, 1], with the
  Gaussian window (σ = 1.5, 11×11) and population covariances of Wang et al.; the SSIM map is
  averaged over the compared pixels.
- ꟻLIP: NVIDIA's ``flip_evaluator`` in LDR mode on the sRGB-encoded shaded images (clipped to
  [0, 1]; frame t−1 is the reference, frame t the test), default viewing conditions (67 pixels per
  degree); the error map is averaged over the compared pixels.

References
----------
- Luo, Cui, Rigg, "The development of the CIE 2000 colour-difference formula: CIEDE2000",
  Color Research & Application 26(5), 2001.
- Sharma, Wu, Dalal, "The CIEDE2000 color-difference formula: implementation notes, supplementary
  test data, and mathematical observations", Color Research & Application 30(1), 2005.
- Wang, Bovik, Sheikh, Simoncelli, "Image quality assessment: from error visibility to structural
  similarity", IEEE TIP 13(4), 2004.
- Andersson et al., "ꟻLIP: A Difference Evaluator for Alternating Images", HPG 2020.
"""

from __future__ import annotations

from dataclasses import dataclass

import colour
import flip_evaluator
import numpy as np
from skimage.metrics import structural_similarity

from csmlab.frame import Frame
from csmlab.metric_registry import finite_mean
from csmlab.metrics.shading import shaded_rgb, srgb_encoded

__all__ = ["JND_CIEDE2000", "PerceptualMaps", "delta_e_2000", "lab_from_linear_srgb", "perceptual_maps",
           "perceptual_summary"]

JND_CIEDE2000: float = 1.0
"""ΔE2000 of one just-noticeable difference. CIEDE2000 was fitted to threshold and small-difference
data scaled so that one unit is about one JND under reference viewing conditions (Luo, Cui, Rigg
2001); ΔE00 > 1 is the usual "visible" criterion (CIE 1976's ΔE*ab counterpart is 2.3,
``colour.difference.JND_CIE1976``)."""

_SRGB = colour.RGB_COLOURSPACES["sRGB"]
_SSIM_SIGMA = 1.5
_SSIM_MIN_SIDE = 11


@dataclass(frozen=True)
class PerceptualMaps:
    """The two evaluations of one frame, shaded, and their per-pixel difference.

    Attributes
    ----------
    lit, previous_lit : ndarray, shape (H, W), float32
        S_t and S_{t−1} at frame t's points; NaN where undefined.
    shaded, previous_shaded : ndarray, shape (H, W, 3), float64
        Their linear RGB shading; NaN where the S is NaN.
    de2000 : ndarray, shape (H, W), float64
        CIEDE2000 between the two shadings; NaN where not compared.
    compared : ndarray, shape (H, W), bool
        Visible pixels where both S are defined.
    """

    lit: np.ndarray
    previous_lit: np.ndarray
    shaded: np.ndarray
    previous_shaded: np.ndarray
    de2000: np.ndarray
    compared: np.ndarray


def lab_from_linear_srgb(rgb) -> np.ndarray:
    """CIELAB ``(..., 3)`` (L* in [0, 100], D65 white) of linear sRGB ``(..., 3)`` (Y = 1 for white)."""
    xyz = colour.RGB_to_XYZ(np.asarray(rgb, dtype=np.float64), _SRGB, apply_cctf_decoding=False)
    return colour.XYZ_to_Lab(xyz, _SRGB.whitepoint)


def delta_e_2000(lab_a, lab_b) -> np.ndarray:
    """CIEDE2000 colour difference ``(...)`` of two CIELAB arrays ``(..., 3)``, by colour-science."""
    return np.asarray(colour.delta_E(np.asarray(lab_a, dtype=np.float64), np.asarray(lab_b, dtype=np.float64),
                                     method="CIE 2000"), dtype=np.float64)


def perceptual_maps(frame: Frame, previous_lit, *, ambient: float) -> PerceptualMaps:
    """Shade frame t's shadow and frame t−1's shadow at frame t's points, and their ΔE2000.

    Parameters
    ----------
    frame : Frame
        Frame t: its G-buffer albedo and normals, light direction and shadow S_t.
    previous_lit : array_like, shape (H, W)
        S_{t−1} at frame t's points (:attr:`TemporalMaps.previous_lit`); NaN where undefined.
    ambient : float
        Ambient term of the shading, in units of the direct light.

    Returns
    -------
    PerceptualMaps
    """
    g = frame.view.gbuffer
    lit = np.where(g.valid, frame.shadow.lit, np.nan).astype(np.float32)
    previous_lit = np.asarray(previous_lit, dtype=np.float32)
    if previous_lit.shape != lit.shape:
        raise ValueError(f"previous_lit: expected shape {lit.shape}, got {previous_lit.shape}")
    shade = dict(light_direction=frame.view.light_direction, ambient=ambient)
    shaded = shaded_rgb(g.albedo, g.normal, lit, **shade)
    previous_shaded = shaded_rgb(g.albedo, g.normal, previous_lit, **shade)
    compared = np.isfinite(lit) & np.isfinite(previous_lit)
    de2000 = np.full(lit.shape, np.nan)
    de2000[compared] = delta_e_2000(lab_from_linear_srgb(shaded[compared]),
                                    lab_from_linear_srgb(previous_shaded[compared]))
    return PerceptualMaps(lit=lit, previous_lit=previous_lit, shaded=shaded, previous_shaded=previous_shaded,
                          de2000=de2000, compared=compared)


def _filled_pair(current: np.ndarray, previous: np.ndarray, compared: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Both images with every uncompared pixel set to the same value in each (current's, else 0)."""
    mask = compared if current.ndim == compared.ndim else compared[..., None]
    a = np.nan_to_num(current, nan=0.0)
    return a, np.where(mask, previous, a)


def perceptual_summary(maps: PerceptualMaps) -> dict[str, float]:
    """ΔE2000 statistics, SSIM of the shadow images and mean ꟻLIP of the shaded images.

    Returns
    -------
    dict of str to float
        ``de2000_mean, de2000_p99, de2000_frac_jnd, ssim, flip`` over the compared pixels; NaN
        when no pixel is compared, and ``ssim`` NaN when the image is smaller than the 11×11 window.
    """
    compared = maps.compared
    if not np.any(compared):
        return dict.fromkeys(("de2000_mean", "de2000_p99", "de2000_frac_jnd", "ssim", "flip"), float("nan"))
    de = maps.de2000[compared]
    out = {
        "de2000_mean": finite_mean(de),
        "de2000_p99": float(np.percentile(de, 99.0)),
        "de2000_frac_jnd": finite_mean((de > JND_CIEDE2000).astype(np.float64)),
    }
    lit, previous_lit = _filled_pair(maps.lit.astype(np.float64), maps.previous_lit.astype(np.float64), compared)
    if min(lit.shape) >= _SSIM_MIN_SIDE:
        _, ssim_map = structural_similarity(previous_lit, lit, data_range=1.0, gaussian_weights=True,
                                            sigma=_SSIM_SIGMA, use_sample_covariance=False, full=True)
        out["ssim"] = finite_mean(ssim_map[compared])
    else:
        out["ssim"] = float("nan")
    shaded, previous_shaded = _filled_pair(maps.shaded, maps.previous_shaded, compared)
    error, _, _ = flip_evaluator.evaluate(
        np.ascontiguousarray(srgb_encoded(previous_shaded), dtype=np.float32),
        np.ascontiguousarray(srgb_encoded(shaded), dtype=np.float32),
        "LDR", applyMagma=False, computeMeanError=False,
    )
    out["flip"] = finite_mean(np.asarray(error)[..., 0][compared])
    return out
