"""Every frame's per-pixel record of the interactive report, checked against brute force."""

import dataclasses

import numpy as np
import pytest
from tests.report.test_capture import _frame

from csmlab.metrics.shading import AMBIENT, shaded_rgb

from csmlab.report.pixels import (
    NO_VALUE,
    RHO_EDGES,
    code_rho,
    decode_rho,
    frame_pixels,
    stack_pixels,
    world_grid,
)
from csmlab.srgb import srgb_encoded

GRID = world_grid([[0.0, 0.0, 0.0], [5.0, 1.0, 3.0]], reach=30.0, cells=16)


def _record(index, **kw):
    frame, measures = _frame(index, **kw)
    rng = np.random.default_rng(index)
    pixels = {**measures.pixels,
              "flipped": np.isfinite(measures.pixels["dS"]) & (rng.random(frame.shadow.lit.shape) > 0.6)}
    return frame, pixels, frame_pixels(frame, pixels, grid=GRID)


def test_sampled_values_are_the_frames_own_pixels_on_a_stride_not_averages():
    frame, pixels, record = _record(1)
    k = record["stride"]
    assert k == 3  # ceil((2 * 320 + 5) / 320)
    h, w = record["lit"].shape
    assert (h, w) == (-(-frame.shadow.lit.shape[0] // k), -(-frame.shadow.lit.shape[1] // k))
    for j in range(h):
        for i in range(w):
            y, x = k * j, k * i
            lit, dS, rho = frame.shadow.lit[y, x], pixels["dS"][y, x], pixels["rho"][y, x]
            valid = frame.view.gbuffer.valid[y, x]
            assert record["lit"][j, i] == (round(254 * float(lit)) if valid and np.isfinite(lit) else NO_VALUE)
            assert record["dS"][j, i] == (round(254 * float(dS)) if np.isfinite(dS) else NO_VALUE)
            assert record["rho"][j, i] == code_rho(rho)
            assert record["cascade"][j, i] == frame.shadow.cascade[y, x]
            assert record["ref_diff"][j, i] == pixels["ref_diff"][y, x]
            assert record["valid"][j, i] == valid
            reference = frame.view.reference[y, x]
            assert record["reference"][j, i] == (int(reference > 0.5) if np.isfinite(reference) else NO_VALUE)


def test_reference_shading_of_the_sampled_pixels_is_the_whole_images_shading_taken_there():
    frame, _, record = _record(3)
    k = record["stride"]
    g, view = frame.view.gbuffer, frame.view
    whole = shaded_rgb(g.albedo, g.normal, np.where(g.valid, view.reference, np.nan),
                       light_direction=view.light_direction, ambient=AMBIENT)[::k, ::k]
    defined = g.valid[::k, ::k] & np.isfinite(frame.shadow.lit[::k, ::k])
    whole[~np.isfinite(whole).all(axis=-1)] = 0.0
    expected = np.rint(255.0 * srgb_encoded(whole)).astype(np.uint8)
    assert defined.any() and (~defined).any()
    np.testing.assert_array_equal(record["reference_shaded"], np.where(defined[..., None], expected, 0))


def test_rho_code_keeps_rho_to_a_sixteenth_of_an_octave_and_clips_the_ends():
    rho = np.exp2(np.linspace(-7.9, 7.9, 2001))
    back = decode_rho(code_rho(rho))
    assert np.max(np.abs(np.log2(back / rho))) <= 1 / 32 + 1e-12
    assert list(code_rho([1e-9, 1e9, np.nan, 0.0, -1.0])) == [0, 254, NO_VALUE, NO_VALUE, NO_VALUE]
    assert decode_rho(code_rho(1.0)) == 1.0


def test_world_cell_sums_match_a_pixel_by_pixel_count():
    frame, pixels, record = _record(2)
    position, dS = frame.view.gbuffer.position, pixels["dS"]
    expected_dS, expected_counted, expected_flips = {}, {}, {}
    for y in range(dS.shape[0]):
        for x in range(dS.shape[1]):
            if not np.isfinite(dS[y, x]):
                continue
            col = int(np.floor((position[y, x, 0] - GRID.x0) / GRID.cell))
            row = int(np.floor((position[y, x, 2] - GRID.z0) / GRID.cell))
            if not (0 <= col < GRID.nx and 0 <= row < GRID.nz):
                continue
            cell = row * GRID.nx + col
            expected_dS[cell] = expected_dS.get(cell, 0.0) + dS[y, x]
            expected_counted[cell] = expected_counted.get(cell, 0) + 1
            expected_flips[cell] = expected_flips.get(cell, 0) + int(pixels["flipped"][y, x])
    assert sorted(expected_counted) == record["cells"].tolist()
    # Summed pixel by pixel in row-major order, as the loop above: the same bits.
    assert record["cell_dS"].tolist() == [expected_dS[c] for c in sorted(expected_dS)]
    assert record["cell_counted"].tolist() == [expected_counted[c] for c in sorted(expected_counted)]
    assert record["cell_flips"].tolist() == [expected_flips[c] for c in sorted(expected_flips)]


def test_rho_histogram_counts_every_pixel_with_a_cascade_in_its_bin():
    frame, pixels, record = _record(3)
    rho, cascade = pixels["rho"].astype(np.float64), frame.shadow.cascade
    for c in range(record["rho_hist"].shape[0]):
        mine = (cascade == c) & np.isfinite(rho) & (rho > 0)
        expected, _ = np.histogram(np.clip(np.log2(rho[mine]), RHO_EDGES[0], RHO_EDGES[-1] - 1e-9), bins=RHO_EDGES)
        assert record["rho_hist"][c].tolist() == expected.tolist()


def test_stacked_record_sums_the_world_cells_of_every_frame():
    records = [_record(i)[2] for i in range(3)]
    stacked = stack_pixels(records)
    assert stacked["lit"].shape == (3, *records[0]["lit"].shape)
    assert stacked["world_counted"].shape == (GRID.nz, GRID.nx)
    assert stacked["world_counted"].sum() == sum(r["cell_counted"].sum() for r in records)
    assert stacked["world_dS"].sum() == pytest.approx(sum(r["cell_dS"].sum() for r in records), rel=1e-12)
    np.testing.assert_array_equal(stacked["rho_hist"], sum(r["rho_hist"] for r in records))


def test_stacking_refuses_records_of_two_world_grids():
    first = _record(0)[2]
    frame, pixels, _ = _record(1)
    other = frame_pixels(frame, pixels, grid=world_grid([[0.0, 0.0, 0.0]], reach=10.0, cells=8))
    with pytest.raises(ValueError, match="world grid"):
        stack_pixels([first, other])


def test_world_grid_covers_the_path_grown_by_the_shadow_reach():
    grid = world_grid([[-10.0, 3.0, 5.0], [20.0, 0.0, -5.0]], reach=50.0, cells=100)
    assert (grid.x0, grid.z0) == (-60.0, -55.0)
    assert grid.cell == pytest.approx(130.0 / 100)
    assert grid.nx == 100 and grid.nx * grid.cell >= 130.0 and grid.nz * grid.cell >= 110.0
    assert grid.index(np.array([[-60.0, 0, -55.0], [np.nan, 0, 0], [1e6, 0, 0]])).tolist() == [0, -1, -1]


def _assert_same_record(got, expected):
    assert got.keys() == expected.keys()
    for name, value in expected.items():
        if isinstance(value, np.ndarray):
            assert value.dtype == got[name].dtype, name
            np.testing.assert_array_equal(got[name], value, err_msg=name)
        else:
            assert got[name] == value, name


def test_methods_sharing_a_view_compute_its_view_pixels_once_and_get_the_records_of_views_of_their_own():
    view = _frame(4)[0].view
    for seed in (0, 7):
        frame, pixels, _ = _record(4, seed=seed)
        # A copy of the view holds none of what the shared one keeps (``derived`` is not copied).
        alone = frame_pixels(dataclasses.replace(frame, view=dataclasses.replace(view)), pixels, grid=GRID)
        _assert_same_record(frame_pixels(dataclasses.replace(frame, view=view), pixels, grid=GRID), alone)
    # The view's own part and its reference's shading, each once for both records.
    assert [key[0] for key in view.derived] == ["view_pixels", "shading_terms", "reference_srgb"]
    other_grid = world_grid([[0.0, 0.0, 0.0]], reach=10.0, cells=8)
    frame_pixels(dataclasses.replace(frame, view=view), pixels, grid=other_grid)
    assert len(view.derived) == 4


def test_rho_histogram_bins_values_on_and_one_ulp_beside_every_edge_as_a_search_among_the_edges():
    frame, pixels, _ = _record(8)
    shape = frame.shadow.lit.shape
    # 2^edge, exact at whole octaves, and its neighbours: around ρ = 1, log2 ρ is ±1e-16, which
    # a bin computed as floor(8 log2 ρ + 64) would round into the upper bin.
    on = np.exp2(RHO_EDGES)
    rho = np.resize(np.concatenate([on, np.nextafter(on, 0.0), np.nextafter(on, np.inf), [2.0 ** -40, 2.0 ** 40]]),
                    shape)
    record = frame_pixels(frame, {**pixels, "rho": rho}, grid=GRID)
    cascade = frame.shadow.cascade
    for c in range(record["rho_hist"].shape[0]):
        mine = np.log2(rho[cascade == c])
        bins = np.clip(np.searchsorted(RHO_EDGES, mine, side="right") - 1, 0, len(RHO_EDGES) - 2)
        assert record["rho_hist"][c].tolist() == np.bincount(bins, minlength=len(RHO_EDGES) - 1).tolist()
