"""The report's tables: reading results back, the summary table's means and best marks, Pareto optimality."""

import itertools

import numpy as np
import pytest

from csmlab.errors import InputError
from csmlab.report.figures import pareto_optimal
from csmlab.metric_registry import format_number
from csmlab.report.summary_table import full_table, headline_table
from csmlab.report.tables import read_columns


def _write(path, text):
    path.write_text(text)
    return path


def test_read_columns_makes_empty_cells_nan_and_keeps_labels_as_text(tmp_path):
    table = read_columns(_write(tmp_path / "m.csv", "frame,method,point,flicker\n0,512,1024,\n1,512,1024,0.25\n"))
    assert table["method"].tolist() == ["512", "512"] and table["point"].tolist() == ["1024", "1024"]
    assert np.isnan(table["flicker"][0]) and table["flicker"][1] == 0.25
    assert table["frame"].dtype == np.float64


def test_read_columns_names_the_file_and_line_of_a_ragged_row(tmp_path):
    path = _write(tmp_path / "m.csv", "frame,method,point\n0,a,b\n1,a\n")
    with pytest.raises(InputError, match=r"m\.csv:3: expected 3 cells, got 2"):
        read_columns(path)


def test_read_columns_names_a_missing_required_column(tmp_path):
    with pytest.raises(InputError, match="expected columns point"):
        read_columns(_write(tmp_path / "m.csv", "frame,method\n0,a\n"), required=("frame", "method", "point"))


def test_pareto_optimal_matches_brute_force_dominance():
    rng = np.random.default_rng(3)
    points = rng.integers(0, 4, size=(40, 3)).astype(float)
    points[5, 1] = np.nan
    optimal = pareto_optimal(points)
    for i, p in enumerate(points):
        dominated = any(np.all(q <= p) and np.any(q < p) for j, q in enumerate(points)
                        if j != i and np.all(np.isfinite(q)))
        assert optimal[i] == (np.all(np.isfinite(p)) and not dominated)


def test_headline_table_means_over_frames_and_time_per_frame_from_timings(tmp_path):
    metrics = read_columns(_write(tmp_path / "metrics.csv", "\n".join(
        ["frame,time_s,method,point,flicker_same,rho_median,memory_bytes"]
        + [f"{f},{f / 30},{m},base,{'' if f == 0 else v * f},{r},{2 ** 22}"
           for m, v, r in (("exact", 0.0, 0.5), ("none", 0.01, 1.25)) for f in range(3)]) + "\n"))
    timings = read_columns(_write(tmp_path / "timings.csv", "\n".join(
        ["frame,method,point,stage,seconds"]
        + [f"{f},{m},base,{s},{t}" for f, (m, s, t) in itertools.product(
            range(3), (("exact", "raster", 0.01), ("exact", "shadow", 0.02), ("none", "raster", 0.005)))]
        + ["0,,,visibility,9.0"]) + "\n"))
    columns, rows = headline_table(metrics, timings)
    keys = [c.key for c in columns]
    assert keys == ["rho_median", "flicker_same", "memory_bytes", "time_ms"]
    cells = {r.method: dict(zip(keys, r.cells)) for r in rows}
    assert cells["exact"]["flicker_same"].text == "0" and cells["exact"]["flicker_same"].best
    assert cells["none"]["flicker_same"].text == format_number(np.mean([0.01, 0.02]))
    assert cells["none"]["rho_median"].best and not cells["exact"]["rho_median"].best
    assert cells["exact"]["memory_bytes"].text == "4" and not cells["exact"]["memory_bytes"].best
    assert cells["exact"]["time_ms"].text == "30" and cells["none"]["time_ms"].text == "5"
    assert cells["none"]["time_ms"].best


def test_full_table_marks_every_column_the_way_the_registry_says(tmp_path):
    metrics = read_columns(_write(tmp_path / "metrics.csv", "\n".join(
        ["frame,time_s,method,point,rho_median,rho_median_c1,ssim,flicker,rho_p95,unknown_column"]
        + ["0,0,a,base,0.5,3.0,0.9,0.2,7,1", "0,0,b,base,1.6,1.2,0.8,0.1,9,2"]) + "\n"))
    names, rows = full_table(metrics)
    assert names == ["rho_median", "rho_median_c1", "ssim", "flicker", "rho_p95", "unknown_column"]
    marks = {r.method: dict(zip(names, (c.best for c in r.cells))) for r in rows}
    # ρ: closest to 1 on a log scale (|ln 0.5| = 0.69 > |ln 1.6| = 0.47), per cascade too; SSIM higher; flicker lower.
    assert marks["b"]["rho_median"] and not marks["a"]["rho_median"]
    assert marks["b"]["rho_median_c1"] and not marks["a"]["rho_median_c1"]
    assert marks["a"]["ssim"] and marks["b"]["flicker"]
    assert marks["a"]["rho_p95"] and not marks["b"]["rho_p95"]     # 7 is closer to 1 than 9
    assert not any(marks[m]["unknown_column"] for m in "ab")
