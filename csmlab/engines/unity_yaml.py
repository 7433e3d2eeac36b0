"""Unity's serialized assets (``.asset``): YAML 1.1 documents headed ``--- !u!<class id> &<file id>``.

PyYAML reads them once the ``!u!`` class tags (Unity's own, declared by ``%TAG !u! tag:unity3d.com,2011:``)
are stripped from the document markers; each document is one object, ``{type name: {field: value}}``.
"""

from __future__ import annotations

import re

import yaml

from csmlab.errors import InputError
from csmlab.engines.reading import read_text

__all__ = ["unity_objects", "unity_text"]

_MARKER = re.compile(r"^--- !u!(\d+) &(-?\d+)( stripped)?\s*$", re.M)


def unity_objects(path) -> list[tuple[int, str, dict]]:
    """``(class id, type name, fields)`` of every object in the Unity asset ``path``.

    Raises
    ------
    InputError
        Not a Unity YAML asset (no ``%YAML`` header or ``!u!`` document), or YAML that does not parse.
    """
    text = read_text(path)
    if not text.startswith("%YAML") or not _MARKER.search(text):
        raise InputError("expected a Unity YAML asset (%YAML 1.1 and --- !u!<class> &<id> documents); set the "
                         "project's Asset Serialization to Force Text", file=path, field="%YAML")
    classes = [int(m.group(1)) for m in _MARKER.finditer(text)]
    try:
        documents = [d for d in yaml.safe_load_all(_MARKER.sub("---", text)) if d is not None]
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        raise InputError(f"expected valid YAML, got {getattr(exc, 'problem', None) or exc}", file=path,
                         line=None if mark is None else mark.line + 1) from None
    objects = []
    for class_id, document in zip(classes, documents):
        if not isinstance(document, dict) or len(document) != 1:
            raise InputError("expected one Unity object per document", file=path, field=f"!u!{class_id}")
        (name, fields), = document.items()
        objects.append((class_id, name, fields if isinstance(fields, dict) else {}))
    return objects


def unity_text(class_id: int, type_name: str, fields: list[str]) -> str:
    """A one-object Unity asset: the header, the ``!u!`` document marker and ``fields`` (``key: value`` lines)."""
    lines = ["%YAML 1.1", "%TAG !u! tag:unity3d.com,2011:", f"--- !u!{class_id} &{11400000 if class_id == 114 else 1}",
             f"{type_name}:", *(f"  {line}" for line in fields)]
    return "\n".join(lines) + "\n"
