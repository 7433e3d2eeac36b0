"""The report's record kernels against pixel-by-pixel loops and NumPy's own reductions, bit for bit."""

from __future__ import annotations

import math

import numpy as np
import pytest

from csmlab.kernels.records import animation_codes, cell_sums, grid_cells, log2_histogram


def _points(height, width, *, seed):
    """World points over and beyond a 6 × 5 grid of 2.5 m cells at x = -3, z = 4: some on cell edges, some NaN."""
    rng = np.random.default_rng(seed)
    p = rng.uniform(-10.0, 25.0, size=(height, width, 3))
    on_edge = rng.random((height, width)) < 0.2
    p[..., 0][on_edge] = -3.0 + 2.5 * rng.integers(-1, 8, np.count_nonzero(on_edge))
    p[rng.random((height, width)) < 0.1] = np.nan
    p[0, 0] = (-3.0, 0.0, 4.0)
    p[0, 1] = (-3.0 + 2.5 * 6, 0.0, 4.0)
    p[0, 2] = (np.inf, 0.0, 5.0)
    return p


def test_grid_cells_are_the_floors_of_each_point_or_minus_one_outside():
    p = _points(7, 13, seed=1)
    cells = grid_cells(p, x0=-3.0, z0=4.0, cell=2.5, nx=6, nz=5)
    for (i, j), got in np.ndenumerate(cells):
        x, z = p[i, j, 0], p[i, j, 2]
        column = math.floor((x - -3.0) / 2.5) if math.isfinite(x) else -1
        row = math.floor((z - 4.0) / 2.5) if math.isfinite(z) else -1
        inside = math.isfinite(x) and math.isfinite(z) and 0 <= column < 6 and 0 <= row < 5
        assert got == (row * 6 + column if inside else -1), (i, j, x, z)
    assert cells[0, 0] == 0 and cells[0, 1] == -1 and cells[0, 2] == -1


def test_grid_cells_refuses_anything_but_an_image_of_points():
    with pytest.raises(ValueError, match="positions"):
        grid_cells(np.zeros((4, 3)), x0=0.0, z0=0.0, cell=1.0, nx=2, nz=2)


def _change(shape, *, seed):
    rng = np.random.default_rng(seed)
    change = rng.random(shape) ** 3 * np.where(rng.random(shape) < 0.5, -1.0, 1.0)
    change[rng.random(shape) < 0.2] = np.nan
    change[rng.random(shape) < 0.02] = np.inf
    return change


def test_cell_sums_keep_the_bits_of_bincount_and_of_a_pixel_by_pixel_sum():
    rng = np.random.default_rng(3)
    shape, size = (19, 23), 11
    cells = rng.integers(-1, size, shape)
    change = np.abs(_change(shape, seed=4))
    flipped = rng.random(shape) < 0.3
    change_sum, counted, flips = cell_sums(cells, change, flipped, size=size)
    kept = np.isfinite(change) & (cells >= 0)
    np.testing.assert_array_equal(change_sum.view(np.int64),
                                  np.bincount(cells[kept], weights=change[kept], minlength=size).view(np.int64))
    expected = [0.0] * size
    for (i, j), c in np.ndenumerate(cells):
        if kept[i, j]:
            expected[c] += float(change[i, j])
    assert change_sum.tolist() == expected
    assert counted.tolist() == np.bincount(cells[kept], minlength=size).tolist()
    assert flips.tolist() == np.bincount(cells[kept & flipped], minlength=size).tolist()
    assert counted.dtype == flips.dtype == np.int64


def test_cell_sums_count_the_largest_floats_as_finite_and_leave_out_infinities_and_nan():
    largest = np.finfo(np.float64).max
    change = np.array([[largest, np.nextafter(largest, 0.0), np.inf, -np.inf, np.nan, 1.0]])
    change_sum, counted, flips = cell_sums(np.array([[0, 1, 2, 2, 2, 3]]), change, np.ones((1, 6), bool), size=4)
    assert change_sum.tolist() == [largest, np.nextafter(largest, 0.0), 0.0, 1.0]
    assert counted.tolist() == [1, 1, 0, 1] and flips.tolist() == [1, 1, 0, 1]


def test_cell_sums_refuse_a_cell_beyond_the_grid_and_mismatched_shapes():
    with pytest.raises(ValueError, match="below 4"):
        cell_sums(np.full((2, 2), 4), np.zeros((2, 2)), np.zeros((2, 2), bool), size=4)
    with pytest.raises(ValueError, match="three"):
        cell_sums(np.zeros((2, 2), np.int64), np.zeros((2, 3)), np.zeros((2, 2), bool), size=4)


