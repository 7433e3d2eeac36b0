"""The csmlab command: a run end to end, list and show, and one test per class of bad input (exit 2)."""

from __future__ import annotations

import json
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
from typer.testing import CliRunner

from csmlab.cli import app

TINY = """
name = "tiny"
extends = ["methods/exact", "methods/none"]

[scene]
kind = "plane_box"

[camera]
path = "walk"
frames = 3
width = 48
height = 27

[shadow]
cascades = 2
resolution = 64
shadow_distance = 40.0
"""

PATH_FILE = "1.0 0 0 0 0 0 0 1\n1.1 0 0 0 0 0 0 1\n1.2 0 0 0 0 0 0 1\n"


def invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args])


def test_run_writes_results_report_and_prints_the_summary_table(tmp_path):
    (tmp_path / "tiny.toml").write_text(TINY)
    outcome = invoke("run", tmp_path / "tiny.toml", "--out", tmp_path / "out")
    assert outcome.exit_code == 0, outcome.output
    out = tmp_path / "out"
    assert {"metrics.csv", "summary.json", "timings.csv", "config.resolved.toml", "index.html"} <= {
        p.name for p in out.iterdir()}
    summary = json.loads((out / "summary.json").read_text())
    assert list(summary["methods"]) == ["exact", "none"]
    assert "flicker_same" in outcome.stdout and "exact" in outcome.stdout and "index.html" in outcome.stdout
    # The report line says what the report's size budget kept: at this size, everything.
    lines = outcome.stdout.splitlines()
    assert any(line.startswith("report:") and line.rstrip().endswith("index.html") for line in lines)
    assert "budget: Explore holds every frame (3 of 3); animations kept" in " ".join(outcome.stdout.split())


def test_list_names_scenes_paths_formats_methods_presets_and_experiments():
    outcome = invoke("list")
    assert outcome.exit_code == 0
    for name in ("terrain", "walk", "tum", "mocap", "quantized", "pcf_bilinear", "methods/exact", "gate"):
        assert name in outcome.stdout


def test_show_prints_the_resolved_experiment_as_toml():
    outcome = invoke("show", "gate")
    assert outcome.exit_code == 0
    document = tomllib.loads(outcome.stdout)
    assert [m["name"] for m in document["methods"]] == ["exact", "quantized", "none"]
    assert document["shadow"]["resolution"] == 256


def bad(tmp_path, text: str, extra_files=None, args=()):
    for name, content in (extra_files or {}).items():
        (tmp_path / name).write_text(content)
    path = tmp_path / "exp.toml"
    path.write_text(text)
    return path, invoke("run", path, "--out", tmp_path / "out", *args)


BAD_INPUTS = {
    "malformed TOML": ('[camera]\npath = "walk"\nframes = = 3\n', {}, "exp.toml:3", "valid TOML"),
    "unknown field": (TINY.replace("frames = 3", "frame = 3"), {}, "camera.frame", "did you mean 'frames'"),
    "wrong type": (TINY.replace("frames = 3", 'frames = "3"'), {}, "camera.frames", "an integer"),
    "out of range": (TINY.replace("cascades = 2", "cascades = 11"), {}, "shadow.cascades", "1..10"),
    "unknown scene": (TINY.replace('"plane_box"', '"plane_bx"'), {}, "scene.kind", "plane_box"),
    "unknown path generator": (TINY.replace('"walk"', '"wlak"'), {}, "camera.path", "walk"),
    "unknown method name": (TINY + '[[methods]]\nname = "x"\nstabilization = "exakt"\n', {},
                            "methods.x.stabilization", "exact"),
    "missing path file": (TINY.replace('path = "walk"', 'file = "gone.txt"\nformat = "tum"'), {}, "camera.file",
                          "gone.txt"),
    "NaN pose": (TINY.replace('path = "walk"', 'file = "nan.txt"\nformat = "tum"\nconvention = "tum"'),
                 {"nan.txt": PATH_FILE.replace("1.1 0 0 0", "1.1 nan 0 0")}, "nan.txt:2", "tx"),
    "unreadable mesh": (TINY.replace('kind = "plane_box"', 'kind = "mesh"\nfile = "junk.obj"'),
                        {"junk.obj": "solid nonsense\n"}, "junk.obj", "file"),
    "zero light direction": (TINY + "[light]\ndirection = [0.0, 0.0, 0.0]\n", {}, "light.direction", "non-zero"),
    "missing experiment": (None, {}, "nowhere.toml", "EXPERIMENT"),
}


@pytest.mark.parametrize("case", list(BAD_INPUTS))
def test_bad_input_exits_2_with_one_line_naming_file_and_field(tmp_path, case):
    text, files, where, words = BAD_INPUTS[case]
    if text is None:
        outcome = invoke("run", tmp_path / "nowhere.toml")
    else:
        _, outcome = bad(tmp_path, text, files)
    assert outcome.exit_code == 2, outcome.output
    message = outcome.stderr.strip()
    assert len(message.splitlines()) == 1 and "Traceback" not in outcome.output
    assert where in message and words in message
    assert not (tmp_path / "out" / "metrics.csv").exists() and not (tmp_path / "out" / "summary.json").exists()


def test_cuda_requested_without_a_gpu_exits_2(tmp_path):
    import warp as wp

    wp.init()
    if wp.get_cuda_device_count() > 0:
        pytest.skip("this machine has a CUDA device")
    _, outcome = bad(tmp_path, TINY, args=("--device", "cuda"))
    assert outcome.exit_code == 2 and "--device" in outcome.stderr


