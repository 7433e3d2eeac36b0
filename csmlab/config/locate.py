"""Where a field is written: the file a merged value came from and its line, for every message."""

from __future__ import annotations

import re
from pathlib import Path

from csmlab.errors import InputError


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
