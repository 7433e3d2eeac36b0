"""The HTML report end to end: a tiny real run through the runner, then the page in a real browser.

The browser is Debian's headless ``chromium`` driven by Selenium through ``chromedriver``
(packages ``chromium`` and ``chromium-driver``); the tests that need it skip, saying why, when
either program or the ``selenium`` package is missing. The tiny run keeps one pixel in two of each
row and column for the interactive page (``VIEW_WIDTH`` lowered for the test), so that the hover
test also proves the mapping from a shown pixel to a pixel of the frame.
"""

import json
import shutil
import time
from html.parser import HTMLParser
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest

from csmlab import results
from csmlab.config import load_experiment
from csmlab.errors import InputError
from csmlab.experiment import build_workload, run_experiment
from csmlab.report import pixels as report_pixels
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
RESULT_FILES = ("summary.json", "metrics.csv", "timings.csv", "cascades.csv", "config.resolved.toml", "casters.npz")


TINY_VIEW_WIDTH = 48
"""Half the tiny run's width: its per-pixel records keep every 2nd pixel of each row and column."""


def _tiny_report(tmp_path_factory, name: str, text: str, *, view_width: int) -> Path:
    """Run the experiment ``text`` with the real runner (in this process), records ``view_width`` wide; its report."""
    root = tmp_path_factory.mktemp(name)
    (root / f"{name}.toml").write_text(text)
    out = root / name
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(report_pixels, "VIEW_WIDTH", view_width)
        run_experiment(load_experiment(root / f"{name}.toml"), out_dir=out)
    return write_report(out).page


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    """A 3-frame, 2-method run of the real runner (in this process), and its report."""
    return _tiny_report(tmp_path_factory, "tiny", TINY, view_width=TINY_VIEW_WIDTH)


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
    assert {"explore/plotly.min.js", "explore/data.js", "explore/kept.js", "explore/explore.js"} <= set(references)
    assert sorted(p.name for p in (tiny_run.parent / "explore" / "frames").iterdir()) == [
        f"f{f:05d}{tail}" for f in range(3) for tail in (".js", "__exact__base.webp", "__none__base.webp")]


def _results_copy(source: Path, copy: Path) -> Path:
    """The results files of a run without its report."""
    copy.mkdir()
    for name in RESULT_FILES:
        shutil.copy(source / name, copy / name)
    for folder in ("anim", "snapshots", "pixels"):
        (copy / folder).mkdir()
        for npz in (source / folder).glob("*.npz"):
            shutil.copy(npz, copy / folder / npz.name)
    return copy


@pytest.mark.slow
@pytest.mark.parametrize("worker", [None, True], ids=["pictures-here", "pictures-in-a-worker-process"])
def test_report_is_regenerated_byte_for_byte_from_the_results_files_alone(tiny_run, tmp_path, worker):
    source = tiny_run.parent
    copy = _results_copy(source, tmp_path / "copy")
    page = write_report(copy, worker=worker).page
    assert page.read_bytes() == tiny_run.read_bytes()
    made = sorted(p.relative_to(copy).as_posix() for p in copy.rglob("*") if p.is_file())
    assert made == sorted(p.relative_to(source).as_posix() for p in source.rglob("*") if p.is_file())
    for name in made:
        if name.endswith((".png", ".webp", ".gif", ".js")) and "view3d" not in name:
            assert (copy / name).read_bytes() == (source / name).read_bytes(), name


def _pixels_measured(toml: Path, *, frame: int, method: str):
    """The oracle of the hover test: frame ``frame`` of ``method`` rendered and measured anew (not read back)."""
    from csmlab.metrics import measure_frame
    from csmlab.render import prepare_scene, render_shadow, render_view

    experiment = load_experiment(toml)
    workload = build_workload(experiment)
    settings = next(v.settings for v in experiment.variants() if v.method == method)
    scene = prepare_scene(workload.scene)
    frames = []
    for index in (frame - 1, frame):
        view = render_view(scene, workload.path.pose(index), workload.light.direction(index), width=workload.width,
                           height=workload.height, index=index)
        frames.append(render_shadow(scene, view, settings))
    return frames[1], measure_frame(frames[1], frames[0]).pixels


def _browser():
    """Headless Debian chromium under Selenium, logging the console and every network request."""
    webdriver = pytest.importorskip("selenium.webdriver")
    from selenium.webdriver.chrome.service import Service

    missing = [p for p in ("chromium", "chromedriver") if shutil.which(p) is None]
    if missing:
        pytest.skip(f"{' and '.join(missing)} not installed (Debian: apt-get install chromium chromium-driver; "
                    "setup.sh does it)")
    options = webdriver.ChromeOptions()
    options.binary_location = shutil.which("chromium")
    for argument in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                     "--window-size=1400,1800", "--enable-unsafe-swiftshader"):
        options.add_argument(argument)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL", "performance": "ALL"})
    return webdriver.Chrome(options=options, service=Service(shutil.which("chromedriver")))


@pytest.fixture(scope="module")
def browser():
    driver = _browser()
    yield driver
    driver.quit()


def _open(browser, page: Path) -> None:
    browser.get_log("browser")
    browser.get_log("performance")
    browser.get(page.resolve().as_uri())


def _errors(browser) -> list[dict]:
    """Console errors, and warnings from scripts (the GPU driver's performance notes are not the page's)."""
    return [e for e in browser.get_log("browser")
            if e["level"] == "SEVERE" or (e["level"] == "WARNING" and e.get("source") in ("console-api", "javascript"))]


def _requests(browser) -> list[str]:
    """The URL of every request the page made since it was opened (DevTools Network.requestWillBeSent)."""
    urls = []
    for entry in browser.get_log("performance"):
        message = json.loads(entry["message"])["message"]
        if message["method"] == "Network.requestWillBeSent":
            urls.append(message["params"]["request"]["url"])
    return urls


