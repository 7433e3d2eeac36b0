"""Finding experiment and preset files, reading TOML, and merging ``extends`` presets.

``extends = ["methods/exact", "scenes/terrain", …]`` merges presets from ``configs/`` (or ``.toml``
files relative to the extending file) before the file's own tables: tables merge key by key, later
wins, the experiment last; ``[[methods]]`` merge by ``name``. Presets are read afresh for every load,
never changed in place. ``name``, ``description`` and ``extends`` are never inherited. The merge
records the file every value came from, for messages (:mod:`csmlab.config.locate`).
"""

from __future__ import annotations

import copy
import difflib
import re
import sys
from pathlib import Path

import csmlab
from csmlab.config.locate import _line_of
from csmlab.errors import InputError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib


PROJECT_DIR = Path(csmlab.__file__).resolve().parents[1]
CONFIGS_DIR = PROJECT_DIR / "configs"
"""Presets, by name relative to this folder without ``.toml`` (``methods/exact``)."""
EXPERIMENTS_DIR = PROJECT_DIR / "experiments"
"""The experiments that come with csmlab (``csmlab run`` runs ``default.toml``)."""

_NOT_INHERITED = ("name", "description", "extends")
_METHOD_NAME = re.compile(r"^[A-Za-z0-9_.+-]+$")


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


def _merged(path: Path, *, then_extends: tuple[Path, ...] = ()) -> tuple[dict, dict]:
    """The merged document of ``path`` and its presets, and the file every value came from.

    ``then_extends``: preset files merged after ``path`` (each with its own presets first), in memory as a
    file extending ``[path, *then_extends]`` would merge them; ``path`` keeps its own name and description.
    """
    merged: dict = {"methods": []}
    origins: dict = {}
    layers = _layers(path) + [layer for preset in then_extends for layer in _layers(Path(preset).resolve())]
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
