"""nerfstudio camera paths: hand-written files in the viewer's layout, read against poses worked by hand.

The oracle is nerfstudio's own reading (``get_path_from_json``: ``camera_to_world`` viewed as 4×4
row-major, ``fov`` vertical in degrees, ``render_width / render_height``) and its OpenGL camera in
a z-up world, turned by hand into csmlab's y-up axes: file (x, y, z) → csmlab (x, z, −y).
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from csmlab.errors import InputError
from csmlab.geometry import quat_to_matrix
from csmlab.paths import guess_format, read_path


def _path_file(tmp_path, poses, **top):
    document = {"keyframes": [], "camera_type": "perspective", "render_height": 1080, "render_width": 1920,
                "fps": 2, "seconds": 1.0, "is_cycle": False, "smoothness_value": 0.5,
                "camera_path": [{"camera_to_world": m, "fov": f, "aspect": 1.777} for m, f in poses], **top}
    file = tmp_path / "camera_path.json"
    file.write_text(json.dumps(document, indent=2))
    return file


IDENTITY_AT = [1, 0, 0, 1.0, 0, 1, 0, 2.0, 0, 0, 1, 3.0, 0, 0, 0, 1]  # row-major: translation in the last column
# Camera turned 90° about the world's +z: its x (right) along world +y, y (up) along world −x.
TURNED_AT = [0, -1, 0, -4.0, 1, 0, 0, 5.0, 0, 0, 1, 6.0, 0, 0, 0, 1]


def test_poses_fov_aspect_and_times_as_nerfstudio_reads_them(tmp_path):
    file = _path_file(tmp_path, [(IDENTITY_AT, 50.0), (TURNED_AT, 70.0)])
    assert guess_format(file) == "nerfstudio"
    path = read_path(file, fps=2.0)
    np.testing.assert_allclose(path.times, [0.0, 0.5])  # pose i at i · seconds / N
    np.testing.assert_allclose(path.positions, [[1, 3, -2], [-4, 6, -5]], atol=1e-12)
    np.testing.assert_allclose(path.fov_y_deg, [50.0, 70.0])
    assert path.aspect == pytest.approx(16 / 9)
    rotations = quat_to_matrix(path.orientations)
    # The identity camera looks along the z-up world's −z: straight down in csmlab, its up along world +y → −Z.
    np.testing.assert_allclose(-rotations[0][:, 2], [0, -1, 0], atol=1e-12)
    np.testing.assert_allclose(rotations[0][:, 1], [0, 0, -1], atol=1e-12)
    # The turned camera's right is world +y → csmlab −Z; it still looks down.
    np.testing.assert_allclose(rotations[1][:, 0], [0, 0, -1], atol=1e-12)
    np.testing.assert_allclose(-rotations[1][:, 2], [0, -1, 0], atol=1e-12)


def test_opengl_convention_reads_a_y_up_world_as_is(tmp_path):
    file = _path_file(tmp_path, [(IDENTITY_AT, 50.0), (IDENTITY_AT, 50.0)])
    path = read_path(file, format="nerfstudio", convention="opengl")
    np.testing.assert_allclose(path.positions[0], [1, 2, 3])
    np.testing.assert_allclose(quat_to_matrix(path.orientations[0]), np.eye(3), atol=1e-12)


@pytest.mark.parametrize("edit, field, match", [
    (lambda d: d["camera_path"][1].pop("camera_to_world"), "camera_path[1].camera_to_world", "16 numbers"),
    (lambda d: d["camera_path"][1].__setitem__("camera_to_world", IDENTITY_AT[:12]), "camera_path[1].camera_to_world",
     "16 finite numbers"),
    (lambda d: d["camera_path"][1]["camera_to_world"].__setitem__(0, float("nan")), "camera_path[1].camera_to_world",
     "finite"),
    (lambda d: d["camera_path"][1]["camera_to_world"].__setitem__(0, 2.0), "camera_path[1].camera_to_world",
     "a rotation"),
    (lambda d: d["camera_path"][1].__setitem__("camera_to_world", {"m": 1}), "camera_path[1].camera_to_world",
     "16 finite numbers .*, got an object"),
    (lambda d: d["camera_path"][1].pop("fov"), "camera_path[1].fov", "no key 'fov'"),
    (lambda d: d["camera_path"][1].__setitem__("fov", 180.0), "camera_path[1].fov", "in \\(0, 180\\)"),
    (lambda d: d["camera_path"][1].__setitem__("fov", "wide"), "camera_path[1].fov", "got the string 'wide'"),
    (lambda d: d.__setitem__("camera_path", {"0": {}}), "camera_path", "a list of poses"),
    (lambda d: d.pop("seconds"), "seconds", "no key 'seconds'"),
    (lambda d: d.__setitem__("render_height", 0), "render_height", "positive"),
    (lambda d: d.__setitem__("camera_type", "fisheye"), "camera_type", "perspective"),
    (lambda d: d.__setitem__("camera_path", []), None, "at least one pose"),
])
def test_a_broken_path_names_the_file_line_and_key(tmp_path, edit, field, match):
    file = _path_file(tmp_path, [(list(IDENTITY_AT), 50.0), (list(TURNED_AT), 70.0)])
    document = json.loads(file.read_text())
    edit(document)
    file.write_text(json.dumps(document, indent=2))
    with pytest.raises(InputError, match=match) as info:
        read_path(file, format="nerfstudio")
    assert info.value.field == field and info.value.file == str(file) and info.value.line is not None
