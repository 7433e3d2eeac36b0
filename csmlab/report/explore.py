"""The interactive part of the report: every frame of every method, scrubbed and pointed at in a browser.

:func:`explore_files` turns the per-pixel records of :mod:`csmlab.report.pixels`
(``pixels/<method>__<point>.npz``) and ``casters.npz`` into the files of a folder the page loads
from ``file://`` with no server and no network, and :func:`write_explore` writes them once the
rest of the report is on disk (the two are apart so that the files can be made while the
report's pictures are drawn)::

    explore/plotly.min.js      Plotly's bundle, copied from the installed ``plotly`` package
    explore/explore.js         the page's script (``templates/explore.js``)
    explore/data.js            the run: variants, frames, per-frame curves, colour tables,
                               world maps (over the cells the run saw), ρ histograms, casters
                               (``window.csmlabRun = …``)
    explore/frames/f<frame>.js one per kept frame (``csmlabFrame(…)``): its value planes as lossless
                               WebP images in base85 text, each distinct plane once (the ray-traced
                               reference is every variant's); per variant the indices of its
                               planes, the cascade geometry, and the name of
    explore/frames/f<frame>__<method>__<point>.webp
                               its shaded view (lossy WebP, shown by an ``<img>`` element)

A frame's value planes are the record's uint8 arrays ``lit, dS, cascade, rho, reference,
ref_diff`` — and, in a run with ``[taa]`` on whose records hold them, the after-TAA ones
``lit_taa, dS_taa, reference_taa`` (:data:`TAA_PLANES`) with a second shaded view per variant,
``f<frame>__<method>__<point>__taa.webp``, of the view through S after TAA — (each ``h × w``,
row-major, int8 ones as their two's-complement bytes), each a
greyscale lossless WebP image: the exact bytes, at the precision the read-out shows (S and |ΔS| to
1/254, ρ to 1/16 octave, :func:`csmlab.report.pixels.frame_pixels`), about a quarter smaller than
the planes zlib-compressed together. The page decodes each from its bytes (base85: a quarter
longer, where base64 is a third) with ``createImageBitmap`` (no colour conversion, no
premultiplication) and reads it back from a canvas: an image made from the page's own bytes leaves
the canvas readable, where one loaded from a ``file://`` address would not. The shaded view is
only shown, so it is a file of its own, with no text encoding. Scripts are loaded with
``<script>`` elements, which browsers allow from ``file://`` where ``fetch`` is refused.

Measured on ``engines.toml`` (13 variants, 120 frames, 320×180 records): a frame's files take
416 KB (at 24 frames, 411 KB where the single script of zlib and base64 took 562 KB), ``data.js``
0.43 MB (5.9 MB at 24 frames before the world maps kept only the cells the run saw), and the
viewer keeps every 2nd frame (60 of 120) in a 59.5 MiB report (its strips then PNG, 6 MiB more than as WebP,
estimated from ``taa.toml``'s).

With ``[taa]`` on (``taa.toml --frames 6``: 11 variants, 320×180 records) a frame's files take 829 KB
``fast`` (596 KB ``compact``) where the same records without the after-TAA planes take 529 KB (362 KB): the
three planes add about 290 KB, the second shaded view 67 KB. Measured on the whole ``taa.toml`` (13 variants,
120 frames): 770 KB a frame compact, and the rest of the report takes 39 MiB of the 60 (13 GIF animations
23.6 MiB, the strips and figures 11 MiB, Plotly 4.6 MiB), so with the animations counted before its frames
the viewer kept every 4th frame (30 of 120) in a 58.1 MiB report (the order below changed that).

The report encodes the planes ``fast`` first (:data:`PLANE_ENCODINGS`) and, only when they would leave
frames or the animations out of the budget, again ``compact``: a run the size of the default one keeps
every frame and animation either way and is spared three quarters of the encoding time. The frames are
made when the budget reads them, once every picture is on disk: ``fast`` in chunks until they overflow
what is left for every frame and the animations (they are all kept exactly when their sum fits), and
then, encoded again, only the frames the plan reads (:class:`FramePayloads`: every 2nd frame, then the
others in chunks until one overflows what is left), the shaded views those already made.
``engines.toml``'s report (13 variants, 120 frames) took 45.4 s wall and 55.8 s CPU with every frame
encoded twice, 34.1 s and 37.0 s so; making every ``fast`` frame first (70.1 MiB of them against the
60 MiB budget) while the pictures were drawn, 39.8–40.2 s and 62.5–64.8 s CPU (`csmlab report` of
its 120 frames, a later machine), made as read 32.7–34.4 s and 56.8–59.2 s, the same files.

The folder is kept under a size budget of the report, the files ``index.html`` loads (:func:`report_size`:
the run's records — ``*.npz``, the CSV, JSON and TOML files at the top — are the report's input, not
part of it). The budget is planned in an order (:func:`budget_plan`): everything else the report writes
(tables, figures, strips, Plotly, ``data.js``); then the frame files of every 2nd frame (the smallest
step k ≥ 2 whose every k-th frame fits); then the GIF animations, whole or not at all; then the other
frames (every frame, if that fits too). What is left out — the viewer's frames beyond every k-th, the
animations — the page says (the ``note``, and one line where the animations would be), and so does
``csmlab``'s report line; the per-frame curves keep every frame.

The order puts the viewer before the animations: it plays the same frames (and more maps) at full
resolution. Measured on ``taa.toml`` (13 variants, 120 frames; ``csmlab report`` of its results): with the
animations (23.6 MiB) planned first, the viewer kept every 4th frame (30 of 120) in 58.1 MiB; planned after
the viewer's every 2nd frame, and with the strips as WebP (8.7 → 2.0 MB), it keeps every 2nd frame (60 of
120, 41.4 MiB of frame files) in 50.1 MiB, and the animations, 23.6 MiB where under 10 MiB were left, are left out.
"""

