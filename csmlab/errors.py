"""The one exception type for bad user input (config, camera-path file, mesh, light).

The CLI turns an :class:`InputError` — or a ``ValueError`` raised while reading input — into one
line on stderr and exit code 2. The message always says where (file, line, field) and what was
expected.
"""

from __future__ import annotations

__all__ = ["InputError"]


class InputError(ValueError):
    """Bad input, located.

    Parameters
    ----------
    message : str
        What was expected and what was found.
    file : str, optional
        The file the input came from.
    line : int, optional
        1-based line number in ``file``.
    field : str, optional
        The field, column or key (``camera.fov_y_deg``, ``qw``).
    """

    def __init__(self, message: str, *, file=None, line: int | None = None, field: str | None = None):
        self.file = None if file is None else str(file)
        self.line = line
        self.field = field
        self.detail = message
        where = ":".join(str(p) for p in (self.file, line) if p is not None)
        parts = [p for p in (where, field) if p]
        super().__init__(": ".join(parts + [message]))
