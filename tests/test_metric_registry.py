"""The metric registry: docs/design.md's column order, one meaning of "better", and no Warp to read a result."""

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import csmlab
from csmlab.metric_registry import (DERIVED, METRICS, best_mask, finite_mean, format_number, is_metric_column,
                                    linear_percentiles, order_statistics, SELECTION_WHOLE_BELOW,
                                    is_per_cascade, metric_columns, metric_named, metric_of, metric_values,
                                    number_or_none, temporal_columns)

DESIGN_COLUMNS = (
    "rho_median, rho_p05, rho_p95, rho_frac_lt1, rho_frac_lt05, sigma_min_p05, utilization, flicker, flicker_same, "
    "flicker_changed, flip_rate, flip_same, flip_changed, de2000_mean, de2000_p99, de2000_frac_jnd, ssim, flip, "
    "ref_false_shadow, ref_false_light, acne, peter_panning, ref_boundary_px, memory_bytes, "
    "texels_rasterized").split(", ")
"""docs/design.md "Interfaces", copied by hand: the contract the registry must keep."""


def test_metric_columns_keep_the_design_order_with_per_cascade_columns():
    columns = metric_columns(2)
    assert [c for c in columns if c in DESIGN_COLUMNS] == DESIGN_COLUMNS
    at = columns.index("utilization")
    assert columns[at + 1:at + 3] == ("utilization_c0", "utilization_c1")
    rho_keys = ("rho_median", "rho_p05", "rho_p95", "rho_frac_lt1", "rho_frac_lt05")
    extensions = ("pages_marked", "pages_rendered", "pool_bytes")  # a virtual clipmap's pages, after the cost
    assert columns[columns.index("texels_rasterized") + 1:] == extensions + tuple(
        f"{k}_c{c}" for c in range(2) for k in rho_keys)
    extensions += ("ref_seam_error", "flicker_taa", "flicker_same_taa", "flicker_changed_taa", "flip_rate_taa",
                   "flip_same_taa", "flip_changed_taa")  # columns added after docs/design.md's list
    assert set(extensions) <= set(columns)
    assert len(set(columns)) == len(columns) == len(DESIGN_COLUMNS) + len(extensions) + 2 + 2 * len(rho_keys)
    with pytest.raises(ValueError, match="positive integer"):
        metric_columns(0)


def test_temporal_columns_are_the_ones_measured_between_frames():
    assert temporal_columns() == ("flicker", "flicker_same", "flicker_changed", "flip_rate", "flip_same",
                                  "flip_changed", "flicker_taa", "flicker_same_taa", "flicker_changed_taa",
                                  "flip_rate_taa", "flip_same_taa", "flip_changed_taa", "de2000_mean", "de2000_p99",
                                  "de2000_frac_jnd", "ssim", "flip")


def test_per_cascade_columns_resolve_to_their_metric_and_nothing_else_does():
    assert is_per_cascade("utilization_c11") and is_per_cascade("rho_p05_c0")
    assert not is_per_cascade("utilization") and not is_per_cascade("flicker_c0") and not is_per_cascade("abc_c1")
    assert metric_of("utilization_c11") is METRICS["utilization"]
    assert metric_of("rho_frac_lt05_c0") is METRICS["rho_frac_lt05"]
    assert metric_of("flicker_c0") is None          # flicker has no per-cascade columns
    assert metric_of("frame") is None and not is_metric_column("time_s")
    assert is_metric_column("memory_bytes")


def test_closest_to_one_scores_reciprocals_alike_and_tells_sides_apart_from_distance():
    rho = METRICS["rho_median"]
    assert rho.better == "one"
    assert rho.score(0.5) == pytest.approx(rho.score(2.0)) == pytest.approx(math.log(2.0))
    assert rho.score(1.0) == 0.0 and rho.score(0.0) == math.inf
    assert rho.score(0.9) > rho.score(1.1)         # 0.9 is farther from 1:1 than 1.1 on a log scale
    assert METRICS["flicker"].score(0.2) > METRICS["flicker"].score(0.1)
    assert METRICS["ssim"].score(0.8) > METRICS["ssim"].score(0.9)


