"""Alpha-tested casters: the depth pass, the camera pass and the reference cut the same holes, against NumPy oracles."""

from __future__ import annotations

import numpy as np
import pytest

from csmlab.camera import CameraPose
from typer.testing import CliRunner

from csmlab.cli import app
from csmlab.geometry import rotation_looking_at
from csmlab.kernels.alpha import masked_mesh, no_masks
from csmlab.kernels.raster import light_space_mesh, rasterize_cascades, rasterize_depth
from csmlab.kernels.reference import hard_shadow
from csmlab.kernels.visibility import camera_hits, mesh_bvh
from csmlab.scene import make_scene
from csmlab.scene.core import AlphaMask, Scene

BITS = 8
UNIT = 2**BITS


def nearest_texel(alpha: np.ndarray, u, v) -> np.ndarray:
    """The oracle's point sampling: texel ``(⌊v·H⌋, ⌊u·W⌋)`` of coordinates repeated into [0, 1)."""
    h, w = alpha.shape
    i = np.minimum(((u - np.floor(u)) * w).astype(int), w - 1)
    j = np.minimum(((v - np.floor(v)) * h).astype(int), h - 1)
    return alpha[j, i]


def near_texel_edge(alpha: np.ndarray, u, v, eps: float = 1e-6) -> np.ndarray:
    """Coordinates within ``eps`` texels of a texel's edge, where float rounding may pick either neighbour."""
    h, w = alpha.shape
    fu, fv = (u - np.floor(u)) * w, (v - np.floor(v)) * h
    return (np.abs(fu - np.rint(fu)) < eps) | (np.abs(fv - np.rint(fv)) < eps)


def random_mask(seed: int, shape=(8, 8)) -> np.ndarray:
    return (np.random.default_rng(seed).random(shape) < 0.5).astype(np.float32)


def quad_in_fixed_point(rng, count: int, resolution: int):
    """``count`` random quads (two triangles each, own vertices) in fixed point with coordinates (0..1)."""
    lo = rng.uniform(1.0, resolution - 12.0, (count, 2))
    size = rng.uniform(2.0, 11.0, (count, 2))
    zero = np.zeros(count)
    corners = np.stack([lo, lo + np.stack([size[:, 0], zero], 1), lo + size, lo + np.stack([zero, size[:, 1]], 1)],
                       axis=1)
    points = np.rint(corners.reshape(-1, 2) * UNIT).astype(np.int64)
    depth = rng.uniform(1.0, 5.0, points.shape[0])
    base = 4 * np.arange(count)[:, None, None]
    triangles = (base + np.array([[0, 1, 2], [0, 2, 3]])[None]).reshape(-1, 3)
    uv = np.tile(np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]), (count, 1))
    return points, depth, triangles, uv


