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
from tests.locations import ROOT


def _obj(path, points, triangles):
    lines = ([f"v {float(x)!r} {float(y)!r} {float(z)!r}" for x, y, z in points]
             + [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in triangles])
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


# --- parts placed by a 4×4 matrix -------------------------------------------------------------------------------------

# The triangle of the plane x + y + z = 1, wound so its normal is +(1, 1, 1)/√3.
SLANT = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])


def _affine(linear, translation=(0.0, 0.0, 0.0)) -> tuple:
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = linear, translation
    return tuple(tuple(float(v) for v in row) for row in m)


@pytest.mark.parametrize("linear, translation, corners, normal", [
    # x stretched 2×: the plane x/2 + y + z = 1, normal ∝ (1/2, 1, 1) → (1, 2, 2)/3 (A n would give (2, 1, 1)).
    ([[2, 0, 0], [0, 1, 0], [0, 0, 1]], (0, 0, 0), [[2, 0, 0], [0, 1, 0], [0, 0, 1]], [1 / 3, 2 / 3, 2 / 3]),
    # x' = x + y (shear), then moved by (1, 2, 3): edges (0, 1, 0) and (−1, 0, 1) from the first corner, normal
    # their cross product (1, 0, 1)/√2.
    ([[1, 1, 0], [0, 1, 0], [0, 0, 1]], (1, 2, 3), [[2, 2, 3], [2, 3, 3], [1, 2, 4]],
     [2 ** -0.5, 0, 2 ** -0.5]),
])
def test_a_matrix_shears_and_stretches_points_and_turns_normals_by_the_inverse_transpose(
        tmp_path, linear, translation, corners, normal):
    part = _obj(tmp_path / "slant.obj", SLANT, [(0, 1, 2)])
    level = load_parts([PartPlacement(file=str(part), matrix=_affine(linear, translation))])
    np.testing.assert_allclose(level.vertices[level.triangles[0]], corners, atol=1e-12)
    np.testing.assert_allclose(level.normals[0], normal, atol=1e-12)
    np.testing.assert_allclose(Scene.from_triangles(level.vertices, level.triangles).normals, level.normals,
                               atol=1e-12)


def test_a_mirroring_matrix_swaps_the_winding_so_faces_and_normals_still_point_outward(tmp_path):
    part = _obj(tmp_path / "slant.obj", SLANT, [(0, 1, 2)])
    mirror = _affine(np.diag([-1.0, 1.0, 1.0]), (4.0, 0.0, 0.0))
    level = load_parts([PartPlacement(file=str(part), matrix=mirror)])
    # x → 4 − x: the corners (3, 0, 0), (4, 1, 0), (4, 0, 1); the face's normal mirrored, (−1, 1, 1)/√3.
    assert {tuple(p) for p in level.vertices[level.triangles[0]].tolist()} == {(3, 0, 0), (4, 1, 0), (4, 0, 1)}
    np.testing.assert_allclose(level.normals[0], np.array([-1.0, 1.0, 1.0]) / 3 ** 0.5, atol=1e-12)
    np.testing.assert_allclose(Scene.from_triangles(level.vertices, level.triangles).normals, level.normals,
                               atol=1e-12)
    # A closed box mirrored and sheared: every face still faces away from the box's centre.
    corners, triangles = box((1.0, 2.0, 3.0))
    level = load_parts([PartPlacement(file=str(_obj(tmp_path / "box.obj", corners, triangles)),
                                      matrix=_affine([[-1.0, 0.5, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 2.0]]))])
    centre = level.vertices.mean(axis=0)
    outward = np.einsum("ij,ij->i", level.normals, level.vertices[level.triangles].mean(axis=1) - centre)
    assert np.all(outward > 0)
    np.testing.assert_allclose(Scene.from_triangles(level.vertices, level.triangles).normals, level.normals,
                               atol=1e-12)


def test_a_part_placed_by_translation_rotation_scale_and_by_the_same_matrix_is_the_same_scene(tmp_path):
    corners, triangles = box((1.0, 2.0, 3.0))
    part = str(_obj(tmp_path / "box.obj", corners, triangles))
    t, r, s = (3.5, -1.25, 7.0), (10.0, -35.0, 70.0), 1.7
    by_trs = load_parts([PartPlacement(file=part, translation=t, rotation_deg=r, scale=s)])
    by_matrix = load_parts([PartPlacement(file=part, matrix=_affine(s * rotation_from_degrees(r), t))])
    assert np.array_equal(by_trs.triangles, by_matrix.triangles)
    # (s p) Rᵀ and p (s R)ᵀ round differently: within 1 ulp of the part's size.
    spacing = np.spacing(np.abs(by_trs.vertices).max())
    assert np.abs(by_trs.vertices - by_matrix.vertices).max() <= spacing
    np.testing.assert_array_max_ulp(by_trs.normals, by_matrix.normals, maxulp=4)


MATRIX = '[[0.0, 0.0, 2.0, 5.0], [0.0, 2.0, 0.0, 0.0], [-2.0, 0.0, 0.0, -2.0], [0.0, 0.0, 0.0, 1.0]]'


def test_an_experiment_with_a_matrix_part_builds_its_level_and_writes_the_matrix_back(tmp_path):
    experiment = load_experiment(_experiment(tmp_path, f'[[scene.parts]]\nfile = "house.obj"\nmatrix = {MATRIX}\n'))
    assert experiment.scene.parts[0].matrix[2] == (-2.0, 0.0, 0.0, -2.0)
    scene = build_workload(experiment).scene
    # The 2 m house turned 90° about +Y (x → −z), doubled and moved to (5, 0, −2): x in [3, 7], z in [−4, 0].
    np.testing.assert_allclose(scene.bounds, [[3.0, 0.0, -4.0], [7.0, 4.0, 0.0]], atol=1e-12)
    written = tmp_path / "written.toml"
    written.write_text(experiment_toml(experiment))
    assert load_experiment(written).scene.parts == experiment.scene.parts


@pytest.mark.parametrize("part, words", [
    (f"matrix = {MATRIX}\nscale = 2.0\n", "either matrix or translation"),
    ("matrix = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 1.0, 0.0, 1.0]]\n",
     "last row"),
    ("matrix = [[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]\n",
     "non-singular"),
    ("matrix = [[1.0, 0.0, 0.0, nan], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]\n",
     "finite"),
    ("matrix = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]\n", "a list of 4 lists of 4 numbers"),
])
def test_a_bad_matrix_is_refused_naming_the_part_and_what_was_expected(tmp_path, part, words):
    with pytest.raises(InputError, match=r"scene\.parts\[0\]\.matrix") as caught:
        load_experiment(_experiment(tmp_path, f'[[scene.parts]]\nfile = "house.obj"\n{part}'))
    assert words in str(caught.value)
