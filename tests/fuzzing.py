"""Property-based fuzzing of file readers: every variant of a good file loads or is refused naming a file.

A reader is fuzzed from a good file (a shipped fixture, or one the project's writers make from
one) by :func:`fuzz_reader`: Hypothesis draws variants of it — each value replaced by each other
JSON type (:data:`REPLACEMENTS`: list, object, string, number, null, NaN, infinity, huge), keys
deleted, values nested one level deeper, the text truncated or re-encoded, tokens of a text file
replaced, bytes of a binary file flipped — writes each beside the good file's companions (buffers,
materials, images) and reads it. The property: the reader returns, or raises
:class:`~csmlab.errors.InputError` naming a file of the variant's folder; any other exception fails
the test with the variant that raised it (Hypothesis shrinks it first), and so does a NumPy
``RuntimeWarning`` (an overflow the reader did not check for prints beside its exit 2).

The runs are seeded (``derandomize=True``: the same variants on every machine, no example
database) and bounded (``max_examples``), so a reader costs a second or two. ``CSMLAB_FUZZ_SEED=N``
draws other variants, from seed ``N``, for a deeper search by hand. Fuzzing another reader
takes a few lines::

    counts = fuzz_reader(read_settings, {"sun.scn.ron": good}, "sun.scn.ron", text_variants(good), examples=40)
"""

from __future__ import annotations

import copy
import json
import os
import struct
import tempfile
import warnings
from collections import Counter
from pathlib import Path

from hypothesis import HealthCheck, given, settings
from hypothesis import seed as hypothesis_seed
from hypothesis import strategies as st

from csmlab.errors import InputError

__all__ = ["REPLACEMENTS", "TEXT_REPLACEMENTS", "byte_variants", "fuzz_reader", "glb_parts", "glb_variants",
           "json_variants", "paths_of", "text_variants"]

REPLACEMENTS = ([], [0, 1], {}, {"k": 1}, "", "x", "1.5", 0, -1, 7, 0.5, -1e-9, None, True, float("nan"),
                float("inf"), -float("inf"), 1e308, 10 ** 40, -(10 ** 40), [[[[[]]]]], "é" * 300)
"""What a value of a JSON document is replaced by: each JSON type, the non-finite numbers, huge ones."""
TEXT_REPLACEMENTS = ("", "x", "nan", "inf", "-inf", "1e999", "-0", "0", "-1", "1e-320", "9" * 400, "1,2", "[]",
                     "{}", "null", "\x00", "é", "0x10", "1_000", "--1", "\t")
"""What a token of a text file (a number of an OBJ ``v`` line, a TUM column) is replaced by."""
_ENCODINGS = ("utf-16", "latin-1", "utf-8-sig", "crlf")


def paths_of(value, prefix: tuple = ()) -> list[tuple]:
    """Every key path of a JSON value, the value itself first (``()``), depth first."""
    found = [prefix]
    if isinstance(value, dict):
        for key, item in value.items():
            found += paths_of(item, prefix + (key,))
    elif isinstance(value, list):
        for index, item in enumerate(value):
            found += paths_of(item, prefix + (index,))
    return found


def _replaced(document, path: tuple, new):
    """A deep copy of ``document`` with the value at ``path`` replaced by ``new`` (``...`` deletes it)."""
    if not path:
        return copy.deepcopy(new)
    out = copy.deepcopy(document)
    holder = out
    for key in path[:-1]:
        holder = holder[key]
    if new is ...:
        del holder[path[-1]]
    else:
        holder[path[-1]] = copy.deepcopy(new)
    return out


def _value_at(document, path: tuple):
    for key in path:
        document = document[key]
    return document


def _encoded(text: str, encoding: str) -> bytes:
    if encoding == "crlf":
        return text.replace("\n", "\r\n").encode("utf-8")
    return text.encode(encoding, errors="replace")


@st.composite
def json_variants(draw, document, *, encode=lambda text: text.encode("utf-8")) -> bytes:
    """A variant of the JSON ``document`` as bytes (``encode`` turns the text into the file: plain, or a GLB)."""
    paths = paths_of(document)
    kind = draw(st.sampled_from(("replace", "replace", "replace", "delete", "nest", "truncate", "reencode")))
    if kind == "truncate":
        text = json.dumps(document)
        return encode(text[:draw(st.integers(0, max(len(text) - 1, 0)))])
    if kind == "reencode":
        return _encoded(json.dumps(document, indent=draw(st.sampled_from((None, 1, "\t")))),
                        draw(st.sampled_from(_ENCODINGS)))
    path = draw(st.sampled_from(paths))
    if kind == "delete" and path:
        variant = _replaced(document, path, ...)
    elif kind == "nest":
        inner = _value_at(document, path)
        variant = _replaced(document, path, draw(st.sampled_from(([inner], {"value": inner}))))
    else:
        variant = _replaced(document, path, draw(st.sampled_from(REPLACEMENTS)))
    return encode(json.dumps(variant, allow_nan=True))


