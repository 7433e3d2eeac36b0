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
- ꟻLIP: LDR-ꟻLIP on the sRGB-encoded shaded images (clipped to [0, 1]; frame t−1 is the
  reference, frame t the test), default viewing conditions (67.02 pixels per degree); the error map
  is averaged over the compared pixels. By one of :data:`FLIP_METHODS`: ``warp``
  (:func:`csmlab.kernels.flip.flip_error_map`, NVIDIA's C++ step for step in Warp kernels, the
  default) or ``flip-evaluator`` (NVIDIA's own ``flip_evaluator`` package, the oracle it is tested
  against); the two agree to float32 rounding of ``powf``.

Only where the two evaluations differ. ΔE2000 is a per-pixel function that is exactly 0 between
equal colours, and SSIM and ꟻLIP are local filters: a pixel whose whole filter support holds equal
values in both images has SSIM exactly 1 and ꟻLIP exactly 0. So each is computed only on
*windows* (:func:`changed_windows`) around the pixels whose S changed, each window grown by the
filter's support so that every value inside is what the whole image gives, and the maps are filled
with 1 (SSIM) or 0 (ꟻLIP) elsewhere; the summaries are then taken over the full maps exactly as
before. Where changes are many (:data:`WIDE_CHANGE`), or their windows cover much of the image
(:data:`SSIM_WHOLE_ABOVE`, :data:`FLIP_WHOLE_ABOVE`), the whole image is filtered instead, by Warp
kernels that skip, pixel by pixel, every pass out of a change's reach: SSIM by scikit-image's
operations (:func:`csmlab.kernels.ssim.ssim_where_changed`, bit for bit its map), ꟻLIP by
NVIDIA's (:func:`csmlab.kernels.flip.flip_reach`), whose windows skip the same way, and only the
colours they read are sRGB-encoded. A frame of ``exact`` changes in a few dozen pixels, so its
perceptual metrics cost a few windows instead of three full-image filters.

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
from csmlab.kernels.flip import flip_error_map, flip_filter_radii, flip_reach
from csmlab.kernels.flip_inputs import colours_read, encoded_pair, filled_differences
from csmlab.kernels.reach import grown_along
from csmlab.kernels.ssim import SSIM_RADIUS, SSIM_SIGMA, ssim_where_changed
from csmlab.metric_registry import finite_mean
from csmlab.metrics.shading import shaded_rgb_pair, view_shading_terms
from csmlab.registry import dispatch
from csmlab.srgb import srgb_encoded

__all__ = ["FLIP_METHODS", "FLIP_SUPPORT", "FLIP_WHOLE_ABOVE", "JND_CIEDE2000", "PerceptualMaps", "SSIM_SUPPORT",
           "SSIM_WHOLE_ABOVE", "WIDE_CHANGE", "changed_windows", "delta_e_2000", "flip_map", "lab_from_linear_srgb",
           "perceptual_maps", "perceptual_summary", "ssim_map"]

JND_CIEDE2000: float = 1.0
"""ΔE2000 of one just-noticeable difference. CIEDE2000 was fitted to threshold and small-difference
data scaled so that one unit is about one JND under reference viewing conditions (Luo, Cui, Rigg
2001); ΔE00 > 1 is the usual "visible" criterion (CIE 1976's ΔE*ab counterpart is 2.3,
``colour.difference.JND_CIE1976``)."""

_SRGB = colour.RGB_COLOURSPACES["sRGB"]
_SSIM_MIN_SIDE = 11

SSIM_SUPPORT: int = SSIM_RADIUS
"""Radius in pixels of scikit-image's Gaussian SSIM window (truncated at 3.5 σ: 11 × 11)."""

