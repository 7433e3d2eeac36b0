"""Mesh import against the fixtures' own text: triangle counts, bounds and enclosed volumes worked out
by hand from tests/data/meshes/*, the documented scale and up-axis maps, and every broken-file class."""


import numpy as np
import pytest

from csmlab.errors import InputError
from csmlab.scene import load_mesh, make_scene
from csmlab.scene.alpha_files import read_alpha_mask
from tests.locations import ROOT, TEST_DATA

MESHES = TEST_DATA / "meshes"
REAL_DATA = ROOT / "data" / "meshes"


def _signed_volume(scene) -> float:
    """Volume enclosed by a closed mesh (divergence theorem); positive when wound outward."""
    a, b, c = (scene.vertices[scene.triangles[:, k]] for k in range(3))
    return float(np.einsum("ij,ij->", a, np.cross(b, c)) / 6.0)


# file, triangles after triangulation, bounds, enclosed volume — read off each fixture's text.
VALID = [
    ("pyramid.obj", 6, [[0, 0, 0], [2, 1.5, 3]], 2 * 3 * 1.5 / 3),     # quad base + 4 sides
    ("wedge.ply", 8, [[-1, 0, 0], [1, 2, 4]], 2 * 2 / 2 * 4),           # 2 triangles + 3 quads
    ("tetra.stl", 4, [[0, 0, 0], [1, 1, 1]], 1 / 6),
    ("tetra.vtk", 4, [[0, 0, 0], [3, 2, 1]], 3 * 2 * 1 / 6),            # one volume cell → its surface
    ("pyramid.gltf", 6, [[0, 0, -1], [2, 3, 0]], 2 * 1 * 3 / 3),
    ("pyramid.glb", 6, [[0, 0, -1], [2, 3, 0]], 2 * 1 * 3 / 3),
]


@pytest.mark.parametrize("name, triangles, bounds, volume", VALID)
def test_each_format_gives_the_fixture_triangles_bounds_and_outward_volume(name, triangles, bounds, volume):
    scene = load_mesh(MESHES / name)
    assert scene.triangle_count == triangles
    np.testing.assert_allclose(scene.bounds, bounds, atol=1e-6)
    assert _signed_volume(scene) == pytest.approx(volume, rel=1e-6)
    np.testing.assert_allclose(np.linalg.norm(scene.normals, axis=1), 1.0, atol=1e-12)
    assert scene.name == name


def test_scale_multiplies_and_z_up_maps_x_y_z_to_x_z_minus_y():
    scene = load_mesh(MESHES / "pyramid.obj", scale=2.0, up="z")
    # (x, y, z) ∈ [0, 2] × [0, 1.5] × [0, 3] → 2 (x, z, −y).
    np.testing.assert_allclose(scene.bounds, [[0, 0, -3], [4, 6, 0]], atol=1e-12)
    assert _signed_volume(scene) == pytest.approx(8 * 3.0, rel=1e-9)


def test_ground_adds_a_documented_plane_under_the_mesh():
    bare = load_mesh(MESHES / "wedge.ply")
    scene = load_mesh(MESHES / "wedge.ply", ground=True, albedo=(0.2, 0.3, 0.4))
    assert scene.triangle_count == bare.triangle_count + 2
    plane = scene.vertices[np.unique(scene.triangles[-2:])]
    # Largest side 4 m → 32 m square centred under (0, 2), at the lowest y = 0.
    np.testing.assert_allclose(np.sort(np.unique(plane[:, 0])), [-16, 16])
    np.testing.assert_allclose(np.sort(np.unique(plane[:, 2])), [2 - 16, 2 + 16])
    assert np.all(plane[:, 1] == 0) and np.all(scene.normals[-2:] == [0, 1, 0])
    np.testing.assert_array_equal(scene.albedo[:-2], np.tile(np.float32([0.2, 0.3, 0.4]), (bare.triangle_count, 1)))


def test_make_scene_mesh_reads_the_file_and_ignores_the_seed():
    a = make_scene("mesh", seed=5, file=str(MESHES / "pyramid.obj"), scale=0.5)
    np.testing.assert_allclose(a.bounds, [[0, 0, 0], [1, 0.75, 1.5]])


@pytest.mark.parametrize("name, scale, triangles", [("cornell_box.obj", 0.001, 36), ("teapot.obj", 1.0, 6320),
                                                    ("airplane.ply", 1.0, 2452)])
def test_shared_real_meshes_load_with_their_published_triangle_counts(name, scale, triangles):
    scene = load_mesh(REAL_DATA / name, scale=scale)
    assert scene.triangle_count == triangles
    if name == "cornell_box.obj":
        # The measured box is 556.0 × 548.8 × 559.2 mm.
        np.testing.assert_allclose(scene.bounds, [[0, 0, 0], [0.556, 0.5488, 0.5592]], atol=1e-7)


