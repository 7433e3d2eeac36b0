"""Slice intervals: what view depths each cascade's box must hold, by fit and blend band (hand-worked cases)."""

import numpy as np
import pytest

from csmlab.cascades.fit import slice_intervals

SPLITS = np.array([0.5, 10.0, 30.0, 100.0])


def test_cascade_fit_takes_each_split_interval():
    np.testing.assert_array_equal(slice_intervals(SPLITS, method="cascade"),
                                  [[0.5, 10.0], [10.0, 30.0], [30.0, 100.0]])


def test_scene_fit_starts_every_cascade_at_the_near_plane():
    np.testing.assert_array_equal(slice_intervals(SPLITS, method="scene"),
                                  [[0.5, 10.0], [0.5, 30.0], [0.5, 100.0]])


def test_blend_band_starts_later_cascades_earlier_by_a_fraction_of_the_previous_one():
    # b = 0.1: cascade 1 starts 0.1 · (10 − 0.5) = 0.95 m early, cascade 2 0.1 · (30 − 10) = 2 m early.
    np.testing.assert_allclose(slice_intervals(SPLITS, method="cascade", blend_band=0.1),
                               [[0.5, 10.0], [9.05, 30.0], [28.0, 100.0]], rtol=0, atol=1e-12)
    # A scene fit already starts at the near plane: the band changes nothing.
    np.testing.assert_array_equal(slice_intervals(SPLITS, method="scene", blend_band=0.1),
                                  slice_intervals(SPLITS, method="scene"))


def test_unknown_fit_lists_the_known_ones():
    with pytest.raises(ValueError, match=r"fit: expected one of \['cascade', 'scene'\]"):
        slice_intervals(SPLITS, method="tight")
