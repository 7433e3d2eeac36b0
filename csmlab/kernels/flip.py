"""LDR-ꟻLIP error map of two sRGB images, operation for operation as NVIDIA's C++ ``FLIP.h``.

:func:`flip_error_map` follows ``FLIP::evaluate`` of the ``flip_evaluator`` package (version 1.7,
``src/cpp/FLIP.h`` and ``src/nanobindFLIP.cpp`` of github.com/NVlabs/flip) in LDR mode with sRGB
inputs, each step a small kernel over both images at once (index 0 the reference, 1 the test):

1. ``ycxcz_kernel`` — sRGB → linear RGB (``nanobindFLIP.cpp``), clamp to [0, 1], → XYZ (D65) →
   YCxCz (``LinearRGBToYCxCz``).
2. ``spatial_rows_kernel``, ``spatial_columns_kernel`` — the contrast sensitivity filters of the
   three opponent channels, separated (``setSpatialFilters``: Y and Cx one Gaussian each, Cz the
   sum of two Gaussians split into two separable parts whose results add); then YCxCz → XYZ →
   linear RGB clamped to [0, 1] → CIELAB → Hunt-adjusted a*, b* (``computeColorDifference``).
3. ``color_difference_kernel`` — HyAB distance, raised to ``qc = 0.7`` and redistributed so that
   ``pc · cmax`` maps to ``pt = 0.95`` (``cmax`` the distance between green and blue).
4. ``feature_rows_kernel``, ``feature_columns_kernel`` — first and second derivatives of a
   Gaussian of σ = 0.5 · 0.082 · ppd pixels on the normalised achromatic channel: edge and point
   strengths (``setFeatureFilter``, ``computeFeatureDifferenceAndFinalError``).
5. ``flip_error_kernel`` — feature difference ``(max(|Δedge|, |Δpoint|) / √2)^qf``, ``qf = 0.5``,
   and the error ``colour difference^(1 − feature difference)``.

Every convolution clamps its taps to the image's edge and sums them in the C++ order (taps from
−r to r, rows first), all in float32 with the C++ constants rounded as the compiler rounds them and
floating-point contraction off (``fuse_fp``), so the result differs from the C++ only where the
two libms' ``powf``/``expf`` do (a few float32 ulps). The filter weights and ``cmax`` are computed
once per (ppd, device) by ``filter_weights_kernel`` with the same functions.

References
----------
- Andersson, Nilsson, Akenine-Möller, Oskarsson, Åström, Fairchild, "ꟻLIP: A Difference Evaluator
  for Alternating Images", Proc. ACM Comput. Graph. Interact. Tech. 3(2) (HPG 2020).
- NVlabs/flip, ``misc/separatedConvolutions.pdf`` — the separated spatial and feature filters.
"""

from __future__ import annotations

import functools

import numpy as np
import warp as wp

from csmlab.kernels import checked_device

__all__ = ["FLIP_DEFAULT_PPD", "flip_error_map", "flip_filter_radii"]

# The C++ multiplies and adds separately; an FMA would round differently.
wp.set_module_options({"fuse_fp": False})

_F = np.float32
_PI = _F(3.14159265358979)

FLIP_DEFAULT_PPD: float = float(_F(0.7) * (_F(3840.0) / _F(0.7)) * (_PI / _F(180.0)))
"""ꟻLIP's default pixels per degree, 67.02…: a 0.7 m wide 3840-pixel monitor seen from 0.7 m,
computed in float32 as ``FLIP::calculatePPD`` does (the value ``flip_evaluator`` uses by default)."""


def _constant(value) -> wp.constant:
    return wp.constant(wp.float32(float(_F(value))))