def test_console_script_entry_point_reports_bad_input_without_traceback(tmp_path):
    path = tmp_path / "exp.toml"
    path.write_text("[camera]\npath = 3\n")
    done = subprocess.run([sys.executable, "-m", "csmlab.cli", "show", str(path)], capture_output=True, text=True)
    assert done.returncode == 2
    assert done.stderr.strip().startswith("csmlab: error:") and "camera.path" in done.stderr
    assert "Traceback" not in done.stderr


NEW_FIELD_BAD_VALUES = {
    "distribution_exponent": ("0.5", "a ratio of at least 1"),
    "first_cascade_far": ("50.0", "below shadow_distance"),
    "extent": ('"cube"', "sphere"),
    "snap": ('"corner"', "centre"),
    "depth_range": ('"light"', "slice"),
    "pancake": ("-1.0", "non-negative"),
    "depth_clamp": ('"yes"', "true or false"),
    "fade_out": ("1.5", "[0, 1]"),
    "bounds": ('"visible"', "sdsm"),
    "hysteresis": ("1.0", "[0, 1)"),
    "engine_precision": ('"float16"', "float32"),
}


@pytest.mark.parametrize("field", list(NEW_FIELD_BAD_VALUES))
def test_bad_value_of_an_engine_field_exits_2_naming_it(tmp_path, field):
    value, words = NEW_FIELD_BAD_VALUES[field]
    split = 'split = "geometric"\n' if field == "first_cascade_far" else ""
    _, outcome = bad(tmp_path, TINY + f'[[methods]]\nname = "x"\n{split}{field} = {value}\n')
    assert outcome.exit_code == 2, outcome.output
    message = outcome.stderr.strip()
    assert len(message.splitlines()) == 1 and f"methods.x.{field}" in message and words in message, message


def test_bad_scene_offset_exits_2_naming_it(tmp_path):
    _, outcome = bad(tmp_path, TINY.replace('kind = "plane_box"', 'kind = "plane_box"\noffset = [1.0, 2.0]'))
    assert outcome.exit_code == 2 and "scene.offset" in outcome.stderr and "3 numbers" in outcome.stderr


def test_list_names_every_engine_choice():
    outcome = invoke("list")
    assert outcome.exit_code == 0
    for name in ("exponent", "geometric", "diagonal", "centre", "sdsm", "float32", "engines/ue5", "seeds/ogldev49",
                 "hard_far_origin"):
        assert name in outcome.stdout, name


def test_help_keeps_the_toml_table_names_that_rich_would_read_as_markup():
    result = CliRunner().invoke(app, ["tune", "--help"], env={"COLUMNS": "200"})
    assert result.exit_code == 0
    text = " ".join(result.output.split())
    assert "its [tune] table" in text and "A [shadow] field to search" in text


# --- options validated as options: the option is named, and nothing is written ------------------

BEVY = Path(__file__).parent / "data" / "engines" / "bevy" / "sun.scn.ron"


def _tree(folder: Path) -> list[tuple[str, int]]:
    """Every path under ``folder`` with its size (folders 0): what a refused command must leave as it was."""
    return sorted((str(p.relative_to(folder)), p.stat().st_size if p.is_file() else 0) for p in folder.rglob("*"))


@pytest.mark.parametrize("option, value, words", [
    ("--frames", "0", "at least 1, got 0"),
    ("--jobs", "-2", "at least 1"),
    ("--device", "gpu0", "cpu, cuda or cuda:N"),
])
def test_a_bad_run_option_exits_2_naming_the_option_and_writes_nothing(tmp_path, option, value, words):
    (tmp_path / "exp.toml").write_text(TINY)
    before = _tree(tmp_path)
    outcome = invoke("run", tmp_path / "exp.toml", "--out", tmp_path / "out", option, value)
    assert outcome.exit_code == 2 and f"{option}: expected" in outcome.stderr and words in outcome.stderr
    assert len(outcome.stderr.strip().splitlines()) == 1 and _tree(tmp_path) == before


def test_run_out_naming_an_existing_file_exits_2_and_leaves_it(tmp_path):
    (tmp_path / "exp.toml").write_text(TINY)
    (tmp_path / "taken").write_text("mine\n")
    outcome = invoke("run", tmp_path / "exp.toml", "--out", tmp_path / "taken")
    assert outcome.exit_code == 2 and "--out: expected a folder for the results, got an existing file" in outcome.stderr
    assert (tmp_path / "taken").read_text() == "mine\n"


@pytest.mark.parametrize("setup, target, words", [
    (lambda t: (t / "folder").mkdir(), "folder", "expected a file to write, got an existing folder"),
    (lambda t: None, "missing/preset.toml", "does not exist"),
    (lambda t: (t / "locked").mkdir(mode=0o500), "locked/preset.toml", "read-only folder"),
])
def test_import_out_that_cannot_be_a_file_exits_2_naming_out_and_touches_nothing(tmp_path, setup, target, words):
    import os

    setup(tmp_path)
    if target.startswith("locked") and os.access(tmp_path / "locked", os.W_OK):
        pytest.skip("this user writes into read-only folders (root)")
    before = _tree(tmp_path)
    outcome = invoke("import", "bevy", BEVY, "--out", tmp_path / target)
    assert outcome.exit_code == 2, outcome.output
    assert "--out: " in outcome.stderr and words in outcome.stderr and "Traceback" not in outcome.output
    assert _tree(tmp_path) == before


def test_a_bad_name_is_blamed_on_the_name_option_not_the_input_file(tmp_path):
    outcome = invoke("import", "bevy", BEVY, "--out", tmp_path / "sun.toml", "--name", "my sun")
    assert outcome.exit_code == 2
    assert "--name: expected a method name" in outcome.stderr and str(BEVY) not in outcome.stderr
    assert not (tmp_path / "sun.toml").exists()
    default = invoke("import", "bevy", BEVY, "--out", tmp_path / "my sun.toml")
    assert default.exit_code == 2 and "--out: expected a method name" in default.stderr
