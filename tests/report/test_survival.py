"""The report is written for every run that wrote its results: the edge cases a real run reaches.

Each case is a real run of the runner (in this process, a few frames of 64 × 36 pixels) followed by
:func:`csmlab.report.write_report`; the oracle is the report page with every file it references
present, and the summary saying what the case must (no pixel in a cascade: no ρ).
"""

from __future__ import annotations

import json
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest

from csmlab.config import load_experiment
from csmlab.experiment import run_experiment
from csmlab.report import write_report
from csmlab.report.images import snapshot_strip_figures

pytestmark = pytest.mark.slow

PLANE_BOX = 'kind = "plane_box"'
FAR_MESH = 'kind = "mesh"\nfile = "far.obj"'
FAR_PYRAMID = """v 5000 0 5000
v 5002 0 5000
v 5001 0 5002
v 5001 2 5001
f 1 2 3
f 1 4 2
f 2 4 3
f 3 4 1
"""
"""A 2 m pyramid 7 km from the origin: no pixel of the walk's view sees it, so no cascade covers a pixel."""


def _experiment(scene: str, *, frames: int, methods: list[tuple[str, str]], camera: str = "") -> str:
    text = (f'name = "case"\n[scene]\n{scene}\n'
            f'[camera]\npath = "walk"\nframes = {frames}\nwidth = 64\nheight = 36\n{camera}'
            '[light]\nelevation_deg = 40.0\nazimuth_deg = 30.0\n[shadow]\ncascades = 2\nresolution = 128\n')
    return text + "".join(f'[[methods]]\nname = "{name}"\n{extra}\n' for name, extra in methods)


class _References(HTMLParser):
    def __init__(self):
        super().__init__()
        self.found = []

    def handle_starttag(self, tag, attrs):
        self.found += [value for name, value in attrs if name in ("src", "href") and value]


def _report(tmp_path: Path, text: str, *, mesh_text: str | None = None) -> tuple[Path, dict]:
    """Run ``text`` and write its report; the page (checked: every local file it names exists) and the summary."""
    if mesh_text is not None:
        (tmp_path / "far.obj").write_text(mesh_text)
    (tmp_path / "case.toml").write_text(text)
    out = tmp_path / "out"
    run_experiment(load_experiment(tmp_path / "case.toml"), out_dir=out, jobs=1)
    page = write_report(out).page
    parser = _References()
    parser.feed(page.read_text(encoding="utf-8"))
    missing = [r for r in parser.found if not r.startswith(("#", "data:", "http")) and not (out / r).is_file()]
    assert page.is_file() and not missing, missing
    return page, json.loads((out / "summary.json").read_text())


def test_a_run_whose_cascades_cover_no_pixel_writes_its_report(tmp_path):
    # The walk kept at csmlab's own origin (fit_level = false): a path fitted to the level would find the pyramid.
    _, summary = _report(tmp_path, _experiment(FAR_MESH, frames=2, methods=[("exact", 'stabilization = "exact"')],
                                               camera="fit_level = false\n"), mesh_text=FAR_PYRAMID)
    assert summary["frames"] == 2 and summary["methods"]["exact"]["rho_median"] is None


def test_a_one_frame_run_writes_its_report(tmp_path):
    _, summary = _report(tmp_path, _experiment(PLANE_BOX, frames=1, methods=[
        ("exact", 'stabilization = "exact"'), ("none", 'stabilization = "none"')]))
    assert summary["frames"] == 1 and sorted(summary["methods"]) == ["exact", "none"]
    assert summary["methods"]["exact"]["rho_median"] is not None


def test_a_one_method_run_writes_its_report(tmp_path):
    _, summary = _report(tmp_path, _experiment(PLANE_BOX, frames=2, methods=[("exact", 'stabilization = "exact"')]))
    assert list(summary["methods"]) == ["exact"] and summary["methods"]["exact"]["rho_median"] is not None


def test_a_method_whose_cascades_hold_no_pixel_beside_one_that_does_writes_its_report(tmp_path):
    # shadow_distance 0.2 m (near is 0.1 m): every pixel of the view lies beyond the last cascade of "short".
    _, summary = _report(tmp_path, _experiment(PLANE_BOX, frames=2, methods=[
        ("exact", 'stabilization = "exact"'), ("short", 'stabilization = "exact"\nshadow_distance = 0.2')]))
    assert summary["methods"]["short"]["rho_median"] is None
    assert summary["methods"]["exact"]["rho_median"] is not None


def _blank_snapshot(height=36, width=64) -> dict:
    """A snapshot no pixel of which is valid or in a cascade."""
    nan = np.full((height, width), np.nan, np.float32)
    return {"valid": np.zeros((height, width), bool), "cascade": np.full((height, width), -1, np.int8),
            "shaded": np.full((height, width, 3), np.nan, np.float32), "rho": nan, "dS": nan,
            "ref_diff": np.zeros((height, width), np.int8)}


def test_a_strip_of_snapshots_without_a_cascaded_pixel_is_drawn(tmp_path):
    snapshot_strip_figures([([_blank_snapshot(), _blank_snapshot()], tmp_path / "strip.png", "frame 1")],
                           ["exact", "none"])
    from PIL import Image

    with Image.open(tmp_path / "strip.png") as image:
        assert image.size[0] > 64 and image.size[1] > 36
