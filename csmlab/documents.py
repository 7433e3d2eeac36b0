"""Parsed documents read through one typed accessor, and the limits of what a file may ask for.

Every reader of a structured file (glTF, nerfstudio, csmlab's JSON paths, and later the engines'
files) parses it with :func:`json_document` (or its text form :func:`json_value`) and reads it
through :class:`Value`: each read states what it expects at its key — an object, a list, a number
in a range, an index into a list, one of some words — and anything else stops with an
:class:`~csmlab.errors.InputError` ``FILE[:LINE]: KEY: expected …, got …`` (the CLI's exit 2).
No reader indexes a parsed document without it, so a list where the format has an object, a string
where it has a number or a ``null`` anywhere is a located message, never an ``AttributeError``,
``TypeError`` or ``KeyError``.

The limits a file may ask for (docs/design.md, "Inputs") live here too, beside the loaders that
enforce the first of them: :data:`MAX_JSON_DEPTH` (nesting), :data:`MAX_IMAGE_TEXELS` (an image's
width × height), :data:`MAX_TRIANGLES` (a scene's triangles, instances counted),
:data:`MAX_COORDINATE` (how far a vertex may lie) and :data:`MAX_FRAMES` (the poses a path may
produce). Each is far above what a real level, texture
or path needs and far below what a machine cannot hold.
"""

from __future__ import annotations

import bisect
import json
import math
import re
from json.decoder import JSONObject
from json.scanner import py_make_scanner
from pathlib import Path

import numpy as np

from csmlab.errors import InputError

__all__ = ["MAX_COORDINATE", "MAX_FRAMES", "MAX_IMAGE_TEXELS", "MAX_JSON_DEPTH", "MAX_TRIANGLES", "Value",
           "described", "found_at", "is_file", "json_document", "json_value", "read_text", "within_limit"]

MAX_JSON_DEPTH = 64
"""Deepest nesting of JSON objects and lists a document may have (glTF needs 7, nerfstudio 4)."""
MAX_IMAGE_TEXELS = 8192 * 8192
"""Most texels (width × height) an image may claim: an 8K texture, below Pillow's own bomb warning (89 Mtexels)."""
MAX_TRIANGLES = 20_000_000
"""Most triangles a scene may hold, every instance counted (about 2 GB of float64 corners and indices)."""
MAX_COORDINATE = 1e12
"""Farthest a mesh vertex may lie from the origin, in metres after ``scale`` (ten times the Sun's distance):
beyond, normals and bounds overflow float64 arithmetic, long before float32 rendering means anything."""
MAX_FRAMES = 10_000_000
"""Most poses a camera-path file may hold, or its span give at the path's fps (about 46 hours at 60 Hz)."""

_STRING = re.compile(r'"(?:[^"\\]|\\.)*"', re.DOTALL)
_SHOWN = 60
"""Characters of a value's text shown after "got" before it is cut."""