def test_a_mask_of_all_ones_rasterizes_the_opaque_quads_bit_for_bit(device):
    rng = np.random.default_rng(3)
    points, depth, triangles, uv = quad_in_fixed_point(rng, 40, 64)
    # Some triangles masked, some opaque, in one mesh: all ones must change nothing.
    vertex_mask = np.where(np.arange(points.shape[0]) // 4 % 3 == 0, -1, 0).astype(np.int32)
    ones = masked_mesh(uv, vertex_mask, (AlphaMask(np.ones((8, 8), np.float32)),), device=device)
    opaque, opaque_count = rasterize_depth(points[None], depth, triangles, resolution=64, bits=BITS, device=device)
    masked, masked_count = rasterize_depth(points[None], depth, triangles, resolution=64, bits=BITS, masks=ones,
                                           device=device)
    assert np.isfinite(opaque).sum() > 500
    np.testing.assert_array_equal(masked, opaque)
    assert masked_count == opaque_count
    # The culled kernels (the render's path) from light-space metres: the same, bit for bit.
    xy = points.astype(np.float64) / UNIT * 0.25
    size = np.array([[0.25, 0.25]])
    plain = light_space_mesh(xy, depth, triangles)
    with_masks = light_space_mesh(xy, depth, triangles, uv=uv, vertex_mask=vertex_mask,
                                  alpha=(AlphaMask(np.ones((8, 8), np.float32)),))
    a, count_a = rasterize_cascades(plain, texel_size=size, origin=np.zeros((1, 2), np.int64), resolution=64,
                                    bits=BITS, device=device)
    b, count_b = rasterize_cascades(with_masks, texel_size=size, origin=np.zeros((1, 2), np.int64), resolution=64,
                                    bits=BITS, device=device)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(a, opaque)
    np.testing.assert_array_equal(count_a, count_b)


def test_a_masked_quad_covers_exactly_the_texels_its_mask_keeps(device):
    """Every texel centre inside an axis-aligned quad is kept where the mask's nearest texel at its
    analytic coordinates is opaque, and only there; coverage counts every centre inside."""
    alpha = random_mask(5)
    x0, y0, side = 3.25, 4.75, 40.0  # no texel centre on an edge
    corners = np.array([[x0, y0], [x0 + side, y0], [x0 + side, y0 + side], [x0, y0 + side]])
    points = np.rint(corners * UNIT).astype(np.int64)
    uv = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    masks = masked_mesh(uv, np.zeros(4, np.int32), (AlphaMask(alpha, 0.5),), device=device)
    triangles = np.array([[0, 1, 2], [0, 2, 3]])
    depth, count = rasterize_depth(points[None], np.full(4, 2.0), triangles, resolution=48, bits=BITS, masks=masks,
                                   device=device)
    j, i = np.mgrid[0:48, 0:48]
    cx, cy = i + 0.5, j + 0.5
    inside = (cx > x0) & (cx < x0 + side) & (cy > y0) & (cy < y0 + side)
    u, v = (cx - x0) / side, (cy - y0) / side
    kept = inside & (nearest_texel(alpha, u, v) >= 0.5)
    doubtful = inside & near_texel_edge(alpha, u, v)
    assert count == inside.sum()
    np.testing.assert_array_equal(np.isfinite(depth[0])[~doubtful], kept[~doubtful])
    assert 0.3 < kept.sum() / inside.sum() < 0.7


def masked_quad_over_ground(alpha, *, cutoff=0.5):
    """A 20 m ground at y = 0 and a 4 m masked quad 2 m above it, coordinates (0..1) over its x and z."""
    ground = Scene.from_triangles([[-10, 0, -10], [10, 0, -10], [10, 0, 10], [-10, 0, 10]], [[0, 2, 1], [0, 3, 2]])
    quad_v = np.array([[-2.0, 2.0, -2.0], [2.0, 2.0, -2.0], [2.0, 2.0, 2.0], [-2.0, 2.0, 2.0]])
    tri = np.array([[0, 2, 1], [0, 3, 2]])
    cross = np.cross(quad_v[tri[:, 1]] - quad_v[tri[:, 0]], quad_v[tri[:, 2]] - quad_v[tri[:, 0]])
    quad = Scene(quad_v, tri, cross / np.linalg.norm(cross, axis=1, keepdims=True), np.full((2, 3), 0.5, np.float32),
                 uv=np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]), vertex_mask=np.zeros(4, np.int32),
                 alpha=(AlphaMask(alpha, cutoff),))
    return ground.merged(quad)


@pytest.mark.parametrize("method", ["irregular", "ray"])
def test_a_masked_quads_shadow_is_its_masks_footprint(method, device):
    alpha = random_mask(7)
    scene = masked_quad_over_ground(alpha)
    bvh = mesh_bvh(scene.vertices, scene.triangles, uv=scene.uv, vertex_mask=scene.vertex_mask, alpha=scene.alpha,
                   device=device)
    light = np.array([0.3, -1.0, 0.2])
    light /= np.linalg.norm(light)
    rng = np.random.default_rng(1)
    points = np.column_stack([rng.uniform(-4, 6, 4000), np.zeros(4000), rng.uniform(-4, 6, 4000)])
    normals = np.tile([0.0, 1.0, 0.0], (4000, 1)).astype(np.float32)
    lit = hard_shadow(bvh, points=points, normals=normals, light_direction=light, method=method)
    # Oracle: the point moved toward the light to the quad's plane y = 2, its coordinates there.
    at = points - light * (2.0 / -light[1])
    u, v = (at[:, 0] + 2.0) / 4.0, (at[:, 2] + 2.0) / 4.0
    over = (u > 0) & (u < 1) & (v > 0) & (v < 1)
    shadowed = over & (nearest_texel(alpha, u, v) >= 0.5)
    clear = ~(near_texel_edge(alpha, u, v, eps=1e-4) | (np.abs(u) < 1e-4) | (np.abs(u - 1) < 1e-4)
              | (np.abs(v) < 1e-4) | (np.abs(v - 1) < 1e-4))
    np.testing.assert_array_equal(lit[clear] == 0.0, shadowed[clear])
    assert 0.2 < shadowed.sum() / over.sum() < 0.8


