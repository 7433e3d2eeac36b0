"""Perceptual change: shading, CIEDE2000 wiring, SSIM and ꟻLIP invariants, handling of uncompared pixels."""

import numpy as np
import pytest

from csmlab.camera import CameraPose
from csmlab.cascades import build_cascades
from csmlab.frame import Frame, GBuffer, ShadowLookup, ShadowMaps, View
from csmlab.kernels.visibility import CameraHits
from csmlab.geometry import rotation_looking_at
from csmlab.metrics.perceptual import (FLIP_METHODS, JND_CIEDE2000, PerceptualMaps, changed_windows,
                                       delta_e_2000, flip_map, lab_from_linear_srgb, perceptual_maps,
                                       perceptual_summary, ssim_map)
from csmlab.metrics.shading import shaded_rgb, shading_terms
from csmlab.settings import ShadowSettings

LIGHT_DOWN = np.array([0.0, -1.0, 0.0])

# Sharma, Wu, Dalal (2005), Table 1, pairs 1, 2, 3, 7, 17, 25: (Lab1, Lab2, ΔE00 to 4 decimals).
SHARMA_PAIRS = [
    ((50.0, 2.6772, -79.7751), (50.0, 0.0, -82.7485), 2.0425),
    ((50.0, 3.1571, -77.2803), (50.0, 0.0, -82.7485), 2.8615),
    ((50.0, 2.8361, -74.0200), (50.0, 0.0, -82.7485), 3.4412),
    ((50.0, 0.0, 0.0), (50.0, -1.0, 2.0), 2.3669),
    ((50.0, 2.5, 0.0), (73.0, 25.0, -18.0), 27.1492),
    ((60.2574, -34.0099, 36.2677), (60.4626, -34.1751, 39.4387), 1.2644),
]


def _grey_frame(lit, *, grey=0.5):
    """A frame of a grey floor facing straight up at a light straight down: cos = 1 everywhere."""
    height, width = lit.shape
    pose = CameraPose(position=[0.0, 10.0, 0.0], orientation=rotation_looking_at(LIGHT_DOWN), aspect=width / height)
    settings = ShadowSettings(cascades=1, resolution=32)
    cascades = build_cascades(pose=pose, light_direction=LIGHT_DOWN, scene_corners=np.zeros((1, 3)), settings=settings)
    valid = np.isfinite(lit)
    gbuffer = GBuffer(hits=CameraHits(
        position=np.zeros((height, width, 3)), normal=np.broadcast_to(np.float32([0, 1, 0]), (height, width, 3)),
        triangle=np.where(valid, 0, -1).astype(np.int32), view_depth=np.full((height, width), 10.0, np.float32)),
        albedo=np.full((height, width, 3), grey, np.float32),
    )
    view = View(index=1, pose=pose, light_direction=LIGHT_DOWN, gbuffer=gbuffer, reference=lit.astype(np.float32))
    shadow = ShadowLookup(lit=lit.astype(np.float32), cascade=np.where(valid, 0, -1).astype(np.int8),
                          blend=np.zeros(lit.shape, bool))
    maps = ShadowMaps(cascades=cascades, depth=np.zeros((1, 32, 32), np.float32), texels_rasterized=0)
    return Frame(view=view, settings=settings, maps=maps, shadow=shadow)


def _lightness(y):
    """CIE 1976 L* of relative luminance Y (white Y = 1), from its definition."""
    f = np.where(y > (6 / 29) ** 3, np.cbrt(y), y / (3 * (6 / 29) ** 2) + 4 / 29)
    return 116.0 * f - 16.0


def _delta_e_2000_of_greys(l1, l2):
    """CIEDE2000 of two neutral greys: only the lightness term survives, ΔL / S_L."""
    mean = 0.5 * (l1 + l2)
    s_l = 1.0 + 0.015 * (mean - 50.0) ** 2 / np.sqrt(20.0 + (mean - 50.0) ** 2)
    return np.abs(l2 - l1) / s_l


@pytest.mark.parametrize("lab1, lab2, expected", SHARMA_PAIRS)
def test_delta_e_2000_matches_sharma_published_pairs(lab1, lab2, expected):
    assert delta_e_2000(np.array(lab1), np.array(lab2)) == pytest.approx(expected, abs=1e-4)


