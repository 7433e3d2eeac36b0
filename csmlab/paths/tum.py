"""TUM trajectory files: ``timestamp tx ty tz qx qy qz qw`` per line.

Whitespace-separated, seconds and metres, quaternion scalar-last, camera-to-world; ``#`` starts a
comment line and blank lines are skipped (Sturm et al., "A Benchmark for the Evaluation of RGB-D
SLAM Systems", 2012, and its file-format page). The axes are not part of the format: SLAM
estimates use the first camera's frame (convention ``tum``), the benchmark's ground truth the
motion-capture room (convention ``mocap``).
"""

from __future__ import annotations

import numpy as np

from csmlab.files import write_atomic
from csmlab.paths.recorded import (
    RecordedPoses,
    data_rows,
    numeric_table,
    ordered_times,
    require_poses,
    text_lines,
    unit_quaternions,
)

__all__ = ["read_tum", "write_tum"]

FIELDS = ("timestamp", "tx", "ty", "tz", "qx", "qy", "qz", "qw")


def read_tum(file) -> RecordedPoses:
    """Every pose of a TUM file, checked (see :mod:`csmlab.paths.recorded`), in the file's axes."""
    lines = text_lines(file)
    rows = data_rows(lines)
    require_poses(rows, file=file, line_count=len(lines))
    values, numbers = numeric_table(rows, file=file, fields=FIELDS)
    return RecordedPoses(
        file=str(file),
        lines=numbers,
        times=ordered_times(values[:, 0], numbers, file=file, field="timestamp"),
        positions=values[:, 1:4],
        orientations=unit_quaternions(values[:, 4:8], numbers, file=file, field="qx qy qz qw"),
    )


def write_tum(poses: RecordedPoses, file) -> None:
    """Write ``poses`` (with times) as a TUM file; numbers in shortest round-trip form."""
    table = np.column_stack([poses.times, poses.positions, poses.orientations])
    body = "".join(" ".join(map(repr, row)) + "\n" for row in table.tolist())
    write_atomic(file, "# " + " ".join(FIELDS) + "\n" + body)
