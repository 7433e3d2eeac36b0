"""Quad derivatives and mipmapped moments across splits: the seam of hardware derivatives and its two fixes."""

import numpy as np
import pytest

from csmlab.metrics.reference import seam_error, split_boundary_pixels
from csmlab.metrics.temporal import temporal_maps, temporal_summary
from csmlab.paths import make_path
from csmlab.quads import LOD_METHODS, quad_derivatives, quad_lanes
from csmlab.render import prepare_scene, render_shadow, render_view
from csmlab.scene import Scene, make_scene
from csmlab.settings import ShadowSettings

SUN = np.array([0.5, -0.7, 0.35])
MIPS = ShadowSettings(cascades=3, resolution=256, stabilization="exact", shadow_distance=60.0, filter="vsm",
                      moment_mips=True)


def _terrain():
    return prepare_scene(make_scene("terrain", seed=1, size=120.0, resolution=24, trees=120, ring_trees=40))


def test_quad_lanes_on_a_plane_are_the_hits_of_the_neighbouring_pixels():
    h = 50.0
    plane = Scene.from_triangles(np.array([[-h, 0, -h], [h, 0, -h], [h, 0, h], [-h, 0, h]], float),
                                 np.array([[0, 2, 1], [0, 3, 2]]))
    dscene = prepare_scene(plane)
    pose = make_path("walk", frames=1, fps=30, seed=2, aspect=48 / 32, far=150.0).poses()[0]
    g = render_view(dscene, pose, SUN, width=48, height=32).gbuffer
    quads = quad_lanes(pose, g.position, g.normal, width=48, height=32)
    rows, cols = np.indices((32, 48))
    for lane in range(4):
        r, c = (rows & ~1) + lane // 2, (cols & ~1) + lane % 2
        hit = g.valid & g.valid[r, c]
        assert hit.sum() > 500
        np.testing.assert_allclose(quads.position[..., lane, :][hit], g.position[r, c][hit], rtol=0, atol=1e-9 * h)
    own = quads.position[rows, cols, quads.slot]
    np.testing.assert_array_equal(own[g.valid], g.position[g.valid])


def test_quad_derivatives_take_each_lane_in_its_own_cascade_the_lowest_or_the_pixels_own():
    unit = 256
    # Two cascades whose boxes lie 1000 texels apart; lanes 1 pixel apart are 1.5 texels apart in each.
    step = np.array([[0, 0], [384, 0], [0, 256], [384, 256]])
    lane_coords = np.stack([step + 5000, step + 5000 + 1000 * unit])[:, None]  # (2, 1, 4, 2)
    lanes = np.array([[1, 0, 1, 1]])  # the pixel (lane 0) in cascade 1, its right neighbour in cascade 0
    own = np.array([1])
    cascade, ddx, ddy = quad_derivatives(lane_coords, lanes, own, method="quad", bits=8)
    assert cascade[0] == 1 and ddx[0, 0, 0] == 1.5 - 1000.0 and ddy[0, 0, 1] == 1.0
    cascade, ddx, ddy = quad_derivatives(lane_coords, lanes, own, method="quad_consistent", bits=8)
    assert cascade[0] == 0 and ddx[0, 0, 0] == 1.5 and ddy[0, 0, 1] == 1.0
    held = np.array([[False], [True]])
    cascade, _, _ = quad_derivatives(lane_coords, lanes, own, method="quad_consistent", bits=8, holds=held)
    assert cascade[0] == 1
    cascade, ddx, ddy = quad_derivatives(lane_coords, lanes, own, method="analytic", bits=8)
    assert cascade[0] == 1 and ddx[0, 0, 0] == 1.5 and ddy[0, 0, 1] == 1.0
    with pytest.raises(ValueError, match="quad_consistent"):
        quad_derivatives(lane_coords, lanes, own, method="psvsm", bits=8)


