"""The experiment schema: documented records, TOML loading with presets, validation, sweep expansion.

An experiment file (DESIGN.md, "Experiments, CLI, outputs") names a scene, a camera path, a light,
base ``[shadow]`` settings, ``[[methods]]`` (named variations on the base), an optional ``[sweep]``
(cartesian product over shadow fields) and optional ``[regress]`` tolerances.

``extends = ["methods/exact", "scenes/terrain", …]`` merges presets from ``configs/`` (or ``.toml``
files relative to the extending file) before the file's own tables: tables merge key by key, later
wins, the experiment last; ``[[methods]]`` merge by ``name``. Presets are read afresh for every load,
never changed in place. ``name``, ``description`` and ``extends`` are never inherited.

Everything a user can get wrong is checked here, before any work, and reported as one
:class:`~csmlab.errors.InputError` naming the file the value came from (preset or experiment), the
line where it is written when it can be found, the field, and what was expected.
"""

from __future__ import annotations

import ast
import copy
import difflib
import functools
import hashlib
import inspect
import itertools
import json
import math
import os
import re
import sys
import textwrap
import typing
from dataclasses import dataclass, field, fields
from pathlib import Path

import csmlab
from csmlab.errors import InputError
from csmlab.registry import parameters, unknown_name_message
from csmlab.settings import ShadowSettings

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

__all__ = [
    "CONFIGS_DIR",
    "EXPERIMENTS_DIR",
    "CameraConfig",
    "Experiment",
    "LightConfig",
    "Method",
    "ReportConfig",
    "SceneConfig",
    "TuneConfig",
    "Variant",
    "config_hash",
    "experiment_document",
    "experiment_toml",
    "field_docs",
    "find_experiment",
    "list_experiments",
    "list_presets",
    "load_experiment",
    "load_tolerances",
    "method_preset_toml",
    "parse_size",
    "sweep_points",
    "workload_hash",
]

PROJECT_DIR = Path(csmlab.__file__).resolve().parents[1]
CONFIGS_DIR = PROJECT_DIR / "configs"
"""Presets, by name relative to this folder without ``.toml`` (``methods/exact``)."""
EXPERIMENTS_DIR = PROJECT_DIR / "experiments"
"""The experiments that come with csmlab (``csmlab run`` runs ``default.toml``)."""

_NOT_INHERITED = ("name", "description", "extends")
_METHOD_NAME = re.compile(r"^[A-Za-z0-9_.+-]+$")


def _expect(predicate, text: str) -> dict:
    """Field metadata: a range check and the words that say what was expected."""
    return {"expect": (predicate, text)}


def _positive(x) -> bool:
    return x > 0 and math.isfinite(x)