def test_lab_from_linear_srgb_of_greys_follows_cie_lightness():
    y = np.array([0.0, 0.01, 0.18, 0.5, 1.0])
    lab = lab_from_linear_srgb(np.repeat(y[:, None], 3, axis=1))
    np.testing.assert_allclose(lab[:, 0], _lightness(y), atol=1e-3)
    np.testing.assert_allclose(lab[:, 1:], 0.0, atol=0.02)


def test_shaded_rgb_is_albedo_times_ambient_plus_lit_cosine():
    albedo = np.float32([[[0.2, 0.4, 0.8]] * 3])
    normal = np.array([[[0, 1, 0], [0, -1, 0], [0, np.sqrt(0.5), np.sqrt(0.5)]]])
    lit = np.array([[1.0, 1.0, 0.5]])
    rgb = shaded_rgb(albedo, normal, lit, light_direction=[0.0, -2.0, 0.0], ambient=0.25)
    expected_irradiance = np.array([0.25 + 1.0, 0.25, 0.25 + 0.5 * np.sqrt(0.5)])
    np.testing.assert_allclose(rgb[0], albedo[0] * expected_irradiance[:, None], rtol=1e-6)
    with pytest.raises(ValueError, match="ambient: expected a non-negative"):
        shaded_rgb(albedo, normal, lit, light_direction=LIGHT_DOWN, ambient=-0.1)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_shaded_rgb_is_the_float64_formula_bit_for_bit(dtype):
    # albedo · (ambient + S · cos), S widened to float64 first: the values the perceptual metrics
    # and the report were pinned with.
    rng = np.random.default_rng(17)
    albedo = rng.random((9, 11, 3))
    normal = rng.normal(size=(9, 11, 3))
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    lit = rng.random((9, 11)).astype(dtype)
    lit[2, 3] = np.nan
    terms = shading_terms(albedo, normal, light_direction=[0.3, -1.0, 0.2])
    expected = terms.albedo * (0.25 + lit.astype(np.float64) * terms.cosine)[..., None]
    rgb = shaded_rgb(albedo, normal, lit, light_direction=[0.3, -1.0, 0.2], ambient=0.25, terms=terms)
    assert rgb.dtype == np.float64 and rgb.tobytes() == expected.tobytes()


def test_shaded_rgb_under_a_coloured_light_is_the_broadcast_formula_bit_for_bit():
    # albedo · (ambient + S · cos · c), as NumPy broadcasts it: the shading multiplies per channel.
    rng = np.random.default_rng(23)
    albedo = rng.random((7, 5, 3))
    normal = rng.normal(size=(7, 5, 3))
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    lit = rng.random((7, 5)).astype(np.float32)
    lit[1, 4] = np.nan
    terms = shading_terms(albedo, normal, light_direction=[0.3, -1.0, 0.2], light_colour=[1.0, 0.8, 0.55])
    expected = terms.albedo * ((lit.astype(np.float64) * terms.cosine)[..., None] * terms.light + 0.25)
    rgb = shaded_rgb(albedo, normal, lit, light_direction=[0.3, -1.0, 0.2], ambient=0.25, terms=terms)
    assert rgb.dtype == np.float64 and rgb.tobytes() == expected.tobytes()


def test_identical_evaluations_give_zero_delta_e_unit_ssim_and_zero_flip():
    rng = np.random.default_rng(4)
    lit = rng.random((48, 64)).astype(np.float32)
    frame = _grey_frame(lit)
    summary = perceptual_summary(perceptual_maps(frame, lit, ambient=0.25))
    assert summary["de2000_mean"] == 0.0 and summary["de2000_p99"] == 0.0 and summary["de2000_frac_jnd"] == 0.0
    assert summary["ssim"] == pytest.approx(1.0, abs=1e-12)
    assert summary["flip"] == 0.0


