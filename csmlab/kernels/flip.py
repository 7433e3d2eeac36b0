"""LDR-ꟻLIP error map of two sRGB images, operation for operation as NVIDIA's C++ ``FLIP.h``.

:func:`flip_error_map` follows ``FLIP::evaluate`` of the ``flip_evaluator`` package (version 1.7,
``src/cpp/FLIP.h`` and ``src/nanobindFLIP.cpp`` of github.com/NVlabs/flip) in LDR mode with sRGB
inputs, in three kernels, each over both images at once where they are filtered alike:

1. ``ycxcz_kernel`` (index 0 the reference, 1 the test) — sRGB → linear RGB
   (``nanobindFLIP.cpp``), clamp to [0, 1], → XYZ (D65) → YCxCz (``LinearRGBToYCxCz``), and the
   achromatic channel normalised to [0, 1] that the feature filters read.
2. ``rows_kernel`` — the row pass of the separated filters: the contrast sensitivity filters of
   the three opponent channels (``setSpatialFilters``: Y and Cx one Gaussian each, Cz the sum of
   two Gaussians split into two separable parts whose results add) and the first and second
   derivatives of a Gaussian of σ = 0.5 · 0.082 · ppd pixels (``setFeatureFilter``).
3. ``columns_kernel`` — the column pass, then per pixel: YCxCz → XYZ → linear RGB clamped to
   [0, 1] → CIELAB → Hunt-adjusted a*, b* (``computeColorDifference``); the HyAB distance raised
   to ``qc = 0.7`` and redistributed so that ``pc · cmax`` maps to ``pt = 0.95`` (``cmax`` the
   distance between green and blue); edge and point strengths, the feature difference
   ``(max(|Δedge|, |Δpoint|) / √2)^qf``, ``qf = 0.5`` (``computeFeatureDifferenceAndFinalError``);
   and the error ``colour difference^(1 − feature difference)``.

On the CPU a thread takes a row, and the row and column passes add the taps of eight and four
neighbouring pixels at once in vectors of 16 floats (:func:`rows_block`, :func:`column_sums_block`,
native code clang vectorizes), each sum in tap order as a pixel at a time adds it: the same bits.

The passes skip what no difference between the images reaches (:func:`flip_reach`): the test
image's colours and row pass are the reference's wherever its inputs are, a pass nothing reads is
not computed, and the error is exactly 0 where the two agree over the whole support — the values
the full computation gives, bit for bit, at a fraction of its cost when few pixels changed.

Every convolution clamps its taps to the image's edge and sums them in the C++ order (taps from
−r to r, rows first), all in float32 with the C++ constants rounded as the compiler rounds them and
floating-point contraction off (``fuse_fp``), and ``exp`` and ``pow`` are the C library's
(:func:`libm_exp`, :func:`libm_pow`): on the CPU the map is the C++'s to within a few float32 ulps
(5.6e-09 on a rendered frame). On CUDA, whose float32 ``expf`` and ``powf`` are not correctly
rounded, the two are evaluated in float64 and rounded once, the value the CPU's C library gives on
all but ~0.06 % of inputs. The filter weights and
``cmax`` are computed once per (ppd, device) by ``filter_weights_kernel`` with the same functions.

References
----------
- Andersson, Nilsson, Akenine-Möller, Oskarsson, Åström, Fairchild, "ꟻLIP: A Difference Evaluator
  for Alternating Images", Proc. ACM Comput. Graph. Interact. Tech. 3(2) (HPG 2020).
- NVlabs/flip, ``misc/separatedConvolutions.pdf`` — the separated spatial and feature filters.
"""

from __future__ import annotations

import functools
import threading

import numpy as np
import warp as wp

from csmlab.kernels import checked_device
from csmlab.kernels.reach import nested_reach

__all__ = ["FLIP_DEFAULT_PPD", "flip_error_map", "flip_filter_radii", "flip_reach", "pixels_differ"]

# The C++ multiplies and adds separately; an FMA would round differently.
wp.set_module_options({"fuse_fp": False, "optimization_level": 3})

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


# Levels of :func:`flip_reach`, each pixel's nearness to a pixel where the two images differ.
READ_BY_ROWS = wp.constant(1)
READ_BY_COLUMNS = wp.constant(2)
MAY_DIFFER = wp.constant(3)
ROWS_DIFFER = wp.constant(4)
DIFFERS = wp.constant(5)


