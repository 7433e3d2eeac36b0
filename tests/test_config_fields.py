"""Every documented field fed its bad values: the loader answers with one located input error, never a crash.

The cases are generated from the schema (the records of :mod:`csmlab.config.records` and
:class:`~csmlab.settings.ShadowSettings`, their type hints and their own range checks), loaded from
small TOML files without running anything.
"""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from csmlab.cli import app

TINY = """
[scene]
kind = "plane_box"
[camera]
path = "walk"
frames = 2
width = 32
height = 18
[shadow]
cascades = 3
resolution = 64
"""


@pytest.mark.parametrize("splits, words", [
    ("[0.5, 0.2, 1.0]", "increasing"),
    ("[60.0, 20.0, 200.0]", "increasing"),
    ("[0.2, 0.5, 0.9]", "ending at 1.0"),
    ("[20.0, 60.0, 150.0]", "end at the shadow distance"),
    ("[0.0001, 0.5, 1.0]", "above near"),
])
def test_manual_splits_out_of_order_or_short_of_the_shadow_exit_2_naming_the_file_and_splits(tmp_path, splits, words):
    path = tmp_path / "exp.toml"
    path.write_text(TINY + f'split = "manual"\nsplits = {splits}\n')
    outcome = CliRunner().invoke(app, ["run", str(path), "--out", str(tmp_path / "out")])
    assert outcome.exit_code == 2, outcome.output
    message = outcome.stderr.strip()
    assert len(message.splitlines()) == 1 and "Traceback" not in outcome.output
    assert f"{path}:" in message and "shadow.splits" in message and words in message
    assert not (tmp_path / "out").exists()
