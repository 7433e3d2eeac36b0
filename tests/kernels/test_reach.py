"""csmlab.kernels.reach: masks grown by shifts equal SciPy's maximum filter, and the levels nest."""

import numpy as np
import pytest
from scipy.ndimage import maximum_filter1d

from csmlab.kernels.reach import grown_along, nested_reach


@pytest.mark.parametrize("shape", [(1, 1), (1, 7), (5, 3), (30, 44)])
@pytest.mark.parametrize("density", [0.0, 0.02, 0.3, 1.0])
@pytest.mark.parametrize("radius", [0, 1, 2, 3, 5, 10, 50])
def test_grown_along_each_axis_is_scipys_maximum_filter_of_the_mask(shape, density, radius):
    mask = np.random.default_rng(radius + 7 * shape[1]).random(shape) < density
    for axis in (0, 1):
        expected = maximum_filter1d(mask.view(np.uint8), 2 * radius + 1, axis=axis, mode="nearest").view(bool)
        got = grown_along(mask, radius, axis)
        assert got.dtype == bool
        np.testing.assert_array_equal(got, expected)


def test_grown_along_leaves_its_input_alone_and_refuses_a_negative_radius():
    mask = np.zeros((4, 9), dtype=bool)
    mask[2, 4] = True
    grown = grown_along(mask, 2, 1)
    assert mask.sum() == 1 and grown[2, 2:7].all() and grown.sum() == 5
    with pytest.raises(ValueError, match="radius"):
        grown_along(mask, -1, 0)


def test_nested_reach_counts_the_levels_each_pixel_lies_in():
    changed = np.zeros((40, 50), dtype=bool)
    changed[20, 25] = True
    reach = nested_reach(changed, 3, (1, 0))
    assert reach.dtype == np.uint8
    assert reach[20, 25] == 3                      # changed, grown along rows, then along columns
    assert reach[20, 22] == reach[20, 28] == 2     # within 3 columns of it
    assert reach[17, 25] == reach[23, 22] == 1     # within 3 rows of those
    assert reach[16, 25] == reach[20, 21] == 0
    assert np.count_nonzero(reach) == 7 * 7