@pytest.mark.parametrize("changed_fraction", [0.0, 0.005, 0.3])
def test_delta_e_statistics_are_numpy_mean_percentile_and_fraction_of_the_compared_pixels(changed_fraction):
    # The 99th percentile partitions the compared values in place: the mean and the fraction must
    # still be the sums in image order, and the percentile NumPy's, exactly.
    rng = np.random.default_rng(21)
    shape = (40, 56)
    compared = rng.random(shape) < 0.9
    de2000 = np.where(rng.random(shape) < changed_fraction, rng.gamma(0.8, 1.5, shape), 0.0)
    de2000[~compared] = np.nan
    lit = np.ones(shape, np.float32)
    shaded = np.full(shape + (3,), 0.5)
    maps = PerceptualMaps(lit=lit, previous_lit=lit, shaded=shaded, previous_shaded=shaded, de2000=de2000,
                          compared=compared)
    summary = perceptual_summary(maps)
    values = de2000[compared]
    assert summary["de2000_mean"] == float(np.mean(values, dtype=np.float64))
    assert summary["de2000_p99"] == float(np.percentile(values, 99.0))
    assert summary["de2000_frac_jnd"] == float(np.mean(values > JND_CIEDE2000))


def test_shadowed_block_gives_the_grey_lightness_difference_on_its_pixels_only():
    lit = np.ones((48, 64), np.float32)
    previous = lit.copy()
    previous[10:20, 30:50] = 0.0
    maps = perceptual_maps(_grey_frame(lit, grey=0.5), previous, ambient=0.25)
    summary = perceptual_summary(maps)
    expected = _delta_e_2000_of_greys(_lightness(0.5 * 1.25), _lightness(0.5 * 0.25))
    changed = previous == 0.0
    np.testing.assert_allclose(maps.de2000[changed], expected, rtol=1e-3)
    assert np.all(maps.de2000[~changed] == 0.0)
    assert summary["de2000_frac_jnd"] == pytest.approx(changed.mean(), abs=1e-12)
    assert expected > JND_CIEDE2000
    assert summary["ssim"] < 0.9 and summary["flip"] > 0.0


def test_uncompared_pixels_add_no_difference():
    # Frame t−1 has no shadow value on the left third and frame t misses the top rows: identical
    # elsewhere, so every measure must read "no change" however the gaps are filled.
    rng = np.random.default_rng(9)
    lit = rng.random((48, 64)).astype(np.float32)
    lit[:5] = np.nan
    previous = lit.copy()
    previous[:, :20] = np.nan
    maps = perceptual_maps(_grey_frame(lit), previous, ambient=0.25)
    summary = perceptual_summary(maps)
    assert maps.compared.sum() == 43 * 44
    assert np.all(np.isnan(maps.de2000[~maps.compared]))
    assert summary["de2000_mean"] == 0.0
    assert summary["ssim"] == pytest.approx(1.0, abs=1e-12)
    assert summary["flip"] == 0.0


def test_nothing_compared_gives_nan_measures():
    lit = np.ones((16, 16), np.float32)
    summary = perceptual_summary(perceptual_maps(_grey_frame(lit), np.full((16, 16), np.nan), ambient=0.25))
    assert all(np.isnan(v) for v in summary.values())


def _sparse_pair(seed, *, shape=(90, 140), changes=12):
    """Two random images that differ at a few random pixels (some near the edges, some clustered)."""
    rng = np.random.default_rng(seed)
    current = rng.random(shape)
    previous = current.copy()
    rows = np.concatenate([rng.integers(0, shape[0], changes), [0, shape[0] - 1]])
    cols = np.concatenate([rng.integers(0, shape[1], changes), [shape[1] - 1, 0]])
    rows, cols = np.concatenate([rows, rows[:3] + 1]) % shape[0], np.concatenate([cols, cols[:3]])
    previous[rows, cols] = rng.random(rows.size)
    return previous, current, previous != current


@pytest.mark.parametrize("seed", range(4))
def test_windowed_ssim_equals_the_whole_image_ssim_bit_for_bit(seed):
    previous, current, changed = _sparse_pair(seed)
    np.testing.assert_array_equal(ssim_map(previous, current, changed=changed), ssim_map(previous, current))


