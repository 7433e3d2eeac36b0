"""Results files: deterministic cell formatting, row order, NaN-aware aggregates, atomic writes, chunks."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

from csmlab.errors import InputError
from csmlab.results import (MetricRow, clear_chunks, format_value, kept_chunks, load_chunk, load_chunk_part,
                            metric_arrays, prepare_output, read_metrics, read_summary, save_chunk, summarize,
                            write_atomic, write_metrics)


def test_cells_round_trip_every_float_exactly():
    values = np.random.default_rng(7).normal(scale=1e3, size=500) ** 3
    assert all(float(format_value(v)) == v for v in values)
    assert [format_value(v) for v in (float("nan"), None, 3.0, -0.0, 0.1, 4194304.0)] == ["", "", "3", "0", "0.1",
                                                                                           "4194304"]


def test_metrics_csv_keeps_the_blocks_order_with_empty_nan_however_they_are_cut(tmp_path):
    rows = {m: [MetricRow(f, f / 30, m, "base", {"x": float(f), "y": math.nan}) for f in range(3)] for m in "ab"}
    write_metrics(tmp_path / "metrics.csv", (rows[m] for m in "ba"), columns=("x", "y"))
    header, read = read_metrics(tmp_path / "metrics.csv")
    assert header == ["frame", "time_s", "method", "point", "x", "y"]
    assert [(r["method"], r["frame"]) for r in read] == [(m, str(f)) for m in "ba" for f in range(3)]
    assert all(r["y"] == "" for r in read) and [float(r["x"]) for r in read] == [0.0, 1.0, 2.0] * 2
    cut = [rows["b"][:1], rows["b"][1:], [], rows["a"]]
    write_metrics(tmp_path / "again.csv", iter(cut), columns=("x", "y"))
    assert (tmp_path / "again.csv").read_bytes() == (tmp_path / "metrics.csv").read_bytes()


def test_summary_means_ignore_nan_and_match_numpy():
    rng = np.random.default_rng(3)
    values = rng.uniform(size=(6, 2))
    values[0, 0] = np.nan
    variants = {("m", p): metric_arrays([MetricRow(f, 0.0, "m", p, {"x": values[f, k], "y": np.nan}) for f in range(6)],
                                        columns=("x", "y")) for k, p in enumerate(("p1", "p2"))}
    methods, points = summarize(variants, columns=("x", "y"), methods=["m"], points=["p1", "p2"])
    assert points["p1"]["m"]["x"] == pytest.approx(np.nanmean(values[:, 0]), rel=1e-15)
    assert methods["m"]["x"] == pytest.approx(np.nanmean(values), rel=1e-15)
    assert methods["m"]["y"] is None and methods["m"]["frames"] == 6


def test_atomic_write_replaces_and_leaves_no_temporary(tmp_path):
    target = tmp_path / "sub" / "file.txt"
    write_atomic(target, "one")
    write_atomic(target, b"two")
    assert target.read_text() == "two"
    assert [p.name for p in target.parent.iterdir()] == ["file.txt"]


@dataclass
class _Chunk:
    start: int
    stop: int
    payload: str
    ranks: tuple = (0, 1)


def test_chunks_are_kept_per_config_and_cleared(tmp_path):
    prepare_output(tmp_path, resolved_toml="x", run_key="aaa", resume=False)
    save_chunk(tmp_path, _Chunk(0, 3, "first"), run_key="aaa")
    save_chunk(tmp_path, _Chunk(3, 6, "second"), run_key="bbb")
    assert load_chunk(tmp_path, 0, 3, (0, 1), run_key="aaa").payload == "first"
    assert load_chunk(tmp_path, 3, 6, (0, 1), run_key="aaa") is None
    assert load_chunk(tmp_path, 6, 9, (0, 1), run_key="aaa") is None
    assert kept_chunks(tmp_path, run_key="aaa") == [(0, 3, (0, 1))]
    clear_chunks(tmp_path)
    assert load_chunk(tmp_path, 0, 3, (0, 1), run_key="aaa") is None


def test_units_of_the_same_frames_and_other_variants_never_take_each_others_place(tmp_path):
    prepare_output(tmp_path, resolved_toml="x", run_key="aaa", resume=False)
    for ranks, payload in (((0, 2), "even"), ((1,), "one"), ((0, 1, 2), "all")):
        save_chunk(tmp_path, _Chunk(0, 4, payload, ranks), run_key="aaa", parts={"captures0": payload.encode()})
    assert [load_chunk(tmp_path, 0, 4, r, run_key="aaa").payload for r in ((0, 2), (1,), (0, 1, 2))] == [
        "even", "one", "all"]
    assert all(load_chunk(tmp_path, 0, 4, r, run_key="aaa") is None for r in ((2,), (0,), (1, 2)))
    assert load_chunk_part(tmp_path, 0, 4, (1,), "captures0") == b"one"
    assert load_chunk_part(tmp_path, 0, 4, (2,), "captures0") is None
    assert kept_chunks(tmp_path, run_key="aaa") == [(0, 4, (0, 1, 2)), (0, 4, (0, 2)), (0, 4, (1,))]
    assert kept_chunks(tmp_path, run_key="bbb") == []


def test_a_new_run_removes_finished_files_and_stale_chunks(tmp_path):
    prepare_output(tmp_path, resolved_toml="x", run_key="aaa", resume=False)
    save_chunk(tmp_path, _Chunk(0, 3, "old"), run_key="aaa")
    for name in ("summary.json", "metrics.csv", "index.html"):
        (tmp_path / name).write_text("old")
    prepare_output(tmp_path, resolved_toml="y", run_key="aaa", resume=False)
    assert not any((tmp_path / n).exists() for n in ("summary.json", "metrics.csv", "index.html"))
    assert load_chunk(tmp_path, 0, 3, (0, 1), run_key="aaa") is None
    assert (tmp_path / "config.resolved.toml").read_text() == "y"


def test_resume_refuses_chunks_of_another_config(tmp_path):
    prepare_output(tmp_path, resolved_toml="x", run_key="aaa", resume=False)
    with pytest.raises(InputError, match="--resume"):
        prepare_output(tmp_path, resolved_toml="x", run_key="bbb", resume=True)


def test_missing_summary_is_a_located_input_error(tmp_path):
    with pytest.raises(InputError, match="finished run") as caught:
        read_summary(tmp_path)
    assert caught.value.file == str(tmp_path / "summary.json")
