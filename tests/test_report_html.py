"""The HTML report end to end: a tiny real run through the runner, then the page in a real browser.

The browser is Debian's headless ``chromium`` driven through ``chromedriver`` (package
``chromium-driver``) with the W3C WebDriver protocol spoken over plain HTTP, so no client
library is needed; the tests that need it skip, saying why, when either program is missing.
"""

import base64
import json
import shutil
import socket
import subprocess
import time
import urllib.error
import urllib.request
from html.parser import HTMLParser
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest

from csmlab import results
from csmlab.config import load_experiment
from csmlab.experiment import run_experiment
from csmlab.report import write_report

TINY = """
name = "tiny"
extends = ["scenes/plane_box", "paths/walk", "lights/sun_40", "methods/exact", "methods/none"]

[camera]
frames = 3
width = 96
height = 54

[shadow]
cascades = 2
resolution = 128
shadow_distance = 40.0
"""
RESULT_FILES = ("summary.json", "metrics.csv", "timings.csv", "cascades.csv", "config.resolved.toml")


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    """A 3-frame, 2-method run of the real runner, and its report."""
    root = tmp_path_factory.mktemp("report")
    (root / "tiny.toml").write_text(TINY)
    out = root / "tiny"
    run_experiment(load_experiment(root / "tiny.toml"), out_dir=out)
    return write_report(out)


class _References(HTMLParser):
    def __init__(self):
        super().__init__()
        self.found = []

    def handle_starttag(self, tag, attrs):
        self.found += [value for name, value in attrs if name in ("src", "href") and value]


def _references(page: Path) -> list[str]:
    parser = _References()
    parser.feed(page.read_text(encoding="utf-8"))
    return [r for r in parser.found if not r.startswith(("#", "data:"))]


def test_every_file_the_report_references_exists_and_none_is_remote(tiny_run):
    references = _references(tiny_run)
    assert not [r for r in references if "://" in r or r.startswith("//")]
    missing = [r for r in references if not (tiny_run.parent / r).is_file()]
    assert not missing
    assert {"figures/curves.png", "anim/exact__base.gif", "anim/none__base.gif"} <= set(references)
    assert any(r.startswith("figures/strip__") for r in references)
    assert any(r.startswith("figures/stabilization__") for r in references)
    assert any(r.startswith("figures/view3d__") for r in references)


def test_report_is_regenerated_byte_for_byte_from_the_results_files_alone(tiny_run, tmp_path):
    source = tiny_run.parent
    copy = tmp_path / "copy"
    copy.mkdir()
    for name in RESULT_FILES:
        shutil.copy(source / name, copy / name)
    for folder in ("anim", "snapshots"):
        (copy / folder).mkdir()
        for npz in (source / folder).glob("*.npz"):
            shutil.copy(npz, copy / folder / npz.name)
    page = write_report(copy)
    assert page.read_bytes() == tiny_run.read_bytes()
    made = sorted(p.relative_to(copy).as_posix() for p in copy.rglob("*") if p.is_file())
    assert made == sorted(p.relative_to(source).as_posix() for p in source.rglob("*") if p.is_file())
    for name in made:
        if name.endswith((".png", ".gif")) and "view3d" not in name:
            assert (copy / name).read_bytes() == (source / name).read_bytes(), name