def _remote(urls: list[str]) -> list[str]:
    return [u for u in urls if not u.startswith(("file://", "data:", "blob:"))]


def _wait(browser, condition, *, what: str, seconds: float = 30.0):
    deadline = time.monotonic() + seconds
    while True:
        value = condition()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.1)


def _shown_frame(browser) -> str:
    return browser.execute_script("return document.getElementById('explore-viewer').dataset.frame")


def _move_slider(browser, index: int) -> None:
    from selenium.webdriver.common.keys import Keys

    slider = browser.find_element("id", "explore-slider")
    slider.send_keys(Keys.HOME)
    for _ in range(index):
        slider.send_keys(Keys.ARROW_RIGHT)


def test_browser_checks_catch_a_missing_image_a_console_error_and_a_remote_request(browser, tmp_path):
    """The checks below must be able to fail: a broken image, a script error and a request off the machine."""
    page = tmp_path / "broken.html"
    page.write_text('<!DOCTYPE html><html><head><meta charset="utf-8"><link rel="icon" href="data:,"></head>'
                    '<body><img src="nowhere.png"><img src="http://127.0.0.1:9/elsewhere.png">'
                    '<script>console.error("boom")</script></body></html>')
    _open(browser, page)
    time.sleep(1.0)
    widths = browser.execute_script("return Array.from(document.images).map(i => i.naturalWidth)")
    assert widths == [0, 0]
    assert any(e["level"] == "SEVERE" for e in _errors(browser))
    assert _remote(_requests(browser)) == ["http://127.0.0.1:9/elsewhere.png"]


@pytest.mark.slow
def test_report_opens_in_headless_chromium_with_every_image_no_console_error_and_no_remote_request(
        tiny_run, browser, tmp_path):
    _open(browser, tiny_run)
    _wait(browser, lambda: _shown_frame(browser) == "0", what="the first frame of the viewer")
    images = browser.execute_script(
        "return Array.from(document.images).map(i => [i.getAttribute('src') || '', i.complete, i.naturalWidth])")
    static = [i for i in images if not i[0].startswith("data:")]
    assert len(static) >= 8
    assert [src for src, complete, width in images if not complete or width == 0] == []
    time.sleep(1.0)
    assert _errors(browser) == []
    requests = _requests(browser)
    assert any(u.endswith("explore/frames/f00000.js") for u in requests)
    assert _remote(requests) == []
    shot = tmp_path / "report.png"
    browser.save_screenshot(str(shot))
    pixels = iio.imread(shot)
    assert pixels.shape[0] >= 1000 and pixels.shape[1] >= 1000
    assert np.std(pixels[..., :3]) > 20, "a blank screenshot"


@pytest.mark.slow
def test_moving_the_slider_changes_the_shown_frame(tiny_run, browser):
    _open(browser, tiny_run)
    _wait(browser, lambda: _shown_frame(browser) == "0", what="frame 0")
    cell = "document.querySelector('.vcell[data-map=shaded][data-stem=none__base] img').src"
    before = browser.execute_script(f"return {cell}")
    _move_slider(browser, 2)
    _wait(browser, lambda: _shown_frame(browser) == "2", what="frame 2 after moving the slider")
    assert browser.execute_script(f"return {cell}") != before
    assert "frame 2" in browser.find_element("id", "explore-frame").text
    assert _errors(browser) == [] and _remote(_requests(browser)) == []


@pytest.mark.slow
def test_unticking_a_method_hides_it_from_the_viewer_and_the_read_out(tiny_run, browser):
    from selenium.webdriver.common.action_chains import ActionChains

    _open(browser, tiny_run)
    _wait(browser, lambda: _shown_frame(browser) == "0", what="frame 0")
    row = browser.find_element("css selector", "#explore-viewer .vrow[data-stem=exact__base]")
    assert row.is_displayed()
    browser.find_element("css selector", "#explore-methods input[data-stem=exact__base]").click()
    assert not row.is_displayed()
    assert browser.find_element("css selector", "#explore-viewer .vrow[data-stem=none__base]").is_displayed()
    ActionChains(browser).move_to_element(
        browser.find_element("css selector", ".vcell[data-map=rho][data-stem=none__base]")).perform()
    stems = [r.get_attribute("data-stem")
             for r in browser.find_elements("css selector", "#explore-readout tr[data-stem]")]
    assert stems == ["none__base"]


def _telling_pixels(rho, dS, lit, cascade, *, stride: int) -> list[tuple[int, int]]:
    """Two pixels of the kept grid where every value is defined: the one that changed most, and the one
    whose values differ most from its grid neighbours' (so that reading a neighbour instead would show)."""
    grid = (slice(None, None, stride), slice(None, None, stride))
    fields = [np.rint(16 * np.log2(rho[grid])), np.rint(254 * dS[grid]), np.rint(254 * lit[grid]),
              cascade[grid].astype(np.float64)]
    defined = np.all([np.isfinite(f) for f in fields], axis=0)
    assert defined.any()
    distinct = np.zeros(defined.shape)
    for f in fields:
        padded = np.pad(f, 1, constant_values=np.nan)
        for dj, di in ((0, 1), (2, 1), (1, 0), (1, 2)):
            neighbour = padded[dj:dj + f.shape[0], di:di + f.shape[1]]
            distinct += np.where(np.isfinite(neighbour), neighbour != f, 0)
    chosen = []
    for score in (np.where(defined, dS[grid], -1.0), np.where(defined, distinct, -1.0)):
        j, i = np.unravel_index(np.argmax(score), score.shape)
        chosen.append((int(j), int(i)))
    return chosen