def pixels_differ(reference, test) -> np.ndarray:
    """``(H, W)`` bool: where two images ``(H, W, 3)`` differ in any channel."""
    unequal = np.asarray(reference) != np.asarray(test)
    return unequal[..., 0] | unequal[..., 1] | unequal[..., 2]


def flip_reach(differs, *, radius: int) -> np.ndarray:
    """How near each pixel lies to one where the two images differ, as the three passes need to know.

    The passes clamp their taps to the image, so a pixel's values depend only on pixels within
    ``radius`` of it, inside the image. Each level is the previous one grown by ``radius`` along
    the axis its pass filters, so they nest, and a pixel holds the number of them it lies in:

    - 5 (``DIFFERS``): the pixels differ;
    - 4 (``ROWS_DIFFER``): within ``radius`` columns of one that differs — the row pass differs;
    - 3 (``MAY_DIFFER``): within ``radius`` rows of level 4 — the error may be nonzero;
    - 2 (``READ_BY_COLUMNS``): within ``radius`` rows of level 3 — the column pass reads its row pass;
    - 1 (``READ_BY_ROWS``): within ``radius`` columns of level 2 — the row pass reads its colour;
    - 0: nothing computed reads it; its error is 0.

    Parameters
    ----------
    differs : array_like, shape (H, W), bool
        Pixels where the reference and the test differ.
    radius : int
        The widest filter's radius in pixels (:func:`flip_filter_radii`).

    Returns
    -------
    ndarray, shape (H, W), uint8
    """
    return nested_reach(differs, int(radius), (1, 0, 0, 1))


# CUDA's float32 expf and powf are not correctly rounded (an H200: wp.exp up to 1.83 ulp off and
# wrong on 30 % of inputs, wp.pow up to 0.87 ulp and 5.9 %), and ꟻLIP's powers amplify an ulp
# (a 640×360 rendered frame: 9.9e-05 from flip_evaluator). On CUDA these evaluate in float64 and
# round once: the correctly rounded value (an H200's float64 exp and pow rounded to float32 equalled
# NumPy's on 20M inputs), which is also what the CPU's C library gives on all but ~0.06 % of inputs
# (glibc, within 0.502 ulp). On the CPU they stay the C library's expf and powf: flip_evaluator's
# own, so the CPU follows the C++ bit for bit at no cost (float64 there cost 25 % of the kernel).
_LIBM_EXP = """
#if defined(__CUDA_ARCH__)
    return static_cast<float>(wp::exp(static_cast<double>(x)));
#else
    return wp::exp(x);
#endif
"""

_LIBM_POW = """
#if defined(__CUDA_ARCH__)
    return static_cast<float>(wp::pow(static_cast<double>(x), static_cast<double>(y)));
#else
    return wp::pow(x, y);
#endif
"""


@wp.func_native(_LIBM_EXP)
def libm_exp(x: float) -> float:
    """``e^x`` in float32 as the CPU's C library gives it (``expf``); on CUDA, correctly rounded (float64 rounded
    once)."""
    ...


@wp.func_native(_LIBM_POW)
def libm_pow(x: float, y: float) -> float:
    """``x^y`` in float32 as the CPU's C library gives it (``powf``); on CUDA, correctly rounded (float64 rounded
    once)."""
    ...


@wp.func
def linear_from_srgb(c: float) -> float:
    """``color3::sRGBToLinearRGB`` of one channel."""
    if c <= 0.04045:
        return c / 12.92
    return libm_pow((c + 0.055) / 1.055, 2.4)


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
        return libm_pow(t, ONE_THIRD)
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
    return a * wp.sqrt(PI / b) * libm_exp(-PI_SQ * x2 / b)


@wp.func
def gaussian_sqrt(x2: float, a: float, b: float) -> float:
    """``GaussianSqrt``: one separable factor of a Cz Gaussian, ``sqrt(a · sqrt(π / b)) · exp(−π² x² / b)``."""
    return wp.sqrt(a * wp.sqrt(PI / b)) * libm_exp(-PI_SQ * x2 / b)


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
        g = libm_exp(-(xx * xx) / (2.0 * std_dev * std_dev))
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
    cmax[0] = libm_pow(hyab(green, blue), QC)


@wp.func
def redistributed(d: float, cmax: float) -> float:
    """The colour difference ``HyAB^qc`` mapped to [0, 1]: [0, pc·cmax) onto [0, pt), the rest onto [pt, 1]."""
    pccmax = PC * cmax
    if d < pccmax:
        return d * (PT / pccmax)
    return PT + ((d - pccmax) / (cmax - pccmax)) * (1.0 - PT)