from __future__ import annotations

import dataclasses
import io
import json
import math
import shutil
import zipfile
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from csmlab.errors import InputError
from csmlab.metric_registry import metric_named, metric_values
from csmlab.registry import check_name
from csmlab.report.capture import capture_stem, read_npz
from csmlab.report.images import (CATEGORY_COLOURS, FALSE_LIGHT, FALSE_SHADOW, NO_SURFACE, change_image,
                                  rho_image)
from csmlab.report.pixels import NO_VALUE, RHO_STEPS, decode_rho
from csmlab.report.view3d import BOX_EDGES, FRUSTUM_EDGES

__all__ = ["BUDGET_BYTES", "CURVES", "PLANES", "PLANE_ENCODINGS", "TAA_CURVES", "TAA_PLANES", "ExploreFiles",
           "FIRST_STEP", "FramePayloads", "budget_plan", "explore_files", "plane_webp", "recoded", "report_size",
           "write_explore"]

BUDGET_BYTES = 60 * 2 ** 20
"""Default size budget of a report (:func:`report_size`): 60 MiB."""
FIRST_STEP = 2
"""The viewer's frame step that the budget plans before the animations (:func:`budget_plan`): every 2nd frame."""
PLANES = ("lit", "dS", "cascade", "rho", "reference", "ref_diff")
"""The value planes of a frame file, in order."""
CURVES = tuple(metric_named(name) for name in ("flicker", "flip_rate", "rho_median", "ref_error"))
"""Per-frame curves of the page, in order: registered metrics (``ref_error`` derived), each with its ``curve`` label."""
TAA_PLANES = ("lit_taa", "dS_taa", "reference_taa")
"""The after-TAA value planes (:func:`csmlab.report.pixels.taa_pixels`), after :data:`PLANES` in a frame file
whose run's records all hold them (with ``shaded_taa``); a run without them has the page it had before."""
TAA_CURVES = (metric_named("flicker_taa"),)
"""Per-frame curves added after ``flicker`` when the records hold the after-TAA planes."""
_WEBP = {"format": "WEBP", "quality": 86, "method": 2}
PLANE_ENCODINGS = {
    "fast": {"format": "WEBP", "lossless": True, "quality": 0, "method": 0},
    "compact": {"format": "WEBP", "lossless": True, "quality": 50, "method": 4},
}
"""Lossless WebP settings of a value plane by name. ``compact`` (method 4 of 6) keeps the size within 1 % of
method 6 at a third of its time; ``fast`` (method 0) takes a quarter of ``compact``'s time for planes 1.9×
larger (measured on the default run's planes: 0.44 s against 1.73 s for 360 planes, 1.41 MB against 0.74 MB).
The bytes decoded are the same."""
_RECORDS = (".npz", ".csv", ".json", ".toml")
_INDEX_RESERVE = 256 * 2 ** 10
_ENCODING_THREADS = 2
_REQUIRED = ("frame", "time_s", "stride", *PLANES, "shaded", "valid", "camera_position", "frustum_corners",
             "box_corners", "world_origin", "world_cell", "world_dS", "world_counted", "world_flips", "rho_edges",
             "rho_hist")