@st.composite
def text_variants(draw, text: str) -> bytes:
    """A variant of a line-based text file: a token replaced, a line deleted or repeated, truncated, re-encoded."""
    lines = text.splitlines()
    kind = draw(st.sampled_from(("token", "token", "token", "delete", "repeat", "truncate", "reencode", "garbage")))
    if kind == "truncate":
        return text[:draw(st.integers(0, max(len(text) - 1, 0)))].encode("utf-8")
    if kind == "reencode":
        return _encoded(text, draw(st.sampled_from(_ENCODINGS)))
    if not lines:
        return draw(st.binary(max_size=64))
    at = draw(st.integers(0, len(lines) - 1))
    if kind == "delete":
        lines = lines[:at] + lines[at + 1:]
    elif kind == "repeat":
        lines = lines[:at + 1] + [lines[at]] * draw(st.integers(1, 3)) + lines[at + 1:]
    elif kind == "garbage":
        return "\n".join(lines[:at]).encode("utf-8") + draw(st.binary(min_size=1, max_size=64)) + "\n".join(
            lines[at:]).encode("utf-8")
    else:
        separator = "," if "," in lines[at] else " "
        tokens = lines[at].split(separator)
        k = draw(st.integers(0, len(tokens) - 1))
        tokens[k] = draw(st.sampled_from(TEXT_REPLACEMENTS))
        lines[at] = separator.join(tokens)
    return ("\n".join(lines) + "\n").encode("utf-8")


@st.composite
def byte_variants(draw, data: bytes) -> bytes:
    """A variant of a binary file: truncated, a byte flipped, a 32-bit field made huge, bytes inserted."""
    kind = draw(st.sampled_from(("truncate", "flip", "huge", "insert")))
    at = draw(st.integers(0, max(len(data) - 1, 0)))
    if kind == "truncate":
        return data[:at]
    if kind == "flip":
        return data[:at] + bytes([data[at] ^ draw(st.integers(1, 255))]) + data[at + 1:] if data else b"\xff"
    if kind == "huge":
        return data[:at] + struct.pack("<I", draw(st.sampled_from((0, 0x7FFFFFFF, 0xFFFFFFFF, 30000)))) + data[at + 4:]
    return data[:at] + draw(st.binary(min_size=1, max_size=16)) + data[at:]


def glb_parts(data: bytes) -> tuple[dict, bytes]:
    """The JSON document and the binary chunk of a well-formed GLB file."""
    json_length = struct.unpack_from("<I", data, 12)[0]
    document = json.loads(data[20:20 + json_length].decode("utf-8"))
    rest = data[20 + json_length:]
    return document, rest[8:8 + struct.unpack_from("<I", rest)[0]] if len(rest) >= 8 else b""


def _glb(text: str, blob: bytes) -> bytes:
    """A GLB container of the JSON ``text`` and the binary chunk ``blob`` (§4.4), padded to 4 bytes."""
    body = text.encode("utf-8")
    body += b" " * (-len(body) % 4)
    blob += b"\0" * (-len(blob) % 4)
    chunks = struct.pack("<II", len(body), 0x4E4F534A) + body + struct.pack("<II", len(blob), 0x004E4942) + blob
    return b"glTF" + struct.pack("<II", 2, 12 + len(chunks)) + chunks


def glb_variants(data: bytes):
    """Variants of a GLB file: its JSON chunk's (:func:`json_variants`, repacked with the same binary chunk), or
    its bytes' (:func:`byte_variants`)."""
    document, blob = glb_parts(data)
    return st.one_of(json_variants(document, encode=lambda text: _glb(text, blob)), byte_variants(data))


def _refusal_names_a_file(error: InputError, folder: Path) -> bool:
    """Whether ``error`` names a file of ``folder`` (a name a variant made up, NUL bytes and all, counts)."""
    return error.file is not None and os.path.dirname(os.path.normpath(error.file)) == os.path.normpath(folder)


def fuzz_reader(read, files: dict[str, bytes], target: str, variants, *, examples: int = 40) -> Counter:
    """Read ``examples`` variants of ``files[target]`` with ``read``; count how each ended.

    Parameters
    ----------
    read : callable
        Takes the variant's path; what it returns is not looked at.
    files : dict
        File name → bytes of the good file and its companions, written into one folder.
    target : str
        The file the variants replace.
    variants : hypothesis strategy
        Of the bytes of the variant (:func:`json_variants`, :func:`text_variants`, :func:`glb_variants`,
        :func:`byte_variants`).
    examples : int
        Variants to try (Hypothesis' ``max_examples``; derandomized, so the same on every run).

    Returns
    -------
    Counter
        ``{"loaded": n, "refused": m}``; their sum is the number of variants tried.

    Raises
    ------
    AssertionError
        For a variant refused with an InputError that names no file of the folder; any exception other
        than InputError propagates with the (shrunk) variant that raised it.
    """
    outcomes: Counter = Counter()
    with tempfile.TemporaryDirectory() as name:
        folder = Path(name)
        for file, data in files.items():
            (folder / file).write_bytes(data)
        path = folder / target

        @settings(max_examples=examples, derandomize=os.environ.get("CSMLAB_FUZZ_SEED") is None, deadline=None,
                  database=None,
                  suppress_health_check=list(HealthCheck))
        @given(variants)
        def one(variant: bytes) -> None:
            path.write_bytes(variant)
            try:
                with warnings.catch_warnings():
                    # NumPy's overflow and invalid-value warnings would print beside exit 2: a reader checks first.
                    warnings.simplefilter("error", RuntimeWarning)
                    read(path)
            except InputError as error:
                assert _refusal_names_a_file(error, folder), f"refused without naming a file of the folder: {error}"
                outcomes["refused"] += 1
            else:
                outcomes["loaded"] += 1

        seed = os.environ.get("CSMLAB_FUZZ_SEED")
        (one if seed is None else hypothesis_seed(int(seed))(one))()
    return outcomes