# FLIPConstants and the colour-space constants, each rounded to float32 as its C++ literal is.
QC = _constant(0.7)
PC = _constant(0.4)
PT = _constant(0.95)
QF = _constant(0.5)
_DELTA = _F(6.0) / _F(29.0)
LAB_DELTA_CUBE = _constant(_DELTA * (_DELTA * _DELTA))
LAB_FACTOR = _constant(_F(1.0) / (_F(3.0) * (_DELTA * _DELTA)))
LAB_TERM = _constant(_F(4.0) / _F(29.0))
ONE_THIRD = _constant(_F(1.0) / _F(3.0))
INV_WHITE = wp.constant(wp.vec3(1.052156925, 1.000000000, 0.918357670))
WHITE = wp.constant(wp.vec3(0.950428545, 1.000000000, 1.088900371))
RGB_TO_XYZ = wp.constant(wp.mat33(
    float(_F(10135552.0) / _F(24577794.0)), float(_F(8788810.0) / _F(24577794.0)),
    float(_F(4435075.0) / _F(24577794.0)),
    float(_F(2613072.0) / _F(12288897.0)), float(_F(8788810.0) / _F(12288897.0)),
    float(_F(887015.0) / _F(12288897.0)),
    float(_F(1425312.0) / _F(73733382.0)), float(_F(8788810.0) / _F(73733382.0)),
    float(_F(70074185.0) / _F(73733382.0)),
))
XYZ_TO_RGB = wp.constant(wp.mat33(
    3.241003275, -1.537398934, -0.498615861,
    -0.969224334, 1.875930071, 0.041554224,
    0.055639423, -0.204011202, 1.057148933,
))
ONE_OVER_116 = _constant(_F(1.0) / _F(116.0))
SIXTEEN_OVER_116 = _constant(_F(16.0) / _F(116.0))
INV_SQRT2 = _constant(_F(1.0) / np.sqrt(_F(2.0)))
PI = _constant(_PI)
PI_SQ = _constant(_PI * _PI)
# GaussianConstants: a1, b1 for Y, Cx and the first Cz Gaussian; a2, b2 for the second Cz Gaussian.
A1 = wp.constant(wp.vec3(1.0, 1.0, 34.1))
B1 = wp.constant(wp.vec3(0.0047, 0.0053, 0.04))
A2_Z = _constant(13.5)
B2_Z = _constant(0.025)
_B_MAX = max(_F(v) for v in (0.0047, 0.0053, 0.04, 1.0e-5, 1.0e-5, 0.025))
_FEATURE_WIDTH = _F(0.082)


def flip_filter_radii(*, pixels_per_degree: float = FLIP_DEFAULT_PPD) -> tuple[int, int]:
    """Radii in pixels of ꟻLIP's spatial (CSF) filter and of its feature (edge/point) filters.

    ``ceil(3 · sqrt(max b / (2π²)) · ppd)`` and ``ceil(3 · 0.5 · 0.082 · ppd)`` in float32, as
    ``calculateSpatialFilterRadius`` and ``LDR_FLIP`` compute them: (10, 9) at the default ppd.
    """
    ppd = _F(pixels_per_degree)
    spatial = int(np.ceil(_F(3.0) * np.sqrt(_B_MAX / (_F(2.0) * (_PI * _PI))) * ppd))
    feature = int(np.ceil(_F(3.0) * (_F(0.5) * _FEATURE_WIDTH * ppd)))
    return spatial, feature


@wp.func
def linear_from_srgb(c: float) -> float:
    """``color3::sRGBToLinearRGB`` of one channel."""
    if c <= 0.04045:
        return c / 12.92
    return wp.pow((c + 0.055) / 1.055, 2.4)


@wp.func
def clamp01(c: wp.vec3) -> wp.vec3:
    """``color3::clamp``: ``Min(Max(c, 0), 1)`` per channel."""
    return wp.vec3(wp.min(wp.max(c[0], 0.0), 1.0), wp.min(wp.max(c[1], 0.0), 1.0), wp.min(wp.max(c[2], 0.0), 1.0))


@wp.func
def apply3(m: wp.mat33, c: wp.vec3) -> wp.vec3:
    """``m · c`` with each row summed left to right, as the C++ writes it."""
    return wp.vec3(m[0, 0] * c[0] + m[0, 1] * c[1] + m[0, 2] * c[2],
                   m[1, 0] * c[0] + m[1, 1] * c[1] + m[1, 2] * c[2],
                   m[2, 0] * c[0] + m[2, 1] * c[1] + m[2, 2] * c[2])


