"""The temporal maps' kernel against the definition's whole-image NumPy passes, bit for bit."""

import numpy as np
import pytest

from csmlab.kernels.temporal import change_maps

SHAPE = (23, 31)


def _inputs(seed):
    rng = np.random.default_rng(seed)
    visible = rng.random(SHAPE) < 0.8
    rows = np.flatnonzero(visible)
    # Values on both sides of 0.5 and on it, NaN, and infinities, which are not counted.
    largest = np.finfo(np.float32).max
    choices = np.float32([0.0, 0.25, 0.5, 0.5000001, 1.0, np.nan, np.inf, largest, np.nextafter(largest, 0)])
    earlier_lit = np.where(rng.random(rows.size) < 0.5, rng.choice(choices, rows.size),
                           rng.random(rows.size)).astype(np.float32)
    lit = np.where(rng.random(SHAPE) < 0.5, rng.choice(choices, SHAPE), rng.random(SHAPE)).astype(np.float32)
    earlier_cascade = rng.integers(-1, 3, rows.size).astype(np.int8)
    cascade = rng.integers(-1, 3, SHAPE).astype(np.int8)
    earlier_blend, blend = rng.random(rows.size) < 0.2, rng.random(SHAPE) < 0.2
    references = np.where(rng.random((2,) + SHAPE) < 0.2, rng.choice(choices, (2,) + SHAPE),
                          rng.random((2,) + SHAPE)).astype(np.float32)
    return visible, rows, earlier_lit, earlier_cascade, earlier_blend, lit, cascade, blend, references


def _numpy_maps(visible, rows, earlier_lit, earlier_cascade, earlier_blend, lit, cascade, blend, references):
    """The definition (csmlab.metrics.temporal) as whole-image NumPy passes."""
    previous_lit = np.full(SHAPE, np.nan, dtype=np.float32)
    previous_lit.reshape(-1)[rows] = earlier_lit
    previous_cascade = np.full(SHAPE, -1, dtype=np.int8)
    previous_cascade.reshape(-1)[rows] = earlier_cascade
    previous_blend = np.zeros(SHAPE, dtype=bool)
    previous_blend.reshape(-1)[rows] = earlier_blend
    counted = visible & (previous_cascade >= 0) & np.isfinite(previous_lit) & np.isfinite(lit)
    with np.errstate(invalid="ignore"):  # inf - inf where not counted
        change = lit.astype(np.float64) - previous_lit.astype(np.float64)
    if references is not None:
        reference, previous_reference = references
        counted &= np.isfinite(reference) & np.isfinite(previous_reference)
        with np.errstate(invalid="ignore"):
            change -= reference.astype(np.float64) - previous_reference.astype(np.float64)
        state_change = (lit > 0.5).astype(np.int8) - (previous_lit > 0.5).astype(np.int8)
        flipped = state_change != (reference > 0.5).astype(np.int8) - (previous_reference > 0.5).astype(np.int8)
    else:
        flipped = (lit > 0.5) != (previous_lit > 0.5)
    return {"previous_lit": previous_lit, "change": np.where(counted, change, np.nan),
            "flipped": flipped & counted, "counted": counted,
            "same_cascade": counted & (previous_cascade == cascade) & ~previous_blend & ~blend}


@pytest.mark.parametrize("light_moved", [False, True])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_change_maps_are_the_definitions_numpy_passes_bit_for_bit(light_moved, seed):
    visible, rows, earlier_lit, earlier_cascade, earlier_blend, lit, cascade, blend, references = _inputs(seed)
    expected = _numpy_maps(visible, rows, earlier_lit, earlier_cascade, earlier_blend, lit, cascade, blend,
                           references if light_moved else None)
    moved = {"reference": references[0], "previous_reference": references[1]} if light_moved else {}
    got = change_maps(rows, earlier_lit, earlier_cascade, earlier_blend, lit=lit, cascade=cascade, blend=blend,
                      **moved)
    assert got.keys() == expected.keys()
    for name, value in expected.items():
        assert got[name].dtype == value.dtype and got[name].shape == SHAPE, name
        assert got[name].tobytes() == value.tobytes(), name
    # Each subset is neither empty nor everything: the inputs reach every branch.
    for name in ("flipped", "counted", "same_cascade"):
        assert 0 < np.count_nonzero(got[name]) < got[name].size, name


def test_no_visible_pixel_leaves_nothing_counted_and_the_earlier_shadow_undefined():
    lit = np.full(SHAPE, 0.75, dtype=np.float32)
    got = change_maps(np.zeros(0, dtype=np.int64), np.zeros(0, np.float32), np.zeros(0, np.int8), np.zeros(0, bool),
                      lit=lit, cascade=np.zeros(SHAPE, np.int8), blend=np.zeros(SHAPE, bool))
    assert np.isnan(got["previous_lit"]).all() and np.isnan(got["change"]).all()
    assert not (got["counted"].any() or got["flipped"].any() or got["same_cascade"].any())


def test_one_reference_without_the_other_and_results_of_another_length_are_refused():
    visible, rows, earlier_lit, earlier_cascade, earlier_blend, lit, cascade, blend, references = _inputs(3)
    with pytest.raises(ValueError, match="expected both"):
        change_maps(rows, earlier_lit, earlier_cascade, earlier_blend, lit=lit, cascade=cascade, blend=blend,
                    reference=references[0])
    with pytest.raises(ValueError, match=f"earlier_lit: expected {rows.size} values"):
        change_maps(rows, earlier_lit[1:], earlier_cascade, earlier_blend, lit=lit, cascade=cascade, blend=blend)
    for bad in (rows[::-1], np.concatenate((rows[:1], rows[:-1])), np.append(rows[:-1], rows.size * 10)):
        with pytest.raises(ValueError, match="rows: expected .* ascending flat indices"):
            change_maps(bad, earlier_lit, earlier_cascade, earlier_blend, lit=lit, cascade=cascade, blend=blend)
