"""VSM, EVSM and MSM moments, blur and their bounds against brute-force NumPy references."""

import numpy as np
import pytest

from csmlab.kernels.moments import blur_moments, moment_lookup, moment_maps, moment_mip_chain, moment_mip_lookup
from csmlab.lookup_choices import family_filters

BITS = 8
UNIT = 2**BITS
EXPONENTS = (20.0, 6.0)
MOMENT_FILTERS = sorted(family_filters("moment"))


def ref_moments(depth, span, method):
    z = np.where(np.isfinite(depth), np.clip(depth.astype(np.float64) / span, 0.0, 1.0), 1.0)
    out = np.zeros(depth.shape + (4,))
    if method == "vsm":
        out[..., 0], out[..., 1] = z, z * z
        return out.astype(np.float32)
    if method == "msm":
        out[...] = z[..., None] ** np.arange(1, 5)
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


def hamburger(mom, t, alpha=3e-6, depth_bias=0.0):
    """Peters and Klein 2015, Algorithm 3 (Hamburger 4MSM): solve the Hankel system, then the quadratic.

    Written from the paper with a general solver and polynomial roots (not the Cholesky steps of
    the kernel): ``b = (1 − α) b + α (½, ½, ½, ½)``, ``B c = (1, z_f, z_f²)`` with B the 3×3 Hankel
    matrix of (1, b₁ … b₄), ``z₂ ≤ z₃`` the roots of ``c₀ + c₁ z + c₂ z²``, G by the three cases.
    """
    b = (1.0 - alpha) * np.asarray(mom, dtype=np.float64) + alpha * 0.5
    zf = t - depth_bias
    hankel = np.array([[1.0, b[0], b[1]], [b[0], b[1], b[2]], [b[1], b[2], b[3]]])
    c = np.linalg.solve(hankel, [1.0, zf, zf * zf])
    z2, z3 = sorted(np.roots([c[2], c[1], c[0]]).real)
    if zf <= z2:
        g = 0.0
    elif zf <= z3:
        g = (zf * z3 - b[0] * (zf + z3) + b[1]) / ((z3 - z2) * (zf - z2))
    else:
        g = 1.0 - (z2 * z3 - b[0] * (z2 + z3) + b[1]) / ((zf - z2) * (zf - z3))
    return 1.0 - float(np.clip(g, 0.0, 1.0))


def ref_lit(m, c, x, y, receiver, method, span, min_variance, power, bleed):
    if np.isnan(receiver):
        return 0.0
    r = m.shape[1] - 1
    fx, fy = (2 * x - UNIT) / (2 * UNIT), (2 * y - UNIT) / (2 * UNIT)
    i0, j0 = int(np.floor(fx)), int(np.floor(fy))
    wx, wy = fx - i0, fy - j0

    def at(i, j):
        return m[c, min(max(j, 0), r), min(max(i, 0), r)].astype(np.float64)

    mom = ((1 - wy) * ((1 - wx) * at(i0, j0) + wx * at(i0 + 1, j0))
           + wy * ((1 - wx) * at(i0, j0 + 1) + wx * at(i0 + 1, j0 + 1)))
    t = float(receiver) / span
    if method == "msm":
        p = hamburger(mom, t)
    elif method == "vsm":
        p = chebyshev(mom[0], np.clip(mom[1] - mom[0] ** 2 + min_variance, 0, 1), t)
    else:
        w = np.exp(EXPONENTS[0] * (2 * t - 1))
        p = chebyshev(mom[0], max(mom[1] - mom[0] ** 2, min_variance * (EXPONENTS[0] * w) ** 2), w)
        if method == "evsm4":
            w = -np.exp(-EXPONENTS[1] * (2 * t - 1))
            p = min(p, chebyshev(mom[2], max(mom[3] - mom[2] ** 2, min_variance * (EXPONENTS[1] * w) ** 2), w))
    p = p**power
    return float(np.clip((p - bleed) / (1 - bleed), 0, 1)) if bleed > 0 else p


@pytest.mark.parametrize("method", sorted(MOMENT_FILTERS))
@pytest.mark.parametrize("power, bleed", [(1.0, 0.0), (3.0, 0.0), (1.0, 0.3)])
def test_moment_filters_equal_the_brute_force_chebyshev_reference(method, power, bleed, device):
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
    moments = blur_moments(moment_maps(depth, span=span, method=method, exponents=EXPONENTS, device=device), radius=2,
                           device=device)
    expected_moments = ref_blur(ref_moments(depth, span, method), 2)
    np.testing.assert_allclose(moments, expected_moments, rtol=1e-6)
    lit = moment_lookup(moments, coords, receiver, cascade=cascade, method=method, span=span, bits=BITS,
                        exponents=EXPONENTS, min_variance=1e-4, power=power, bleed=bleed, device=device)
    expected = [ref_lit(moments, c, *coords[c, k], receiver[c, k], method, span, 1e-4, power, bleed)
                for k, c in enumerate(cascade)]
    np.testing.assert_allclose(lit, expected, atol=1e-5)
    assert np.all(lit[:3][cascade[:3] == 0] == 0.0)  # receivers turned from the light