@wp.func
def ycxcz_from_xyz(xyz: wp.vec3) -> wp.vec3:
    """``color3::XYZToYCxCz`` (D65)."""
    v = wp.cw_mul(xyz, INV_WHITE)
    return wp.vec3(116.0 * v[1] - 16.0, 500.0 * (v[0] - v[1]), 200.0 * (v[1] - v[2]))


@wp.func
def xyz_from_ycxcz(c: wp.vec3) -> wp.vec3:
    """``color3::YCxCzToXYZ`` (D65)."""
    y = (c[0] + 16.0) / 116.0
    cx = c[1] / 500.0
    cz = c[2] / 200.0
    return wp.cw_mul(wp.vec3(y + cx, y, y - cz), WHITE)


@wp.func
def lab_f(t: float) -> float:
    if t > LAB_DELTA_CUBE:
        return wp.pow(t, ONE_THIRD)
    return LAB_FACTOR * t + LAB_TERM


@wp.func
def lab_from_xyz(xyz: wp.vec3) -> wp.vec3:
    """``color3::XYZToCIELab`` (D65)."""
    v = wp.cw_mul(xyz, INV_WHITE)
    fx = lab_f(v[0])
    fy = lab_f(v[1])
    fz = lab_f(v[2])
    return wp.vec3(116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz))


@wp.func
def hunt_adjusted(lab: wp.vec3) -> wp.vec3:
    """``color3::Hunt`` on a* and b*: ``0.01 · L* · c``."""
    return wp.vec3(lab[0], 0.01 * lab[0] * lab[1], 0.01 * lab[0] * lab[2])


@wp.func
def hyab(a: wp.vec3, b: wp.vec3) -> float:
    """``color3::HyAB``: city-block in L*, Euclidean in (a*, b*)."""
    return wp.abs(a[0] - b[0]) + wp.sqrt((a[1] - b[1]) * (a[1] - b[1]) + (a[2] - b[2]) * (a[2] - b[2]))


@wp.func
def gaussian(x2: float, a: float, b: float) -> float:
    """The CSF Gaussian ``a · sqrt(π / b) · exp(−π² x² / b)``."""
    return a * wp.sqrt(PI / b) * wp.exp(-PI_SQ * x2 / b)


@wp.func
def gaussian_sqrt(x2: float, a: float, b: float) -> float:
    """``GaussianSqrt``: one separable factor of a Cz Gaussian, ``sqrt(a · sqrt(π / b)) · exp(−π² x² / b)``."""
    return wp.sqrt(a * wp.sqrt(PI / b)) * wp.exp(-PI_SQ * x2 / b)