@wp.func
def filtered_lab(y: float, cx: float, cz: float) -> wp.vec3:
    """Hunt-adjusted CIELAB of a filtered YCxCz colour, clamped to the linear RGB cube first."""
    linear = clamp01(apply3(XYZ_TO_RGB, xyz_from_ycxcz(wp.vec3(y, cx, cz))))
    return hunt_adjusted(lab_from_xyz(apply3(RGB_TO_XYZ, linear)))


@wp.func
def edge_and_point(d: wp.vec4) -> wp.vec2:
    """Edge and point strengths of (d/dx, d²/dx², d/dy, d²/dy²): the gradient's and the second derivatives' norms."""
    return wp.vec2(wp.sqrt(d[0] * d[0] + d[2] * d[2]), wp.sqrt(d[1] * d[1] + d[3] * d[3]))


@wp.func
def flip_error(color_difference: float, reference_features: wp.vec2, test_features: wp.vec2) -> float:
    """``color_difference^(1 − feature difference)``, the feature difference ``(max(|Δedge|, |Δpoint|)/√2)^qf``."""
    edge = wp.abs(reference_features[0] - test_features[0])
    point = wp.abs(reference_features[1] - test_features[1])
    feature = libm_pow(INV_SQRT2 * wp.max(edge, point), QF)
    return libm_pow(color_difference, 1.0 - feature)


@wp.func
def ycxcz_and_luma(c: wp.vec3):
    """sRGB → linear RGB clamped to [0, 1] → YCxCz, and the achromatic channel normalised to [0, 1]."""
    linear = clamp01(wp.vec3(linear_from_srgb(c[0]), linear_from_srgb(c[1]), linear_from_srgb(c[2])))
    v = ycxcz_from_xyz(apply3(RGB_TO_XYZ, linear))
    return v, v[0] * ONE_OVER_116 + SIXTEEN_OVER_116


@wp.func
def ycxcz_pixel(reference: wp.array2d(dtype=wp.vec3), test: wp.array2d(dtype=wp.vec3), level: int, i: int, j: int,
                ycxcz: wp.array3d(dtype=wp.vec3), luma: wp.array3d(dtype=float)):
    """Pixel (i, j) of both images in YCxCz and luma; the test's values are the reference's where the pixels agree."""
    v, y = ycxcz_and_luma(reference[i, j])
    ycxcz[0, i, j] = v
    luma[0, i, j] = y
    if level == DIFFERS:
        v, y = ycxcz_and_luma(test[i, j])
    ycxcz[1, i, j] = v
    luma[1, i, j] = y


@wp.kernel
def ycxcz_kernel(reference: wp.array2d(dtype=wp.vec3), test: wp.array2d(dtype=wp.vec3),
                 reach: wp.array2d(dtype=wp.uint8), run: int, ycxcz: wp.array3d(dtype=wp.vec3),
                 luma: wp.array3d(dtype=float)):
    # Index 0 the reference, 1 the test. A thread per run of ``run`` pixels of a row: on the CPU the
    # whole row, so that a thread's start, which copies every argument, serves them all; on a GPU one.
    i, k = wp.tid()
    j = k * run
    end = wp.min(j + run, reach.shape[1])
    while j < end:
        level = int(reach[i, j])
        if level >= READ_BY_ROWS:
            ycxcz_pixel(reference, test, level, i, j, ycxcz, luma)
        j += 1


@wp.func
def rows_of(ycxcz: wp.array3d(dtype=wp.vec3), luma: wp.array3d(dtype=float), k: int, i: int, j: int,
            spatial: wp.array(dtype=wp.vec4), spatial_radius: int, feature: wp.array(dtype=wp.vec3),
            feature_radius: int):
    """Image k's row pass at (i, j): (Y, Cx, Cz, Cz) by the spatial weights, (d/dx, d²/dx², Gaussian) of the luma."""
    last = ycxcz.shape[2] - 1
    # The taps are `while` loops: a range known only at run time costs Warp's CPU code several times
    # more per step (the dense pair of 640×360 pixels: 136 → 103 ms).
    spatial_sum = wp.vec4(0.0)
    t = -spatial_radius
    while t <= spatial_radius:
        a = ycxcz[k, i, wp.min(wp.max(0, j + t), last)]
        # (Y, Cx, Cz, Cz) weighted by (Y, Cx, first Cz, second Cz) weights.
        spatial_sum += wp.cw_mul(spatial[t + spatial_radius], wp.vec4(a[0], a[1], a[2], a[2]))
        t += 1
    feature_sum = wp.vec3(0.0)
    t = -feature_radius
    while t <= feature_radius:
        g = feature[t + feature_radius]
        feature_sum += wp.vec3(g[1], g[2], g[0]) * luma[k, i, wp.min(wp.max(0, j + t), last)]
        t += 1
    return spatial_sum, feature_sum


