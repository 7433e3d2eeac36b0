"""csmlab's own camera-path files: one schema, written as CSV or as JSON.

Fields of every pose (names exact, lower case):

=============  ========  ==========================================================
field          unit      meaning
=============  ========  ==========================================================
``time``       s         time stamp; never going back (repeats resolved by a rule)
``x y z``      metres    camera position in the file's world axes
``qx qy qz qw``          camera-to-world unit quaternion, scalar last ...
``yaw pitch``  degrees   ... **or** csmlab's yaw/pitch/roll (``R = R_y(yaw) R_x(pitch)
``roll``                 R_z(roll)``, see :func:`~csmlab.paths.conventions.orientation_from_yaw_pitch_roll`;
                         valid with convention ``opengl`` only)
``fov_y_deg``  degrees   optional: vertical field of view of that pose, in (0, 180)
=============  ========  ==========================================================

Every pose of a file uses the same fields; an unknown field is refused, not ignored.

CSV: comma-separated; the first line that is neither blank nor a ``#`` comment is the header
naming the columns (any order), then one pose per line::

    time,x,y,z,qx,qy,qz,qw,fov_y_deg
    0.0,20.0,1.7,0.0,0.0,0.0,0.0,1.0,60.0

JSON: an object whose one key ``poses`` holds a list of objects with those fields::

    {"poses": [
      {"time": 0.0, "x": 20.0, "y": 1.7, "z": 0.0, "yaw": 0.0, "pitch": -5.0, "roll": 0.0}
    ]}

Errors name the line of the header (a missing column) or of the pose (its ``{`` in JSON).
"""

from __future__ import annotations

import json
from collections.abc import Sequence

import numpy as np

from csmlab.documents import json_value
from csmlab.errors import InputError
from csmlab.files import write_atomic
from csmlab.paths.conventions import orientation_from_yaw_pitch_roll
from csmlab.paths.recorded import (
    RecordedPoses,
    data_rows,
    numeric_table,
    ordered_times,
    require_poses,
    text_lines,
    unit_quaternions,
)

__all__ = ["read_csv", "read_json", "write_csv", "write_json"]

POSITION = ("time", "x", "y", "z")
QUATERNION = ("qx", "qy", "qz", "qw")
ANGLES = ("yaw", "pitch", "roll")
FOV = "fov_y_deg"


def _schema(names: Sequence[str], *, file, line: int) -> tuple[str, ...]:
    """The fields, in canonical order, that a header (or first JSON pose) names; checked."""
    given = list(names)
    known = set(POSITION + QUATERNION + ANGLES + (FOV,))
    for name in given:
        if name not in known:
            raise InputError(f"unknown field {name!r}: expected {', '.join(POSITION)}, then {' '.join(QUATERNION)} "
                             f"or {' '.join(ANGLES)}, optionally {FOV}", file=file, line=line, field=name)
        if given.count(name) > 1:
            raise InputError(f"field {name!r} given twice", file=file, line=line, field=name)
    has_q = any(n in given for n in QUATERNION)
    has_a = any(n in given for n in ANGLES)
    if has_q and has_a:
        raise InputError(f"expected the orientation as {' '.join(QUATERNION)} or as {' '.join(ANGLES)}, not both",
                         file=file, line=line, field="yaw")
    orientation = ANGLES if has_a else QUATERNION
    fields = POSITION + orientation + ((FOV,) if FOV in given else ())
    for name in fields:
        if name not in given:
            raise InputError(f"missing column: expected the fields {' '.join(fields)}", file=file, line=line,
                             field=name)
    return fields


def _recorded(values: np.ndarray, lines: np.ndarray, fields: tuple[str, ...], *, file,
              header_line: int) -> RecordedPoses:
    """Check the parsed numbers of ``fields`` and build the record."""
    column = {name: values[:, k] for k, name in enumerate(fields)}
    if "yaw" in column:
        orientations = orientation_from_yaw_pitch_roll(yaw_deg=column["yaw"], pitch_deg=column["pitch"],
                                                       roll_deg=column["roll"])
        angles_line = header_line
    else:
        orientations = unit_quaternions(np.column_stack([column[n] for n in QUATERNION]), lines, file=file,
                                        field="qx qy qz qw")
        angles_line = None
    fov = column.get(FOV)
    if fov is not None:
        bad = (fov <= 0.0) | (fov >= 180.0)
        if np.any(bad):
            k = int(np.argmax(bad))
            raise InputError(f"expected a vertical field of view in (0, 180) degrees, got {float(fov[k])!r}", file=file,
                             line=int(lines[k]), field=FOV)
    return RecordedPoses(
        file=str(file),
        lines=lines,
        times=ordered_times(column["time"], lines, file=file, field="time"),
        positions=np.column_stack([column["x"], column["y"], column["z"]]),
        orientations=orientations,
        fov_y_deg=None if fov is None else fov.copy(),
        angles_line=angles_line,
        time_field="time",
    )


