"""Rusty Object Notation (RON), the text of Bevy's ``.scn.ron`` scenes, read into Python values.

The subset serde's RON writer emits: structs ``(field: value, …)`` and named ones ``Name(…)`` as dicts
(the name dropped), tuples ``(a, b)`` and lists ``[a, b]`` as lists, maps ``{key: value}`` as dicts,
enum variants with one value ``Some(x)`` as ``{"Some": x}``, bare variants ``None`` as strings, numbers,
strings, booleans, ``//`` and ``/* */`` comments, trailing commas.
"""

from __future__ import annotations

import re

from csmlab.errors import InputError

__all__ = ["parse_ron"]

_TOKEN = re.compile(r"""\s+|//[^\n]*|/\*.*?\*/|(?P<string>"(?:[^"\\]|\\.)*")|(?P<number>[-+]?(?:\d[\d_]*\.?[\d_]*(?:[eE][-+]?\d+)?|\.\d+(?:[eE][-+]?\d+)?|inf|NaN))(?![\w])|(?P<ident>[A-Za-z_][\w]*)|(?P<punct>[()\[\]{}:,])""", re.S)


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

    def sequence(close):
        items = []
        while peek()[1] != close:
            items.append(value())
            if peek()[1] != close:
                take(",")
        take(close)
        return items

    def parenthesised():
        take("(")
        kind = peek()[0]
        after = tokens[position[0] + 1][1] if position[0] + 1 < len(tokens) else ""
        if kind == "ident" and after == ":":
            fields = {}
            while peek()[1] != ")":
                name = take()[1]
                take(":")
                fields[name] = value()
                if peek()[1] != ")":
                    take(",")
            take(")")
            return fields
        return sequence(")")

    def value():
        kind, text_, line = peek()
        if kind == "string":
            take()
            return bytes(text_[1:-1], "utf-8").decode("unicode_escape")
        if kind == "number":
            take()
            clean = text_.replace("_", "")
            return float(clean) if any(c in clean for c in ".eEin") or clean == "NaN" else int(clean)
        if text_ == "(":
            return parenthesised()
        if text_ == "[":
            take("[")
            return sequence("]")
        if text_ == "{":
            take("{")
            mapping = {}
            while peek()[1] != "}":
                key = value()
                take(":")
                mapping[key if not isinstance(key, (list, dict)) else str(key)] = value()
                if peek()[1] != "}":
                    take(",")
            take("}")
            return mapping
        if kind == "ident":
            take()
            if text_ in ("true", "false"):
                return text_ == "true"
            if peek()[1] == "(":
                inner = parenthesised()
                if isinstance(inner, list):
                    return {text_: inner[0] if len(inner) == 1 else inner}
                return inner
            return text_
        raise InputError(f"expected a value, got {text_ or 'the end of the file'!r}", file=file, line=line)

    result = value()
    if position[0] != len(tokens):
        raise InputError(f"expected the end of the document, got {peek()[1]!r}", file=file, line=peek()[2])
    return result
