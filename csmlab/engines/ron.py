"""Rusty Object Notation (RON), the text of Bevy's ``.scn.ron`` scenes, read into Python values.

The subset serde's RON writer emits: structs ``(field: value, …)`` and named ones ``Name(…)`` as dicts
(the name dropped), tuples ``(a, b)`` and lists ``[a, b]`` as lists, maps ``{key: value}`` as dicts,
enum variants with one value ``Some(x)`` as ``{"Some": x}``, bare variants ``None`` as strings, numbers,
strings (Rust's escapes), booleans, ``//`` and ``/* */`` comments, trailing commas. Structs and maps are
:class:`~csmlab.engines.reading.Located` at their line, so that an :class:`~csmlab.engines.reading.Entry` read
of them names it; nesting deeper than :data:`csmlab.documents.MAX_JSON_DEPTH` is refused.
"""

from __future__ import annotations

import re

from csmlab.documents import MAX_JSON_DEPTH
from csmlab.engines.reading import Located
from csmlab.errors import InputError

__all__ = ["parse_ron"]

_TOKEN = re.compile(r"\s+|//[^\n]*|/\*.*?\*/|"
                    r'(?P<string>"(?:[^"\\]|\\.)*")|'
                    r"(?P<number>[-+]?(?:\d[\d_]*\.?[\d_]*(?:[eE][-+]?\d+)?|\.\d+(?:[eE][-+]?\d+)?|inf|NaN))(?![\w])|"
                    r"(?P<ident>[A-Za-z_][\w]*)|(?P<punct>[()\[\]{}:,])", re.S)


_ESCAPE = re.compile(r"""\\(?:u\{(?P<code>[0-9a-fA-F]{1,6})\}|x(?P<byte>[0-7][0-9a-fA-F])|(?P<plain>[nrt0\\"'])|.?)""",
                     re.S)
_PLAIN = {"n": "\n", "r": "\r", "t": "\t", "0": "\0", "\\": "\\", '"': '"', "'": "'"}


def _string(quoted: str, *, file, line: int) -> str:
    """The text of a RON string token (its quotes included), its Rust escapes replaced."""
    def escape(match: re.Match) -> str:
        if match.group("plain") is not None:
            return _PLAIN[match.group("plain")]
        if match.group("byte") is not None:
            return chr(int(match.group("byte"), 16))
        code = int(match.group("code"), 16) if match.group("code") is not None else None
        if code is None or code > 0x10FFFF or 0xD800 <= code < 0xE000:
            raise InputError(f"expected a string escape (\\n, \\t, \\\\, \\\", \\u{{…}}), got {match.group()!r}",
                             file=file, line=line + quoted.count("\n", 0, match.start()))
        return chr(code)

    return _ESCAPE.sub(escape, quoted[1:-1])


def _tokens(text: str, file) -> list[tuple[str, str, int]]:
    tokens, pos = [], 0
    while pos < len(text):
        match = _TOKEN.match(text, pos)
        if match is None:
            line = text.count("\n", 0, pos) + 1
            raise InputError(f"expected RON, got {text[pos:pos + 20]!r}", file=file, line=line)
        kind = match.lastgroup
        if kind is not None:
            tokens.append((kind, match.group(kind), text.count("\n", 0, pos) + 1))
        pos = match.end()
    return tokens


def parse_ron(text: str, *, file=None):
    """The value of the RON document ``text``; InputError naming ``file`` and the line where it is malformed."""
    tokens = _tokens(text, file)
    position = [0]

    def peek():
        return tokens[position[0]] if position[0] < len(tokens) else ("end", "", tokens[-1][2] if tokens else 1)

    def take(expected=None):
        token = peek()
        if token[0] == "end" or (expected is not None and token[1] != expected):
            raise InputError(f"expected {expected or 'a value'}, got {token[1] or 'the end of the file'!r}",
                             file=file, line=token[2])
        position[0] += 1
        return token

    def sequence(close, depth):
        items = []
        while peek()[1] != close:
            items.append(value(depth + 1))
            if peek()[1] != close:
                take(",")
        take(close)
        return items

    def located(line: int) -> Located:
        mapping = Located()
        mapping.line, mapping.key_lines = line, {}
        return mapping

    def parenthesised(depth):
        line = take("(")[2]
        kind = peek()[0]
        after = tokens[position[0] + 1][1] if position[0] + 1 < len(tokens) else ""
        if kind == "ident" and after == ":":
            fields = located(line)
            while peek()[1] != ")":
                _, name, at = take()
                take(":")
                fields.key_lines[name] = at
                fields[name] = value(depth + 1)
                if peek()[1] != ")":
                    take(",")
            take(")")
            return fields
        return sequence(")", depth)

    def number(text_: str, line: int):
        clean = text_.replace("_", "")
        try:
            return float(clean) if any(c in clean for c in ".eEin") or clean == "NaN" else int(clean)
        except ValueError:  # an integer of more digits than Python converts
            raise InputError(f"expected a number, got {len(clean)} digits", file=file, line=line) from None

    def value(depth: int = 0):
        kind, text_, line = peek()
        if depth > MAX_JSON_DEPTH:
            raise InputError(f"expected RON nested at most {MAX_JSON_DEPTH} deep (docs/design.md, \"Inputs\")",
                             file=file, line=line)
        if kind == "string":
            take()
            return _string(text_, file=file, line=line)
        if kind == "number":
            take()
            return number(text_, line)
        if text_ == "(":
            return parenthesised(depth)
        if text_ == "[":
            take("[")
            return sequence("]", depth)
        if text_ == "{":
            take("{")
            mapping = located(line)
            while peek()[1] != "}":
                at = peek()[2]
                key = value(depth + 1)
                key = key if not isinstance(key, (list, dict)) else str(key)
                take(":")
                mapping.key_lines[key] = at
                mapping[key] = value(depth + 1)
                if peek()[1] != "}":
                    take(",")
            take("}")
            return mapping
        if kind == "ident":
            take()
            if text_ in ("true", "false"):
                return text_ == "true"
            if peek()[1] == "(":
                inner = parenthesised(depth)
                if isinstance(inner, list):
                    variant = located(line)
                    variant[text_] = inner[0] if len(inner) == 1 else inner
                    return variant
                return inner
            return text_
        raise InputError(f"expected a value, got {text_ or 'the end of the file'!r}", file=file, line=line)

    result = value()
    if position[0] != len(tokens):
        raise InputError(f"expected the end of the document, got {peek()[1]!r}", file=file, line=peek()[2])
    return result