def described(value) -> str:
    """``value`` as an error message shows it: its JSON type and, cut to a few words, its text."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, dict):
        kind = f"an object with keys {list(value)[:6]!r}"[:_SHOWN]
        return kind if value else "an empty object"
    if isinstance(value, list):
        return f"a list of {len(value)} item(s)"
    text = repr(value)
    if len(text) > _SHOWN:
        text = text[:_SHOWN] + "…"
    return f"the string {text}" if isinstance(value, str) else text


def within_limit(count: int, limit: int, *, what: str, file, field: str | None = None, line: int | None = None) -> int:
    """``count`` when it is at most ``limit``; InputError naming ``file`` and ``field`` (``what`` counted) otherwise."""
    if count > limit:
        raise InputError(f"expected at most {limit:,} {what} (docs/design.md, \"Inputs\"), got {count:,}", file=file,
                         field=field, line=line)
    return count


class _Located(dict):
    """A JSON object that remembers the 1-based line of its opening brace."""

    line: int


class Value:
    """One value of a parsed document, with the file and the key it sits at, read by what it is expected to be.

    Parameters
    ----------
    value : object
        The parsed value (``dict``, ``list``, ``str``, ``int``, ``float``, ``bool`` or ``None``).
    file : str or Path
        The document's file, for error messages.
    key : str
        Where the value is: ``""`` for the document, ``nodes[2].rotation`` below it.
    line : int, optional
        The 1-based line of the value (or of the object holding it) when the document was read
        with lines (:func:`json_document` with ``lines=True``).
    what : str, optional
        What the key holds, as :meth:`at` stated it: the default "expected …" of the reads below.
    """

    __slots__ = ("file", "key", "line", "raw", "what")

    def __init__(self, value, *, file, key: str = "", line: int | None = None, what: str | None = None):
        self.raw = value
        self.file = file
        self.key = key
        self.line = getattr(value, "line", line)
        self.what = what

    def __repr__(self) -> str:
        return f"Value({self.file}: {self.key or '<document>'} = {described(self.raw)})"

    def error(self, expected: str, *, got: bool = True) -> InputError:
        """An InputError at this value: ``expected {expected}`` and, with ``got``, what was found."""
        detail = f"expected {expected}, got {described(self.raw)}" if got else f"expected {expected}"
        return InputError(detail, file=self.file, line=self.line, field=self.key or None)

    # -- containers ------------------------------------------------------------------------------

    def _child_key(self, name) -> str:
        if isinstance(name, int):
            return f"{self.key}[{name}]"
        return f"{self.key}.{name}" if self.key else str(name)

    def is_object(self) -> bool:
        return isinstance(self.raw, dict)

    def mapping(self, what: str | None = None) -> Value:
        """This value, checked to be a JSON object."""
        if not isinstance(self.raw, dict):
            raise self.error(what or self.what or "an object")
        return self

    def keys(self) -> list[str]:
        """The keys of this object, in file order."""
        return list(self.mapping().raw)

    def has(self, name: str) -> bool:
        """Whether this object has ``name`` with a value other than null."""
        return self.mapping().raw.get(name) is not None

    def at(self, name: str, what: str | None = None) -> Value:
        """Key ``name`` of this object; InputError when it is missing or null (``what``: what it should hold)."""
        raw = self.mapping().raw
        child = Value(raw.get(name), file=self.file, key=self._child_key(name), line=self.line, what=what)
        if child.raw is None:
            what = what or "a value"
            raise child.error(f"{what}, got no key {name!r}", got=False) if name not in raw else child.error(what)
        return child

    def get(self, name: str) -> Value | None:
        """Key ``name`` of this object, or None when it is missing or null."""
        raw = self.mapping().raw.get(name)
        return None if raw is None else Value(raw, file=self.file, key=self._child_key(name), line=self.line)

    def items(self, what: str | None = None) -> list[Value]:
        """The entries of this list."""
        if not isinstance(self.raw, list):
            raise self.error(what or self.what or "a list")
        return [Value(item, file=self.file, key=self._child_key(i), line=self.line) for i, item in enumerate(self.raw)]

    def fields(self) -> list[tuple[str, Value]]:
        """``(key, value)`` of every member of this object, in file order."""
        return [(name, Value(raw, file=self.file, key=self._child_key(name), line=self.line))
                for name, raw in self.mapping().raw.items()]

    def list_at(self, name: str, what: str = "a list") -> list[Value]:
        """The entries of list ``name`` of this object; ``[]`` when the key is missing or null."""
        child = self.get(name)
        return [] if child is None else child.items(what)

    # -- scalars ---------------------------------------------------------------------------------

    def number(self, *, minimum: float | None = None, maximum: float | None = None, above: float | None = None,
               below: float | None = None, what: str | None = None) -> float:
        """This value as a finite float within the bounds given (a JSON number; not a boolean, not a string)."""
        raw = self.raw
        bounds = [f"≥ {minimum:g}" if minimum is not None else "", f"≤ {maximum:g}" if maximum is not None else "",
                  f"> {above:g}" if above is not None else "", f"< {below:g}" if below is not None else ""]
        expected = what or self.what or " ".join(["a finite number"] + [b for b in bounds if b])
        if isinstance(raw, bool) or not isinstance(raw, (int, float)):
            raise self.error(expected)
        try:
            value = float(raw)
        except OverflowError:
            raise self.error(expected) from None
        if (not math.isfinite(value) or (minimum is not None and value < minimum)
                or (maximum is not None and value > maximum) or (above is not None and value <= above)
                or (below is not None and value >= below)):
            raise self.error(expected)
        return value

    def integer(self, *, minimum: int | None = None, below: int | None = None, what: str | None = None) -> int:
        """This value as an int in ``[minimum, below)`` (a JSON integer; ``2.0`` and ``true`` are not)."""
        raw = self.raw
        what = what or self.what
        if what is None:
            what = "an integer" + (f" ≥ {minimum}" if minimum is not None else "") + (
                f" < {below}" if below is not None else "")
        if isinstance(raw, bool) or not isinstance(raw, int) or (minimum is not None and raw < minimum) or (
                below is not None and raw >= below):
            raise self.error(what)
        return raw

    def index(self, count: int, what: str) -> int:
        """This value as an index into a list of ``count`` (``what``: the list's name, ``accessors``)."""
        return self.integer(minimum=0, below=count, what=f"an index into {what} in [0, {count})")

    def text(self, choices=None, what: str | None = None) -> str:
        """This value as a string (one of ``choices`` when given)."""
        expected = what or ("one of " + ", ".join(repr(c) for c in choices) if choices is not None
                            else self.what or "a string")
        if not isinstance(self.raw, str) or (choices is not None and self.raw not in choices):
            raise self.error(expected)
        return self.raw

    def boolean(self) -> bool:
        """This value as true or false."""
        if not isinstance(self.raw, bool):
            raise self.error("true or false")
        return self.raw

    def numbers(self, count: int | None = None, what: str | None = None) -> np.ndarray:
        """This value as a list of finite numbers, float64 ``(count,)`` (any length when ``count`` is None)."""
        raw = self.raw
        expected = what or self.what or (f"a list of {count} finite numbers" if count is not None
                                         else "a list of finite numbers")
        if not isinstance(raw, list) or (count is not None and len(raw) != count) or any(
                isinstance(v, bool) or not isinstance(v, (int, float)) for v in raw):
            raise self.error(expected)
        try:
            values = np.array(raw, dtype=np.float64)
        except OverflowError:
            raise self.error(expected) from None
        if not np.all(np.isfinite(values)):
            raise self.error(expected)
        return values


def is_file(path) -> bool:
    """Whether ``path`` names a regular file; False, not an exception, for a name no file can have.

    A document may name any file (an MTL's ``map_d``, a glTF ``uri``): a name too long for the file
    system or holding a NUL byte is a file that is not there.
    """
    try:
        return Path(path).is_file()
    except (OSError, ValueError):
        return False


def found_at(path) -> str:
    """What is at ``path``, as an error message says it: ``a directory``, ``a file`` or ``nothing``."""
    try:
        return "a directory" if Path(path).is_dir() else "a file" if Path(path).is_file() else "nothing"
    except (OSError, ValueError):
        return "nothing (a name no file can have)"


def read_text(path) -> str:
    """The UTF-8 text of ``path`` (a byte-order mark dropped); InputError naming the file when it cannot be read."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise InputError(f"expected a readable file, got {exc.strerror or exc}", file=path) from None
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InputError(f"expected UTF-8 text, got {exc.reason}", file=path,
                         line=data[:exc.start].count(b"\n") + 1) from None


def _depth_check(text: str, *, file) -> None:
    """Refuse ``text`` whose objects and lists nest deeper than :data:`MAX_JSON_DEPTH` (outside strings)."""
    if text.count("[") + text.count("{") <= MAX_JSON_DEPTH:
        return
    bare = np.frombuffer(_STRING.sub(lambda m: " " * len(m.group().encode("utf-8")), text).encode("utf-8"),
                         dtype=np.uint8)
    step = (np.isin(bare, (ord("["), ord("{"))).astype(np.int32)
            - np.isin(bare, (ord("]"), ord("}"))).astype(np.int32))
    depth = np.cumsum(step)
    if depth.size and depth.max() > MAX_JSON_DEPTH:
        at = int(np.argmax(depth > MAX_JSON_DEPTH))
        raise InputError(f"expected JSON nested at most {MAX_JSON_DEPTH} deep (docs/design.md, \"Inputs\"), got "
                         f"{int(depth.max())} levels", file=file, line=int(np.count_nonzero(bare[:at] == 10)) + 1)


def json_value(text: str, *, file, lines: bool = False) -> Value:
    """The JSON document ``text`` (of ``file``) as a :class:`Value`; InputError naming the file and line otherwise.

    With ``lines``, every object remembers the line of its ``{`` and errors below it name that
    line. Nesting deeper than :data:`MAX_JSON_DEPTH` is refused before parsing (Python's parser
    would recurse into it). ``NaN`` and ``Infinity`` parse; :meth:`Value.number` refuses them.
    """
    _depth_check(text, file=file)
    decoder = json.JSONDecoder()
    if lines:
        starts = [0] + [match.end() for match in re.finditer("\n", text)]

        def parse_object(s_and_end, *args):
            obj, end = JSONObject(s_and_end, *args)
            located = _Located(obj)
            located.line = bisect.bisect_right(starts, s_and_end[1] - 1)
            return located, end

        decoder.parse_object = parse_object
        decoder.scan_once = py_make_scanner(decoder)
    try:
        document = decoder.decode(text)
    except json.JSONDecodeError as exc:
        raise InputError(f"expected JSON, got {exc.msg}", file=file, line=exc.lineno) from None
    except (ValueError, RecursionError) as exc:  # an integer of more digits than Python converts
        raise InputError(f"expected JSON, got {exc}", file=file) from None
    return Value(document, file=file, line=1 if lines else None)


def json_document(path, *, lines: bool = False) -> Value:
    """The JSON document in file ``path`` as a :class:`Value` (see :func:`json_value`)."""
    return json_value(read_text(path), file=path, lines=lines)
