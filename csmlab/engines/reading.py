"""What every importer shares: the engine's defaults, typed values from a file, and the record of each field's origin.

Every importer reads its files through :class:`Entry`, a :class:`csmlab.documents.Value` whose numbers may be
spelled as text (an ini's ``2048``, a ConfigFile's ``0.5``): each read states what it expects at its key and
anything else is an InputError ``FILE[:LINE]: KEY: expected …, got …`` (the CLI's exit 2).

An importer starts from the engine's preset (``configs/engines/<preset>.toml``, read here: the one place
the engine's defaults live), and every value it finds in the engine's files replaces the preset's,
remembering the file and key it came from. Engine settings csmlab has no knob for are recorded as
*unmodelled*, with the value found and why.
"""

from __future__ import annotations

import functools
import math
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from csmlab import documents
from csmlab.documents import Value, read_text
from csmlab.errors import InputError
from csmlab.settings import ShadowSettings

__all__ = ["Entry", "Imported", "Located", "LocatingLoader", "Reading", "attribute_name", "engine_settings",
           "json_document", "located_mapping", "one_line", "read_text", "toml_name", "yaml_document"]


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


def attribute_name(name: str) -> str:
    """The :class:`~csmlab.settings.ShadowSettings` attribute of a TOML field name (``lambda`` is ``lambda_``)."""
    return "lambda_" if name == "lambda" else name


class Entry(Value):
    """A value of an engine's file, read by what it is expected to be (:class:`csmlab.documents.Value`).

    Its members are Entries too. Numbers may be spelled as text, as the engines' text formats write them
    (an ini's ``2048``, a C# ``0.5f``), and an integer may be written as a float without a fraction (``4.0``);
    anything else where a number is expected, a list where a member set is, a string where a list is, is an
    InputError naming the file, the key and what was found.
    """

    __slots__ = ()

    @classmethod
    def of(cls, value: Value) -> Entry:
        """``value`` (a :class:`~csmlab.documents.Value`) as an Entry."""
        return cls(value.raw, file=value.file, key=value.key, line=value.line, what=value.what)

    def _line_of(self, name) -> int | None:
        """The line of key ``name`` of this mapping where the parser kept it (:attr:`Located.key_lines`), else the
        mapping's."""
        lines = getattr(self.raw, "key_lines", None)
        return lines.get(name, self.line) if lines else self.line

    def member(self, name) -> Entry | None:
        """Key ``name`` of this object, null included (a read of it then says so), or None when the key is absent."""
        raw = self.mapping().raw
        if name not in raw:
            return None
        return Entry(raw[name], file=self.file, key=self._child_key(name), line=self._line_of(name))

    def at(self, name: str, what: str | None = None) -> Entry:
        """Key ``name`` of this object; InputError at its line when it is missing or null (``what``: what it holds)."""
        child = self.member(name)
        if child is None:
            return Entry.of(super().at(name, what))  # raises: no key ``name``
        child.what = what
        if child.raw is None:
            raise child.error(what or "a value")
        return child

    def get(self, name) -> Entry | None:
        """Key ``name`` of this object, or None when it is missing or null."""
        child = self.member(name)
        return None if child is None or child.raw is None else child

    def items(self, what: str | None = None) -> list[Entry]:
        """The entries of this list."""
        return [Entry.of(item) for item in super().items(what)]

    def fields(self) -> list[tuple[str, Entry]]:
        """``(key, value)`` of every member of this object, in file order, each at its key's line."""
        return [(name, self.member(name)) for name in self.mapping().raw]

    @property
    def tag(self) -> str:
        """The YAML tag of this mapping (:class:`Located`), ``""`` for an untagged value."""
        return getattr(self.raw, "tag", "")

    def _spelled(self) -> Value:
        """This value, the number it spells when it is the text of one."""
        if not isinstance(self.raw, str):
            return self
        try:
            parsed = float(self.raw.strip().rstrip("fF"))
        except ValueError:
            return self
        return Value(parsed, file=self.file, key=self.key, line=self.line, what=self.what)

    def number(self, *, minimum: float | None = None, maximum: float | None = None, above: float | None = None,
               below: float | None = None, what: str | None = None) -> float:
        """This value as a finite float within the bounds given: a number, or the text of one."""
        return Value.number(self._spelled(), minimum=minimum, maximum=maximum, above=above, below=below, what=what)

    def integer(self, *, minimum: int | None = None, below: int | None = None, what: str | None = None) -> int:
        """This value as an int in ``[minimum, below)``: an integer, a float without a fraction, or the text of one."""
        spelled = self._spelled()
        if isinstance(spelled.raw, float) and math.isfinite(spelled.raw) and spelled.raw == int(spelled.raw):
            spelled = Value(int(spelled.raw), file=self.file, key=self.key, line=self.line, what=self.what)
        return Value.integer(spelled, minimum=minimum, below=below, what=what)

    def choice(self, choices: dict, what: str | None = None):
        """``choices[value]`` for this value, a key of ``choices`` (a word or a number)."""
        raw = self.raw
        if isinstance(raw, (str, int, float)) and not isinstance(raw, bool) and raw in choices:
            return choices[raw]
        raise self.error(what or "one of " + ", ".join(repr(c) for c in choices))