@pytest.mark.parametrize("method", sorted(FLIP_METHODS))
@pytest.mark.parametrize("seed", range(4))
def test_windowed_flip_equals_the_whole_image_flip_bit_for_bit(seed, method):
    previous, current, changed = _sparse_pair(seed)
    rng = np.random.default_rng(100 + seed)
    albedo = rng.random(current.shape + (3,))
    reference, test = albedo * previous[..., None], albedo * current[..., None]
    whole = flip_map(reference, test, method=method)
    assert np.count_nonzero(whole) > changed.sum()  # the error spreads beyond the changed pixels
    np.testing.assert_array_equal(flip_map(reference, test, changed=changed, method=method), whole)


@pytest.mark.parametrize("method", sorted(FLIP_METHODS))
def test_flip_encoding_only_the_colours_read_gives_the_fully_encoded_images_flip(method):
    from csmlab.srgb import srgb_encoded

    previous, current, changed = _sparse_pair(7)
    albedo = np.random.default_rng(8).random(current.shape + (3,))
    reference, test = albedo * previous[..., None], albedo * current[..., None]
    encoded = (np.ascontiguousarray(srgb_encoded(x), dtype=np.float32) for x in (reference, test))
    np.testing.assert_array_equal(flip_map(reference, test, method=method), FLIP_METHODS[method](*encoded))


def test_flip_of_changes_over_most_of_the_image_equals_flip_evaluators_windows():
    # Changes every 12 pixels: windows cover the image; the Warp method takes the whole image at
    # once, flip_evaluator its windows.
    previous, current, _ = _sparse_pair(5)
    previous[::12, ::12] = 1.0 - current[::12, ::12]
    changed = previous != current
    albedo = np.random.default_rng(6).random(current.shape + (3,))
    reference, test = albedo * previous[..., None], albedo * current[..., None]
    warp = flip_map(reference, test, changed=changed)
    oracle = flip_map(reference, test, changed=changed, method="flip-evaluator")
    assert np.abs(warp - oracle).max() <= 1e-5
    assert abs(warp.mean(dtype=np.float64) - oracle.mean(dtype=np.float64)) <= 1e-6 * oracle.mean()


def test_unknown_flip_method_is_refused_with_the_names():
    image = np.zeros((4, 4, 3))
    with pytest.raises(ValueError, match="flip method: expected one of \\['flip-evaluator', 'warp'\\]"):
        flip_map(image, image, method="wrap")


def test_windowed_delta_e_equals_the_whole_image_delta_e_bit_for_bit():
    previous, current, changed = _sparse_pair(7)
    frame = _grey_frame(current.astype(np.float32))
    maps = perceptual_maps(frame, previous.astype(np.float32), ambient=0.25)
    whole = delta_e_2000(lab_from_linear_srgb(maps.shaded.reshape(-1, 3)),
                         lab_from_linear_srgb(maps.previous_shaded.reshape(-1, 3))).reshape(current.shape)
    np.testing.assert_array_equal(maps.de2000, whole)
    assert np.all(whole[~changed] == 0.0)


def test_changed_windows_cover_every_pixel_within_the_support_exactly_once():
    _, _, changed = _sparse_pair(3)
    support = 4
    windows = changed_windows(changed, support=support)
    covered = np.zeros(changed.shape, int)
    for (rows, cols), keep in windows:
        covered[rows, cols] += keep
        # A kept pixel's whole support lies in its window or beyond the image's edge.
        r, c = np.nonzero(keep)
        assert np.all((r >= support) | (rows.start == 0)) and np.all((c >= support) | (cols.start == 0))
        assert np.all((r < keep.shape[0] - support) | (rows.stop == changed.shape[0]))
        assert np.all((c < keep.shape[1] - support) | (cols.stop == changed.shape[1]))
    rr, cc = np.nonzero(changed)
    near = np.zeros(changed.shape, bool)
    for r, c in zip(rr, cc):
        near[max(r - support, 0):r + support + 1, max(c - support, 0):c + support + 1] = True
    np.testing.assert_array_equal(covered, near.astype(int))
    assert changed_windows(np.zeros((5, 5), bool), support=2) == []


def test_changes_everywhere_make_the_whole_image_one_window():
    changed = np.zeros((40, 60), bool)
    changed[::6, ::6] = True
    ((rows, cols), keep), = changed_windows(changed, support=4)
    assert (rows, cols) == (slice(0, 40), slice(0, 60)) and keep[changed].all()