@pytest.mark.slow
def test_hovering_a_pixel_reads_the_values_the_metrics_per_pixel_arrays_hold(tiny_run, browser):
    from selenium.webdriver.common.action_chains import ActionChains

    frame_index, method, stride = 2, "none", 2
    frame, measured = _pixels_measured(tiny_run.parent.parent / "tiny.toml", frame=frame_index, method=method)
    rho, dS, lit = measured["rho"], measured["dS"], np.asarray(frame.shadow.lit, dtype=np.float64)
    cascade = np.asarray(frame.shadow.cascade)
    shown_h, shown_w = lit[::stride, ::stride].shape

    _open(browser, tiny_run)
    _wait(browser, lambda: _shown_frame(browser) == "0", what="frame 0")
    _move_slider(browser, frame_index)
    _wait(browser, lambda: _shown_frame(browser) == str(frame_index), what=f"frame {frame_index}")
    cell = browser.find_element("css selector", f".vcell[data-map=dS][data-stem={method}__base]")
    box = cell.rect

    def read(key: str) -> str:
        return browser.find_element("css selector",
                                    f"#explore-readout tr[data-stem={method}__base] td[data-key={key}]").text

    for j, i in _telling_pixels(rho, dS, lit, cascade, stride=stride):
        y, x = stride * j, stride * i
        dx = (i + 0.5) * box["width"] / shown_w - box["width"] / 2
        dy = (j + 0.5) * box["height"] / shown_h - box["height"] / 2
        ActionChains(browser).move_to_element_with_offset(cell, int(round(dx)), int(round(dy))).perform()
        assert f"pixel x = {x}, y = {y}" in browser.find_element("id", "explore-where").text
        # The stored precision (ρ to 1/16 octave, S and |ΔS| to 1/254), then the page's 3 digits.
        stored_rho = float(report_pixels.decode_rho(report_pixels.code_rho(rho[y, x])))
        assert abs(stored_rho / float(rho[y, x]) - 1.0) <= 0.022
        assert float(read("rho")) == pytest.approx(stored_rho, rel=5e-3)
        assert float(read("dS")) == pytest.approx(round(round(254 * float(dS[y, x])) / 254, 3), abs=1e-9)
        assert float(read("lit")) == pytest.approx(round(round(254 * float(lit[y, x])) / 254, 3), abs=1e-9)
        assert read("cascade") == str(int(cascade[y, x]))
        assert read("reference") == ("lit" if frame.view.reference[y, x] > 0.5 else "shadowed")
    stems = {r.get_attribute("data-stem")
             for r in browser.find_elements("css selector", "#explore-readout tr[data-stem]")}
    assert stems == {"exact__base", "none__base"}
    assert _errors(browser) == []


@pytest.mark.slow
def test_clicking_a_point_of_a_curve_moves_the_slider_to_its_frame(tiny_run, browser):
    from selenium.webdriver.common.action_chains import ActionChains

    _open(browser, tiny_run)
    _wait(browser, lambda: _shown_frame(browser) == "0", what="frame 0")
    plot = browser.find_element("id", "explore-curves")
    # Where frame 1 of the first method's flicker curve is drawn, in pixels from the plot's top-left corner.
    point = browser.execute_script("""
        const gd = arguments[0], trace = gd._fullData[0], k = trace.x.indexOf(1);
        const xa = gd._fullLayout[trace.xaxis.replace('x', 'xaxis')];
        const ya = gd._fullLayout[trace.yaxis.replace('y', 'yaxis')];
        return [xa._offset + xa.l2p(trace.x[k]), ya._offset + ya.l2p(trace.y[k])];""", plot)
    box = plot.rect
    ActionChains(browser).move_to_element_with_offset(
        plot, int(round(point[0] - box["width"] / 2)), int(round(point[1] - box["height"] / 2))).click().perform()
    _wait(browser, lambda: _shown_frame(browser) == "1", what="frame 1 after clicking its point")
    assert browser.find_element("id", "explore-slider").get_attribute("value") == "1"
    assert _errors(browser) == []


@pytest.mark.slow
def test_a_small_budget_thins_the_viewer_frames_and_the_page_says_so(tiny_run, tmp_path):
    copy = tmp_path / "thin"
    shutil.copytree(tiny_run.parent, copy)
    written = write_report(copy, budget_bytes=1)
    assert sorted(p.name for p in (copy / "explore" / "frames").iterdir()) == [
        "f00000.js", "f00000__exact__base.webp", "f00000__none__base.webp"]
    assert (copy / "explore" / "kept.js").read_text() == "window.csmlabKept = [0];\n"
    text = written.page.read_text(encoding="utf-8")
    assert "holds every 3rd frame (1 of 3)" in text
    assert written.kept == "Explore holds every 3rd frame (1 of 3); animations left out"


def test_a_run_the_size_of_its_budget_keeps_every_frame_and_animation_and_says_nothing_is_left_out(tiny_run):
    text = tiny_run.read_text(encoding="utf-8")
    assert (tiny_run.parent / "explore" / "kept.js").read_text() == "window.csmlabKept = [0, 1, 2];\n"
    assert sorted(p.name for p in (tiny_run.parent / "anim").glob("*.gif")) == ["exact__base.gif", "none__base.gif"]
    assert 'id="explore-note"' not in text and 'id="animations-note"' not in text
    assert 'id="animations"' in text