@wp.kernel
def filter_weights_kernel(
    pixels_per_degree: float,
    spatial_radius: int,
    feature_radius: int,
    spatial: wp.array(dtype=wp.vec4),
    feature: wp.array(dtype=wp.vec3),
    cmax: wp.array(dtype=float),
):
    # One thread: the weights are normalised by sums taken in tap order.
    delta_x = 1.0 / pixels_per_degree
    sum_ycx = wp.vec2(0.0)
    sum_cz = wp.vec2(0.0)
    for x in range(2 * spatial_radius + 1):
        ix = float(x - spatial_radius) * delta_x
        ix2 = ix * ix
        w = wp.vec4(gaussian(ix2, A1[0], B1[0]), gaussian(ix2, A1[1], B1[1]),
                    gaussian_sqrt(ix2, A1[2], B1[2]), gaussian_sqrt(ix2, A2_Z, B2_Z))
        spatial[x] = w
        sum_ycx = wp.vec2(sum_ycx[0] + w[0], sum_ycx[1] + w[1])
        sum_cz = wp.vec2(sum_cz[0] + w[2], sum_cz[1] + w[3])
    norm_y = 1.0 / sum_ycx[0]
    norm_cx = 1.0 / sum_ycx[1]
    norm_cz = 1.0 / wp.sqrt(sum_cz[0] * sum_cz[0] + sum_cz[1] * sum_cz[1])
    for x in range(2 * spatial_radius + 1):
        w = spatial[x]
        spatial[x] = wp.vec4(w[0] * norm_y, w[1] * norm_cx, w[2] * norm_cz, w[3] * norm_cz)

    std_dev = 0.5 * 0.082 * pixels_per_degree
    g_sum = float(0.0)
    dg_negative = float(0.0)
    dg_positive = float(0.0)
    ddg_negative = float(0.0)
    ddg_positive = float(0.0)
    for x in range(2 * feature_radius + 1):
        xx = float(x - feature_radius)
        g = wp.exp(-(xx * xx) / (2.0 * std_dev * std_dev))
        g_sum += g
        dg = -xx * g
        if dg > 0.0:
            dg_positive += dg
        else:
            dg_negative -= dg
        ddg = (xx * xx / (std_dev * std_dev) - 1.0) * g
        if ddg > 0.0:
            ddg_positive += ddg
        else:
            ddg_negative -= ddg
        feature[x] = wp.vec3(g, dg, ddg)
    for x in range(2 * feature_radius + 1):
        p = feature[x]
        dg_sum = dg_negative
        if p[1] > 0.0:
            dg_sum = dg_positive
        ddg_sum = ddg_negative
        if p[2] > 0.0:
            ddg_sum = ddg_positive
        feature[x] = wp.vec3(p[0] / g_sum, p[1] / dg_sum, p[2] / ddg_sum)

    # computeMaxDistance: HyAB between Hunt-adjusted green and blue, raised to qc.
    green = hunt_adjusted(lab_from_xyz(apply3(RGB_TO_XYZ, wp.vec3(0.0, 1.0, 0.0))))
    blue = hunt_adjusted(lab_from_xyz(apply3(RGB_TO_XYZ, wp.vec3(0.0, 0.0, 1.0))))
    cmax[0] = wp.pow(hyab(green, blue), QC)


@wp.kernel
def ycxcz_kernel(srgb: wp.array3d(dtype=wp.vec3), ycxcz: wp.array3d(dtype=wp.vec3)):
    k, i, j = wp.tid()
    c = srgb[k, i, j]
    linear = clamp01(wp.vec3(linear_from_srgb(c[0]), linear_from_srgb(c[1]), linear_from_srgb(c[2])))
    ycxcz[k, i, j] = ycxcz_from_xyz(apply3(RGB_TO_XYZ, linear))


@wp.kernel
def spatial_rows_kernel(
    ycxcz: wp.array3d(dtype=wp.vec3),
    weights: wp.array(dtype=wp.vec4),
    radius: int,
    rows: wp.array3d(dtype=wp.vec4),
):
    k, i, j = wp.tid()
    last = ycxcz.shape[2] - 1
    y = float(0.0)
    cx = float(0.0)
    cz1 = float(0.0)
    cz2 = float(0.0)
    for t in range(-radius, radius + 1):
        c = ycxcz[k, i, wp.min(wp.max(0, j + t), last)]
        w = weights[t + radius]
        y += w[0] * c[0]
        cx += w[1] * c[1]
        cz1 += w[2] * c[2]
        cz2 += w[3] * c[2]
    rows[k, i, j] = wp.vec4(y, cx, cz1, cz2)


@wp.kernel
def spatial_columns_kernel(
    rows: wp.array3d(dtype=wp.vec4),
    weights: wp.array(dtype=wp.vec4),
    radius: int,
    lab: wp.array3d(dtype=wp.vec3),
):
    k, i, j = wp.tid()
    last = rows.shape[1] - 1
    y = float(0.0)
    cx = float(0.0)
    cz1 = float(0.0)
    cz2 = float(0.0)
    for t in range(-radius, radius + 1):
        r = rows[k, wp.min(wp.max(0, i + t), last), j]
        w = weights[t + radius]
        y += w[0] * r[0]
        cx += w[1] * r[1]
        cz1 += w[2] * r[2]
        cz2 += w[3] * r[3]
    linear = clamp01(apply3(XYZ_TO_RGB, xyz_from_ycxcz(wp.vec3(y, cx, cz1 + cz2))))
    lab[k, i, j] = hunt_adjusted(lab_from_xyz(apply3(RGB_TO_XYZ, linear)))