@dataclass(frozen=True)
class ExploreFiles:
    """The interactive part of a run, made in memory: written by :func:`write_explore` once the rest is on disk.

    Attributes
    ----------
    frames : list of int
        Frames every variant recorded, increasing.
    run : str
        The JSON of ``data.js`` (``window.csmlabRun``).
    payloads : FramePayloads
        The files of each of ``frames``: name in ``explore/frames/`` → bytes (its ``csmlabFrame(…)``
        script and its variants' shaded views), made when first read.
    stride : int
        Frame pixels per record pixel along a row or column.
    cell : float
        World cell side, metres.
    """

    frames: list[int]
    run: str
    payloads: FramePayloads
    stride: int
    cell: float


class FramePayloads(Sequence):
    """The files of each frame of a run (:func:`_frame_file`), made when first read and kept.

    Indexed like a list of dicts (name in ``explore/frames/`` → bytes); a slice makes the frames it
    lacks on two threads (WebP lets go of the GIL while it encodes). The budget reads the sizes of
    the frames it plans (:func:`budget_plan`), so a run whose planes are encoded again ``compact``
    encodes only the frames its plan reads; the shaded views, the same bytes in every encoding, are
    made once for both (:meth:`encoded`).
    """

    def __init__(self, frames: list[int], present, records, *, encoding: str, taa: bool, shaded: dict | None = None):
        self._frames, self._present, self._records, self._taa = frames, present, records, taa
        self._encoding = check_name(encoding, PLANE_ENCODINGS, field="encoding")
        self._shaded = {} if shaded is None else shaded
        self._made: dict[int, dict[str, bytes]] = {}

    def __len__(self) -> int:
        return len(self._frames)

    def __getitem__(self, index):
        if isinstance(index, slice):
            wanted = range(len(self))[index]
            missing = [k for k in wanted if k not in self._made]
            with ThreadPoolExecutor(max_workers=_ENCODING_THREADS) as threads:
                for k, payload in zip(missing, threads.map(self._make, missing)):
                    self._made[k] = payload
            return [self._made[k] for k in wanted]
        k = range(len(self))[index]
        if k not in self._made:
            self._made[k] = self._make(k)
        return self._made[k]

    def encoded(self, encoding: str) -> FramePayloads:
        """The same frames with their planes encoded ``encoding``, sharing these records and shaded views."""
        return FramePayloads(self._frames, self._present, self._records, encoding=encoding, taa=self._taa,
                             shaded=self._shaded)

    def _make(self, k: int) -> dict[str, bytes]:
        return _frame_file(self._frames[k], self._present, self._records, encoding=self._encoding, taa=self._taa,
                           shaded=self._shaded)


def recoded(files: ExploreFiles, encoding: str) -> ExploreFiles:
    """``files`` with their value planes encoded ``encoding`` (:data:`PLANE_ENCODINGS`), the frames made when read."""
    return dataclasses.replace(files, payloads=files.payloads.encoded(encoding))


