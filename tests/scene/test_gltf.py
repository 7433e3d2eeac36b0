"""glTF levels: triangles placed by the node tree and EXT_mesh_gpu_instancing, and the sun.

Fixtures are written here by :class:`csmlab.scene.gltf_writer.GltfBuilder` (boxes of known size, masked cards);
oracles are the boxes' corners moved by hand-composed transforms (a 90° turn, a translation, a
mirror), their enclosed volume, and the sun's −Z axis turned by a known rotation. The real
Khronos sample assets under tests/data/gltf/vendor/ (git-ignored, see its README) are read when
present.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from csmlab.errors import InputError
from csmlab.scene import load_mesh
from csmlab.scene.gltf import read_gltf, sun_of
from csmlab.scene.gltf_writer import GltfBuilder, box
from tests.locations import TEST_DATA

VENDOR = TEST_DATA / "gltf" / "vendor"
HALF_TURN_Y = [0.0, np.sin(np.pi / 4), 0.0, np.cos(np.pi / 4)]  # 90° about +Y: (x, y, z) → (z, y, −x)


def _volume(scene) -> float:
    a, b, c = (scene.vertices[scene.triangles[:, k]] for k in range(3))
    return float(np.einsum("ij,ij->", a, np.cross(b, c)) / 6.0)


def _unit_box(builder):
    return builder.add_mesh(*box((1.0, 2.0, 1.0)), name="box")  # x, z in [−0.5, 0.5], y in [0, 2]


def test_a_child_is_placed_by_its_parents_rotation_then_translation(tmp_path):
    b = GltfBuilder()
    child = b.add_node(mesh=_unit_box(b), translation=(3.0, 0.0, 0.0))
    parent = b.add_node(translation=(0.0, 1.0, 10.0), rotation=HALF_TURN_Y, children=[child])
    scene = load_mesh(b.save(tmp_path / "tree.glb", roots=[parent]))
    # Child box at x ∈ [2.5, 3.5], z ∈ [−0.5, 0.5]; turned: x ∈ [−0.5, 0.5], z ∈ [−3.5, −2.5]; moved.
    np.testing.assert_allclose(scene.bounds, [[-0.5, 1.0, 6.5], [0.5, 3.0, 7.5]], atol=1e-6)
    assert scene.triangle_count == 12 and _volume(scene) == pytest.approx(2.0, rel=1e-6)


def test_a_column_major_matrix_node_equals_its_translation(tmp_path):
    b = GltfBuilder()
    matrix = np.eye(4)
    matrix[:3, 3] = (5.0, 0.0, -2.0)
    node = b.add_node(mesh=_unit_box(b), matrix=matrix.T)  # column-major: the translation is elements 12–14
    scene = load_mesh(b.save(tmp_path / "matrix.gltf", roots=[node]))
    np.testing.assert_allclose(scene.bounds, [[4.5, 0.0, -2.5], [5.5, 2.0, -1.5]], atol=1e-6)


def test_instances_are_placed_at_node_times_translation_rotation_scale(tmp_path):
    b = GltfBuilder()
    node = b.add_node(mesh=_unit_box(b), translation=(0.0, 0.0, 100.0), instances={
        "TRANSLATION": [[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [20.0, 0.0, 0.0]],
        "ROTATION": [[0, 0, 0, 1], HALF_TURN_Y, [0, 0, 0, 1]],
        "SCALE": [[1.0, 1.0, 1.0], [4.0, 1.0, 1.0], [1.0, 3.0, 1.0]]})
    scene = load_mesh(b.save(tmp_path / "instanced.glb", roots=[node]))
    assert scene.triangle_count == 36
    boxes = scene.vertices[scene.triangles].reshape(3, 12 * 3, 3)  # instance by instance, in order
    expected = [
        [[-0.5, 0.0, 99.5], [0.5, 2.0, 100.5]],
        # Scaled 4 along x first (x ∈ [−2, 2]), then turned 90° about y: the long side lies along z.
        [[9.5, 0.0, 98.0], [10.5, 2.0, 102.0]],
        [[19.5, 0.0, 99.5], [20.5, 6.0, 100.5]],
    ]
    for k in range(3):
        np.testing.assert_allclose([boxes[k].min(axis=0), boxes[k].max(axis=0)], expected[k], atol=1e-5)
    assert _volume(scene) == pytest.approx(2.0 + 8.0 + 6.0, rel=1e-5)


def test_a_mirrored_instance_keeps_its_triangles_facing_out(tmp_path):
    b = GltfBuilder()
    node = b.add_node(mesh=_unit_box(b), instances={"TRANSLATION": [[0, 0, 0], [5, 0, 0]],
                                                    "SCALE": [[1, 1, 1], [-1, 1, 1]]})
    scene = load_mesh(b.save(tmp_path / "mirror.glb", roots=[node]))
    # A negative determinant reverses the winding (glTF §3.7.2.1); both boxes enclose +2 m³.
    assert _volume(scene) == pytest.approx(4.0, rel=1e-6)
    centres = scene.vertices[scene.triangles].mean(axis=1)
    outward = np.einsum("ij,ij->i", scene.normals, centres - np.where(centres[:, :1] > 2.5, [5, 1, 0], [0, 1, 0]))
    assert np.all(outward > 0)


def test_a_mesh_shared_by_two_nodes_is_drawn_twice(tmp_path):
    b = GltfBuilder()
    mesh = _unit_box(b)
    roots = [b.add_node(mesh=mesh), b.add_node(mesh=mesh, translation=(0.0, 0.0, -7.0))]
    scene = load_mesh(b.save(tmp_path / "shared.glb", roots=roots))
    assert scene.triangle_count == 24
    np.testing.assert_allclose(scene.bounds, [[-0.5, 0.0, -7.5], [0.5, 2.0, 0.5]], atol=1e-6)


def test_a_node_outside_the_default_scene_is_not_drawn(tmp_path):
    b = GltfBuilder()
    mesh = _unit_box(b)
    b.add_node(mesh=mesh, translation=(50.0, 0.0, 0.0))
    shown = b.add_node(mesh=mesh)
    assert load_mesh(b.save(tmp_path / "hidden.glb", roots=[shown])).triangle_count == 12


def test_the_sun_shines_along_its_nodes_world_minus_z(tmp_path):
    b = GltfBuilder()
    pitch = np.radians(-40.0) / 2  # turned down 40° about +X, under a parent turned 90° about +Y
    sun = b.add_node(light=b.add_light(name="sun"), rotation=[np.sin(pitch), 0.0, 0.0, np.cos(pitch)])
    rig = b.add_node(rotation=HALF_TURN_Y, children=[sun])
    file = b.save(tmp_path / "sun.glb", roots=[b.add_node(mesh=_unit_box(b)), rig])
    found = sun_of(read_gltf(file))
    # −Z turned down by 40°: (0, −sin 40°, −cos 40°); then 90° about +Y: (x, y, z) → (z, y, −x).
    np.testing.assert_allclose(found.direction, [-np.cos(np.radians(40)), -np.sin(np.radians(40)), 0.0], atol=1e-9)
    assert found.name == "sun"


@pytest.mark.parametrize("lights, match", [
    ((), "found none"),
    (("directional", "directional"), "found 2: a, b"),
    (("point",), "found none"),
])
def test_the_sun_must_be_one_directional_light(tmp_path, lights, match):
    b = GltfBuilder()
    roots = [b.add_node(mesh=_unit_box(b))]
    for name, kind in zip("ab", lights):
        roots.append(b.add_node(light=b.add_light(name=name, kind=kind)))
    file = b.save(tmp_path / "lights.glb", roots=roots)
    with pytest.raises(InputError, match=match) as info:
        sun_of(read_gltf(file))
    assert info.value.field == "KHR_lights_punctual" and info.value.file == str(file)


def test_a_nan_position_names_its_accessor(tmp_path):
    b = GltfBuilder()
    points, triangles = box()
    points[3, 1] = np.nan
    file = b.save(tmp_path / "nan.glb", roots=[b.add_node(mesh=b.add_mesh(points, triangles))])
    with pytest.raises(InputError, match="expected finite numbers") as info:
        load_mesh(file)
    assert info.value.field == "accessors[0]" and str(file) in str(info.value)


def test_a_buffer_view_too_short_for_its_accessor_is_refused(tmp_path):
    b = GltfBuilder()
    b.add_mesh(*box())
    b.document.accessors[0].count = 80  # the view holds 8 positions
    file = b.save(tmp_path / "short.gltf", roots=[b.add_node(mesh=0)])
    with pytest.raises(InputError, match="inside bufferViews") as info:
        load_mesh(file)
    assert info.value.field == "accessors[0]"


def test_a_child_index_out_of_range_is_refused(tmp_path):
    b = GltfBuilder()
    node = b.add_node(mesh=_unit_box(b), children=[7])
    with pytest.raises(InputError) as info:
        load_mesh(b.save(tmp_path / "child.glb", roots=[node]))
    assert info.value.field == "nodes[0].children[0]"


def test_vendor_cameras_sample_loads_its_turned_square():
    """Khronos glTF-Sample-Assets Models/Cameras/glTF-Embedded/Cameras.gltf (CC0 1.0)."""
    file = VENDOR / "Cameras.gltf"
    if not file.is_file():
        pytest.skip(f"{file} absent: the vendor files are not committed (tests/data/gltf/vendor/README.md)")
    scene = load_mesh(file)
    # The unit square in z = 0 turned −45° about +X (rotation −0.383, 0, 0, 0.92375): y → (cos, −sin)·y.
    assert scene.triangle_count == 2
    angle = 2 * np.arctan2(0.383, 0.92375)
    np.testing.assert_allclose(scene.bounds, [[0, 0, -np.sin(angle)], [1, np.cos(angle), 0]], atol=1e-6)


def test_strips_and_fans_give_the_specifications_triangles(tmp_path):
    b = GltfBuilder()
    square = np.array([[0, 0, 0], [1, 0, 0], [0, 0, -1], [1, 0, -1]], dtype=float)  # on y = 0, facing +Y
    mesh = b.add_mesh(square, [[0, 1, 2], [3, 0, 0]], name="strip")  # six indices 0 1 2 3 0 0, re-moded below
    b.document.meshes[mesh].primitives[0].mode = 5
    b.document.accessors[b.document.meshes[mesh].primitives[0].indices].count = 4  # strip 0 1 2 3
    fan = b.add_mesh(square[[0, 1, 3, 2]] + [5, 0, 0], [[0, 1, 2], [3, 0, 0]], name="fan")
    b.document.meshes[fan].primitives[0].mode = 6
    b.document.accessors[b.document.meshes[fan].primitives[0].indices].count = 4  # fan 0 1 2 3
    scene = load_mesh(b.save(tmp_path / "strip.glb", roots=[b.add_node(mesh=mesh), b.add_node(mesh=fan)]))
    # Strip (0 1 2), (2 1 3); fan (0 1 2), (0 2 3): four triangles, all counter-clockwise seen from +Y.
    assert scene.triangle_count == 4
    np.testing.assert_allclose(scene.normals, np.tile([0.0, 1.0, 0.0], (4, 1)), atol=1e-12)


def test_a_non_unit_node_rotation_names_the_node(tmp_path):
    b = GltfBuilder()
    node = b.add_node(mesh=_unit_box(b), rotation=[0.0, 0.0, 0.0, 2.0])
    with pytest.raises(InputError, match="expected a unit quaternion") as info:
        load_mesh(b.save(tmp_path / "rotation.glb", roots=[node]))
    assert info.value.field == "nodes[0].rotation"


def _png(rgba) -> bytes:
    from io import BytesIO

    from PIL import Image

    out = BytesIO()
    Image.fromarray(rgba, "RGBA").save(out, format="PNG")
    return out.getvalue()


def test_every_instance_of_a_masked_mesh_keeps_its_mask_and_uv(tmp_path):
    rng = np.random.default_rng(7)
    rgba = rng.integers(0, 256, size=(4, 8, 4), dtype=np.uint8)
    b = GltfBuilder()
    material = b.add_masked_material(_png(rgba), cutoff=0.25, alpha_factor=0.5)
    card = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [2.0, 1.0, 0.0], [0.0, 1.0, 0.0]])  # facing +Z
    uv = np.array([[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]])  # v down the image: the top edge is v = 0
    masked = b.add_node(mesh=b.add_mesh(card, [[0, 1, 2], [0, 2, 3]], uv=uv, material=material), instances={
        "TRANSLATION": [[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [20.0, 0.0, 0.0]],
        "ROTATION": [[0, 0, 0, 1], HALF_TURN_Y, [0, 0, 0, 1]],
        "SCALE": [[1.0, 1.0, 1.0], [1.0, 1.0, 1.0], [-1.0, 1.0, 1.0]]})
    opaque = b.add_node(mesh=_unit_box(b), translation=(0.0, 0.0, 30.0))
    scene = load_mesh(b.save(tmp_path / "cards.glb", roots=[masked, opaque]))
    (mask,) = scene.alpha
    np.testing.assert_allclose(mask.alpha, rgba[..., 3] / 255.0 * 0.5, atol=1e-6)
    assert mask.cutoff == pytest.approx(0.25)
    # Each instance's corners placed by hand: as is; turned 90° about +Y ((x, y, z) → (z, y, −x)); mirrored in x.
    placed = [card, card[:, [2, 1, 0]] * [1, 1, -1] + [10, 0, 0], card * [-1, 1, 1] + [20, 0, 0]]
    card_triangles = scene.vertex_mask[scene.triangles[:, 0]] == 0
    assert card_triangles.sum() == 6 and np.all(scene.vertex_mask[scene.triangles[~card_triangles]] == -1)
    corners = np.unique(scene.triangles[card_triangles])
    for instance, expected in enumerate(placed):
        for corner, position in enumerate(expected):
            (at,) = corners[np.all(np.abs(scene.vertices[corners] - position) < 1e-6, axis=1)]
            assert scene.vertex_mask[at] == 0, (instance, corner)
            np.testing.assert_array_equal(scene.uv[at], uv[corner])


def test_a_mask_cutoff_of_zero_names_the_materials_field(tmp_path):
    b = GltfBuilder()
    material = b.add_masked_material(_png(np.full((2, 2, 4), 255, np.uint8)), cutoff=0.0)
    node = b.add_node(mesh=b.add_mesh(*box(), uv=np.zeros((8, 2)), material=material))
    with pytest.raises(InputError, match=r"expected a number in \(0, 1\]") as info:
        load_mesh(b.save(tmp_path / "cutoff.glb", roots=[node]))
    assert info.value.field == "materials[0].alphaCutoff"


def _edited_gltf(tmp_path, edit) -> Path:
    """A box with a sun on a node, saved as JSON glTF, then ``edit`` applied to its parsed JSON."""
    import json

    b = GltfBuilder()
    file = b.save(tmp_path / "edited.gltf", roots=[b.add_node(mesh=_unit_box(b)),
                                                   b.add_node(light=b.add_light(name="sun"))])
    document = json.loads(file.read_text())
    edit(document)
    file.write_text(json.dumps(document))
    return file


@pytest.mark.parametrize("edit, field, match", [
    (lambda d: d["extensions"].__setitem__("KHR_lights_punctual", [1, 2]), "extensions.KHR_lights_punctual",
     "expected an object, got a list"),
    (lambda d: d["extensions"]["KHR_lights_punctual"].__setitem__("lights", "sun"),
     "extensions.KHR_lights_punctual.lights", "expected a list, got the string 'sun'"),
    (lambda d: d["extensions"]["KHR_lights_punctual"]["lights"].__setitem__(0, 7),
     "extensions.KHR_lights_punctual.lights[0]", "expected an object, got 7"),
    (lambda d: d["nodes"][1]["extensions"]["KHR_lights_punctual"].__setitem__("light", "0"),
     "nodes[1].extensions.KHR_lights_punctual.light", "expected an index into lights in \\[0, 1\\), got the string"),
    (lambda d: d["extensions"]["KHR_lights_punctual"]["lights"][0].__setitem__("type", None),
     "extensions.KHR_lights_punctual.lights[0].type", "expected a light type, got null"),
])
def test_a_lights_extension_of_the_wrong_shape_names_its_key(tmp_path, edit, field, match):
    file = _edited_gltf(tmp_path, edit)
    with pytest.raises(InputError, match=match) as info:
        sun_of(read_gltf(file))
    assert info.value.field == field and info.value.file == str(file)


@pytest.mark.parametrize("edit, field, match", [
    (lambda d: d["nodes"][0].__setitem__("extensions", {"EXT_mesh_gpu_instancing": {"attributes": "T"}}),
     "nodes[0].extensions.EXT_mesh_gpu_instancing.attributes",
     "expected TRANSLATION, ROTATION and/or SCALE accessors, got the string 'T'"),
    (lambda d: d["nodes"][0].__setitem__("extensions", {"EXT_mesh_gpu_instancing": []}),
     "nodes[0].extensions.EXT_mesh_gpu_instancing", "expected an object, got a list"),
    (lambda d: d["nodes"][0].__setitem__("translation", {"x": 1}), "nodes[0].translation",
     "expected 3 finite numbers, got an object"),
    (lambda d: d["meshes"][0]["primitives"][0].__setitem__("attributes", [0]), "meshes[0].primitives[0].attributes",
     "expected an object of vertex attributes, got a list"),
    (lambda d: d["accessors"][0].__setitem__("count", 1e30), "accessors[0].count",
     "expected an element count, got 1e\\+30"),
    (lambda d: d["accessors"][0].__setitem__("count", 10 ** 12), "accessors[0].count", "expected at most"),
    (lambda d: d.__setitem__("nodes", {"0": {}}), "nodes", "expected a list, got an object"),
    (lambda d: d.__setitem__("asset", {"version": 2}), "asset.version", "expected \"2.0\" \\(glTF 2.0\\), got 2"),
])
def test_a_level_of_the_wrong_shape_names_its_key(tmp_path, edit, field, match):
    file = _edited_gltf(tmp_path, edit)
    with pytest.raises(InputError, match=match) as info:
        load_mesh(file)
    assert info.value.field == field and info.value.file == str(file)


def test_a_pathologically_nested_gltf_is_refused_not_recursed_into(tmp_path):
    file = _edited_gltf(tmp_path, lambda d: d.__setitem__("extras", [[[]]]))
    file.write_text(file.read_text().replace("[[[]]]", "[" * 50_000 + "]" * 50_000))
    with pytest.raises(InputError, match="nested at most 64 deep") as info:
        load_mesh(file)
    assert info.value.file == str(file)


def test_instances_beyond_the_triangle_limit_are_refused_before_they_are_placed(tmp_path, monkeypatch):
    import csmlab.scene.gltf as gltf_module

    monkeypatch.setattr(gltf_module, "MAX_TRIANGLES", 30)
    b = GltfBuilder()
    node = b.add_node(mesh=_unit_box(b), instances={"TRANSLATION": [[float(i), 0.0, 0.0] for i in range(3)]})
    with pytest.raises(InputError, match="expected at most 30 triangles in the scene .*, got 36") as info:
        load_mesh(b.save(tmp_path / "many.glb", roots=[node]))
    assert info.value.field == "nodes[0]"