@wp.kernel
def color_difference_kernel(lab: wp.array3d(dtype=wp.vec3), cmax: wp.array(dtype=float),
                            difference: wp.array2d(dtype=float)):
    i, j = wp.tid()
    c = cmax[0]
    pccmax = PC * c
    d = wp.pow(hyab(lab[0, i, j], lab[1, i, j]), QC)
    # Differences below pc·cmax fill [0, pt]; the rest (pt, 1].
    if d < pccmax:
        d = d * (PT / pccmax)
    else:
        d = PT + ((d - pccmax) / (c - pccmax)) * (1.0 - PT)
    difference[i, j] = d


@wp.kernel
def feature_rows_kernel(
    ycxcz: wp.array3d(dtype=wp.vec3),
    weights: wp.array(dtype=wp.vec3),
    radius: int,
    rows: wp.array3d(dtype=wp.vec3),
):
    k, i, j = wp.tid()
    last = ycxcz.shape[2] - 1
    dx = float(0.0)
    ddx = float(0.0)
    g = float(0.0)
    for t in range(-radius, radius + 1):
        # The achromatic channel normalised to [0, 1].
        y = ycxcz[k, i, wp.min(wp.max(0, j + t), last)][0] * ONE_OVER_116 + SIXTEEN_OVER_116
        w = weights[t + radius]
        dx += w[1] * y
        ddx += w[2] * y
        g += w[0] * y
    rows[k, i, j] = wp.vec3(dx, ddx, g)


@wp.kernel
def feature_columns_kernel(
    rows: wp.array3d(dtype=wp.vec3),
    weights: wp.array(dtype=wp.vec3),
    radius: int,
    features: wp.array3d(dtype=wp.vec2),
):
    k, i, j = wp.tid()
    last = rows.shape[1] - 1
    dx = float(0.0)
    ddx = float(0.0)
    dy = float(0.0)
    ddy = float(0.0)
    for t in range(-radius, radius + 1):
        r = rows[k, wp.min(wp.max(0, i + t), last), j]
        w = weights[t + radius]
        dx += w[0] * r[0]
        ddx += w[0] * r[1]
        dy += w[1] * r[2]
        ddy += w[2] * r[2]
    features[k, i, j] = wp.vec2(wp.sqrt(dx * dx + dy * dy), wp.sqrt(ddx * ddx + ddy * ddy))


@wp.kernel
def flip_error_kernel(features: wp.array3d(dtype=wp.vec2), difference: wp.array2d(dtype=float),
                      error: wp.array2d(dtype=float)):
    i, j = wp.tid()
    reference = features[0, i, j]
    test = features[1, i, j]
    edge = wp.abs(reference[0] - test[0])
    point = wp.abs(reference[1] - test[1])
    feature = wp.pow(INV_SQRT2 * wp.max(edge, point), QF)
    error[i, j] = wp.pow(difference[i, j], 1.0 - feature)


@functools.lru_cache(maxsize=8)
def _filters(pixels_per_degree: float, device: str) -> tuple[int, int, wp.array, wp.array, wp.array]:
    """Spatial and feature radii, their weights and cmax on ``device`` (computed once per ppd)."""
    spatial_radius, feature_radius = flip_filter_radii(pixels_per_degree=pixels_per_degree)
    spatial = wp.empty(2 * spatial_radius + 1, dtype=wp.vec4, device=device)
    feature = wp.empty(2 * feature_radius + 1, dtype=wp.vec3, device=device)
    cmax = wp.empty(1, dtype=float, device=device)
    wp.launch(filter_weights_kernel, dim=1, inputs=(pixels_per_degree, spatial_radius, feature_radius),
              outputs=(spatial, feature, cmax), device=device)
    return spatial_radius, feature_radius, spatial, feature, cmax


