"""The check of every frame's view: a camera inside geometry, below the ground, or behind a near plane that clips
most of the view is flagged by frame; an experiment warns with the frames named or, asked to, refuses.

Oracles: small analytic scenes where the answer is known by construction — a closed box with
outward normals (inside it every view ray meets a back face), the same box turned inside out (a
room: front faces), a plane with the camera under or over it, a wall a few centimetres in front of
the eye with a 10 cm near plane.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from csmlab.camera import CameraPath
from csmlab.config import load_experiment
from csmlab.errors import InputError
from csmlab.experiment import build_workload
from csmlab.paths.conventions import orientation_from_yaw_pitch_roll
from csmlab.paths.view_check import ViewFindings, check_views, findings_line, frame_ranges
from csmlab.scene.core import Scene
from csmlab.scene.gltf_writer import box, ground
from csmlab.scene.level import Level


def _path(positions, *, yaw=0.0, pitch=0.0, near=0.1) -> CameraPath:
    positions = np.asarray(positions, dtype=np.float64)
    n = len(positions)
    q = orientation_from_yaw_pitch_roll(yaw_deg=np.full(n, yaw), pitch_deg=np.full(n, pitch), roll_deg=np.zeros(n))
    return CameraPath(times=np.arange(n) / 30.0, positions=positions, orientations=q, fov_y_deg=60.0, near=near)


def _box_level(*, inward: bool) -> Level:
    corners, triangles = box((10.0, 4.0, 10.0))
    return Level.of(Scene.from_triangles(corners, triangles[:, ::-1] if inward else triangles))


def test_a_camera_inside_a_closed_solid_is_flagged_and_one_outside_is_not():
    path = _path([[0.0, 2.0, 0.0], [1.0, 1.0, 2.0], [0.0, 2.0, 30.0]])
    findings = check_views(_box_level(inward=False), path)
    assert findings.inside_geometry == (0, 1)


def test_a_camera_in_a_room_modelled_with_inward_normals_is_not_inside_geometry():
    path = _path([[0.0, 2.0, 0.0], [3.0, 1.0, -2.0]], pitch=-10.0)
    assert check_views(_box_level(inward=True), path).clean


def test_a_camera_under_a_ground_plane_is_below_the_ground_and_over_it_is_not():
    points, triangles = ground(half_size=50.0)
    level = Level.of(Scene.from_triangles(points + [0.0, 5.0, 0.0], triangles))
    findings = check_views(level, _path([[0.0, 6.7, 0.0], [0.0, 1.7, 0.0], [3.0, 4.9, 3.0], [0.0, 5.1, 0.0]]))
    assert findings.below_ground == (1, 2)
    assert findings.inside_geometry == () and findings.near_clipped == ()


def test_a_floor_above_the_eye_is_not_ground_when_a_floor_lies_below_it():
    lower, triangles = ground(half_size=20.0)
    upper = lower + [0.0, 3.0, 0.0]
    level = Level.of(Scene.from_triangles(np.concatenate([lower, upper]),
                                          np.concatenate([triangles, triangles + len(lower)])))
    assert check_views(level, _path([[0.0, 1.7, 0.0]])).clean


def test_a_wall_nearer_than_the_near_plane_is_flagged_as_clipping_the_view():
    # A wall facing +Z at z = −0.05 in front of a camera at the origin looking along −Z.
    points, triangles = ground(half_size=20.0)
    wall = np.stack([points[:, 0], points[:, 2], np.full(len(points), -0.05)], axis=1)
    level = Level.of(Scene.from_triangles(wall, triangles[:, ::-1]))
    assert level.first_hits([[0.0, 0.0, 0.0]], [[0.0, 0.0, -1.0]]).facing[0] == 1
    findings = check_views(level, _path([[0.0, 0.0, 0.0], [0.0, 0.0, 2.0]]))
    assert findings.near_clipped == (0,)
    assert findings.inside_geometry == ()


def test_frames_are_named_as_ranges_on_one_line():
    assert frame_ranges([0, 1, 2, 5, 7, 8]) == [(0, 2), (5, 5), (7, 8)]
    findings = ViewFindings(frames=12, inside_geometry=(3, 4, 5, 6, 10), below_ground=(0,))
    line = findings_line(findings.as_dict())
    assert line == ("view check (12 frames): camera inside geometry in frame(s) 3–6, 10; "
                    "camera below the ground in frame(s) 0")
    assert findings_line(ViewFindings(frames=3).as_dict()) is None
    assert json.loads(json.dumps(findings.as_dict()))["inside_geometry"] == [[3, 6], [10, 10]]


def _plane_experiment(tmp_path, check: str, *, fit: str = "false"):
    points, triangles = ground(half_size=30.0)
    lines = [f"v {x} {y + 5.0} {z}" for x, y, z in points] + [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in triangles]
    (tmp_path / "plane.obj").write_text("\n".join(lines) + "\n")
    path = tmp_path / "x.toml"
    path.write_text(f'[scene]\nkind = "mesh"\nfile = "plane.obj"\n[camera]\npath = "pan"\nframes = 4\n'
                    f'width = 32\nheight = 18\nfit_level = {fit}\nview_check = "{check}"\n'
                    '[[methods]]\nname = "exact"\n')
    return path


def test_an_experiment_whose_camera_is_under_the_level_warns_with_the_frames_in_its_workload(tmp_path):
    workload = build_workload(load_experiment(_plane_experiment(tmp_path, "warn")))
    assert workload.views.below_ground == (0, 1, 2, 3)


def test_view_check_refuse_stops_with_an_input_error_naming_the_field_and_frames(tmp_path):
    with pytest.raises(InputError, match=r"camera\.view_check.*camera below the ground in frame\(s\) 0–3"):
        build_workload(load_experiment(_plane_experiment(tmp_path, "refuse")))


def test_a_level_fitted_path_stands_on_the_mesh_level_and_passes_the_check(tmp_path):
    workload = build_workload(load_experiment(_plane_experiment(tmp_path, "refuse", fit="true")))
    np.testing.assert_allclose(workload.path.positions[:, 1], 6.7, atol=1e-4)
    assert workload.views.clean


def test_view_check_off_runs_no_check(tmp_path):
    assert build_workload(load_experiment(_plane_experiment(tmp_path, "off"))).views is None


def test_show_loads_and_checks_the_scene_camera_and_light(tmp_path):
    from typer.testing import CliRunner

    from csmlab.cli import app

    outcome = CliRunner().invoke(app, ["show", str(_plane_experiment(tmp_path, "warn"))])
    assert outcome.exit_code == 0
    assert "# view check (4 frames): camera below the ground in frame(s) 0–3" in outcome.stdout
    assert "# scene: plane.obj, 2 triangles" in outcome.stdout
    refused = CliRunner().invoke(app, ["show", str(_plane_experiment(tmp_path, "refuse"))])
    assert refused.exit_code == 2 and "camera.view_check" in refused.stderr
    experiment = _plane_experiment(tmp_path, "warn")
    (tmp_path / "plane.obj").write_text("v 0 0 0\nv 1 0 0\nf 1 2 3\n")  # a face naming a vertex it lacks
    broken = CliRunner().invoke(app, ["show", str(experiment)])
    assert broken.exit_code == 2 and "plane.obj" in broken.stderr and "Traceback" not in broken.output


def test_a_long_path_is_checked_in_batches_with_the_same_findings(monkeypatch):
    import csmlab.paths.view_check as view_check

    level = _box_level(inward=False)
    positions = [[0.0, 2.0, 0.0] if i % 7 < 3 else [0.0, 2.0, 30.0] for i in range(40)]
    whole = check_views(level, _path(positions))
    monkeypatch.setattr(view_check, "FRAMES_PER_CAST", 6)
    assert check_views(level, _path(positions)) == whole
    assert whole.inside_geometry == tuple(i for i in range(40) if i % 7 < 3)