def explore_files(out_dir, *, groups: list[tuple[str, str]], labels: list[str], metrics,
                  encoding: str = "compact") -> ExploreFiles | None:
    """Make the ``explore/`` folder's per-run and per-frame files of a results directory in memory.

    Parameters
    ----------
    out_dir : str or Path
        The results directory.
    groups : list of (method, point)
        The variants in results order.
    labels : list of str
        Their display names.
    metrics : Columns
        ``metrics.csv``.
    encoding : str, keyword-only
        A key of :data:`PLANE_ENCODINGS`: how the value planes are compressed (:func:`plane_webp`).

    Returns
    -------
    ExploreFiles or None
        None when the run kept no per-pixel record.

    Raises
    ------
    InputError
        If a pixel record or ``casters.npz`` is unreadable or lacks an array.
    """
    out = Path(out_dir)
    present = [(g, label) for g, label in zip(groups, labels) if (out / "pixels" / f"{capture_stem(*g)}.npz").is_file()]
    if not present:
        return None
    records = [_read_record(out / "pixels" / f"{capture_stem(*g)}.npz") for g, _ in present]
    frames = sorted(set.intersection(*(set(r["frame"].tolist()) for r in records)))
    taa = all(name in r for r in records for name in (*TAA_PLANES, "shaded_taa"))
    run = _run_data(present, records, frames, metrics, _casters(out / "casters.npz"), taa=taa)
    # The frames are made when the budget reads them (write_explore): a run whose planes are encoded
    # again compact makes only as many in this encoding as prove that they do not all fit.
    payloads = FramePayloads(frames, present, records, encoding=encoding, taa=taa)
    return ExploreFiles(frames=frames, run=run, payloads=payloads, stride=int(records[0]["stride"]),
                        cell=float(records[0]["world_cell"]))


def write_explore(out_dir, files: ExploreFiles | None, *, budget_bytes: int = BUDGET_BYTES,
                  animations: Sequence[Path] = (), compact: bool = False) -> dict | None:
    """Write the ``explore/`` folder of a results directory; return what the page's template needs.

    Parameters
    ----------
    out_dir : str or Path
        The results directory, its static report already written (its size counts against the budget).
    files : ExploreFiles or None
        :func:`explore_files` of the directory; None removes the folder.
    budget_bytes : int, keyword-only
        Largest size of the report (:func:`report_size`) once the folder is written.
    animations : sequence of Path, keyword-only
        The report's animations, already written: planned after the viewer's every 2nd frame and before
        its other frames (:func:`budget_plan`), and removed when they do not fit. With ``files`` None
        they stay.
    compact : bool, keyword-only
        Encode the planes again ``compact`` (:data:`PLANE_ENCODINGS`, :func:`recoded`) and write those files
        instead when ``files`` would leave frames or the animations out: only the frames the plan reads are
        encoded again.

    Returns
    -------
    dict or None
        ``frames`` (frames in the run), ``kept`` (frames with a frame file), ``step``, ``stride`` (and as
        an ordinal, ``stride_ordinal``), ``cell`` (world cell side, metres), ``size`` (:func:`report_size` but
        ``index.html``) and ``budget``, ``animations`` (whether they were kept), ``note`` (what the budget
        left out, or None), ``animations_note`` (the line shown where left-out animations would be, or None)
        and ``kept_text`` (what was kept, for the command line); None when ``files`` is None.
    """
    out = Path(out_dir)
    folder = out / "explore"
    shutil.rmtree(folder, ignore_errors=True)
    if files is None:
        return None
    (folder / "frames").mkdir(parents=True)
    _copy_assets(folder)
    (folder / "data.js").write_text(f"window.csmlabRun = {files.run};\n", encoding="utf-8")
    animation_bytes = sum(Path(p).stat().st_size for p in animations)
    available = budget_bytes - (report_size(out) - animation_bytes + _INDEX_RESERVE)
    if compact and len(files.frames) >= FIRST_STEP and not _all_fit(_frame_sizes(files), available - animation_bytes):
        # The plan below would leave frames or the animations out (every frame and the animations fit
        # exactly when their sum does): encoded again at once, the frames not yet made never made.
        files = recoded(files, "compact")
        compact = False
    step, kept_animations = budget_plan(_frame_sizes(files), available, animation_bytes=animation_bytes)
    if (step > 1 or not kept_animations) and compact:
        files = recoded(files, "compact")
        step, kept_animations = budget_plan(_frame_sizes(files), available, animation_bytes=animation_bytes)
    if not kept_animations:
        for path in animations:
            Path(path).unlink()
    kept = files.frames[::step]
    for payload in files.payloads[::step]:
        for name, data in payload.items():
            (folder / "frames" / name).write_bytes(data)
    (folder / "kept.js").write_text(f"window.csmlabKept = {json.dumps(kept)};\n", encoding="utf-8")
    size = report_size(out)
    frames = len(files.frames)
    budget_mib = f"{budget_bytes / 2 ** 20:.3g} MiB"
    left_out = []
    if step > 1:
        left_out.append(f"the frame viewer holds every {_ordinal(step)} frame ({len(kept)} of {frames}); the curves "
                        f"keep every frame")
    if not kept_animations:
        left_out.append("the animations are left out (play the frames here)")
    note = (f"To keep this report under its size budget of {budget_mib}, {', and '.join(left_out)}." if left_out
            else None)
    every = "every frame" if step == 1 else f"every {_ordinal(step)} frame"
    animations_note = None if kept_animations else (
        f"Animations left out to keep {every} in Explore under the {budget_mib} budget: play the frames there.")
    kept_text = (f"Explore holds {every} ({len(kept)} of {frames})"
                 + ("" if not animations else "; animations kept" if kept_animations else "; animations left out"))
    return {"frames": frames, "kept": len(kept), "step": step, "stride": files.stride,
            "stride_ordinal": _ordinal(files.stride), "cell": files.cell, "size": size, "budget": budget_bytes,
            "animations": kept_animations, "note": note, "animations_note": animations_note, "kept_text": kept_text}


