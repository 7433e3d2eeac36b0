"""Base-colour textures and the sun's colour in the shaded views, against analytic oracles.

Oracles: a 2×2 checker texture on a quad seen from above — each pixel's texel found from the hit's
world position (the quad's coordinates are linear in x and z), decoded by the sRGB formula
(``colour``'s IEC 61966-2-1), times the file's sun colour and ``n · l`` of its direction; a scene
without textures and a white sun shade to the same bits as before.
"""

from __future__ import annotations

import io

import numpy as np
import pytest
from PIL import Image

from csmlab.camera import CameraPose
from csmlab.errors import InputError
from csmlab.geometry import rotation_looking_at
from csmlab.kernels.texture import textured_albedo
from csmlab.metrics.shading import shaded_rgb, shading_terms
from csmlab.render import prepare_scene, render_view
from csmlab.report import _light
from csmlab.scene.core import ColourTexture, ColourTextures, Scene
from csmlab.scene.gltf import read_gltf, sun_of
from csmlab.scene.gltf_writer import GltfBuilder, ground
from csmlab.scene.mesh import load_mesh
from csmlab.scene.parts import PartPlacement, load_parts

CHECKER = np.array([[[255, 0, 0], [0, 255, 0]], [[0, 0, 255], [200, 100, 50]]], dtype=np.uint8)
"""2×2 sRGB texels: row 0 (v < ½) red, green; row 1 blue, brown."""
SUN_COLOUR = [1.0, 0.5, 0.25]


def _png(texels: np.ndarray) -> bytes:
    out = io.BytesIO()
    Image.fromarray(texels, "RGB").save(out, format="PNG")
    return out.getvalue()


def _srgb_decoded(code) -> np.ndarray:
    """IEC 61966-2-1's decoding of 8-bit codes, written out."""
    c = np.asarray(code, dtype=np.float64) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _textured_level(tmp_path, *, factor=(1.0, 1.0, 1.0), colour=SUN_COLOUR, texels=CHECKER):
    """A 2 m quad on y = 0 with u = (x + 1)/2, v = (z + 1)/2, its checker, and a sun tilted 30° off the vertical."""
    b = GltfBuilder()
    material = b.add_masked_material(_png(texels))
    entry = b.document.materials[material]
    entry.alphaMode, entry.alphaCutoff = "OPAQUE", None
    entry.pbrMetallicRoughness.baseColorFactor = [*factor, 1.0]
    points, triangles = ground(half_size=1.0)
    uv = np.c_[(points[:, 0] + 1.0) / 2.0, (points[:, 2] + 1.0) / 2.0]
    quad = b.add_node(mesh=b.add_mesh(points, triangles, uv=uv, material=material))
    light = b.add_light(name="sun")
    b._lights[light]["color"] = list(colour)
    angle = np.radians(-60.0)  # about +X: the light's −Z turns to (0, −sin 60°, −cos 60°)
    sun = b.add_node(light=light, rotation=[np.sin(angle / 2), 0.0, 0.0, np.cos(angle / 2)])
    return b.save(tmp_path / "checker.glb", roots=[quad, sun])


def _view(scene: Scene, sun, *, width=48, device="cpu"):
    pose = CameraPose(position=np.array([0.0, 3.0, 0.01]), orientation=rotation_looking_at([0.0, -1.0, -0.003]),
                      aspect=1.0, far=20.0)
    return render_view(prepare_scene(scene, device=device), pose, sun.direction, width=width, height=width,
                       reference=False, light_colour=sun.colour)


def test_a_checker_seen_from_above_shades_as_texel_times_sun_colour_times_cosine(tmp_path, device):
    path = _textured_level(tmp_path, factor=(1.0, 0.8, 0.6))
    sun = sun_of(read_gltf(path))
    scene = load_mesh(path)
    assert scene.textured
    view = _view(scene, sun, device=device)
    g = view.gbuffer
    terms = shading_terms(g.albedo, g.normal, light_direction=view.light_direction, light_colour=view.light_colour)
    shaded = shaded_rgb(None, None, np.ones(g.triangle.shape), light_direction=view.light_direction, ambient=0.0,
                        terms=terms)
    u, v = (g.position[..., 0] + 1.0) / 2.0, (g.position[..., 2] + 1.0) / 2.0
    inside = (g.triangle >= 0) & (np.abs(u - 0.5) > 0.01) & (np.abs(v - 0.5) > 0.01)
    texel = CHECKER[(v >= 0.5).astype(int), (u >= 0.5).astype(int)]
    cosine = np.cos(np.radians(30.0))
    expected = _srgb_decoded(texel) * [1.0, 0.8, 0.6] * SUN_COLOUR * cosine
    np.testing.assert_allclose(np.asarray(sun.colour), SUN_COLOUR)
    assert inside.sum() > 500 and {tuple(t) for t in texel[inside]} == {tuple(t) for t in CHECKER.reshape(-1, 3)}
    np.testing.assert_allclose(shaded[inside], expected[inside], rtol=1e-6, atol=1e-7)
    np.testing.assert_array_equal(g.albedo[g.triangle < 0], 0.0)