@dataclass(frozen=True)
class SceneConfig:
    """``[scene]``: what the camera sees and the light shines on."""

    kind: str = "terrain"
    """A procedural scene (``csmlab list`` names them) or ``mesh`` (a file)."""
    seed: int = 1
    """Random seed of a procedural scene."""
    file: str = ""
    """mesh: the mesh file (OBJ, PLY, STL, VTK, glTF), relative to the file that names it."""
    scale: float = field(default=1.0, metadata=_expect(_positive, "a positive number of metres per mesh unit"))
    """mesh: metres per mesh unit."""
    up: str = "y"
    """mesh: the file's up axis, y or z (a Z-up file is turned to Y-up)."""
    ground: bool = False
    """mesh: add a ground plane under the mesh to receive its shadow."""
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Metres the whole world (scene and camera path) is moved by: a world far from the origin (10⁶ m)."""
    params: dict = field(default_factory=dict)
    """Further keyword parameters of the procedural scene (its generator's signature lists them)."""


@dataclass(frozen=True)
class CameraConfig:
    """``[camera]``: the camera path (a generator or a recorded file) and the image."""

    path: str = ""
    """A path generator (``csmlab list`` names them); leave empty when ``file`` is set."""
    file: str = ""
    """A recorded camera path, relative to the file that names it; leave empty when ``path`` is set."""
    format: str = ""
    """file: its format (``csmlab list`` names them); empty guesses it from the file."""
    convention: str = ""
    """file: its camera axis convention; empty takes the format's own."""
    scale: float = field(default=1.0, metadata=_expect(_positive, "a positive number of metres per file unit"))
    """file: metres per file unit."""
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """file: world position in metres the path is moved by after scaling."""
    time_offset: float = 0.0
    """file: the run's clock at the file's first pose, seconds (the clock starts there, not at the file's time stamps)."""
    start_s: float | None = None
    """file: first time kept, seconds on the run's clock (see ``time_offset``); unset keeps from the start."""
    end_s: float | None = None
    """file: last time kept, seconds on the run's clock (see ``time_offset``); unset keeps to the end."""
    times_file: str = ""
    """file: a separate time-stamp file (KITTI), relative to the file that names it."""
    anchor: str = ""
    """file: "first" puts the first pose at ``offset`` (georeferenced/UTM paths); empty keeps the file's positions."""
    duplicate_times: str = "first"
    """file: poses under a repeated time stamp: first (default, as pandas/NumPy keep), last, mean or error."""
    max_gap: float | None = field(default=None, metadata=_expect(_positive, "a positive number of seconds"))
    """file: a step between poses longer than this (seconds) is a tracking gap; unset: 10 × the median step."""
    gaps: str = "interpolate"
    """file: tracking gaps are bridged (interpolate), cut (no frame inside, temporal metrics restart) or an error."""
    seed: int = 1
    """Random seed of a generated path."""
    frames: int = field(default=120, metadata=_expect(lambda x: x >= 1, "at least 1 frame"))
    """Frames to render: a generated path's length, a recorded path's cap."""
    fps: float = field(default=30.0, metadata=_expect(_positive, "a positive frame rate in Hz"))
    """Frames per second (a recorded path is resampled to it)."""
    width: int = field(default=640, metadata=_expect(lambda x: 8 <= x <= 16384, "an image width in 8..16384 pixels"))
    """Image width in pixels."""
    height: int = field(default=360, metadata=_expect(lambda x: 8 <= x <= 16384, "an image height in 8..16384 pixels"))
    """Image height in pixels."""
    fov_y_deg: float = field(default=60.0, metadata=_expect(lambda x: 0 < x < 180, "an angle in (0, 180) degrees"))
    """Vertical field of view, degrees."""
    near: float = field(default=0.1, metadata=_expect(_positive, "a positive distance in metres"))
    """Near clip distance, metres."""
    far: float = field(default=400.0, metadata=_expect(_positive, "a positive distance in metres"))
    """Far clip distance, metres."""
    params: dict = field(default_factory=dict)
    """Further keyword parameters of the path generator (its signature lists them)."""

    @property
    def aspect(self) -> float:
        """Width / height of the image."""
        return self.width / self.height


@dataclass(frozen=True)
class LightConfig:
    """``[light]``: the directional light, as a vector or as a sun's elevation and azimuth."""

    direction: tuple[float, float, float] | None = None
    """From the light toward the scene, any non-zero length; or set elevation/azimuth instead."""
    elevation_deg: float | None = field(default=None, metadata=_expect(lambda x: -90 <= x <= 90,
                                                                       "an angle in [-90, 90] degrees"))
    """Sun elevation above the horizon, degrees (90: straight down). Default 40."""
    azimuth_deg: float | None = None
    """Sun azimuth from +Z toward +X about +Y, degrees. Default 30."""
    elevation_end_deg: float | None = field(default=None, metadata=_expect(lambda x: -90 <= x <= 90,
                                                                           "an angle in [-90, 90] degrees"))
    """Animated sun: elevation at the last frame, degrees (linear in between)."""
    azimuth_end_deg: float | None = None
    """Animated sun: azimuth at the last frame, degrees (linear in between)."""

    @property
    def is_static(self) -> bool:
        """The light direction is the same in every frame."""
        return self.direction is not None or (
            self.elevation_end_deg in (None, self.elevation_deg) and self.azimuth_end_deg in (None, self.azimuth_deg))


@dataclass(frozen=True)
class ReportConfig:
    """``[report]``: what the HTML report keeps."""

    snapshot_frames: tuple[int, ...] | None = field(default=None, metadata=_expect(lambda x: x >= 0,
                                                                                   "frame numbers >= 0"))
    """Frames kept at full resolution (frames past the end are skipped); unset: three spread over the run."""


_SIZE_UNITS = {"": 1, "b": 1, "kb": 10**3, "mb": 10**6, "gb": 10**9, "kib": 2**10, "mib": 2**20, "gib": 2**30}


def parse_size(text) -> int:
    """Bytes from ``64MiB``, ``16MB``, ``1.5GiB`` or a plain number of bytes (int or digits).

    Raises
    ------
    ValueError
        Saying what was expected.
    """
    if isinstance(text, int) and not isinstance(text, bool) and text > 0:
        return text
    match = re.fullmatch(r"\s*([0-9]+(?:\.[0-9]*)?)\s*([A-Za-z]*)\s*", text) if isinstance(text, str) else None
    unit = match.group(2).lower() if match else None
    if unit not in _SIZE_UNITS or float(match.group(1)) <= 0:
        raise ValueError(f"expected a positive size such as 64MiB, 16MB or 16777216 (bytes), got {text!r}")
    return int(round(float(match.group(1)) * _SIZE_UNITS[unit]))


@dataclass(frozen=True)
class TuneConfig:
    """``[tune]``: what ``csmlab tune`` searches and under which budgets (command-line options win).

    Every other key of ``[tune]`` is a ``[shadow]`` field to search: a list of choices
    (``resolution = [512, 1024, 2048]``) or a range (``lambda = { min = 0.3, max = 0.95 }``, with
    ``log = true`` for a log scale and ``step`` for a grid).
    """

    space: tuple = ()
    """``(field, ("choice", values) | ("range", lo, hi, log, step))`` pairs, in file order."""
    method: str = ""
    """The method to tune; empty: the experiment's first."""
    objectives: tuple[str, ...] = ()
    """metrics.csv columns to improve (means over frames); empty: ``rho_p05``."""
    trials: int | None = field(default=None, metadata=_expect(lambda x: x >= 1, "at least 1 trial"))
    """Candidates to evaluate; unset: 20."""
    seed: int | None = None
    """Sampler seed; unset: 0."""
    memory_budget: int | None = None
    """Shadow-map memory in bytes no recommended setting may exceed (TOML: ``"64MiB"``, ``"16MB"`` or bytes)."""
    max_flicker: float | str | None = None
    """Largest ``flicker_metric`` a recommended setting may have: a number, or ``"best-preset"`` (the
    lowest of the engine presets within the memory budget)."""
    flicker_metric: str = "flicker"
    """The flicker column the budget applies to (flicker, flicker_same, flip_rate, …)."""


@dataclass(frozen=True)
class Method:
    """One ``[[methods]]`` entry: a name and the ``[shadow]`` fields it changes.

    Attributes
    ----------
    name : str
        As it appears in ``metrics.csv`` and the report.
    overrides : dict
        The shadow fields the entry sets (TOML names).
    settings : ShadowSettings
        The base ``[shadow]`` with ``overrides`` applied.
    """

    name: str
    overrides: dict
    settings: ShadowSettings


@dataclass(frozen=True)
class Variant:
    """One method at one sweep point: the unit that gets its own rows in ``metrics.csv``."""

    method: str
    point: str
    settings: ShadowSettings


@dataclass(frozen=True)
class Experiment:
    """A validated experiment.

    Attributes
    ----------
    name : str
        Names the results (``reports/<name>/``); defaults to the file's stem.
    description : str
    source : str
        The experiment file, absolute.
    extends : tuple of str
        The presets it extends, as written.
    scene : SceneConfig
    camera : CameraConfig
        File fields hold absolute paths.
    light : LightConfig
    shadow : ShadowSettings
        The base settings.
    methods : tuple of Method
        In file order (presets first).
    sweep : tuple of (str, tuple)
        Shadow field and its values, in file order.
    regress : dict
        Metric name to ``{"abs": float, "rel": float}`` tolerances.
    report : ReportConfig
    chunk_frames : int
        Frames per unit of work.
    tune : TuneConfig
        What ``csmlab tune`` searches (the ``[tune]`` table).
    """

    name: str
    description: str
    source: str
    extends: tuple[str, ...]
    scene: SceneConfig
    camera: CameraConfig
    light: LightConfig
    shadow: ShadowSettings
    methods: tuple[Method, ...]
    sweep: tuple[tuple[str, tuple], ...]
    regress: dict
    report: ReportConfig
    chunk_frames: int
    tune: TuneConfig = TuneConfig()

    def points(self) -> list[tuple[str, dict]]:
        """Sweep points ``(label, {field: value})`` (:func:`sweep_points`)."""
        return sweep_points(self.sweep)

    def variants(self) -> list[Variant]:
        """Every method at every sweep point, methods outermost; the sweep's fields win over the method's."""
        return [Variant(method=m.name, point=label, settings=m.settings.replace(**point))
                for m in self.methods for label, point in self.points()]

    def with_frames(self, frames: int) -> "Experiment":
        """The same experiment with the camera's frame cap set to ``frames``."""
        if not isinstance(frames, int) or frames < 1:
            raise InputError(f"expected at least 1 frame, got {frames!r}", field="--frames")
        camera = CameraConfig(**{**_record_fields(self.camera), "frames": frames})
        return Experiment(**{**_record_fields(self), "camera": camera})


_TOP_FIELDS = ("name", "description", "extends", "chunk_frames", "scene", "camera", "light", "shadow", "methods",
               "sweep", "regress", "report", "tune")
_DOCS_TOP = {
    "name": "Names the results folder reports/<name>/; defaults to the file's stem.",
    "description": "One line on what the experiment shows.",
    "chunk_frames": "Frames per unit of work (parallelism, resume); results do not depend on it.",
}


def sweep_points(sweep) -> list[tuple[str, dict]]:
    """The points of a sweep, ``(label, {field: value})``, in order, the last field fastest.

    ``sweep`` is a sequence of ``(field, values)`` pairs or a dict of them; labels read
    ``resolution=512/levels=16``. Without a sweep the one point is ``("base", {})``.
    """
    pairs = list(sweep.items()) if isinstance(sweep, dict) else list(sweep)
    if not pairs:
        return [("base", {})]
    names = [name for name, _ in pairs]
    return [("/".join(f"{n}={repr(v) if isinstance(v, float) else v}" for n, v in zip(names, values)),
             dict(zip(names, values)))
            for values in itertools.product(*(values for _, values in pairs))]


def _record_fields(record) -> dict:
    return {f.name: getattr(record, f.name) for f in fields(record)}


# --- finding files -------------------------------------------------------------------------------


def find_experiment(name_or_path=None) -> Path:
    """The experiment file: a path, or the name of one in ``experiments/``; ``None`` is ``default``.

    Raises
    ------
    InputError
        If there is no such file; the message lists the built-in experiments.
    """
    if name_or_path is None:
        return EXPERIMENTS_DIR / "default.toml"
    path = Path(name_or_path)
    if path.is_file():
        return path.resolve()
    builtin = EXPERIMENTS_DIR / f"{path.name}.toml" if path.suffix == "" else None
    if builtin is not None and builtin.is_file():
        return builtin
    raise InputError(f"expected an experiment file or one of {sorted(list_experiments())}, got no such file",
                     file=name_or_path, field="EXPERIMENT")


def _described(files: dict[str, Path]) -> dict[str, str]:
    out = {}
    for name, path in sorted(files.items()):
        try:
            out[name] = str(_read_toml(path).get("description", ""))
        except InputError as exc:
            out[name] = f"(unreadable: {exc})"
    return out


def list_presets() -> dict[str, str]:
    """Preset name (``methods/exact``) to its description, sorted by name."""
    return _described({p.relative_to(CONFIGS_DIR).with_suffix("").as_posix(): p
                       for p in CONFIGS_DIR.rglob("*.toml")})


def list_experiments() -> dict[str, str]:
    """Built-in experiment name to its description, sorted by name."""
    return _described({p.stem: p for p in EXPERIMENTS_DIR.glob("*.toml")})


def _read_toml(path: Path) -> dict:
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise InputError(f"expected a readable TOML file, got {exc.strerror or exc}", file=path) from None
    except UnicodeDecodeError as exc:
        raise InputError(f"expected UTF-8 text, got {exc.reason}", file=path) from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        where = re.search(r"\(at line (\d+), column (\d+)\)", str(exc))
        message = re.sub(r"\s*\(at line \d+, column \d+\)", "", str(exc))
        line = int(where.group(1)) if where else None
        column = f", column {where.group(2)}" if where else ""
        raise InputError(f"expected valid TOML, got a syntax error{column}: {message}", file=path, line=line) from None


def _preset_path(entry, *, relative_to: Path, origin: Path) -> Path:
    if not isinstance(entry, str) or not entry:
        raise InputError(f"expected a preset name, got {entry!r}", file=origin, line=_line_of(origin, "extends"),
                         field="extends")
    if entry.endswith(".toml"):
        path = (relative_to / entry).resolve()
    else:
        path = CONFIGS_DIR / f"{entry}.toml"
    if path.is_file():
        return path
    known = sorted(list_presets())
    close = difflib.get_close_matches(entry, known, n=1)
    hint = f"did you mean {close[0]!r}? " if close else ""
    raise InputError(f"no preset {entry!r}: {hint}expected one of {known} or a .toml file", file=origin,
                     line=_line_of(origin, "extends"), field="extends")


# --- merging presets ----------------------------------------------------------------------------


def _layers(path: Path, *, chain: tuple[Path, ...] = ()) -> list[tuple[Path, dict]]:
    """``(file, document)`` of every preset ``path`` extends, depth first, then ``path`` itself."""
    if path in chain:
        cycle = " -> ".join(str(p) for p in (*chain, path))
        raise InputError(f"expected presets without a cycle, got {cycle}", file=path, field="extends")
    document = _read_toml(path)
    extends = document.get("extends", [])
    if not isinstance(extends, list):
        raise InputError(f"expected a list of preset names, got {extends!r}", file=path,
                         line=_line_of(path, "extends"), field="extends")
    layers = []
    for entry in extends:
        layers += _layers(_preset_path(entry, relative_to=path.parent, origin=path), chain=(*chain, path))
    return layers + [(path, document)]


def _merge_table(into: dict, layer: dict, origins: dict, *, prefix: str, file: Path) -> None:
    for key, value in layer.items():
        where = f"{prefix}.{key}" if prefix else key
        if isinstance(value, dict) and isinstance(into.get(key), dict):
            _merge_table(into[key], value, origins, prefix=where, file=file)
        else:
            into[key] = copy.deepcopy(value)
            origins[where] = file
            if isinstance(value, dict):
                for sub in _leaves(value, where):
                    origins[sub] = file


def _leaves(table: dict, prefix: str):
    for key, value in table.items():
        yield f"{prefix}.{key}"
        if isinstance(value, dict):
            yield from _leaves(value, f"{prefix}.{key}")


def _merge_methods(into: list, entries, origins: dict, *, file: Path) -> None:
    if not isinstance(entries, list) or not all(isinstance(e, dict) for e in entries):
        raise InputError("expected [[methods]] tables", file=file, line=_line_of(file, "methods"), field="methods")
    seen = set()
    for index, entry in enumerate(entries):
        name = entry.get("name")
        if not isinstance(name, str) or not _METHOD_NAME.match(name):
            raise InputError(f"expected a name of letters, digits and _.+- in [[methods]] entry {index + 1}, got "
                             f"{name!r}", file=file, line=_line_of(file, "methods", index=index), field="methods.name")
        if name in seen:
            raise InputError(f"expected each method name once in a file, got {name!r} twice", file=file,
                             line=_line_of(file, "methods", index=index), field=f"methods.{name}")
        seen.add(name)
        existing = next((m for m in into if m["name"] == name), None)
        if existing is None:
            existing = {"name": name}
            into.append(existing)
        origins[f"methods.{name}"] = file
        for key, value in entry.items():
            existing[key] = copy.deepcopy(value)
            origins[f"methods.{name}.{key}"] = file


def _merged(path: Path) -> tuple[dict, dict]:
    """The merged document of ``path`` and its presets, and the file every value came from."""
    merged: dict = {"methods": []}
    origins: dict = {}
    layers = _layers(path)
    for file, document in layers:
        own = file == path
        for key, value in document.items():
            if key in _NOT_INHERITED and not own:
                continue
            if key == "methods":
                _merge_methods(merged["methods"], value, origins, file=file)
            elif isinstance(value, dict) and isinstance(merged.get(key), dict):
                _merge_table(merged[key], value, origins, prefix=key, file=file)
            else:
                _merge_table(merged, {key: value}, origins, prefix="", file=file)
    return merged, origins


# --- locating a field in its file ----------------------------------------------------------------


def _line_of(file, section: str, key: str | None = None, *, index: int | None = None,
             method: str | None = None) -> int | None:
    """1-based line of ``key`` in ``[section]`` of ``file`` (top level when ``key`` is None and
    ``section`` a top-level key); in ``[[methods]]``, the entry named ``method`` or number ``index``."""
    try:
        lines = Path(file).read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError):
        return None
    blocks: list[tuple[str, int, list[tuple[int, str]]]] = [("", 0, [])]
    for number, text in enumerate(lines, start=1):
        header = re.match(r"^\s*\[\[?\s*([A-Za-z0-9_.\-\" ]+?)\s*\]\]?\s*(#.*)?$", text)
        if header:
            blocks.append((header.group(1).strip().replace('"', ""), number, []))
        else:
            blocks[-1][2].append((number, text))

    def key_line(block_lines, name):
        pattern = re.compile(rf"^\s*[\"']?{re.escape(name)}[\"']?\s*=")
        return next((n for n, t in block_lines if pattern.match(t)), None)

    if key is None:
        top = key_line(blocks[0][2], section)
        if top is not None or section != "methods":
            return top
    candidates = [b for b in blocks if b[0] == section]
    if section == "methods":
        if method is not None:
            candidates = [b for b in candidates
                          if any(re.match(rf"^\s*name\s*=\s*[\"']{re.escape(method)}[\"']", t) for _, t in b[2])]
        elif index is not None:
            candidates = candidates[index:index + 1]
        if key is None:
            return candidates[0][1] if candidates else None
    for _, _, block_lines in candidates:
        found = key_line(block_lines, key)
        if found is not None:
            return found
    return None


