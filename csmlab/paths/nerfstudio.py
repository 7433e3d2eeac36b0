"""nerfstudio camera-path JSON: what ``ns-render camera-path`` reads and the nerfstudio viewer writes.

The fields read, as nerfstudio's ``get_path_from_json`` (``nerfstudio/cameras/camera_paths.py``)
and ``RenderCameraPath`` (``nerfstudio/scripts/render.py``) read them (nerfstudio @ 50e0e3c):

- ``camera_path``: a list of poses, each with ``camera_to_world`` — a 4×4 camera-to-world matrix as
  16 numbers in row-major order (``torch.tensor(...).view(4, 4)``) — and ``fov``, the vertical field
  of view in degrees (its focal length is ``render_height / 2 / tan(fov / 2)``);
- ``render_width``, ``render_height``: the image size in pixels, whose ratio is the aspect;
- ``seconds``: the duration; the viewer writes ``fps · seconds`` poses, pose ``i`` shown at
  ``i · seconds / N`` (``ns-render`` plays the ``N`` poses in ``seconds``).

Other keys (``keyframes``, ``crop``, ``camera_type`` ``perspective``, per-pose ``aspect``) are not
used; a non-perspective ``camera_type`` is refused. The camera is OpenGL's (x right, y up, looking
along −z): the viewer turns its own OpenCV-style pose about x by 180° before writing
(``render_panel.py``, ``pose.rotation() @ SO3.from_x_radians(pi)``). The world is nerfstudio's,
z up after its data parsers' ``orientation_method = "up"``: convention ``nerfstudio``
(:data:`csmlab.paths.conventions.CONVENTIONS`). A ``camera_to_world`` whose 3×3 part is not a
rotation (within :data:`ROTATION_TOLERANCE`) or whose last row is not ``0 0 0 1`` is refused.
"""

from __future__ import annotations

import json

import numpy as np

from csmlab.errors import InputError
from csmlab.files import write_atomic
from csmlab.geometry import quat_from_matrix, quat_to_matrix
from csmlab.paths.recorded import RecordedPoses, require_poses, text_lines
from csmlab.paths.tabular import json_number, located_json

__all__ = ["ROTATION_TOLERANCE", "read_nerfstudio", "write_nerfstudio"]

ROTATION_TOLERANCE = 1e-3
"""Largest ``|Rᵀ R − I|`` entry of a ``camera_to_world`` rotation taken as rounding."""


def _number(document, key: str, *, file, positive: bool = True) -> float:
    if key not in document:
        raise InputError(f"expected the key {key!r} (nerfstudio camera path)", file=file,
                         line=getattr(document, "line", 1), field=key)
    value = json_number(document[key], file=file, line=document.line, field=key)
    if not np.isfinite(value) or (positive and value <= 0):
        raise InputError(f"expected a finite {'positive ' if positive else ''}number, got {value!r}", file=file,
                         line=document.line, field=key)
    return value


def read_nerfstudio(file) -> RecordedPoses:
    """The poses of a nerfstudio camera-path JSON file, in nerfstudio's axes.

    Returns
    -------
    RecordedPoses
        ``times`` ``i · seconds / N``; positions and camera-to-world quaternions from
        ``camera_to_world``; ``fov_y_deg`` from ``fov``; ``aspect`` ``render_width / render_height``;
        ``lines`` the line of each pose's ``{``.

    Raises
    ------
    InputError
        Naming the file, the line and the key: a missing key, a number that is not finite, a
        ``camera_to_world`` that is not 16 numbers or not a rigid transform, an empty path.
    """
    lines = text_lines(file)
    document = located_json("\n".join(lines), file=file)
    if not isinstance(document, dict) or not isinstance(document.get("camera_path"), list):
        raise InputError("expected an object with a 'camera_path' list (nerfstudio camera path)", file=file,
                         line=getattr(document, "line", 1), field="camera_path")
    if document.get("camera_type", "perspective") != "perspective":
        raise InputError(f"expected camera_type 'perspective', got {document['camera_type']!r}", file=file,
                         line=document.line, field="camera_type")
    poses = document["camera_path"]
    require_poses(poses, file=file, line_count=len(lines))
    seconds = _number(document, "seconds", file=file)
    aspect = _number(document, "render_width", file=file) / _number(document, "render_height", file=file)
    matrices, fov, numbers = np.empty((len(poses), 4, 4)), np.empty(len(poses)), []
    for k, pose in enumerate(poses):
        if not isinstance(pose, dict):
            raise InputError(f"expected camera_path[{k}] to be an object, got {pose!r}", file=file,
                             line=document.line, field="camera_path")
        numbers.append(pose.line)
        values = pose.get("camera_to_world")
        if not isinstance(values, list) or len(values) != 16:
            raise InputError(f"expected camera_path[{k}].camera_to_world: 16 numbers (4×4, row-major), got "
                             f"{values!r}", file=file, line=pose.line, field="camera_to_world")
        matrices[k] = np.reshape([json_number(v, file=file, line=pose.line, field="camera_to_world")
                                  for v in values], (4, 4))
        fov[k] = _number(pose, "fov", file=file)
        bad = (not np.all(np.isfinite(matrices[k])) or not np.allclose(matrices[k, 3], [0, 0, 0, 1])
               or np.abs(matrices[k, :3, :3].T @ matrices[k, :3, :3] - np.eye(3)).max() > ROTATION_TOLERANCE
               or np.linalg.det(matrices[k, :3, :3]) <= 0)
        if bad:
            raise InputError(f"expected camera_path[{k}].camera_to_world to be finite, a rotation (orthonormal, "
                             f"det +1) and translation with last row 0 0 0 1, got {values!r}", file=file,
                             line=pose.line, field="camera_to_world")
        if not 0 < fov[k] < 180:
            raise InputError(f"expected camera_path[{k}].fov in (0, 180) degrees, got {fov[k]!r}", file=file,
                             line=pose.line, field="fov")
    u, _, vt = np.linalg.svd(matrices[:, :3, :3])
    return RecordedPoses(file=str(file), lines=np.asarray(numbers, dtype=np.int64),
                         times=np.arange(len(poses)) * (seconds / len(poses)), positions=matrices[:, :3, 3].copy(),
                         orientations=quat_from_matrix(u @ vt), fov_y_deg=fov, aspect=aspect, time_field="seconds")


def write_nerfstudio(poses: RecordedPoses, file) -> None:
    """Write ``poses`` as a nerfstudio camera path; read back, it gives the same poses and times.

    ``seconds`` is ``N`` times the mean step (so pose ``i`` returns at ``i · seconds / N`` exactly
    when the times are evenly spaced from 0), the image 1920 pixels wide at the poses' aspect (16:9
    when unknown) and ``fov`` 60° where the poses carry none.
    """
    count = poses.positions.shape[0]
    step = float(np.mean(np.diff(poses.times))) if count > 1 else 1.0
    matrices = np.tile(np.eye(4), (count, 1, 1))
    matrices[:, :3, :3] = quat_to_matrix(poses.orientations)
    matrices[:, :3, 3] = poses.positions
    fov = poses.fov_y_deg if poses.fov_y_deg is not None else np.full(count, 60.0)
    aspect = poses.aspect if poses.aspect is not None else 16.0 / 9.0
    document = {"camera_type": "perspective", "render_width": 1920, "render_height": 1920 / aspect,
                "seconds": step * count, "fps": 1.0 / step,
                "camera_path": [{"camera_to_world": m.reshape(-1).tolist(), "fov": float(f), "aspect": aspect}
                                for m, f in zip(matrices, fov)]}
    write_atomic(file, json.dumps(document, indent=1) + "\n")
