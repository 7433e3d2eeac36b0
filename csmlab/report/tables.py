"""The results files the report is drawn from, read back as columns.

``metrics.csv``, ``timings.csv`` and ``cascades.csv`` are read into :class:`Columns`: one NumPy
array per column, float64 where every cell is a number (empty cells become NaN, as docs/design.md
writes undefined values) and str otherwise. Rows keep the file's order.
"""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from csmlab.errors import InputError
from csmlab.results import TIMING_COLUMNS

__all__ = ["TEXT_COLUMNS", "Columns", "ResultFiles", "read_columns", "read_results"]


@dataclass(frozen=True)
class Columns:
    """A table as columns.

    Attributes
    ----------
    data : dict of str to ndarray
        Column name → ``(N,)`` float64 (numbers, NaN for empty cells) or str array.
    """

    data: dict

    def __getitem__(self, name: str) -> np.ndarray:
        return self.data[name]

    def __contains__(self, name: str) -> bool:
        return name in self.data

    def __len__(self) -> int:
        return len(next(iter(self.data.values()))) if self.data else 0

    @property
    def names(self) -> list[str]:
        """Column names in file order."""
        return list(self.data)

    def where(self, mask: np.ndarray) -> Columns:
        """The rows where ``mask`` (N,) bool is true."""
        return Columns({k: v[mask] for k, v in self.data.items()})

    def groups(self) -> list[tuple[str, str]]:
        """The distinct ``(method, point)`` pairs, in order of first appearance."""
        return list(dict.fromkeys(zip(self.data["method"].tolist(), self.data["point"].tolist())))

    def of(self, method: str, point: str) -> Columns:
        """The rows of one method × sweep point, sorted by frame."""
        rows = self.where((self.data["method"] == method) & (self.data["point"] == point))
        return rows.where(np.argsort(rows.data["frame"], kind="stable"))


TEXT_COLUMNS = ("method", "point", "stage")
CASCADE_KEYS = ("frame", "method", "point", "cascade")
"""Label columns, kept as text even when their cells look like numbers (a point named ``512``)."""


def read_columns(path, *, required: tuple[str, ...] = ()) -> Columns:
    """Read a CSV file with a header row into :class:`Columns` (label columns :data:`TEXT_COLUMNS` as str).

    Raises
    ------
    InputError
        If the file is missing, has no header, a row of the wrong length, or lacks a column of
        ``required``; the message names the file (and line).
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("expected a results file here; run `csmlab run` first", file=path)
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    if not rows:
        raise InputError("expected a header row, found an empty file", file=path, line=1)
    header, body = rows[0], rows[1:]
    for i, row in enumerate(body):
        if len(row) != len(header):
            raise InputError(f"expected {len(header)} cells, got {len(row)}", file=path, line=i + 2)
    missing = [name for name in required if name not in header]
    if missing:
        raise InputError(f"expected columns {', '.join(missing)}", file=path, line=1)
    cells = list(zip(*body)) if body else [()] * len(header)
    return Columns({name: _column(values, text=name in TEXT_COLUMNS) for name, values in zip(header, cells)})


def _column(cells, *, text: bool) -> np.ndarray:
    if text:
        return np.array(cells, dtype=str)
    try:
        return np.array([float(c) if c != "" else np.nan for c in cells], dtype=np.float64)
    except ValueError:
        return np.array(cells, dtype=str)


@dataclass(frozen=True)
class ResultFiles:
    """Everything the report reads from a results directory.

    Attributes
    ----------
    directory : Path
    summary : dict
        ``summary.json``.
    metrics : Columns
        ``metrics.csv``.
    timings : Columns or None
        ``timings.csv`` when present.
    cascades : Columns or None
        ``cascades.csv`` (written by :func:`csmlab.report.capture.write_captures`) when present.
    regress : dict or None
        ``regress.json`` when present: ``status`` and ``rows`` (dicts, the verdict last).
    """

    directory: Path
    summary: dict
    metrics: Columns
    timings: Columns | None
    cascades: Columns | None
    regress: dict | None


def read_results(directory) -> ResultFiles:
    """Read a results directory; ``summary.json`` and ``metrics.csv`` are required.

    Raises
    ------
    InputError
        If a required file is missing or malformed; the message names the file.
    """
    directory = Path(directory)
    metrics = read_columns(directory / "metrics.csv", required=("frame", "method", "point"))
    if len(metrics) == 0:
        raise InputError("expected at least one row of results, found none", file=directory / "metrics.csv", line=2)
    timings = directory / "timings.csv"
    cascades = directory / "cascades.csv"
    regress = directory / "regress.json"
    return ResultFiles(
        directory=directory,
        summary=_read_json(directory / "summary.json"),
        metrics=metrics,
        timings=read_columns(timings, required=TIMING_COLUMNS) if timings.exists() else None,
        cascades=read_columns(cascades, required=CASCADE_KEYS) if cascades.exists() else None,
        regress=_read_json(regress) if regress.exists() else None,
    )


def _read_json(path: Path):
    if not path.is_file():
        raise InputError("expected a results file here; run `csmlab run` first", file=path)
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError as error:
        raise InputError(f"expected JSON: {error.msg}", file=path, line=error.lineno) from None