def test_the_camera_sees_through_a_masks_holes_and_the_ray_method_refuses_masks(device):
    alpha = random_mask(11)
    scene = masked_quad_over_ground(alpha)
    bvh = mesh_bvh(scene.vertices, scene.triangles, uv=scene.uv, vertex_mask=scene.vertex_mask, alpha=scene.alpha,
                   device=device)
    pose = CameraPose(position=np.array([0.0, 8.0, 0.5]), orientation=rotation_looking_at([0.0, -1.0, -0.05]),
                      aspect=1.0, far=50.0)
    args = dict(position=pose.position, rotation=pose.rotation, fov_y_deg=pose.fov_y_deg, aspect=1.0, far=50.0,
                width=64, height=64)
    hits = camera_hits(bvh, **args)
    quad = hits.triangle >= 2
    ground = (hits.triangle >= 0) & ~quad
    # Oracle: each pixel's ray meets the plane y = 2 at coordinates (u, v); opaque there → the quad.
    rows, cols = np.mgrid[0:64, 0:64]
    tan = np.tan(np.radians(pose.fov_y_deg) / 2.0)
    x = ((cols + 0.5) / 64 * 2 - 1) * tan
    y = (1 - (rows + 0.5) / 64 * 2) * tan
    direction = pose.rotation @ np.stack([x, y, -np.ones_like(x)], axis=-1)[..., None]
    direction = direction[..., 0]
    s = (2.0 - pose.position[1]) / direction[..., 1]
    at = pose.position + direction * s[..., None]
    u, v = (at[..., 0] + 2.0) / 4.0, (at[..., 2] + 2.0) / 4.0
    over = (u > 0.01) & (u < 0.99) & (v > 0.01) & (v < 0.99) & ~near_texel_edge(alpha, u, v, eps=1e-3)
    opaque = nearest_texel(alpha, u, v) >= 0.5
    assert np.all(quad[over & opaque]) and np.all(ground[over & ~opaque])
    assert (over & ~opaque).sum() > 100 and (over & opaque).sum() > 100
    with pytest.raises(ValueError, match="alpha masks"):
        camera_hits(bvh, method="ray", **args)


def test_the_foliage_scene_is_seeded_and_holds_leaf_and_chain_link_masks():
    a, b = make_scene("foliage", seed=4), make_scene("foliage", seed=4)
    np.testing.assert_array_equal(a.vertices, b.vertices)
    np.testing.assert_array_equal(a.alpha[0].alpha, b.alpha[0].alpha)
    assert not np.array_equal(make_scene("foliage", seed=5).vertices, a.vertices)
    assert a.masked and [m.source for m in a.alpha] == ["foliage leaf", "foliage chain-link"]
    # Each triangle's three vertices share a mask (the record checks it); both masks are used.
    used = set(np.unique(a.vertex_mask[a.triangles[:, 0]]))
    assert used == {-1, 0, 1}


def test_a_leaf_mask_file_that_cannot_be_read_exits_2_naming_it(tmp_path):
    bad = tmp_path / "leaf.png"
    bad.write_bytes(b"not a png at all")
    exp = tmp_path / "exp.toml"
    exp.write_text(f'extends = ["scenes/foliage", "paths/walk", "methods/exact"]\n[scene]\nleaf_mask_file = "{bad}"\n'
                   '[camera]\nframes = 2\nwidth = 32\nheight = 18\n[shadow]\nresolution = 64\n')
    outcome = CliRunner().invoke(app, ["run", str(exp), "--out", str(tmp_path / "out")])
    assert outcome.exit_code == 2, outcome.output
    message = outcome.stderr.strip()
    assert len(message.splitlines()) == 1 and str(bad) in message and "scene.leaf_mask_file" in message
    assert not (tmp_path / "out" / "metrics.csv").exists()


