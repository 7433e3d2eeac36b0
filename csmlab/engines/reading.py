"""What every importer shares: the engine's defaults, typed values from a file, and the record of each field's origin.

An importer starts from the engine's preset (``configs/engines/<preset>.toml``, read here: the one place
the engine's defaults live), and every value it finds in the engine's files replaces the preset's,
remembering the file and key it came from. Engine settings csmlab has no knob for are recorded as
*unmodelled*, with the value found and why.
"""

from __future__ import annotations

import functools
import json
import math
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from csmlab.errors import InputError
from csmlab.settings import ShadowSettings

__all__ = ["Imported", "Reading", "engine_settings", "json_document", "number", "read_text", "toml_name"]


@functools.cache
def engine_settings(preset: str) -> ShadowSettings:
    """The settings of ``configs/engines/<preset>.toml`` as an experiment that ``extends`` it resolves them.

    The engines' defaults are read from their presets, never repeated: a value an engine's file does
    not set is the preset's.
    """
    from csmlab.config import load_experiment

    with tempfile.TemporaryDirectory() as folder:
        probe = Path(folder) / "engine_defaults.toml"
        probe.write_text(f'extends = ["engines/{preset}"]\n[camera]\npath = "walk"\n', encoding="utf-8")
        return load_experiment(probe).methods[0].settings


def toml_name(attribute: str) -> str:
    """The TOML spelling of a :class:`~csmlab.settings.ShadowSettings` attribute (``lambda_`` is ``lambda``)."""
    return "lambda" if attribute == "lambda_" else attribute


def read_text(path) -> str:
    """The UTF-8 text of ``path``; InputError naming the file when it cannot be read."""
    try:
        return Path(path).read_text(encoding="utf-8-sig")
    except OSError as exc:
        raise InputError(f"expected a readable file, got {exc.strerror or exc}", file=path) from None
    except UnicodeDecodeError as exc:
        raise InputError(f"expected UTF-8 text, got {exc.reason}", file=path) from None


def json_document(path):
    """The JSON value of ``path``; InputError naming the file (and the line) when it cannot be read or parsed."""
    try:
        return json.loads(read_text(path))
    except json.JSONDecodeError as exc:
        raise InputError(f"expected JSON, got {exc.msg}", file=path, line=exc.lineno) from None


def number(value, *, file, key: str, integer: bool = False, minimum: float | None = None,
           above: float | None = None) -> float | int:
    """``value`` (a number or its text) as a float or an int, checked; InputError naming ``file`` and ``key``."""
    kind = "an integer" if integer else "a number"
    bounds = (f" of at least {minimum:g}" if minimum is not None else "") + (f" above {above:g}" if above is not None
                                                                              else "")
    try:
        if isinstance(value, bool):
            raise ValueError
        parsed = float(value.strip().rstrip("fF")) if isinstance(value, str) else float(value)
    except (TypeError, ValueError):
        raise InputError(f"expected {kind}{bounds}, got {value!r}", file=file, field=key) from None
    if (not math.isfinite(parsed) or (integer and parsed != int(parsed)) or (minimum is not None and parsed < minimum)
            or (above is not None and parsed <= above)):
        raise InputError(f"expected {kind}{bounds}, got {value!r}", file=file, field=key)
    return int(parsed) if integer else parsed


@dataclass(frozen=True)
class Imported:
    """An engine's shadow settings as csmlab settings.

    Attributes
    ----------
    engine : str
        A key of :data:`csmlab.engines.IMPORT_METHODS`.
    preset : str
        The engine preset the defaults came from (``configs/engines/<preset>.toml``).
    settings : ShadowSettings
        The preset's settings with every value found in the files.
    origins : dict
        ``{attribute: "file: key = value"}`` for every field a file set.
    unmodelled : tuple of str
        Engine settings found that csmlab has no knob for, each with its file, key, value and why.
    """

    engine: str
    preset: str
    settings: ShadowSettings
    origins: dict
    unmodelled: tuple[str, ...]


@dataclass
class Reading:
    """The settings being read: the preset's, the values found so far, their origins and the unmodelled ones."""

    engine: str
    preset: str
    values: dict = field(default_factory=dict)
    origins: dict = field(default_factory=dict)
    unmodelled: list = field(default_factory=list)
    pending: dict = field(default_factory=dict)
    """Values that need another file's before they become fields (Godot's atlas size needs the split count)."""

    @property
    def base(self) -> ShadowSettings:
        return engine_settings(self.preset)

    def set(self, attribute: str, value, *, file, key: str, raw=None) -> None:
        """Set ``attribute`` to ``value``, read from ``key`` of ``file`` (``raw``: the value as the file spells it)."""
        self.values[attribute] = value
        shown = value if raw is None else raw
        self.origins[attribute] = f"{Path(file).name}: {key} = {shown}"

    def lack(self, *, file, key: str, value, why: str) -> None:
        """Record that ``key = value`` of ``file`` has no csmlab knob, and ``why``."""
        self.unmodelled.append(f"{Path(file).name}: {key} = {value} ({why})")

    def result(self) -> Imported:
        return Imported(self.engine, self.preset, self.base.replace(**self.values), dict(self.origins),
                        tuple(self.unmodelled))
