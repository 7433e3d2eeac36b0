"""A glTF level as an experiment: the file's sun as the light, its camera's aspect as the image's shape,
and the config fields that only make sense with a glTF file refused elsewhere.

Oracles: the shipped level's sun node as written by data/gltf/make_level.py (35° down, turned 30°
about +Y) evaluated by hand; the image width ``height × aspectRatio``; the fields' documented rules.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from csmlab.config import find_experiment, load_experiment
from csmlab.errors import InputError
from csmlab.experiment import build_workload
from csmlab.scene.gltf_writer import GltfBuilder, box

ROOT = Path(__file__).resolve().parents[1]


def test_shipped_level_takes_its_sun_camera_and_geometry_from_the_one_file():
    experiment = load_experiment(find_experiment("gltf_level"), frames=3)
    workload = build_workload(experiment)
    e, a = np.radians(35.0), np.radians(30.0)
    # −Z pitched down 35° about +X, then turned 30° about +Y: (−sin a cos e, −sin e, −cos a cos e).
    np.testing.assert_allclose(workload.light.direction(0), [-np.sin(a) * np.cos(e), -np.sin(e),
                                                             -np.cos(a) * np.cos(e)], atol=1e-6)
    np.testing.assert_allclose(workload.path.positions[0], [0.0, 1.7, 40.0], atol=1e-5)  # the rig's first key + eye
    assert (workload.path.near, workload.path.far, workload.width) == pytest.approx((0.1, 300.0, 640))
    assert workload.scene.triangle_count == 2 * 8 * 8 + 12 * 32 + 12 * 40  # ground, buildings, fence posts


def test_shipped_level_is_what_its_script_writes(tmp_path):
    from importlib.util import module_from_spec, spec_from_file_location

    spec = spec_from_file_location("make_level", ROOT / "data" / "gltf" / "make_level.py")
    module = module_from_spec(spec)
    spec.loader.exec_module(module)
    written = module.write_level(tmp_path / "level.glb")
    assert written.read_bytes() == (ROOT / "data" / "gltf" / "level.glb").read_bytes()


def _level(tmp_path, *, aspect):
    b = GltfBuilder()
    eye = b.add_node(name="eye", camera=b.add_camera(name="eye", yfov_rad=1.0, znear=0.1, zfar=50.0, aspect=aspect),
                     translation=(0.0, 2.0, 10.0))
    b.add_animation([(eye, "translation", [0.0, 1.0], [[0, 2, 10], [0, 2, 8]], "LINEAR")])
    sun = b.add_node(light=b.add_light(name="sun"), rotation=[-np.sin(np.pi / 4), 0.0, 0.0, np.cos(np.pi / 4)])
    floor = b.add_node(mesh=b.add_mesh(*box((20.0, 1.0, 20.0))))
    return b.save(tmp_path / "level.glb", roots=[floor, sun, eye])


def _experiment(tmp_path, text: str) -> Path:
    path = tmp_path / "x.toml"
    path.write_text(text + '\n[[methods]]\nname = "exact"\n')
    return path


LEVEL = '[scene]\nkind = "mesh"\nfile = "level.glb"\n[camera]\nfile = "level.glb"\nwidth = 32\nheight = 18\n'


def test_the_files_aspect_sets_the_image_width_at_the_configured_height(tmp_path):
    _level(tmp_path, aspect=2.0)
    workload = build_workload(load_experiment(_experiment(tmp_path, LEVEL + "[light]\nfrom_scene = true\n")))
    assert (workload.width, workload.height, workload.path.aspect) == (36, 18, 2.0)
    np.testing.assert_allclose(workload.light.direction(0), [0.0, -1.0, 0.0], atol=1e-6)  # turned 90° down


def test_without_from_scene_the_light_is_the_configured_one(tmp_path):
    _level(tmp_path, aspect=2.0)
    workload = build_workload(load_experiment(_experiment(tmp_path, LEVEL + "[light]\ndirection = [1.0, -1.0, 0.0]\n")))
    np.testing.assert_allclose(workload.light.direction(0), [np.sqrt(0.5), -np.sqrt(0.5), 0.0], atol=1e-12)


@pytest.mark.parametrize("text, field, words", [
    ('[scene]\nkind = "plane_box"\n[camera]\npath = "walk"\n[light]\nfrom_scene = true\n', "light.from_scene",
     "expected a glTF scene"),
    (LEVEL + "[light]\nfrom_scene = true\nelevation_deg = 30.0\n", "light.elevation_deg", "from_scene"),
    ('[camera]\nfile = "path.txt"\ncamera = "eye"\n', "camera.camera", "only with a glTF file"),
    ('[camera]\npath = "walk"\ncamera = "eye"\n', "camera.camera", "only with a recorded file"),
])
def test_gltf_only_fields_are_refused_elsewhere(tmp_path, text, field, words):
    _level(tmp_path, aspect=2.0)
    (tmp_path / "path.txt").write_text("0 0 0 0 0 0 0 1\n1 0 0 1 0 0 0 1\n")
    with pytest.raises(InputError, match=words) as info:
        load_experiment(_experiment(tmp_path, text))
    assert info.value.field == field


def test_a_level_without_a_sun_stops_naming_the_extension(tmp_path):
    b = GltfBuilder()
    eye = b.add_node(name="eye", camera=b.add_camera(name="eye", yfov_rad=1.0, znear=0.1))
    b.add_animation([(eye, "translation", [0.0, 1.0], [[0, 2, 10], [0, 2, 8]], "LINEAR")])
    b.save(tmp_path / "level.glb", roots=[b.add_node(mesh=b.add_mesh(*box())), eye])
    with pytest.raises(InputError, match="one directional light") as info:
        build_workload(load_experiment(_experiment(tmp_path, LEVEL + "[light]\nfrom_scene = true\n")))
    assert info.value.field == "KHR_lights_punctual" and info.value.file == str(tmp_path / "level.glb")


@pytest.mark.parametrize("camera, key", [("", "animations"), ("nobody", "camera")])
def test_a_bad_camera_file_exits_2_with_one_line_naming_the_file_and_key(tmp_path, camera, key):
    from typer.testing import CliRunner

    from csmlab.cli import app

    b = GltfBuilder()
    eye = b.add_node(name="eye", camera=b.add_camera(name="eye", yfov_rad=1.0, znear=0.1))
    b.save(tmp_path / "level.glb", roots=[b.add_node(mesh=b.add_mesh(*box())), eye])
    text = LEVEL + (f'camera = "{camera}"\n' if camera else "")
    outcome = CliRunner().invoke(app, ["run", str(_experiment(tmp_path, text)), "--out", str(tmp_path / "out")])
    assert outcome.exit_code == 2, outcome.output
    message = outcome.stderr.strip()
    assert len(message.splitlines()) == 1 and str(tmp_path / "level.glb") in message and key in message