def test_seam_figure_is_above_zero_with_quad_derivatives_and_each_fix_brings_it_down():
    dscene = _terrain()
    pose = make_path("walk", frames=1, fps=30, seed=1, aspect=160 / 90, far=150.0).poses()[0]
    view = render_view(dscene, pose, SUN, width=160, height=90)
    frames = {lod: render_shadow(dscene, view, MIPS.replace(lod=lod)) for lod in LOD_METHODS}
    seam = {lod: seam_error(frame)["ref_seam_error"] for lod, frame in frames.items()}
    assert split_boundary_pixels(frames["quad"].shadow.cascade).sum() > 100
    assert seam["quad"] > 0.0
    assert seam["quad_consistent"] < seam["quad"]
    assert seam["analytic"] < seam["quad"]
    # The seam is the boundary's alone: away from it every lane of a quad shares one cascade, and
    # hardware derivatives are the analytic ones bit for bit.
    near = split_boundary_pixels(frames["quad"].shadow.cascade)
    near = near | np.roll(near, 1, 0) | np.roll(near, -1, 0) | np.roll(near, 1, 1) | np.roll(near, -1, 1)
    away = view.gbuffer.valid & ~near & (frames["quad"].shadow.cascade >= 0)
    np.testing.assert_array_equal(frames["quad"].shadow.lit[away], frames["analytic"].shadow.lit[away])
    assert np.any(frames["quad"].shadow.lit[near] != frames["analytic"].shadow.lit[near])


def test_exact_keeps_zero_same_cascade_flicker_with_mipmapped_vsm_and_quad_derivatives_move_the_seam():
    dscene = _terrain()
    variants = {lod: MIPS.replace(lod=lod) for lod in LOD_METHODS}
    variants["anisotropic"] = MIPS.replace(lod="analytic", anisotropy=4)
    variants["evsm4_blend"] = MIPS.replace(filter="evsm4", lod="quad_consistent", blend_band=0.1)
    path = make_path("walk", frames=5, fps=30, seed=1, aspect=96 / 54, far=150.0)
    previous = dict.fromkeys(variants)
    same = {name: [] for name in variants}
    for i, pose in enumerate(path.poses()):
        view = render_view(dscene, pose, SUN, width=96, height=54, index=i)
        for name, settings in variants.items():
            frame = render_shadow(dscene, view, settings)
            if previous[name] is not None:
                same[name].append(temporal_summary(temporal_maps(frame, previous[name]))["flicker_same"])
            previous[name] = frame
    for name in ("quad_consistent", "analytic", "anisotropic", "evsm4_blend"):
        assert same[name] == [0.0] * 4, name
    # A lane that changes cascade beside a pixel that does not changes that pixel's level of detail.
    assert max(same["quad"]) > 0.0


@pytest.mark.parametrize("line, field", [
    ('lod = "hardware"', "methods.m.lod"), ("anisotropy = 0", "methods.m.anisotropy"),
    ("anisotropy = 17", "methods.m.anisotropy"), ("max_lod = 9", "methods.m.max_lod"),
    ('moment_mips = "yes"', "methods.m.moment_mips"),
])
def test_a_bad_mip_field_is_an_input_error_naming_it(tmp_path, line, field):
    from csmlab.config import load_experiment
    from csmlab.errors import InputError

    file = tmp_path / "bad.toml"
    file.write_text(f'[scene]\nkind = "plane_box"\n[camera]\npath = "orbit"\n[[methods]]\nname = "m"\nfilter = "vsm"\n'
                    f'{line}\n')
    with pytest.raises(InputError, match=field.replace(".", r"\.")):
        load_experiment(file)


def test_show_documents_the_mip_fields():
    from csmlab.config import field_docs

    docs = field_docs(ShadowSettings)
    for name in ("moment_mips", "lod", "max_lod", "anisotropy"):
        assert docs[name], name
    assert "quad_consistent" in docs["lod"]