class _Located:
    """Raises :class:`InputError` for a dotted field, naming the file it came from and its line."""

    def __init__(self, origins: dict, default: Path):
        self.origins = origins
        self.default = default

    def file_of(self, where: str) -> Path:
        parts = where.split(".")
        for n in range(len(parts), 0, -1):
            found = self.origins.get(".".join(parts[:n]))
            if found is not None:
                return found
        return self.default

    def error(self, where: str, message: str) -> InputError:
        file = self.file_of(where)
        parts = where.split(".")
        if parts[0] == "methods" and len(parts) >= 2:
            line = _line_of(file, "methods", parts[2] if len(parts) > 2 else None, method=parts[1])
        elif len(parts) == 1:
            line = _line_of(file, parts[0])
        else:
            line = _line_of(file, parts[0], parts[1])
        return InputError(message, file=file, line=line, field=where)


# --- typed fields ---------------------------------------------------------------------------------


def _type_name(kind) -> str:
    if kind is bool:
        return "true or false"
    if kind is int:
        return "an integer"
    if kind is float:
        return "a number"
    if kind is str:
        return "a string"
    if kind is dict:
        return "a table"
    origin = typing.get_origin(kind)
    args = typing.get_args(kind)
    if origin is tuple and len(args) == 2 and args[1] is Ellipsis:
        return f"a list of {_type_name(args[0]).removeprefix('a ').removeprefix('an ')}s"
    if origin is tuple:
        return f"a list of {len(args)} numbers"
    if type(None) in args:
        return _type_name(next(a for a in args if a is not type(None)))
    return str(kind)