CARD_OBJ = """mtllib card.mtl
v -1 0 -1
v 1 0 -1
v 1 0 1
v -1 0 1
v -1 1 0
v 1 1 0
v 1 2 0
v -1 2 0
vt 0 0
vt 1 0
vt 1 1
vt 0 1
usemtl ground
f 1 4 3 2
usemtl leaf
f 5/1 6/2 7/3 8/4
"""
CARD_MTL = "newmtl ground\nKd 0.5 0.5 0.5\nnewmtl leaf\nKd 0.2 0.5 0.1\nmap_d leaf.png\n"


def write_card(folder, png: bytes | None):
    (folder / "card.obj").write_text(CARD_OBJ)
    (folder / "card.mtl").write_text(CARD_MTL)
    if png is not None:
        (folder / "leaf.png").write_bytes(png)


def test_an_obj_materials_map_d_becomes_the_alpha_mask_of_its_faces(tmp_path):
    from io import BytesIO

    from PIL import Image

    rgba = np.zeros((4, 8, 4), np.uint8)
    rgba[..., 3] = random_mask(3, (4, 8)) * 255
    buffer = BytesIO()
    Image.fromarray(rgba, "RGBA").save(buffer, format="PNG")
    write_card(tmp_path, buffer.getvalue())
    scene = make_scene("mesh", file=tmp_path / "card.obj")
    (mask,) = scene.alpha
    np.testing.assert_array_equal(mask.alpha, rgba[..., 3] / 255.0)
    assert mask.cutoff == 0.5
    card = scene.vertex_mask[scene.triangles[:, 0]] == 0
    assert card.sum() == 2 and np.all(scene.vertex_mask[scene.triangles[~card]] == -1)
    # OBJ's v runs up the image: the corner at vt (0, 0) (the card's bottom left, y = 1) samples the image's
    # last row, v = 1 here.
    corners = scene.triangles[card].reshape(-1)
    bottom_left = corners[np.all(scene.vertices[corners] == [-1.0, 1.0, 0.0], axis=1)][0]
    np.testing.assert_array_equal(scene.uv[bottom_left], [0.0, 1.0])


def test_an_obj_map_d_that_cannot_be_read_exits_2_naming_it(tmp_path):
    write_card(tmp_path, b"GIF89a broken")
    exp = tmp_path / "exp.toml"
    exp.write_text(f'extends = ["paths/walk", "methods/exact"]\n[scene]\nkind = "mesh"\n'
                   f'file = "{tmp_path / "card.obj"}"\n'
                   '[camera]\nframes = 2\nwidth = 32\nheight = 18\n[shadow]\nresolution = 64\n')
    outcome = CliRunner().invoke(app, ["run", str(exp), "--out", str(tmp_path / "out")])
    assert outcome.exit_code == 2, outcome.output
    message = outcome.stderr.strip()
    assert len(message.splitlines()) == 1 and "leaf.png" in message and "map_d" in message


