"""SSIM's Warp kernels against scikit-image's whole-image map (the oracle), bit for bit."""

import numpy as np
import pytest
from skimage.metrics import structural_similarity

from csmlab.kernels.ssim import SSIM_RADIUS, ssim_reach, ssim_where_changed


def _scikit_image(previous, current):
    """scikit-image's SSIM map with the settings of csmlab.metrics.perceptual, on the whole image."""
    return structural_similarity(previous, current, data_range=1.0, gaussian_weights=True, sigma=1.5,
                                 use_sample_covariance=False, full=True)[1]


def _pair(seed, shape, fraction):
    rng = np.random.default_rng(seed)
    current = rng.random(shape)
    previous = current.copy()
    changed = rng.random(shape) < fraction
    # Changes on the edges and corners too, where the filters reflect.
    changed[0, 0] = changed[-1, shape[1] // 2] = changed[shape[0] // 2, -1] = fraction > 0
    previous[changed] = rng.random(np.count_nonzero(changed))
    return previous, current, changed


@pytest.mark.parametrize("shape", [(11, 11), (12, 30), (47, 13), (90, 140)])
@pytest.mark.parametrize("fraction", [0.0, 0.003, 0.05, 1.0])
def test_ssim_where_changed_is_scikit_images_map_bit_for_bit(shape, fraction, device):
    previous, current, changed = _pair(int(fraction * 1000) + shape[0], shape, fraction)
    np.testing.assert_array_equal(ssim_where_changed(previous, current, changed, device=device),
                                  _scikit_image(previous, current))


def test_shadow_like_images_give_scikit_images_map_bit_for_bit(device):
    # Lit fractions: mostly exact 0 and 1 with soft edges, as S is; a shifted edge between the two.
    y, x = np.mgrid[0:60, 0:80]
    current = np.clip((x - 0.4 * y - 20.0) / 3.0, 0.0, 1.0)
    previous = np.clip((x - 0.4 * y - 21.0) / 3.0, 0.0, 1.0)
    np.testing.assert_array_equal(ssim_where_changed(previous, current, previous != current, device=device),
                                  _scikit_image(previous, current))


def test_a_superset_of_the_changes_gives_the_same_map_and_one_out_of_reach(device):
    previous, current, changed = _pair(3, (64, 96), 0.002)
    expected = _scikit_image(previous, current)
    more = changed | (np.random.default_rng(4).random(changed.shape) < 0.05)
    np.testing.assert_array_equal(ssim_where_changed(previous, current, more, device=device), expected)
    out_of_reach = ssim_reach(changed) < 2
    only_changed = ssim_where_changed(previous, current, changed, device=device)
    assert out_of_reach.any() and np.all(only_changed[out_of_reach] == 1.0)


def test_reach_levels_are_the_growths_of_the_changes_along_columns_then_rows():
    changed = np.zeros((31, 41), dtype=bool)
    changed[15, 20] = True
    reach = ssim_reach(changed)
    r = SSIM_RADIUS
    assert reach[15, 20] == 4
    assert reach[15 - r, 20] == reach[15 + r, 20] == 3 and reach[15 - r - 1, 20] == 0
    assert reach[15 - r, 20 - r] == 2 and reach[15, 20 + r + 1] == 1
    assert reach[15, 20 + 2 * r] == 1 and reach[15, 20 + 2 * r + 1] == 0


@pytest.mark.parametrize("previous, current, changed, match", [
    (np.zeros((12, 12)), np.zeros((12, 13)), np.zeros((12, 12), bool), "expected three \\(H, W\\) arrays"),
    (np.zeros((12, 12, 1)), np.zeros((12, 12, 1)), np.zeros((12, 12, 1), bool), "expected three \\(H, W\\) arrays"),
    (np.zeros((12, 12)), np.zeros((12, 12)), np.zeros((12, 11), bool), "expected three \\(H, W\\) arrays"),
    (np.zeros((10, 40)), np.zeros((10, 40)), np.zeros((10, 40), bool), "expected sides of at least 11"),
])
def test_bad_shapes_are_refused(previous, current, changed, match):
    with pytest.raises(ValueError, match=match):
        ssim_where_changed(previous, current, changed)
