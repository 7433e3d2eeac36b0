"""A Godot level as its files hold it: the glTF files a ``.tscn`` instances, each placed by its node's transform.

The fixture tests/data/engines/godot4/town/ (written for these tests, after godot-demo-projects' scenes):
``town.tscn`` turns a ``Street`` 90° about +Y and moves it 10 m along +X; under it a pyramid scaled 2 at 5 m
along the street's +Z, and ``props/lamp.tscn`` at 3 m along its −Z, whose ``Post`` lifts a half-size
pyramid 4 m; a ``Hidden`` (``visible = false``) node holds a pyramid that must not count, and ``Marker``
instances one with no transform. The expected points below are worked by hand from Godot's rules: a
``Transform3D`` lists the basis's rows then the origin, a child is placed in its parent's frame, and
an instancing node's ``transform`` replaces the instanced scene root's.

``csmlab import godot4`` writes those instances as ``[[scene.parts]]``: the level it writes is loaded and built, and
its triangles are checked against the same hand-worked points; a level built here with
:class:`~csmlab.scene.gltf_writer.GltfBuilder` (a ``.glb`` crate, mirrored and stretched by its node) adds the
instances csmlab cannot place, which the import lists as not imported.
"""

from __future__ import annotations

import tomllib

import numpy as np
import pytest
from tests.engines.engine_cases import DATA
from typer.testing import CliRunner

from csmlab.cli import app
from csmlab.config import load_experiment
from csmlab.engines.godot4 import gltf_instances
from csmlab.errors import InputError
from csmlab.experiment import build_workload
from csmlab.scene.core import Scene
from csmlab.scene.gltf_writer import GltfBuilder, box

TOWN = DATA / "godot4" / "town"


def _placed(record, point) -> np.ndarray:
    return (record.transform @ np.append(point, 1.0))[:3]


def test_a_scenes_gltf_instances_come_in_file_order_with_their_node_paths_and_files():
    records = gltf_instances(TOWN / "town.tscn")
    assert [r.node for r in records] == ["Street/Pyramid", "Street/Lamp/Post/Bulb", "Marker"]
    assert all(r.file == (TOWN / "props" / "pyramid.gltf").resolve() for r in records)
    assert all(r.transform.shape == (4, 4) and np.array_equal(r.transform[3], [0, 0, 0, 1]) for r in records)


def test_each_instance_is_placed_by_its_own_and_its_ancestors_transforms():
    street, bulb, marker = gltf_instances(TOWN / "town.tscn")
    # Street/Pyramid: (1, 0, 0) scaled 2 → (2, 0, 0); its origin (0, 0, 5) in the street's frame; the street
    # turned +90° about +Y (+X → −Z, +Z → +X) and moved to (10, 0, 0): (15, 0, 0) + (0, 0, −2).
    assert np.allclose(_placed(street, [1, 0, 0]), [15, 0, -2])
    assert np.allclose(_placed(street, [0, 1, 0]), [10 + 5, 2, 0])
    assert np.allclose(_placed(marker, [1, 2, 3]), [1, 2, 3])
    # The lamp at (0, 0, −3) of the street → (7, 0, 0); its post 4 m up; the bulb half size: (0, 0, 2) → (1, 0, 0)
    # after the street's turn.
    assert np.allclose(_placed(bulb, [0, 0, 0]), [7, 4, 0])
    assert np.allclose(_placed(bulb, [0, 0, 2]), [8, 4, 0])


def test_the_instancing_nodes_transform_replaces_the_instanced_scenes_root_transform():
    # lamp.tscn's root sits at (100, 100, 100) in its own file; instanced, the Lamp node's transform wins.
    bulb = gltf_instances(TOWN / "town.tscn")[1]
    assert np.all(np.abs(bulb.transform[:3, 3]) < 50)


def test_a_hidden_subtree_contributes_no_instance():
    assert not any(r.node.startswith("Hidden") for r in gltf_instances(TOWN / "town.tscn"))


HEADER = '[gd_scene format=3]\n\n'
MESH = '[ext_resource type="PackedScene" path="mesh.gltf" id="1"]\n\n[node name="Root" type="Node3D"]\n\n'


@pytest.mark.parametrize("body, field, words", [
    (MESH + '[node name="A" parent="." instance=ExtResource("9")]\n', "A.instance", "id '9'"),
    (MESH + '[node name="A" parent="." instance=ExtResource("1")]\ntransform = Transform3D(1, 0, 0)\n',
     "A.transform", "12 numbers"),
    (MESH + '[node name="A" parent="Nowhere" instance=ExtResource("1")]\n', "Nowhere/A.parent", "'Nowhere'"),
    ('[ext_resource type="PackedScene" path="tree.fbx" id="1"]\n\n[node name="Root" type="Node3D"]\n\n'
     '[node name="A" parent="." instance=ExtResource("1")]\n', "A.instance", ".glb, .gltf"),
    ('[ext_resource type="PackedScene" path="absent.glb" id="1"]\n\n[node name="Root" type="Node3D"]\n\n'
     '[node name="A" parent="." instance=ExtResource("1")]\n', "A.instance", "found none"),
    ('[ext_resource type="PackedScene" path="res://mesh.gltf" id="1"]\n\n[node name="Root" type="Node3D"]\n\n'
     '[node name="A" parent="." instance=ExtResource("1")]\n', "ext_resource.path", "project.godot"),
    ('[ext_resource type="PackedScene" path="level.tscn" id="1"]\n\n[node name="Root" type="Node3D"]\n\n'
     '[node name="A" parent="." instance=ExtResource("1")]\n', "instance", "instance each other"),
])
def test_a_broken_level_names_the_file_and_the_node(tmp_path, body, field, words):
    (tmp_path / "mesh.gltf").write_text((TOWN / "props" / "pyramid.gltf").read_text())
    level = tmp_path / "level.tscn"
    level.write_text(HEADER + body)
    with pytest.raises(InputError) as caught:
        gltf_instances(level)
    assert caught.value.field == field and words in str(caught.value)
    assert caught.value.file == str(level.resolve())


