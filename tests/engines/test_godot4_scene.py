"""A Godot level as its files hold it: the glTF files a ``.tscn`` instances, each placed by its node's transform.

The fixture tests/data/engines/godot4/town/ (written for these tests, after godot-demo-projects' scenes):
``town.tscn`` turns a ``Street`` 90° about +Y and moves it 10 m along +X; under it a pyramid scaled 2 at 5 m
along the street's +Z, and ``props/lamp.tscn`` at 3 m along its −Z, whose ``Post`` lifts a half-size
pyramid 4 m; a ``Hidden`` (``visible = false``) node holds a pyramid that must not count, and ``Marker``
instances one with no transform. The expected points below are worked by hand from Godot's rules: a
``Transform3D`` lists the basis's rows then the origin, a child is placed in its parent's frame, and
an instancing node's ``transform`` replaces the instanced scene root's.
"""

from __future__ import annotations

import numpy as np
import pytest
from engine_cases import DATA

from csmlab.engines.godot4 import gltf_instances
from csmlab.errors import InputError

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
