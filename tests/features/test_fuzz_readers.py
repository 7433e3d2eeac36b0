"""Every reader of a user's file, fuzzed: each variant of a shipped fixture loads or exits 2 naming the file.

The good files are the shipped fixtures (data/gltf/level.glb, data/meshes/cornell_box.obj,
tests/data/meshes/pyramid.gltf, tests/data/paths/*) and files the project's own writers make from
them (the TUM fixture as csmlab CSV and JSON, nerfstudio and an animated glTF camera; a masked card
as OBJ + MTL + PNG and as glTF). :func:`tests.fuzzing.fuzz_reader` draws the variants (seeded, a
fixed number per reader) and fails on any exception other than an InputError naming a file of the
variant's folder. Each test also checks that both outcomes occur where a reader has both — a
fuzzer whose variants all load, or all fail, tests nothing.
"""

from __future__ import annotations

import json
import os
from io import BytesIO
from pathlib import Path

import numpy as np
import pytest

from csmlab.paths.formats import read_path, write_path
from csmlab.scene import load_mesh
from csmlab.scene.alpha_files import read_alpha_mask
from csmlab.scene.gltf import read_gltf, sun_of
from csmlab.scene.gltf_writer import GltfBuilder, box
from tests.fuzzing import byte_variants, fuzz_reader, glb_variants, json_variants, text_variants
from tests.locations import ROOT

pytestmark = [pytest.mark.fuzz, pytest.mark.slow]

PATHS = ROOT / "tests" / "data" / "paths"
EXAMPLES = int(os.environ.get("CSMLAB_FUZZ_EXAMPLES", "40"))
"""Variants per reader: 40 runs the module in about 20 s; ``CSMLAB_FUZZ_EXAMPLES=1000`` searches deeper."""
TRIED: dict[str, int] = {}
"""Variants tried per reader, filled as the tests run (printed with ``-s``, reported in the issue's note)."""


def _fuzzed(name: str, read, files: dict[str, bytes], target: str, variants, *, examples: int = EXAMPLES,
            both: bool = True):
    counts = fuzz_reader(read, files, target, variants, examples=examples)
    TRIED[name] = sum(counts.values())
    print(f"fuzz {name}: {TRIED[name]} variants, {counts['loaded']} loaded, {counts['refused']} refused (exit 2)")
    assert TRIED[name] >= examples // 2
    if both:
        assert counts["loaded"] and counts["refused"], counts
    return counts


def _png(alpha: np.ndarray) -> bytes:
    from PIL import Image

    rgba = np.zeros(alpha.shape + (4,), np.uint8)
    rgba[..., 3] = alpha
    buffer = BytesIO()
    Image.fromarray(rgba, "RGBA").save(buffer, format="PNG")
    return buffer.getvalue()


LEAF = _png(np.tile(np.array([[0, 255], [255, 0]], np.uint8), (4, 4)))
CARD_OBJ = ("mtllib card.mtl\nv -1 0 -1\nv 1 0 -1\nv 1 0 1\nv -1 0 1\nv -1 1 0\nv 1 1 0\nv 1 2 0\nv -1 2 0\n"
            "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nusemtl ground\nf 1 4 3 2\nusemtl leaf\nf 5/1 6/2 7/3 8/4\n")
CARD_MTL = "newmtl ground\nKd 0.5 0.5 0.5\nnewmtl leaf\nKd 0.2 0.5 0.1\nmap_d leaf.png\n"


def _tum_as(format: str, suffix: str, tmp_path: Path) -> dict[str, bytes]:
    """The shipped TUM fixture written by csmlab's own writer in ``format``: ``path<suffix>`` and its companions."""
    rows = [line.split() for line in (PATHS / "tum_fr1_xyz_head.txt").read_text().splitlines()
            if line.strip() and not line.startswith("#")]
    # Times from 0: a glTF keeps them as float32, which cannot tell 1.3e9 s stamps 10 ms apart.
    start = float(rows[0][0])
    source = tmp_path / "source" / "tum.txt"
    source.parent.mkdir()
    source.write_text("".join(" ".join([repr(float(r[0]) - start)] + r[1:]) + "\n" for r in rows))
    path = read_path(source, format="tum", convention="tum")
    out = tmp_path / "out"
    out.mkdir()
    write_path(path, out / f"path{suffix}", format=format)
    return {file.name: file.read_bytes() for file in out.iterdir()}


