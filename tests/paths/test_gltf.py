"""An animated glTF camera as a camera path, against the glTF 2.0 interpolation rules worked by hand.

Every fixture is written here by :class:`csmlab.scene.gltf_writer.GltfBuilder`; the oracles are the
specification's formulas evaluated on the keys (the midpoint of a LINEAR pair, the Hermite basis of
CUBICSPLINE, a STEP key held, a child carried round by an animated parent). The real Khronos
AnimatedTriangle under tests/data/gltf/vendor/ (git-ignored) is read when present.
"""

from __future__ import annotations


import numpy as np
import pytest

from csmlab.errors import InputError
from csmlab.geometry import quat_to_matrix
from csmlab.paths import read_path
from csmlab.paths.gltf import read_gltf_camera, sample_channel
from csmlab.scene.gltf import read_gltf
from csmlab.scene.gltf_writer import GltfBuilder
from tests.locations import TEST_DATA

VENDOR = TEST_DATA / "gltf" / "vendor"


def _about_y(deg: float) -> list[float]:
    return [0.0, float(np.sin(np.radians(deg) / 2)), 0.0, float(np.cos(np.radians(deg) / 2))]


def _camera_file(tmp_path, channels, *, name="camera.glb", camera_at=None, parent_channels=(), **camera):
    """A file with one camera node (optionally under an animated parent) and the given channels."""
    b = GltfBuilder()
    spec = {"yfov_rad": np.radians(50.0), "znear": 0.25, "zfar": 150.0, "aspect": 2.0, **camera}
    eye = b.add_node(name="eye", camera=b.add_camera(name="lens", **spec), translation=camera_at)
    root = eye
    if parent_channels:
        root = b.add_node(name="rig", children=[eye])
    b.add_animation([(eye, *c) for c in channels] + [(root, *c) for c in parent_channels])
    return b.save(tmp_path / name, roots=[root])


def test_linear_translation_is_at_the_midpoint_at_the_mid_time(tmp_path):
    file = _camera_file(tmp_path, [("translation", [0.0, 2.0], [[0, 1, 0], [10, 3, -20]], "LINEAR")])
    poses = read_gltf_camera(file, fps=10.0)
    assert poses.times.size == 21
    np.testing.assert_allclose(poses.positions[10], [5.0, 2.0, -10.0], atol=1e-6)
    np.testing.assert_allclose(poses.positions[5], [2.5, 1.5, -5.0], atol=1e-6)


def test_linear_rotation_slerps_to_the_half_angle(tmp_path):
    file = _camera_file(tmp_path, [("rotation", [0.0, 1.0], [_about_y(0), _about_y(120)], "LINEAR")])
    poses = read_gltf_camera(file, fps=4.0)
    # Slerp keeps the angular speed: 30° per quarter second (a normalised lerp would not at 0.25 s).
    for k, deg in enumerate([0, 30, 60, 90, 120]):
        np.testing.assert_allclose(quat_to_matrix(poses.orientations[k]), quat_to_matrix(_about_y(deg)), atol=1e-6)


def test_step_holds_each_key_until_the_next(tmp_path):
    file = _camera_file(tmp_path, [("translation", [0.0, 1.0, 2.0], [[0, 0, 0], [1, 0, 0], [2, 0, 0]], "STEP")])
    poses = read_gltf_camera(file, fps=10.0)
    np.testing.assert_allclose(poses.positions[:, 0], np.repeat([0.0, 1.0, 2.0], [10, 10, 1]), atol=0)


def test_cubicspline_with_zero_tangents_follows_the_hermite_ease(tmp_path):
    zero = [0.0, 0.0, 0.0]
    values = [zero, [0, 0, 0], zero, zero, [8, 0, 0], zero]  # (in-tangent, value, out-tangent) per key
    file = _camera_file(tmp_path, [("translation", [0.0, 2.0], values, "CUBICSPLINE")])
    poses = read_gltf_camera(file, fps=2.0)
    s = np.array([0.0, 0.25, 0.5, 0.75, 1.0])
    np.testing.assert_allclose(poses.positions[:, 0], 8.0 * (3 * s**2 - 2 * s**3), atol=1e-5)