def _coerce(value, kind):
    """``value`` as ``kind`` (int, float, str, bool, dict, tuples, ``X | None``); raise TypeError if it is not."""
    args = typing.get_args(kind)
    origin = typing.get_origin(kind)
    if type(None) in args:
        return _coerce(value, next(a for a in args if a is not type(None)))
    if kind is bool:
        ok = isinstance(value, bool)
    elif kind is int:
        ok = isinstance(value, int) and not isinstance(value, bool)
    elif kind is float:
        ok = isinstance(value, (int, float)) and not isinstance(value, bool)
        value = float(value) if ok else value
    elif kind in (str, dict):
        ok = isinstance(value, kind)
    elif origin is tuple:
        items = args[:1] * len(value) if len(args) == 2 and args[1] is Ellipsis and isinstance(value, list) else args
        ok = isinstance(value, list) and len(value) == len(items)
        if ok:
            return tuple(_coerce(v, k) for v, k in zip(value, items))
    else:
        raise TypeError(kind)
    if not ok:
        raise TypeError(kind)
    return value


def _typed_value(value, kind, check, *, where: str, located: _Located):
    try:
        out = _coerce(value, kind)
    except TypeError:
        raise located.error(where, f"expected {_type_name(kind)}, got {value!r}") from None
    if check is not None and out is not None:
        predicate, text = check
        values = out if isinstance(out, tuple) else (out,)
        if isinstance(out, float) and not math.isfinite(out) or not all(predicate(v) for v in values):
            raise located.error(where, f"expected {text}, got {value!r}")
    if isinstance(out, tuple) and any(isinstance(v, float) and not math.isfinite(v) for v in out):
        raise located.error(where, f"expected finite numbers, got {value!r}")
    if isinstance(out, float) and not math.isfinite(out):
        raise located.error(where, f"expected a finite number, got {value!r}")
    return out