class _FrameSizes(Sequence):
    """Bytes of each frame's files, read from :class:`FramePayloads` as the plan asks for them."""

    def __init__(self, payloads: FramePayloads):
        self._payloads = payloads

    def __len__(self) -> int:
        return len(self._payloads)

    def __getitem__(self, index):
        if isinstance(index, slice):
            return [sum(map(len, payload.values())) for payload in self._payloads[index]]
        return sum(map(len, self._payloads[index].values()))


def _frame_sizes(files: ExploreFiles) -> _FrameSizes:
    return _FrameSizes(files.payloads)


def budget_plan(sizes: Sequence[int], available: int, *, animation_bytes: int) -> tuple[int, bool]:
    """The viewer's frame step and whether the animations are kept, planned in the report's order.

    First the frame files of every :data:`FIRST_STEP`-th frame (or, where they do not fit, of every k-th,
    the smallest k that fits), then the animations if they fit in what is left, then every frame if
    the other frames fit in what the animations leave.

    Parameters
    ----------
    sizes : sequence of int
        Bytes of each frame's files, in frame order.
    available : int
        Bytes of the budget left once everything else of the report is written, the animations not counted.
    animation_bytes : int, keyword-only
        Bytes of the animations, kept whole or left out.

    Returns
    -------
    step : int
        Every ``step``-th frame, from the first, keeps its files (every frame but the first dropped at worst).
    animations : bool
        Whether the animations are kept (always, when they take no bytes).
    """
    step = _thinning(sizes, available, first=min(FIRST_STEP, max(len(sizes), 1)))
    left = available - sum(sizes[::step])
    animations = animation_bytes <= max(left, 0)
    if animations:
        left -= animation_bytes
    if step == FIRST_STEP and _others_fit(sizes, step, left):
        step = 1
    return step, animations


_PLAN_CHUNK = 8
"""Frames whose sizes :func:`_fit_in_chunks` reads at once: enough for both encoding threads, few past the answer."""


def _others_fit(sizes: Sequence[int], step: int, left: int) -> bool:
    """Whether the frames not in ``sizes[::step]`` fit in ``left`` bytes (:func:`_fit_in_chunks`)."""
    return _fit_in_chunks(sizes, left, offsets=range(1, step), step=step)


def _all_fit(sizes: Sequence[int], left: int) -> bool:
    """Whether all of ``sizes`` fit in ``left`` bytes (:func:`_fit_in_chunks`)."""
    return _fit_in_chunks(sizes, left, offsets=(0,), step=1)


def _fit_in_chunks(sizes: Sequence[int], left: int, *, offsets, step: int) -> bool:
    """Whether ``sizes[offset::step]`` of every offset fit in ``left`` bytes together; read in chunks of
    :data:`_PLAN_CHUNK`, stopping at the first that overflows (the sizes of :class:`FramePayloads` are
    encoded as they are read)."""
    total = 0
    for offset in offsets:
        for start in range(offset, len(sizes), step * _PLAN_CHUNK):
            total += sum(sizes[start:start + step * _PLAN_CHUNK:step])
            if total > left:
                return False
    return True