_ROWS_BLOCK = """
#if !defined(__CUDA_ARCH__)
{
#pragma clang fp contract(off)
    // Four pixels side by side in a vector of 16 floats, each lane adding its channel's weighted taps in
    // tap order: rows_of's sums bit for bit. Two such groups of both images, spatial and feature sums:
    // twelve sums that do not wait on each other at every tap.
    typedef float v16 __attribute__((ext_vector_type(16)));
    typedef float v4 __attribute__((ext_vector_type(4)));
    assert(ycxcz.strides[2] == 12 && luma.strides[2] == 4 && spatial_rows.strides[2] == 16
           && feature_rows.strides[2] == 12 && j - spatial_radius >= 0 && j - feature_radius >= 0
           && j + 7 + spatial_radius < ycxcz.shape[2] && j + 7 + feature_radius < ycxcz.shape[2]);
    v16 spatial_sum[2][2] = {{0.0f, 0.0f}, {0.0f, 0.0f}};
    v16 feature_sum[2][2] = {{0.0f, 0.0f}, {0.0f, 0.0f}};
    const int reach = wp::max(spatial_radius, feature_radius);
    for (int t = -reach; t <= reach; ++t) {
        if (t >= -spatial_radius && t <= spatial_radius) {
            v4 w;
            __builtin_memcpy(&w, &wp::index(spatial, t + spatial_radius), 16);
            const v16 weights = __builtin_shufflevector(w, w, 0, 1, 2, 3, 0, 1, 2, 3, 0, 1, 2, 3, 0, 1, 2, 3);
            for (int k = 0; k < 2; ++k) {
                const char* colours = reinterpret_cast<const char*>(ycxcz.data) + k * ycxcz.strides[0]
                                      + i * ycxcz.strides[1] + (j + t) * 12;
                for (int q = 0; q < 2; ++q) {
                    // (Y, Cx, Cz) of four pixels widened to (Y, Cx, Cz, Cz).
                    v16 a = 0.0f;
                    __builtin_memcpy(&a, colours + q * 48, 48);
                    a = __builtin_shufflevector(a, a, 0, 1, 2, 2, 3, 4, 5, 5, 6, 7, 8, 8, 9, 10, 11, 11);
                    spatial_sum[k][q] = spatial_sum[k][q] + weights * a;
                }
            }
        }
        if (t >= -feature_radius && t <= feature_radius) {
            // (dg, ddg, g) · luma of four pixels in lanes 0-11; lanes 12-15 unused.
            const wp::vec3 g = wp::index(feature, t + feature_radius);
            const v16 weights = {g[1], g[2], g[0], g[1], g[2], g[0], g[1], g[2], g[0], g[1], g[2], g[0], 0.0f, 0.0f,
                                 0.0f, 0.0f};
            for (int k = 0; k < 2; ++k) {
                const char* lumas = reinterpret_cast<const char*>(luma.data) + k * luma.strides[0]
                                    + i * luma.strides[1] + (j + t) * 4;
                for (int q = 0; q < 2; ++q) {
                    v4 l;
                    __builtin_memcpy(&l, lumas + q * 16, 16);
                    feature_sum[k][q] = feature_sum[k][q]
                                        + weights * __builtin_shufflevector(l, l, 0, 0, 0, 1, 1, 1, 2, 2, 2, 3, 3, 3, 3,
                                                                            3, 3, 3);
                }
            }
        }
    }
    for (int k = 0; k < 2; ++k) {
        char* spatial_out = reinterpret_cast<char*>(spatial_rows.data) + k * spatial_rows.strides[0]
                            + i * spatial_rows.strides[1] + j * 16;
        char* feature_out = reinterpret_cast<char*>(feature_rows.data) + k * feature_rows.strides[0]
                            + i * feature_rows.strides[1] + j * 12;
        for (int q = 0; q < 2; ++q) {
            __builtin_memcpy(spatial_out + q * 64, &spatial_sum[k][q], 64);
            __builtin_memcpy(feature_out + q * 48, &feature_sum[k][q], 48);
        }
    }
}
#endif
"""


