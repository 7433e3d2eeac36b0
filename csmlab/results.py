"""The results files of a run, written atomically, and their reading back.

Files in a results directory (docs/design.md, "Interfaces"):

``config.resolved.toml``
    The experiment with its presets merged, written before any work.
``metrics.csv``
    ``frame, time_s, method, point`` then the metric columns; one row per frame × method × sweep
    point, sorted by method (config order), point (sweep order), frame. Floats are written as
    Python's shortest round-trip ``repr``, whole numbers without a fraction, NaN as an empty cell:
    the same numbers give the same bytes.
``timings.csv``
    ``frame, method, point, stage, seconds``: wall-clock times, kept apart so that the two files
    above are byte-identical run after run. Stages shared by all methods (the view) have an empty
    method and point.
``summary.json``
    ``name, config_hash, workload_hash, csmlab_version, environment, frames, config, light_moves,
    point_fields, stabilization, invariants, methods, points``: ``light_moves`` whether the light's direction
    changes over the run, ``point_fields[P]`` the shadow fields sweep point P sets (typed as in the
    config), ``stabilization[M][P]`` the stabilization method M uses at P, ``invariants[M][P]`` what
    method M promises at P (:func:`csmlab.invariants.summary_invariants`: ``flicker_same_zero`` →
    ``promised, metric, value, why``, the invariants ``csmlab regress`` holds exactly) — written once,
    so that no reader rebuilds them from ``config``;
    ``methods[M][metric]`` is the mean of M's rows' finite values (frames and sweep points),
    ``points[P][M][metric]`` the mean over frames at sweep point P; each with ``frames``. A metric with
    no value in any frame is ``null``. A recorded camera path adds ``recording``
    (:meth:`csmlab.paths.timing.TimingReport.as_dict`: repeated time stamps and tracking gaps, how
    many, where, how long, and the rules applied). ``view_check`` (unless ``[camera] view_check = "off"``,
    :meth:`csmlab.paths.view_check.ViewFindings.as_dict`): frames checked and, for each check, the
    flagged frames as ``[first, last]`` ranges. ``blend_materials`` (a glTF level with ``alphaMode = "BLEND"``
    materials, :func:`csmlab.experiment.build_workload`): the rule they were read by and their names.
    ``light_colour`` (a light that is not white: a glTF sun's ``color``): its linear RGB.
    Written last: a directory without it holds no
    finished run.
``.chunks/``
    Finished units of work of a run in progress (pickles, each with the config hash and device it
    belongs to), so that ``--resume`` redoes only what is missing. A unit is a range of frames of
    a set of variants (results ranks): its file is named by both, so units of different variant
    sets never take each other's place. Removed when the run finishes.

Every file is written to a temporary name and renamed into place (``os.replace``), so a reader never
sees half a file.
"""

from __future__ import annotations

import csv
import hashlib
import importlib.metadata
import io
import json
import math
import pickle
import platform
import shutil
from pathlib import Path
from typing import NamedTuple

import numpy as np

import csmlab
from csmlab.errors import InputError
from csmlab.files import write_atomic
from csmlab.metric_registry import finite_mean

__all__ = [
    "FINAL_FILES",
    "KEY_COLUMNS",
    "MetricRow",
    "TIMING_COLUMNS",
    "TimingRow",
    "clear_chunks",
    "environment",
    "format_value",
    "kept_chunks",
    "load_chunk",
    "load_chunk_part",
    "metric_arrays",
    "prepare_output",
    "read_metrics",
    "read_summary",
    "save_chunk",
    "summarize",
    "write_atomic",
    "write_metrics",
    "write_summary",
    "write_timings",
]

KEY_COLUMNS = ("frame", "time_s", "method", "point")
"""The columns of ``metrics.csv`` before the metrics."""
TIMING_COLUMNS = ("frame", "method", "point", "stage", "seconds")
FINAL_FILES = ("summary.json", "metrics.csv", "timings.csv", "regress.json", "index.html")
"""Files a finished run leaves (or the report adds); removed when a new run starts in the directory."""
_CHUNKS = ".chunks"


