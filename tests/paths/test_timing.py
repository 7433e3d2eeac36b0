"""Recorded paths as they come: repeated time stamps, tracking gaps, REP 103 axes and UTM-sized anchors."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from csmlab.cli import app
from csmlab.errors import InputError
from csmlab.geometry import quat_to_matrix
from csmlab.paths import read_path
from csmlab.paths.formats import read_recording
from csmlab.paths.recorded import RecordedPoses
from csmlab.paths.timing import find_gaps, frames_outside_gaps, resolve_duplicates
from tests.locations import ROOT

DATA = ROOT / "data" / "paths"
TUM_GROUND_TRUTH = DATA / "tum_freiburg1_xyz_groundtruth.txt"
EUROC = DATA / "euroc_v102_groundtruth_50hz.csv"


def _split(file):
    lines = file.read_text().splitlines()
    return [t for t in lines if t.startswith("#")], [t for t in lines if t.strip() and not t.startswith("#")]


def _tum_with_repeats_and_gaps(tmp_path):
    """TUM's freiburg1_xyz ground truth with what real files have: line 505 repeats line 504's stamp with
    a pose 3 mm away, rows 1000–1149 (1.5 s) and 2000–2039 (0.4 s) lost to tracking."""
    header, rows = _split(TUM_GROUND_TRUTH)
    stamp, x, *rest = rows[500].split()
    repeat = " ".join([stamp, repr(float(x) + 0.003), *rest])
    path = tmp_path / "tum_repeats_gaps.txt"
    path.write_text("\n".join(header + rows[:501] + [repeat] + rows[501:1000] + rows[1150:2000] + rows[2040:]) + "\n")
    return path


def _euroc_with_repeats_and_gaps(tmp_path):
    """The EuRoC V1_02 ground truth (50 Hz) with two repeated nanosecond stamps and a 2 s gap."""
    header, rows = _split(EUROC)
    twice = [rows[30].split(",")[0] + "," + ",".join(rows[31].split(",")[1:]),
             rows[60].split(",")[0] + "," + ",".join(rows[61].split(",")[1:])]
    kept = rows[:31] + [twice[0]] + rows[31:61] + [twice[1]] + rows[61:200] + rows[300:]
    path = tmp_path / "euroc_repeats_gaps.csv"
    path.write_text("\n".join(header + kept) + "\n")
    return path


def _recorded(times, positions=None, orientations=None):
    n = len(times)
    p = np.arange(3.0 * n).reshape(n, 3) if positions is None else np.asarray(positions, dtype=float)
    q = np.tile([0.0, 0.0, 0.0, 1.0], (n, 1)) if orientations is None else np.asarray(orientations, dtype=float)
    return RecordedPoses(file="f.txt", lines=np.arange(1, n + 1) + 10, times=np.asarray(times, dtype=float),
                         positions=p, orientations=q)


@pytest.mark.parametrize("rule, expected", [("first", [0.0, 3.0, 9.0]), ("last", [0.0, 6.0, 9.0]),
                                            ("mean", [0.0, 4.5, 9.0])])
def test_resolve_duplicates_keeps_one_pose_per_stamp_by_rule(rule, expected):
    resolved, found = resolve_duplicates(_recorded([0.0, 1.0, 1.0, 2.0]), rule=rule)
    np.testing.assert_array_equal(resolved.times, [0.0, 1.0, 2.0])
    np.testing.assert_array_equal(resolved.positions[:, 0], expected)
    np.testing.assert_array_equal(resolved.lines, [11, 12, 14])
    assert len(found) == 1 and found[0].lines == (12, 13) and found[0].time_s == 1.0
    assert found[0].spread_m == pytest.approx(np.sqrt(27.0))


def test_resolve_duplicates_mean_averages_quaternions_of_either_sign():
    half = np.sin(np.radians(10.0)), np.cos(np.radians(10.0))
    q = [[0.0, 0.0, 0.0, 1.0], [0.0, 0.0, half[0], half[1]], [0.0, 0.0, -half[0], -half[1]]]
    resolved, _ = resolve_duplicates(_recorded([0.0, 1.0, 1.0], orientations=q), rule="mean")
    np.testing.assert_allclose(resolved.orientations[1], [0.0, 0.0, half[0], half[1]], atol=1e-15)


def test_resolve_duplicates_error_names_the_second_line():
    with pytest.raises(InputError, match=r"f.txt:13.*timestamp.*1.0 again \(line 12\)"):
        resolve_duplicates(_recorded([0.0, 1.0, 1.0, 2.0]), rule="error")


def test_find_gaps_uses_ten_median_steps_by_default_and_measures_the_jump():
    times = np.array([0.0, 0.1, 0.2, 0.3, 1.4, 1.5, 1.6])
    positions = np.zeros((7, 3))
    positions[4:, 0] = 2.0
    limit, gaps = find_gaps(times, positions, np.arange(7) + 1, max_gap=None)
    assert limit == pytest.approx(1.0)
    assert len(gaps) == 1 and gaps[0].lines == (4, 5) and gaps[0].jump_m == 2.0
    assert gaps[0].duration_s == pytest.approx(1.1)
    assert find_gaps(times, positions, np.arange(7) + 1, max_gap=2.0)[1] == ()


def test_frames_outside_gaps_drop_frames_inside_and_restart_after():
    _, gaps = find_gaps([0.0, 0.1, 0.2, 1.0, 1.1], np.zeros((5, 3)), np.arange(5), max_gap=0.5)
    keep, restart = frames_outside_gaps(np.arange(12) / 10.0, gaps)
    np.testing.assert_array_equal(np.flatnonzero(keep), [0, 1, 2, 10, 11])
    np.testing.assert_array_equal(restart, [False, False, False, True, False])


def test_a_stamp_going_back_is_still_refused(tmp_path):
    file = tmp_path / "back.txt"
    file.write_text("1.0 0 0 0 0 0 0 1\n2.0 0 0 0 0 0 0 1\n1.5 0 0 0 0 0 0 1\n")
    with pytest.raises(InputError, match=r"back.txt:3.*never go back"):
        read_path(file, format="tum")


def test_real_tum_ground_truth_with_repeats_and_gaps_is_read_and_reported(tmp_path):
    file = _tum_with_repeats_and_gaps(tmp_path)
    bridged = read_recording(file, format="tum", convention="mocap", fps=30.0, from_first_pose=True)
    cut = read_recording(file, format="tum", convention="mocap", fps=30.0, from_first_pose=True, gaps="cut")
    record = bridged.timing.as_dict()
    assert record["duplicates"] == 1 and record["duplicate_list"][0]["lines"] == [504, 505]
    assert record["duplicate_list"][0]["spread_m"] == pytest.approx(0.003)
    assert record["gaps"] == 2 and record["max_gap_s"] == pytest.approx(0.1, rel=0.01)
    assert [round(g["duration_s"], 2) for g in record["gap_list"]] == [1.61, 0.41]
    # Cut: the frames inside the gaps (1.6 s and 0.4 s at 30 fps) are gone; two frames restart.
    assert len(bridged.path) - len(cut.path) == 48 + 12
    assert len(cut.restarts) == 2
    for gap in cut.timing.gaps:
        assert not np.any((cut.path.times > gap.start_s) & (cut.path.times < gap.end_s))


def test_real_euroc_file_with_repeated_nanoseconds_is_read(tmp_path):
    recording = read_recording(_euroc_with_repeats_and_gaps(tmp_path), format="euroc", duplicate_times="last")
    assert recording.timing.as_dict()["duplicates"] == 2 and len(recording.timing.gaps) == 1
    assert recording.timing.gaps[0].duration_s == pytest.approx(2.02, abs=1e-5)


def test_ros_convention_looks_along_body_x_with_body_z_up(tmp_path):
    # REP 103: identity body pose looks east (+x) with z up; yawed 90° it looks north (+y).
    file = tmp_path / "ros.txt"
    s = float(np.sqrt(0.5))
    file.write_text(f"0.0 10 20 1.5 0 0 0 1\n0.1 10 20 1.5 0 0 {s!r} {s!r}\n")
    path = read_path(file, format="tum", convention="ros")
    forward = -quat_to_matrix(path.orientations)[:, :, 2]
    up = quat_to_matrix(path.orientations)[:, :, 1]
    # csmlab world: east = +X, up = +Y, north = -Z.
    np.testing.assert_allclose(forward, [[1.0, 0.0, 0.0], [0.0, 0.0, -1.0]], atol=1e-15)
    np.testing.assert_allclose(up, [[0.0, 1.0, 0.0], [0.0, 1.0, 0.0]], atol=1e-15)
    np.testing.assert_array_equal(path.positions[0], [10.0, 1.5, -20.0])


def test_anchor_first_keeps_millimetres_of_utm_coordinates(tmp_path):
    # Eastings/northings of 4.6e5 / 5.4e6 m with millimetre steps: the path starts at offset and every
    # step is the file's difference, exact to float64 (5.4e6 m carries ~1e-9 m).
    east, north = 461234.567, 5412345.678
    steps = np.array([[0.0, 0.0, 0.0], [0.001, 0.002, 0.0], [0.104, -0.003, 0.0005]])
    file = tmp_path / "utm.txt"
    file.write_text("".join(f"{0.1 * k!r} {float(east + d[0])!r} {float(north + d[1])!r} {float(250.0 + d[2])!r} "
                            "0 0 0 1\n" for k, d in enumerate(steps)))
    path = read_path(file, format="tum", convention="ros", anchor="first", offset=(5.0, 1.7, -3.0))
    np.testing.assert_array_equal(path.positions[0], [5.0, 1.7, -3.0])
    expected = np.array([5.0, 1.7, -3.0]) + steps[:, [0, 2, 1]] * [1.0, 1.0, -1.0]
    np.testing.assert_allclose(path.positions, expected, rtol=0, atol=1e-9)


@pytest.mark.slow
def test_real_files_with_repeats_and_gaps_run_end_to_end_with_default_settings(tmp_path):
    file = _tum_with_repeats_and_gaps(tmp_path)
    experiment = tmp_path / "tum.toml"
    experiment.write_text(f"""