def _unknown(where: str, key: str, known, located: _Located) -> InputError:
    close = difflib.get_close_matches(key, list(known), n=1)
    hint = f"did you mean {close[0]!r}? " if close else ""
    return located.error(f"{where}.{key}" if where else key,
                         f"unknown field {key!r}: {hint}expected one of {sorted(known)}")


def _record(cls, table, *, where: str, located: _Located, extra=()):
    """An instance of the dataclass ``cls`` from a TOML table; keys in ``extra`` go to its ``params``."""
    if not isinstance(table, dict):
        raise located.error(where, f"expected a table [{where}], got {table!r}")
    hints = typing.get_type_hints(cls)
    own = {f.name: f for f in fields(cls) if f.name != "params"}
    values, params = {}, {}
    for key, value in table.items():
        if key in own:
            values[key] = _typed_value(value, hints[key], own[key].metadata.get("expect"),
                                       where=f"{where}.{key}", located=located)
        elif key in extra:
            params[key] = value
        else:
            raise _unknown(where, key, [*own, *extra], located)
    if params:
        values["params"] = params
    return cls(**values)


def _registry_name(value: str, registry, *, where: str, located: _Located) -> None:
    if value not in registry:
        raise located.error(where, unknown_name_message(value, registry))


def _existing_file(value: str, *, where: str, located: _Located) -> str:
    base = located.file_of(where).parent
    path = (base / value).resolve()
    if not path.is_file():
        raise located.error(where, f"expected an existing file, got {value!r} (looked for {path})")
    if not os.access(path, os.R_OK):
        raise located.error(where, f"expected a readable file, got {value!r} (permission denied: {path})")
    return str(path)


# --- sections ----------------------------------------------------------------------------------------


def _scene(table, located: _Located) -> SceneConfig:
    from csmlab.scene import SCENE_KINDS

    kind = table.get("kind", SceneConfig.kind) if isinstance(table, dict) else None
    if isinstance(kind, str):
        _registry_name(kind, SCENE_KINDS, where="scene.kind", located=located)
    generator = SCENE_KINDS.get(kind) if isinstance(kind, str) and kind != "mesh" else None
    accepted = parameters(generator) if generator is not None else ()
    common = {"kind", "seed", "file", "scale", "up", "ground", "offset"}
    extra = [p for p in accepted if p not in common]
    scene = _record(SceneConfig, table, where="scene", located=located, extra=extra)
    if scene.kind != "mesh":
        for key in ("file", "scale", "up", "ground"):
            if key in table:
                raise located.error(f"scene.{key}",
                                    f"expected {key} only with kind = \"mesh\", got kind = {scene.kind!r}")
        return scene
    if not scene.file:
        raise located.error("scene.file", "expected a mesh file with kind = \"mesh\", got none")
    from csmlab.scene.mesh import UP_AXES

    _registry_name(scene.up, UP_AXES, where="scene.up", located=located)
    return SceneConfig(**{**_record_fields(scene), "file": _existing_file(scene.file, where="scene.file",
                                                                          located=located)})


def _camera(table, located: _Located) -> CameraConfig:
    from csmlab.paths import CONVENTIONS, PATH_FORMATS, PATH_GENERATORS
    from csmlab.paths.formats import ANCHORS
    from csmlab.paths.timing import DUPLICATE_RULES, GAP_RULES

    name = table.get("path") if isinstance(table, dict) else None
    if isinstance(name, str) and name:
        _registry_name(name, PATH_GENERATORS, where="camera.path", located=located)
    generator = PATH_GENERATORS.get(name) if isinstance(name, str) else None
    accepted = parameters(generator) if generator is not None else ()
    common = {f.name for f in fields(CameraConfig)} | {"aspect", "light_direction", "name"}
    extra = [p for p in accepted if p not in common]
    camera = _record(CameraConfig, table, where="camera", located=located, extra=extra)
    if camera.far <= camera.near:
        raise located.error("camera.far", f"expected a distance greater than near ({camera.near}), got {camera.far}")
    file_only = ("format", "convention", "scale", "offset", "time_offset", "start_s", "end_s", "times_file", "anchor",
                 "duplicate_times", "max_gap", "gaps")
    if camera.path and camera.file:
        raise located.error("camera.file", f"expected either path (a generator) or file, got both: path = "
                                           f"{camera.path!r} (from {located.file_of('camera.path')}) and file")
    if not camera.path and not camera.file:
        raise located.error("camera.path",
                            f"expected a path generator {sorted(PATH_GENERATORS)} or a file, got neither")
    if camera.path:
        for key in file_only:
            if key in table:
                raise located.error(f"camera.{key}", f"expected {key} only with a recorded file, got path = "
                                                     f"{camera.path!r}")
        return camera
    if camera.params:
        key = next(iter(camera.params))
        raise _unknown("camera", key, [f.name for f in fields(CameraConfig) if f.name != "params"], located)
    if camera.format:
        _registry_name(camera.format, PATH_FORMATS, where="camera.format", located=located)
    if camera.convention:
        _registry_name(camera.convention, CONVENTIONS, where="camera.convention", located=located)
    for key, choices in (("anchor", ANCHORS), ("duplicate_times", DUPLICATE_RULES), ("gaps", GAP_RULES)):
        _registry_name(getattr(camera, key), choices, where=f"camera.{key}", located=located)
    if camera.start_s is not None and camera.end_s is not None and camera.end_s < camera.start_s:
        raise located.error("camera.end_s",
                            f"expected a time not before start_s ({camera.start_s}), got {camera.end_s}")
    files = {"file": _existing_file(camera.file, where="camera.file", located=located)}
    if camera.times_file:
        files["times_file"] = _existing_file(camera.times_file, where="camera.times_file", located=located)
    return CameraConfig(**{**_record_fields(camera), **files})