class MetricRow(NamedTuple):
    """One row of ``metrics.csv``: one frame of one method at one sweep point.

    Attributes
    ----------
    frame : int
    time_s : float
        The camera pose's time stamp, seconds.
    method, point : str
        Method name and sweep-point label.
    values : dict of str to float
        Metric name → value; a column it lacks is an empty cell.
    """

    frame: int
    time_s: float
    method: str
    point: str
    values: dict


class TimingRow(NamedTuple):
    """One row of ``timings.csv``: wall-clock seconds of one stage of one frame.

    ``method`` and ``point`` are empty for the view's stages, shared by every method.
    """

    frame: int
    method: str
    point: str
    stage: str
    seconds: float


def format_value(value) -> str:
    """One ``metrics.csv`` cell: empty for None/NaN, whole numbers without a fraction, else ``repr(float)``."""
    if value is None:
        return ""
    if isinstance(value, str):
        return value
    number = float(value)
    if math.isnan(number):
        return ""
    if number.is_integer() and abs(number) < 2.0 ** 53:
        return str(int(number))
    return repr(number)


def _csv_text(header, rows) -> str:
    text = io.StringIO()
    writer = csv.writer(text, lineterminator="\n")
    if header is not None:
        writer.writerow(header)
    writer.writerows(rows)
    return text.getvalue()


def write_metrics(path, blocks, *, columns) -> Path:
    """Write ``metrics.csv`` from blocks of rows in file order, streamed.

    Parameters
    ----------
    path : str or Path
    blocks : iterable of lists of MetricRow
        The rows in the order of the file — each variant's rows by frame, the variants in results
        order — cut into blocks (a variant each, as :func:`csmlab.experiment.run_experiment` reads
        them back from its chunks): each block is written before the next is asked for, so a long
        path's rows are never all in memory.
    columns : sequence of str
        The metric columns, in order.
    """
    def pieces():
        yield _csv_text([*KEY_COLUMNS, *columns], [])
        for block in blocks:
            yield _csv_text(None, [[str(r.frame), format_value(r.time_s), r.method, r.point,
                                    *(format_value(r.values.get(c)) for c in columns)] for r in block])

    return write_atomic(path, pieces())


def write_timings(path, blocks, *, order: dict) -> Path:
    """Write ``timings.csv`` from blocks of :class:`TimingRow` (a chunk's each, in frame order), streamed.

    Rows are sorted by frame then variant rank within each block — the file's order, as long as the
    blocks cover increasing frame ranges. ``order`` maps ``(method, point)`` to its rank; the shared
    stages (``("", "")``) come first.
    """
    def pieces():
        yield _csv_text(TIMING_COLUMNS, [])
        for block in blocks:
            ordered = sorted(block, key=lambda r: (r.frame, order.get((r.method, r.point), -1)))
            yield _csv_text(None, [[str(r.frame), r.method, r.point, r.stage, repr(float(r.seconds))]
                                   for r in ordered])

    return write_atomic(path, pieces())


def read_metrics(path) -> tuple[list[str], list[dict]]:
    """The header and the rows (dicts of strings) of a ``metrics.csv``."""
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        return list(reader.fieldnames or []), list(reader)


def _value(mean: float) -> float | None:
    return None if math.isnan(mean) else mean


def metric_arrays(rows, *, columns) -> dict[str, np.ndarray]:
    """One variant's rows as arrays: ``frame`` (N,) int64 and each metric column (N,) float64, NaN where empty."""
    nan = float("nan")
    values = np.array([[nan if r.values.get(c) is None else r.values[c] for c in columns] for r in rows],
                      dtype=np.float64).reshape(len(rows), len(columns))
    return {"frame": np.array([r.frame for r in rows], dtype=np.int64),
            **{c: values[:, k] for k, c in enumerate(columns)}}


def _aggregate(arrays: list[dict], columns) -> dict:
    out = {c: _value(finite_mean(np.concatenate([a[c] for a in arrays]) if arrays else [])) for c in columns}
    out["frames"] = len(np.unique(np.concatenate([a["frame"] for a in arrays]))) if arrays else 0
    return out


