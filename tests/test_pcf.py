"""Weighted PCF kernels against brute-force NumPy references; Gaussian and PCSS through the lookup on hand-worked
cases; exact-zero under box moves."""

import numpy as np
import pytest

from csmlab.cascades import Cascade, CascadeSet
from csmlab.filters import interleaved_gradient_noise, lookup_shadow
from csmlab.frame import ShadowMaps
from csmlab.geometry import light_basis
from csmlab.kernels.pcf import weighted_pcf
from csmlab.lookup_choices import FILTER_METHODS, family_filters, poisson_disk
from csmlab.settings import ShadowSettings

BITS = 8
UNIT = 2**BITS
WEIGHTED = sorted(family_filters("weighted"))


def ref_tap(depth, c, i, j, receiver, slope, x, y):
    """The receiver-plane depth test of one texel, written out (clamped texel index)."""
    r = depth.shape[1] - 1
    di = ((2 * i + 1) * UNIT - 2 * x) / (2 * UNIT)
    dj = ((2 * j + 1) * UNIT - 2 * y) / (2 * UNIT)
    plane = np.float32(float(receiver) + slope[0] * di + slope[1] * dj)
    return float(plane <= depth[c, min(max(j, 0), r), min(max(i, 0), r)])


def ref_tent_weights(t, h, lo, hi, samples=4000):
    """Per texel k in [lo, hi]: the tent of half-width h centred at t integrated over [k, k + 1) by the midpoint rule."""
    k = np.arange(lo, hi + 1)
    u = k[:, None] + (np.arange(samples) + 0.5) / samples
    tent = np.maximum(0.0, 1.0 - np.abs(u - t) / h) / h
    return tent.mean(axis=1)


def ref_tent_sum(depth, c, x, y, receiver, slope, h, radius):
    i, j = x // UNIT, y // UNIT
    wx = ref_tent_weights(x / UNIT, h, i - radius, i + radius)
    wy = ref_tent_weights(y / UNIT, h, j - radius, j + radius)
    return sum(wx[a] * wy[b] * ref_tap(depth, c, i - radius + a, j - radius + b, receiver, slope, x, y)
               for a in range(2 * radius + 1) for b in range(2 * radius + 1))