def test_moment_lookup_is_lit_in_front_of_a_flat_caster_and_dark_far_behind_it(device):
    depth = np.full((1, 16, 16), 10.0, np.float32)
    coords = np.full((1, 2, 2), 8 * UNIT + 77)
    receiver = np.array([[9.0, 30.0]], np.float32)
    for method in MOMENT_FILTERS:
        moments = blur_moments(moment_maps(depth, span=40.0, method=method, exponents=EXPONENTS, device=device),
                               radius=1, device=device)
        lit = moment_lookup(moments, coords, receiver, cascade=np.zeros(2, np.int32), method=method, span=40.0,
                            bits=BITS, exponents=EXPONENTS, min_variance=1e-6, device=device)
        assert lit[0] == 1.0, method
        assert lit[1] < 0.01, method


@pytest.mark.parametrize("alpha, depth_bias", [(3e-6, 0.0), (3e-5, 0.002)])
def test_msm_equals_the_papers_hamburger_reconstruction_under_its_moment_and_depth_bias(alpha, depth_bias, device):
    rng = np.random.default_rng(17)
    depth = rng.uniform(0.0, 30.0, (1, 20, 20)).astype(np.float32)
    depth[:, 4:12, 3:9] = 6.0
    moments = blur_moments(moment_maps(depth, span=30.0, method="msm", device=device), radius=2, device=device)
    np.testing.assert_allclose(moments, ref_blur(ref_moments(depth, 30.0, "msm"), 2), rtol=1e-6)
    n = 300
    coords = rng.integers(2 * UNIT, 18 * UNIT, (1, n, 2))
    receiver = rng.uniform(0.0, 33.0, (1, n)).astype(np.float32)
    lit = moment_lookup(moments, coords, receiver, cascade=np.zeros(n, np.int32), method="msm", span=30.0, bits=BITS,
                        moment_bias=alpha, depth_bias=depth_bias, device=device)
    expected = []
    for k in range(n):
        x, y = coords[0, k]
        fx, fy = (2 * x - UNIT) / (2 * UNIT), (2 * y - UNIT) / (2 * UNIT)
        i0, j0 = int(np.floor(fx)), int(np.floor(fy))
        wx, wy = fx - i0, fy - j0
        m = moments[0].astype(np.float64)
        mom = ((1 - wy) * ((1 - wx) * m[j0, i0] + wx * m[j0, i0 + 1])
               + wy * ((1 - wx) * m[j0 + 1, i0] + wx * m[j0 + 1, i0 + 1]))
        expected.append(hamburger(mom, float(receiver[0, k]) / 30.0, alpha, depth_bias))
    np.testing.assert_allclose(lit, expected, atol=1e-5)
    assert 0.05 < np.mean(lit) < 0.95  # both lit and shadowed receivers are tested


