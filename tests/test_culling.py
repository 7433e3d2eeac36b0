"""Face culling in the depth pass ([shadow] cull): OpenGL's glCullFace in the light's view, on the host."""

import numpy as np
import pytest

from csmlab.camera import CameraPose
from csmlab.culling import CULL_METHODS, culled_triangles, front_facing
from csmlab.geometry import rotation_looking_at
from csmlab.light import direction_from_angles
from csmlab.scene.core import Scene
from csmlab.settings import ShadowSettings

LIGHT = direction_from_angles(elevation_deg=60.0, azimuth_deg=30.0)


def test_front_facing_is_a_counter_clockwise_front_turned_toward_the_light():
    # Written out, not from csmlab: OpenGL's window area of (a, b, c) seen along d is positive
    # (front-facing under glFrontFace(GL_CCW)) when the right-handed normal (b - a) x (c - a) points
    # back at the light, n . d < 0; zero area (edge-on) is back-facing.
    vertices = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    up = [0, 1, 2]            # (0,0,1) x (1,0,0) = (0, 1, 0): faces +Y
    down = [0, 2, 1]          # faces -Y
    wall = [0, 2, 3]          # faces +Z: edge-on to a light straight down
    down_light = np.array([0.0, -1.0, 0.0])
    assert front_facing(vertices, np.array([up, down, wall]), down_light).tolist() == [True, False, False]
    tris = np.array([up, down, wall])
    assert culled_triangles(vertices, tris, down_light, "back").tolist() == [up]
    assert culled_triangles(vertices, tris, down_light, "front").tolist() == [down, wall]
    assert culled_triangles(vertices, tris, down_light, "none") is tris
    assert set(CULL_METHODS) == {"none", "back", "front"}
    with pytest.raises(ValueError, match="cull"):
        culled_triangles(vertices, tris, down_light, "both")


HEIGHT = 8.0
"""The quad's height: its footprint lies HEIGHT·tan(30°) = 4.6 m from below it, clear of its 3 m side."""
FOOTPRINT = HEIGHT * np.array([LIGHT[0], 0.0, LIGHT[2]]) / -LIGHT[1]


def _ground_and_quad(*, quad_faces_up: bool) -> Scene:
    """A 60 m ground facing up (triangles 0, 1) and a 3 m square quad HEIGHT above it facing up or down."""
    ground = np.array([[-30.0, 0.0, -30.0], [30.0, 0.0, -30.0], [30.0, 0.0, 30.0], [-30.0, 0.0, 30.0]])
    quad = np.array([[-1.5, HEIGHT, -1.5], [1.5, HEIGHT, -1.5], [1.5, HEIGHT, 1.5], [-1.5, HEIGHT, 1.5]])
    up = np.array([[0, 3, 2], [0, 2, 1]])   # counter-clockwise seen from +Y
    quad_tris = up + 4 if quad_faces_up else up[:, ::-1] + 4
    return Scene.from_triangles(np.concatenate([ground, quad]), np.concatenate([up, quad_tris]))


def _ground_shadow(scene: Scene, cull: str, **fields):
    """``(lit, reference)`` at the ground pixels of a camera looking straight down on the quad's footprint
    (the quad itself out of its view): the hard shadow map's and the ray cast's."""
    from csmlab.render import render_frame

    pose = CameraPose(position=FOOTPRINT + [0.0, 14.0, 0.0], orientation=rotation_looking_at((0.0, -1.0, 0.0)),
                      aspect=4.0 / 3.0)
    settings = ShadowSettings(cascades=1, resolution=512, shadow_distance=20.0, filter="none", bias_constant=0.05,
                              bias_slope=0.0, normal_offset=0.0, receiver_plane_bias=False, cull=cull, **fields)
    frame = render_frame(scene, pose, LIGHT, settings, width=160, height=120)
    ground = (frame.view.gbuffer.hits.triangle >= 0) & (frame.view.gbuffer.hits.triangle < 2) \
        & (frame.shadow.cascade >= 0)
    assert ground.sum() > 15000
    return frame.shadow.lit[ground], frame.view.reference[ground]


@pytest.mark.parametrize("fields", [{}, {"depth_range": "slice", "depth_clamp": False}],
                         ids=["culled_kernels", "host_snapped"])
@pytest.mark.parametrize("quad_faces_up", [True, False], ids=["quad_faces_light", "quad_faces_away"])
def test_a_quad_casts_its_footprint_only_under_the_cull_that_keeps_it(quad_faces_up, fields):
    # The light comes from above: an up-facing quad is front-facing, kept by "back" (and "none"),
    # dropped by "front"; a down-facing one the other way round. The ray cast sees both sides, so
    # its shadow is the quad's footprint on the ground whatever the winding.
    scene = _ground_and_quad(quad_faces_up=quad_faces_up)
    keeps, drops = ("back", "front") if quad_faces_up else ("front", "back")
    for cull in ("none", keeps):
        lit, reference = _ground_shadow(scene, cull, **fields)
        shadowed = reference == 0.0
        assert shadowed.sum() > 300, "the footprint should cover part of the ground"
        # Agreement but at the footprint's edge (texels of ~8 cm, pixels of ~13 cm).
        assert np.mean(lit == reference) > 0.99, (cull, np.mean(lit == reference))
        assert np.mean(lit[shadowed] == 0.0) > 0.9
    lit, reference = _ground_shadow(scene, drops, **fields)
    assert (reference == 0.0).sum() > 300
    assert np.all(lit == 1.0), f"cull = {drops!r} should leave the ground wholly lit"


