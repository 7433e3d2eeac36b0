"""Values grouped by cascade against NumPy's masks and compactions."""

import numpy as np
import pytest

from csmlab.kernels.groups import values_by_cascade


def _maps(seed, shape=(19, 27), cascades=4):
    rng = np.random.default_rng(seed)
    values = rng.choice(np.float32([0.25, 0.5, np.nextafter(np.float32(0.5), 0), 1.0, np.nextafter(np.float32(1), 0),
                                    2.0, np.nan]), shape)
    values = np.where(rng.random(shape) < 0.5, values, rng.random(shape) * 2).astype(np.float32)
    other = rng.random(shape).astype(np.float32)
    cascade = rng.integers(-1, cascades, shape).astype(np.int8)
    return values, other, cascade


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_groups_are_each_cascades_values_in_row_major_order_with_numpys_counts(seed):
    values, other, cascade = _maps(seed)
    got = values_by_cascade(values, other, cascade, cascades=4)
    for c in range(4):
        group = got["grouped"][got["bounds"][c]:got["bounds"][c + 1]]
        expected = values[cascade == c]
        assert group.tobytes() == expected.tobytes()
        assert got["below_one"][c] == np.count_nonzero(expected < 1.0)
        assert got["below_half"][c] == np.count_nonzero(expected < 0.5)
    assert got["bounds"][0] == 0 and got["bounds"][-1] == np.count_nonzero(cascade >= 0)
    assert got["other"].tobytes() == other[cascade >= 0].tobytes()


def test_no_pixel_with_a_cascade_gives_empty_groups():
    values, other, cascade = _maps(3)
    got = values_by_cascade(values, other, np.full_like(cascade, -1), cascades=4)
    assert got["grouped"].size == got["other"].size == 0 and got["bounds"].tolist() == [0] * 5
    assert got["below_one"].tolist() == got["below_half"].tolist() == [0] * 4


def test_a_cascade_the_maps_lack_and_mismatched_shapes_are_refused():
    values, other, cascade = _maps(4)
    with pytest.raises(ValueError, match="cascade: expected -1 or indices below 3, got 3"):
        values_by_cascade(values, other, cascade, cascades=3)
    cascade[0, 0] = -2
    with pytest.raises(ValueError, match="got -2"):
        values_by_cascade(values, other, cascade, cascades=4)
    with pytest.raises(ValueError, match="expected one shape"):
        values_by_cascade(values, other[:3], cascade, cascades=4)