@pytest.mark.parametrize(("sizes", "available", "animation_bytes", "plan"), [
    ([10] * 6, 100, 20, (1, True)),   # 60 + 20 fit
    ([10] * 6, 60, 20, (2, True)),    # every 2nd frame (30), then the animations (20); the other 30 do not fit in 10
    ([10] * 6, 45, 20, (2, False)),   # every 2nd frame; the animations do not fit in 15, nor the other frames
    ([10] * 6, 60, 40, (1, False)),   # every 2nd frame; the animations do not fit in 30; the other frames do
    ([10] * 6, 25, 5, (3, True)),     # every 2nd frame does not fit, every 3rd (20) does: 5 left, room no frame can use
    ([10] * 6, 25, 6, (3, False)),
    ([10] * 6, 5, 0, (6, True)),      # nothing fits: the first frame alone; no animations to leave out
    ([10], 5, 5, (1, False)),         # one frame: it is every frame
])
def test_the_budget_plans_every_2nd_frame_then_the_animations_then_the_other_frames(sizes, available, animation_bytes,
                                                                                    plan):
    from csmlab.report.explore import budget_plan

    assert budget_plan(sizes, available, animation_bytes=animation_bytes) == plan


class _ReadSizes(list):
    """Frame sizes that remember which frames a plan read (as :class:`FramePayloads` encodes what is read)."""

    def __init__(self, sizes):
        super().__init__(sizes)
        self.read = set()

    def __getitem__(self, index):
        self.read.update(range(len(self))[index] if isinstance(index, slice) else [index])
        return super().__getitem__(index)

    def __iter__(self):
        return (self[k] for k in range(len(self)))


@pytest.mark.parametrize("seed", range(40))
def test_the_budget_plans_the_same_from_the_sizes_it_reads_and_stops_at_the_first_overflow(seed):
    from csmlab.report.explore import budget_plan

    rng = np.random.default_rng(seed)
    sizes = rng.integers(1, 100, rng.integers(1, 120)).tolist()
    available, animation_bytes = int(rng.integers(0, 1.2 * sum(sizes))), int(rng.choice([0, 50, 500]))
    lazy = _ReadSizes(sizes)
    step, kept = budget_plan(lazy, available, animation_bytes=animation_bytes)
    # The plan, from a plain list: the smallest step from 2 that fits, then the animations, then every frame.
    want = next((k for k in range(2, len(sizes) + 1) if sum(sizes[::k]) <= available), max(len(sizes), 1))
    left = available - sum(sizes[::want])
    want_kept = animation_bytes <= max(left, 0)
    left -= animation_bytes if want_kept else 0
    if want == 2 and sum(sizes[1::2]) <= left:
        want = 1
    assert (step, kept) == (want, want_kept)
    others = sorted(lazy.read - set(range(0, len(sizes), 2)))
    if step == 2 and others:
        # Every other frame read up to the chunk where they overflowed, and no chunk beyond it.
        assert sum(sizes[k] for k in others) > left and sum(sizes[k] for k in others[:-8]) <= left


@pytest.mark.parametrize("seed", range(60))
def test_every_frame_and_the_animations_fit_exactly_when_their_sizes_add_up_to_what_is_available(seed):
    # The report encodes the planes again compact as soon as the fast frames read so far overflow
    # (explore._all_fit), before any plan: the same choice as the plan's (every frame and the
    # animations kept, or not), and it reads no chunk past the one that overflows.
    from csmlab.report.explore import FIRST_STEP, _all_fit, budget_plan

    rng = np.random.default_rng(seed)
    sizes = rng.integers(1, 100, rng.integers(FIRST_STEP, 120)).tolist()
    available, animation_bytes = int(rng.integers(-50, 1.2 * sum(sizes))), int(rng.choice([0, 50, 500]))
    lazy = _ReadSizes(sizes)
    fits = _all_fit(lazy, available - animation_bytes)
    assert fits == (budget_plan(sizes, available, animation_bytes=animation_bytes) == (1, True))
    read = sorted(lazy.read)
    assert read == list(range(len(read)))
    if not fits:
        # Chunks of 8 from the first frame: the last one read overflowed, those before it did not.
        before = (len(read) - 1) // 8 * 8
        assert sum(sizes[:len(read)]) > available - animation_bytes
        assert before == 0 or sum(sizes[:before]) <= available - animation_bytes


def test_a_report_whose_fast_frames_overflow_encodes_compact_without_making_every_fast_frame(tiny_run, tmp_path,
                                                                                            monkeypatch):
    import csmlab.report.explore as explore

    made = []
    frame_file = explore._frame_file

    def counted(frame, present, records, *, encoding, **options):
        made.append((encoding, frame))
        return frame_file(frame, present, records, encoding=encoding, **options)

    monkeypatch.setattr(explore, "_frame_file", counted)
    monkeypatch.setattr(explore, "_PLAN_CHUNK", 1)
    parts = _budget_parts(tiny_run)
    made.clear()
    # Room for the report but its frames, and for the first compact frame: the first fast frame, larger, overflows.
    budget = parts["rest"] + explore._INDEX_RESERVE + parts["animations"] + parts["sizes"][0]
    copy = tmp_path / "overflowing"
    shutil.copytree(tiny_run.parent, copy)
    written = write_report(copy, budget_bytes=budget)
    fast = [frame for encoding, frame in made if encoding == "fast"]
    assert len(parts["sizes"]) > 1 and len(fast) == 1
    assert written.kept and any(encoding == "compact" for encoding, _ in made)


def test_planes_encoded_again_are_the_files_of_that_encoding_and_share_the_shaded_views(tiny_run):
    from csmlab.report.explore import explore_files, recoded
    from csmlab.report.tables import read_results

    out = tiny_run.parent
    metrics = read_results(out).metrics
    groups = metrics.groups()
    made = {encoding: explore_files(out, groups=groups, labels=[m for m, _ in groups], metrics=metrics,
                                    encoding=encoding) for encoding in ("fast", "compact")}
    again = recoded(made["fast"], "compact")
    assert list(again.payloads) == list(made["compact"].payloads) != list(made["fast"].payloads)
    for fast, compact in zip(made["fast"].payloads, again.payloads):
        views = [name for name in fast if name.endswith(".webp")]
        assert views and all(compact[name] is fast[name] for name in views)