@pytest.mark.parametrize("fields", [{}, {"depth_range": "slice", "depth_clamp": False}],
                         ids=["culled_kernels", "host_snapped"])
def test_no_culling_stores_the_nearer_of_the_two_culled_maps_bit_for_bit(fields):
    # Each texel stores the nearest covering triangle: the map of both windings is the minimum of
    # the map of the front faces and that of the back faces, bit for bit, on both raster paths.
    from csmlab.camera import CameraPose
    from csmlab.cascades import build_cascades
    from csmlab.render import prepare_scene, shadow_maps
    from csmlab.scene import make_scene

    dscene = prepare_scene(make_scene("plane_box", box_center=(6.0, 4.0)))
    pose = CameraPose(position=(0.0, 3.0, 0.0), orientation=rotation_looking_at((0.3, -0.4, -1.0)), aspect=1.5)
    maps = {}
    for cull in ("none", "back", "front"):
        settings = ShadowSettings(cascades=2, resolution=128, shadow_distance=40.0, cull=cull, **fields).validated()
        cascades = build_cascades(pose=pose, light_direction=LIGHT, scene_corners=dscene.corners, settings=settings)
        maps[cull] = shadow_maps(dscene, cascades, settings).depth
    assert np.isfinite(maps["back"]).sum() > np.isfinite(maps["front"]).sum() > 0
    assert np.array_equal(maps["none"], np.minimum(maps["back"], maps["front"]))


def test_a_settings_object_refuses_an_unknown_cull():
    assert ShadowSettings().cull == "none"
    with pytest.raises(ValueError, match="^cull: expected one of"):
        ShadowSettings(cull="both").validated()


@pytest.mark.parametrize("kind", ["plane_box", "terrain", "city", "fence"])
def test_procedural_scenes_wind_closed_shapes_outward_and_the_ground_up(kind):
    # Culling reads the winding, so the generators' must be glTF's: counter-clockwise seen from
    # outside. Each connected piece is either closed (every edge shared by two triangles: a box,
    # prism, cone or icosahedron, all convex) with every normal pointing away from its centroid,
    # or the open ground, every normal up.
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    from csmlab.scene import make_scene

    scene = make_scene(kind)
    v, t = scene.vertices, scene.triangles.astype(np.int64)
    n = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    rows = np.repeat(np.arange(len(t)), 3)
    graph = coo_matrix((np.ones(rows.size), (rows, len(t) + t.reshape(-1))), shape=(len(t) + len(v),) * 2)
    _, label = connected_components(graph, directed=False)
    piece = label[:len(t)]
    edges = np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1)
    _, edge_id, uses = np.unique(edges, axis=0, return_inverse=True, return_counts=True)
    open_piece = np.zeros(label.max() + 1, dtype=bool)
    open_piece[np.tile(piece, 3)[uses[edge_id.reshape(-1)] != 2]] = True
    closed = ~open_piece[piece]
    centre = (v[t[:, 0]] + v[t[:, 1]] + v[t[:, 2]]) / 3.0
    count = np.bincount(piece, minlength=label.max() + 1)[:, None]
    piece_centre = np.stack([np.bincount(piece, weights=centre[:, k], minlength=len(count)) for k in range(3)],
                            axis=1) / np.maximum(count, 1)
    outward = np.einsum("ij,ij->i", n, centre - piece_centre[piece]) > 0.0
    assert closed.sum() > 0 and (~closed).sum() > 0
    assert np.all(outward[closed]), f"{kind}: {np.sum(~outward[closed])} closed-shape triangles face inward"
    assert np.all(n[~closed, 1] > 0.0), f"{kind}: {np.sum(n[~closed, 1] <= 0)} ground triangles face down"


@pytest.mark.parametrize("value, words", [('"both"', "cull"), ("true", "cull")])
def test_a_bad_cull_in_an_experiment_exits_2_naming_cull(tmp_path, value, words):
    from typer.testing import CliRunner

    from csmlab.cli import app

    path = tmp_path / "exp.toml"
    path.write_text('name = "t"\n[scene]\nkind = "plane_box"\n[camera]\npath = "orbit"\nframes = 2\n'
                    f'[shadow]\ncascades = 2\nresolution = 64\ncull = {value}\n')
    outcome = CliRunner().invoke(app, ["run", str(path), "--out", str(tmp_path / "out")])
    assert outcome.exit_code == 2, outcome.output
    message = outcome.stderr.strip()
    assert len(message.splitlines()) == 1 and "Traceback" not in outcome.output
    assert f"{path}:" in message and "shadow.cull" in message, message
    assert not (tmp_path / "out").exists()


def test_each_engine_preset_culls_the_faces_its_engine_culls(tmp_path):
    # three.js renders a FrontSide mesh's back faces (WebGLShadowMap getDepthMaterial: shadowSide
    # FrontSide -> BackSide); Godot 4 and Bevy draw the material's default back-face culling; Stride
    # (CullMode.None), MJP (NoCullDesc) and every preset not yet read for it rasterize both windings; URP and
    # HDRP's Lit ShadowCaster pass culls back faces (Cull[_Cull], [_CullMode] = 2, Back).
    from csmlab.config import CONFIGS_DIR, load_experiment

    expected = {"threejs_csm": "front", "godot4": "back", "bevy": "back", "unity_urp": "back", "unity_hdrp": "back"}
    for preset in sorted((CONFIGS_DIR / "engines").glob("*.toml")):
        path = tmp_path / "exp.toml"
        path.write_text(f'extends = ["engines/{preset.stem}"]\n[camera]\npath = "walk"\n')
        (method,) = load_experiment(path).methods
        assert method.settings.cull == expected.get(preset.stem, "none"), preset.stem