@wp.func_native(_ROWS_BLOCK)
def rows_block(ycxcz: wp.array3d(dtype=wp.vec3), luma: wp.array3d(dtype=float), i: int, j: int,
               spatial: wp.array(dtype=wp.vec4), spatial_radius: int, feature: wp.array(dtype=wp.vec3),
               feature_radius: int, spatial_rows: wp.array3d(dtype=wp.vec4), feature_rows: wp.array3d(dtype=wp.vec3)):
    """:func:`rows_of` both images at pixels j … j + 7 of row i, stored, on the CPU: every tap inside the row (no
    clamping), the same sums in the same order, bit for bit.

    Native code so that clang adds eight pixels' taps in vectors of 16 floats; a GPU's threads
    take a pixel each and never call it.
    """
    ...


@wp.func
def rows_pixel(ycxcz: wp.array3d(dtype=wp.vec3), luma: wp.array3d(dtype=float), level: int, i: int, j: int,
               spatial: wp.array(dtype=wp.vec4), spatial_radius: int, feature: wp.array(dtype=wp.vec3),
               feature_radius: int, spatial_rows: wp.array3d(dtype=wp.vec4), feature_rows: wp.array3d(dtype=wp.vec3)):
    """Both images' row passes at (i, j): the test's is the reference's where its row does not differ."""
    s, f = rows_of(ycxcz, luma, 0, i, j, spatial, spatial_radius, feature, feature_radius)
    spatial_rows[0, i, j] = s
    feature_rows[0, i, j] = f
    if level >= ROWS_DIFFER:
        s, f = rows_of(ycxcz, luma, 1, i, j, spatial, spatial_radius, feature, feature_radius)
    spatial_rows[1, i, j] = s
    feature_rows[1, i, j] = f


@wp.func
def four_at_least(reach: wp.array2d(dtype=wp.uint8), i: int, j: int, level: int) -> bool:
    """Pixels j … j + 3 of row i all lie at ``level`` of :func:`flip_reach` or nearer a difference."""
    return (int(reach[i, j]) >= level and int(reach[i, j + 1]) >= level and int(reach[i, j + 2]) >= level
            and int(reach[i, j + 3]) >= level)


@wp.kernel
def rows_kernel(
    ycxcz: wp.array3d(dtype=wp.vec3),
    luma: wp.array3d(dtype=float),
    reach: wp.array2d(dtype=wp.uint8),
    spatial: wp.array(dtype=wp.vec4),
    spatial_radius: int,
    feature: wp.array(dtype=wp.vec3),
    feature_radius: int,
    run: int,
    spatial_rows: wp.array3d(dtype=wp.vec4),
    feature_rows: wp.array3d(dtype=wp.vec3),
):
    i, k = wp.tid()
    j = k * run
    end = wp.min(j + run, reach.shape[1])
    inner = wp.max(spatial_radius, feature_radius)
    while j < end:
        level = int(reach[i, j])
        if (run > 1 and j >= inner and j + 8 <= end and j + 7 + inner < reach.shape[1]
                and four_at_least(reach, i, j, READ_BY_COLUMNS) and four_at_least(reach, i, j + 4, READ_BY_COLUMNS)):
            # On the CPU (a row a thread) eight pixels at once where no tap is clamped, both images: where
            # the test's row does not differ its pass is the reference's, as rows_pixel copies it.
            rows_block(ycxcz, luma, i, j, spatial, spatial_radius, feature, feature_radius, spatial_rows, feature_rows)
            j += 8
        else:
            if level >= READ_BY_COLUMNS:
                rows_pixel(ycxcz, luma, level, i, j, spatial, spatial_radius, feature, feature_radius, spatial_rows,
                           feature_rows)
            j += 1


@wp.func
def column_sums(spatial_rows: wp.array3d(dtype=wp.vec4), feature_rows: wp.array3d(dtype=wp.vec3), i: int, j: int,
                spatial: wp.array(dtype=wp.vec4), spatial_radius: int, feature: wp.array(dtype=wp.vec3),
                feature_radius: int):
    """Both images' column passes at (i, j): (Y, Cx, Cz, Cz) and (d/dx, d²/dx², d/dy, d²/dy²) of each.

    One walk over the taps for the two images (a weight and a clamped row found once for both),
    each sum still added in tap order, so each is what a walk of its own gives.
    """
    last = spatial_rows.shape[1] - 1
    # `while` loops: see rows_of.
    reference_spatial = wp.vec4(0.0)
    test_spatial = wp.vec4(0.0)
    t = -spatial_radius
    while t <= spatial_radius:
        w = spatial[t + spatial_radius]
        row = wp.min(wp.max(0, i + t), last)
        reference_spatial += wp.cw_mul(w, spatial_rows[0, row, j])
        test_spatial += wp.cw_mul(w, spatial_rows[1, row, j])
        t += 1
    # x-derivatives smoothed in y by the Gaussian, the x-smoothed luma differentiated in y.
    reference_feature = wp.vec4(0.0)
    test_feature = wp.vec4(0.0)
    t = -feature_radius
    while t <= feature_radius:
        g = feature[t + feature_radius]
        w = wp.vec4(g[0], g[0], g[1], g[2])
        row = wp.min(wp.max(0, i + t), last)
        a = feature_rows[0, row, j]
        reference_feature += wp.cw_mul(w, wp.vec4(a[0], a[1], a[2], a[2]))
        b = feature_rows[1, row, j]
        test_feature += wp.cw_mul(w, wp.vec4(b[0], b[1], b[2], b[2]))
        t += 1
    return reference_spatial, test_spatial, reference_feature, test_feature