def _ordinal(n: int) -> str:
    suffix = "th" if 10 <= n % 100 <= 20 else {1: "st", 2: "nd", 3: "rd"}.get(n % 10, "th")
    return f"{n}{suffix}"


def _thinning(sizes: Sequence[int], available: int, *, first: int = 1) -> int:
    """The smallest frame step from ``first`` whose frame files fit in ``available`` bytes (every frame but the first
    dropped at worst)."""
    for step in range(first, len(sizes) + 1):
        if sum(sizes[::step]) <= available:
            return step
    return max(len(sizes), 1)


def report_size(out_dir) -> int:
    """Bytes of the report in a results directory: every file but the run's records.

    The records — ``*.npz`` anywhere (``pixels/``, ``snapshots/``, ``anim/``, ``casters.npz``) and
    the ``.csv``, ``.json`` and ``.toml`` files at the top — are what the report is made from, kept
    to remake it; ``index.html`` with its figures, animations and ``explore/`` is what a reader opens.
    """
    out = Path(out_dir)
    return sum(p.stat().st_size for p in out.rglob("*")
               if p.is_file() and p.suffix != ".npz" and not (p.parent == out and p.suffix in _RECORDS))


def _read_record(path: Path) -> dict:
    try:
        record = read_npz(path)
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as error:
        raise InputError(f"expected a csmlab pixel record (.npz), got an unreadable file: {error}", file=path) from None
    missing = [k for k in _REQUIRED if k not in record]
    if missing:
        raise InputError(f"expected arrays {', '.join(missing)} in the pixel record", file=path, field=missing[0])
    return record


def _casters(path: Path) -> np.ndarray:
    if not path.is_file():
        return np.zeros((0, 3), dtype=np.float32)
    try:
        return np.asarray(read_npz(path)["points"], dtype=np.float32).reshape(-1, 3)
    except (OSError, ValueError, KeyError, zipfile.BadZipFile, EOFError) as error:
        raise InputError(f"expected an .npz with an array 'points' (P, 3), got {error}", file=path,
                         field="points") from None


def _copy_assets(folder: Path) -> None:
    from plotly.offline import get_plotlyjs

    (folder / "plotly.min.js").write_text(get_plotlyjs(), encoding="utf-8")
    shutil.copyfile(Path(__file__).parent / "templates" / "explore.js", folder / "explore.js")


def _rounded(values, digits: int = 3):
    """Nested lists of ``values`` rounded to ``digits`` decimals, None for NaN (JSON-safe, stable text)."""
    array = np.asarray(values, dtype=np.float64)
    if array.size == 0:
        return array.tolist()
    # Python's round on a flat list, nested afterwards: the world maps hold tens of thousands of values.
    nested = [None if not math.isfinite(v) else round(v, digits) for v in array.ravel().tolist()]
    for n in reversed(array.shape[1:]):
        nested = [nested[i:i + n] for i in range(0, len(nested), n)]
    return nested if array.ndim else nested[0]


def _u8_colours(rgb) -> list:
    return np.rint(np.clip(np.asarray(rgb, dtype=np.float64), 0, 1) * 255).astype(int).tolist()


