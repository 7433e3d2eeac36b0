"""The runner: one row per frame × variant, numbers independent of chunking, determinism, resume."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from csmlab.config import load_experiment
from csmlab.errors import InputError
from csmlab.experiment import Unit, build_workload, check_device, chunk_ranges, run_experiment, units_of_work

TINY = """
name = "tiny"
extends = ["methods/exact", "methods/none"]
chunk_frames = 3

[scene]
kind = "terrain"
resolution = 24
trees = 60
ring_trees = 60

[camera]
path = "walk"
frames = 6
width = 64
height = 36

[light]
elevation_deg = 35.0
azimuth_deg = 40.0

[shadow]
cascades = 2
resolution = 128
shadow_distance = 40.0
"""


def run_tiny(tmp_path, name: str, text: str = TINY, **options):
    path = tmp_path / f"{name}.toml"
    path.write_text(text)
    out = tmp_path / name
    return run_experiment(load_experiment(path), out_dir=out, **options), out


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    return run_tiny(tmp_path_factory.mktemp("reference"), "reference")


def rows_of(out):
    with open(out / "metrics.csv", newline="") as f:
        return list(csv.DictReader(f))


def test_one_row_per_frame_and_method_with_no_temporal_value_at_frame_0(reference):
    _, out = reference
    rows = rows_of(out)
    assert [(r["method"], int(r["frame"])) for r in rows] == [(m, f) for m in ("exact", "none") for f in range(6)]
    assert all(float(r["time_s"]) == pytest.approx(int(r["frame"]) / 30.0) for r in rows)
    assert all((r["flicker"] == "") == (r["frame"] == "0") for r in rows)
    assert (out / "timings.csv").is_file() and (out / "config.resolved.toml").is_file()
    assert not (out / ".chunks").exists()


def test_exact_keeps_same_cascade_flicker_at_zero_and_none_does_not(reference):
    result, _ = reference
    methods = result.summary["methods"]
    assert methods["exact"]["flicker_same"] == 0.0
    assert methods["none"]["flicker_same"] > 0.0


def test_summary_holds_hashes_config_and_every_metric_column(reference):
    result, out = reference
    summary = json.loads((out / "summary.json").read_text())
    assert summary == result.summary
    assert {"name", "config_hash", "workload_hash", "csmlab_version", "environment", "config", "methods",
            "points"} <= set(summary)
    columns = list(rows_of(out)[0])[4:]
    assert set(summary["methods"]["exact"]) == set(columns) | {"frames"}
    assert summary["points"]["base"] == summary["methods"]


def test_two_runs_give_byte_identical_metrics_and_summary(reference, tmp_path):
    _, first = reference
    _, second = run_tiny(tmp_path, "again")
    for name in ("metrics.csv", "summary.json"):
        assert (second / name).read_bytes() == (first / name).read_bytes()


def test_chunk_boundaries_do_not_change_a_number(reference, tmp_path):
    _, chunked = reference
    _, whole = run_tiny(tmp_path, "whole", TINY.replace("chunk_frames = 3", "chunk_frames = 6"))
    assert (whole / "metrics.csv").read_bytes() == (chunked / "metrics.csv").read_bytes()


class _Forgetful(dict):
    """A process memory of units that keeps nothing: every unit renders its previous frame again."""

    def __setitem__(self, key, value):
        pass


def test_a_unit_starting_from_the_previous_units_last_frames_gives_the_files_of_one_rendering_them_again(
        reference, tmp_path, monkeypatch):
    import csmlab.experiment

    _, kept = reference
    monkeypatch.setattr(csmlab.experiment, "_UNIT_END", _Forgetful())
    _, fresh = run_tiny(tmp_path, "fresh")
    for name in ("metrics.csv", "cascades.csv", "pixels/exact__base.npz", "pixels/none__base.npz",
                 "anim/none__base.npz"):
        assert (fresh / name).read_bytes() == (kept / name).read_bytes(), name


class Interrupted(Exception):
    pass


def test_interrupted_run_resumed_equals_an_uninterrupted_one(reference, tmp_path):
    _, uninterrupted = reference
    calls = []

    def stop_after_first_chunk(done, total):
        calls.append(done)
        if done > 0:
            raise Interrupted

    with pytest.raises(Interrupted):
        run_tiny(tmp_path, "reference", progress=stop_after_first_chunk)
    out = tmp_path / "reference"
    assert calls == [0, 3]
    assert not (out / "metrics.csv").exists() and not (out / "summary.json").exists()
    assert len(list((out / ".chunks").glob("chunk_*.pkl"))) == 1
    result, out = run_tiny(tmp_path, "reference", resume=True)
    assert (result.chunks_resumed, result.chunks_run) == (1, 1)
    for name in ("metrics.csv", "summary.json"):
        assert (out / name).read_bytes() == (uninterrupted / name).read_bytes()


# Four variants of different cost (unity_urp takes the host path) through TAA, 4 frames.
TINY_TAA = TINY.replace('extends = ["methods/exact", "methods/none"]',
                        'extends = ["methods/exact", "methods/quantized", "methods/none", "engines/unity_urp"]'
                        ).replace("frames = 6", "frames = 4") + "\n[taa]\nenabled = true\nphases = 4\n"


@pytest.fixture(scope="module")
def taa_one_unit(tmp_path_factory):
    """The TAA run as one unit of every variant (one process): the order of a run before the split."""
    return run_tiny(tmp_path_factory.mktemp("taa"), "one_unit", TINY_TAA)


def result_files(out) -> dict:
    """Every results file but the wall-clock ones (timings, the cost figure, the page that shows them) and the
    resolved config (which names the experiment file)."""
    skipped = {"timings.csv", "index.html", "cost.png", "config.resolved.toml"}
    return {p.relative_to(out): p.read_bytes() for p in sorted(out.rglob("*")) if p.is_file() and p.name not in skipped}


def timing_keys(out) -> list:
    with open(out / "timings.csv", newline="") as f:
        return [(r["frame"], r["method"], r["point"], r["stage"]) for r in csv.DictReader(f)]


def test_taa_split_by_variant_gives_the_one_unit_run_byte_for_byte(taa_one_unit, tmp_path):
    one, one_out = taa_one_unit
    split, split_out = run_tiny(tmp_path, "split", TINY_TAA, jobs=2)  # in this process, one unit per variant
    assert (one.chunks_run, split.chunks_run) == (1, 4)
    files = result_files(one_out)
    assert {"metrics.csv", "summary.json"} <= {str(p) for p in files}
    assert any(str(p).startswith("pixels") for p in files) and any(str(p).startswith("anim") for p in files)
    assert result_files(split_out) == files
    # The view is rendered by every unit and timed by one: the same rows, once per frame.
    keys = timing_keys(split_out)
    assert keys == timing_keys(one_out)
    assert [k for k in keys if k[1] == ""] == [(str(f), "", "", s) for f in range(4)
                                               for s in ("visibility", "reference", "taa_reference")]


def test_taa_run_resumed_with_other_jobs_reuses_its_finished_units(taa_one_unit, tmp_path):
    _, uninterrupted = taa_one_unit

    def stop_after_first_unit(done, total):
        if done > 0:
            raise Interrupted

    # Units of one variant each: the first finished is a quarter of the work, one frame's worth.
    with pytest.raises(Interrupted):
        run_tiny(tmp_path, "taa", TINY_TAA, jobs=2, progress=stop_after_first_unit)
    out = tmp_path / "taa"
    assert len(list((out / ".chunks").glob("chunk_*.pkl"))) == 1
    result, _ = run_tiny(tmp_path, "taa", TINY_TAA, resume=True)  # one process: the other three in one unit
    assert (result.chunks_resumed, result.chunks_run) == (1, 1)
    assert result_files(out) == result_files(uninterrupted)


def test_taa_units_cover_every_variant_once_and_reuse_only_disjoint_kept_units():
    assert units_of_work(5, 3, chunk_frames=2, taa=False, split=True) == (
        [], [Unit(0, 2, (0, 1, 2)), Unit(2, 4, (0, 1, 2)), Unit(4, 5, (0, 1, 2))])
    assert units_of_work(5, 3, chunk_frames=2, taa=False, split=False, kept=[Unit(2, 4, (0, 1, 2))])[0] == [
        Unit(2, 4, (0, 1, 2))]
    assert units_of_work(5, 3, chunk_frames=2, taa=True, split=True) == (
        [], [Unit(0, 5, (0,)), Unit(0, 5, (1,)), Unit(0, 5, (2,))])
    assert units_of_work(5, 3, chunk_frames=2, taa=True, split=False) == ([], [Unit(0, 5, (0, 1, 2))])
    # Kept: a unit of another frame count (ignored), two overlapping ones (the first taken).
    kept = [Unit(0, 4, (1,)), Unit(0, 5, (0, 2)), Unit(0, 5, (2,))]
    assert units_of_work(5, 3, chunk_frames=2, taa=True, split=True, kept=kept) == (
        [Unit(0, 5, (0, 2))], [Unit(0, 5, (1,))])
    assert units_of_work(5, 3, chunk_frames=2, taa=True, split=False, kept=[Unit(0, 5, (0, 1, 2))]) == (
        [Unit(0, 5, (0, 1, 2))], [])


def test_sweep_gives_rows_and_summaries_per_point(tmp_path):
    text = TINY.replace("frames = 6", "frames = 2") + "[sweep]\nresolution = [64, 128]\n"
    result, out = run_tiny(tmp_path, "sweep", text)
    rows = rows_of(out)
    assert [(r["method"], r["point"], r["frame"]) for r in rows] == [
        (m, f"resolution={r}", str(f)) for m in ("exact", "none") for r in (64, 128) for f in range(2)]
    points = result.summary["points"]
    assert list(points) == ["resolution=64", "resolution=128"]
    assert points["resolution=64"]["exact"]["memory_bytes"] * 4 == points["resolution=128"]["exact"]["memory_bytes"]


def test_chunk_ranges_cover_every_frame_once():
    assert chunk_ranges(7, 3) == [(0, 3), (3, 6), (6, 7)]
    assert chunk_ranges(2, 10) == [(0, 2)]


def test_mesh_that_cannot_be_read_is_a_located_input_error(tmp_path):
    mesh = tmp_path / "broken.obj"
    mesh.write_text("this is not an obj file\n")
    path = tmp_path / "mesh.toml"
    path.write_text('[scene]\nkind = "mesh"\nfile = "broken.obj"\n[camera]\npath = "walk"\nframes = 2\n')
    with pytest.raises(InputError) as caught:
        build_workload(load_experiment(path))
    assert "broken.obj" in str(caught.value)


def test_cuda_on_a_machine_without_it_is_bad_input():
    import warp as wp

    wp.init()
    if wp.get_cuda_device_count() > 0:
        pytest.skip("this machine has a CUDA device")
    with pytest.raises(InputError, match="--device"):
        check_device("cuda")
    with pytest.raises(InputError, match="cpu, cuda"):
        check_device("gpu")


def test_recorded_path_runs_on_a_clock_from_its_first_pose(tmp_path):
    # Oracle: the fixture's first time stamp is 1311868164.363181 s (Unix time); at 30 fps the run's
    # frames fall at k/30 s, and start_s/end_s cut on that clock.
    fixture = Path(__file__).parent / "data" / "paths" / "tum_fr2_desk_orbslam_head.txt"
    path = tmp_path / "recorded.toml"
    path.write_text(f'[scene]\nkind = "plane_box"\n[camera]\nfile = "{fixture}"\nfps = 30.0\nframes = 100\n'
                    f'start_s = 0.1\nend_s = 0.5\n')
    times = build_workload(load_experiment(path)).path.times
    np.testing.assert_allclose(times, np.arange(3, 16) / 30.0, atol=1e-9)


def test_a_chunk_runs_with_one_thread_in_every_library_pool(monkeypatch):
    # Workers are one process per core: ꟻLIP's OpenMP and OpenBLAS must not start pools of their own.
    from threadpoolctl import threadpool_info

    import csmlab.experiment as experiment
    import csmlab.metrics  # noqa: F401  (ꟻLIP's OpenMP library loaded, as in a worker)

    def threads():
        return {pool["filepath"]: pool["num_threads"] for pool in threadpool_info()}

    outside = threads()
    monkeypatch.setattr(experiment, "_run_chunk", lambda job, chunk: threadpool_info())
    pools = experiment.run_chunk(None, Unit(0, 1, (0,)))
    assert {"openmp", "blas"} <= {pool["user_api"] for pool in pools}
    assert all(pool["num_threads"] == 1 for pool in pools)
    assert threads() == outside  # the caller's own settings come back afterwards


def test_image_frames_are_every_frame_of_a_short_path_and_an_even_sample_of_a_long_one():
    from csmlab.experiment import IMAGE_FRAMES, image_frames

    assert image_frames(5) == frozenset(range(5)) and image_frames(IMAGE_FRAMES) == frozenset(range(IMAGE_FRAMES))
    kept = sorted(image_frames(10_000))
    assert len(kept) == IMAGE_FRAMES and kept[0] == 0 and kept[-1] == 9_999
    assert np.ptp(np.diff(kept)) <= 1


def test_a_long_path_keeps_metrics_of_every_frame_and_images_of_the_sample(tmp_path, monkeypatch):
    import csmlab.experiment
    from csmlab.report import write_report
    from csmlab.report.capture import read_npz

    monkeypatch.setattr(csmlab.experiment, "IMAGE_FRAMES", 3)
    run, out = run_tiny(tmp_path, "long")
    assert sorted({int(r["frame"]) for r in rows_of(out)}) == list(range(6))
    for method in ("exact", "none"):
        assert read_npz(out / "anim" / f"{method}__base.npz")["frame"].tolist() == [0, 2, 5]
    write_report(out)
    assert (out / "index.html").is_file()


def test_a_run_without_images_keeps_the_same_metrics_and_cascade_rows_and_no_animation_or_pixel_record(
        reference, tmp_path):
    _, out = run_tiny(tmp_path, "plain", images=False)
    _, kept = reference
    for name in ("metrics.csv", "cascades.csv"):
        assert (out / name).read_bytes() == (kept / name).read_bytes()
    assert not list((out / "anim").glob("*.npz")) and not list((out / "pixels").glob("*.npz"))
    assert list((kept / "anim").glob("*.npz")) and list((kept / "pixels").glob("*.npz"))