def test_a_white_light_shades_to_the_same_bits_as_no_colour():
    rng = np.random.default_rng(5)
    albedo, normal = rng.random((6, 7, 3)), rng.normal(size=(6, 7, 3))
    lit = np.where(rng.random((6, 7)) < 0.1, np.nan, rng.random((6, 7)))
    d = [0.2, -1.0, 0.3]
    plain = shaded_rgb(albedo, normal, lit, light_direction=d, ambient=0.25)
    white = shaded_rgb(None, None, lit, light_direction=d, ambient=0.25,
                       terms=shading_terms(albedo, normal, light_direction=d, light_colour=[1.0, 1.0, 1.0]))
    assert plain.tobytes() == white.tobytes()
    red = shaded_rgb(None, None, lit, light_direction=d, ambient=0.25,
                     terms=shading_terms(albedo, normal, light_direction=d, light_colour=[1.0, 0.0, 0.0]))
    np.testing.assert_array_equal(red[..., 1:], albedo[..., 1:] * np.where(np.isnan(lit), np.nan, 0.25)[..., None])
    np.testing.assert_array_equal(red[..., 0], plain[..., 0])


def test_an_untextured_scene_keeps_the_triangle_albedo_bit_for_bit(tmp_path, device):
    path = _textured_level(tmp_path)
    sun = sun_of(read_gltf(path))
    textured = load_mesh(path)
    plain = Scene(textured.vertices, textured.triangles, textured.normals, textured.albedo, name="plain")
    mixed = plain.merged(textured.merged(plain))  # untextured triangles beside textured ones
    g_plain = _view(plain, sun, width=24, device=device).gbuffer
    expected = np.where((g_plain.triangle >= 0)[..., None], plain.albedo[np.maximum(g_plain.triangle, 0)], 0.0)
    assert g_plain.albedo.tobytes() == expected.astype(np.float32).tobytes()
    assert mixed.textured and mixed.colour.vertex_texture.tolist().count(-1) == 2 * len(plain.vertices)
    g_mixed = _view(mixed, sun, width=24, device=device).gbuffer
    corner = mixed.triangles[np.maximum(g_mixed.triangle, 0), 0]
    untextured = (g_mixed.triangle >= 0) & (mixed.colour.vertex_texture[corner] < 0)
    assert untextured.sum() > 100
    assert (g_mixed.albedo[untextured].tobytes()
            == mixed.albedo[g_mixed.triangle[untextured]].astype(np.float32).tobytes())


def test_a_texture_that_is_not_an_image_is_refused_naming_it(tmp_path):
    b = GltfBuilder()
    material = b.add_masked_material(b"not a png")
    b.document.materials[material].alphaMode = "OPAQUE"
    points, triangles = ground(half_size=1.0)
    node = b.add_node(mesh=b.add_mesh(points, triangles, uv=np.zeros((len(points), 2)), material=material))
    with pytest.raises(InputError) as caught:
        load_mesh(b.save(tmp_path / "bad.glb", roots=[node]))
    assert caught.value.field == "images[0]" and "colour texture" in str(caught.value)


def test_colour_textures_refuse_a_triangle_with_two_textures():
    texture = ColourTexture(CHECKER)
    colour = ColourTextures(np.zeros((3, 2)), np.array([0, 0, -1], np.int32), (texture,))
    with pytest.raises(ValueError, match="share a texture"):
        Scene(np.eye(3), [[0, 1, 2]], [[0.577, 0.577, 0.577]], [[0.5, 0.5, 0.5]], colour=colour)


def test_the_report_header_names_the_suns_colour_beside_its_source():
    assert _light({"from_scene": True}, SUN_COLOUR) == (
        "the scene file's sun (KHR_lights_punctual), colour 1, 0.5, 0.25 (linear RGB)")
    assert _light({"from_scene": True}) == "the scene file's sun (KHR_lights_punctual)"


OBJ = """mtllib level.mtl
v -1 0 -1
v 1 0 -1
v 1 0 1
v -1 0 1
v 3 0 -1
v 3 0 1
vt 0 1
vt 1 1
vt 1 0
vt 0 0
usemtl checker
f 1/1 4/4 3/3 2/2
usemtl plain
f 2 3 6 5
"""


