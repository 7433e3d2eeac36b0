"""Files written whole or not at all.

:func:`write_atomic` writes through a temporary file in the target's folder, flushed to disk, then
renamed into place (``os.replace``, atomic on POSIX and Windows): a reader — the report, a resumed
run, a CI job — sees the old file or the new one, never half of one, and an interrupted write
leaves no stray temporary file.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterable
from pathlib import Path

__all__ = ["write_atomic"]


def write_atomic(path, data: str | bytes | Iterable[str | bytes]) -> Path:
    """Write ``data`` (text as UTF-8, newlines untranslated) to ``path``; return the path.

    ``data`` may also be an iterable of pieces, written one after the other as they come (a long
    file is then never whole in memory). The folder is created when missing.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    pieces = [data] if isinstance(data, (str, bytes)) else data
    handle, temporary = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(handle, "wb") as f:
            for piece in pieces:
                f.write(piece.encode("utf-8") if isinstance(piece, str) else piece)
            f.flush()
            os.fsync(f.fileno())
        os.replace(temporary, path)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise
    return path