def test_shading_with_the_views_shared_terms_equals_shading_from_scratch():
    rng = np.random.default_rng(4)
    albedo = rng.random((6, 7, 3)).astype(np.float32)
    normal = rng.normal(size=(6, 7, 3)).astype(np.float32)
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    lit = rng.random((6, 7)).astype(np.float32)
    lit[0, 0] = np.nan
    terms = shading_terms(albedo, normal, light_direction=[0.3, -1.0, 0.2])
    np.testing.assert_array_equal(
        shaded_rgb(albedo, normal, lit, light_direction=[0.3, -1.0, 0.2], ambient=0.25, terms=terms),
        shaded_rgb(albedo, normal, lit, light_direction=[0.3, -1.0, 0.2], ambient=0.25))


def test_previous_shading_shaded_only_where_s_differs_equals_shading_the_whole_image_bit_for_bit():
    rng = np.random.default_rng(5)
    current = np.where(rng.random((24, 32)) < 0.1, np.nan, rng.random((24, 32))).astype(np.float32)
    previous = current.copy()
    previous[rng.random(current.shape) < 0.05] = np.nan
    previous[3:9, 4:20] = rng.random((6, 16))
    frame = _grey_frame(current)
    g = frame.view.gbuffer
    maps = perceptual_maps(frame, previous, ambient=0.25)
    whole = shaded_rgb(g.albedo, g.normal, previous, light_direction=LIGHT_DOWN, ambient=0.25)
    assert maps.previous_shaded.tobytes() == whole.tobytes()


@pytest.mark.parametrize("channels", [(), (3,)])
def test_filled_pair_is_nan_to_num_of_current_and_previous_where_compared(channels):
    from csmlab.metrics.perceptual import _filled_pair

    rng = np.random.default_rng(23)
    current = rng.random((12, 15) + channels)
    previous = rng.random((12, 15) + channels)
    current[rng.random(current.shape) < 0.2] = np.nan
    compared = rng.random((12, 15)) < 0.7
    for infinities in (False, True):
        if infinities:
            current[0, 0], current[1, 1] = np.inf, -np.inf
        filled_current, filled_previous = _filled_pair(current, previous, compared)
        expected = np.nan_to_num(current, nan=0.0)
        mask = compared if not channels else compared[..., None]
        assert filled_current.tobytes() == expected.tobytes()
        assert filled_previous.tobytes() == np.where(mask, previous, expected).tobytes()
        assert not np.shares_memory(filled_current, current)


def test_filling_uncompared_pixels_window_by_window_equals_filling_the_whole_images():
    from csmlab.metrics.perceptual import _filled_pair

    rng = np.random.default_rng(9)
    previous = rng.random((40, 56)).round(1)
    current = previous.copy()
    current[10:14, 20:30] = rng.random((4, 10))
    current[30, 5] = np.nan
    compared = np.isfinite(current) & (rng.random((40, 56)) < 0.95)
    changed = compared & (current != previous)
    whole_current, whole_previous = _filled_pair(current, previous, compared)
    np.testing.assert_array_equal(ssim_map(previous, current, changed=changed, compared=compared),
                                  ssim_map(whole_previous, whole_current, changed=changed))
    shaded = np.repeat(current[..., None], 3, axis=-1) * [0.9, 0.8, 0.7]
    previous_shaded = np.repeat(previous[..., None], 3, axis=-1) * [0.9, 0.8, 0.7]
    whole_shaded, whole_previous_shaded = _filled_pair(shaded, previous_shaded, compared)
    for method in FLIP_METHODS:
        np.testing.assert_array_equal(
            flip_map(previous_shaded, shaded, changed=changed, compared=compared, method=method),
            flip_map(whole_previous_shaded, whole_shaded, changed=changed, method=method))