def _light(table, located: _Located) -> LightConfig:
    light = _record(LightConfig, table, where="light", located=located)
    angles = [k for k in ("elevation_deg", "azimuth_deg", "elevation_end_deg", "azimuth_end_deg") if k in table]
    if light.direction is not None:
        if angles:
            raise located.error(f"light.{angles[0]}", "expected either direction or elevation/azimuth angles, got both")
        if math.hypot(*light.direction) < 1e-12:
            raise located.error("light.direction", f"expected a non-zero vector from the light toward the scene, "
                                                   f"got {list(light.direction)}")
        return light
    elevation = 40.0 if light.elevation_deg is None else light.elevation_deg
    azimuth = 30.0 if light.azimuth_deg is None else light.azimuth_deg
    return LightConfig(elevation_deg=elevation, azimuth_deg=azimuth, elevation_end_deg=light.elevation_end_deg,
                       azimuth_end_deg=light.azimuth_end_deg)


@functools.cache
def _shadow_types() -> dict:
    """Type of every ShadowSettings field by its TOML name."""
    return {("lambda" if k == "lambda_" else k): v for k, v in typing.get_type_hints(ShadowSettings).items()}


def _shadow_fields(table, *, where: str, located: _Located, allow=("name",)) -> dict:
    """``[shadow]``-field overrides of a table, typed; keys in ``allow`` are skipped."""
    if not isinstance(table, dict):
        raise located.error(where, f"expected a table, got {table!r}")
    types = _shadow_types()
    out = {}
    for key, value in table.items():
        if key in allow:
            continue
        if key not in types:
            raise _unknown(where, key, [*types, *allow], located)
        out[key] = _typed_value(value, types[key], None, where=f"{where}.{key}", located=located)
    return out


def _checked_settings(settings: ShadowSettings, *, where_of, located: _Located) -> ShadowSettings:
    """``settings`` after range and method-name checks; ``where_of(field)`` says where a field was set."""
    from csmlab.cascades import (BOUNDS_METHODS, DEPTH_RANGE_METHODS, EXTENT_METHODS, FIT_METHODS, SNAP_METHODS,
                                 SPLIT_METHODS, STABILIZATION_METHODS)
    from csmlab.lookup_choices import FILTER_METHODS, SELECTION_METHODS
    from csmlab.texels import PRECISION_METHODS

    try:
        settings.validated()
    except ValueError as exc:
        name, _, message = str(exc).partition(": ")
        raise located.error(where_of(name), message) from None
    for name, registry in (("split", SPLIT_METHODS), ("fit", FIT_METHODS), ("stabilization", STABILIZATION_METHODS),
                           ("selection", SELECTION_METHODS), ("filter", FILTER_METHODS),
                           ("extent", EXTENT_METHODS), ("snap", SNAP_METHODS), ("depth_range", DEPTH_RANGE_METHODS),
                           ("bounds", BOUNDS_METHODS), ("engine_precision", PRECISION_METHODS)):
        _registry_name(getattr(settings, name), registry, where=where_of(name), located=located)
    if settings.split == "geometric" and settings.cascades > 1 and settings.first_cascade_far >= settings.shadow_distance:
        raise located.error(where_of("first_cascade_far"), f"expected a distance below shadow_distance "
                                                           f"({settings.shadow_distance} m), got {settings.first_cascade_far}")
    if settings.split == "manual" and len(settings.splits) != settings.cascades:
        raise located.error(where_of("splits"), f"expected {settings.cascades} split distances (one per cascade) with "
                                                f"split = \"manual\", got {len(settings.splits)}")
    return settings


def _methods(entries: list, base: ShadowSettings, located: _Located) -> tuple[Method, ...]:
    if not entries:
        return (Method(name="base", overrides={}, settings=base),)
    out = []
    for entry in entries:
        name = entry["name"]
        overrides = _shadow_fields(entry, where=f"methods.{name}", located=located)
        settings = _checked_settings(
            base.replace(**overrides), located=located,
            where_of=lambda f, o=overrides, n=name: f"methods.{n}.{f}" if f in o else f"shadow.{f}")
        out.append(Method(name=name, overrides=overrides, settings=settings))
    return tuple(out)


def _sweep(table, methods: tuple[Method, ...], located: _Located) -> tuple[tuple[str, tuple], ...]:
    if not isinstance(table, dict):
        raise located.error("sweep", f"expected a table of shadow fields and their values, got {table!r}")
    out = []
    for key, values in table.items():
        if not isinstance(values, list) or not values:
            raise located.error(f"sweep.{key}", f"expected a non-empty list of values, got {values!r}")
        typed = [_shadow_fields({key: v}, where="sweep", located=located, allow=())[key] for v in values]
        if len(set(map(repr, typed))) != len(typed):
            raise located.error(f"sweep.{key}", f"expected distinct values, got {values!r}")
        out.append((key, tuple(typed)))
    for m in methods:
        for values in itertools.product(*(v for _, v in out)):
            point = dict(zip((k for k, _ in out), values))
            _checked_settings(m.settings.replace(**point), located=located,
                              where_of=lambda f, p=point, n=m.name: f"sweep.{f}" if f in p else f"methods.{n}.{f}")
    return tuple(out)


def _regress(table, located: _Located) -> dict:
    from csmlab.metric_registry import METRICS, is_metric_column

    if not isinstance(table, dict):
        raise located.error("regress", f"expected a table of metric tolerances, got {table!r}")
    out = {}
    for metric, tolerance in table.items():
        if not is_metric_column(metric):
            raise _unknown("regress", metric, METRICS, located)
        if not isinstance(tolerance, dict):
            raise located.error(f"regress.{metric}", f"expected {{ abs = …, rel = … }}, got {tolerance!r}")
        entry = {}
        for key, value in tolerance.items():
            if key not in ("abs", "rel"):
                raise _unknown(f"regress.{metric}", key, ("abs", "rel"), located)
            entry[key] = _typed_value(value, float, (lambda x: x >= 0, "a non-negative tolerance"),
                                      where=f"regress.{metric}.{key}", located=located)
        out[metric] = entry
    return out