def _budget_parts(tiny_run) -> dict:
    """Bytes of the tiny run's report by part, its frames as the report encodes them when something is left out."""
    from csmlab.report.explore import explore_files, report_size
    from csmlab.report.tables import read_results

    out = tiny_run.parent
    metrics = read_results(out).metrics
    groups = metrics.groups()
    compact = explore_files(out, groups=groups, labels=[m for m, _ in groups], metrics=metrics, encoding="compact")
    sizes = [sum(map(len, payload.values())) for payload in compact.payloads]
    frames = sum(p.stat().st_size for p in (out / "explore" / "frames").iterdir())
    animations = sum(p.stat().st_size for p in (out / "anim").glob("*.gif"))
    return {"rest": report_size(out) - frames - animations, "sizes": sizes, "animations": animations}


@pytest.mark.slow
def test_the_animations_are_left_out_before_the_viewers_every_2nd_frame_and_the_page_says_so(tiny_run, tmp_path):
    from csmlab.report.explore import _INDEX_RESERVE, report_size

    parts = _budget_parts(tiny_run)
    sizes = parts["sizes"]
    # Room for frames 0 and 2 and less than half of either the animations or frame 1: neither fits.
    slack = min(parts["animations"], sizes[1]) // 2
    budget = parts["rest"] + _INDEX_RESERVE + sizes[0] + sizes[2] + slack
    copy = tmp_path / "no_animations"
    shutil.copytree(tiny_run.parent, copy)
    written = write_report(copy, budget_bytes=budget)
    assert (copy / "explore" / "kept.js").read_text() == "window.csmlabKept = [0, 2];\n"
    assert not list((copy / "anim").glob("*.gif"))
    assert report_size(copy) <= budget
    text = written.page.read_text(encoding="utf-8")
    assert "anim/" not in text
    assert ("Animations left out to keep every 2nd frame in Explore under the "
            f"{budget / 2 ** 20:.3g} MiB budget: play the frames there.") in text
    assert "holds every 2nd frame (2 of 3); the curves keep every frame, and the animations are left out" in text
    assert written.kept == "Explore holds every 2nd frame (2 of 3); animations left out"


@pytest.mark.slow
def test_the_animations_come_before_the_viewers_other_frames(tiny_run, tmp_path):
    from csmlab.report.explore import _INDEX_RESERVE

    parts = _budget_parts(tiny_run)
    sizes = parts["sizes"]
    # Room for frames 0 and 2, the animations, and half of frame 1.
    budget = parts["rest"] + _INDEX_RESERVE + sizes[0] + sizes[2] + parts["animations"] + sizes[1] // 2
    copy = tmp_path / "animations"
    shutil.copytree(tiny_run.parent, copy)
    written = write_report(copy, budget_bytes=budget)
    assert (copy / "explore" / "kept.js").read_text() == "window.csmlabKept = [0, 2];\n"
    assert sorted(p.name for p in (copy / "anim").glob("*.gif")) == ["exact__base.gif", "none__base.gif"]
    text = written.page.read_text(encoding="utf-8")
    assert 'id="animations-note"' not in text and "anim/exact__base.gif" in text
    assert written.kept == "Explore holds every 2nd frame (2 of 3); animations kept"


def test_a_broken_pixel_record_is_reported_naming_the_file(tiny_run, tmp_path):
    copy = tmp_path / "broken"
    shutil.copytree(tiny_run.parent, copy)
    (copy / "pixels" / "none__base.npz").write_bytes(b"not a zip")
    with pytest.raises(InputError, match="none__base.npz.*pixel record"):
        write_report(copy)

def _fabricated_sweep(out: Path) -> None:
    """A sweep's results files without captures: 2 methods × 3 resolutions × 2 frames."""
    rng = np.random.default_rng(7)
    points = [(f"resolution={r}", r) for r in (256, 512, 1024)]
    rows = []
    for method in ("exact", "none"):
        for label, resolution in points:
            for frame in range(2):
                rows.append(results.MetricRow(frame, frame / 30, method, label, {
                    "rho_median": resolution / 512, "flicker": np.nan if frame == 0 else rng.random() / resolution,
                    "flicker_same": 0.0 if method == "exact" else 1.0 / resolution, "flicker_changed": 0.001,
                    "flip_rate": 0.01, "memory_bytes": 4 * 4 * resolution ** 2}))
    columns = ["rho_median", "flicker", "flicker_same", "flicker_changed", "flip_rate", "memory_bytes"]
    out.mkdir()
    # Built method by method, point by point, frame by frame: the file's order, one block.
    results.write_metrics(out / "metrics.csv", [rows], columns=columns)
    (out / "summary.json").write_text(json.dumps({
        "name": "sweep", "config_hash": "0" * 16, "csmlab_version": "0",
        "config": {"camera": {"fps": 30}, "sweep": {"resolution": [p for _, p in points]}},
        "point_fields": {label: {"resolution": r} for label, r in points}}))
    (out / "regress.json").write_text(json.dumps({"status": "fail", "rows": [
        {"method": "none", "point": "resolution=256", "metric": "flicker_same", "baseline": 0.001, "now": 0.004,
         "delta": 0.003, "verdict": "regression"}]}))


def test_sweep_report_plots_metrics_against_the_parameter_and_the_pareto_front(tmp_path):
    _fabricated_sweep(tmp_path / "sweep")
    page = write_report(tmp_path / "sweep").page
    references = _references(page)
    assert {"figures/sweep__resolution.png", "figures/pareto.png", "figures/curves.png"} <= set(references)
    assert all((page.parent / r).is_file() for r in references)
    text = page.read_text(encoding="utf-8")
    assert "Regression" in text and "verdict-regression" in text and "verdict-fail" in text