@pytest.mark.parametrize("better, values, expected", [
    ("lower", [0.3, 0.0, 0.0, np.nan], [False, True, True, False]),
    ("higher", [0.3, 0.9, 0.1], [False, True, False]),
    ("one", [0.5, 1.5, 3.0, 0.9], [False, False, False, True]),
    ("one", [0.5, 2.0], [True, True]),
    ("one", [0.0, 4.0, -1.0], [False, False, False]),
    ("lower", [4.0, 4.0, np.nan], [False, False, False]),
    ("either", [1.0, 2.0], [False, False]),
])
def test_best_mask_marks_the_best_and_nothing_when_all_equal(better, values, expected):
    assert best_mask(values, better=better).tolist() == expected


def test_format_number_keeps_an_exact_zero_and_marks_undefined():
    assert format_number(0.0) == "0"
    assert format_number(float("nan")) == "—" and format_number(None) == "—" and format_number(math.inf) == "—"
    assert format_number(0.000123456) == "0.000123"
    assert format_number(4321.5) == "4,322"


def test_format_number_takes_more_digits_when_asked_and_a_metric_shows_its_scaled_value():
    assert format_number(0.0123456, digits=4) == "0.01235" and format_number(4321.5, digits=4) == "4,322"
    assert METRICS["memory_bytes"].shown(16 * 2**20) == "16" and METRICS["flip_rate"].shown(0.0123) == "1.23"
    assert METRICS["flip_rate"].shown(None) == "—"


def test_ref_error_is_registered_derived_from_false_shadow_and_false_light_and_never_a_column():
    ref_error = DERIVED["ref_error"]
    assert metric_named("ref_error") is ref_error and metric_named("flicker") is METRICS["flicker"]
    assert ref_error.sum_of == ("ref_false_shadow", "ref_false_light") and ref_error.better == "lower"
    assert "ref_error" not in metric_columns(4) and not is_metric_column("ref_error")
    columns = {"ref_false_shadow": np.array([0.25, np.nan]), "ref_false_light": np.array([0.5, 0.125])}
    np.testing.assert_array_equal(metric_values("ref_error", columns), [0.75, np.nan])
    assert metric_values("ref_error", {"ref_false_shadow": columns["ref_false_shadow"]}) is None
    assert metric_values("ref_false_light", columns) is columns["ref_false_light"]


def test_metric_labels_live_only_in_the_registry():
    """Every at-a-glance line, Explore curve label and label-unit pair is spelled once, in the registry."""
    registered = [*METRICS.values(), *DERIVED.values()]
    spelled = ([m.glance for m in registered if m.glance] + [m.curve for m in registered if m.curve]
               + [f'"{m.label}", "{m.unit}"' for m in registered])
    package = Path(csmlab.__file__).parent
    for path in package.rglob("*.py"):
        if path.name != "metric_registry.py":
            text = path.read_text()
            assert not [s for s in spelled if s in text], path


def test_a_missing_summary_value_is_none():
    assert number_or_none(None) is None and number_or_none(math.nan) is None and number_or_none(2) == 2.0


def test_finite_mean_leaves_out_missing_values_and_sums_in_float64():
    assert finite_mean([None, 1.0, np.nan, 3.0, np.inf]) == 2.0
    assert math.isnan(finite_mean([])) and math.isnan(finite_mean([None, np.nan]))
    ones = np.full(2**20 + 1, 0.1, dtype=np.float32)
    assert finite_mean(ones) == pytest.approx(float(np.float32(0.1)), rel=1e-12)
    assert finite_mean(np.array([True, False, False, True])) == 0.5


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_linear_percentiles_are_numpys_bit_for_bit_with_ties_infinities_nans_and_single_values(dtype):
    rng = np.random.default_rng(5)
    for trial in range(400):
        size = int(rng.integers(1, 5)) if trial % 4 == 0 else int(rng.integers(5, 300))
        values = (rng.random(size) * 10.0 ** rng.uniform(-3, 3)).astype(dtype)
        if trial % 5 == 0:
            values = np.round(values, 1)  # ties between neighbouring ranks
        if trial % 7 == 0:
            values[rng.integers(0, size)] = np.inf
        if trial % 11 == 0:
            values[rng.integers(0, size)] = np.nan
        q = tuple(float(x) for x in rng.choice([0.0, 1.0, 5.0, 33.3, 50.0, 95.0, 99.0, 100.0],
                                               size=int(rng.integers(1, 4)), replace=False))
        with np.errstate(invalid="ignore"):
            want = np.percentile(values.astype(np.float64), list(q))
            got = linear_percentiles(values.copy(), q)
        assert got.dtype == np.float64 and got.tobytes() == want.tobytes(), (size, q)
    assert np.isnan(linear_percentiles(np.zeros(0, dtype=dtype), (5.0, 50.0))).all()