def summarize(variants: dict, *, columns, methods, points) -> tuple[dict, dict]:
    """The ``methods`` and ``points`` aggregates of ``summary.json``.

    Parameters
    ----------
    variants : dict of (method, point) to dict of str to ndarray
        Each variant's :func:`metric_arrays`, frames in order.
    columns : sequence of str
        The metric columns.
    methods, points : sequence of str
        Method names and sweep-point labels in config order (the JSON keeps it).

    Returns
    -------
    methods : dict
        ``{method: {metric: mean of its rows' finite values (None when none), …, "frames": N}}``.
    points : dict
        ``{point: {method: {…}}}``.
    """
    method_summary = {m: _aggregate([variants[(m, p)] for p in points if (m, p) in variants], columns)
                      for m in methods}
    point_summary = {p: {m: _aggregate([variants[(m, p)]] if (m, p) in variants else [], columns) for m in methods}
                     for p in points}
    return method_summary, point_summary


def environment(*, device: str) -> dict:
    """Versions and machine the numbers came from (no time, no host name: two runs give the same)."""
    return {
        "python": platform.python_version(),
        "numpy": np.__version__,
        # The installed distribution's version: importing Warp for it would cost the parent a second.
        "warp": importlib.metadata.version("warp-lang"),
        "platform": platform.platform(),
        "machine": platform.machine(),
        "device": device,
    }


def _json_safe(value):
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(v) for v in value]
    return value


def json_text(document: dict) -> str:
    """``document`` as indented JSON, NaN and infinities as ``null``, a final newline."""
    return json.dumps(_json_safe(document), indent=2, allow_nan=False) + "\n"


def write_summary(path, *, name: str, config_hash: str, workload_hash: str, device: str, frames: int,
                  config: dict, light_moves: bool, point_fields: dict, stabilization: dict, invariants: dict,
                  methods: dict, points: dict, recording: dict | None = None, view_check: dict | None = None,
                  blend_materials: dict | None = None, light_colour: list | None = None) -> Path:
    """Write ``summary.json`` (fields in the module docstring; ``recording`` only for a recorded path,
    ``view_check`` only when the check ran, ``blend_materials`` only for a level that has them,
    ``light_colour`` only for a light that is not white)."""
    extra = {key: value for key, value in (("recording", recording), ("view_check", view_check),
                                           ("blend_materials", blend_materials), ("light_colour", light_colour))
             if value is not None}
    return write_atomic(path, json_text({
        "name": name,
        "config_hash": config_hash,
        "workload_hash": workload_hash,
        "csmlab_version": csmlab.__version__,
        "environment": environment(device=device),
        "frames": frames,
        "config": config,
        "light_moves": light_moves,
        "point_fields": point_fields,
        "stabilization": stabilization,
        "invariants": invariants,
        "methods": methods,
        "points": points,
        **extra,
    }))


def read_summary(results_dir) -> dict:
    """The ``summary.json`` of a results directory.

    Raises
    ------
    InputError
        If it is missing (the run did not finish) or not a csmlab summary.
    """
    path = Path(results_dir) / "summary.json"
    if not path.is_file():
        raise InputError("expected the summary.json of a finished run (csmlab run writes it last), got no such file",
                         file=path)
    return read_json(path, required=("name", "workload_hash", "methods", "points", "config", "light_moves",
                                      "point_fields", "stabilization"))


def read_json(path, *, required=()) -> dict:
    """A JSON object from ``path`` holding the ``required`` keys; InputError naming the file otherwise."""
    try:
        document = json.loads(Path(path).read_text(encoding="utf-8"))
    except OSError as exc:
        raise InputError(f"expected a readable JSON file, got {exc.strerror or exc}", file=path) from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"expected JSON, got {exc}", file=path) from None
    if not isinstance(document, dict):
        raise InputError(f"expected a JSON object, got {type(document).__name__}", file=path)
    for key in required:
        if key not in document:
            raise InputError(f"expected a field {key!r}, got none", file=path, field=key)
    return document


def prepare_output(out_dir, *, resolved_toml: str, run_key: str, resume: bool) -> Path:
    """Make ``out_dir`` ready for a run: stale final files removed, the resolved config written.

    ``run_key`` names what chunks belong to (the config hash and the device). Without ``resume``
    the chunks of an earlier run are cleared; with it they are kept, provided they have this key.

    Raises
    ------
    InputError
        With ``resume`` when the chunks belong to another config or device.
    """
    out = Path(out_dir)
    chunks = out / _CHUNKS
    marker = chunks / "run_key"
    if resume and marker.is_file() and marker.read_text().strip() != run_key:
        raise InputError(f"expected chunks of this config and device ({run_key}) to resume, got chunks of "
                         f"{marker.read_text().strip()}: run without --resume", file=chunks, field="--resume")
    if not resume and chunks.exists():
        shutil.rmtree(chunks)
    for name in FINAL_FILES:
        (out / name).unlink(missing_ok=True)
    write_atomic(out / "config.resolved.toml", resolved_toml)
    chunks.mkdir(parents=True, exist_ok=True)
    write_atomic(marker, run_key + "\n")
    return out