def ref_lit(filter, depth, c, x, y, receiver, slope, width, radius, disk=None, angle=0.0):
    """S by brute force, straight from each filter's definition in csmlab.kernels.pcf."""
    i, j = x // UNIT, y // UNIT
    if filter == "pcf_gaussian":
        offsets = range(-radius, radius + 1)
        w = {(a, b): np.exp(-(a * a + b * b) / (2 * width**2)) for a in offsets for b in offsets}
        total = sum(w.values())
        return sum(v * ref_tap(depth, c, i + a, j + b, receiver, slope, x, y) for (a, b), v in w.items()) / total
    if filter == "pcf_tent":
        return ref_tent_sum(depth, c, x, y, receiver, slope, width, radius)
    if filter == "pcf_poisson":
        rot = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
        hits = 0.0
        for o in disk:
            ox, oy = np.round(width * (rot @ o) * UNIT)
            hits += ref_tap(depth, c, int((x + ox) // UNIT), int((y + oy) // UNIT), receiver, slope, x, y)
        return hits / len(disk)
    # pcss
    if np.isnan(receiver):
        return 0.0
    blockers = [depth[c, j + b, i + a] for a in range(-radius, radius + 1) for b in range(-radius, radius + 1)
                if not ref_tap(depth, c, i + a, j + b, receiver, slope, x, y)]
    if not blockers:
        return 1.0
    half = np.clip(0.5 * (float(receiver) - np.mean(np.float64(blockers))) * width, 0.5, radius)
    return ref_tent_sum(depth, c, x, y, receiver, slope, half, radius)


def random_case(seed, *, count=2, resolution=16, n=60, radius=3):
    rng = np.random.default_rng(seed)
    depth = rng.uniform(0.0, 10.0, (count, resolution, resolution)).astype(np.float32)
    depth[rng.random(depth.shape) < 0.1] = np.inf
    coords = rng.integers(radius * UNIT, (resolution - radius) * UNIT, (count, n, 2))
    receiver = rng.uniform(0.0, 10.0, (count, n)).astype(np.float32)
    slope = rng.normal(0.0, 0.5, (count, n, 2))
    cascade = rng.integers(0, count, n).astype(np.int32)
    return depth, coords, receiver, slope, cascade


@pytest.mark.parametrize("filter, width", [("pcf_gaussian", 0.8), ("pcf_gaussian", 2.0), ("pcf_tent", 2.5),
                                           ("pcf_tent", 0.7), ("pcf_poisson", 2.5), ("pcss", 0.4)])
def test_weighted_pcf_equals_the_numpy_reference(filter, width, device):
    depth, coords, receiver, slope, cascade = random_case(5)
    radius = 3
    disk = poisson_disk(16, seed=3)
    angle = np.random.default_rng(2).uniform(0, 2 * np.pi, cascade.shape[0])
    lit = weighted_pcf(depth, coords, receiver, cascade=cascade, filter=filter, width=width, radius=radius,
                       bits=BITS, receiver_slope=slope, disk=disk, angle=angle, device=device)
    expected = [ref_lit(filter, depth, c, *coords[c, k], receiver[c, k], slope[c, k], width, radius, disk, angle[k])
                for k, c in enumerate(cascade)]
    np.testing.assert_allclose(lit, expected, atol=1e-5)


def test_weighted_pcf_blend_mixes_the_next_cascade_by_its_weight(device):
    depth, coords, receiver, slope, _ = random_case(8)
    n = coords.shape[1]
    zero = np.zeros(n, np.int32)
    weight = np.linspace(0.0, 0.9, n)
    args = dict(filter="pcf_tent", width=1.5, radius=2, bits=BITS, receiver_slope=slope, device=device)
    mixed = weighted_pcf(depth, coords, receiver, cascade=zero, blend_weight=weight, **args)
    first = weighted_pcf(depth, coords, receiver, cascade=zero, **args)
    second = weighted_pcf(depth, coords, receiver, cascade=zero + 1, **args)
    np.testing.assert_allclose(mixed, (1 - weight) * first + weight * second, atol=1e-6)


def test_unity_tent_5x5_weights_sum_to_one_over_six_texels():
    # Unity's 5×5 tent: half-width 2.5 texels reaches exactly 6 texels per axis wherever the point lies.
    for t in np.linspace(0.0, 0.999, 7):
        w = ref_tent_weights(t, 2.5, -3, 3)
        assert np.count_nonzero(w > 1e-12) == 6
        assert w.sum() == pytest.approx(1.0, abs=1e-6)
    assert FILTER_METHODS["pcf_tent"].radius_of(ShadowSettings(filter="pcf_tent", filter_size=5)) == 3


def test_a_lit_receiver_is_fully_lit_and_a_buried_one_fully_shadowed_by_every_filter(device):
    depth = np.full((1, 16, 16), 5.0, np.float32)
    coords = np.array([[[8 * UNIT + 37, 8 * UNIT + 200], [7 * UNIT, 9 * UNIT + 1]]])
    disk = poisson_disk(12, seed=1)
    for filter in WEIGHTED:
        width = 0.3 if filter == "pcss" else 1.7
        for receiver, expected in ((4.0, 1.0), (6.0, 0.0)):
            lit = weighted_pcf(depth, coords, np.full((1, 2), receiver, np.float32), cascade=np.zeros(2, np.int32),
                               filter=filter, width=width, radius=3, bits=BITS, disk=disk, device=device)
            np.testing.assert_allclose(lit, expected, atol=1e-6, err_msg=filter)


TEXEL = 0.5
"""Metres per texel of the one cascade of :func:`lit_at_texel_centre`."""


def lit_at_texel_centre(depth, settings, *, receiver_depth=10.0, device="cpu"):
    """S through the whole lookup of one flat receiver facing the light at the centre of texel (8, 8).

    One 16 × 16 cascade of 0.5 m texels with its box at the light-space origin; no normal offset,
    no bias, no receiver-plane slope: the receiver's depth is ``receiver_depth`` at every tap.
    """
    basis = light_basis([0.2, -1.0, 0.1])
    cascade = Cascade(split_near=0.1, split_far=50.0, slice_near=0.1, slice_far=50.0,
                      texel_size=np.array([TEXEL, TEXEL]), origin=np.zeros(2), resolution=16, depth_near=0.0,
                      depth_far=20.0)
    cascades = CascadeSet(basis=basis, zref=0.0, splits=np.array([0.1, 50.0]), cascades=(cascade,), margin_texels=1)
    point = np.array([[8.5 * TEXEL, 8.5 * TEXEL, receiver_depth]]) @ basis
    settings = settings.replace(cascades=1, resolution=16, normal_offset=0.0, bias_constant=0.0, bias_slope=0.0,
                                receiver_plane_bias=False)
    maps = ShadowMaps(cascades=cascades, depth=depth, texels_rasterized=0)
    found = lookup_shadow(maps, points=point, normals=-basis[2:].astype(np.float32), view_depth=np.array([1.0]),
                          settings=settings, device=device)
    assert found.cascade.tolist() == [0]
    return float(found.lit[0])


@pytest.mark.parametrize("fields, sigma", [({"filter_sigma": 0.8}, 0.8), ({"filter_sigma": 1.2}, 1.2),
                                           ({"filter_width_m": 3.0}, 1.5)],
                         ids=["sigma", "wide_sigma", "width_in_metres"])
def test_pcf_gaussian_weighs_known_blockers_with_the_gaussian_of_its_sigma(fields, sigma, device):
    # Oracle: the DirectX sample's Gaussian over the 5 × 5 texels around texel (8, 8), written out:
    # w(di, dj) = exp(−(di² + dj²) / 2σ²), S = Σ w · lit / Σ w, σ in texels (filter_width_m spans ±2σ:
    # 3 m over 0.5 m texels is σ = 1.5). Blockers (depth 2 m, above the receiver at 10 m) fill
    # column 7 and the texels (9, 9) and (10, 6); every other texel is empty.
    depth = np.full((1, 16, 16), np.inf, np.float32)
    depth[0, :, 7] = 2.0
    depth[0, 9, 9] = 2.0
    depth[0, 6, 10] = 2.0
    offsets = np.arange(-2, 3)
    di, dj = np.meshgrid(offsets, offsets, indexing="xy")
    lit = np.isinf(depth[0, 8 + dj, 8 + di])

    def gaussian(s):
        weights = np.exp(-(di**2 + dj**2) / (2.0 * s**2))
        return float(np.sum(weights * lit) / np.sum(weights))

    got = lit_at_texel_centre(depth, ShadowSettings(filter="pcf_gaussian", filter_size=5, **fields), device=device)
    assert got == pytest.approx(gaussian(sigma), abs=1e-6)
    # The case tells σ from σ / 2 (a width halved anywhere from the settings to the kernel).
    assert abs(gaussian(sigma) - gaussian(sigma / 2)) > 0.01


@pytest.mark.parametrize("half_width", [0.75, 1.0, 1.5, 2.0])
def test_pcss_on_a_hand_worked_half_plane_blocker(half_width, device):
    # Blockers at depth 2 m over texels i < 8, empty elsewhere; a flat receiver at depth 10 m at
    # the centre of texel (8, 8), blocker search over 5 × 5 texels (columns 6 and 7 block: d_b = 2 m).
    # A light of angular diameter θ gives w = (d_r − d_b) · 2 tan(θ/2) / texel penumbra texels
    # (Fernando 2005, for a directional light), a tent of half-width h = w / 2 centred at x = 8.5:
    # the blockers (x < 8) cover (h − ½)² / 2h² of its area, so S = 1 − (h − ½)² / 2h².
    theta = 2.0 * np.degrees(np.arctan(half_width * TEXEL / (10.0 - 2.0)))
    assert 0.5 * (10.0 - 2.0) * 2.0 * np.tan(np.radians(theta) / 2.0) / TEXEL == pytest.approx(half_width)
    depth = np.full((1, 16, 16), np.inf, np.float32)
    depth[0, :, :8] = 2.0
    expected = 1.0 - (half_width - 0.5) ** 2 / (2.0 * half_width**2)
    got = lit_at_texel_centre(depth, ShadowSettings(filter="pcss", filter_size=5, light_size_deg=theta), device=device)
    assert got == pytest.approx(expected, abs=1e-6)
    # No blocker in reach: fully lit.
    assert lit_at_texel_centre(np.full((1, 16, 16), np.inf, np.float32),
                               ShadowSettings(filter="pcss", filter_size=5, light_size_deg=theta), device=device) == 1.0


@pytest.mark.parametrize("filter", WEIGHTED)
def test_weighted_pcf_is_bit_identical_when_the_box_moves_by_whole_texels(filter, device):
    # The same world: maps shifted by (3, −2) texels and receivers' local coordinates with them.
    depth, coords, receiver, slope, cascade = random_case(11, resolution=24, radius=6)
    moved = np.full_like(depth, np.inf)
    moved[:, 2:, :21] = depth[:, :22, 3:]
    shift = np.array([-3 * UNIT, 2 * UNIT])
    args = dict(cascade=cascade, filter=filter, width=0.35 if filter == "pcss" else 2.2, radius=3, bits=BITS,
                receiver_slope=slope, disk=poisson_disk(16, seed=1), device=device)
    inside = np.all((coords >= 6 * UNIT) & (coords < 18 * UNIT), axis=(0, 2))
    before = weighted_pcf(depth, coords, receiver, **args)
    after = weighted_pcf(moved, coords + shift, receiver, **args)
    np.testing.assert_array_equal(before[inside], after[inside])


def test_poisson_disk_is_fixed_by_its_seed_and_lies_in_the_unit_disk():
    a, b, c = poisson_disk(16, seed=4), poisson_disk(16, seed=4), poisson_disk(16, seed=5)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    assert np.all(np.linalg.norm(a, axis=1) <= 1.0)
    # Blue noise: no two taps closer than a third of the mean spacing of 16 points in the unit disk.
    gaps = np.linalg.norm(a[:, None] - a[None], axis=2) + np.eye(16) * 9
    assert gaps.min() > np.sqrt(np.pi / 16) / 3


def test_interleaved_gradient_noise_matches_jimenez_formula_and_depends_on_the_pixel_only():
    noise = interleaved_gradient_noise(np.array([[0.3, 0.9], [10.0, 3.0], [10.7, 3.2]]))
    expected = (52.9829189 * ((0.06711056 * 10 + 0.00583715 * 3) % 1.0)) % 1.0
    np.testing.assert_allclose(noise, [0.0, expected, expected], atol=1e-9)


def test_weighted_pcf_rejects_an_unknown_filter_naming_the_valid_ones():
    depth, coords, receiver, _, cascade = random_case(1)
    with pytest.raises(ValueError, match="pcf_tent"):
        weighted_pcf(depth, coords, receiver, cascade=cascade, filter="tent", width=1.0, radius=2, bits=BITS)