def test_a_file_that_is_no_scene_is_refused(tmp_path):
    path = tmp_path / "notes.tscn"
    path.write_text("hello\n")
    with pytest.raises(InputError, match="gd_scene"):
        gltf_instances(path)


def test_a_scene_can_list_the_instances_csmlab_cannot_read_in_place_of_refusing_them(tmp_path):
    (tmp_path / "mesh.gltf").write_text((TOWN / "props" / "pyramid.gltf").read_text())
    level = tmp_path / "level.tscn"
    level.write_text(HEADER + MESH + '[node name="A" parent="." instance=ExtResource("1")]\n\n'
                     '[ext_resource type="PackedScene" path="tree.fbx" id="2"]\n\n'
                     '[node name="Tree" parent="." instance=ExtResource("2")]\n')
    skipped = []
    assert [r.node for r in gltf_instances(level, skipped=skipped)] == ["A"]
    assert skipped == ["Tree (tree.fbx): csmlab reads glTF (.glb, .gltf) and text scenes (.tscn), not .fbx: export it "
                       "as glTF 2.0"]


def _import(*args):
    outcome = CliRunner().invoke(app, ["import", "godot4", *map(str, args)])
    assert outcome.exit_code == 0, outcome.output
    return outcome.output


def test_import_of_the_town_writes_a_level_whose_triangles_land_where_the_nodes_put_them(tmp_path):
    out = tmp_path / "elsewhere" / "town.toml"
    out.parent.mkdir()
    printed = _import(TOWN / "project.godot", TOWN / "town.tscn", "--out", out)
    assert "level: 3 glTF instance(s)" in printed and "not imported" not in printed
    parts = tomllib.loads(out.read_text())["scene"]["parts"]
    assert all(not part["file"].startswith("/") and (out.parent / part["file"]).resolve() ==
               (TOWN / "props" / "pyramid.gltf").resolve() for part in parts)
    scene = build_workload(load_experiment(out, frames=2)).scene
    assert scene.triangle_count == 3 * 6
    # The pyramid's apex (1, 3, −0.5) and its base corner (0, 0, 0), worked by hand as in the tests above:
    # Street/Pyramid scaled 2, +5 along the street's z, the street turned +90° about +Y and moved +10 along x;
    # the bulb half size, 4 m up, −3 along the street's z; the marker as it is. The hidden pyramid (x = 50) is absent.
    expected = {(14.0, 6.0, -2.0), (15.0, 0.0, 0.0), (6.75, 5.5, -0.5), (7.0, 4.0, 0.0), (1.0, 3.0, -0.5),
                (0.0, 0.0, 0.0)}
    assert expected <= {tuple(p) for p in np.round(scene.vertices, 12).tolist()}
    assert scene.bounds[1, 0] == 15.0
    np.testing.assert_allclose(Scene.from_triangles(scene.vertices, scene.triangles).normals, scene.normals,
                               atol=1e-12)


LEVEL = """[gd_scene format=3]

[ext_resource type="PackedScene" path="res://crate.glb" id="1"]
[ext_resource type="PackedScene" path="res://tree.fbx" id="2"]
[ext_resource type="PackedScene" path="res://gone.glb" id="3"]

[node name="Level" type="Node3D"]

[node name="Crate" parent="." instance=ExtResource("1")]
transform = Transform3D(-2, 0, 0, 0, 1, 0, 0, 0, 1, 5, 0, 0)

[node name="Tree" parent="." instance=ExtResource("2")]

[node name="Flat" parent="." instance=ExtResource("1")]
transform = Transform3D(1, 0, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0)

[node name="Gone" parent="." instance=ExtResource("3")]

[node name="Sun" type="DirectionalLight3D" parent="."]
shadow_enabled = true
"""


def test_import_places_a_mirrored_glb_and_lists_every_instance_it_cannot_place_with_why(tmp_path):
    project = tmp_path / "game"
    project.mkdir()
    (project / "project.godot").write_text("config_version=5\n")
    (project / "tree.fbx").write_bytes(b"Kaydara FBX Binary")
    builder = GltfBuilder()
    corners, triangles = box((1.0, 2.0, 3.0))
    builder.save(project / "crate.glb",
                 roots=[builder.add_node(name="Crate", mesh=builder.add_mesh(corners, triangles))])
    (project / "level.tscn").write_text(LEVEL)
    out = tmp_path / "level.toml"
    printed = " ".join(_import(project / "level.tscn", "--out", out).split())
    assert "level: 1 glTF instance(s)" in printed
    written = out.read_text()
    for node, words in (("Tree (res://tree.fbx)", "not .fbx"), ("Flat (crate.glb)", "a scale of 0"),
                        ("Gone (res://gone.glb)", "no file at")):
        assert f"not imported: {node}" in printed and words in printed
        assert f"# not imported: {node}" in written
    scene = build_workload(load_experiment(out, frames=2)).scene
    # x → 5 − 2x: the 1 × 2 × 3 box's x in [−0.5, 0.5] lands in [4, 6]; the mirror keeps its faces outward.
    expected = {(5.0 - 2.0 * x, y, z) for x, y, z in corners.tolist()}
    assert {tuple(p) for p in scene.vertices.tolist()} == expected
    outward = np.einsum("ij,ij->i", scene.normals, scene.vertices[scene.triangles].mean(axis=1) - [5.0, 1.0, 0.0])
    assert scene.triangle_count == 12 and np.all(outward > 0)