def _chunk_path(out_dir, start: int, stop: int, ranks: tuple[int, ...], part: str = "") -> Path:
    # The variant set by a digest: a list of ranks can outgrow a file name (a sweep of hundreds of
    # points); the payload holds the ranks themselves, checked on reading.
    variants = hashlib.sha256(",".join(map(str, ranks)).encode()).hexdigest()[:16]
    suffix = f".{part}.bin" if part else ".pkl"
    return Path(out_dir) / _CHUNKS / f"chunk_{start:07d}_{stop:07d}_{variants}{suffix}"


def save_chunk(out_dir, result, *, run_key: str, parts: dict[str, bytes] | None = None) -> Path:
    """Keep one finished unit of work for ``--resume``: an object with ``start``, ``stop`` and ``ranks``.

    ``ranks`` (tuple of int) are the results ranks of the variants it holds, frames ``[start, stop)``.
    ``parts`` (name to bytes) are kept beside it, each in a file of its own, so that a reader who
    needs one of them (:func:`load_chunk_part`) does not read the others; they are written first,
    so a chunk that :func:`load_chunk` finds has all of its parts.
    """
    ranks = tuple(result.ranks)
    for name, data in (parts or {}).items():
        write_atomic(_chunk_path(out_dir, result.start, result.stop, ranks, name), data)
    payload = pickle.dumps({"run_key": run_key, "start": result.start, "stop": result.stop, "ranks": ranks,
                            "result": result}, protocol=pickle.HIGHEST_PROTOCOL)
    return write_atomic(_chunk_path(out_dir, result.start, result.stop, ranks), payload)


def load_chunk_part(out_dir, start: int, stop: int, ranks: tuple[int, ...], name: str) -> bytes | None:
    """The part ``name`` kept with the unit of frames ``[start, stop)`` and variants ``ranks``; None when there is
    none."""
    path = _chunk_path(out_dir, start, stop, tuple(ranks), name)
    return path.read_bytes() if path.is_file() else None


def _chunk_payload(path: Path) -> dict | None:
    try:
        payload = pickle.loads(path.read_bytes())
    except (OSError, pickle.UnpicklingError, EOFError, AttributeError, ImportError):
        return None
    return payload if isinstance(payload, dict) else None


def load_chunk(out_dir, start: int, stop: int, ranks: tuple[int, ...], *, run_key: str):
    """The kept unit of frames ``[start, stop)`` and variants ``ranks`` of ``run_key``.

    None when there is none, it is unreadable or of another run. One unit at a time: a run keeps
    its finished units here rather than in memory, so that a long path's results are streamed to
    disk and read back unit by unit.
    """
    ranks = tuple(ranks)
    payload = _chunk_payload(_chunk_path(out_dir, start, stop, ranks))
    if payload is None or payload.get("run_key") != run_key or payload.get("ranks") != ranks:
        return None
    return payload["result"]


def kept_chunks(out_dir, *, run_key: str) -> list[tuple[int, int, tuple[int, ...]]]:
    """``(start, stop, ranks)`` of every readable unit of ``run_key`` kept in ``out_dir``, sorted.

    What a resumed run may reuse: it picks the units that fit its plan (:func:`load_chunk` reads one).
    """
    found = []
    for path in (Path(out_dir) / _CHUNKS).glob("chunk_*.pkl"):
        payload = _chunk_payload(path)
        if payload is not None and payload.get("run_key") == run_key and "ranks" in payload:
            found.append((payload["start"], payload["stop"], payload["ranks"]))
    return sorted(found)


def clear_chunks(out_dir) -> None:
    """Remove the kept chunks once the final files are written."""
    shutil.rmtree(Path(out_dir) / _CHUNKS, ignore_errors=True)