@pytest.mark.parametrize("name, field", [
    ("nan_vertex.obj", "vertices"),
    ("lines_only.obj", "triangles"),
    ("degenerate.obj", "triangles"),
    ("garbage.obj", "file"),    # VTK returns an empty mesh without complaint
    ("garbage.ply", "file"),    # VTK reports an error and returns an empty mesh
    ("garbage.vtk", "file"),    # PyVista raises
    ("garbage.glb", "file"),
    ("empty.stl", "file"),
    ("missing.obj", "file"),
    ("README.md", "file"),      # a suffix that is not a mesh format
])
def test_every_broken_file_raises_input_error_naming_it_and_prints_nothing(capfd, name, field):
    with pytest.raises(InputError) as info:
        load_mesh(MESHES / name)
    assert info.value.file == str(MESHES / name) and info.value.field == field
    assert str(MESHES / name) in str(info.value) and "expected" in str(info.value)
    out, err = capfd.readouterr()
    assert out == "" and err == ""


def test_a_nan_vertex_in_a_text_file_is_located_by_line():
    with pytest.raises(InputError) as info:
        load_mesh(MESHES / "nan_vertex.obj")
    assert info.value.line == 4 and ":4: vertices: expected finite" in str(info.value)


def test_a_directory_is_not_a_mesh_file():
    with pytest.raises(InputError, match="expected an existing mesh file, found a directory"):
        load_mesh(MESHES)


@pytest.mark.parametrize("keywords, match", [
    (dict(scale=0.0), "^scale: expected"),
    (dict(scale=float("inf")), "^scale: expected"),
    (dict(up="x"), r"^up: expected one of \['y', 'z'\]"),
    (dict(albedo=(1.5, 0.0, 0.0)), "^albedo: expected"),
])
def test_bad_keywords_raise_value_error_naming_the_keyword(keywords, match):
    with pytest.raises(ValueError, match=match):
        load_mesh(MESHES / "pyramid.obj", **keywords)


def _png_header(width: int, height: int) -> bytes:
    """A PNG whose IHDR claims ``width × height`` RGBA texels and holds none (a decompression bomb's header)."""
    import struct
    import zlib

    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 6, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(b"")) + chunk(b"IEND", b""))


def test_an_obj_mask_claiming_30000_squared_texels_is_refused_before_decoding(tmp_path):
    (tmp_path / "bomb.png").write_bytes(_png_header(30000, 30000))
    (tmp_path / "card.mtl").write_text("newmtl leaf\nmap_d bomb.png\n")
    (tmp_path / "card.obj").write_text("mtllib card.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\n"
                                       "usemtl leaf\nf 1/1 2/2 3/3\n")
    with pytest.raises(InputError, match="at most 67,108,864 texels .*900000000 pixels") as info:
        load_mesh(tmp_path / "card.obj")
    assert info.value.file == str(tmp_path / "bomb.png") and info.value.field == "map_d"


def test_a_mask_claiming_more_texels_than_the_limit_but_fewer_than_pillows_is_refused(tmp_path):
    (tmp_path / "big.png").write_bytes(_png_header(9000, 9000))
    with pytest.raises(InputError, match="at most 67,108,864 texels .*9000 × 9000.*, got 81,000,000") as info:
        read_alpha_mask(tmp_path / "big.png", field="alpha_mask")
    assert info.value.file == str(tmp_path / "big.png") and info.value.field == "alpha_mask"


def test_an_mtl_naming_a_map_no_file_system_can_hold_is_a_missing_map(tmp_path):
    (tmp_path / "card.mtl").write_text("newmtl leaf\nmap_d " + "x" * 300 + ".png\n")
    (tmp_path / "card.obj").write_text("mtllib card.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\n"
                                       "vt 0 0\nvt 1 0\nvt 0 1\nusemtl leaf\nf 1/1 2/2 3/3\n")
    with pytest.raises(InputError, match="expected an existing image file") as info:
        load_mesh(tmp_path / "card.obj")
    assert info.value.field == "map_d"


def test_an_obj_face_naming_a_vertex_the_file_lacks_is_refused_at_its_line(tmp_path):
    (tmp_path / "gap.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n")
    with pytest.raises(InputError, match="expected v references in \\[1, 3\\].*got '4'") as info:
        load_mesh(tmp_path / "gap.obj")
    assert (info.value.line, info.value.field) == (4, "f")
    (tmp_path / "relative.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf -3/1 -2/-1 -1/1\n")
    assert load_mesh(tmp_path / "relative.obj").triangle_count == 1


def test_a_vertex_beyond_the_coordinate_limit_is_refused_not_overflowed(tmp_path):
    import warnings

    (tmp_path / "far.obj").write_text("v 0 0 0\nv 1e300 0 0\nv 0 1 0\nf 1 2 3\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        with pytest.raises(InputError, match="within 1e\\+12 m of the origin.*vertex 2") as info:
            load_mesh(tmp_path / "far.obj", scale=1e10)
    assert info.value.field == "vertices"
