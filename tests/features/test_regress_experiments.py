"""Every shipped experiment passes the gate against its own baseline: it promises nothing it cannot keep.

Tiny, as the smoke tests of ``test_presets`` (32×18 pixels, 64² maps, the terrain cut down, a sweep's
first two values) but 3 frames, so that two frames have a temporal value. Before the promise was
derived from the settings, ``engines`` (Bevy's pancaked slice boxes), ``hard_dueling`` and
``hard_sdsm`` (SDSM's moving splits) and ``hard_zoom`` (a changing field of view) failed here.
"""

from __future__ import annotations

import pytest

from csmlab.config import find_experiment, list_experiments, load_experiment
from csmlab.experiment import run_experiment
from csmlab.regress import regress, write_baseline

pytestmark = pytest.mark.slow

TINY = """
extends = ["{path}"]

[camera]
frames = 3
width = 32
height = 18

[shadow]
resolution = 64
"""


def _tiny(name: str) -> str:
    source = find_experiment(name)
    full = load_experiment(source)
    text = TINY.format(path=source.as_posix())
    if full.scene.kind == "terrain":
        text += "[scene]\nresolution = 24\ntrees = 60\nring_trees = 60\n"
    if full.sweep:
        text += "[sweep]\n" + "".join(f"{k} = {list(v[:2])}\n" for k, v in full.sweep).replace(
            "resolution = [512, 1024]", "resolution = [32, 64]")
    return text


@pytest.mark.parametrize("name", sorted(list_experiments()))
def test_experiment_passes_regress_against_its_own_baseline(tmp_path, name):
    path = tmp_path / f"{name}.toml"
    path.write_text(_tiny(name))
    run_experiment(load_experiment(path), out_dir=tmp_path / "run")
    write_baseline(tmp_path / "run", tmp_path / "baseline.json")
    result = regress(tmp_path / "run", tmp_path / "baseline.json")
    assert result.passed, [(c.method, c.point, c.metric, c.now, c.verdict, c.why) for c in result.failures]