class _WebDriver:
    """Just enough of the W3C WebDriver protocol to load a page, run a script, read the log, take a screenshot."""

    def __init__(self):
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
        self.base = f"http://127.0.0.1:{port}"
        self.process = subprocess.Popen([shutil.which("chromedriver"), f"--port={port}"],
                                        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        deadline = time.monotonic() + 30
        while True:
            try:
                self._call("GET", "/status")
                break
            except (urllib.error.URLError, ConnectionError):
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.1)
        options = {"binary": shutil.which("chromium"),
                   "args": ["--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                            "--window-size=1400,1800", "--allow-file-access-from-files"]}
        session = self._call("POST", "/session", {"capabilities": {"alwaysMatch": {
            "browserName": "chrome", "goog:chromeOptions": options, "goog:loggingPrefs": {"browser": "ALL"}}}})
        self.session = f"/session/{session['sessionId']}"

    def _call(self, method, path, body=None):
        request = urllib.request.Request(self.base + path, method=method,
                                         data=None if body is None else json.dumps(body).encode(),
                                         headers={"Content-Type": "application/json"})
        with urllib.request.urlopen(request, timeout=60) as response:
            return json.loads(response.read())["value"]

    def open(self, path: Path):
        self._call("POST", f"{self.session}/url", {"url": path.resolve().as_uri()})

    def images(self):
        """``[src, complete, naturalWidth]`` of every ``<img>`` once the page has loaded."""
        return self._call("POST", f"{self.session}/execute/sync", {"script": (
            "return Array.from(document.images).map(i => [i.getAttribute('src'), i.complete, i.naturalWidth]);"),
            "args": []})

    def console(self):
        """Browser log entries since the last call."""
        return self._call("POST", f"{self.session}/se/log", {"type": "browser"})

    def screenshot(self) -> bytes:
        return base64.b64decode(self._call("GET", f"{self.session}/screenshot"))

    def close(self):
        try:
            self._call("DELETE", self.session)
        finally:
            self.process.terminate()
            self.process.wait(timeout=30)


@pytest.fixture(scope="module")
def browser():
    missing = [p for p in ("chromium", "chromedriver") if shutil.which(p) is None]
    if missing:
        pytest.skip(f"{' and '.join(missing)} not installed (Debian: apt-get install chromium chromium-driver; "
                    "setup.sh does it)")
    driver = _WebDriver()
    yield driver
    driver.close()


def test_browser_check_catches_a_missing_image_and_a_console_error(browser, tmp_path):
    """The check below must be able to fail: a page with a broken image and a script error."""
    page = tmp_path / "broken.html"
    page.write_text('<!DOCTYPE html><html><head><meta charset="utf-8"><link rel="icon" href="data:,"></head>'
                    '<body><img src="nowhere.png"><script>console.error("boom")</script></body></html>')
    browser.open(page)
    assert [(src, width) for src, _, width in browser.images()] == [("nowhere.png", 0)]
    assert any(e["level"] == "SEVERE" for e in browser.console())


def test_report_opens_in_headless_chromium_with_every_image_and_no_console_error(tiny_run, browser, tmp_path):
    browser.console()
    browser.open(tiny_run)
    images = browser.images()
    assert len(images) >= 8
    assert [src for src, complete, width in images if not complete or width == 0] == []
    assert [e for e in browser.console() if e["level"] in ("SEVERE", "WARNING")] == []
    shot = tmp_path / "report.png"
    shot.write_bytes(browser.screenshot())
    pixels = iio.imread(shot)
    assert pixels.shape[0] >= 1000 and pixels.shape[1] >= 1000
    assert np.std(pixels[..., :3]) > 20, "a blank screenshot"


def _fabricated_sweep(out: Path) -> None:
    """A sweep's results files without captures: 2 methods × 3 resolutions × 2 frames."""
    rng = np.random.default_rng(7)
    points = [(f"resolution={r}", r) for r in (256, 512, 1024)]
    rows = []
    for method in ("exact", "none"):
        for label, resolution in points:
            for frame in range(2):
                rows.append((frame, frame / 30, method, label, {
                    "rho_median": resolution / 512, "flicker": np.nan if frame == 0 else rng.random() / resolution,
                    "flicker_same": 0.0 if method == "exact" else 1.0 / resolution, "flicker_changed": 0.001,
                    "flip_rate": 0.01, "memory_bytes": 4 * 4 * resolution ** 2}))
    columns = ["rho_median", "flicker", "flicker_same", "flicker_changed", "flip_rate", "memory_bytes"]
    order = {(m, label): k for k, (m, (label, _)) in enumerate((m, p) for m in ("exact", "none") for p in points)}
    out.mkdir()
    results.write_metrics(out / "metrics.csv", rows, columns=columns, order=order)
    (out / "summary.json").write_text(json.dumps({
        "name": "sweep", "config_hash": "0" * 16, "csmlab_version": "0",
        "config": {"camera": {"fps": 30}, "sweep": {"resolution": [p for _, p in points]}}}))
    (out / "regress.json").write_text(json.dumps({"status": "fail", "rows": [
        {"method": "none", "point": "resolution=256", "metric": "flicker_same", "baseline": 0.001, "now": 0.004,
         "delta": 0.003, "verdict": "regression"}]}))


def test_sweep_report_plots_metrics_against_the_parameter_and_the_pareto_front(tmp_path):
    _fabricated_sweep(tmp_path / "sweep")
    page = write_report(tmp_path / "sweep")
    references = _references(page)
    assert {"figures/sweep__resolution.png", "figures/pareto.png", "figures/curves.png"} <= set(references)
    assert all((page.parent / r).is_file() for r in references)
    text = page.read_text(encoding="utf-8")
    assert "Regression" in text and "verdict-regression" in text and "verdict-fail" in text
