"""KITTI odometry pose files: 12 numbers a line, a 3×4 camera-to-world matrix in row-major order.

``r00 r01 r02 tx r10 r11 r12 ty r20 r21 r22 tz``: the pose of the left camera (x right, y down,
z forward) in the frame of the first one, metres (Geiger et al., "Are we ready for Autonomous
Driving?", 2012, odometry devkit). The file has no time stamps: they come from a separate times
file (``times.txt``: one time in seconds per line, as the devkit ships) or from a frame rate.
"""

from __future__ import annotations

import numpy as np

from csmlab.errors import InputError
from csmlab.files import write_atomic
from csmlab.geometry import quat_from_matrix, quat_to_matrix
from csmlab.paths.recorded import (
    QUATERNION_TOLERANCE,
    RecordedPoses,
    data_rows,
    numeric_table,
    ordered_times,
    require_poses,
    text_lines,
)

__all__ = ["read_kitti", "read_kitti_times", "write_kitti"]

FIELDS = ("r00", "r01", "r02", "tx", "r10", "r11", "r12", "ty", "r20", "r21", "r22", "tz")


def read_kitti(file) -> RecordedPoses:
    """Every pose of a KITTI file (``times`` is ``None``), in the file's axes.

    Raises
    ------
    InputError
        As :func:`~csmlab.paths.recorded.numeric_table`, and on a 3×3 block that is not a
        rotation: ``max |RᵀR - I|`` above 2·10⁻³ (the quaternion tolerance, doubled as ``R``
        is quadratic in ``q``) or a reflection.
    """
    lines = text_lines(file)
    rows = data_rows(lines)
    require_poses(rows, file=file, line_count=len(lines))
    values, numbers = numeric_table(rows, file=file, fields=FIELDS)
    matrices = values.reshape(-1, 3, 4)
    rotations = matrices[:, :, :3]
    error = np.max(np.abs(np.einsum("nji,njk->nik", rotations, rotations) - np.eye(3)), axis=(1, 2))
    bad = (error > 2 * QUATERNION_TOLERANCE) | (np.linalg.det(rotations) <= 0)
    if np.any(bad):
        k = int(np.argmax(bad))
        raise InputError(f"expected a rotation in the 3×3 block (orthonormal within {2 * QUATERNION_TOLERANCE}, "
                         f"det +1), got max |RᵀR - I| = {error[k]:.3g}, det = {np.linalg.det(rotations[k]):.6g}",
                         file=file, line=int(numbers[k]), field="r00..r22")
    return RecordedPoses(file=str(file), lines=numbers, times=None, positions=matrices[:, :, 3].copy(),
                         orientations=quat_from_matrix(rotations))


def read_kitti_times(file, *, count: int) -> np.ndarray:
    """Time stamps ``(count,)`` in seconds from a KITTI times file, one per pose.

    Raises
    ------
    InputError
        On a broken line, times that do not strictly increase, or a count other than ``count``.
    """
    lines = text_lines(file)
    rows = data_rows(lines)
    require_poses(rows, file=file, line_count=len(lines))
    values, numbers = numeric_table(rows, file=file, fields=("time",))
    found = values.shape[0]
    if found != count:
        where = numbers[count] if found > count else numbers[-1]
        raise InputError(f"expected one time per pose ({count}), found {found}", file=file, line=int(where),
                         field="time")
    times = ordered_times(values[:, 0], numbers, file=file, field="time")
    repeated = np.flatnonzero(np.diff(times) == 0)
    if repeated.size:
        k = int(repeated[0]) + 1
        # Repeats are resolved by duplicate_times only where the pose file has the stamps (not KITTI).
        raise InputError(f"expected times that strictly increase, got {float(times[k])!r} again (line "
                         f"{int(numbers[k - 1])})", file=file, line=int(numbers[k]), field="time")
    return times


def write_kitti(poses: RecordedPoses, file) -> None:
    """Write ``poses`` as a KITTI file (times are not part of it); shortest round-trip numbers."""
    matrices = np.concatenate([quat_to_matrix(poses.orientations), poses.positions[:, :, None]], axis=2)
    body = "".join(" ".join(map(repr, row)) + "\n" for row in matrices.reshape(-1, 12).tolist())
    write_atomic(file, body)