def _run_data(present, records, frames, metrics, casters, *, taa: bool) -> str:
    """``data.js``'s JSON; with ``taa``, also the after-TAA planes, their curve and ``"taa": true``."""
    curves_shown = (CURVES[0], *TAA_CURVES, *CURVES[1:]) if taa else CURVES
    codes = np.arange(255)
    rho_lut = rho_image(decode_rho(codes)[None, :])[0]
    dS_lut = change_image(codes[None, :] / 254.0)[0]
    first = records[0]
    seen_z, seen_x = _counted_extent([r["world_counted"] for r in records])
    variants = []
    for ((method, point), label), record in zip(present, records):
        rows = metrics.of(method, point)
        by_frame = {int(f): k for k, f in enumerate(rows["frame"])}
        curves = {}
        for metric in curves_shown:
            column = metric_values(metric.name, rows)
            if column is not None:
                curves[metric.name] = _rounded([column[by_frame[f]] * metric.scale if f in by_frame else np.nan
                                                for f in frames], 6)
        counted = record["world_counted"][seen_z, seen_x].astype(np.float64)
        with np.errstate(invalid="ignore", divide="ignore"):
            mean_dS = np.where(counted > 0, record["world_dS"][seen_z, seen_x] / counted, np.nan)
            flip_rate = np.where(counted > 0, 100.0 * record["world_flips"][seen_z, seen_x] / counted, np.nan)
        index = {int(f): k for k, f in enumerate(record["frame"])}
        variants.append({
            "stem": capture_stem(method, point), "method": method, "point": point, "label": label,
            "curves": curves,
            "path": _rounded([record["camera_position"][index[f]][[0, 2]] for f in frames], 2),
            "world": {"mean_dS": _rounded(mean_dS, 5), "flip_rate": _rounded(flip_rate, 3),
                      "counted": counted.astype(np.int64).tolist()},
            "rho_hist": record["rho_hist"].astype(np.int64).tolist(),
        })
    times = {int(f): float(t) for f, t in zip(first["frame"], first["time_s"])}
    cell = float(first["world_cell"])
    origin = first["world_origin"]
    run = {
        "frames": frames,
        "times": [round(times[f], 4) for f in frames],
        "fps": _fps([times[f] for f in frames]),
        "width": int(first["lit"].shape[2]), "height": int(first["lit"].shape[1]),
        "stride": int(first["stride"]),
        "cascades": int(first["box_corners"].shape[1]),
        "planes": [*PLANES, *(TAA_PLANES if taa else ())], "no_value": NO_VALUE, "rho_steps": RHO_STEPS,
        **({"taa": True} if taa else {}),
        "curves": [{"key": m.name, "label": m.curve} for m in curves_shown],
        "colours": {"rho": rho_lut.tolist(), "dS": dS_lut.tolist(), "categories": _u8_colours(CATEGORY_COLOURS),
                    "false_shadow": _u8_colours(FALSE_SHADOW), "false_light": _u8_colours(FALSE_LIGHT),
                    "no_surface": _u8_colours(NO_SURFACE)},
        "world": {"x": _rounded(origin[0] + cell * (np.arange(seen_x.start, seen_x.stop) + 0.5), 2),
                  "z": _rounded(origin[1] + cell * (np.arange(seen_z.start, seen_z.stop) + 0.5), 2),
                  "cell": round(cell, 4)},
        "rho_centres": _rounded(np.exp2(0.5 * (first["rho_edges"][:-1] + first["rho_edges"][1:])), 5),
        "casters": _rounded(casters, 2),
        "box_edges": BOX_EDGES.tolist(), "frustum_edges": FRUSTUM_EDGES.tolist(),
        "variants": variants,
    }
    return json.dumps(run, separators=(",", ":"), allow_nan=False)


def _counted_extent(counts: list[np.ndarray]) -> tuple[slice, slice]:
    """The rows and columns ``(nz, nx)`` of the world grid that some pixel of some variant fell in.

    The world maps are written over this rectangle only: a walk sees a few per cent of its scene's
    grid, and the uncounted cells, written as ``null``, made most of ``data.js``.
    """
    hit = np.logical_or.reduce([np.asarray(c) > 0 for c in counts])
    if not hit.any():
        return slice(0, hit.shape[0]), slice(0, hit.shape[1])
    rows, cols = np.flatnonzero(hit.any(axis=1)), np.flatnonzero(hit.any(axis=0))
    return slice(int(rows[0]), int(rows[-1]) + 1), slice(int(cols[0]), int(cols[-1]) + 1)


def _fps(times: list[float]) -> float:
    steps = np.diff(np.asarray(times, dtype=np.float64))
    steps = steps[np.isfinite(steps) & (steps > 0)]
    return round(float(1.0 / np.median(steps)), 3) if steps.size else 30.0


