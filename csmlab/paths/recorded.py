"""What a camera-path file says, checked and located, before any change of convention.

Every reader turns its file into a :class:`RecordedPoses` through the helpers below, so every
format refuses the same broken input the same way: an :class:`~csmlab.errors.InputError` naming
the file, the 1-based line and the field, and what was expected. Nothing is half-read: a reader
either returns every pose or raises.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from collections.abc import Sequence

import numpy as np

from csmlab.documents import MAX_FRAMES, within_limit
from csmlab.errors import InputError

__all__ = [
    "QUATERNION_TOLERANCE",
    "RecordedPoses",
    "data_rows",
    "ordered_times",
        "numeric_table",
    "require_poses",
    "text_lines",
    "unit_quaternions",
]

QUATERNION_TOLERANCE = 1e-3
"""A quaternion with ``| |q| - 1 |`` up to this is rounding in the file and is normalised; beyond, it is broken."""


@dataclass(frozen=True)
class RecordedPoses:
    """The poses of one file in the file's own convention and unit.

    Attributes
    ----------
    file : str
        Where they came from (for error messages).
    lines : ndarray, shape (N,), int64
        1-based line of each pose in ``file``.
    times : ndarray, shape (N,), float64, or None
        Seconds, never going back (a stamp may repeat); ``None`` when the format has none (KITTI).
    positions : ndarray, shape (N, 3), float64
        Positions in the file's world axes and length unit.
    orientations : ndarray, shape (N, 4), float64
        Unit quaternions ``(x, y, z, w)``, the file's camera axes to its world axes.
    fov_y_deg : ndarray, shape (N,), float64, or None
        Vertical field of view per pose in degrees, when the file gives one.
    angles_line : int or None
        Line of the ``yaw``/``pitch``/``roll`` field when orientations were given as angles,
        which are defined in csmlab's own axes only.
    time_field : str
        The format's name of the time column (for error messages).
    aspect : float or None
        Width / height when the file states it (glTF ``aspectRatio``, nerfstudio's render size).
    near, far : float or None
        Clip distances in the file's length unit when the file states them (glTF ``znear``, ``zfar``).
    """

    file: str
    lines: np.ndarray
    times: np.ndarray | None
    positions: np.ndarray
    orientations: np.ndarray
    fov_y_deg: np.ndarray | None = None
    angles_line: int | None = None
    time_field: str = "timestamp"
    aspect: float | None = None
    near: float | None = None
    far: float | None = None


def text_lines(file) -> list[str]:
    """The lines of a UTF-8 text file, without line ends.

    Raises
    ------
    InputError
        If the file is missing, is not a regular file, or is not UTF-8 text.
    """
    path = Path(file)
    if not path.is_file():
        raise InputError("expected an existing camera-path file", file=path)
    try:
        return path.read_text(encoding="utf-8-sig").splitlines()
    except UnicodeDecodeError as err:
        line = path.read_bytes()[: err.start].count(b"\n") + 1
        raise InputError("expected UTF-8 text, found undecodable bytes", file=path, line=line) from None


def data_rows(lines: Sequence[str], *, delimiter: str | None = None, comment: str = "#") -> list[tuple[int, list[str]]]:
    """``(line_number, fields)`` of every line that is neither blank nor a ``comment`` line.

    Fields are split on ``delimiter`` (whitespace when ``None``) and stripped.
    """
    rows = []
    for number, text in enumerate(lines, start=1):
        stripped = text.strip()
        if not stripped or stripped.startswith(comment):
            continue
        rows.append((number, [f.strip() for f in stripped.split(delimiter)]))
    return rows


def require_poses(rows: Sequence, *, file, line_count: int) -> None:
    """Refuse a file with no pose (located at its last line, line 1 when it has none) or with more than
    :data:`~csmlab.documents.MAX_FRAMES`."""
    if not rows:
        raise InputError("expected at least one pose, found none (the file is empty or only comments)",
                         file=file, line=max(line_count, 1))
    within_limit(len(rows), MAX_FRAMES, what="poses", file=file)


def numeric_table(rows: Sequence[tuple[int, list[str]]], *, file, fields: Sequence[str],
                  extra_fields: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Parse ``rows`` into finite float64 numbers, one column per name in ``fields``.

    Parameters
    ----------
    rows : sequence of (int, list of str)
        ``(line_number, fields)`` as from :func:`data_rows`.
    file : str or Path
        For error messages.
    fields : sequence of str
        Name of each expected column, in order.
    extra_fields : bool
        Whether further columns are ignored (``True``) or refused.

    Returns
    -------
    values : ndarray, shape (N, len(fields)), float64
    lines : ndarray, shape (N,), int64

    Raises
    ------
    InputError
        On a missing or surplus column, a field that is not a number, or NaN/inf; located at
        the first offending line and named by its field.
    """
    width = len(fields)
    values = np.empty((len(rows), width))
    for k, (number, tokens) in enumerate(rows):
        if len(tokens) < width:
            raise InputError(f"missing column: expected {width} fields ({' '.join(fields)}), found {len(tokens)}",
                             file=file, line=number, field=fields[len(tokens)])
        if len(tokens) > width and not extra_fields:
            raise InputError(f"expected {width} fields ({' '.join(fields)}), found {len(tokens)}",
                             file=file, line=number)
        for j in range(width):
            try:
                values[k, j] = float(tokens[j])
            except ValueError:
                raise InputError(f"expected a number, got {tokens[j]!r}", file=file, line=number,
                                 field=fields[j]) from None
    lines = np.array([number for number, _ in rows], dtype=np.int64)
    bad = ~np.isfinite(values)
    if np.any(bad):
        k, j = np.argwhere(bad)[0]
        raise InputError(f"expected a finite number, got {values[k, j]}", file=file, line=int(lines[k]),
                         field=fields[j])
    return values, lines


def unit_quaternions(q, lines: np.ndarray, *, file, field: str = "quaternion") -> np.ndarray:
    """Normalise quaternions ``(N, 4)`` whose length is within :data:`QUATERNION_TOLERANCE` of 1.

    Raises
    ------
    InputError
        At the first line whose quaternion is zero or further from unit length.
    """
    q = np.asarray(q, dtype=np.float64)
    with np.errstate(over="ignore", invalid="ignore"):  # |q| of a huge component is inf: refused below
        length = np.linalg.norm(q, axis=1)
    bad = np.abs(length - 1.0) > QUATERNION_TOLERANCE
    if np.any(bad):
        k = int(np.argmax(bad))
        raise InputError(f"expected a unit quaternion (|q| within {QUATERNION_TOLERANCE} of 1), got |q| = "
                         f"{length[k]:.6g}", file=file, line=int(lines[k]), field=field)
    return q / length[:, None]


def ordered_times(times, lines: np.ndarray, *, file, field: str = "timestamp") -> np.ndarray:
    """Return ``times`` ``(N,)`` after checking that they never go back.

    A repeated stamp is allowed here: :func:`csmlab.paths.timing.resolve_duplicates` resolves it
    by the rule the user chose.

    Raises
    ------
    InputError
        At the first line whose time is before the previous one.
    """
    times = np.asarray(times, dtype=np.float64)
    bad = np.diff(times) < 0
    if np.any(bad):
        k = int(np.argmax(bad)) + 1
        raise InputError(f"expected time stamps that never go back, got {float(times[k])!r} after "
                         f"{float(times[k - 1])!r} (line {int(lines[k - 1])})", file=file, line=int(lines[k]),
                         field=field)
    return times