@pytest.mark.parametrize("order", ["random", "sorted", "reversed", "ties", "zeros_and_infinities", "periodic"])
def test_linear_percentiles_of_long_arrays_are_numpys_bit_for_bit_whichever_way_the_values_lie(order):
    # Long enough for the sample's brackets (SELECTION_WHOLE_BELOW); orders that put a strided sample
    # far from the array's (sorted, periodic at the sample's stride) and ties across a bracket's ends.
    rng = np.random.default_rng(8)
    for trial, dtype in enumerate((np.float32, np.float64) * 3):
        size = int(rng.integers(SELECTION_WHOLE_BELOW, 4 * SELECTION_WHOLE_BELOW))
        values = rng.lognormal(0.0, 1.5, size)
        if order == "sorted":
            values = np.sort(values)
        elif order == "reversed":
            values = np.sort(values)[::-1].copy()
        elif order == "ties":
            values = np.round(values, 0)
        elif order == "zeros_and_infinities":
            values[rng.random(size) < 0.3] = 0.0
            values[rng.integers(0, size, 7)] = np.inf
        elif order == "periodic":
            values = np.tile(np.sort(rng.random(64)), size // 64 + 1)[:size]
        values = values.astype(dtype)
        q = ((5.0, 50.0, 95.0), (0.0, 99.0, 100.0), (33.3,))[trial % 3]
        want = np.percentile(values.astype(np.float64), list(q))
        got = linear_percentiles(values.copy(), q)
        assert got.tobytes() == want.tobytes(), (order, size, dtype, q)


def test_order_statistics_answer_none_for_a_nan_and_a_negative_zero_keeps_numpys_choice_of_tie():
    values = np.linspace(-1.0, 1.0, 3 * SELECTION_WHOLE_BELOW)
    values[5] = np.nan
    assert order_statistics(values.copy(), np.array([10, 20])) is None
    # Zeros of both signs at the rank: the whole array partitioned as np.percentile's partition does.
    signed = np.zeros(3 * SELECTION_WHOLE_BELOW)
    signed[::2] = -0.0
    signed[:100] = -1.0
    rank = signed.size // 2
    want = np.percentile(signed, 50.0)
    assert linear_percentiles(signed.copy(), (50.0,)).tobytes() == np.array([want]).tobytes()
    assert order_statistics(signed.copy(), np.array([rank]))[0] == 0.0


def test_a_declaration_with_an_unknown_direction_is_refused():
    from csmlab.metric_registry import Metric

    with pytest.raises(ValueError, match="better"):
        Metric("x", "x", "-", "up")
    with pytest.raises(ValueError, match="plots"):
        Metric("x", "x", "-", "lower", plots=("everywhere",))


def test_reading_tolerances_or_results_does_not_import_warp(tmp_path):
    tolerances = tmp_path / "tolerances.toml"
    tolerances.write_text("[regress]\nflicker_same = { abs = 0.0 }\nutilization_c5 = { rel = 0.1 }\n")
    code = ("import sys\n"
            "from csmlab.config import load_tolerances\n"
            "import csmlab.regress, csmlab.compare, csmlab.verdict, csmlab.report.summary_table, csmlab.report.sweep\n"
            f"assert set(load_tolerances({str(tolerances)!r})) == {{'flicker_same', 'utilization_c5'}}\n"
            "print('warp' in sys.modules)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False", out.stderr