def test_cubicspline_tangents_are_scaled_by_the_key_interval(tmp_path):
    zero = [0.0, 0.0, 0.0]
    values = [zero, zero, [1, 0, 0], zero, zero, zero]  # only key 0's out-tangent: 1 m/s along x
    file = _camera_file(tmp_path, [("translation", [0.0, 2.0], values, "CUBICSPLINE")])
    poses = read_gltf_camera(file, fps=2.0)
    s = np.array([0.0, 0.25, 0.5, 0.75, 1.0])
    np.testing.assert_allclose(poses.positions[:, 0], 2.0 * (s**3 - 2 * s**2 + s), atol=1e-6)


def test_a_camera_under_an_animated_parent_is_carried_round(tmp_path):
    file = _camera_file(tmp_path, [], camera_at=(0.0, 0.0, 5.0),
                        parent_channels=[("rotation", [0.0, 1.0], [_about_y(0), _about_y(90)], "LINEAR"),
                                         ("translation", [0.0, 1.0], [[0, 2, 0], [0, 2, 0]], "LINEAR")])
    poses = read_gltf_camera(file, fps=2.0)
    for k, deg in enumerate([0.0, 45.0, 90.0]):
        a = np.radians(deg)
        # R_y(a) (0, 0, 5) + (0, 2, 0); the camera turns with its parent.
        np.testing.assert_allclose(poses.positions[k], [5 * np.sin(a), 2.0, 5 * np.cos(a)], atol=1e-6)
        np.testing.assert_allclose(quat_to_matrix(poses.orientations[k]), quat_to_matrix(_about_y(deg)), atol=1e-6)


def test_the_path_takes_the_cameras_projection_and_clock(tmp_path):
    file = _camera_file(tmp_path, [("translation", [0.5, 1.5], [[0, 0, 0], [1, 0, 0]], "LINEAR")])
    path = read_path(file, fps=10.0, scale=2.0)
    assert len(path) == 11 and path.times[0] == pytest.approx(0.5)
    assert path.fov_y_deg == pytest.approx(np.full(11, 50.0))
    assert (path.aspect, path.near, path.far) == pytest.approx((2.0, 0.5, 300.0))  # clip distances × scale


def test_a_scaled_camera_node_keeps_a_rotation(tmp_path):
    b = GltfBuilder()
    eye = b.add_node(name="eye", camera=b.add_camera(name="lens", yfov_rad=1.0, znear=0.1), scale=(2.0, 2.0, 2.0),
                     rotation=_about_y(30))
    b.add_animation([(eye, "translation", [0.0, 1.0], [[0, 0, 0], [0, 0, -1]], "LINEAR")])
    poses = read_gltf_camera(b.save(tmp_path / "scaled.glb", roots=[eye]), fps=1.0)
    np.testing.assert_allclose(quat_to_matrix(poses.orientations[0]), quat_to_matrix(_about_y(30)), atol=1e-6)
    assert poses.far is None and poses.aspect is None


def _two_cameras(tmp_path):
    b = GltfBuilder()
    nodes = [b.add_node(name=n, camera=b.add_camera(name=f"{n} lens", yfov_rad=0.8, znear=0.1)) for n in ("a", "b")]
    b.add_animation([(nodes[1], "translation", [0.0, 1.0], [[0, 0, 0], [0, 0, -4]], "LINEAR")])
    return b.save(tmp_path / "two.glb", roots=nodes)


def test_camera_picks_one_of_several_by_node_or_camera_name(tmp_path):
    file = _two_cameras(tmp_path)
    for name in ("b", "b lens"):
        np.testing.assert_allclose(read_gltf_camera(file, camera=name, fps=1.0).positions[-1], [0, 0, -4], atol=1e-6)


@pytest.mark.parametrize("camera, field, match", [
    ("", "camera", r"expected camera = one of \['a', 'b'\]"),
    ("c", "camera", "got 'c' \\(no camera by that name\\)"),
    ("a", "animations", "expected an animation moving camera 'a'"),
])
def test_a_missing_unknown_or_still_camera_names_the_key(tmp_path, camera, field, match):
    file = _two_cameras(tmp_path)
    with pytest.raises(InputError, match=match) as info:
        read_gltf_camera(file, camera=camera)
    assert info.value.field == field and info.value.file == str(file)