def gltf_card(image_uri: str) -> str:
    """A glTF of an opaque ground quad and, under a node moved 1 m up, a card of a MASK material (cutoff 0.3)."""
    import base64
    import json

    positions = np.array([[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1], [-1, 0, 0], [1, 0, 0], [1, 1, 0], [-1, 1, 0]],
                         np.float32)
    uv = np.array([[0, 1], [1, 1], [1, 0], [0, 0]], np.float32)
    indices = np.array([0, 2, 1, 0, 3, 2], np.uint16)
    blob = positions.tobytes() + uv.tobytes() + indices.tobytes()
    views = [dict(buffer=0, byteOffset=0, byteLength=96), dict(buffer=0, byteOffset=96, byteLength=32),
             dict(buffer=0, byteOffset=128, byteLength=12)]
    accessors = [dict(bufferView=0, componentType=5126, count=4, type="VEC3"),
                 dict(bufferView=0, byteOffset=48, componentType=5126, count=4, type="VEC3"),
                 dict(bufferView=1, componentType=5126, count=4, type="VEC2"),
                 dict(bufferView=2, componentType=5123, count=6, type="SCALAR")]
    gltf = dict(asset=dict(version="2.0"), scene=0, scenes=[dict(nodes=[0, 1])],
                nodes=[dict(mesh=0), dict(mesh=1, translation=[0.0, 1.0, 0.0])],
                meshes=[dict(primitives=[dict(attributes=dict(POSITION=0), indices=3, material=0)]),
                        dict(primitives=[dict(attributes=dict(POSITION=1, TEXCOORD_0=2), indices=3, material=1)])],
                materials=[dict(), dict(alphaMode="MASK", alphaCutoff=0.3,
                                        pbrMetallicRoughness=dict(baseColorTexture=dict(index=0)))],
                textures=[dict(source=0)], images=[dict(uri=image_uri)],
                buffers=[dict(byteLength=len(blob), uri="data:application/octet-stream;base64,"
                              + base64.b64encode(blob).decode())], bufferViews=views, accessors=accessors)
    return json.dumps(gltf)


def test_a_gltf_mask_materials_base_colour_alpha_cuts_its_primitives(tmp_path):

    from PIL import Image

    rgba = np.full((4, 4, 4), 255, np.uint8)
    rgba[..., 3] = (random_mask(8, (4, 4)) * 255).astype(np.uint8)
    Image.fromarray(rgba, "RGBA").save(tmp_path / "leaf.png")
    (tmp_path / "card.gltf").write_text(gltf_card("leaf.png"))
    scene = make_scene("mesh", file=tmp_path / "card.gltf")
    (mask,) = scene.alpha
    np.testing.assert_array_equal(mask.alpha, rgba[..., 3] / 255.0)
    assert mask.cutoff == pytest.approx(0.3)
    card = scene.vertex_mask[scene.triangles[:, 0]] == 0
    assert card.sum() == 2 and (~card).sum() == 2
    # The node's translation moves the card 1 m up; glTF's coordinates are kept as they are (v down).
    corners = scene.triangles[card].reshape(-1)
    assert scene.vertices[corners, 1].min() == 1.0 and scene.vertices[corners, 1].max() == 2.0
    top_left = corners[np.all(scene.vertices[corners] == [-1.0, 2.0, 0.0], axis=1)][0]
    np.testing.assert_array_equal(scene.uv[top_left], [0.0, 0.0])


def test_a_gltf_mask_image_that_cannot_be_read_exits_2_naming_it(tmp_path):
    (tmp_path / "leaf.png").write_bytes(b"\x89PNG broken")
    (tmp_path / "card.gltf").write_text(gltf_card("leaf.png"))
    exp = tmp_path / "exp.toml"
    exp.write_text(f'extends = ["paths/walk", "methods/exact"]\n[scene]\nkind = "mesh"\n'
                   f'file = "{tmp_path / "card.gltf"}"\n[camera]\nframes = 2\nwidth = 32\nheight = 18\n'
                   '[shadow]\nresolution = 64\n')
    outcome = CliRunner().invoke(app, ["run", str(exp), "--out", str(tmp_path / "out")])
    assert outcome.exit_code == 2, outcome.output
    message = outcome.stderr.strip()
    assert len(message.splitlines()) == 1 and "leaf.png" in message and "images" in message


@pytest.mark.parametrize("device, message", [("tpu", "device: expected 'cpu' or 'cuda'"),
                                             ("cuda:99", "device: .*'cuda:99'")])
def test_masked_mesh_and_no_masks_refuse_a_device_warp_cannot_use_by_name(device, message):
    with pytest.raises(ValueError, match=message):
        masked_mesh(np.zeros((3, 2)), np.zeros(3, np.int32), (AlphaMask(np.ones((2, 2), np.float32)),), device=device)
    with pytest.raises(ValueError, match=message):
        no_masks(device=device)
