"""VSM and EVSM moments, blur and Chebyshev lookup against a brute-force NumPy reference."""

import numpy as np
import pytest

from csmlab.kernels.moments import MOMENT_METHODS, blur_moments, moment_lookup, moment_maps

BITS = 8
UNIT = 2**BITS
EXPONENTS = (20.0, 6.0)


def ref_moments(depth, span, method):
    z = np.where(np.isfinite(depth), np.clip(depth.astype(np.float64) / span, 0.0, 1.0), 1.0)
    out = np.zeros(depth.shape + (4,))
    if method == "vsm":
        out[..., 0], out[..., 1] = z, z * z
        return out.astype(np.float32)
    p = np.exp(EXPONENTS[0] * (2 * z - 1))
    out[..., 0], out[..., 1] = p, p * p
    if method == "evsm4":
        n = -np.exp(-EXPONENTS[1] * (2 * z - 1))
        out[..., 2], out[..., 3] = n, n * n
    return out.astype(np.float32)


def ref_blur(m, radius):
    """Box of 2r + 1 texels along x then y, edge texels repeated, rounded to float32 after each pass."""
    def along(a, axis):
        pad = [(0, 0)] * 4
        pad[axis] = (radius, radius)
        padded = np.pad(a.astype(np.float64), pad, mode="edge")
        size = a.shape[axis]
        total = sum(np.take(padded, range(k, k + size), axis=axis) for k in range(2 * radius + 1))
        return (total / (2 * radius + 1)).astype(np.float32)
    return along(along(m, 2), 1)


def chebyshev(mean, variance, t):
    return 1.0 if t <= mean else variance / (variance + (t - mean) ** 2)


def ref_lit(m, c, x, y, receiver, method, span, min_variance, power, bleed):
    if np.isnan(receiver):
        return 0.0
    r = m.shape[1] - 1
    fx, fy = (2 * x - UNIT) / (2 * UNIT), (2 * y - UNIT) / (2 * UNIT)
    i0, j0 = int(np.floor(fx)), int(np.floor(fy))
    wx, wy = fx - i0, fy - j0
    at = lambda i, j: m[c, min(max(j, 0), r), min(max(i, 0), r)].astype(np.float64)
    mom = (1 - wy) * ((1 - wx) * at(i0, j0) + wx * at(i0 + 1, j0)) + wy * ((1 - wx) * at(i0, j0 + 1) + wx * at(i0 + 1, j0 + 1))
    t = float(receiver) / span
    if method == "vsm":
        p = chebyshev(mom[0], np.clip(mom[1] - mom[0] ** 2 + min_variance, 0, 1), t)
    else:
        w = np.exp(EXPONENTS[0] * (2 * t - 1))
        p = chebyshev(mom[0], max(mom[1] - mom[0] ** 2, min_variance * (EXPONENTS[0] * w) ** 2), w)
        if method == "evsm4":
            w = -np.exp(-EXPONENTS[1] * (2 * t - 1))
            p = min(p, chebyshev(mom[2], max(mom[3] - mom[2] ** 2, min_variance * (EXPONENTS[1] * w) ** 2), w))
    p = p**power
    return float(np.clip((p - bleed) / (1 - bleed), 0, 1)) if bleed > 0 else p


@pytest.mark.parametrize("method", sorted(MOMENT_METHODS))
@pytest.mark.parametrize("power, bleed", [(1.0, 0.0), (3.0, 0.0), (1.0, 0.3)])
def test_moment_filters_equal_the_brute_force_chebyshev_reference(method, power, bleed):
    rng = np.random.default_rng(7)
    span = 40.0
    depth = rng.uniform(0.0, 40.0, (2, 24, 24)).astype(np.float32)
    depth[:, 6:14, 4:12] = 8.0  # a flat occluder, so that some receivers sit in a zero-variance region
    depth[rng.random(depth.shape) < 0.05] = np.inf
    n = 200
    coords = rng.integers(2 * UNIT, 22 * UNIT, (2, n, 2))
    receiver = rng.uniform(0.0, 44.0, (2, n)).astype(np.float32)
    receiver[0, :3] = np.nan
    cascade = rng.integers(0, 2, n).astype(np.int32)
    moments = blur_moments(moment_maps(depth, span=span, method=method, exponents=EXPONENTS), radius=2)
    expected_moments = ref_blur(ref_moments(depth, span, method), 2)
    np.testing.assert_allclose(moments, expected_moments, rtol=1e-6)
    lit = moment_lookup(moments, coords, receiver, cascade=cascade, method=method, span=span, bits=BITS,
                        exponents=EXPONENTS, min_variance=1e-4, power=power, bleed=bleed)
    expected = [ref_lit(moments, c, *coords[c, k], receiver[c, k], method, span, 1e-4, power, bleed)
                for k, c in enumerate(cascade)]
    np.testing.assert_allclose(lit, expected, atol=1e-5)
    assert np.all(lit[:3][cascade[:3] == 0] == 0.0)  # receivers turned from the light


def test_moment_lookup_is_lit_in_front_of_a_flat_caster_and_dark_far_behind_it():
    depth = np.full((1, 16, 16), 10.0, np.float32)
    coords = np.full((1, 2, 2), 8 * UNIT + 77)
    receiver = np.array([[9.0, 30.0]], np.float32)
    for method in MOMENT_METHODS:
        moments = blur_moments(moment_maps(depth, span=40.0, method=method, exponents=EXPONENTS), radius=1)
        lit = moment_lookup(moments, coords, receiver, cascade=np.zeros(2, np.int32), method=method, span=40.0,
                            bits=BITS, exponents=EXPONENTS, min_variance=1e-6)
        assert lit[0] == 1.0, method
        assert lit[1] < 0.01, method


def test_blur_moves_with_the_map():
    # A whole-texel shift of the map shifts the blurred moments by the same texels (away from the edges).
    rng = np.random.default_rng(2)
    depth = rng.uniform(0, 30, (1, 32, 32)).astype(np.float32)
    a = blur_moments(moment_maps(depth, span=30.0, method="evsm4", exponents=EXPONENTS), radius=3)
    b = blur_moments(moment_maps(np.roll(depth, (2, -3), axis=(1, 2)), span=30.0, method="evsm4",
                                 exponents=EXPONENTS), radius=3)
    np.testing.assert_array_equal(np.roll(a, (2, -3), axis=(1, 2))[:, 8:24, 8:24], b[:, 8:24, 8:24])