FLIP_SUPPORT: int = max(flip_filter_radii())
"""Radius in pixels over which an LDR-ꟻLIP error value depends on its inputs at 67.02 pixels per
degree: the colour pipeline's spatial filter reaches ``ceil(3·sqrt(0.04 / (2π²))·67.02) = 10`` pixels
and the feature pipeline's edge and point detectors ``ceil(3 · 0.5 · 0.082 · 67.02) = 9`` (Andersson
et al. 2020, sections 4.1 and 4.2)."""

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
    lit = np.where(g.valid, frame.shadow.lit, np.nan).astype(np.float32, copy=False)
    previous_lit = np.asarray(previous_lit, dtype=np.float32)
    if previous_lit.shape != lit.shape:
        raise ValueError(f"previous_lit: expected shape {lit.shape}, got {previous_lit.shape}")
    terms = view_shading_terms(frame.view)
    shaded, previous_shaded = shaded_rgb_pair(lit, previous_lit, terms=terms, ambient=ambient)
    compared = np.isfinite(lit) & np.isfinite(previous_lit)
    de2000 = np.where(compared, 0.0, np.nan)
    # Equal colours are 0 apart: the difference is computed only where S changed.
    changed = compared & (lit != previous_lit)
    # Both shadings' CIELAB in one colour-science call (a colour's conversion is its own, batched or not).
    index = np.flatnonzero(changed)
    lab = lab_from_linear_srgb(np.concatenate((_pixels_taken(shaded, index), _pixels_taken(previous_shaded, index))))
    de2000.reshape(-1)[index] = delta_e_2000(lab[:index.size], lab[index.size:])
    return PerceptualMaps(lit=lit, previous_lit=previous_lit, shaded=shaded, previous_shaded=previous_shaded,
                          de2000=de2000, compared=compared)