@pytest.mark.slow
def test_the_runs_records_do_not_count_against_the_report_budget(tiny_run, tmp_path):
    from csmlab.report.explore import report_size

    copy = tmp_path / "records"
    shutil.copytree(tiny_run.parent, copy)
    budget = report_size(copy) + 2 ** 20
    # Records twice the budget: the report alone fits, so every frame keeps its files.
    (copy / "pixels" / "padding.npz").write_bytes(bytes(2 * budget))
    write_report(copy, budget_bytes=budget)
    assert (copy / "explore" / "kept.js").read_text() == "window.csmlabKept = [0, 1, 2];\n"
    assert report_size(copy) <= budget


def test_the_reference_sequence_equals_the_shaded_one_where_the_method_agrees_with_the_ray_traced_shadow(tiny_run):
    for method in ("exact", "none"):
        record = np.load(tiny_run.parent / "pixels" / f"{method}__base.npz")
        lit, reference = record["lit"].astype(int), record["reference"]
        shaded, reference_shaded = record["shaded"].astype(int), record["reference_shaded"].astype(int)
        defined = (reference != report_pixels.NO_VALUE) & (lit != report_pixels.NO_VALUE)
        agrees = defined & (lit == 254 * (reference == 1))
        assert agrees.sum() > 1000
        assert np.array_equal(shaded[agrees], reference_shaded[agrees])
        assert (reference_shaded[defined].sum(axis=-1) > 0).all()
        # Less light than the reference is darker, more is brighter: by the direct light, where it reaches the surface.
        darker = defined & (lit < 254 * (reference == 1))
        brighter = defined & (lit > 254 * (reference == 1))
        assert (reference_shaded[darker] >= shaded[darker]).all()
        assert (shaded[brighter] >= reference_shaded[brighter]).all()
        # Where the method has no shadow (beyond its shadow distance), the reference is blanked as the method is.
        assert (reference_shaded[lit == report_pixels.NO_VALUE] == 0).all()


@pytest.mark.slow
def test_the_summary_says_how_to_install_the_video_metric_until_a_run_is_scored(tiny_run, tmp_path):
    from csmlab.report.video_quality import INSTALL

    assert 'id="jod-missing"' in tiny_run.read_text(encoding="utf-8")
    assert INSTALL.split()[0] in tiny_run.read_text(encoding="utf-8")
    copy = tmp_path / "scored"
    shutil.copytree(tiny_run.parent, copy)
    summary = json.loads((copy / "summary.json").read_text())
    summary["jod"] = {"display": "standard_fhd", "metric": "ColorVideoVDP 0.5.7",
                      "sequences": {"shaded": {"exact__base": 9.4321, "none__base": 8.1}}}
    (copy / "summary.json").write_text(json.dumps(summary))
    text = write_report(copy).page.read_text(encoding="utf-8")
    assert 'id="jod-missing"' not in text
    table = text.split('id="jod"', 1)[1].split("</table>", 1)[0]
    assert "JOD, as rendered" in table and "9.43" in table and "8.10" in table
    assert table.index(">exact<") < table.index(">none<")


@pytest.mark.parametrize("length", [0, 1, 2, 3, 4, 5, 8, 1023, 4096])
def test_base85_is_the_standard_librarys_text(length):
    import base64

    from csmlab.report.explore import base85

    data = np.random.default_rng(length).integers(0, 256, size=length, dtype=np.uint8).tobytes()
    edges = bytes([255] * length)
    assert base85(data) == base64.b85encode(data).decode("ascii")
    assert base85(edges) == base64.b85encode(edges).decode("ascii")


@pytest.mark.parametrize("encoding", ["fast", "compact"])
@pytest.mark.parametrize("dtype", [np.uint8, np.int8])
def test_a_value_plane_is_stored_byte_for_byte(dtype, encoding):
    import base64
    import io

    from PIL import Image

    from csmlab.report.explore import plane_webp

    rng = np.random.default_rng(7)
    plane = rng.integers(np.iinfo(dtype).min, np.iinfo(dtype).max, size=(37, 53), endpoint=True).astype(dtype)
    text = plane_webp(plane, encoding=encoding)
    assert not set(text) & set("\"\\'\n")
    decoded = np.asarray(Image.open(io.BytesIO(base64.b85decode(text))).convert("RGB"))
    assert np.array_equal(decoded[..., 0], plane.view(np.uint8))


# ---- the report of a run with [taa] on: the after-TAA planes, maps, curve, JOD pair and settings ----------------
# The fence: its slats' shadows change under the jittered walk, where the plane and box of TINY's first frames do not.
TINY_TAA = TINY.replace('name = "tiny"', 'name = "tiny_taa"').replace("scenes/plane_box", "scenes/fence").replace(
    "width = 96\nheight = 54", "width = 64\nheight = 36").replace("resolution = 128", "resolution = 64") + """
[taa]
enabled = true
phases = 4
alpha = 0.2
"""
TAA_KEYS = ("lit_taa", "dS_taa", "reference_taa", "shaded_taa", "reference_shaded_taa")
TINY_TAA_VIEW_WIDTH = 32
"""Half the tiny TAA run's width: its records keep every 2nd pixel of each row and column."""


@pytest.fixture(scope="module")
def tiny_taa_run(tmp_path_factory):
    """The tiny run with ``[taa]`` on (3 frames, 64×36), and its report."""
    return _tiny_report(tmp_path_factory, "tiny_taa", TINY_TAA, view_width=TINY_TAA_VIEW_WIDTH)