name = "tum_repeats_gaps"
extends = ["methods/exact"]
[scene]
kind = "plane_box"
[camera]
file = "{file.name}"
format = "tum"
convention = "mocap"
offset = [0.0, 0.5, 4.0]
start_s = 9.5
frames = 12
width = 32
height = 18
[shadow]
cascades = 1
resolution = 64
shadow_distance = 20.0
""")
    outcome = CliRunner().invoke(app, ["run", str(experiment), "--out", str(tmp_path / "out")])
    assert outcome.exit_code == 0, outcome.output
    assert "1 repeated time stamp(s)" in outcome.stdout and "2 tracking gap(s)" in outcome.stdout
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["recording"]["duplicates"] == 1 and summary["recording"]["gaps"] == 2
    assert summary["recording"]["gaps_rule"] == "interpolate" and summary["recording"]["duplicate_times"] == "first"
    page = (tmp_path / "out" / "index.html").read_text()
    assert "Recorded path: time stamps" in page and "1004–1005" in page


def test_cut_gaps_leave_the_frame_after_a_gap_without_temporal_metrics(tmp_path):
    file = _tum_with_repeats_and_gaps(tmp_path)
    experiment = tmp_path / "tum.toml"
    experiment.write_text(f"""
name = "tum_cut"
extends = ["methods/exact"]
[scene]
kind = "plane_box"
[camera]
file = "{file.name}"
format = "tum"
convention = "mocap"
offset = [0.0, 0.5, 4.0]
gaps = "cut"
start_s = 9.8
frames = 8
width = 32
height = 18
[shadow]
cascades = 1
resolution = 64
shadow_distance = 20.0
""")
    outcome = CliRunner().invoke(app, ["run", str(experiment), "--out", str(tmp_path / "out")])
    assert outcome.exit_code == 0, outcome.output
    rows = (tmp_path / "out" / "metrics.csv").read_text().splitlines()
    header = rows[0].split(",")
    flicker = [row.split(",")[header.index("flicker")] for row in rows[1:]]
    times = [float(row.split(",")[header.index("time_s")]) for row in rows[1:]]
    # Frames at 9.8, 9.833, ..., 9.967, then 11.6 (the first after the 1.61 s gap): no flicker at 0 and there.
    restart = next(k for k, t in enumerate(times) if t > 11.0)
    assert flicker[0] == "" and flicker[restart] == ""
    assert all(value != "" for k, value in enumerate(flicker) if k not in (0, restart))


TINY_RECORDED = """
name = "tiny_recorded"
extends = ["methods/exact"]
[scene]
kind = "plane_box"
[camera]
file = "p.txt"
format = "tum"
{extra}
frames = 3
width = 16
height = 9
[shadow]
cascades = 1
resolution = 32
"""

POSES = "0.0 0 1 5 0 0 0 1\n0.1 0 1 5 0 0 0 1\n0.1 0 1 5.01 0 0 0 1\n0.2 0 1 5 0 0 0 1\n3.0 0 1 5 0 0 0 1\n"

BAD_FIELDS = {
    "duplicate_times": ('duplicate_times = "sometimes"', "camera.duplicate_times",
                        "['error', 'first', 'last', 'mean']"),
    "gaps": ('gaps = "skip"', "camera.gaps", "['cut', 'error', 'interpolate']"),
    "max_gap": ("max_gap = -0.5", "camera.max_gap", "a positive number of seconds"),
    "max_gap type": ('max_gap = "long"', "camera.max_gap", "number"),
    "anchor": ('anchor = "start"', "camera.anchor", "'first'"),
    "convention": ('convention = "ros2"', "camera.convention", "ros"),
    "repeat refused": ('duplicate_times = "error"', "p.txt:3", "timestamp"),
    "gap refused": ('gaps = "error"', "p.txt:5", "max_gap"),
}


@pytest.mark.parametrize("case", list(BAD_FIELDS))
def test_a_bad_recording_field_exits_2_naming_it(tmp_path, case):
    extra, where, words = BAD_FIELDS[case]
    (tmp_path / "p.txt").write_text(POSES)
    (tmp_path / "exp.toml").write_text(TINY_RECORDED.format(extra=extra))
    outcome = CliRunner().invoke(app, ["run", str(tmp_path / "exp.toml"), "--out", str(tmp_path / "out")])
    assert outcome.exit_code == 2, outcome.output
    message = outcome.stderr.strip()
    assert len(message.splitlines()) == 1 and "Traceback" not in outcome.output
    assert where in message and words in message, message
