"""A level of several files placed by transforms (``[[scene.parts]]``).

Oracles: the transform written out by hand for a turn of 90° about one axis (exact images of the
unit axes), the normals recomputed from the placed winding by :meth:`Scene.from_triangles`, and the
loader's documented refusals.
"""

from __future__ import annotations

import numpy as np
import pytest

from csmlab.config import experiment_toml, load_experiment
from csmlab.errors import InputError
from csmlab.experiment import build_workload
from csmlab.scene.core import Scene
from csmlab.scene.gltf_writer import box, ground
from csmlab.scene.parts import PartPlacement, load_parts, rotation_from_degrees


def _obj(path, points, triangles):
    lines = [f"v {float(x)!r} {float(y)!r} {float(z)!r}" for x, y, z in points] + [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in triangles]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_rotations_turn_about_x_then_y_then_z():
    np.testing.assert_allclose(rotation_from_degrees((90.0, 0.0, 0.0)) @ [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(rotation_from_degrees((0.0, 90.0, 0.0)) @ [0.0, 0.0, 1.0], [1.0, 0.0, 0.0], atol=1e-12)
    # X first, then Z: +Y → +Z (about X) → +Z (about Z leaves it).
    np.testing.assert_allclose(rotation_from_degrees((90.0, 0.0, 90.0)) @ [0.0, 1.0, 0.0], [0.0, 0.0, 1.0],
                               atol=1e-12)
    np.testing.assert_allclose(rotation_from_degrees((90.0, 0.0, 90.0)) @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0],
                               atol=1e-12)


def test_parts_are_scaled_turned_and_moved_and_their_normals_follow_the_winding(tmp_path):
    corners, triangles = box((1.0, 2.0, 3.0))
    part = _obj(tmp_path / "box.obj", corners, triangles)
    floor_points, floor_triangles = ground(half_size=10.0)
    floor = _obj(tmp_path / "floor.obj", floor_points, floor_triangles)
    placement = PartPlacement(file=str(part), translation=(5.0, 0.0, -2.0), rotation_deg=(0.0, 90.0, 0.0), scale=2.0)
    level = load_parts([placement], file=str(floor))
    placed = level.vertices[len(floor_points):]
    # Turned 90° about +Y: (x, y, z) → (z, y, −x); scaled by 2 first, moved last.
    expected = np.stack([2.0 * corners[:, 2], 2.0 * corners[:, 1], -2.0 * corners[:, 0]], axis=1) + [5.0, 0.0, -2.0]
    np.testing.assert_allclose(placed, expected, atol=1e-12)
    recomputed = Scene.from_triangles(level.vertices, level.triangles)
    np.testing.assert_allclose(level.normals, recomputed.normals, atol=1e-12)
    assert level.triangle_count == len(floor_triangles) + len(triangles)


def _experiment(tmp_path, parts: str, *, scene_extra: str = "") -> object:
    corners, triangles = box((2.0, 2.0, 2.0))
    _obj(tmp_path / "house.obj", corners, triangles)
    points, tris = ground(half_size=30.0)
    _obj(tmp_path / "terrain.obj", points, tris)
    path = tmp_path / "level.toml"
    path.write_text(f'[scene]\nkind = "mesh"\n{scene_extra}\n{parts}\n[camera]\npath = "walk"\nframes = 3\n'
                    'width = 32\nheight = 18\n[[methods]]\nname = "exact"\n')
    return path


PARTS = ('[[scene.parts]]\nfile = "terrain.obj"\n'
         '[[scene.parts]]\nfile = "house.obj"\ntranslation = [8.0, 0.0, 3.0]\nrotation_deg = [0.0, 45.0, 0.0]\n'
         '[[scene.parts]]\nfile = "house.obj"\ntranslation = [-8.0, 0.0, 3.0]\nscale = 1.5\n')


def test_an_experiment_of_several_files_builds_one_level_and_writes_its_parts_back(tmp_path):
    experiment = load_experiment(_experiment(tmp_path, PARTS))
    assert [p.file.rsplit("/", 1)[-1] for p in experiment.scene.parts] == ["terrain.obj", "house.obj", "house.obj"]
    workload = build_workload(experiment)
    assert workload.scene.triangle_count == 2 + 12 + 12
    np.testing.assert_allclose(workload.scene.bounds[1, 1], 3.0)  # the scaled house: 2 m × 1.5
    written = tmp_path / "written.toml"
    written.write_text(experiment_toml(experiment))
    assert load_experiment(written).scene.parts == experiment.scene.parts


def test_a_missing_part_file_is_refused_naming_the_part(tmp_path):
    text = PARTS + '[[scene.parts]]\nfile = "nowhere.obj"\n'
    with pytest.raises(InputError, match=r"scene\.parts\[3\]\.file.*expected an existing file"):
        load_experiment(_experiment(tmp_path, text))


def test_parts_are_refused_on_a_procedural_scene_and_bad_transforms_name_their_field(tmp_path):
    path = tmp_path / "x.toml"
    path.write_text('[scene]\nkind = "terrain"\n[[scene.parts]]\nfile = "a.obj"\n[camera]\npath = "walk"\n'
                    '[[methods]]\nname = "exact"\n')
    with pytest.raises(InputError, match=r"scene\.parts.*only with kind = \"mesh\""):
        load_experiment(path)
    bad = '[[scene.parts]]\nfile = "house.obj"\nscale = -1.0\n'
    with pytest.raises(InputError, match=r"scene\.parts\[0\]\.scale"):
        load_experiment(_experiment(tmp_path, bad))
    bad = '[[scene.parts]]\nfile = "house.obj"\ntranslation = [1.0, 2.0]\n'
    with pytest.raises(InputError, match=r"scene\.parts\[0\]\.translation"):
        load_experiment(_experiment(tmp_path, bad))


ROOT = __import__("pathlib").Path(__file__).resolve().parents[1]


def test_the_shipped_terrain_window_is_what_its_script_writes(tmp_path):
    from importlib.util import module_from_spec, spec_from_file_location

    spec = spec_from_file_location("make_patch", ROOT / "data" / "meshes" / "make_jacksboro_patch.py")
    module = module_from_spec(spec)
    spec.loader.exec_module(module)
    written = module.write_patch(tmp_path / "patch.obj")
    assert written.read_bytes() == (ROOT / "data" / "meshes" / "jacksboro_patch.obj").read_bytes()


def test_the_level_of_parts_gets_a_walk_on_its_ground_and_the_unfitted_walk_is_flagged_under_it():
    from csmlab.config import find_experiment
    from csmlab.paths import make_path
    from csmlab.paths.view_check import check_views
    from csmlab.scene.level import Level

    workload = build_workload(load_experiment(find_experiment("level_parts"), frames=12))
    assert len(load_experiment(find_experiment("level_parts")).scene.parts) == 6
    level = Level.of(workload.scene)
    ground = level.ground_heights(workload.path.positions[:, 0], workload.path.positions[:, 2])
    np.testing.assert_allclose(workload.path.positions[:, 1] - ground, 1.7, atol=0.031)  # eye height ± head bob
    assert workload.views.clean
    unfitted = check_views(level, make_path("walk", frames=12))
    assert unfitted.below_ground == tuple(range(12))