def _resolves_anew(toml: Path, *, method: str):
    """The oracle of the after-TAA planes: each frame of ``method`` rendered with its jitter and its S and R resolved
    by :func:`csmlab.metrics.taa.resolve_view` in frame order here (not read back), with the before-TAA change."""
    from csmlab.metrics import measure_frame
    from csmlab.metrics.taa import halton_jitter, resolve_view
    from csmlab.render import prepare_scene, render_shadow, render_view

    experiment = load_experiment(toml)
    workload = build_workload(experiment)
    settings = next(v.settings for v in experiment.variants() if v.method == method)
    scene = prepare_scene(workload.scene)
    taa = experiment.taa
    out, previous, shadow, reference = [], None, None, None
    for index in range(len(workload.path.positions)):
        light = workload.light.direction(index)
        view = render_view(scene, workload.path.pose(index), light, width=workload.width, height=workload.height,
                           index=index, previous_light_direction=workload.light.direction(index - 1) if index else None,
                           jitter=halton_jitter(index, phases=taa.phases))
        frame = render_shadow(scene, view, settings)
        reference = resolve_view(view.reference, view, previous and previous.view, reference, taa=taa)
        shadow = resolve_view(frame.shadow.lit, view, previous and previous.view, shadow, taa=taa)
        out.append((frame, shadow, reference, measure_frame(frame, previous).pixels))
        previous = frame
    return out


@pytest.mark.slow
def test_a_taa_runs_record_holds_the_after_taa_planes_and_they_decode_to_the_resolves(tiny_taa_run):
    from csmlab.metrics.shading import shaded_rgb
    from csmlab.srgb import srgb_encoded

    stride, step = 2, 0.5 / 254 + 1e-9  # the record's pixels; its precision, ±1/508
    record = np.load(tiny_taa_run.parent / "pixels" / "none__base.npz")
    assert set(TAA_KEYS) <= set(record.files)
    take = (slice(None, None, stride), slice(None, None, stride))
    changes = 0
    for k, (frame, shadow, reference, pixels) in enumerate(
            _resolves_anew(tiny_taa_run.parent.parent / "tiny_taa.toml", method="none")):
        valid = frame.view.gbuffer.valid[take]
        s, r = shadow.out[take].astype(np.float64), reference.out[take].astype(np.float64)
        lit_taa = _decoded(record["lit_taa"][k])
        assert np.array_equal(np.isnan(lit_taa), ~(valid & np.isfinite(s)))
        np.testing.assert_allclose(lit_taa[valid], s[valid], atol=step, rtol=0)
        np.testing.assert_allclose(_decoded(record["reference_taa"][k])[valid], r[valid], atol=step, rtol=0)
        change = np.abs((s - shadow.reprojected[take]) - (r - reference.reprojected[take]))
        change[~np.isfinite(pixels["dS"][take])] = np.nan
        dS_taa = _decoded(record["dS_taa"][k])
        assert np.array_equal(np.isnan(dS_taa), np.isnan(change))
        np.testing.assert_allclose(dS_taa[~np.isnan(change)], np.minimum(change[~np.isnan(change)], 1.0), atol=step,
                                   rtol=0)
        changes += int(np.count_nonzero(dS_taa > 0))
        # The views through T^S and T^R, shaded as the run shades S, to the sRGB code.
        g = frame.view.gbuffer
        for name, resolved in (("shaded_taa", shadow), ("reference_shaded_taa", reference)):
            lit = np.where(g.valid & np.isfinite(shadow.out), resolved.out, np.nan)
            expected = np.rint(srgb_encoded(np.nan_to_num(shaded_rgb(
                g.albedo, g.normal, lit, light_direction=frame.view.light_direction, ambient=0.25)))[take] * 255)
            assert np.abs(record[name][k].astype(int) - expected).max() <= 1, name
        if k == 0:
            # The first frame has no history: the resolve is its input, the shaded view after TAA the one before it.
            assert np.isnan(dS_taa).all()
            assert np.array_equal(record["shaded_taa"][0], record["shaded"][0])
            assert np.array_equal(record["reference_shaded_taa"][0], record["reference_shaded"][0])
    assert changes > 0, "a walk with a jittered camera changes something after TAA"


def _decoded(coded: np.ndarray) -> np.ndarray:
    """A uint8 plane of the record as float64 values, NaN where it has none (written here from the record's coding)."""
    return np.where(coded == 255, np.nan, coded.astype(np.float64) / 254.0)


def test_a_run_without_taa_keeps_no_taa_keys_files_maps_or_curve(tiny_run):
    out = tiny_run.parent
    for path in (out / "pixels").glob("*.npz"):
        assert not set(TAA_KEYS) & set(np.load(path).files), path
    assert not list((out / "explore" / "frames").glob("*__taa.webp"))
    data = (out / "explore" / "data.js").read_text()
    assert '"taa"' not in data and "_taa" not in data
    frame = (out / "explore" / "frames" / "f00001.js").read_text()
    assert "img_taa" not in frame
    assert 'id="taa-settings"' not in tiny_run.read_text(encoding="utf-8")