def _checked_image(name: str, image) -> np.ndarray:
    array = np.asarray(image)
    if array.ndim != 3 or array.shape[2] != 3 or array.shape[0] < 1 or array.shape[1] < 1:
        raise ValueError(f"{name}: expected an (H, W, 3) sRGB image, got shape {array.shape}")
    array = array.astype(np.float32)
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name}: expected finite values, got NaN or infinity")
    if array.min() < 0.0 or array.max() > 1.0:
        raise ValueError(f"{name}: expected sRGB values in [0, 1], got [{array.min()}, {array.max()}]")
    return array


def flip_error_map(reference, test, *, pixels_per_degree: float = FLIP_DEFAULT_PPD,
                   device: str = "cpu") -> np.ndarray:
    """LDR-ꟻLIP error of ``test`` against ``reference``, per pixel, as ``flip_evaluator`` computes it.

    Parameters
    ----------
    reference, test : array_like, shape (H, W, 3)
        sRGB-encoded display values in [0, 1] (converted to float32).
    pixels_per_degree : float
        Viewing condition: image pixels per degree of visual angle (> 0). The default is
        ꟻLIP's own, :data:`FLIP_DEFAULT_PPD` ≈ 67.02.
    device : str
        Warp device, ``"cpu"`` or ``"cuda"``.

    Returns
    -------
    ndarray, shape (H, W), float32
        The error in [0, 1]; exactly 0 where the two images agree over the filters' support
        (:func:`flip_filter_radii`). Near the edges the filters clamp to the edge pixel.

    Raises
    ------
    ValueError
        On a shape other than (H, W, 3), differing shapes, values outside [0, 1] or not finite,
        a non-positive ``pixels_per_degree``, or an unusable device.
    """
    device = checked_device(device)
    reference = _checked_image("reference", reference)
    test = _checked_image("test", test)
    if test.shape != reference.shape:
        raise ValueError(f"test: expected the reference's shape {reference.shape}, got {test.shape}")
    ppd = float(_F(pixels_per_degree))
    if not (np.isfinite(ppd) and ppd > 0.0):
        raise ValueError(f"pixels_per_degree: expected a finite value > 0, got {pixels_per_degree!r}")
    spatial_radius, feature_radius, spatial, feature, cmax = _filters(ppd, device)
    height, width = reference.shape[:2]
    pair = (2, height, width)
    srgb = wp.array(np.stack((reference, test)), dtype=wp.vec3, device=device)
    ycxcz = wp.empty(pair, dtype=wp.vec3, device=device)
    wp.launch(ycxcz_kernel, dim=pair, inputs=(srgb,), outputs=(ycxcz,), device=device)

    spatial_rows = wp.empty(pair, dtype=wp.vec4, device=device)
    lab = wp.empty(pair, dtype=wp.vec3, device=device)
    difference = wp.empty((height, width), dtype=float, device=device)
    wp.launch(spatial_rows_kernel, dim=pair, inputs=(ycxcz, spatial, spatial_radius), outputs=(spatial_rows,),
              device=device)
    wp.launch(spatial_columns_kernel, dim=pair, inputs=(spatial_rows, spatial, spatial_radius), outputs=(lab,),
              device=device)
    wp.launch(color_difference_kernel, dim=(height, width), inputs=(lab, cmax), outputs=(difference,), device=device)

    feature_rows = wp.empty(pair, dtype=wp.vec3, device=device)
    features = wp.empty(pair, dtype=wp.vec2, device=device)
    error = wp.empty((height, width), dtype=float, device=device)
    wp.launch(feature_rows_kernel, dim=pair, inputs=(ycxcz, feature, feature_radius), outputs=(feature_rows,),
              device=device)
    wp.launch(feature_columns_kernel, dim=pair, inputs=(feature_rows, feature, feature_radius),
              outputs=(features,), device=device)
    wp.launch(flip_error_kernel, dim=(height, width), inputs=(features, difference), outputs=(error,), device=device)
    return error.numpy()