def _filled_pair(current: np.ndarray, previous: np.ndarray, compared: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Both images with every uncompared pixel set to the same value in each (current's, else 0)."""
    mask = compared if current.ndim == compared.ndim else compared[..., None]
    # nan_to_num's values (NaN → 0, ±inf → the largest finite) in fewer passes: the images hold NaN
    # where S is undefined but no infinity, which is looked for once.
    a = np.array(current, copy=True)
    np.copyto(a, 0.0, where=np.isnan(a))
    if np.isinf(a).any():
        a = np.nan_to_num(a)
    return a, np.where(mask, previous, a)


def changed_windows(changed, *, support: int) -> list[tuple[tuple[slice, slice], np.ndarray]]:
    """Windows on which a local filter of radius ``support`` must be evaluated where ``changed``.

    A pixel's value can differ from the no-change value only if a changed pixel lies within
    ``support`` of it (its *reach*). The reach is cut into bands of ``4·support`` rows; in each
    band, runs of columns holding reach pixels (split where more than ``2·support`` columns hold
    none) are boxed and each box grown by ``support`` more pixels (clipped to the image), so that
    every reach pixel's whole support lies inside its window — or beyond the image's edge, exactly
    as in the full image. Bands follow the shape of the changes, where one bounding box of a
    winding shadow edge would hold mostly unchanged pixels. Windows are merged when their union
    costs no more than the two apart, and when the windows add up to the image's area the image
    itself is the one window.

    Parameters
    ----------
    changed : array_like, shape (H, W), bool
        Pixels where the two images differ.
    support : int
        Filter radius in pixels (≥ 0).

    Returns
    -------
    list of ((slice, slice), ndarray)
        Per window: its rows and columns in the image, and a bool mask of the window's shape
        holding the reach pixels whose value the window gives exactly (each reach pixel in
        exactly one window).
    """
    changed = np.asarray(changed, dtype=bool)
    if not changed.any():
        return []
    height, width = changed.shape
    # The square window's maximum, one axis at a time (SciPy's maximum_filter, mode "constant", gives the same).
    reach = grown_along(grown_along(changed, support, 0), support, 1)
    band = max(4 * support, 1)
    # Boxes of reach pixels: [row0, row1, col0, col1) and the core they keep, [row0, row1, col0, col1).
    boxes = []
    for r0 in range(0, height, band):
        r1 = min(r0 + band, height)
        columns = np.flatnonzero(reach[r0:r1].any(axis=0))
        if columns.size == 0:
            continue
        rows = np.flatnonzero(reach[r0:r1, columns[0]:columns[-1] + 1].any(axis=1)) + r0
        breaks = np.flatnonzero(np.diff(columns) > 2 * support + 1)
        for first, last in zip(np.r_[0, breaks + 1], np.r_[breaks, columns.size - 1]):
            core = (int(rows[0]), int(rows[-1]) + 1, int(columns[first]), int(columns[last]) + 1)
            boxes.append([max(core[0] - support, 0), min(core[1] + support, height),
                          max(core[2] - support, 0), min(core[3] + support, width), [core]])
    merged = True
    while merged:
        merged = False
        for i in range(len(boxes)):
            for j in range(i + 1, len(boxes)):
                a, b = boxes[i], boxes[j]
                union = [min(a[0], b[0]), max(a[1], b[1]), min(a[2], b[2]), max(a[3], b[3])]
                if (union[1] - union[0]) * (union[3] - union[2]) <= _area(a) + _area(b):
                    boxes[i] = union + [a[4] + b[4]]
                    del boxes[j]
                    merged = True
                    break
            if merged:
                break
    if sum(_area(box) for box in boxes) >= height * width:
        # Windows that add up to the image cost more than the image (changes everywhere: `none`).
        return [((slice(0, height), slice(0, width)), reach)]
    windows = []
    for r0, r1, c0, c1, cores in boxes:
        keep = np.zeros((r1 - r0, c1 - c0), dtype=bool)
        for k0, k1, j0, j1 in cores:
            keep[k0 - r0:k1 - r0, j0 - c0:j1 - c0] = reach[k0:k1, j0:j1]
        windows.append(((slice(r0, r1), slice(c0, c1)), keep))
    return windows


def _area(box) -> int:
    return (box[1] - box[0]) * (box[3] - box[2])


def _windowed(evaluate, images: tuple, windows, *, shape: tuple[int, int], fill: float, dtype) -> np.ndarray:
    """``(H, W)``: ``fill`` everywhere except the kept pixels of each window, from ``evaluate(*crops)``."""
    out = np.full(shape, fill, dtype=dtype)
    for window, keep in windows:
        values = evaluate(*(image[window] for image in images))
        out[window][keep] = values[keep]
    return out


def _ssim_full(previous: np.ndarray, current: np.ndarray) -> np.ndarray:
    _, full = structural_similarity(previous, current, data_range=1.0, gaussian_weights=True, sigma=SSIM_SIGMA,
                                    use_sample_covariance=False, full=True)
    return full


def ssim_map(previous, current, *, changed=None, compared=None, device: str = "cpu") -> np.ndarray:
    """SSIM map ``(H, W)`` float64 of two shadow images (scikit-image, the settings of the module docstring).

    With ``changed`` (bool ``(H, W)``: where the two differ) it is computed only where a change
    reaches and is exactly 1 elsewhere — the same values as scikit-image gives for the whole image:
    on :func:`changed_windows` by scikit-image, or, for changes over more than :data:`WIDE_CHANGE`
    of the pixels or windows over more than :data:`SSIM_WHOLE_ABOVE` of the image, pixel by pixel
    over the whole image by
    :func:`csmlab.kernels.ssim.ssim_where_changed` (scikit-image's operations in Warp kernels on
    ``device``). Without, by scikit-image on the whole image. With ``compared`` (bool ``(H, W)``)
    every other pixel is first set to the same value in both images (``current``'s, else 0).
    Both images need sides of at least 11 pixels.
    """
    previous = np.asarray(previous, dtype=np.float64)
    current = np.asarray(current, dtype=np.float64)
    windows = None
    if changed is not None:
        windows = _windows_or_whole(changed, support=SSIM_SUPPORT, whole_above=SSIM_WHOLE_ABOVE)
        if windows is None:
            if compared is not None:
                current, previous = _filled_pair(current, previous, compared)
            return ssim_where_changed(previous, current, changed, device=device)
    images, evaluate = _with_compared((previous, current), compared, _ssim_full)
    if changed is None:
        return evaluate(*images)
    return _windowed(evaluate, images, windows, shape=current.shape, fill=1.0, dtype=np.float64)


WIDE_CHANGE: float = 0.005
"""Fraction of changed pixels above which :func:`ssim_map` and :func:`flip_map` (``warp``) filter
the whole image, skipping pixel by pixel what no change reaches, rather than
:func:`changed_windows`: the same values, and cheaper — on the default walk, ``none`` changes
about 1 % of its pixels a frame, whose windows cover 45 % (SSIM) and 70 % (ꟻLIP) of the image, in
dozens of windows costing more than the whole (SSIM's Warp kernels: 32 ms a frame where
scikit-image on the whole image took 66); ``exact`` changes under 0.03 %, whose few windows cost
less than one pass over the image (6 ms against 12)."""


SSIM_WHOLE_ABOVE: float = 0.04
"""Fraction of the image above which :func:`ssim_map`'s :func:`changed_windows` cost more than its
kernels over the whole image: on the default walk and the engines, a window costs ~55 ms per image
area (scikit-image filters every pixel of it), the kernels ~3.5 ms (they skip what no change
reaches); 0.10 of the image in windows took 6.5 ms, the kernels 3.4 (CPU, 640×360)."""

FLIP_WHOLE_ABOVE: float = 0.2
"""As :data:`SSIM_WHOLE_ABOVE`, for :func:`flip_map` (``warp``): windows ~2 ms + 52 ms per image
area, the whole image ~8.5 ms + what the changes reach; 0.24–0.27 of the image in windows cost about
as much as the whole (15.1 against 13.5 ms, 16.8 against 16.3), 0.43 took 25.2 ms against 19.4."""


def _windows_or_whole(changed, *, support: int, whole_above: float):
    """The :func:`changed_windows` of ``changed`` (bool ``(H, W)``), or None where the whole image costs
    less: changes over :data:`WIDE_CHANGE` of the pixels, or windows over ``whole_above`` of the image."""
    changed = np.asarray(changed, dtype=bool)
    if np.count_nonzero(changed) > WIDE_CHANGE * changed.size:
        return None
    windows = changed_windows(changed, support=support)
    area = sum((rows.stop - rows.start) * (columns.stop - columns.start) for (rows, columns), _ in windows)
    return None if area > whole_above * changed.size else windows


def _with_compared(images: tuple, compared, evaluate):
    """``images`` and ``evaluate(previous, current)``, or, with ``compared``, the mask as a third image
    and an ``evaluate`` that first fills the pair (:func:`_filled_pair`): crops of all three then
    give the crops of the filled pair, so only the windows are filled."""
    if compared is None:
        return images, evaluate

    def filled(previous, current, mask):
        current, previous = _filled_pair(current, previous, mask)
        return evaluate(previous, current)

    return (*images, np.asarray(compared, dtype=bool)), filled


def _flip_evaluator(reference: np.ndarray, test: np.ndarray) -> np.ndarray:
    """NVIDIA's ``flip_evaluator`` (C++, one call per image pair)."""
    error, _, _ = flip_evaluator.evaluate(reference, test, "LDR", applyMagma=False, computeMeanError=False)
    return np.asarray(error)[..., 0]


def _flip_warp(reference: np.ndarray, test: np.ndarray, *, device: str = "cpu", reach=None) -> np.ndarray:
    """:func:`csmlab.kernels.flip.flip_error_map` on a Warp device (``reach`` of the linear images, when known)."""
    return flip_error_map(reference, test, device=device, reach=reach)


FLIP_METHODS = {"warp": _flip_warp, "flip-evaluator": _flip_evaluator}
"""LDR-ꟻLIP implementations by name: each maps two sRGB float32 images ``(H, W, 3)`` in [0, 1]
(reference, test) to the error map ``(H, W)`` float32 at ꟻLIP's default 67.02 pixels per degree."""


def flip_map(reference, test, *, changed=None, compared=None, method: str = "warp", device: str = "cpu") -> np.ndarray:
    """LDR-ꟻLIP error map ``(H, W)`` float32 of two linear RGB images ``(H, W, 3)`` (sRGB-encoded, clipped, here).

    With ``changed`` (bool ``(H, W)``: where the images differ) it is computed on
    :func:`changed_windows` only, or on the whole image where the changes are wide (more than
    :data:`WIDE_CHANGE` of the pixels or windows over :data:`FLIP_WHOLE_ABOVE` of the image, with
    ``warp``), and is exactly 0 elsewhere — the same values
    as the whole image gives. With ``compared`` (bool ``(H, W)``) every other pixel is first set to
    the same value in both images (``test``'s, else 0). Only the colours ꟻLIP reads to evaluate a
    pixel that may differ are sRGB-encoded (:func:`csmlab.kernels.flip.flip_reach`). ``method``
    names one of :data:`FLIP_METHODS`; ``device`` is the Warp device of ``warp``, whose kernels
    skip, pixel by pixel, what lies out of a change's reach.
    """
    def encoded(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        reference, test, reach = _encoded_where_read(a, b)
        return dispatch(FLIP_METHODS, method, reference, test, field="flip method",
                        offered={"device": device, "reach": reach})

    reference = np.asarray(reference, dtype=np.float64)
    test = np.asarray(test, dtype=np.float64)
    windows = None
    if changed is not None:
        windows = (_windows_or_whole(changed, support=FLIP_SUPPORT, whole_above=FLIP_WHOLE_ABOVE)
                   if method == "warp" else changed_windows(changed, support=FLIP_SUPPORT))
    if windows is None:
        # The whole image: filled and encoded together, only at the pixels ꟻLIP reads.
        reference, test, reach = _encoded_where_read(reference, test, compared=compared)
        return dispatch(FLIP_METHODS, method, reference, test, field="flip method",
                        offered={"device": device, "reach": reach})
    images, evaluate = _with_compared((reference, test), compared, encoded)
    return _windowed(evaluate, images, windows, shape=images[1].shape[:2], fill=0.0, dtype=np.float32)


def _encoded_where_read(reference: np.ndarray, test: np.ndarray, *,
                        compared=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Both linear images ``(H, W, 3)`` sRGB-encoded as float32 where ꟻLIP reads them for a pixel
    that may differ, and 0 in both elsewhere: the same error map as both encoded whole. And the
    :func:`csmlab.kernels.flip.flip_reach` ``(H, W)`` uint8 of the linear images' differences, a
    superset of the encoded ones' (two colours may encode alike), so that ꟻLIP need not grow it again.

    With ``compared`` (bool ``(H, W)``), of the pair :func:`_filled_pair` makes (the test's
    ``nan_to_num``, and the reference's pixels only where compared): the same bits, but filled
    only at the pixels read, not over the whole image first (``none`` reads 45 % of them).
    """
    reference = np.ascontiguousarray(reference, dtype=np.float64)
    test = np.ascontiguousarray(test, dtype=np.float64)
    differs = filled_differences(reference, test, compared)
    reach = flip_reach(differs, radius=FLIP_SUPPORT)
    test_read, reference_read = colours_read(reference, test, reach, differs, fill=compared is not None)
    # Encoded by NumPy (its pow), the same compact arrays as ever; placed back by the kernel.
    reference_encoded, test_encoded = encoded_pair(reach, differs, srgb_encoded(test_read),
                                                   srgb_encoded(reference_read))
    return reference_encoded, test_encoded, reach


def _pixels_taken(image: np.ndarray, index: np.ndarray) -> np.ndarray:
    """``(N, 3)``: the pixels ``index`` (flat) of a C-contiguous ``(H, W, 3)`` image, each one element
    of a void view (NumPy gathers those in one pass; a row-wise fancy index takes 4× as long)."""
    pixels = image.reshape(-1).view(np.dtype((np.void, 3 * image.itemsize)))
    return np.take(pixels, index).view(image.dtype).reshape(-1, 3)


def perceptual_summary(maps: PerceptualMaps, *, device: str = "cpu") -> dict[str, float]:
    """ΔE2000 statistics, SSIM of the shadow images and mean ꟻLIP of the shaded images.

    ꟻLIP by the default of :data:`FLIP_METHODS` (``warp``) on the Warp ``device``.

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
    mean = finite_mean(de)
    # A count over N is the mean of the booleans, exactly.
    frac_jnd = np.count_nonzero(de > JND_CIEDE2000) / de.size
    # ``de`` is a copy: partitioned in place (after the sums, whose order it would change), not copied again.
    out = {
        "de2000_mean": mean,
        "de2000_p99": float(np.percentile(de, 99.0, overwrite_input=True)),
        "de2000_frac_jnd": frac_jnd,
    }
    # Filled (uncompared pixels equal in both), the images differ exactly where a compared pixel's S changed.
    changed = compared & (maps.lit != maps.previous_lit)
    if min(maps.lit.shape) >= _SSIM_MIN_SIDE:
        out["ssim"] = finite_mean(ssim_map(maps.previous_lit, maps.lit, changed=changed, compared=compared,
                                           device=device)[compared])
    else:
        out["ssim"] = float("nan")
    out["flip"] = finite_mean(flip_map(maps.previous_shaded, maps.shaded, changed=changed, compared=compared,
                                       device=device)[compared])
    return out