def test_fuzzed_gltf_levels_load_or_exit_2_naming_the_file():
    level = (ROOT / "data" / "gltf" / "level.glb").read_bytes()
    _fuzzed("glTF level (load_mesh, GLB)", load_mesh, {"level.glb": level}, "level.glb", glb_variants(level))
    pyramid = json.loads((ROOT / "tests" / "data" / "meshes" / "pyramid.gltf").read_text())
    _fuzzed("glTF level (load_mesh, JSON)", load_mesh, {"pyramid.gltf": b""}, "pyramid.gltf", json_variants(pyramid))


def test_fuzzed_gltf_suns_load_or_exit_2_naming_the_file():
    level = (ROOT / "data" / "gltf" / "level.glb").read_bytes()
    _fuzzed("glTF KHR_lights_punctual sun", lambda p: sun_of(read_gltf(p)), {"level.glb": level}, "level.glb",
            glb_variants(level))


def test_fuzzed_gltf_camera_paths_load_or_exit_2_naming_the_file():
    level = (ROOT / "data" / "gltf" / "level.glb").read_bytes()
    _fuzzed("glTF animated camera (level.glb)", lambda p: read_path(p, format="gltf", camera="eye"),
            {"level.glb": level}, "level.glb", glb_variants(level))


def test_fuzzed_masked_gltf_cards_load_or_exit_2_naming_the_file(tmp_path):
    builder = GltfBuilder()
    points, triangles = box((1.0, 1.0, 0.1))
    uv = points[:, :2] - points[:, :2].min(axis=0)
    card = builder.add_mesh(points, triangles, uv=uv, material=builder.add_masked_material(LEAF, cutoff=0.4))
    file = builder.save(tmp_path / "card.gltf", roots=[builder.add_node(mesh=card)])
    document = json.loads(file.read_text())
    _fuzzed("glTF MASK material and texture", load_mesh, {"card.gltf": b""}, "card.gltf", json_variants(document))


def test_fuzzed_obj_and_mtl_files_load_or_exit_2_naming_the_file():
    cornell = (ROOT / "data" / "meshes" / "cornell_box.obj").read_text()
    _fuzzed("OBJ (cornell_box.obj)", load_mesh, {"cornell_box.obj": b""}, "cornell_box.obj", text_variants(cornell))
    files = {"card.obj": CARD_OBJ.encode(), "card.mtl": CARD_MTL.encode(), "leaf.png": LEAF}
    _fuzzed("OBJ with map_d", load_mesh, files, "card.obj", text_variants(CARD_OBJ))
    # A broken MTL leaves its materials without maps (as viewers draw them): every variant loads.
    _fuzzed("MTL", lambda p: load_mesh(p.parent / "card.obj"), files, "card.mtl", text_variants(CARD_MTL), both=False)


def test_fuzzed_mask_images_load_or_exit_2_naming_the_file():
    _fuzzed("mask image (PNG)", read_alpha_mask, {"leaf.png": LEAF}, "leaf.png", byte_variants(LEAF))


@pytest.mark.parametrize("name, format, suffix, kind", [
    ("TUM", "tum", ".txt", "text"),
    ("EuRoC", "euroc", ".csv", "text"),
    ("csmlab CSV", "csv", ".csv", "text"),
    ("csmlab JSON", "json", ".json", "json"),
    ("nerfstudio", "nerfstudio", ".json", "json"),
    ("glTF camera (written)", "gltf", ".gltf", "json"),
])
def test_fuzzed_path_files_load_or_exit_2_naming_the_file(tmp_path, name, format, suffix, kind):
    files = _tum_as(format, suffix, tmp_path)
    good = files[f"path{suffix}"]
    variants = (text_variants(good.decode("utf-8")) if kind == "text"
                else json_variants(json.loads(good)))
    options = {"camera": "camera"} if format == "gltf" else {}
    _fuzzed(f"path: {name}", lambda p: read_path(p, format=format, **options), files, f"path{suffix}", variants)


