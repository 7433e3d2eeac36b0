"""The shading kernels against a pixel-by-pixel loop of the formula in Python floats (IEEE float64, one rounding an
operation)."""

import numpy as np
import pytest

from csmlab.kernels.shading import shaded_pair, shaded_pixels


def _looped(albedo, cosine, lit, light, ambient):
    """The shading pixel by pixel: S widened to float64, then each product and sum rounded on its own."""
    out = np.empty(np.shape(lit) + (3,))
    for index in np.ndindex(np.shape(lit)):
        irradiance = float(lit[index]) * float(cosine[index])
        for c in range(3):
            scaled = irradiance if light is None else float(light[c]) * irradiance
            out[index + (c,)] = float(albedo[index + (c,)]) * (scaled + ambient)
    return out


def _terms(shape, seed):
    rng = np.random.default_rng(seed)
    albedo = rng.random(shape + (3,))
    cosine = np.maximum(rng.normal(size=shape), 0.0)
    lit = rng.random(shape)
    lit[rng.random(shape) < 0.2] = np.nan
    return albedo, cosine, lit


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("light", [None, (1.0, 0.8, 0.55)])
def test_shaded_pixels_are_the_formula_looped_pixel_by_pixel_bit_for_bit(dtype, light):
    albedo, cosine, lit = _terms((13, 17), seed=3)
    lit = lit.astype(dtype)
    got = shaded_pixels(albedo, cosine, lit, light=light, ambient=0.25)
    expected = _looped(albedo, cosine, lit, light, 0.25)
    assert got.dtype == np.float64 and got.shape == (13, 17, 3)
    assert np.array_equal(np.isnan(got), np.isnan(expected))
    assert np.isnan(got).any()
    assert got[np.isfinite(got)].tobytes() == expected[np.isfinite(expected)].tobytes()


def test_shaded_pixels_of_a_run_longer_than_a_threads_and_of_strided_terms_are_the_loops():
    # 3 × 1500 pixels span three threads' runs; the terms are views that every other row of a larger image makes.
    albedo, cosine, lit = _terms((6, 1500), seed=4)
    got = shaded_pixels(albedo[::2], cosine[::2], lit[::2], ambient=0.0)
    expected = _looped(albedo[::2], cosine[::2], lit[::2], None, 0.0)
    assert np.array_equal(got, expected, equal_nan=True)


@pytest.mark.parametrize("light", [None, (0.5, 1.0, 0.25)])
def test_a_pair_is_two_shadings_and_copies_the_first_where_the_two_shadows_agree(light):
    albedo, cosine, lit = _terms((19, 23), seed=5)
    lit = lit.astype(np.float32)
    other = lit.copy()
    rng = np.random.default_rng(6)
    changed = rng.random(lit.shape) < 0.3
    other[changed] = rng.random(np.count_nonzero(changed))
    other[rng.random(lit.shape) < 0.1] = np.nan
    first, second = shaded_pair(albedo, cosine, lit, other, light=light, ambient=0.25)
    assert np.array_equal(first, _looped(albedo, cosine, lit, light, 0.25), equal_nan=True)
    assert np.array_equal(second, _looped(albedo, cosine, other, light, 0.25), equal_nan=True)
    agree = (lit == other) | (np.isnan(lit) & np.isnan(other))
    assert agree.any() and (~agree).any()
    # Where the two agree the second is the first's value, bit for bit (its NaN too).
    assert first[agree].tobytes() == second[agree].tobytes()


def test_a_one_dimensional_shadow_and_an_empty_one_are_shaded_as_images_are():
    albedo, cosine, lit = _terms((37,), seed=7)
    assert np.array_equal(shaded_pixels(albedo, cosine, lit, ambient=0.5), _looped(albedo, cosine, lit, None, 0.5),
                          equal_nan=True)
    assert shaded_pixels(np.zeros((0, 3)), np.zeros(0), np.zeros(0), ambient=0.5).shape == (0, 3)


def test_terms_of_another_shape_than_the_shadow_are_refused():
    albedo, cosine, lit = _terms((4, 5), seed=8)
    with pytest.raises(ValueError, match=r"albedo, cosine: expected shapes \(4, 6, 3\) and \(4, 6\)"):
        shaded_pixels(albedo, cosine, np.zeros((4, 6)), ambient=0.25)
    with pytest.raises(ValueError, match="other: expected the shape of lit"):
        shaded_pair(albedo, cosine, lit, lit[:3], ambient=0.25)