def read_csv(file) -> RecordedPoses:
    """Every pose of a csmlab CSV path file (schema in the module docstring), in the file's axes."""
    lines = text_lines(file)
    rows = data_rows(lines, delimiter=",")
    require_poses(rows, file=file, line_count=len(lines))
    header_line, header = rows[0]
    fields = _schema(header, file=file, line=header_line)
    require_poses(rows[1:], file=file, line_count=len(lines))
    index = [header.index(name) for name in fields]
    ordered = []
    for number, tokens in rows[1:]:
        if len(tokens) < len(header):
            raise InputError(f"missing column: expected {len(header)} fields ({','.join(header)}), found "
                             f"{len(tokens)}", file=file, line=number, field=header[len(tokens)])
        if len(tokens) > len(header):
            raise InputError(f"expected {len(header)} fields ({','.join(header)}), found {len(tokens)}",
                             file=file, line=number)
        ordered.append((number, [tokens[i] for i in index]))
    values, numbers = numeric_table(ordered, file=file, fields=fields)
    return _recorded(values, numbers, fields, file=file, header_line=header_line)


def read_json(file) -> RecordedPoses:
    """Every pose of a csmlab JSON path file (schema in the module docstring), in the file's axes.

    The document is read through :class:`csmlab.documents.Value`: a value of the wrong type names
    its pose and field (``poses[3].qw``) and the line of the pose's ``{``.
    """
    lines = text_lines(file)
    text = "\n".join(lines)
    if not text.strip():
        require_poses([], file=file, line_count=len(lines))
    document = json_value(text, file=file, lines=True).mapping("an object with one key 'poses' holding a list")
    if document.keys() != ["poses"]:
        raise document.error(f"an object with one key 'poses' holding a list, got keys {sorted(document.keys())}",
                             got=False)
    poses = document.at("poses", "a list of poses").items("a list of poses")
    require_poses(poses, file=file, line_count=len(lines))
    first = poses[0].mapping("a pose: an object of numbers")
    fields = _schema(first.keys(), file=file, line=first.line)
    rows = []
    for pose in poses:
        names = pose.mapping("a pose: an object of numbers").keys()
        for name in names:
            if name not in fields:
                raise InputError(f"unexpected field {name!r}: the first pose has {' '.join(fields)}", file=file,
                                 line=pose.line, field=name)
        rows.append((pose.line, [pose.at(n, f"a number (the first pose has {' '.join(fields)})").number(
            what="a finite number") for n in fields]))
    values, numbers = numeric_table(rows, file=file, fields=fields)
    return _recorded(values, numbers, fields, file=file, header_line=first.line)


def _table(poses: RecordedPoses) -> tuple[tuple[str, ...], list[list[float]]]:
    fields = POSITION + QUATERNION + ((FOV,) if poses.fov_y_deg is not None else ())
    columns = [poses.times[:, None], poses.positions, poses.orientations]
    if poses.fov_y_deg is not None:
        columns.append(poses.fov_y_deg[:, None])
    return fields, np.concatenate(columns, axis=1).tolist()


def write_csv(poses: RecordedPoses, file) -> None:
    """Write ``poses`` as a csmlab CSV file with quaternion columns (and ``fov_y_deg`` when known)."""
    fields, table = _table(poses)
    body = "".join(",".join(map(repr, row)) + "\n" for row in table)
    write_atomic(file, ",".join(fields) + "\n" + body)


def write_json(poses: RecordedPoses, file) -> None:
    """Write ``poses`` as a csmlab JSON file, one pose per line, with quaternions."""
    fields, table = _table(poses)
    items = ",\n".join("  " + json.dumps(dict(zip(fields, row))) for row in table)
    write_atomic(file, '{"poses": [\n' + items + "\n]}\n")
