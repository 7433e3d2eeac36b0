"""Unity's serialized assets (``.asset``): YAML 1.1 documents headed ``--- !u!<class id> &<file id>``.

PyYAML reads them once the ``!u!`` class tags (Unity's own, declared by ``%TAG !u! tag:unity3d.com,2011:``)
are stripped from the document markers; each document is one object, ``{type name: {field: value}}``, whose
fields an importer reads through :class:`~csmlab.engines.reading.Entry` (each mapping at its line).
"""

from __future__ import annotations

import re

from csmlab.engines.reading import Entry, read_text, yaml_document
from csmlab.errors import InputError

__all__ = ["unity_objects", "unity_text"]

_MARKER = re.compile(r"^--- !u!(\d+) &(-?\d+)( stripped)?\s*$", re.M)


def unity_objects(path) -> list[tuple[int, object, Entry]]:
    """``(class id, type name, fields)`` of every object in the Unity asset ``path`` (fields: an Entry, the
    object's mapping where the document holds one).

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
    documents = [d for d in yaml_document(_MARKER.sub("---", text), file=path, what="valid YAML", every=True)
                 if d is not None]
    objects = []
    for class_id, document in zip(classes, documents):
        if not isinstance(document, dict) or len(document) != 1:
            raise InputError("expected one Unity object per document", file=path, field=f"!u!{class_id}",
                             line=getattr(document, "line", None))
        (name, fields), = document.items()
        objects.append((class_id, name, Entry(fields, file=path, line=getattr(document, "line", None))))
    return objects


def unity_text(class_id: int, type_name: str, fields: list[str]) -> str:
    """A one-object Unity asset: the header, the ``!u!`` document marker and ``fields`` (``key: value`` lines)."""
    lines = ["%YAML 1.1", "%TAG !u! tag:unity3d.com,2011:", f"--- !u!{class_id} &{11400000 if class_id == 114 else 1}",
             f"{type_name}:", *(f"  {line}" for line in fields)]
    return "\n".join(lines) + "\n"