class Located(dict):
    """A parsed mapping that remembers the 1-based line it starts on and, in tagged YAML, its tag (Stride's
    ``!LightComponent`` is ``tag = "LightComponent"``): an :class:`Entry` of it names that line."""

    line: int | None = None
    tag: str = ""
    key_lines: dict | None = None
    """The 1-based line of each key, where the parser knows it."""


def located_mapping(node: yaml.MappingNode, items=()) -> Located:
    """A :class:`Located` of YAML mapping ``node``'s line and its keys' lines (a key's ``*`` override mark dropped)."""
    mapping = Located(items)
    mapping.line = node.start_mark.line + 1
    mapping.key_lines = {}
    for key, _ in node.value:
        if isinstance(key, yaml.ScalarNode):
            mapping.key_lines[key.value] = mapping.key_lines[key.value.rstrip("*")] = key.start_mark.line + 1
    return mapping


class LocatingLoader(yaml.SafeLoader):
    """PyYAML's safe loader whose mappings are :class:`Located` at their lines."""

    def construct_located(self, node):
        mapping = located_mapping(node)
        yield mapping
        mapping.update(self.construct_mapping(node))


LocatingLoader.add_constructor("tag:yaml.org,2002:map", LocatingLoader.construct_located)


def yaml_document(text: str, *, file, loader=LocatingLoader, what: str = "YAML", every: bool = False):
    """The YAML document ``text`` of ``file`` (with ``every``, the list of its documents) read by ``loader``.

    Raises
    ------
    InputError
        YAML that does not parse, or a value PyYAML cannot build (a date that is no date, nesting
        deeper than Python recurses), named with the file and, where PyYAML knows it, the line.
    """
    try:
        return list(yaml.load_all(text, Loader=loader)) if every else yaml.load(text, Loader=loader)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        raise InputError(f"expected {what}, got {getattr(exc, 'problem', None) or exc}", file=file,
                         line=None if mark is None else mark.line + 1) from None
    except (ValueError, TypeError, RecursionError) as exc:  # a timestamp out of range, nesting past the stack
        raise InputError(f"expected {what}, got {type(exc).__name__}: {str(exc)[:80]}", file=file) from None


def json_document(path) -> Entry:
    """The JSON document in file ``path`` as an :class:`Entry`, every object with its line
    (:func:`csmlab.documents.json_document`: nesting deeper than ``MAX_JSON_DEPTH`` refused)."""
    return Entry.of(documents.json_document(path, lines=True))


_SHOWN = 200
"""Characters of a file's value an origin or an unmodelled line shows before it is cut."""


def one_line(text: str) -> str:
    """``text`` as one line of a TOML comment: control characters (a line break in a file's string) escaped, cut to
    :data:`_SHOWN` characters."""
    text = "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)
    return text if len(text) <= _SHOWN else text[:_SHOWN] + "…"


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
        self.origins[attribute] = one_line(f"{Path(file).name}: {key} = {shown}")

    def lack(self, *, file, key: str, value, why: str) -> None:
        """Record that ``key = value`` of ``file`` has no csmlab knob, and ``why``."""
        self.unmodelled.append(one_line(f"{Path(file).name}: {key} = {value}") + f" ({why})")

    def result(self) -> Imported:
        return Imported(self.engine, self.preset, self.base.replace(**self.values), dict(self.origins),
                        tuple(self.unmodelled))
