"""Smoke tests: every preset validates, every experiment file runs end to end at a tiny size.

Tiny: 2 frames of 32×18 pixels, 64² maps, the first two values of a sweep, and the terrain's
height field and tree count cut down (the full terrain is the scene tests' business and costs
seconds per run here).
"""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest

from csmlab.config import (CONFIGS_DIR, PROJECT_DIR, experiment_document, find_experiment, list_experiments,
                           list_presets, load_experiment)
from csmlab.experiment import run_experiment

TINY = """
extends = ["{path}"]

[camera]
frames = 2
width = 32
height = 18

[shadow]
resolution = 64
"""


def _plain(value):
    return [_plain(v) for v in value] if isinstance(value, (list, tuple)) else value


@pytest.mark.parametrize("preset", sorted(list_presets()))
def test_preset_resolves_to_the_values_it_sets(tmp_path, preset):
    """Every value a preset file writes reaches the resolved experiment: its sections' fields, and its
    [[methods]] entries' fields in that method's shadow settings (read from the file, not from csmlab)."""
    path = tmp_path / "exp.toml"
    camera = "" if preset.startswith("paths/") else '[camera]\npath = "walk"\n'
    path.write_text(f'extends = ["{preset}"]\n{camera}')
    experiment = load_experiment(path)
    written = tomllib.loads((CONFIGS_DIR / f"{preset}.toml").read_text())
    document = experiment_document(experiment)
    checked = 0
    for section, table in written.items():
        if section in ("description", "extends"):
            continue
        if section == "methods":
            resolved = {m.name: m.settings for m in experiment.methods}
            for entry in table:
                settings = resolved[entry["name"]]
                for key, value in entry.items():
                    if key not in ("name", "description"):
                        # shadow_distance = "camera_far" names where the shadow ends (shadow_distance_from).
                        attribute = {"lambda": "lambda_"}.get(key, key)
                        if key == "shadow_distance" and isinstance(value, str):
                            attribute = "shadow_distance_from"
                        assert _plain(getattr(settings, attribute)) == value, (entry, key)
                        checked += 1
            continue
        for key, value in table.items():
            assert _plain(document[section][key]) == value, (section, key)
            checked += 1
    assert checked > 0, f"{preset} sets nothing"


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(list_experiments()))
def test_experiment_runs_at_tiny_size(tmp_path, name):
    source = find_experiment(name)
    full = load_experiment(source)
    text = TINY.format(path=source.as_posix())
    if full.scene.kind == "terrain":
        text += "[scene]\nresolution = 24\ntrees = 60\nring_trees = 60\n"
    if full.sweep:
        text += "[sweep]\n" + "".join(f"{k} = {list(v[:2])}\n" for k, v in full.sweep).replace(
            "resolution = [512, 1024]", "resolution = [32, 64]")
    path = tmp_path / f"{name}.toml"
    path.write_text(text)
    result = run_experiment(load_experiment(path), out_dir=tmp_path / "out")
    assert list(result.summary["methods"]) == [m.name for m in full.methods]
    assert result.frames == 2 and (tmp_path / "out" / "metrics.csv").is_file()


@pytest.mark.parametrize("name", sorted(list_experiments()))
def test_experiment_reads_only_files_inside_the_repository(name):
    """A lone clone runs every shipped experiment: no file it names lies outside the repository."""
    experiment = load_experiment(find_experiment(name))
    named = [experiment.scene.file, experiment.camera.file, experiment.camera.times_file]
    for file in filter(None, named):
        resolved = Path(file).resolve()
        assert resolved.is_file() and resolved.is_relative_to(PROJECT_DIR), file