def _frame_file(frame: int, present, records, *, encoding: str, taa: bool = False,
                shaded: dict | None = None) -> dict[str, bytes]:
    """The files of one frame: ``f<frame>.js`` (``csmlabFrame(frame, {planes: [base85 WebP, …], variants: {stem:
    {img, planes (indices, in PLANES order), camera, frustum, boxes}}})``) and each variant's shaded view
    ``f<frame>__<stem>.webp``. A plane equal to one already in the frame (the reference's, in every variant)
    is encoded once. With ``taa``, each variant's planes go on with :data:`TAA_PLANES` and it has ``img_taa``,
    its view shaded through S after TAA, ``f<frame>__<stem>__taa.webp``. ``shaded`` keeps the shaded views by
    file name for another encoding of the planes to take (their bytes do not depend on it)."""
    files, variants, indices, planes = {}, {}, {}, []
    shaded = {} if shaded is None else shaded

    def shaded_file(name: str, image: np.ndarray, lit: np.ndarray) -> None:
        if name not in shaded:
            shaded[name] = _shaded_webp(image, defined=lit != NO_VALUE)
        files[name] = shaded[name]

    def plane_index(plane: np.ndarray) -> int:
        key = np.ascontiguousarray(plane).tobytes()
        if key not in indices:
            indices[key] = len(planes)
            planes.append(plane_webp(plane, encoding=encoding))
        return indices[key]

    for ((method, point), _), record in zip(present, records):
        stem = capture_stem(method, point)
        k = int(np.flatnonzero(record["frame"] == frame)[0])
        image = f"f{frame:05d}__{stem}.webp"
        shaded_file(image, record["shaded"][k], record["lit"][k])
        variants[stem] = {
            "img": f"explore/frames/{image}",
            "planes": [plane_index(record[name][k]) for name in (*PLANES, *(TAA_PLANES if taa else ()))],
            "camera": _rounded(record["camera_position"][k], 3),
            "frustum": _rounded(record["frustum_corners"][k], 3),
            "boxes": _rounded(record["box_corners"][k], 3),
        }
        if taa:
            image = f"f{frame:05d}__{stem}__taa.webp"
            shaded_file(image, record["shaded_taa"][k], record["lit_taa"][k])
            variants[stem]["img_taa"] = f"explore/frames/{image}"
    body = {"planes": planes, "variants": variants}
    files[f"f{frame:05d}.js"] = f"csmlabFrame({frame},{json.dumps(body, separators=(',', ':'))});\n".encode("ascii")
    return files


def _shaded_webp(shaded, *, defined) -> bytes:
    """A shaded view ``(h, w, 3)`` uint8 sRGB as lossy WebP, the no-surface colour where not ``defined`` ``(h, w)``."""
    from PIL import Image

    shaded = np.where(defined[..., None], shaded, np.array(_u8_colours(NO_SURFACE), dtype=np.uint8))
    buffer = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(shaded, dtype=np.uint8)).save(buffer, **_WEBP)
    return buffer.getvalue()


def plane_webp(plane, *, encoding: str = "compact") -> str:
    """A value plane ``(h, w)`` uint8 or int8 (as its two's-complement bytes) as a lossless greyscale WebP, in base85.

    ``encoding`` names one of :data:`PLANE_ENCODINGS`.

    Base85 (RFC 1924's alphabet, :func:`base64.b85encode` without padding: none of its characters
    needs escaping in a JavaScript string) is 25 % longer than the bytes where base64 is a third.
    """
    from PIL import Image

    buffer = io.BytesIO()
    settings = PLANE_ENCODINGS[check_name(encoding, PLANE_ENCODINGS, field="encoding")]
    Image.fromarray(np.ascontiguousarray(plane).view(np.uint8)).save(buffer, **settings)
    return base85(buffer.getvalue())


_B85_ALPHABET = np.frombuffer(b"0123456789ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz!#$%&()*+-;<=>?@^_`{|}~",
                              dtype=np.uint8)


def base85(data: bytes) -> str:
    """``data`` in base85, the text of :func:`base64.b85encode` (RFC 1924's alphabet, no padding), with NumPy.

    The standard library's encoder loops in Python over every 4 bytes, holding the GIL: a report's
    planes spent longer in it than in their WebP encoding, and kept the second encoding thread waiting.
    """
    padding = -len(data) % 4
    words = np.frombuffer(data + bytes(padding), dtype=">u4").astype(np.uint64)
    digits = np.empty((words.size, 5), dtype=np.uint8)
    for k in range(4, -1, -1):
        digits[:, k] = words % 85
        words //= 85
    text = _B85_ALPHABET[digits].tobytes()
    return text[:len(text) - padding].decode("ascii")
