"""EuRoC MAV ground-truth CSV: ``#timestamp`` (ns), position, quaternion **w x y z**, more columns.

Comma-separated; the first line is a ``#`` header; columns 2–4 are ``p_RS_R_{x,y,z}`` in metres
and 5–8 ``q_RS_{w,x,y,z}``; the velocity and bias columns that follow are ignored (Burri et al.,
"The EuRoC micro aerial vehicle datasets", 2016). The pose is the body (IMU) frame in the z-up
room frame; convention ``euroc`` says how csmlab turns it into a camera.
"""

from __future__ import annotations

import numpy as np

from csmlab.errors import InputError
from csmlab.files import write_atomic
from csmlab.paths.recorded import (
    RecordedPoses,
    data_rows,
    numeric_table,
    require_poses,
    text_lines,
    unit_quaternions,
)

__all__ = ["read_euroc", "write_euroc"]

FIELDS = ("p_RS_R_x", "p_RS_R_y", "p_RS_R_z", "q_RS_w", "q_RS_x", "q_RS_y", "q_RS_z")
HEADER = "#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z []"
_NS = 1_000_000_000


def _nanoseconds(rows, *, file) -> np.ndarray:
    stamps = []
    for number, tokens in rows:
        try:
            stamp = int(tokens[0])
        except ValueError:
            stamp = None
        if stamp is None or not -(2 ** 63) <= stamp < 2 ** 63:
            shown = tokens[0] if len(tokens[0]) <= 40 else tokens[0][:40] + "…"
            raise InputError(f"expected whole nanoseconds that fit 64 bits, got {shown!r}", file=file, line=number,
                             field="timestamp")
        stamps.append(stamp)
    return np.array(stamps, dtype=np.int64)


def read_euroc(file) -> RecordedPoses:
    """Every pose of a EuRoC ground-truth file, in the file's axes (times in seconds)."""
    lines = text_lines(file)
    rows = data_rows(lines, delimiter=",")
    require_poses(rows, file=file, line_count=len(lines))
    values, numbers = numeric_table([(n, t[1:]) for n, t in rows], file=file, fields=FIELDS, extra_fields=True)
    ns = _nanoseconds(rows, file=file)
    bad = np.diff(ns) < 0
    if np.any(bad):
        k = int(np.argmax(bad)) + 1
        raise InputError(f"expected time stamps that never go back, got {ns[k]} ns after {ns[k - 1]} ns",
                         file=file, line=int(numbers[k]), field="timestamp")
    seconds, rest = np.divmod(ns, _NS)
    return RecordedPoses(
        file=str(file),
        lines=numbers,
        times=seconds.astype(np.float64) + rest.astype(np.float64) / _NS,
        positions=values[:, 0:3],
        orientations=unit_quaternions(values[:, [4, 5, 6, 3]], numbers, file=file, field="q_RS_w q_RS_x q_RS_y q_RS_z"),
    )


def write_euroc(poses: RecordedPoses, file) -> None:
    """Write ``poses`` as the first eight EuRoC columns; times rounded to whole nanoseconds."""
    whole = np.floor(poses.times)
    ns = whole.astype(np.int64) * _NS + np.rint((poses.times - whole) * _NS).astype(np.int64)
    lines = [HEADER]
    for stamp, p, q in zip(ns.tolist(), poses.positions.tolist(), poses.orientations[:, [3, 0, 1, 2]].tolist()):
        lines.append(",".join([str(stamp), *map(repr, p), *map(repr, q)]))
    write_atomic(file, "\n".join(lines) + "\n")
