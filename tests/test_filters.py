"""Every filter through the whole frame: exact stabilization keeps zero same-cascade flicker, per-pixel rotation breaks
it."""

import numpy as np
import pytest

from csmlab.lookup_choices import FAMILIES, FILTER_METHODS
from csmlab.metrics.temporal import temporal_maps, temporal_summary
from csmlab.paths import make_path
from csmlab.render import prepare_scene, render_shadow, render_view
from csmlab.scene import make_scene
from csmlab.settings import ShadowSettings

SUN = np.array([0.5, -0.7, 0.35])
STEADY = {"pcf_gaussian": {}, "pcf_tent": {"filter_size": 5}, "pcf_poisson": {"filter_size": 5},
          "pcss": {"filter_size": 5, "light_size_deg": 2.0}, "pcf_tent_world": {"filter_width_m": 1.5},
          "pcf_unorm16": {"depth_format": "unorm16"}, "vsm": {"vsm_bleed": 0.2}, "evsm2": {},
          "evsm4": {"moment_blur": 3, "depth_format": "unorm16"}, "msm": {},
          "pcf_vogel": {"vogel_taps": 4, "vogel_radius": 2.0, "vogel_angle": 2.4, "vogel_scale": "first_split"},
          "pcf_castano": {"filter_size": 5}, "pcf_tent_bilinear": {"filter_size": 7}, "pcf_bilinear_box": {}}


def _walk(variants, frames=10):
    """Same-cascade flicker per frame of each settings variant on a small terrain walk, static light."""
    dscene = prepare_scene(make_scene("terrain", seed=1, size=120.0, resolution=24, trees=120, ring_trees=40))
    path = make_path("walk", frames=frames, fps=30, seed=1, aspect=96 / 54, far=150.0)
    previous = dict.fromkeys(variants)
    out = {name: [] for name in variants}
    for i, pose in enumerate(path.poses()):
        view = render_view(dscene, pose, SUN, width=96, height=54, index=i)
        for name, settings in variants.items():
            frame = render_shadow(dscene, view, settings)
            if previous[name] is not None:
                out[name].append(temporal_summary(temporal_maps(frame, previous[name])))
            previous[name] = frame
    return {name: {key: np.array([s[key] for s in rows]) for key in rows[0]} for name, rows in out.items()}


def test_exact_keeps_zero_same_cascade_flicker_under_every_filter_and_unorm16_and_pixel_rotation_breaks_it():
    base = ShadowSettings(cascades=3, resolution=256, stabilization="exact", shadow_distance=60.0)
    variants = {name: base.replace(filter=name.removesuffix("_world").removesuffix("_unorm16"), **params)
                for name, params in STEADY.items()}
    variants["rotated"] = base.replace(filter="pcf_poisson", filter_size=5, poisson_rotation="pixel")
    variants["rotated_vogel"] = base.replace(filter="pcf_vogel", vogel_taps=4, vogel_radius=2.0,
                                             poisson_rotation="pixel")
    variants["none_stabilized"] = base.replace(stabilization="none", filter="pcf_tent", filter_size=5)
    summary = _walk(variants)
    for name in STEADY:
        assert np.all(summary[name]["flicker_same"] == 0.0), name
        assert np.all(summary[name]["flip_same"] == 0.0), name
    assert np.nanmean(summary["rotated"]["flicker_same"]) > 0.0
    assert np.nanmean(summary["rotated_vogel"]["flicker_same"]) > 0.0
    assert np.nanmean(summary["none_stabilized"]["flicker_same"]) > 0.0


def test_every_filter_has_one_record_and_the_margin_follows_its_radius():
    # The texels each filter reads beyond the point's at filter_size 5, moment_blur 5 (module docs of
    # csmlab.kernels.shadow, .pcf, .moments): a tent or disk of half-width 2.5 around a point anywhere
    # in its texel reaches 3; a bilinear lookup of moments blurred over 5 texels reaches 1 + 2.
    # Bilinear-compare taps read one texel past where they fall: a Vogel disk of 1 texel reaches 2, Castaño's
    # 5×5, Unity's 5×5 tent and DirectX's 5×5 of bilinear taps reach 3.
    radius = {"none": 0, "pcf": 2, "pcf_bilinear": 1, "pcf_gaussian": 2, "pcf_tent": 3, "pcf_poisson": 3,
              "pcf_vogel": 2, "pcf_castano": 3, "pcf_tent_bilinear": 3, "pcf_bilinear_box": 3, "pcss": 2,
              "vsm": 3, "evsm2": 3, "evsm4": 3, "msm": 3}
    assert list(FILTER_METHODS) == list(radius)
    for name, record in FILTER_METHODS.items():
        settings = ShadowSettings(filter=name, filter_size=5, moment_blur=5)
        assert record.name == name and record.family in FAMILIES and record.description
        assert record.radius_of(settings) == radius[name], name
        assert settings.margin_texels == radius[name] + 1, name
    # With mips, a bilinear lookup at level 3 reads within 1.5 · 8 texels, two probes spread 4 more.
    mips = ShadowSettings(filter="vsm", moment_blur=5, moment_mips=True, max_lod=3, anisotropy=2)
    assert mips.margin_texels == 16 + 2 + 1
    with pytest.raises(ValueError, match="filter: expected one of .*'pcf_poisson'"):
        _ = ShadowSettings(filter="poisson").margin_texels