BlockSums = wp.types.matrix(shape=(16, 4), dtype=wp.float32)
""":func:`column_sums` of four neighbouring pixels of a row (:func:`column_sums_block`): rows 0–3 the reference's
(Y, Cx, Cz, Cz) of each pixel, 4–7 the test's, 8–11 the reference's (d/dx, d²/dx², d/dy, d²/dy²), 12–15 the test's."""

_COLUMN_SUMS_BLOCK = """
wp::mat_t<16, 4, float> sums;
#if !defined(__CUDA_ARCH__)
{
#pragma clang fp contract(off)
    // Four pixels' vec4s side by side in one vector of 16 floats: each lane's weight is its channel's,
    // so the sums of all four pixels are the same element-wise products and sums, in tap order.
    typedef float v16 __attribute__((ext_vector_type(16)));
    typedef float v4 __attribute__((ext_vector_type(4)));
    assert(spatial_rows.strides[2] == 16 && feature_rows.strides[2] == 12 && j >= 0 && j + 4 <= spatial_rows.shape[2]);
    const int last = spatial_rows.shape[1] - 1;
    const char* spatial_0 = reinterpret_cast<const char*>(spatial_rows.data) + j * 16;
    const char* spatial_1 = spatial_0 + spatial_rows.strides[0];
    v16 reference_spatial = 0.0f, test_spatial = 0.0f;
    for (int t = -spatial_radius; t <= spatial_radius; ++t) {
        const size_t row = size_t(wp::min(wp::max(0, i + t), last)) * spatial_rows.strides[1];
        v4 w;
        __builtin_memcpy(&w, &wp::index(spatial, t + spatial_radius), 16);
        const v16 weights = __builtin_shufflevector(w, w, 0, 1, 2, 3, 0, 1, 2, 3, 0, 1, 2, 3, 0, 1, 2, 3);
        v16 a, b;
        __builtin_memcpy(&a, spatial_0 + row, 64);
        __builtin_memcpy(&b, spatial_1 + row, 64);
        reference_spatial = reference_spatial + weights * a;
        test_spatial = test_spatial + weights * b;
    }
    const char* feature_0 = reinterpret_cast<const char*>(feature_rows.data) + j * 12;
    const char* feature_1 = feature_0 + feature_rows.strides[0];
    v16 reference_feature = 0.0f, test_feature = 0.0f;
    for (int t = -feature_radius; t <= feature_radius; ++t) {
        const size_t row = size_t(wp::min(wp::max(0, i + t), last)) * feature_rows.strides[1];
        const wp::vec3 g = wp::index(feature, t + feature_radius);
        // (g, g, dg, ddg) · (d/dx, d²/dx², g, g) of each pixel's row pass: its vec3 widened to four.
        const v16 weights = {g[0], g[0], g[1], g[2], g[0], g[0], g[1], g[2], g[0], g[0], g[1], g[2], g[0], g[0], g[1],
                             g[2]};
        v16 a = 0.0f, b = 0.0f;
        __builtin_memcpy(&a, feature_0 + row, 48);
        __builtin_memcpy(&b, feature_1 + row, 48);
        a = __builtin_shufflevector(a, a, 0, 1, 2, 2, 3, 4, 5, 5, 6, 7, 8, 8, 9, 10, 11, 11);
        b = __builtin_shufflevector(b, b, 0, 1, 2, 2, 3, 4, 5, 5, 6, 7, 8, 8, 9, 10, 11, 11);
        reference_feature = reference_feature + weights * a;
        test_feature = test_feature + weights * b;
    }
    __builtin_memcpy(&sums.data[0][0], &reference_spatial, 64);
    __builtin_memcpy(&sums.data[4][0], &test_spatial, 64);
    __builtin_memcpy(&sums.data[8][0], &reference_feature, 64);
    __builtin_memcpy(&sums.data[12][0], &test_feature, 64);
}
#endif
return sums;
"""