def test_msm_bleeds_less_than_vsm_where_two_occluders_overlap_in_the_filter(device):
    """The paper's light-leaking case: a receiver in the shadow of a far occluder (z = 0.5) whose filter
    also holds a near occluder's edge (z = 0.2); every receiver at 0.6 is fully shadowed."""
    depth = np.where(np.arange(32) < 16, 0.2, 0.5).astype(np.float32)[None, None, :].repeat(32, axis=1)
    coords = np.stack([np.arange(8 * UNIT, 24 * UNIT, UNIT // 4), np.full(64, 16 * UNIT)], axis=-1)[None]
    receiver = np.full((1, 64), 0.6, np.float32)
    lit = {}
    for method in ("vsm", "msm"):
        moments = blur_moments(moment_maps(depth, span=1.0, method=method, device=device), radius=3, device=device)
        lit[method] = moment_lookup(moments, coords, receiver, cascade=np.zeros(64, np.int32), method=method,
                                    span=1.0, bits=BITS, device=device)
    assert lit["vsm"].max() > 0.3  # Chebyshev's bound leaks 1 − a of the near occluder's share a
    assert lit["msm"].max() < 0.01
    assert np.all(lit["msm"] <= lit["vsm"])


def test_blur_moves_with_the_map(device):
    # A whole-texel shift of the map shifts the blurred moments by the same texels (away from the edges).
    rng = np.random.default_rng(2)
    depth = rng.uniform(0, 30, (1, 32, 32)).astype(np.float32)
    a = blur_moments(moment_maps(depth, span=30.0, method="evsm4", exponents=EXPONENTS, device=device), radius=3,
                     device=device)
    b = blur_moments(moment_maps(np.roll(depth, (2, -3), axis=(1, 2)), span=30.0, method="evsm4",
                                 exponents=EXPONENTS, device=device), radius=3, device=device)
    np.testing.assert_array_equal(np.roll(a, (2, -3), axis=(1, 2))[:, 8:24, 8:24], b[:, 8:24, 8:24])


def ref_chain(level0, origin, max_lod):
    """Each level a 2×2 box of the one below on the global grid: pad by the parity in front, by the edge behind."""
    chain = [level0]
    s = np.asarray(origin, dtype=np.int64)
    for _ in range(max_lod):
        src = chain[-1].astype(np.float64)
        parent = s // 2
        b = s - 2 * parent
        size = src.shape[1] // 2 + 1
        out = np.zeros((src.shape[0], size, size, 4))
        for c in range(src.shape[0]):
            padded = np.pad(src[c], ((b[c, 1], 2 * size), (b[c, 0], 2 * size), (0, 0)), mode="edge")
            out[c] = padded[:2 * size, :2 * size].reshape(size, 2, size, 2, 4).mean(axis=(1, 3))
        chain.append(out.astype(np.float32))
        s = parent
    return chain


@pytest.mark.parametrize("origin", [[[0, 0], [0, 0]], [[5, -3], [-8, 13]]])
def test_mip_chain_equals_a_numpy_box_downsample_on_the_global_texel_grid(origin, device):
    rng = np.random.default_rng(4)
    moments = rng.uniform(0.0, 1.0, (2, 20, 20, 4)).astype(np.float32)
    chain = moment_mip_chain(moments, origin_texels=np.array(origin), max_lod=3, device=device)
    expected = ref_chain(moments, origin, 3)
    assert [level.shape for level in chain] == [(2, 20, 20, 4), (2, 11, 11, 4), (2, 6, 6, 4), (2, 4, 4, 4)]
    for level, want in zip(chain, expected):
        np.testing.assert_allclose(level, want, rtol=1e-6)
    # Independently: a level-l texel whose global 2^l × 2^l block lies inside the map is that block's mean.
    o = np.array(origin)
    for lod in (1, 2, 3):
        step = 2**lod
        for c in range(2):
            shift = o[c] % step  # level-0 texels of the box before its first whole global block
            for j in range(chain[lod].shape[1]):
                for i in range(chain[lod].shape[2]):
                    x0, y0 = i * step - shift[0], j * step - shift[1]
                    if min(x0, y0) >= 0 and max(x0, y0) + step <= 20:
                        block = moments[c, y0:y0 + step, x0:x0 + step].astype(np.float64).mean(axis=(0, 1))
                        np.testing.assert_allclose(chain[lod][c, j, i], block, rtol=1e-5)
    if origin == [[0, 0], [0, 0]]:
        plain = moments.astype(np.float64).reshape(2, 10, 2, 10, 2, 4).mean(axis=(2, 4))
        np.testing.assert_allclose(chain[1][:, :10, :10], plain, rtol=1e-6)


def ref_mip_lit(chain, origin, c, x, y, ddx, ddy, receiver, method, span, anisotropy):
    """The trilinear/anisotropic lookup of moment_mip_lookup in float64 NumPy, then Chebyshev as ref_lit."""
    max_lod = len(chain) - 1
    px, py = np.linalg.norm(ddx), np.linalg.norm(ddy)
    major, pmax, pmin = (ddy, py, px) if py > px else (ddx, px, py)
    probes = 1
    if anisotropy > 1 and pmax > 0:
        probes = int(min(np.ceil(pmax / pmin), anisotropy)) if pmin > 0 else anisotropy
    lod = float(np.clip(np.log2(pmax / probes), 0, max_lod)) if pmax > 0 else 0.0
    base, frac = int(np.floor(lod)), lod - np.floor(lod)
    reach = probes * 2.0**max_lod
    major = np.asarray(major) * (reach / pmax if pmax > reach else 1.0)

    def bilinear(level, xp, yp):
        step = 2**level
        shift = (np.asarray(origin[c]) % step) * UNIT
        fx, fy = (xp + shift[0]) / (step * UNIT) - 0.5, (yp + shift[1]) / (step * UNIT) - 0.5
        i0, j0 = int(np.floor(fx)), int(np.floor(fy))
        wx, wy = fx - i0, fy - j0
        m = chain[level][c]
        r = m.shape[0] - 1

        def at(i, j):
            return m[min(max(j, 0), r), min(max(i, 0), r)].astype(np.float64)

        return ((1 - wy) * ((1 - wx) * at(i0, j0) + wx * at(i0 + 1, j0))
                + wy * ((1 - wx) * at(i0, j0 + 1) + wx * at(i0 + 1, j0 + 1)))

    total = np.zeros(4)
    for p in range(probes):
        t = (p + 0.5) / probes - 0.5
        xp, yp = x + int(np.rint(major[0] * t * UNIT)), y + int(np.rint(major[1] * t * UNIT))
        m = bilinear(base, xp, yp)
        if frac > 0:
            m = (1 - frac) * m + frac * bilinear(base + 1, xp, yp)
        total += m
    mom = total / probes
    t = float(receiver) / span
    if method == "msm":
        return hamburger(mom, t)
    if method == "vsm":
        return chebyshev(mom[0], np.clip(mom[1] - mom[0] ** 2 + 1e-4, 0, 1), t)
    w = np.exp(EXPONENTS[0] * (2 * t - 1))
    p = chebyshev(mom[0], max(mom[1] - mom[0] ** 2, 1e-4 * (EXPONENTS[0] * w) ** 2), w)
    w = -np.exp(-EXPONENTS[1] * (2 * t - 1))
    return min(p, chebyshev(mom[2], max(mom[3] - mom[2] ** 2, 1e-4 * (EXPONENTS[1] * w) ** 2), w))


@pytest.mark.parametrize("method", ["vsm", "evsm4", "msm"])
@pytest.mark.parametrize("anisotropy", [1, 4])
def test_trilinear_and_anisotropic_lookup_equal_a_numpy_reference(method, anisotropy, device):
    rng = np.random.default_rng(11)
    span = 40.0
    depth = rng.uniform(0.0, 40.0, (2, 48, 48)).astype(np.float32)
    depth[:, 10:30, 12:26] = 9.0
    origin = np.array([[7, -2], [-5, 4]])
    chain = moment_mip_chain(blur_moments(moment_maps(depth, span=span, method=method, exponents=EXPONENTS), radius=1),
                             origin_texels=origin, max_lod=3, device=device)
    n = 120
    coords = rng.integers(16 * UNIT, 32 * UNIT, (2, n, 2))
    receiver = rng.uniform(0.0, 44.0, (2, n)).astype(np.float32)
    cascade = rng.integers(0, 2, n).astype(np.int32)
    ddx = rng.normal(0.0, 3.0, (n, 2)) * rng.choice([0.1, 1.0, 10.0], (n, 1))
    ddy = rng.normal(0.0, 1.0, (n, 2))
    ddx[:4] = 0.0  # no footprint: level 0
    lit = moment_mip_lookup(chain, coords, receiver, origin_texels=origin, cascade=cascade, ddx=ddx, ddy=ddy,
                            method=method, span=span, bits=BITS, anisotropy=anisotropy, exponents=EXPONENTS,
                            min_variance=1e-4, device=device)
    expected = [ref_mip_lit(chain, origin, c, *coords[c, k], ddx[k], ddy[k], receiver[c, k], method, span, anisotropy)
                for k, c in enumerate(cascade)]
    np.testing.assert_allclose(lit, expected, atol=1e-5)


def test_a_footprint_under_one_texel_is_the_bilinear_lookup_of_level_zero(device):
    rng = np.random.default_rng(3)
    depth = rng.uniform(0.0, 30.0, (2, 32, 32)).astype(np.float32)
    moments = blur_moments(moment_maps(depth, span=30.0, method="evsm2", exponents=EXPONENTS), radius=2)
    chain = moment_mip_chain(moments, origin_texels=np.array([[3, 1], [-6, 9]]), max_lod=2)
    coords = rng.integers(8 * UNIT, 24 * UNIT, (2, 64, 2))
    receiver = rng.uniform(0.0, 33.0, (2, 64)).astype(np.float32)
    cascade = rng.integers(0, 2, 64).astype(np.int32)
    small = rng.uniform(-0.6, 0.6, (64, 2))
    args = dict(cascade=cascade, method="evsm2", span=30.0, bits=BITS, exponents=EXPONENTS, device=device)
    np.testing.assert_array_equal(
        moment_mip_lookup(chain, coords, receiver, origin_texels=np.array([[3, 1], [-6, 9]]), ddx=small,
                          ddy=small * 0.5, **args),
        moment_lookup(moments, coords, receiver, **args))