def test_a_filter_reads_what_its_record_says():
    reads = {name: record.reads_of(ShadowSettings(filter=name)) for name, record in FILTER_METHODS.items()}
    assert {name for name, what in reads.items() if "moments" in what} == {"vsm", "evsm2", "evsm4", "msm"}
    assert all("pixels" not in what and "mips" not in what for what in reads.values())
    assert "pixels" in FILTER_METHODS["pcf_poisson"].reads_of(ShadowSettings(poisson_rotation="pixel"))
    assert "mips" in FILTER_METHODS["evsm2"].reads_of(ShadowSettings(moment_mips=True))


def test_world_width_is_the_same_in_metres_in_every_cascade_up_to_the_tap_cap():
    from csmlab.cascades import build_cascades
    from csmlab.camera import CameraPose

    pose = CameraPose(position=np.array([0.0, 2.0, 0.0]), orientation=np.array([1.0, 0.0, 0.0, 0.0]), fov_y_deg=60.0,
                      aspect=16 / 9, near=0.1, far=200.0)
    settings = ShadowSettings(filter="pcf_tent", filter_size=7, filter_width_m=0.8, cascades=4, resolution=512)
    cascades = build_cascades(pose=pose, light_direction=SUN, scene_corners=np.array([[-50, 0, -50], [50, 5, 50]]),
                              settings=settings)
    texel = np.array([max(c.texel_size) for c in cascades.cascades])
    width = FILTER_METHODS["pcf_tent"].width_of(texel, settings, cascades.splits[1:])
    np.testing.assert_allclose(width, np.clip(0.4 / texel, 0.01, 3.5))
    assert width[0] > width[-1]


@pytest.mark.parametrize("line, field", [
    ('filter = "pcf_tentt"', "methods.m.filter"), ('poisson_rotation = "screen"', "methods.m.poisson_rotation"),
    ("light_size_deg = 0.0", "methods.m.light_size_deg"), ("filter_width_m = -1.0", "methods.m.filter_width_m"),
    ('depth_format = "d16"', "methods.m.depth_format"), ('atlas_layout = "3x3"', "methods.m.atlas_layout"),
    ("cascade_resolutions = [512, 256]", "methods.m.cascade_resolutions"),
    ('filter = "pcf_vogel"\nvogel_scale = "split"', "methods.m.vogel_scale"),
    ('filter = "pcf_vogel"\nvogel_radius = 0.0', "methods.m.vogel_radius"),
    ('filter = "pcf_castano"\nfilter_size = 7', "methods.m.filter_size"),
])
def test_a_bad_filter_or_storage_field_is_an_input_error_naming_it(tmp_path, line, field):
    from csmlab.config import load_experiment
    from csmlab.errors import InputError

    file = tmp_path / "bad.toml"
    file.write_text(f'[scene]\nkind = "plane_box"\n[camera]\npath = "orbit"\n[[methods]]\nname = "m"\n{line}\n')
    with pytest.raises(InputError, match=field.replace(".", r"\.")):
        load_experiment(file)


def test_hdrps_dithered_borders_read_the_pixels_but_rotate_no_disk():
    # sphere_dither reads each receiver's pixel for its border noise; a Vogel disk whose rotation is "none" stays
    # unrotated there: wherever the dither keeps a receiver's sphere, S is the plain sphere selection's, bit for bit.
    dscene = prepare_scene(make_scene("terrain", seed=1, size=120.0, resolution=24, trees=120, ring_trees=40))
    pose = make_path("walk", frames=2, fps=30, seed=1, aspect=96 / 54, far=150.0).pose(1)
    view = render_view(dscene, pose, SUN, width=96, height=54, index=1)
    base = ShadowSettings(cascades=3, resolution=256, shadow_distance=60.0, selection="sphere", filter="pcf_vogel",
                          vogel_taps=8, vogel_radius=2.0)
    plain = render_shadow(dscene, view, base).shadow
    dithered = render_shadow(dscene, view, base.replace(selection="sphere_dither",
                                                       cascade_borders=(0.05, 0.05, 0.0))).shadow
    rotated = render_shadow(dscene, view, base.replace(poisson_rotation="pixel")).shadow
    kept = (dithered.cascade == plain.cascade) & (plain.cascade >= 0)
    assert np.count_nonzero(kept) > 0.9 * np.count_nonzero(plain.cascade >= 0)
    np.testing.assert_array_equal(dithered.lit[kept], plain.lit[kept])
    assert np.any(rotated.lit[kept] != plain.lit[kept])              # a rotation would show here