def _assert_maps_equal_their_windowed_values(previous, current, changed):
    """ssim_map and flip_map of a grey pair (and its tinted RGB) equal the maps filtered window by window."""
    from csmlab.metrics.perceptual import FLIP_SUPPORT, SSIM_SUPPORT, _flip_warp, _ssim_full, _windowed
    from csmlab.srgb import srgb_encoded

    windowed = _windowed(_ssim_full, (previous, current), changed_windows(changed, support=SSIM_SUPPORT),
                         shape=current.shape, fill=1.0, dtype=np.float64)
    np.testing.assert_array_equal(ssim_map(previous, current, changed=changed), windowed)
    rgb, previous_rgb = (np.repeat(x[..., None], 3, axis=-1) * [0.9, 0.7, 0.5] for x in (current, previous))

    def flip(a, b):
        return _flip_warp(np.ascontiguousarray(srgb_encoded(a), dtype=np.float32),
                          np.ascontiguousarray(srgb_encoded(b), dtype=np.float32))

    windowed = _windowed(flip, (previous_rgb, rgb), changed_windows(changed, support=FLIP_SUPPORT),
                         shape=current.shape, fill=0.0, dtype=np.float32)
    np.testing.assert_array_equal(flip_map(previous_rgb, rgb, changed=changed), windowed)


def test_wide_changes_filtered_whole_give_the_windowed_values():
    from csmlab.metrics.perceptual import WIDE_CHANGE

    rng = np.random.default_rng(21)
    previous = rng.random((48, 64)).round(1)
    current = previous.copy()
    spots = rng.random((48, 64)) < 0.02
    current[spots] = rng.random(spots.sum())
    changed = current != previous
    assert changed.mean() > WIDE_CHANGE
    _assert_maps_equal_their_windowed_values(previous, current, changed)


def test_encoding_with_compared_fills_only_the_pixels_read_and_gives_the_filled_pairs_encoding():
    from csmlab.metrics.perceptual import _encoded_where_read, _filled_pair

    rng = np.random.default_rng(41)
    previous = rng.random((30, 44, 3)).round(1)
    current = previous.copy()
    current[8:12, 5:30] = rng.random((4, 25, 3))
    current[20, 40] = np.nan
    compared = rng.random((30, 44)) < 0.9
    previous[~compared] = rng.random((np.count_nonzero(~compared), 3))
    for odd in (None, np.inf, -np.inf, np.nan):
        if odd is not None:
            # A compared pixel whose test colour is not finite: filled, it is nan_to_num's value,
            # here the reference's own (the filled pair agrees there), and once not.
            current[2, 3, 1] = odd
            previous[2, 3] = np.nan_to_num(current[2, 3])
            current[4, 6, 2] = odd
            compared[2, 3] = compared[4, 6] = True
        filled_current, filled_previous = _filled_pair(current, previous, compared)
        expected = _encoded_where_read(filled_previous, filled_current)
        got = _encoded_where_read(previous, current, compared=compared)
        for a, b in zip(got, expected):
            assert a.dtype == b.dtype and a.tobytes() == b.tobytes()


def test_few_changes_whose_windows_cover_much_of_the_image_are_filtered_whole_to_the_windowed_values():
    from csmlab.metrics.perceptual import (FLIP_SUPPORT, FLIP_WHOLE_ABOVE, SSIM_SUPPORT, SSIM_WHOLE_ABOVE, WIDE_CHANGE,
                                           _windows_or_whole)

    rng = np.random.default_rng(22)
    previous = rng.random((90, 120)).round(1)
    current = previous.copy()
    for row, column in ((10, 15), (45, 100), (80, 60), (20, 70)):
        current[row, column] = 1.0 - previous[row, column]
    changed = current != previous
    assert 0 < changed.mean() <= WIDE_CHANGE
    # Scattered: their windows cover more of the image than the whole image's kernels cost.
    assert _windows_or_whole(changed, support=SSIM_SUPPORT, whole_above=SSIM_WHOLE_ABOVE) is None
    assert _windows_or_whole(changed, support=FLIP_SUPPORT, whole_above=FLIP_WHOLE_ABOVE) is None
    # One change in a frame-sized image keeps its window (21 × 21 pixels for SSIM).
    one = np.zeros((360, 640), dtype=bool)
    one[45, 100] = True
    assert len(_windows_or_whole(one, support=SSIM_SUPPORT, whole_above=SSIM_WHOLE_ABOVE)) == 1
    assert len(_windows_or_whole(one, support=FLIP_SUPPORT, whole_above=FLIP_WHOLE_ABOVE)) == 1
    _assert_maps_equal_their_windowed_values(previous, current, changed)
