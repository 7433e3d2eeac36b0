"""Weighted PCF kernels against brute-force NumPy references, PCSS on a hand-worked case, exact-zero under box moves."""

import numpy as np
import pytest

from csmlab.filters import filter_radius, filter_widths, interleaved_gradient_noise, poisson_disk
from csmlab.kernels.pcf import PCF_KERNELS, pcss_width, weighted_pcf

BITS = 8
UNIT = 2**BITS


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
def test_weighted_pcf_equals_the_numpy_reference(filter, width):
    depth, coords, receiver, slope, cascade = random_case(5)
    radius = 3
    disk = poisson_disk(16, seed=3)
    angle = np.random.default_rng(2).uniform(0, 2 * np.pi, cascade.shape[0])
    lit = weighted_pcf(depth, coords, receiver, cascade=cascade, filter=filter, width=width, radius=radius,
                       bits=BITS, receiver_slope=slope, disk=disk, angle=angle)
    expected = [ref_lit(filter, depth, c, *coords[c, k], receiver[c, k], slope[c, k], width, radius, disk, angle[k])
                for k, c in enumerate(cascade)]
    np.testing.assert_allclose(lit, expected, atol=1e-5)


def test_weighted_pcf_blend_mixes_the_next_cascade_by_its_weight():
    depth, coords, receiver, slope, _ = random_case(8)
    n = coords.shape[1]
    zero = np.zeros(n, np.int32)
    weight = np.linspace(0.0, 0.9, n)
    args = dict(filter="pcf_tent", width=1.5, radius=2, bits=BITS, receiver_slope=slope)
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
    assert filter_radius("pcf_tent", 5) == 3


def test_a_lit_receiver_is_fully_lit_and_a_buried_one_fully_shadowed_by_every_filter():
    depth = np.full((1, 16, 16), 5.0, np.float32)
    coords = np.array([[[8 * UNIT + 37, 8 * UNIT + 200], [7 * UNIT, 9 * UNIT + 1]]])
    disk = poisson_disk(12, seed=1)
    for filter in PCF_KERNELS:
        width = 0.3 if filter == "pcss" else 1.7
        for receiver, expected in ((4.0, 1.0), (6.0, 0.0)):
            lit = weighted_pcf(depth, coords, np.full((1, 2), receiver, np.float32), cascade=np.zeros(2, np.int32),
                               filter=filter, width=width, radius=3, bits=BITS, disk=disk)
            np.testing.assert_allclose(lit, expected, atol=1e-6, err_msg=filter)


def test_pcss_width_and_lit_fraction_on_a_hand_worked_half_plane_blocker():
    # Blockers at depth 2 m over texels i < 8, empty elsewhere; a flat receiver at depth 10 m at
    # the centre of texel (8, 8). Search radius 2: columns 6 and 7 block, so d_b = 2 m. A light of
    # angular diameter θ with 2 tan(θ/2) = 0.125 on texels of 0.5 m gives 0.25 penumbra texels per
    # metre: w = (10 − 2) · 0.25 = 2 texels, a tent of half-width 1 centred at x = 8.5. The
    # blockers cover x < 8, where the tent holds (1 − 0.5)² / 2 = 0.125 of its area: S = 0.875.
    depth = np.full((1, 16, 16), np.inf, np.float32)
    depth[0, :, :8] = 2.0
    coords = np.array([[[8 * UNIT + UNIT // 2, 8 * UNIT + UNIT // 2]]])
    receiver = np.array([[10.0]], np.float32)
    theta = 2.0 * np.degrees(np.arctan(0.125 / 2.0))

    from csmlab.cascades import Cascade, CascadeSet
    from csmlab.geometry import light_basis
    from csmlab.settings import ShadowSettings

    cascade = Cascade(split_near=0.1, split_far=50.0, slice_near=0.1, slice_far=50.0, texel_size=np.array([0.5, 0.5]),
                      origin=np.zeros(2), resolution=16, depth_near=0.0, depth_far=20.0)
    cascades = CascadeSet(basis=light_basis([0.0, -1.0, 0.2]), zref=0.0, splits=np.array([0.1, 50.0]),
                          cascades=(cascade,), margin_texels=3)
    per_metre = filter_widths(cascades, ShadowSettings(filter="pcss", filter_size=5, light_size_deg=theta))
    np.testing.assert_allclose(per_metre, [0.25])
    width = pcss_width(depth, coords, receiver, cascade=np.zeros(1, np.int32), penumbra_per_metre=per_metre,
                       radius=2, bits=BITS)
    np.testing.assert_allclose(width, [2.0])
    lit = weighted_pcf(depth, coords, receiver, cascade=np.zeros(1, np.int32), filter="pcss", width=per_metre,
                       radius=2, bits=BITS)
    np.testing.assert_allclose(lit, [0.875], atol=1e-6)


@pytest.mark.parametrize("filter", sorted(PCF_KERNELS))
def test_weighted_pcf_is_bit_identical_when_the_box_moves_by_whole_texels(filter):
    # The same world: maps shifted by (3, −2) texels and receivers' local coordinates with them.
    depth, coords, receiver, slope, cascade = random_case(11, resolution=24, radius=6)
    moved = np.full_like(depth, np.inf)
    moved[:, 2:, :21] = depth[:, :22, 3:]
    shift = np.array([-3 * UNIT, 2 * UNIT])
    args = dict(cascade=cascade, filter=filter, width=0.35 if filter == "pcss" else 2.2, radius=3, bits=BITS,
                receiver_slope=slope, disk=poisson_disk(16, seed=1))
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
