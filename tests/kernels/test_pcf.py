"""Weighted PCF kernels against brute-force NumPy references; Gaussian and PCSS through the lookup on hand-worked
cases; exact-zero under box moves."""

import numpy as np
import pytest
import warp as wp

from csmlab.cascades import Cascade, CascadeSet
from csmlab.filters import interleaved_gradient_noise, lookup_shadow
from csmlab.frame import ShadowMaps
from csmlab.geometry import light_basis
from csmlab.kernels.pcf import AXIS_TAPS, axis_table, axis_tables, weighted_pcf
from csmlab.lookup_choices import FILTER_METHODS, PCF_CASTANO, PCF_TENT_BILINEAR, family_filters, poisson_disk
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
    """Per texel k in [lo, hi]: the tent of half-width h centred at t integrated over [k, k + 1) by the midpoint
    rule."""
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


# --- The engines' kernels of hardware bilinear-compare taps, each against its engine's formula written out.


def ref_bilinear(depth, px, py, receiver):
    """A comparison sampler with linear filtering at (px, py) texels: the 2×2 texel centres around it, bilinear."""
    i0, j0 = int(np.floor(px - 0.5)), int(np.floor(py - 0.5))
    fx, fy = px - 0.5 - i0, py - 0.5 - j0
    lit = lambda i, j: float(receiver <= depth[j, i])  # noqa: E731
    return ((1 - fy) * ((1 - fx) * lit(i0, j0) + fx * lit(i0 + 1, j0))
            + fy * ((1 - fx) * lit(i0, j0 + 1) + fx * lit(i0 + 1, j0 + 1)))


def ref_vogel(depth, px, py, receiver, *, taps, radius, golden_angle, phi=0.0):
    """Godot 4 ``sample_directional_pcf_shadow`` over ``get_vogel_disk`` (r = sqrt(i + 0.5) / sqrt(n),
    θ = i · 2.4) and three.js ``vogelDiskSample`` (r = sqrt((i + 0.5) / n), θ = i · 2.39996… + φ):
    equal weights of bilinear-compare taps at the point plus radius · r · (cos θ, sin θ)."""
    total = 0.0
    for i in range(taps):
        r = np.sqrt(i + 0.5) / np.sqrt(taps)
        theta = i * golden_angle + phi
        total += ref_bilinear(depth, px + radius * r * np.cos(theta), py + radius * r * np.sin(theta), receiver)
    return total / taps


def ref_castano(depth, px, py, receiver, size):
    """Castaño's kernel as Filament's ``ShadowSample_PCF_Low`` (size 3) and Bevy's
    ``sample_shadow_map_castano_thirteen`` / Stride's ``Get5x5FilterKernel`` (size 5) write it."""
    base_u, base_v = np.floor(px + 0.5), np.floor(py + 0.5)
    s, t = px + 0.5 - base_u, py + 0.5 - base_v
    base_u -= 0.5
    base_v -= 0.5

    def axis(s):
        if size == 3:
            uw = [3 - 2 * s, 1 + 2 * s]
            return uw, [(2 - s) / uw[0] - 1, s / uw[1] + 1], 16.0
        uw = [4 - 3 * s, 7.0, 1 + 3 * s]
        return uw, [(3 - 2 * s) / uw[0] - 2, (3 + s) / uw[1], s / uw[2] + 2], 144.0

    uw, u, norm = axis(s)
    vw, v, _ = axis(t)
    return sum(uw[a] * vw[b] * ref_bilinear(depth, base_u + u[a], base_v + v[b], receiver)
               for a in range(len(u)) for b in range(len(v))) / norm


def ref_dx_box(depth, px, py, receiver, size):
    """DirectX CascadedShadowMaps11 ``CalculatePCFPercentLit``: SampleCmpLevelZero at whole-texel offsets, averaged."""
    r = size // 2
    return sum(ref_bilinear(depth, px + a, py + b, receiver) for a in range(-r, r + 1) for b in range(-r, r + 1)) \
        / size**2


def ref_tent_texels(depth, px, py, receiver, size):
    """Unity's tent of base N (half-width N/2): each texel weighted by the tent's integral over it."""
    i, j = int(px), int(py)
    r = size // 2 + 1
    wx = ref_tent_weights(px, size / 2.0, i - r, i + r, samples=20000)
    wy = ref_tent_weights(py, size / 2.0, j - r, j + r, samples=20000)
    return sum(wx[a] * wy[b] * float(receiver <= depth[j - r + b, i - r + a])
               for a in range(2 * r + 1) for b in range(2 * r + 1))


