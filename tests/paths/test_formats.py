"""Recorded camera paths: round trips, hand-made files, resampling, broken files, real recordings.

Oracles: the poses a path was written from (round trips); poses worked out by hand for small
files (see tests/data/paths/README.md); plain line counts and first/last time stamps read with
``str.split`` for the real recordings; and, for broken files, the line and field planted in them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from csmlab.errors import InputError
from csmlab.geometry import quat_to_matrix
from csmlab.paths import PATH_FORMATS, guess_format, make_path, read_path, write_path
from tests.locations import ROOT, TEST_DATA

DATA = TEST_DATA / "paths"
REAL_DATA = ROOT / "data" / "paths"


def _forward(path) -> np.ndarray:
    return -quat_to_matrix(path.orientations)[:, :, 2]


def _assert_same_poses(a, b, *, times=True, atol=1e-9):
    assert len(a) == len(b)
    if times:
        np.testing.assert_allclose(a.times, b.times, rtol=0, atol=atol)
    np.testing.assert_allclose(a.positions, b.positions, rtol=0, atol=atol)
    np.testing.assert_allclose(quat_to_matrix(a.orientations), quat_to_matrix(b.orientations), rtol=0, atol=atol)


@pytest.fixture
def walk():
    path = make_path("walk", frames=60, seed=2)
    fov = 50.0 + 10.0 * np.sin(path.times)
    return type(path)(times=path.times + 0.25, positions=path.positions, orientations=path.orientations,
                      fov_y_deg=fov, name="walk")


def test_every_format_reads_back_the_poses_it_wrote(walk, tmp_path):
    for name in PATH_FORMATS:
        file = tmp_path / f"walk.{name}"
        write_path(walk, file, format=name)
        assert guess_format(file) == name
        back = read_path(file, format=name, fps=30.0) if name == "kitti" else read_path(file)
        # glTF accessors are float32; nerfstudio, like KITTI, has no clock of its own (pose i at i · seconds / N).
        _assert_same_poses(walk, back, times=name not in ("kitti", "nerfstudio"), atol=2e-5 if name == "gltf" else 1e-9)
        if name in ("csv", "json", "nerfstudio"):
            np.testing.assert_allclose(back.fov_y_deg, walk.fov_y_deg, rtol=1e-15)
    kitti = read_path(tmp_path / "walk.kitti", format="kitti", fps=30.0)
    np.testing.assert_allclose(kitti.times, walk.times - 0.25, atol=1e-12)


def test_kitti_file_holds_the_camera_to_world_matrices(walk, tmp_path):
    file = tmp_path / "walk.txt"
    write_path(walk, file, format="kitti", convention="opengl")
    rows = np.loadtxt(file).reshape(-1, 3, 4)
    np.testing.assert_allclose(rows[:, :, :3], quat_to_matrix(walk.orientations), atol=1e-12)
    np.testing.assert_allclose(rows[:, :, 3], walk.positions, atol=1e-12)


def test_a_path_survives_every_convention(walk, tmp_path):
    for convention in ("opengl", "tum", "kitti", "mocap", "euroc", "unreal", "unity"):
        file = tmp_path / f"{convention}.csv"
        write_path(walk, file, format="csv", convention=convention)
        _assert_same_poses(walk, read_path(file, convention=convention))


def test_hand_written_csv_gives_the_documented_poses():
    path = read_path(DATA / "csmlab_quaternion.csv")
    np.testing.assert_allclose(path.positions, [[20, 1.7, 0], [20, 1.7, -1]])
    np.testing.assert_allclose(_forward(path), [[0, 0, -1], [-1, 0, 0]], atol=1e-12)
    np.testing.assert_array_equal(path.fov_y_deg, [60.0, 45.0])


def test_hand_written_yaw_pitch_roll_json_gives_the_documented_poses():
    path = read_path(DATA / "csmlab_yaw_pitch_roll.json", fov_y_deg=70.0)
    np.testing.assert_allclose(_forward(path), [[0, 0, -1], [-1, 0, 0], [0, -0.5, -np.sqrt(0.75)]], atol=1e-12)
    np.testing.assert_array_equal(path.times, [0.0, 1.0, 2.0])
    np.testing.assert_array_equal(path.fov_y_deg, 70.0)


def test_hand_written_tum_kitti_and_euroc_lines_land_as_documented(tmp_path):
    # One camera at (1, 2, 3) turned +90° about its down axis: looking along its world's +X.
    s = float(np.sqrt(0.5))
    (tmp_path / "a.tum").write_text(f"0.0 1 2 3 0 {s!r} 0 {s!r}\n1.0 1 2 3 0 0 0 1\n")
    (tmp_path / "a.kitti").write_text("0 0 1 1  0 1 0 2  -1 0 0 3\n")
    # EuRoC: body at (1, 2, 3), identity: csmlab looks up (+Y) with +X up; q written w first.
    (tmp_path / "a.csv").write_text("#timestamp [ns],x,y,z,qw,qx,qy,qz,vx\n1500000000,1,2,3,1,0,0,0,9\n")
    tum = read_path(tmp_path / "a.tum")
    kitti = read_path(tmp_path / "a.kitti", fps=10.0)
    euroc = read_path(tmp_path / "a.csv")
    np.testing.assert_allclose(tum.positions[0], (1, -2, -3))
    np.testing.assert_allclose(_forward(tum), [[1, 0, 0], [0, 0, -1]], atol=1e-12)
    np.testing.assert_allclose(kitti.positions[0], (1, -2, -3))
    np.testing.assert_allclose(_forward(kitti)[0], (1, 0, 0), atol=1e-12)
    assert euroc.times[0] == 1.5
    np.testing.assert_allclose(euroc.positions[0], (1, 3, -2))
    np.testing.assert_allclose(_forward(euroc)[0], (0, 1, 0), atol=1e-12)
    np.testing.assert_allclose(quat_to_matrix(euroc.orientations[0])[:, 1], (1, 0, 0), atol=1e-12)


def test_scale_offset_and_time_offset_apply_after_conversion():
    plain = read_path(DATA / "tum_fr2_desk_orbslam_head.txt")
    moved = read_path(DATA / "tum_fr2_desk_orbslam_head.txt", scale=10.0, offset=(5.0, 1.7, -2.0),
                      time_offset=-plain.times[0])
    np.testing.assert_allclose(moved.positions, plain.positions * 10.0 + (5.0, 1.7, -2.0), atol=1e-12)
    np.testing.assert_allclose(moved.times, plain.times - plain.times[0], atol=1e-9)
    assert moved.times[0] == 0.0
    np.testing.assert_array_equal(moved.orientations, plain.orientations)


def test_unreal_centimetres_become_metres(tmp_path):
    (tmp_path / "ue.csv").write_text("time,x,y,z,qx,qy,qz,qw\n0,1000,-250,170,0,0,0,1\n")
    path = read_path(tmp_path / "ue.csv", convention="unreal")
    np.testing.assert_allclose(path.positions[0], (-2.5, 1.7, -10.0))


def test_resampling_keeps_the_endpoints_and_is_monotone(tmp_path):
    rng = np.random.default_rng(11)
    times = np.concatenate([[0.0], np.sort(rng.uniform(0.0, 2.0, 57)), [2.0]])
    q = rng.normal(size=(59, 4)) * 0.05 + (0, 0, 0, 1)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    rows = np.column_stack([times, rng.normal(size=(59, 3)), q])
    np.savetxt(tmp_path / "irregular.txt", rows, fmt="%.17g")
    original = read_path(tmp_path / "irregular.txt")
    path = read_path(tmp_path / "irregular.txt", fps=30.0)
    assert len(path) == 61
    assert np.all(np.diff(path.times) > 0)
    np.testing.assert_allclose(np.diff(path.times), 1 / 30, atol=1e-12)
    for end in (0, -1):
        assert path.times[end] == pytest.approx(original.times[end], abs=1e-12)
        np.testing.assert_allclose(path.positions[end], original.positions[end], atol=1e-12)
        np.testing.assert_allclose(quat_to_matrix(path.orientations[end]), quat_to_matrix(original.orientations[end]),
                                   atol=1e-12)


def test_crop_keeps_the_time_window():
    path = read_path(DATA / "kitti_00_head.txt", times_file=DATA / "kitti_00_head_times.txt")
    window = path.crop(1.0, 2.0)
    assert np.all((window.times >= 1.0) & (window.times <= 2.0))
    assert len(window) == np.count_nonzero((path.times >= 1.0) & (path.times <= 2.0)) > 0


TUM_OK = "1.0 0 0 0 0 0 0 1\n"
BROKEN = [
    # (id, file name, text, extra read_path arguments, line, field)
    ("missing-column", "a.txt", TUM_OK + "2.0 0 0 0 0 0 0\n", {}, 2, "qw"),
    ("missing-csv-column", "a.csv", "time,x,y,z,qx,qy,qz\n0,0,0,0,0,0,0\n", {}, 1, "qw"),
    ("short-csv-row", "a.csv", "time,x,y,z,qx,qy,qz,qw\n0,0,0,0,0,0,0,1\n1,0,0\n", {}, 3, "z"),
    ("unknown-csv-column", "a.csv", "time,x,y,z,qx,qy,qz,qw,fov\n0,0,0,0,0,0,0,1,60\n", {}, 1, "fov"),
    ("non-numeric", "a.txt", TUM_OK + "2.0 0 abc 0 0 0 0 1\n", {}, 2, "ty"),
    ("non-numeric-json", "a.json", '{"poses": [\n {"time": 0, "x": 0, "y": "one", "z": 0,'
                                   ' "qx": 0, "qy": 0, "qz": 0, "qw": 1}\n]}\n', {}, 2, "poses[0].y"),
    ("zero-quaternion", "a.txt", "# c\n" + TUM_OK + "2.0 0 0 0 0 0 0 0\n", {}, 3, "qx qy qz qw"),
    ("unnormalised-quaternion", "a.txt", TUM_OK + "2.0 0 0 0 0 0 0 1.01\n", {}, 2, "qx qy qz qw"),
    ("unnormalised-euroc", "a.csv", "#timestamp,x,y,z,qw,qx,qy,qz\n5,0,0,0,0.5,0,0,0\n", {}, 2,
     "q_RS_w q_RS_x q_RS_y q_RS_z"),
    ("not-a-rotation", "a.txt", "1 0 0 0 0 1 0 0 0 0 -1 0\n", {"fps": 10.0}, 1, "r00..r22"),
    ("time-goes-back", "a.txt", TUM_OK + "3.0 0 0 0 0 0 0 1\n\n2.0 0 0 0 0 0 0 1\n", {}, 4, "timestamp"),
    ("time-repeats", "a.csv", "time,x,y,z,qx,qy,qz,qw\n0,0,0,0,0,0,0,1\n0,1,0,0,0,0,0,1\n",
     {"duplicate_times": "error"}, 3, "time"),
    ("euroc-time-repeats", "a.csv", "#timestamp,x,y,z,qw,qx,qy,qz\n5,0,0,0,1,0,0,0\n5,0,0,0,1,0,0,0\n",
     {"duplicate_times": "error"}, 3, "timestamp"),
    ("euroc-time-goes-back", "a.csv", "#timestamp,x,y,z,qw,qx,qy,qz\n5,0,0,0,1,0,0,0\n4,0,0,0,1,0,0,0\n", {}, 3,
     "timestamp"),
    ("euroc-float-time", "a.csv", "#timestamp,x,y,z,qw,qx,qy,qz\n5.5,0,0,0,1,0,0,0\n", {}, 2, "timestamp"),
    ("empty", "a.txt", "", {"format": "tum"}, 1, None),
    ("only-comments", "a.txt", "# t tx ty tz qx qy qz qw\n#\n", {"format": "tum"}, 2, None),
    ("empty-unknown-format", "a.txt", "\n\n", {}, 2, None),
    ("header-only-csv", "a.csv", "time,x,y,z,qx,qy,qz,qw\n", {}, 1, None),
    ("empty-json-poses", "a.json", '{"poses": []}\n', {}, 1, None),
    ("nan", "a.txt", TUM_OK + "2.0 0 nan 0 0 0 0 1\n", {}, 2, "ty"),
    ("nan-json", "a.json", '{"poses": [\n {"time": 0, "x": NaN, "y": 0, "z": 0,'
                           ' "qx": 0, "qy": 0, "qz": 0, "qw": 1}\n]}\n', {}, 2, "poses[0].x"),
    ("json-syntax", "a.json", '{"poses": [\n {"time": 0,,}\n]}\n', {}, 2, None),
    ("json-missing-field", "a.json", '{"poses": [\n {"time": 0, "x": 0, "y": 0, "z": 0, "qx": 0, "qy": 0,'
                                     ' "qz": 0, "qw": 1},\n {"time": 1, "x": 0, "y": 0, "z": 0}\n]}\n', {}, 3,
     "poses[1].qx"),
    ("json-pose-not-an-object", "a.json", '{"poses": [\n {"time": 0, "x": 0, "y": 0, "z": 0, "qx": 0, "qy": 0,'
                                          ' "qz": 0, "qw": 1},\n [1, 2]\n]}\n', {}, 1, "poses[1]"),
    ("json-too-deep", "a.json", '{"poses": ' + "[" * 100 + "]" * 100 + "}", {}, 1, None),
    ("fov-out-of-range", "a.csv", "time,x,y,z,yaw,pitch,roll,fov_y_deg\n0,0,0,0,0,0,0,180\n", {}, 2, "fov_y_deg"),
    ("angles-in-other-convention", "a.csv", "# hi\ntime,x,y,z,yaw,pitch,roll\n0,0,0,0,0,0,0\n",
     {"convention": "unity"}, 2, "yaw"),
    ("unknown-format", "a.txt", "1 2 3\n", {}, 1, "format"),
    ("kitti-times-count", "a.txt", "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1 0\n", {"times_file": "t.txt"},
     1, "time"),
]


@pytest.mark.parametrize("name, text, kwargs, line, field", [b[1:] for b in BROKEN], ids=[b[0] for b in BROKEN])
def test_broken_file_raises_input_error_naming_file_line_and_field(tmp_path, name, text, kwargs, line, field):
    file = tmp_path / name
    file.write_text(text)
    if "times_file" in kwargs:
        (tmp_path / "t.txt").write_text("0.0\n")
        kwargs = {"times_file": tmp_path / "t.txt"}
    with pytest.raises(InputError) as caught:
        read_path(file, **kwargs)
    err = caught.value
    located = tmp_path / "t.txt" if "times_file" in kwargs else file
    assert (err.file, err.line, err.field) == (str(located), line, field)
    assert str(err).startswith(f"{located}:{line}: ")


def test_kitti_without_times_names_the_missing_argument():
    with pytest.raises(InputError, match="times_file"):
        read_path(DATA / "kitti_00_head.txt")


def test_missing_file_is_input_error(tmp_path):
    with pytest.raises(InputError, match="expected an existing camera-path file"):
        read_path(tmp_path / "nowhere.txt", format="tum")


def test_bad_arguments_name_the_argument():
    for kwargs, message in (({"format": "bvh"}, "format: expected one of"), ({"convention": "zup"}, "convention:"),
                            ({"scale": 0.0}, "scale:"), ({"fps": -1.0}, "fps:"), ({"offset": (1, 2)}, "offset:")):
        with pytest.raises(ValueError, match=message):
            read_path(DATA / "tum_fr2_desk_orbslam_head.txt", **kwargs)


def _data_lines(file: Path, comment: str = "#") -> list[list[str]]:
    lines = [line.strip() for line in file.read_text().splitlines()]
    return [line.replace(",", " ").split() for line in lines if line and not line.startswith(comment)]


FIXTURES = [
    # (file, read_path arguments, seconds per time unit in its first column or None)
    ("tum_fr1_xyz_head.txt", {"convention": "mocap"}, 1.0),
    ("tum_fr2_desk_orbslam_head.txt", {}, 1.0),
    ("kitti_00_head.txt", {"times_file": "kitti_00_head_times.txt"}, None),
    ("euroc_v102_head.csv", {}, 1e-9),
]
REAL = [
    ("tum_freiburg1_xyz_groundtruth.txt", {"convention": "mocap"}, 1.0),
    ("tum_fr2_desk_orbslam.txt", {}, 1.0),
    ("kitti_00_first800.txt", {"times_file": "kitti_00_first800_times.txt"}, None),
    ("euroc_v102_groundtruth_50hz.csv", {}, 1e-9),
]


def _check_recording(folder: Path, name: str, kwargs: dict, unit):
    kwargs = {k: folder / v if k == "times_file" else v for k, v in kwargs.items()}
    path = read_path(folder / name, **kwargs)
    rows = _data_lines(folder / name)
    assert len(path) == len(rows)
    stamps = _data_lines(kwargs["times_file"]) if unit is None else rows
    expected = (float(stamps[-1][0]) - float(stamps[0][0])) * (unit or 1.0)
    # Times are kept as recorded: float64 resolves 0.24 µs at the 1.4e9 s of these epochs.
    assert path.times[-1] - path.times[0] == pytest.approx(expected, abs=1e-6)
    # Every one of these recordings was made by a camera held (or mounted) upright: with the
    # right convention the camera's up vector points up in csmlab's world on average.
    up = quat_to_matrix(path.orientations)[:, :, 1]
    assert np.mean(up[:, 1]) > 0.6
    return path


@pytest.mark.parametrize("name, kwargs, unit", FIXTURES)
def test_recording_excerpts_read_with_their_counts_and_durations(name, kwargs, unit):
    _check_recording(DATA, name, kwargs, unit)


@pytest.mark.parametrize("name, kwargs, unit", REAL)
def test_real_recordings_read_with_their_counts_and_durations(name, kwargs, unit):
    path = _check_recording(REAL_DATA, name, kwargs, unit)
    assert 25.0 < path.times[-1] - path.times[0] < 100.0


def test_a_path_spanning_more_frames_than_the_limit_is_refused_before_resampling(tmp_path):
    file = tmp_path / "long.txt"
    file.write_text("0 0 0 0 0 0 0 1\n1e12 0 0 1 0 0 0 1\n")
    with pytest.raises(InputError, match="at most 10,000,000 frames at 30 fps .*1e\\+12 s.*got 30,000,000,000,001"):
        read_path(file, format="tum", fps=30.0)


def test_stamps_near_the_float_limit_raise_no_overflow_warning(tmp_path):
    import warnings

    file = tmp_path / "far.csv"
    file.write_text("time,x,y,z,qx,qy,qz,qw\n0,0,0,0,0,0,0,1\n1,0,0,0,0,0,0,1\n1e308,0,0,0,0,0,0,1\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        assert read_path(file).times[-1] == 1e308