def _coded(values):
    finite = np.isfinite(values)
    return np.where(finite, np.rint(np.clip(np.where(finite, values, 0.0), 0.0, 1.0) * 254.0), 255).astype(np.uint8)


@pytest.mark.parametrize("k", [1, 2, 3, 7])
def test_animation_codes_are_the_coded_block_mean_and_max_of_a_numpy_reduction_over_the_block_axes(k):
    rng = np.random.default_rng(k)
    height, width = 5 * k + k - 1, 9 * k + 1
    # float64 values of full mantissas: sums of float32 ones would be exact in any order.
    lit = rng.random((height, width))
    lit[rng.random((height, width)) < 0.3] = np.nan
    lit[:k, :k] = np.nan
    change = _change((height, width), seed=k)
    change[:k, :k] = np.nan
    h, w = height // k, width // k
    blocks = lit[:h * k, :w * k].reshape(h, k, w, k)
    defined = np.isfinite(blocks)
    count = defined.sum(axis=(1, 3))
    mean = np.where(count > 0, np.where(defined, blocks, 0.0).sum(axis=(1, 3)) / np.maximum(count, 1), np.nan)
    magnitude = np.abs(change[:h * k, :w * k]).reshape(h, k, w, k)
    largest = np.where(np.isfinite(magnitude), magnitude, -1.0).max(axis=(1, 3))
    lit_codes, change_codes = animation_codes(lit, change, k=k)
    np.testing.assert_array_equal(lit_codes, _coded(mean))
    np.testing.assert_array_equal(change_codes, _coded(np.where(largest >= 0.0, largest, np.nan)))
    assert lit_codes[0, 0] == change_codes[0, 0] == 255


def test_animation_codes_round_half_to_even_and_clip():
    # Half-way codes and values beyond [0, 1], in blocks of one pixel.
    lit = np.array([[0.5 / 254, 1.5 / 254, 2.0, -1.0]], dtype=np.float64)
    change = np.array([[2.5 / 254, -3.5 / 254, 7.0, -np.inf]])
    lit_codes, change_codes = animation_codes(lit, change, k=1)
    # 254 · v is exactly 0.5, 1.5, 2.5 and 3.5 here: to the even neighbour, as np.rint rounds.
    assert lit_codes.tolist() == [[0, 2, 254, 0]]
    assert change_codes.tolist() == [[2, 4, 254, 255]]


def test_animation_codes_refuse_blocks_of_eight_pixels_or_more():
    with pytest.raises(ValueError, match="1 to 7"):
        animation_codes(np.zeros((8, 8)), np.zeros((8, 8)), k=8)


def test_log2_histogram_counts_each_defined_pixel_in_its_bin_among_the_edges_by_group():
    rng = np.random.default_rng(7)
    edges = np.linspace(-2.0, 2.0, 33)
    shape = (13, 17)
    # Values on the edges, one ulp either side of them, and beyond both ends.
    on_edges = rng.choice(edges, shape)
    values = np.where(rng.random(shape) < 0.5, on_edges, rng.uniform(-3.0, 3.0, shape))
    values = np.where(rng.random(shape) < 0.2, np.nextafter(values, rng.choice([-np.inf, np.inf], shape)), values)
    group = rng.integers(0, 3, shape)
    defined = rng.random(shape) < 0.8
    counts = log2_histogram(values, group, defined, edges=edges, groups=3)
    expected = np.zeros((3, 32), dtype=np.int64)
    for (i, j), v in np.ndenumerate(values):
        if defined[i, j]:
            expected[group[i, j], min(max(np.searchsorted(edges, v, side="right") - 1, 0), 31)] += 1
    np.testing.assert_array_equal(counts, expected)


def test_log2_histogram_refuses_a_defined_pixel_outside_the_groups():
    group = np.array([[0, 3]])
    with pytest.raises(ValueError, match="1 pixels outside"):
        log2_histogram(np.zeros((1, 2)), group, np.ones((1, 2), bool), edges=np.linspace(0, 1, 5), groups=3)
    assert log2_histogram(np.zeros((1, 2)), group, np.array([[True, False]]), edges=np.linspace(0, 1, 5),
                          groups=3).sum() == 1