def _obj_level(folder, *, mtl: str, leaf: bool = False):
    (folder / "level.obj").write_text(OBJ)
    (folder / "level.mtl").write_text(mtl)
    (folder / "checker.png").write_bytes(_png(CHECKER))
    if leaf:
        rgba = np.full((2, 2, 4), 255, np.uint8)
        out = io.BytesIO()
        Image.fromarray(rgba, "RGBA").save(out, format="PNG")
        (folder / "leaf.png").write_bytes(out.getvalue())
    return folder / "level.obj"


@pytest.mark.parametrize("masked", [False, True])
def test_an_obj_materials_kd_and_map_kd_colour_its_faces(tmp_path, masked, device):
    mtl = ("newmtl checker\nKd 0.5 1 0.25\nmap_Kd checker.png\n" + ("map_d leaf.png\n" if masked else "")
           + "newmtl plain\nKd 0.3\n")
    scene = load_mesh(_obj_level(tmp_path, mtl=mtl, leaf=masked), albedo=(0.6, 0.6, 0.6))
    textured = scene.colour.vertex_texture[scene.triangles[:, 0]] >= 0
    assert textured.sum() == 2 and scene.masked is masked
    np.testing.assert_allclose(scene.albedo[textured], [[0.5, 1.0, 0.25]] * 2)
    np.testing.assert_allclose(scene.albedo[~textured], [[0.3, 0.3, 0.3]] * 2)
    # A hit at (x, z) on the checker quad: vt runs with x and against z (u = (x + 1)/2, vt_v = (1 − z)/2),
    # OBJ's v up the image, so the image row is ⌊(z + 1)/2 · 2⌋.
    x, z = np.meshgrid([-0.5, 0.5], [-0.5, 0.5])
    hit = np.stack([x, np.zeros_like(x), z], axis=-1)
    quad_triangle = np.array([[int(np.flatnonzero(textured)[k])] for k in (0, 1)])
    found = None
    for t in quad_triangle[:, 0]:  # the point lies in one of the quad's two triangles: take each, keep the inside
        albedo = textured_albedo(scene, np.full(x.shape, t, np.int32), hit, device=device)
        found = albedo if found is None else np.where(_inside(scene, t, hit)[..., None], albedo, found)
    texel = CHECKER[((z + 1.0) / 2.0 * 2).astype(int), ((x + 1.0) / 2.0 * 2).astype(int)]
    np.testing.assert_allclose(found, _srgb_decoded(texel) * [0.5, 1.0, 0.25], rtol=1e-6)


def _inside(scene: Scene, t: int, points: np.ndarray) -> np.ndarray:
    """Whether ``points`` on the y = 0 plane lie inside triangle ``t`` (its x, z corners)."""
    a, b, c = scene.vertices[scene.triangles[t]][:, [0, 2]]
    p = points[..., [0, 2]]

    def side(u, v):
        return (v[0] - u[0]) * (p[..., 1] - u[1]) - (v[1] - u[1]) * (p[..., 0] - u[0])
    s = np.stack([side(a, b), side(b, c), side(c, a)])
    return np.all(s >= 0, axis=0) | np.all(s <= 0, axis=0)


def test_a_bad_kd_is_refused_naming_the_mtl_line(tmp_path):
    path = _obj_level(tmp_path, mtl="newmtl checker\nKd 0.5 2 0.25\n")
    with pytest.raises(InputError) as caught:
        load_mesh(path)
    assert caught.value.field == "Kd" and caught.value.line == 2 and str(caught.value.file).endswith("level.mtl")


def test_a_placed_part_keeps_its_texture_where_it_is_placed(tmp_path, device):
    path = _textured_level(tmp_path)
    mirror = ((-1, 0, 0, 0), (0, 1, 0, 0), (0, 0, 1, 0), (0, 0, 0, 1))
    level = load_parts([PartPlacement(file=str(path), translation=(10.0, 0.0, 0.0)),
                        PartPlacement(file=str(path), matrix=mirror)], ground=True)
    assert level.textured and len(level.colour.textures) == 2
    # The mirrored copy (x → −x) at the origin: a hit at (x, z) shows the texel of (−x, z) in the file.
    x, z = np.meshgrid([-0.5, 0.5], [-0.5, 0.5])
    hit = np.stack([x, np.zeros_like(x), z], axis=-1)
    mirrored = np.flatnonzero(level.colour.vertex_texture[level.triangles[:, 0]] == 1)
    found = None
    for t in mirrored:
        albedo = textured_albedo(level, np.full(x.shape, t, np.int32), hit, device=device)
        found = albedo if found is None else np.where(_inside(level, t, hit)[..., None], albedo, found)
    texel = CHECKER[((z + 1.0) / 2.0 * 2).astype(int), ((-x + 1.0) / 2.0 * 2).astype(int)]
    np.testing.assert_allclose(found, _srgb_decoded(texel), rtol=1e-6)