def test_fuzzed_shipped_path_fixtures_load_or_exit_2_naming_the_file():
    for fixture, options in (("tum_fr2_desk_orbslam_head.txt", {"format": "tum"}),
                             ("euroc_v102_head.csv", {"format": "euroc"}),
                             ("csmlab_quaternion.csv", {}),
                             ("kitti_00_head.txt", {"format": "kitti", "fps": 10.0})):
        text = (PATHS / fixture).read_text()
        _fuzzed(f"path fixture {fixture}", lambda p, options=options: read_path(p, **options), {fixture: b""}, fixture,
                text_variants(text), examples=EXAMPLES // 2)
    document = json.loads((PATHS / "csmlab_yaw_pitch_roll.json").read_text())
    _fuzzed("path fixture csmlab_yaw_pitch_roll.json", read_path, {"p.json": b""}, "p.json", json_variants(document),
            examples=EXAMPLES // 2)
    times = (PATHS / "kitti_00_head_times.txt").read_text()
    poses = (PATHS / "kitti_00_head.txt").read_bytes()
    _fuzzed("KITTI times file", lambda p: read_path(p.parent / "poses.txt", format="kitti", times_file=p),
            {"poses.txt": poses, "times.txt": b""}, "times.txt", text_variants(times), examples=EXAMPLES // 2)


def _gltf_with_signalling_nan(tmp_path: Path) -> bytes:
    builder = GltfBuilder()
    points, triangles = box((1.0, 1.0, 1.0))
    points = points.astype(np.float32)
    points.view(np.uint32)[2, 1] = 0x7F800001  # a signalling NaN: casting it to float64 raises "invalid"
    return builder.save(tmp_path / "snan.glb", roots=[builder.add_node(mesh=builder.add_mesh(points, triangles))]
                        ).read_bytes()


def test_variants_a_deeper_search_found_load_or_exit_2(tmp_path):
    """What ``CSMLAB_FUZZ_EXAMPLES=300 CSMLAB_FUZZ_SEED=1`` found beyond the seeded run, kept as fixed variants."""
    from hypothesis import strategies as st

    pose = '{"time": 0, "x": 0, "y": 0, "z": 0, "qx": 1e308, "qy": 0, "qz": 0, "qw": 1}'
    rotation = "[1e308, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]"
    cornell = (ROOT / "data" / "meshes" / "cornell_box.obj").read_bytes()
    cases = [
        ("csmlab JSON, a huge quaternion component", "p.json", {}, f'{{"poses": [{pose}]}}'.encode()),
        ("nerfstudio, a huge matrix entry", "p.json", {"format": "nerfstudio"},
         f'{{"render_width": 2, "render_height": 1, "seconds": 1, "camera_path": [{{"camera_to_world": {rotation}, '
         f'"fov": 60}}]}}'.encode()),
        ("EuRoC, a stamp beyond 64 bits", "p.csv", {"format": "euroc"}, b"#timestamp,x,y,z,qw,qx,qy,qz\n"
                                                                      + b"9" * 40 + b",0,0,0,1,0,0,0\n"),
    ]
    for name, file, options, data in cases:
        counts = _fuzzed(f"found: {name}", lambda p, options=options: read_path(p, **options), {file: data}, file,
                         st.sampled_from([data]), examples=1, both=False)
        assert counts == {"refused": 1}, name
    # An undecodable byte in a material name: VTK keeps that material's coordinates under no name.
    broken = cornell.replace(b"o tall_block\nusemtl white\n", b"o tall_block\nusemtl white\xff\n")
    assert broken != cornell
    _fuzzed("found: OBJ, an undecodable material name", load_mesh, {"c.obj": broken}, "c.obj",
            st.sampled_from([broken]), examples=1, both=False)
    card = {"card.obj": CARD_OBJ.encode(), "leaf.png": LEAF}
    mtl = CARD_MTL.replace("map_d leaf.png", "map_d \x00").encode()
    counts = _fuzzed("found: MTL, a map_d named by a NUL byte", lambda p: load_mesh(p.parent / "card.obj"),
                     {**card, "card.mtl": mtl}, "card.mtl", st.sampled_from([mtl]), examples=1, both=False)
    assert counts == {"refused": 1}
    times = b"0\n-0\n" + b"".join(b"%d\n" % k for k in range(1, 29))  # one per pose of the 30
    counts = _fuzzed("found: KITTI times file, a repeated time", lambda p: read_path(
        p.parent / "poses.txt", format="kitti", times_file=p),
        {"poses.txt": (PATHS / "kitti_00_head.txt").read_bytes()}, "times.txt", st.sampled_from([times]), examples=1,
        both=False)
    assert counts == {"refused": 1}
    snan = _gltf_with_signalling_nan(tmp_path)
    counts = _fuzzed("found: glTF, a signalling NaN", load_mesh, {"s.glb": snan}, "s.glb", st.sampled_from([snan]),
                     examples=1, both=False)
    assert counts == {"refused": 1}
