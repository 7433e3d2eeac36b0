"""KHR_texture_transform on alpha masks and the rule for alphaMode BLEND casters, with the BLEND warning.

Oracles: the extension's own GLSL (``translation * rotation * scale`` built as column-major ``mat3``
from its README) evaluated with NumPy matrices; the coordinates a masked card is read with, with and
without an offset; the documented rule (``opaque`` keeps BLEND solid, ``masked`` alpha-tests it).
"""

from __future__ import annotations

import io

import numpy as np
import pytest
from PIL import Image

from csmlab.config import load_experiment
from csmlab.documents import Value
from csmlab.errors import InputError
from csmlab.experiment import build_workload
from csmlab.scene.gltf import gltf_scene_triangles, read_gltf
from csmlab.scene.gltf_materials import TEXTURE_TRANSFORM, blend_line, transformed_uv
from csmlab.scene.gltf_writer import GltfBuilder, ground
from csmlab.scene.mesh import load_mesh


def _glsl_matrix(offset, rotation, scale) -> np.ndarray:
    """The README's matrices: GLSL ``mat3(a, b, c, d, e, f, g, h, i)`` has columns (a, b, c), (d, e, f), (g, h, i)."""
    def mat3(*values):
        return np.array(values, dtype=np.float64).reshape(3, 3).T
    c, s = np.cos(rotation), np.sin(rotation)
    translation = mat3(1, 0, 0, 0, 1, 0, offset[0], offset[1], 1)
    turn = mat3(c, s, 0, -s, c, 0, 0, 0, 1)
    scaling = mat3(scale[0], 0, 0, 0, scale[1], 0, 0, 0, 1)
    return translation @ turn @ scaling


def _info(transform) -> Value:
    """A textureInfo object with the transform, as the reader sees it."""
    return Value({"index": 0, "extensions": {TEXTURE_TRANSFORM: transform}}, file="level.gltf", key="tex")


def test_texture_transform_is_the_extensions_glsl_matrix():
    uv = np.random.default_rng(3).uniform(-1.0, 2.0, size=(50, 2))
    transform = {"offset": [0.25, -0.5], "rotation": 0.392699, "scale": [1.5, 0.75]}
    expected = (_glsl_matrix(transform["offset"], transform["rotation"], transform["scale"])
                @ np.c_[uv, np.ones(len(uv))].T).T[:, :2]
    np.testing.assert_allclose(transformed_uv(uv, _info(transform)), expected, atol=1e-12)
    np.testing.assert_array_equal(transformed_uv(uv, _info({})), uv)


def test_a_bad_transform_is_refused_naming_the_key():
    with pytest.raises(InputError) as caught:
        transformed_uv(np.zeros((1, 2)), _info({"scale": [1.0]}))
    assert caught.value.field == "tex.extensions.KHR_texture_transform.scale"


def _half_mask_png() -> bytes:
    """A 2×1 RGBA image: the left texel (u < ½) opaque, the right one clear."""
    image = Image.fromarray(np.array([[[255, 255, 255, 255], [255, 255, 255, 0]]], dtype=np.uint8), "RGBA")
    out = io.BytesIO()
    image.save(out, format="PNG")
    return out.getvalue()


def _card(tmp_path, *, transform=None, mode="MASK", name="leaves"):
    b = GltfBuilder()
    material = b.add_masked_material(_half_mask_png())
    entry = b.document.materials[material]
    entry.name, entry.alphaMode = name, mode
    if transform is not None:
        entry.pbrMetallicRoughness.baseColorTexture.extensions = {TEXTURE_TRANSFORM: transform}
    points, triangles = ground(half_size=1.0)
    uv = np.c_[(points[:, 0] + 1.0) / 4.0, (points[:, 2] + 1.0) / 2.0]  # u in [0, ½]: the opaque texel
    card = b.add_node(mesh=b.add_mesh(points, triangles, uv=uv, material=material))
    return b.save(tmp_path / "card.glb", roots=[card])


def test_a_mask_reads_its_coordinates_through_the_texture_transform(tmp_path):
    plain = gltf_scene_triangles(read_gltf(_card(tmp_path)))[2]["uv"]
    moved = gltf_scene_triangles(read_gltf(_card(tmp_path, transform={"offset": [0.5, 0.0]})))[2]["uv"]
    np.testing.assert_allclose(moved, plain + [0.5, 0.0], atol=1e-7)


@pytest.mark.parametrize("rule, masked", [("opaque", False), ("masked", True)])
def test_blend_materials_cast_solid_or_alpha_tested_by_the_rule(tmp_path, rule, masked):
    scene = load_mesh(_card(tmp_path, mode="BLEND"), blend_casters=rule)
    assert scene.masked is masked
    # Either way the card's mask is kept for a method's own rule ([shadow] blend_casters).
    assert scene.blended and np.all(scene.vertex_blend == 0) and scene.alpha[0].cutoff == 0.5
    assert scene.casters("masked").masked and not scene.casters("opaque").masked


def test_a_mask_material_is_not_marked_blended(tmp_path):
    scene = load_mesh(_card(tmp_path, mode="MASK"))
    assert scene.masked and not scene.blended and scene.vertex_blend is None
    assert scene.casters("none") is scene


def test_the_none_rule_drops_the_blended_triangles_and_keeps_the_others(tmp_path):
    scene = load_mesh(_card(tmp_path, mode="BLEND"), ground=True)
    blended = scene.vertex_blend[scene.triangles[:, 0]] >= 0
    assert blended.sum() == 2 and (~blended).sum() == 2
    casters = scene.casters("none")
    np.testing.assert_array_equal(casters.triangles, scene.triangles[~blended])
    np.testing.assert_array_equal(casters.vertices, scene.vertices)
    with pytest.raises(ValueError, match="blend_casters: expected one of"):
        scene.casters("scene")


def test_a_blend_flag_that_disagrees_with_the_mask_is_refused(tmp_path):
    from dataclasses import replace

    scene = load_mesh(_card(tmp_path, mode="BLEND"), ground=True)
    with pytest.raises(ValueError, match="vertex_blend: expected the three vertices"):
        replace(scene, vertex_blend=np.r_[scene.vertex_blend[:-1], 0])
    with pytest.raises(ValueError, match="vertex_blend: expected"):
        replace(scene, vertex_blend=np.full(len(scene.vertices), 5))
    merged = scene.merged(scene)
    assert merged.vertex_blend.tolist() == scene.vertex_blend.tolist() + [
        b + len(scene.alpha) if b >= 0 else -1 for b in scene.vertex_blend]


def test_a_level_with_blend_materials_names_them_in_its_workload_and_warning(tmp_path):
    _card(tmp_path, mode="BLEND", name="glass")
    path = tmp_path / "x.toml"
    path.write_text('[scene]\nkind = "mesh"\nfile = "card.glb"\n[camera]\npath = "pan"\nframes = 2\nwidth = 32\n'
                    'height = 18\nview_check = "off"\n[[methods]]\nname = "exact"\n')
    note = build_workload(load_experiment(path)).blend
    assert note == {"rule": "opaque", "materials": ["card.glb: glass"]}
    assert blend_line(note).startswith('1 alphaMode BLEND material(s) cast solid ([scene] blend_casters = "opaque"')
    assert blend_line(note).endswith("card.glb: glass")