def test_receiver_rows_are_the_points_with_three_finite_coordinates_and_a_view_depth():
    """Checked point by point: a NaN or infinite coordinate, or a NaN view depth, leaves a point out; an infinite
    view depth alone does not."""
    from csmlab.filters import receiver_rows

    rng = np.random.default_rng(2)
    points = rng.uniform(-5.0, 5.0, (6, 7, 3))
    view_depth = rng.uniform(0.1, 50.0, (6, 7))
    for (i, j, axis), value in zip(rng.integers(0, [6, 7, 3], size=(12, 3)), [np.nan, np.inf, -np.inf] * 4):
        points[i, j, axis] = value
    view_depth[1, ::2] = np.nan
    view_depth[4, 1::3] = np.inf
    expected = [row for row, (p, z) in enumerate(zip(points.reshape(-1, 3), view_depth.reshape(-1)))
                if all(np.isfinite(c) for c in p) and not np.isnan(z)]
    np.testing.assert_array_equal(receiver_rows(points, view_depth), expected)
    assert 0 < len(expected) < 42


def test_a_lookup_given_its_receivers_rows_shades_as_one_that_finds_them():
    """render_shadow hands lookup_shadow the view's receiver rows, found once for its methods: the same S, cascade
    and blend as when the lookup finds them, where the view has misses."""
    from csmlab.filters import lookup_shadow, receiver_rows

    dscene = prepare_scene(make_scene("terrain", seed=1, size=120.0, resolution=24, trees=120, ring_trees=40))
    pose = next(iter(make_path("walk", frames=2, fps=30, seed=1, aspect=96 / 54, far=150.0).poses()))
    view = render_view(dscene, pose, SUN, width=96, height=54, reference=False)
    g = view.gbuffer
    assert not g.valid.all()
    settings = ShadowSettings(filter="pcf", filter_size=3, blend_band=0.2)
    maps = render_shadow(dscene, view, settings, lookup=False).maps
    common = dict(points=g.position, normals=g.normal, view_depth=g.view_depth, settings=settings)
    found = lookup_shadow(maps, **common)
    given = lookup_shadow(maps, rows=receiver_rows(g.position, g.view_depth), **common)
    for a, b in zip((found.lit, found.cascade, found.blend), (given.lit, given.cascade, given.blend)):
        np.testing.assert_array_equal(a, b)
    assert np.isfinite(found.lit).sum() > 100


def test_a_lookup_of_the_visible_points_alone_shades_them_as_among_the_misses():
    """Where every point is a receiver (the temporal metric's visible points) the lookup returns the receivers'
    results as they are; they equal the same points' among the view's misses."""
    from csmlab.filters import lookup_shadow

    dscene = prepare_scene(make_scene("terrain", seed=1, size=120.0, resolution=24, trees=120, ring_trees=40))
    pose = next(iter(make_path("walk", frames=2, fps=30, seed=1, aspect=96 / 54, far=150.0).poses()))
    g = render_view(dscene, pose, SUN, width=96, height=54, reference=False).gbuffer
    settings = ShadowSettings(filter="pcf", filter_size=3, blend_band=0.2, fade_out=0.1)
    maps = render_shadow(dscene, render_view(dscene, pose, SUN, width=96, height=54, reference=False), settings,
                         lookup=False).maps
    whole = lookup_shadow(maps, points=g.position, normals=g.normal, view_depth=g.view_depth, settings=settings)
    valid = g.valid
    alone = lookup_shadow(maps, points=g.position[valid], normals=g.normal[valid], view_depth=g.view_depth[valid],
                          settings=settings)
    for a, b in zip((whole.lit, whole.cascade, whole.blend), (alone.lit, alone.cascade, alone.blend)):
        np.testing.assert_array_equal(a[valid], b)
    assert not valid.all() and np.isfinite(alone.lit).sum() > 100 and alone.blend.any()