@wp.func_native(_COLUMN_SUMS_BLOCK)
def column_sums_block(spatial_rows: wp.array3d(dtype=wp.vec4), feature_rows: wp.array3d(dtype=wp.vec3), i: int,
                      j: int, spatial: wp.array(dtype=wp.vec4), spatial_radius: int, feature: wp.array(dtype=wp.vec3),
                      feature_radius: int) -> BlockSums:
    """:func:`column_sums` of pixels j … j + 3 of row i, on the CPU: the same sums in the same order, bit for bit.

    Native code so that clang adds the four pixels' taps in one vector of 16 floats (the pass's sums
    ~2× faster than a pixel at a time; its per-pixel tail stays Warp's); floating-point contraction
    off, as in the rest of the module. A GPU's threads take a pixel each and never call it (its
    ``sums`` are then undefined).
    """
    ...


@wp.func
def summed_lab(spatial_sum: wp.vec4) -> wp.vec3:
    """Hunt-adjusted CIELAB of a column pass's (Y, Cx, Cz, Cz): the two Cz parts add (the Cz filter
    is a sum of two Gaussians)."""
    return filtered_lab(spatial_sum[0], spatial_sum[1], spatial_sum[2] + spatial_sum[3])


@wp.func
def error_of_sums(reference_spatial: wp.vec4, test_spatial: wp.vec4, reference_feature: wp.vec4,
                  test_feature: wp.vec4, cmax: float) -> float:
    """The ꟻLIP error of a pixel from both images' column sums."""
    color_difference = redistributed(libm_pow(hyab(summed_lab(reference_spatial), summed_lab(test_spatial)), QC),
                                     cmax)
    return flip_error(color_difference, edge_and_point(reference_feature), edge_and_point(test_feature))


@wp.func
def error_at(spatial_rows: wp.array3d(dtype=wp.vec4), feature_rows: wp.array3d(dtype=wp.vec3), i: int, j: int,
             spatial: wp.array(dtype=wp.vec4), spatial_radius: int, feature: wp.array(dtype=wp.vec3),
             feature_radius: int, cmax: float) -> float:
    """The ꟻLIP error at (i, j) from both images' row passes."""
    reference_spatial, test_spatial, reference_feature, test_feature = column_sums(
        spatial_rows, feature_rows, i, j, spatial, spatial_radius, feature, feature_radius)
    return error_of_sums(reference_spatial, test_spatial, reference_feature, test_feature, cmax)


@wp.kernel
def columns_kernel(
    spatial_rows: wp.array3d(dtype=wp.vec4),
    feature_rows: wp.array3d(dtype=wp.vec3),
    reach: wp.array2d(dtype=wp.uint8),
    spatial: wp.array(dtype=wp.vec4),
    spatial_radius: int,
    feature: wp.array(dtype=wp.vec3),
    feature_radius: int,
    cmax: wp.array(dtype=float),
    run: int,
    error: wp.array2d(dtype=float),
):
    i, k = wp.tid()
    j = k * run
    end = wp.min(j + run, reach.shape[1])
    while j < end:
        # Below MAY_DIFFER the inputs are equal over the whole support: equal filtered values, a HyAB
        # distance of 0, an error of 0.
        if run > 1 and j + 4 <= end and four_at_least(reach, i, j, MAY_DIFFER):
            # On the CPU (a row a thread) four pixels' sums at once, each pixel's error then as below.
            m = column_sums_block(spatial_rows, feature_rows, i, j, spatial, spatial_radius, feature, feature_radius)
            for p in range(4):
                error[i, j + p] = error_of_sums(m[p], m[4 + p], m[8 + p], m[12 + p], cmax[0])
            j += 4
        else:
            e = float(0.0)
            if int(reach[i, j]) >= MAY_DIFFER:
                e = error_at(spatial_rows, feature_rows, i, j, spatial, spatial_radius, feature, feature_radius,
                             cmax[0])
            error[i, j] = e
            j += 1


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


_SCRATCH = threading.local()