def _tune(table, methods: tuple[Method, ...], located: _Located) -> TuneConfig:
    """``[tune]``: its options, and every other key a ``[shadow]`` field with choices or a range."""
    from csmlab.metric_registry import metric_columns

    if not isinstance(table, dict):
        raise located.error("tune", f"expected a table of search ranges and options, got {table!r}")
    options = {f.name: f for f in fields(TuneConfig) if f.name != "space"}
    hints = typing.get_type_hints(TuneConfig)
    types = _shadow_types()
    space, values = [], {}
    for key, value in table.items():
        where = f"tune.{key}"
        if key == "memory_budget":
            try:
                values[key] = parse_size(value)
            except ValueError as exc:
                raise located.error(where, str(exc)) from None
        elif key == "max_flicker":
            if isinstance(value, str) and value != "best-preset":
                raise located.error(where, f'expected a non-negative number or "best-preset", got {value!r}')
            values[key] = value if value == "best-preset" else _typed_value(
                value, float, (lambda x: x >= 0, 'a non-negative number or "best-preset"'), where=where,
                located=located)
        elif key in options:
            values[key] = _typed_value(value, hints[key], options[key].metadata.get("expect"), where=where,
                                       located=located)
        elif key in types:
            space.append((key, _tune_spec(value, types[key], where=where, located=located)))
        else:
            raise _unknown("tune", key, [*options, *types], located)
    known = metric_columns(8)
    for key in ("objectives", "flicker_metric"):
        for metric in (values.get(key) or ()) if key == "objectives" else [values.get(key, "flicker")]:
            if metric not in known:
                raise located.error(f"tune.{key}", f"expected metrics.csv columns {sorted(known)}, got {metric!r}")
    names = [m.name for m in methods]
    if values.get("method") and values["method"] not in names:
        raise located.error("tune.method", f"expected one of the experiment's methods {names}, got "
                                           f"{values['method']!r}")
    tuned = next(m for m in methods if m.name == (values.get("method") or names[0]))
    for key, spec in space:
        for value in (spec[1] if spec[0] == "choice" else spec[1:3]):
            _checked_settings(tuned.settings.replace(**{key: value}), located=located,
                              where_of=lambda f, k=key: f"tune.{k}" if f == k else f"methods.{tuned.name}.{f}")
    return TuneConfig(space=tuple(space), **values)


def _tune_spec(value, kind, *, where: str, located: _Located) -> tuple:
    """``("choice", values)`` from a list, ``("range", lo, hi, log, step)`` from ``{ min, max, log, step }``."""
    if isinstance(value, list):
        if not value:
            raise located.error(where, "expected a non-empty list of choices")
        choices = tuple(_typed_value(v, kind, None, where=where, located=located) for v in value)
        if len(set(map(repr, choices))) != len(choices):
            raise located.error(where, f"expected distinct choices, got {value!r}")
        return ("choice", choices)
    if not isinstance(value, dict) or kind not in (int, float):
        what = "a list of choices or { min = …, max = … }" if kind in (int, float) else "a list of choices"
        raise located.error(where, f"expected {what}, got {value!r}")
    for key in value:
        if key not in ("min", "max", "log", "step"):
            raise _unknown(where, key, ("min", "max", "log", "step"), located)
    if "min" not in value or "max" not in value:
        raise located.error(where, f"expected both min and max, got {value!r}")
    lo, hi = (_typed_value(value[k], kind, None, where=f"{where}.{k}", located=located) for k in ("min", "max"))
    log = _typed_value(value.get("log", False), bool, None, where=f"{where}.log", located=located)
    step = (_typed_value(value["step"], kind, (_positive, "a positive step"), where=f"{where}.step", located=located)
            if "step" in value else None)
    if not lo < hi or (log and lo <= 0):
        raise located.error(where, f"expected min < max{' and min > 0 on a log scale' if log else ''}, got "
                                   f"{lo}..{hi}")
    return ("range", lo, hi, log, step)


def load_tolerances(path) -> dict:
    """Regression tolerances from a TOML file: ``metric = { abs = …, rel = … }`` at the top level or
    under ``[regress]``.

    Raises
    ------
    InputError
        Naming the file, the field and what was expected.
    """
    path = Path(path).resolve()
    document = _read_toml(path)
    table = document.get("regress", document) if set(document) <= {"regress"} else document
    origins = {f"regress.{key}": path for key in table}
    return _regress(table, _Located(origins, path))


def load_experiment(path, *, frames: int | None = None) -> Experiment:
    """Read, merge and validate an experiment file.

    Parameters
    ----------
    path : str or Path
        The experiment TOML file.
    frames : int, optional
        Overrides ``camera.frames`` (the ``--frames`` option).

    Returns
    -------
    Experiment

    Raises
    ------
    InputError
        Malformed TOML, an unknown field (with the closest known name), a wrong type or range, an
        unknown scene, path, format or method name, a missing or unreadable file, a zero-length light
        direction: the message names the file, the line where found, the field and what was expected.
    """
    path = Path(path).resolve()
    merged, origins = _merged(path)
    located = _Located(origins, path)
    for key in merged:
        if key not in _TOP_FIELDS:
            raise _unknown("", key, _TOP_FIELDS, located)
    name = merged.get("name", path.stem)
    if not isinstance(name, str) or not _METHOD_NAME.match(name):
        raise located.error("name", f"expected a name of letters, digits and _.+-, got {name!r}")
    description = merged.get("description", "")
    if not isinstance(description, str):
        raise located.error("description", f"expected a string, got {description!r}")
    chunk_frames = _typed_value(merged.get("chunk_frames", 10), int, (lambda x: x >= 1, "at least 1 frame"),
                                where="chunk_frames", located=located)
    scene = _scene(merged.get("scene", {}), located)
    camera = _camera(merged.get("camera", {}), located)
    light = _light(merged.get("light", {}), located)
    base = ShadowSettings().replace(**_shadow_fields(merged.get("shadow", {}), where="shadow", located=located,
                                                     allow=()))
    base = _checked_settings(base, where_of=lambda f: f"shadow.{f}", located=located)
    methods = _methods(merged["methods"], base, located)
    experiment = Experiment(
        name=name,
        description=description,
        source=str(path),
        extends=tuple(merged.get("extends", ())),
        scene=scene,
        camera=camera,
        light=light,
        shadow=base,
        methods=methods,
        sweep=_sweep(merged.get("sweep", {}), methods, located),
        regress=_regress(merged.get("regress", {}), located),
        report=_record(ReportConfig, merged.get("report", {}), where="report", located=located),
        chunk_frames=chunk_frames,
        tune=_tune(merged.get("tune", {}), methods, located),
    )
    return experiment if frames is None else experiment.with_frames(frames)


# --- the resolved document, its hashes, its TOML -----------------------------------------------------