def test_a_taa_runs_explore_offers_the_after_taa_planes_views_and_curve(tiny_taa_run):
    out = tiny_taa_run.parent
    run = json.loads((out / "explore" / "data.js").read_text().removeprefix("window.csmlabRun = ").rstrip(";\n"))
    assert run["taa"] is True and run["planes"][-3:] == ["lit_taa", "dS_taa", "reference_taa"]
    assert [c["key"] for c in run["curves"]][:2] == ["flicker", "flicker_taa"]
    from csmlab.report.tables import read_results

    metrics = read_results(out).metrics
    for v in run["variants"]:
        flicker = metrics.of(v["method"], v["point"])["flicker_taa"]
        assert v["curves"]["flicker_taa"][1:] == [round(float(x), 6) for x in flicker[1:]]
    for f in range(3):
        body = json.loads((out / "explore" / "frames" / f"f{f:05d}.js").read_text().split(",", 1)[1].rsplit(");", 1)[0])
        for stem, v in body["variants"].items():
            assert v["img_taa"] == f"explore/frames/f{f:05d}__{stem}__taa.webp"
            assert (out / v["img_taa"]).is_file() and len(v["planes"]) == len(run["planes"])
    text = tiny_taa_run.read_text(encoding="utf-8")
    assert 'id="taa-settings"' in text and "4 jitter phases" in text and "α = 0.2" in text and "ycocg_minmax" in text


def test_only_a_taa_run_offers_the_after_taa_sequence_to_the_video_metric(tiny_run, tiny_taa_run):
    from csmlab.report.video_quality import SEQUENCES, record_sequences

    assert SEQUENCES["after_taa"] == ("shaded_taa", "reference_shaded_taa")
    assert record_sequences(tiny_run.parent, sequence="after_taa") == {}
    assert set(record_sequences(tiny_run.parent, sequence="shaded")) == {"exact__base", "none__base"}
    for name in SEQUENCES:
        fed = record_sequences(tiny_taa_run.parent, sequence=name)
        assert set(fed) == {"exact__base", "none__base"}
        for stem, (test, reference, fps) in fed.items():
            record = np.load(tiny_taa_run.parent / "pixels" / f"{stem}.npz")
            assert test.shape == reference.shape == (3, 18, 32, 3) and test.dtype == reference.dtype == np.uint8
            assert np.array_equal(test, record[SEQUENCES[name][0]])
            assert np.array_equal(reference, record[SEQUENCES[name][1]])
            assert fps == pytest.approx(1.0 / np.median(np.diff(record["time_s"])))
    # After TAA the sequences differ from the ones before it (frame 0 aside, where the resolve is its input).
    before, after = (record_sequences(tiny_taa_run.parent, sequence=n)["none__base"][0]
                     for n in ("shaded", "after_taa"))
    assert np.array_equal(before[0], after[0]) and not np.array_equal(before[1:], after[1:])


@pytest.mark.slow
def test_the_explore_page_shows_the_after_taa_maps_and_values_only_for_a_taa_run(tiny_run, tiny_taa_run, browser):
    from selenium.webdriver.common.action_chains import ActionChains

    _open(browser, tiny_run)
    _wait(browser, lambda: _shown_frame(browser) == "0", what="frame 0 of the run without TAA")
    assert browser.find_elements("css selector", "[data-map=dS_taa], [data-map=shaded_taa], td[data-key=lit_taa]") == []

    stride, frame_index, method = 2, 2, "none"
    record = np.load(tiny_taa_run.parent / "pixels" / f"{method}__base.npz")
    _open(browser, tiny_taa_run)
    _wait(browser, lambda: _shown_frame(browser) == "0", what="frame 0")
    _move_slider(browser, frame_index)
    _wait(browser, lambda: _shown_frame(browser) == str(frame_index), what=f"frame {frame_index}")
    titles = [e.text for e in browser.find_elements("css selector", "#explore-viewer .vtitle")]
    assert titles[:2] == ["shaded view", "shaded after TAA"] and "|ΔS| after TAA (less R's)" in titles
    image = browser.execute_script(
        f"const i = document.querySelector('.vcell[data-map=shaded_taa][data-stem={method}__base] img');"
        "return [i.getAttribute('src'), i.complete, i.naturalWidth]")
    assert image == [f"explore/frames/f{frame_index:05d}__{method}__base__taa.webp", True, 32]
    cell = browser.find_element("css selector", f".vcell[data-map=dS_taa][data-stem={method}__base]")
    box = cell.rect
    dS_taa = record["dS_taa"][frame_index]
    h, w = dS_taa.shape
    j, i = np.unravel_index(np.argmax(np.where(dS_taa == 255, -1, dS_taa.astype(int))), dS_taa.shape)
    ActionChains(browser).move_to_element_with_offset(
        cell, int(round((i + 0.5) * box["width"] / w - box["width"] / 2)),
        int(round((j + 0.5) * box["height"] / h - box["height"] / 2))).perform()
    assert f"pixel x = {stride * i}, y = {stride * j}" in browser.find_element("id", "explore-where").text

    def read(key: str) -> str:
        return browser.find_element("css selector",
                                    f"#explore-readout tr[data-stem={method}__base] td[data-key={key}]").text

    for key in ("dS_taa", "lit_taa", "reference_taa", "dS", "lit"):
        assert read(key) == f"{record[key][frame_index][j, i] / 254:.3f}", key
    assert _errors(browser) == [] and _remote(_requests(browser)) == []


@pytest.mark.slow
def test_a_taa_runs_summary_shows_the_jod_before_and_after_taa_side_by_side(tiny_taa_run, tmp_path):
    copy = tmp_path / "scored"
    shutil.copytree(tiny_taa_run.parent, copy)
    summary = json.loads((copy / "summary.json").read_text())
    summary["jod"] = {"display": "standard_fhd", "metric": "ColorVideoVDP 0.5.7",
                      "sequences": {"shaded": {"exact__base": 9.4321, "none__base": 8.1},
                                    "after_taa": {"exact__base": 9.61, "none__base": 8.75}}}
    (copy / "summary.json").write_text(json.dumps(summary))
    table = write_report(copy).page.read_text(encoding="utf-8").split('id="jod"', 1)[1].split("</table>", 1)[0]
    assert table.index("JOD, as rendered") < table.index("JOD, after TAA")
    none = table.split(">none<", 1)[1]
    assert none.index("8.10") < none.index("8.75")