def _scratch(pair: tuple[int, int, int], device: str) -> tuple[wp.array, wp.array, wp.array, wp.array]:
    """The passes' intermediate arrays of an image pair ``(2, H, W)`` on ``device``: both images' YCxCz and luma,
    their row passes.

    Kept from call to call, per thread, for the last shape and device: a run's frames share both,
    and fresh arrays cost their pages' first touch every frame (~20 MB at 640×360, a few ms).
    Nothing is read that the call has not written: each pass reads only pixels its reach level
    has the previous pass write.
    """
    key = (pair, device)
    if getattr(_SCRATCH, "key", None) != key:
        _SCRATCH.key = key
        _SCRATCH.arrays = (wp.empty(pair, dtype=wp.vec3, device=device), wp.empty(pair, dtype=float, device=device),
                           wp.empty(pair, dtype=wp.vec4, device=device), wp.empty(pair, dtype=wp.vec3, device=device))
    return _SCRATCH.arrays


def _pixels_per_thread(device: str, width: int) -> int:
    """The run of a row's pixels each thread of the three passes takes: on the CPU the whole row, so that a
    thread's start, which copies every argument, serves them all, and the row passes take four or eight
    pixels at once (:func:`rows_block`, :func:`column_sums_block`); on a GPU one."""
    return width if wp.get_device(device).is_cpu else 1


def _checked_image(name: str, image) -> np.ndarray:
    """The image as C-contiguous float32 ``(H, W, 3)``, not copied when it is one already."""
    array = np.asarray(image)
    if array.ndim != 3 or array.shape[2] != 3 or array.shape[0] < 1 or array.shape[1] < 1:
        raise ValueError(f"{name}: expected an (H, W, 3) sRGB image, got shape {array.shape}")
    array = np.ascontiguousarray(array, dtype=np.float32)
    # min and max propagate NaN, and an infinity is their value if present: two passes tell all three.
    low, high = array.min(), array.max()
    if not (np.isfinite(low) and np.isfinite(high)):
        raise ValueError(f"{name}: expected finite values, got NaN or infinity")
    if low < 0.0 or high > 1.0:
        raise ValueError(f"{name}: expected sRGB values in [0, 1], got [{low}, {high}]")
    return array


def flip_error_map(reference, test, *, pixels_per_degree: float = FLIP_DEFAULT_PPD,
                   device: str = "cpu", reach=None) -> np.ndarray:
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
    reach : array_like, shape (H, W), uint8, optional
        :func:`flip_reach` of a superset of the pixels where the images differ, with the radius
        ``max(flip_filter_radii(pixels_per_degree=...))``, when the caller has it (from the
        images it encoded these from): the same error map, as a pass computed where the inputs
        agree gives the values it would have skipped. By default the images are compared here.

    Returns
    -------
    ndarray, shape (H, W), float32
        The error in [0, 1]; exactly 0 where the two images agree over the filters' support
        (:func:`flip_filter_radii`), where it is not computed (:func:`flip_reach`). Near the edges
        the filters clamp to the edge pixel.

    Raises
    ------
    ValueError
        On a shape other than (H, W, 3), differing shapes, values outside [0, 1] or not finite,
        a non-positive ``pixels_per_degree``, a ``reach`` of another shape, or an unusable device.
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
    if reach is None:
        reach = flip_reach(pixels_differ(reference, test), radius=max(spatial_radius, feature_radius))
    reach = np.asarray(reach, dtype=np.uint8)
    if reach.shape != (height, width):
        raise ValueError(f"reach: expected the images' shape {(height, width)}, got {reach.shape}")
    # Read in place where the device can (the CPU): the checked reach and images.
    reach = wp.array(np.ascontiguousarray(reach), dtype=wp.uint8, device=device, copy=False)
    ycxcz, luma, spatial_rows, feature_rows = _scratch(pair, device)
    run = _pixels_per_thread(device, width)
    runs = (height, -(-width // run))
    wp.launch(ycxcz_kernel, dim=runs,
              inputs=(wp.array(reference, dtype=wp.vec3, device=device, copy=False),
                      wp.array(test, dtype=wp.vec3, device=device, copy=False), reach, run),
              outputs=(ycxcz, luma), device=device)
    wp.launch(rows_kernel, dim=runs,
              inputs=(ycxcz, luma, reach, spatial, spatial_radius, feature, feature_radius, run),
              outputs=(spatial_rows, feature_rows), device=device)
    error = wp.empty((height, width), dtype=float, device=device)
    wp.launch(columns_kernel, dim=runs,
              inputs=(spatial_rows, feature_rows, reach, spatial, spatial_radius, feature, feature_radius, cmax, run),
              outputs=(error,), device=device)
    return error.numpy()
