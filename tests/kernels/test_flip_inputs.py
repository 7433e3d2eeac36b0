"""ꟻLIP's input kernels against NumPy's masks, ``nan_to_num``, gathers and float32 casts, bit for bit."""

import numpy as np
import pytest

from csmlab.kernels.flip_inputs import colours_read, encoded_pair, filled_differences

LARGEST = np.finfo(np.float64).max


def _pair(seed, shape=(17, 29)):
    rng = np.random.default_rng(seed)
    reference = rng.random(shape + (3,)).round(1)
    test = reference.copy()
    changed = rng.random(shape) < 0.15
    test[changed] = rng.random((np.count_nonzero(changed), 3)).round(1)
    # Values nan_to_num fills, and ones it keeps: NaN and infinities in the test, the largest floats in both.
    for pixel in ((1, 2), (3, 4), (5, 6), (7, 8)):
        test[pixel] = reference[pixel]
    test[1, 2, 0], test[3, 4, 1], test[5, 6, 2], test[7, 8, 0] = np.nan, np.inf, -np.inf, LARGEST
    reference[1, 2, 0], reference[3, 4, 1], reference[5, 6, 2], reference[7, 8, 0] = 0.5, LARGEST, -LARGEST, LARGEST
    reference[9, 10, 1] = np.nan
    compared = rng.random(shape) < 0.8
    compared[1, 2] = compared[3, 4] = compared[5, 6] = compared[7, 8] = True
    return reference, test, compared


@pytest.mark.parametrize("seed", [0, 1])
def test_differences_of_the_filled_pair_are_numpys_masks(seed):
    reference, test, compared = _pair(seed)
    unequal = reference != np.nan_to_num(test)
    expected = compared & (unequal[..., 0] | unequal[..., 1] | unequal[..., 2])
    got = filled_differences(reference, test, compared)
    assert got.dtype == bool and np.array_equal(got, expected)
    # Filled, the infinities equal the largest floats; NaN is 0, not the reference's value.
    assert not got[3, 4] and not got[5, 6] and not got[7, 8] and got[1, 2]
    raw = reference != test
    assert np.array_equal(filled_differences(reference, test), raw[..., 0] | raw[..., 1] | raw[..., 2])


def test_colours_read_are_the_filled_tests_and_the_references_gathered_in_row_major_order():
    reference, test, compared = _pair(2)
    differs = filled_differences(reference, test, compared)
    reach = np.where(np.random.default_rng(3).random(differs.shape) < 0.4, 2, 0).astype(np.uint8)
    reach[differs] = 5
    test_read, reference_read = colours_read(reference, test, reach, differs, fill=True)
    assert test_read.tobytes() == np.nan_to_num(test)[reach > 0].tobytes()
    assert reference_read.tobytes() == reference[differs].tobytes()
    unfilled, _ = colours_read(reference, test, reach, differs, fill=False)
    assert unfilled.tobytes() == test[reach > 0].tobytes()


def test_the_encoded_pair_places_each_colour_rounded_to_float32_and_zero_elsewhere():
    rng = np.random.default_rng(4)
    reach = (rng.random((11, 13)) < 0.5).astype(np.uint8) * 3
    differs = (reach > 0) & (rng.random(reach.shape) < 0.3)
    # Float64 values that round to float32 (half-way cases included).
    test_encoded = rng.random((np.count_nonzero(reach), 3))
    test_encoded[0, 0] = 1.0 + 2.0 ** -24
    reference_encoded = rng.random((np.count_nonzero(differs), 3))
    reference_out, test_out = encoded_pair(reach, differs, test_encoded, reference_encoded)
    expected_test = np.zeros(reach.shape + (3,), dtype=np.float32)
    expected_test[reach > 0] = test_encoded
    expected_reference = expected_test.copy()
    expected_reference[differs] = reference_encoded
    assert test_out.dtype == reference_out.dtype == np.float32
    assert test_out.tobytes() == expected_test.tobytes()
    assert reference_out.tobytes() == expected_reference.tobytes()


def test_mismatched_shapes_and_counts_are_refused():
    reference, test, compared = _pair(5)
    with pytest.raises(ValueError, match="test: expected the reference's shape"):
        filled_differences(reference, test[:3])
    with pytest.raises(ValueError, match="compared: expected the images' shape"):
        filled_differences(reference, test, compared[:3])
    with pytest.raises(ValueError, match="reference: expected a C-contiguous float64"):
        filled_differences(np.zeros(reference.shape, np.float32), test)
    reach = np.ones(compared.shape, np.uint8)
    with pytest.raises(ValueError, match="reach, differs: expected the images' shape"):
        colours_read(reference, test, reach[:3], compared, fill=True)
    with pytest.raises(ValueError, match="expected a colour per pixel of the reach"):
        encoded_pair(reach, compared, np.zeros((3, 3)), np.zeros((np.count_nonzero(compared), 3)))