def blocker_field(seed=4, resolution=24):
    """A 24 × 24 map of blockers at 2 m (a column, a row end, scattered texels) over empty texels, one cascade."""
    rng = np.random.default_rng(seed)
    depth = np.full((resolution, resolution), np.inf, np.float32)
    depth[:, 9] = 2.0
    depth[14, 12:] = 2.0
    depth[rng.random(depth.shape) < 0.25] = 2.0
    return depth


POINTS = [tuple(np.round(np.array(p) * UNIT) / UNIT) for p in
          [(11.5, 11.5), (11.0, 12.0), (12.3, 10.77), (10.9, 13.41), (12.99, 12.01)]]
"""Receiver points in texels (on the 2⁻⁸-texel fixed point): texel centres, texel corners and arbitrary fractions."""


def lit_of(filter, depth, point, *, width, radius, disk=None, angle=0.0, device="cpu"):
    coords = np.round(np.array(point) * UNIT).astype(np.int64)[None, None, :]
    return float(weighted_pcf(depth[None], coords, np.full((1, 1), 10.0, np.float32), cascade=np.zeros(1, np.int32),
                              filter=filter, width=width, radius=radius, bits=BITS, disk=disk,
                              angle=None if angle == 0.0 else np.array([angle]), device=device)[0])


@pytest.mark.parametrize("engine, taps, radius, golden_angle", [("godot4_soft_low", 4, 2.0, 2.4),
                                                                ("threejs_pcf", 5, 1.0, 2.399963229728653)])
@pytest.mark.parametrize("phi", [0.0, 1.3])
def test_pcf_vogel_is_the_engines_vogel_disk_of_bilinear_taps(engine, taps, radius, golden_angle, phi, device):
    depth = blocker_field()
    settings = ShadowSettings(filter="pcf_vogel", vogel_taps=taps, vogel_radius=radius, vogel_angle=golden_angle)
    record = FILTER_METHODS["pcf_vogel"]
    for point in POINTS:
        got = lit_of("pcf_vogel", depth, point, width=float(record.width_of([1.0], settings)[0]),
                     radius=record.radius_of(settings), disk=record.offsets_of(settings), angle=phi, device=device)
        expected = ref_vogel(depth, *point, 10.0, taps=taps, radius=radius, golden_angle=golden_angle, phi=phi)
        # Tap positions are rounded to 2⁻⁸ texel (the hardware's sub-texel precision): a bilinear weight moves < 1/256.
        assert got == pytest.approx(expected, abs=taps * 2.0 / UNIT), (engine, point)


def test_godot_shrinks_the_vogel_radius_with_the_split():
    # scene_forward_lights_inc.glsl: blur_factor = shadow_split_offsets.x / shadow_split_offsets[k] (no blend_splits),
    # the radius directional_shadow_pixel_size · soft_shadow_scale (blur 1.0 × quality radius 2.0) · blur_factor.
    far = np.array([10.09, 20.08, 50.05, 100.0])
    settings = ShadowSettings(filter="pcf_vogel", vogel_taps=4, vogel_radius=2.0, vogel_scale="first_split")
    width = FILTER_METHODS["pcf_vogel"].width_of(np.ones(4), settings, far)
    np.testing.assert_allclose(width, 2.0 * far[0] / far)
    assert FILTER_METHODS["pcf_vogel"].width_of(np.ones(4), settings.replace(vogel_scale="none"), far).tolist() \
        == [2.0] * 4
    assert "pixels" in FILTER_METHODS["pcf_vogel"].reads_of(settings.replace(poisson_rotation="pixel"))
    assert "pixels" not in FILTER_METHODS["pcf_vogel"].reads_of(settings)


@pytest.mark.parametrize("engine, size", [("filament_pcf_low", 3), ("bevy_gaussian_stride_5x5", 5)])
def test_pcf_castano_is_castanos_kernel_of_bilinear_taps(engine, size, device):
    depth = blocker_field(seed=7)
    settings = ShadowSettings(filter="pcf_castano", filter_size=size)
    record = FILTER_METHODS["pcf_castano"]
    for point in POINTS:
        got = lit_of("pcf_castano", depth, point, width=float(record.width_of([1.0], settings)[0]),
                     radius=record.radius_of(settings), device=device)
        assert got == pytest.approx(ref_castano(depth, *point, 10.0, size), abs=2.0 / UNIT), (engine, point)