def test_a_file_without_a_camera_names_cameras(tmp_path):
    b = GltfBuilder()
    file = b.save(tmp_path / "none.glb", roots=[b.add_node(name="empty")])
    with pytest.raises(InputError, match="perspective camera, found none") as info:
        read_gltf_camera(file)
    assert info.value.field == "cameras"


def test_a_non_unit_rotation_key_is_refused_with_its_time(tmp_path):
    file = _camera_file(tmp_path, [("rotation", [0.0, 1.0], [[0, 0, 0, 1], [0, 0.5, 0, 0.5]], "LINEAR")])
    with pytest.raises(InputError, match=r"key 1 at t = 1 s has \|q\| = 0.707") as info:
        read_gltf_camera(file)
    assert info.value.field == "animations[0].samplers[0].output"


def test_a_nan_key_names_its_accessor(tmp_path):
    file = _camera_file(tmp_path, [("translation", [0.0, 1.0], [[0, 0, 0], [np.nan, 0, 0]], "LINEAR")])
    with pytest.raises(InputError, match="expected finite numbers") as info:
        read_gltf_camera(file)
    assert info.value.field.startswith("accessors[") and str(file) in str(info.value)


def test_key_times_that_go_back_are_refused(tmp_path):
    file = _camera_file(tmp_path, [("translation", [1.0, 0.0], [[0, 0, 0], [1, 0, 0]], "LINEAR")])
    with pytest.raises(InputError, match="strictly increasing") as info:
        read_gltf_camera(file)
    assert info.value.field == "animations[0].samplers[0].input"


def test_a_cubicspline_sampler_needs_three_values_per_key(tmp_path):
    file = _camera_file(tmp_path, [("translation", [0.0, 1.0], [[0, 0, 0], [1, 0, 0]], "CUBICSPLINE")])
    with pytest.raises(InputError, match="expected 6 values of 3 components") as info:
        read_gltf_camera(file)
    assert info.value.field == "animations[0].samplers[0].output"


def test_sample_channel_holds_the_ends_outside_the_keys():
    values = np.array([[1.0], [3.0]])
    for rule in ("LINEAR", "STEP"):
        np.testing.assert_array_equal(sample_channel([1.0, 2.0], values, rule, [0.0, 5.0]), [[1.0], [3.0]])


def test_vendor_animated_triangle_turns_a_quarter_per_quarter_second():
    """Khronos glTF-Sample-Assets Models/AnimatedTriangle/glTF-Embedded (CC0 1.0): rotation keys
    0°, 90°, 180°, 270°, 360° about +Z at 0, 0.25, 0.5, 0.75, 1 s (its buffer); slerp halves them."""
    file = VENDOR / "AnimatedTriangle.gltf"
    if not file.is_file():
        pytest.skip(f"{file} absent: the vendor files are not committed (tests/data/gltf/vendor/README.md)")
    from csmlab.paths.gltf import animation_channels

    channel = animation_channels(read_gltf(file), {0})[0, "rotation"]
    q = sample_channel(channel.times, channel.values, channel.interpolation, [0.125, 0.375], rotation=True)
    angles = np.degrees(2 * np.arctan2(q[:, 2], q[:, 3]))
    np.testing.assert_allclose(angles, [45.0, 135.0], atol=0.05)


def test_vendor_cameras_sample_has_one_perspective_camera_and_no_animation():
    """Khronos glTF-Sample-Assets Models/Cameras/glTF-Embedded (CC0 1.0): a perspective camera
    (yfov 0.7, aspectRatio 1) and an orthographic one, neither animated."""
    file = VENDOR / "Cameras.gltf"
    if not file.is_file():
        pytest.skip(f"{file} absent: the vendor files are not committed (tests/data/gltf/vendor/README.md)")
    from csmlab.paths.gltf import camera_nodes

    (camera,) = camera_nodes(read_gltf(file))
    assert (camera.node, camera.aspect, camera.near, camera.far) == (1, 1.0, 0.01, 100.0)
    assert camera.fov_y_deg == pytest.approx(np.degrees(0.7))
    with pytest.raises(InputError) as info:
        read_gltf_camera(file)
    assert info.value.field == "animations"
