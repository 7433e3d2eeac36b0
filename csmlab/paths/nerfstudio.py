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

from csmlab.documents import Value, json_value
from csmlab.files import write_atomic
from csmlab.geometry import quat_from_matrix, quat_to_matrix
from csmlab.paths.recorded import RecordedPoses, require_poses, text_lines

__all__ = ["ROTATION_TOLERANCE", "read_nerfstudio", "write_nerfstudio"]

ROTATION_TOLERANCE = 1e-3
"""Largest ``|Rᵀ R − I|`` entry of a ``camera_to_world`` rotation taken as rounding."""


def _positive(document: Value, key: str) -> float:
    return document.at(key, "a finite positive number (nerfstudio camera path)").number(
        above=0.0, what="a finite positive number")


def _pose_matrix(pose: Value) -> np.ndarray:
    """``pose.camera_to_world`` ``(4, 4)``, checked to be a rigid transform."""
    field = pose.at("camera_to_world", "16 numbers (4×4, row-major)")
    matrix = field.numbers(16, what="16 finite numbers (4×4, row-major)").reshape(4, 4)
    with np.errstate(over="ignore", invalid="ignore"):  # a huge entry gives inf or NaN: not a rotation
        bad = (not np.allclose(matrix[3], [0, 0, 0, 1])
               or not np.abs(matrix[:3, :3].T @ matrix[:3, :3] - np.eye(3)).max() <= ROTATION_TOLERANCE
               or not np.linalg.det(matrix[:3, :3]) > 0)
    if bad:
        raise field.error("a rotation (orthonormal, det +1) and translation with last row 0 0 0 1")
    return matrix


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
        Naming the file, the line and the key (read through :class:`csmlab.documents.Value`): a
        missing key, a value of the wrong type, a number that is not finite, a ``camera_to_world``
        that is not 16 numbers or not a rigid transform, an empty path, more than
        :data:`~csmlab.documents.MAX_FRAMES` poses.
    """
    lines = text_lines(file)
    document = json_value("\n".join(lines), file=file, lines=True).mapping(
        "an object with a 'camera_path' list (nerfstudio camera path)")
    camera_type = document.get("camera_type")
    if camera_type is not None:
        camera_type.text(("perspective",))
    poses = document.at("camera_path", "a list of poses (nerfstudio camera path)").items(
        "a list of poses (nerfstudio camera path)")
    require_poses(poses, file=file, line_count=len(lines))
    seconds = _positive(document, "seconds")
    aspect = _positive(document, "render_width") / _positive(document, "render_height")
    if not np.isfinite(aspect) or aspect <= 0.0:
        raise document.at("render_height").error("a render size whose width / height is a finite positive number")
    matrices, fov, numbers = np.empty((len(poses), 4, 4)), np.empty(len(poses)), []
    for k, pose in enumerate(poses):
        pose.mapping("an object with camera_to_world and fov")
        numbers.append(pose.line)
        matrices[k] = _pose_matrix(pose)
        fov[k] = pose.at("fov", "a vertical field of view in (0, 180) degrees").number(
            above=0.0, below=180.0, what="a vertical field of view in (0, 180) degrees")
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