def _settings_document(settings: ShadowSettings) -> dict:
    return {("lambda" if f.name == "lambda_" else f.name): _plain(getattr(settings, f.name)) for f in fields(settings)}


def _plain(value):
    if isinstance(value, tuple):
        return [_plain(v) for v in value]
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    return value


def _section_document(record) -> dict:
    out = {}
    for f in fields(record):
        value = getattr(record, f.name)
        if f.name == "params":
            out.update(_plain(value))
        elif value is not None:
            out[f.name] = _plain(value)
    return out


def experiment_document(experiment: Experiment) -> dict:
    """The resolved experiment as plain data in the TOML file's shape: every field, presets merged.

    ``[shadow]`` holds every base setting; each ``[[methods]]`` entry its name and overrides. File
    fields hold absolute paths. Loading this document as a TOML file gives the same experiment.
    """
    scene = _section_document(experiment.scene)
    if experiment.scene.kind != "mesh":
        for key in ("file", "scale", "up", "ground"):
            scene.pop(key)
    if not any(experiment.scene.offset):
        scene.pop("offset")
    camera = _section_document(experiment.camera)
    drop = ("path",) if experiment.camera.file else ("file", "format", "convention", "scale", "offset", "time_offset",
                                                     "times_file", "anchor", "duplicate_times", "max_gap", "gaps")
    for key in drop:
        camera.pop(key, None)
    document = {
        "name": experiment.name,
        "description": experiment.description,
        "chunk_frames": experiment.chunk_frames,
        "scene": scene,
        "camera": camera,
        "light": _section_document(experiment.light),
        "shadow": _settings_document(experiment.shadow),
        "methods": [{"name": m.name, **_plain(m.overrides)} for m in experiment.methods],
    }
    if experiment.sweep:
        document["sweep"] = {k: list(v) for k, v in experiment.sweep}
    if experiment.regress:
        document["regress"] = _plain(experiment.regress)
    report = _section_document(experiment.report)
    if report:
        document["report"] = report
    return document


def _file_digest(path: str) -> str:
    return "sha256:" + hashlib.sha256(Path(path).read_bytes()).hexdigest()


def _hashed(document: dict) -> str:
    return hashlib.sha256(json.dumps(document, sort_keys=True, separators=(",", ":")).encode()).hexdigest()[:16]


def _content_addressed(section: dict) -> dict:
    """A section with its file fields replaced by the files' content digests (hashes don't depend on where)."""
    return {k: (_file_digest(v) if k in ("file", "times_file") and v else v) for k, v in section.items()}


def config_hash(experiment: Experiment) -> str:
    """16 hex digits of SHA-256 over the resolved document (files by content, name and description left out)."""
    document = experiment_document(experiment)
    for key in ("name", "description", "chunk_frames"):
        document.pop(key)
    for key in ("scene", "camera"):
        document[key] = _content_addressed(document[key])
    return _hashed(document)


def workload_hash(experiment: Experiment, *, frames: int) -> str:
    """16 hex digits of SHA-256 over what the gate compares on: scene, camera, light and frame count.

    Parameters
    ----------
    experiment : Experiment
    frames : int
        Frames actually rendered (a recorded path may hold fewer than ``camera.frames``).
    """
    document = experiment_document(experiment)
    camera = _content_addressed(document["camera"])
    camera.pop("frames")
    return _hashed({"scene": _content_addressed(document["scene"]), "camera": camera, "light": document["light"],
                    "frames": frames})


def field_docs(cls) -> dict[str, str]:
    """The docstring under each field of the dataclass ``cls``, by field name (TOML spelling)."""
    try:
        tree = ast.parse(textwrap.dedent(inspect.getsource(cls)))
    except (OSError, TypeError):
        return {}
    body = tree.body[0].body
    docs = {}
    for node, after in zip(body, body[1:]):
        if (isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name) and isinstance(after, ast.Expr)
                and isinstance(after.value, ast.Constant) and isinstance(after.value.value, str)):
            name = "lambda" if node.target.id == "lambda_" else node.target.id
            docs[name] = " ".join(after.value.value.split())
    return docs


def _toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        if math.isfinite(value):
            return repr(value)
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")
    if isinstance(value, int):
        return str(value)
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, list):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{k} = {_toml_value(v)}" for k, v in value.items()) + " }"
    raise TypeError(f"no TOML form for {value!r}")


def _toml_table(table: dict, docs: dict, *, comments: bool) -> list[str]:
    texts = {key: f"{key} = {_toml_value(value)}" for key, value in table.items()}
    width = min(max((len(t) for t in texts.values()), default=0), 40)
    lines = []
    for key, text in texts.items():
        doc = docs.get(key, "").replace("``", "")
        lines.append(f"{text:<{width}}  # {doc}" if comments and doc else text)
    return lines


def experiment_toml(experiment: Experiment, *, comments: bool = True) -> str:
    """The resolved experiment as a TOML file; with ``comments``, each field's documentation beside it."""
    document = experiment_document(experiment)
    sections = {"scene": field_docs(SceneConfig), "camera": field_docs(CameraConfig),
                "light": field_docs(LightConfig), "shadow": field_docs(ShadowSettings),
                "report": field_docs(ReportConfig)}
    top = {k: v for k, v in document.items() if not isinstance(v, (dict, list))}
    lines = [f"# {experiment.source}", *_toml_table(top, _DOCS_TOP, comments=comments), ""]
    for key in ("scene", "camera", "light", "shadow"):
        lines += [f"[{key}]", *_toml_table(document[key], sections[key], comments=comments), ""]
    for method in document["methods"]:
        lines += ["[[methods]]", *_toml_table(method, sections["shadow"], comments=comments), ""]
    for key in ("sweep", "regress", "report"):
        if key in document:
            lines += [f"[{key}]", *_toml_table(document[key], sections.get(key, {}), comments=comments), ""]
    return "\n".join(lines)


def method_preset_toml(name: str, settings: ShadowSettings, *, description: str, header: str = "") -> str:
    """A method preset (``configs/methods`` form) holding every field of ``settings``, each documented.

    ``header`` becomes comment lines at the top; ``extends = ["that_file.toml"]`` then gives a method
    named ``name`` with exactly these settings.
    """
    lines = [f"# {line}" for line in header.splitlines()]
    lines += [f"description = {_toml_value(description)}", "", "[[methods]]", f"name = {_toml_value(name)}",
              *_toml_table(_settings_document(settings), field_docs(ShadowSettings), comments=True)]
    return "\n".join(lines) + "\n"
