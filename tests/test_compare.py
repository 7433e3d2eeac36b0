"""csmlab compare: two runs of one workload, A against B, from their results folders; other workloads refused."""

from __future__ import annotations

import json
import math
import shutil
from html.parser import HTMLParser
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest
from typer.testing import CliRunner

from csmlab.cli import app
from csmlab.compare import compare_runs, flatten, metric_direction
from csmlab.config import EXPERIMENTS_DIR, load_experiment
from csmlab.errors import InputError
from csmlab.experiment import run_experiment

DEFAULT = EXPERIMENTS_DIR / "default.toml"
TINY = """extends = ["{default}"]
name = "{name}"
[camera]
frames = 3
width = 96
height = 54
[light]
elevation_deg = {elevation}
[shadow]
cascades = 2
resolution = {resolution}
"""


def _listing(directory: Path) -> dict[str, bytes]:
    return {p.relative_to(directory).as_posix(): p.read_bytes() for p in sorted(directory.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """The default experiment at tiny size: A at 128² cascades, B at 256², C another light (another workload)."""
    root = tmp_path_factory.mktemp("compare")
    for name, resolution, elevation in (("a", 128, 40.0), ("b", 256, 40.0), ("c", 128, 60.0)):
        (root / f"{name}.toml").write_text(TINY.format(default=DEFAULT.as_posix(), name=f"tiny_{name}",
                                                       resolution=resolution, elevation=elevation))
        run_experiment(load_experiment(root / f"{name}.toml"), out_dir=root / name)
    before = {name: _listing(root / name) for name in ("a", "b")}
    outcome = CliRunner().invoke(app, ["compare", str(root / "a"), str(root / "b"), "--out", str(root / "ab")])
    assert outcome.exit_code == 0, outcome.output
    return root, before


def test_compare_reads_only_the_results_folders(runs):
    root, before = runs
    assert {name: _listing(root / name) for name in ("a", "b")} == before


def test_two_different_workloads_exit_2_naming_what_differs(runs, tmp_path):
    root, _ = runs
    outcome = CliRunner().invoke(app, ["compare", str(root / "a"), str(root / "c"), "--out", str(tmp_path / "x")])
    assert outcome.exit_code == 2
    assert "light.elevation_deg: 40.0 vs 60.0" in outcome.output and "summary.json" in outcome.output
    assert "Traceback" not in outcome.output and not (tmp_path / "x").exists()


def test_a_folder_without_a_finished_run_exits_2(runs, tmp_path):
    root, _ = runs
    outcome = CliRunner().invoke(app, ["compare", str(root / "a"), str(tmp_path), "--out", str(tmp_path / "x")])
    assert outcome.exit_code == 2 and "summary.json" in outcome.output


def test_doubled_resolution_doubles_rho_and_quadruples_memory_marked_better_and_worse(runs):
    root, _ = runs
    comparison = compare_runs(root / "a", root / "b")
    assert comparison.matched == [("exact", "base"), ("quantized", "base"), ("none", "base")]
    assert ("shadow.resolution", 128, 256) in comparison.settings
    assert all(not key.startswith(("scene", "camera", "light")) for key, _, _ in comparison.settings)
    for pair, deltas in comparison.deltas.items():
        by_metric = {d.metric: d for d in deltas}
        rho, memory = by_metric["rho_median"], by_metric["memory_bytes"]
        # ρ is linear in texels per side: twice the texels over the same boxes, twice ρ.
        assert rho.b / rho.a == pytest.approx(2.0, rel=0.05), pair
        # Median and p95 ρ are best at 1: B is better exactly when it lies closer to 1 on a log scale.
        for closest_to_one in (rho, by_metric["rho_p95"]):
            nearer = abs(math.log(closest_to_one.b)) < abs(math.log(closest_to_one.a))
            assert closest_to_one.verdict == ("better" if nearer else "worse"), (pair, closest_to_one)
        assert rho.beyond_tolerance
        assert memory.b == 4 * memory.a and memory.verdict == "worse"


def test_a_method_in_one_run_only_is_listed_as_such(runs, tmp_path):
    root, _ = runs
    shutil.copytree(root / "b", tmp_path / "b")
    summary = json.loads((tmp_path / "b" / "summary.json").read_text())
    del summary["methods"]["none"], summary["points"]["base"]["none"]
    (tmp_path / "b" / "summary.json").write_text(json.dumps(summary))
    comparison = compare_runs(root / "a", tmp_path / "b")
    assert comparison.only_a == [("none", "base")] and comparison.only_b == []
    outcome = CliRunner().invoke(app, ["compare", str(root / "a"), str(tmp_path / "b"), "--out", str(tmp_path / "r")])
    assert outcome.exit_code == 0, outcome.output
    assert "Only in A: none" in (tmp_path / "r" / "index.html").read_text()


def test_methods_config_entries_are_keyed_by_name_and_directions_follow_the_gate():
    flat = flatten({"shadow": {"resolution": 512}, "methods": [{"name": "q", "levels": 4}]})
    assert flat == {"shadow.resolution": 512, "methods[q].levels": 4, "methods[q]": "present"}
    assert (metric_direction("flicker"), metric_direction("rho_median_c1"), metric_direction("rho_p95")) == \
        ("lower", "one", "one")


class _References(HTMLParser):
    def __init__(self):
        super().__init__()
        self.found = []

    def handle_starttag(self, tag, attrs):
        self.found += [value for name, value in attrs if name in ("src", "href") and value]


# metric, A, B within the gate's tolerance, B beyond it (both the wrong way), worked by hand from the
# registry's (abs, rel): allowed = max(abs, rel · |A|); for rho_median on the |ln ρ| scale.
HAND_WORKED = [
    ("rho_median", 1.6, 1.605, 1.61),             # (1e-6, 0.005): ln(1 + 0.008/1.6) = 0.00499; ln(1.605/1.6) =
                                                  # 0.00312, ln(1.61/1.6) = 0.00623
    ("rho_p05", 0.8, 0.797, 0.795),               # (1e-6, 0.005): 0.004
    ("rho_frac_lt1", 0.5, 0.509, 0.511),          # (1e-3, 0.02): 0.01
    ("utilization", 0.4, 0.397, 0.395),           # (1e-4, 0.01): 0.004
    ("ssim", 0.9, 0.892, 0.89),                   # (1e-4, 0.01): 0.009
    ("flicker", 0.01, 0.0104, 0.0106),            # (1e-6, 0.05): 0.0005
    ("flip_rate", 0.02, 0.0209, 0.0211),          # (1e-6, 0.05): 0.001
    ("de2000_mean", 2.0, 2.09, 2.11),             # (1e-3, 0.05): 0.1
    ("de2000_frac_jnd", 0.1, 0.104, 0.106),       # (1e-5, 0.05): 0.005
    ("flip", 0.02, 0.0209, 0.0211),               # (1e-5, 0.05): 0.001
    ("ref_false_shadow", 0.02, 0.0209, 0.0211),   # (1e-4, 0.05): 0.001
    ("ref_boundary_px", 3.0, 3.29, 3.31),         # (1e-3, 0.10): 0.3
    ("texels_rasterized", 1e6, 1.09e6, 1.11e6),   # (0, 0.10): 100,000
]


def _summary_folder(folder: Path, values: dict) -> Path:
    """A results folder holding only a summary.json of one method ``m`` with ``values``."""
    folder.mkdir()
    entry = {**values, "frames": 3}
    (folder / "summary.json").write_text(json.dumps({
        "name": "hand", "workload_hash": "w", "config": {}, "light_moves": False, "point_fields": {"base": {}},
        "stabilization": {"m": {"base": "exact"}}, "methods": {"m": entry}, "points": {"base": {"m": entry}}}))
    return folder


def _deltas(tmp_path, a: dict, b: dict) -> dict:
    comparison = compare_runs(_summary_folder(tmp_path / "a", a), _summary_folder(tmp_path / "b", b))
    return {d.metric: d for d in comparison.deltas[("m", "base")]}


@pytest.mark.parametrize("beyond", [False, True])
def test_a_change_is_flagged_beyond_tolerance_by_hand_worked_numbers(tmp_path, beyond):
    a = {metric: value for metric, value, _, _ in HAND_WORKED}
    b = {metric: (out if beyond else within) for metric, _, within, out in HAND_WORKED}
    deltas = _deltas(tmp_path, a, b)
    for metric, *_ in HAND_WORKED:
        assert (deltas[metric].verdict, deltas[metric].beyond_tolerance) == ("worse", beyond), metric


def test_closest_to_one_is_judged_on_the_log_scale_as_the_gate_does(tmp_path):
    """0.5 → 2.0 is as far from 1 as before: moved, neither better nor worse, not beyond (a linear margin
    flags 1.5 ≫ 0.0025); 0.9 → 1.1 is nearer, by |ln 1.1| − |ln 0.9| = −0.0101, beyond ln(1.005) = 0.00499."""
    deltas = _deltas(tmp_path, {"rho_median": 0.5, "rho_p95": 0.9}, {"rho_median": 2.0, "rho_p95": 1.1})
    assert (deltas["rho_median"].verdict, deltas["rho_median"].beyond_tolerance) == ("changed", False)
    assert (deltas["rho_p95"].verdict, deltas["rho_p95"].beyond_tolerance) == ("better", True)


def test_report_shows_curves_and_the_frames_that_differ_most_with_every_file_present(runs):
    root, _ = runs
    page = root / "ab" / "index.html"
    parser = _References()
    parser.feed(page.read_text(encoding="utf-8"))
    references = [r for r in parser.found if not r.startswith(("#", "data:"))]
    assert "figures/curves.png" in references
    assert any(r.startswith("figures/frame__f") for r in references)
    assert [r for r in references if not (page.parent / r).is_file()] == []
    text = page.read_text(encoding="utf-8")
    assert "shadow.resolution" in text and "Frames where B differs most from A" in text


@pytest.fixture(scope="module")
def browser():
    webdriver = pytest.importorskip("selenium.webdriver")
    missing = [p for p in ("chromium", "chromedriver") if shutil.which(p) is None]
    if missing:
        pytest.skip(f"{' and '.join(missing)} not installed (Debian: apt-get install chromium chromium-driver)")
    options = webdriver.ChromeOptions()
    options.binary_location = shutil.which("chromium")
    for argument in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                     "--window-size=1400,1800", "--allow-file-access-from-files"):
        options.add_argument(argument)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(options=options, service=webdriver.ChromeService(shutil.which("chromedriver")))
    yield driver
    driver.quit()


def _images(browser) -> list:
    return browser.execute_script(
        "return Array.from(document.images).map(i => [i.getAttribute('src'), i.complete, i.naturalWidth]);")


def test_browser_check_catches_a_missing_image(browser, tmp_path):
    """The check below must be able to fail."""
    page = tmp_path / "broken.html"
    page.write_text('<!DOCTYPE html><html><head><link rel="icon" href="data:,"></head><body><img src="no.png"></body>')
    browser.get(page.resolve().as_uri())
    assert [(src, width) for src, _, width in _images(browser)] == [("no.png", 0)]


def test_comparison_opens_in_headless_chromium_with_every_image(runs, browser, tmp_path):
    root, _ = runs
    browser.get_log("browser")
    browser.get((root / "ab" / "index.html").resolve().as_uri())
    images = _images(browser)
    assert len(images) >= 2
    assert [src for src, complete, width in images if not complete or width == 0] == []
    assert [e for e in browser.get_log("browser") if e["level"] in ("SEVERE", "WARNING")] == []
    shot = tmp_path / "compare.png"
    browser.save_screenshot(str(shot))
    assert np.std(iio.imread(shot)[..., :3]) > 20, "a blank screenshot"


def test_compare_refuses_through_the_library_too(runs):
    root, _ = runs
    with pytest.raises(InputError, match="workload_hash"):
        compare_runs(root / "a", root / "c")