@pytest.mark.parametrize("size, weights", [(3, [1, 2, 1]), (5, [1, 3, 4, 3, 1])])
def test_pcf_castano_weighs_texels_1_2_1_and_1_3_4_3_1_at_a_texel_centre(size, weights, device):
    # Castaño's kernels at a texel centre are the binomial-like texel weights [1,2,1]/4 and [1,3,4,3,1]/12:
    # a lone blocker at (di, dj) from the receiver's texel takes w(di) · w(dj) of the light.
    w = np.array(weights, float) / sum(weights)
    r = size // 2
    for di, dj in [(-1, 0), (0, 0), (1, 1), (r, -r)]:
        depth = np.full((24, 24), np.inf, np.float32)
        depth[11 + dj, 11 + di] = 2.0
        got = lit_of("pcf_castano", depth, (11.5, 11.5), width=size / 2.0, radius=r + 1, device=device)
        # Castaño's offsets (1/3 texel, …) round to 2⁻⁸ texel, the hardware's sub-texel precision.
        assert got == pytest.approx(1.0 - w[di + r] * w[dj + r], abs=1.0 / UNIT)


@pytest.mark.parametrize("size", [3, 5, 7])
def test_pcf_tent_bilinear_is_unitys_tent_in_bilinear_taps(size, device):
    # Unity's SampleShadow_ComputeSamples_Tent_NxN: the per-texel tent weights, folded two texels per tap and axis.
    depth = blocker_field(seed=9)
    for point in POINTS:
        got = lit_of("pcf_tent_bilinear", depth, point, width=size / 2.0, radius=size // 2 + 1, device=device)
        expected = ref_tent_texels(depth, *point, 10.0, size)
        assert got == pytest.approx(expected, abs=((size + 1) // 2) ** 2 * 2.0 / UNIT), point
    # The same weights as the tent of point taps (pcf_tent), up to the taps' rounding to 2⁻⁸ texel.
    for point in POINTS:
        a = lit_of("pcf_tent_bilinear", depth, point, width=size / 2.0, radius=size // 2 + 1, device=device)
        b = lit_of("pcf_tent", depth, point, width=size / 2.0, radius=size // 2 + 1, device=device)
        assert a == pytest.approx(b, abs=((size + 1) // 2) ** 2 * 2.0 / UNIT)


def test_pcf_tent_bilinear_of_the_largest_filter_size_fills_its_axis_table(device):
    # filter_size 63, the settings' largest: 32 taps per axis, every entry of the per-axis table (AXIS_TAPS).
    assert (63 + 1) // 2 == AXIS_TAPS
    depth = blocker_field(seed=9, resolution=80)
    for point in [(40.5, 40.5), (39.30078125, 41.76953125), (40.98828125, 39.01171875)]:
        got = lit_of("pcf_tent_bilinear", depth, point, width=31.5, radius=33, device=device)
        # The taps' offsets round to 2⁻⁸ texel: a few 10⁻⁵ of S here.
        assert got == pytest.approx(ref_tent_texels(depth, *point, 10.0, 63), abs=2e-4), point


@wp.kernel
def _computed_taps_kernel(code: int, size: int, bits: int, points: wp.array(dtype=wp.int64),
                          texel: wp.array2d(dtype=wp.int64), fraction: wp.array2d(dtype=wp.float64),
                          weight: wp.array2d(dtype=wp.float64)):
    k = wp.tid()
    unit = wp.int64(1) << wp.int64(bits)
    t, f, w = axis_table(code, size, (size + 1) // 2, points[k], unit, bits,
                         wp.float64(1.0) / wp.float64(wp.int64(2) * unit))
    for a in range((size + 1) // 2):
        texel[k, a] = t[a]
        fraction[k, a] = f[a]
        weight[k, a] = w[a]


@pytest.mark.parametrize("code, size, bits", [(PCF_CASTANO, 3, 8), (PCF_CASTANO, 5, 8), (PCF_TENT_BILINEAR, 7, 8),
                                              (PCF_TENT_BILINEAR, 5, 3), (PCF_TENT_BILINEAR, 63, 6)])
def test_axis_tables_hold_the_taps_computed_at_the_point_itself(code, size, bits, device):
    # Each point's taps computed where it lies (axis_table at x) are the table's at its remainder past the nearest
    # texel corner b, moved by b: bit for bit, at every remainder, for points on both sides of the origin and far
    # from it.
    unit = 2**bits
    rng = np.random.default_rng(size + bits)
    corners = np.concatenate([[-3, 0, 1, 7], rng.integers(-2**30, 2**30, 12)]).astype(np.int64)
    points = (corners[:, None] * unit + np.arange(unit) - unit // 2).reshape(-1)
    count = (size + 1) // 2
    computed = [wp.zeros((points.size, count), dtype=dtype, device=device) for dtype in (wp.int64, wp.float64,
                                                                                        wp.float64)]
    wp.launch(_computed_taps_kernel, dim=points.size,
              inputs=(code, size, bits, wp.array(points, dtype=wp.int64, device=device)), outputs=computed,
              device=device)
    tables = axis_tables(code, [size / 2.0, size / 2.0], bits=bits, device=device)
    assert tables.slot.numpy().tolist() == [0, 0]
    remainder = np.arange(unit)[None, :].repeat(corners.size, axis=0).reshape(-1)
    b = np.repeat(corners, unit)
    texel, fraction, weight = (a.numpy()[0, remainder, :count] for a in (tables.texel, tables.fraction,
                                                                          tables.weight))
    np.testing.assert_array_equal(computed[0].numpy(), texel + b[:, None])
    np.testing.assert_array_equal(computed[1].numpy(), fraction)
    np.testing.assert_array_equal(computed[2].numpy(), weight)


def test_axis_tables_keep_one_table_per_filter_size_and_a_stand_in_for_other_filters():
    tables = axis_tables(PCF_TENT_BILINEAR, [2.5, 3.5, 2.5], bits=4, device="cpu")
    assert tables.slot.numpy().tolist() == [0, 1, 0]
    assert tables.texel.shape == (2, 16, 4)
    assert axis_tables(FILTER_METHODS["pcf_gaussian"].code, [1.0, 1.0], bits=8, device="cpu").texel.shape == (1, 1, 1)


def test_weighted_pcf_rejects_a_separable_kernel_wider_than_its_axis_table():
    depth, coords, receiver, _, cascade = random_case(1)
    with pytest.raises(ValueError, match="at most 32 taps per axis"):
        weighted_pcf(depth, coords, receiver, cascade=cascade, filter="pcf_tent_bilinear", width=32.5, radius=34,
                     bits=BITS)


@pytest.mark.parametrize("size", [3, 5])
def test_pcf_bilinear_box_is_the_directx_samples_grid_of_bilinear_taps(size, device):
    depth = blocker_field(seed=3)
    for point in POINTS:
        got = lit_of("pcf_bilinear_box", depth, point, width=size / 2.0, radius=size // 2 + 1, device=device)
        assert got == pytest.approx(ref_dx_box(depth, *point, 10.0, size), abs=1e-6), point


@pytest.mark.parametrize("filter, fields", [("pcf_vogel", {"vogel_taps": 4, "vogel_radius": 2.0}),
                                            ("pcf_castano", {"filter_size": 3}), ("pcf_castano", {"filter_size": 5}),
                                            ("pcf_tent_bilinear", {"filter_size": 7}),
                                            ("pcf_bilinear_box", {"filter_size": 3})])
def test_bilinear_tap_filters_are_bit_identical_when_the_box_moves_by_whole_texels(filter, fields, device):
    settings = ShadowSettings(filter=filter, **fields)
    record = FILTER_METHODS[filter]
    radius = record.radius_of(settings)
    depth, coords, receiver, slope, cascade = random_case(21, resolution=24, radius=6)
    moved = np.full_like(depth, np.inf)
    moved[:, 2:, :21] = depth[:, :22, 3:]
    shift = np.array([-3 * UNIT, 2 * UNIT])
    args = dict(cascade=cascade, filter=filter, width=float(record.width_of([1.0], settings)[0]), radius=radius,
                bits=BITS, receiver_slope=slope, disk=record.offsets_of(settings), device=device)
    # Taps reach 4 texels at most: the shifted maps hold every tap of a receiver in [7, 17)².
    inside = np.all((coords >= 7 * UNIT) & (coords < 17 * UNIT), axis=(0, 2))
    before = weighted_pcf(depth, coords, receiver, **args)
    after = weighted_pcf(moved, coords + shift, receiver, **args)
    np.testing.assert_array_equal(before[inside], after[inside])
    assert not np.all(np.isin(before[inside], (0.0, 1.0)))  # the taps do filter


def test_bilinear_tap_filters_reach_no_further_than_their_radius(device):
    # A blocker ring just beyond the record's radius never shadows; the same ring at the radius does somewhere.
    for filter, fields in [("pcf_vogel", {"vogel_taps": 5, "vogel_radius": 1.0}), ("pcf_castano", {"filter_size": 5}),
                           ("pcf_tent_bilinear", {"filter_size": 7}), ("pcf_bilinear_box", {"filter_size": 3})]:
        settings = ShadowSettings(filter=filter, **fields)
        record = FILTER_METHODS[filter]
        r = record.radius_of(settings)
        depth = np.full((32, 32), 2.0, np.float32)
        depth[16 - r:17 + r, 16 - r:17 + r] = np.inf
        rng = np.random.default_rng(0)
        for _ in range(40):
            point = 16 + rng.random(2)
            for phi in (0.0, 2.0):
                got = lit_of(filter, depth, point, width=float(record.width_of([1.0], settings)[0]), radius=r,
                             disk=record.offsets_of(settings), angle=phi, device=device)
                assert got == 1.0, (filter, point)
