"""Error against the reference: state counts, boundary sets and the symmetric boundary distance."""

import numpy as np
import pytest

from csmlab.camera import CameraPose
from csmlab.cascades import build_cascades
from csmlab.frame import Frame, GBuffer, ShadowLookup, ShadowMaps, View
from csmlab.kernels.visibility import CameraHits
from csmlab.geometry import rotation_looking_at
from csmlab.metrics.reference import (bias_errors, boundary_pixels, mean_boundary_distance, reference_boundary,
                                     reference_maps, reference_summary)
from csmlab.render import prepare_scene, render_shadow, render_view
from csmlab.scene import make_scene
from csmlab.settings import ShadowSettings

LIGHT_DOWN = np.array([0.0, -1.0, 0.0])


def _frame(lit, reference):
    """A frame whose only content that matters here is S (``lit``), R and which pixels hit."""
    height, width = lit.shape
    pose = CameraPose(position=[0.0, 10.0, 0.0], orientation=rotation_looking_at(LIGHT_DOWN), aspect=width / height)
    settings = ShadowSettings(cascades=1, resolution=32)
    cascades = build_cascades(pose=pose, light_direction=LIGHT_DOWN, scene_corners=np.zeros((1, 3)), settings=settings)
    valid = np.isfinite(reference)
    zeros3 = np.zeros((height, width, 3), np.float32)
    gbuffer = GBuffer(hits=CameraHits(position=np.zeros((height, width, 3)), normal=zeros3,
                                      triangle=np.where(valid, 0, -1).astype(np.int32),
                                      view_depth=np.ones((height, width), np.float32)),
                      albedo=zeros3)
    view = View(index=0, pose=pose, light_direction=LIGHT_DOWN, gbuffer=gbuffer, reference=reference.astype(np.float32))
    shadow = ShadowLookup(lit=lit.astype(np.float32), cascade=np.where(np.isfinite(lit), 0, -1).astype(np.int8),
                          blend=np.zeros(lit.shape, bool))
    maps = ShadowMaps(cascades=cascades, depth=np.zeros((1, 32, 32), np.float32), texels_rasterized=0)
    return Frame(view=view, settings=settings, maps=maps, shadow=shadow)


def _brute_force_mean_distance(a, b):
    """Mean over both boundary sets of the distance to the nearest pixel of the other, by all pairs."""
    pa, pb = np.argwhere(a).astype(float), np.argwhere(b).astype(float)
    d = np.linalg.norm(pa[:, None, :] - pb[None, :, :], axis=-1)
    return np.concatenate([d.min(axis=1), d.min(axis=0)]).mean()


def test_false_shadow_and_false_light_count_the_disagreeing_pixels():
    reference = np.ones((40, 60))
    reference[:, :30] = 0.0
    lit = reference.copy()
    lit[0:4, 40:50] = 0.2     # 40 pixels: shadow where R is lit
    lit[10:13, 0:5] = 0.9     # 15 pixels: lit where R is shadowed
    lit[20, 20] = np.nan      # no cascade: not compared
    reference[39, 59] = np.nan  # a miss: not compared
    maps = reference_maps(_frame(lit, reference))
    summary = reference_summary(maps)
    compared = 40 * 60 - 2
    assert maps.compared.sum() == compared
    assert summary["ref_false_shadow"] == pytest.approx(40 / compared, abs=1e-15)
    assert summary["ref_false_light"] == pytest.approx(15 / compared, abs=1e-15)
    assert np.count_nonzero(maps.diff == 1) == 40 and np.count_nonzero(maps.diff == -1) == 15


def test_lit_fraction_exactly_one_half_counts_as_shadow():
    reference = np.ones((8, 8))
    maps = reference_maps(_frame(np.full((8, 8), 0.5), reference))
    assert np.all(maps.diff == 1)


def test_straight_edges_three_columns_apart_are_three_pixels_apart():
    reference = np.ones((30, 50))
    reference[:, :20] = 0.0
    lit = np.ones((30, 50))
    lit[:, :23] = 0.0
    summary = reference_summary(reference_maps(_frame(lit, reference)))
    assert summary["ref_boundary_px"] == 3.0
    assert summary["ref_false_shadow"] == pytest.approx(3 / 50, abs=1e-15)


def test_boundary_pixels_are_shadowed_pixels_with_a_lit_four_neighbour():
    shadowed = np.zeros((5, 5), bool)
    shadowed[1:4, 1:4] = True
    compared = np.ones((5, 5), bool)
    expected = shadowed.copy()
    expected[2, 2] = False
    np.testing.assert_array_equal(boundary_pixels(shadowed, compared), expected)
    # A lit neighbour that is not compared (a miss) makes no boundary.
    np.testing.assert_array_equal(boundary_pixels(shadowed, shadowed), np.zeros((5, 5), bool))


def test_mean_boundary_distance_matches_all_pairs_brute_force():
    rng = np.random.default_rng(12)
    a = rng.random((40, 50)) < 0.03
    b = rng.random((40, 50)) < 0.02
    assert mean_boundary_distance(a, b) == pytest.approx(_brute_force_mean_distance(a, b), rel=1e-12)
    assert mean_boundary_distance(a, b) == mean_boundary_distance(b, a)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_mean_boundary_distance_of_mostly_shared_boundaries_equals_all_pairs_exactly(seed):
    # Shared pixels are not queried (0 from the other set): the mean must still be the all-pairs
    # one bit for bit, each distance √(integer) summed in the same order.
    rng = np.random.default_rng(seed)
    a = rng.random((48, 64)) < 0.05
    b = a.copy()
    b[rng.random(b.shape) < 0.02] ^= True
    b[:, :3] = False
    assert (a & b).sum() > 0.8 * a.sum()
    assert mean_boundary_distance(a, b) == _brute_force_mean_distance(a, b)
    assert mean_boundary_distance(b, a) == _brute_force_mean_distance(b, a)
    assert mean_boundary_distance(a, a) == 0.0


def test_mean_boundary_distance_of_empty_sets():
    empty = np.zeros((6, 6), bool)
    one = empty.copy()
    one[2, 3] = True
    assert mean_boundary_distance(empty, empty) == 0.0
    assert np.isnan(mean_boundary_distance(one, empty))


def test_identical_shadow_gives_zero_error():
    rng = np.random.default_rng(2)
    reference = (rng.random((32, 48)) < 0.5).astype(float)
    summary = reference_summary(reference_maps(_frame(reference, reference)))
    assert summary == {"ref_false_shadow": 0.0, "ref_false_light": 0.0, "ref_boundary_px": 0.0}


def test_error_of_an_8192_cascade_on_plane_box_is_small_and_rises_as_resolution_falls():
    dscene = prepare_scene(make_scene("plane_box", plane_size=40.0, box_size=2.0))
    eye = np.array([4.0, 4.0, 4.0])
    pose = CameraPose(position=eye, orientation=rotation_looking_at(np.array([1.5, 0.0, -1.5]) - eye),
                      aspect=96 / 54, far=100.0)
    view = render_view(dscene, pose, [0.7, -0.6, -0.4], width=96, height=54)
    assert np.nanmean(view.reference < 0.5) > 0.05  # the box's shadow is in view
    errors = []
    for resolution in (8192, 2048, 512, 128):
        frame = render_shadow(dscene, view, ShadowSettings(cascades=1, resolution=resolution, shadow_distance=20.0))
        summary = reference_summary(reference_maps(frame))
        errors.append(summary["ref_false_shadow"] + summary["ref_false_light"])
    assert errors[0] < 0.005
    assert np.all(np.diff(errors) > 0), errors


@pytest.mark.parametrize("shape", [(17, 23), (1, 9), (9, 1), (2, 2)])
def test_split_boundary_pixels_are_those_with_another_cascade_among_their_8_neighbours_by_brute_force(shape):
    from csmlab.metrics.reference import split_boundary_pixels

    rng = np.random.default_rng(sum(shape))
    cascade = rng.integers(-1, 3, size=shape)
    expected = np.zeros(shape, dtype=bool)
    for i in range(shape[0]):
        for j in range(shape[1]):
            neighbours = cascade[max(i - 1, 0):i + 2, max(j - 1, 0):j + 2]
            expected[i, j] = cascade[i, j] >= 0 and np.any((neighbours >= 0) & (neighbours != cascade[i, j]))
    np.testing.assert_array_equal(split_boundary_pixels(cascade), expected)
    # The lookup's own int8 selection is compared as it is, the same pixels.
    np.testing.assert_array_equal(split_boundary_pixels(cascade.astype(np.int8)), expected)


def test_split_boundary_pixels_are_both_sides_of_a_cascade_change_and_the_seam_error_is_their_mean_error():
    from types import SimpleNamespace

    from csmlab.metrics.reference import seam_error, split_boundary_pixels

    cascade = np.array([[0, 0, 0, 1, 1, 1],
                        [0, 0, 0, 1, 1, -1],
                        [-1, -1, -1, -1, -1, -1]])
    expected = np.array([[0, 0, 1, 1, 0, 0],
                         [0, 0, 1, 1, 0, 0],
                         [0, 0, 0, 0, 0, 0]], dtype=bool)
    np.testing.assert_array_equal(split_boundary_pixels(cascade), expected)
    lit = np.array([[1.0, 1.0, 0.75, 0.5, 0.0, 0.0]] * 3, np.float32)
    reference = np.ones((3, 6), np.float32)
    frame = SimpleNamespace(shadow=SimpleNamespace(lit=lit, cascade=cascade),
                            view=SimpleNamespace(reference=reference,
                                                 gbuffer=SimpleNamespace(valid=np.ones((3, 6), bool))))
    assert seam_error(frame) == {"ref_seam_error": (0.25 + 0.5) / 2}
    frame.shadow.cascade = np.zeros((3, 6), int)
    assert np.isnan(seam_error(frame)["ref_seam_error"])


# Acne and peter-panning: analytic scenes whose expected errors follow from their geometry alone.

def _slab_view():
    """A 2 × 2 m slab floating 3.0–3.2 m above a plane, the light straight down, seen from below it.

    Returns the device scene, the view, and the slab footprint's ``|x|, |z| < 1`` m outline.
    """
    from csmlab.scene.shapes import height_field, placed, scene_from_parts, unit_box

    grid = np.linspace(-10.0, 10.0, 2)
    plane = height_field(grid, grid, np.zeros((2, 2)), albedo=(0.5, 0.5, 0.5))
    slab = placed(unit_box(), scale=[1.0, 0.1, 1.0], offset=[[0.0, 3.1, 0.0]], albedo=(0.7, 0.35, 0.2))
    dscene = prepare_scene(scene_from_parts([plane, slab], name="slab"))
    eye = np.array([2.5, 1.5, 0.8])
    pose = CameraPose(position=eye, orientation=rotation_looking_at(-eye), aspect=1.5, far=50.0)
    return dscene, render_view(dscene, pose, LIGHT_DOWN, width=96, height=64)


def _bias_only(bias_constant):
    """One 256² cascade, the nearest texel, no slope bias, normal offset or receiver plane: the constant bias alone."""
    return ShadowSettings(cascades=1, resolution=256, shadow_distance=10.0, filter="none", bias_slope=0.0,
                          normal_offset=0.0, receiver_plane_bias=False, bias_constant=bias_constant)


def _footprint_distances(view):
    """Per pixel: on the ground, the distance in metres (x/z, the light's view) to the slab's outline; the
    largest step between ground 4-neighbours within 0.5 m of it (how far a pixel centre lies from an edge)."""
    p = view.gbuffer.position
    ground = view.gbuffer.valid & (np.abs(p[..., 1]) < 1e-9)
    inside = ground & (np.abs(p[..., 0]) < 1.0) & (np.abs(p[..., 2]) < 1.0)
    outline = np.abs(np.abs(p[..., [0, 2]]) - 1.0)
    to_outline = np.where(inside, outline.min(axis=-1),
                          np.hypot(np.maximum(np.abs(p[..., 0]) - 1.0, 0.0), np.maximum(np.abs(p[..., 2]) - 1.0, 0.0)))
    near = ground & (np.abs(p[..., 0]) < 1.5) & (np.abs(p[..., 2]) < 1.5)
    step = 0.0
    for a, b, both in ((p[1:], p[:-1], near[1:] & near[:-1]), (p[:, 1:], p[:, :-1], near[:, 1:] & near[:, :-1])):
        step = max(step, float(np.linalg.norm((a - b)[both][:, [0, 2]], axis=-1).max()))
    return ground, inside, to_outline, step


def test_a_constant_bias_above_the_casters_height_is_peter_panning_and_no_acne():
    dscene, view = _slab_view()
    _, inside, to_outline, step = _footprint_distances(view)
    frame = render_shadow(dscene, view, _bias_only(3.5))  # the slab's top stands 3.2 m above the ground
    maps = reference_maps(frame)
    errors = bias_errors(frame, maps)
    compared = maps.compared.sum()
    band = frame.maps.cascades.margin_texels * float(np.max(frame.maps.cascades.cascades[0].texel_size))
    # Every visible ground point under the slab is lit: the whole shadow is false light.
    assert np.count_nonzero(maps.diff == -1) == np.count_nonzero(inside & maps.compared)
    # Peter-panning counts it but for the points within the band of the outline (less a pixel's step).
    surely_counted = np.count_nonzero(inside & maps.compared & (to_outline > band + 2.0 * step))
    assert surely_counted > 40
    assert surely_counted / compared <= errors["peter_panning"] <= np.count_nonzero(inside & maps.compared) / compared
    assert errors["acne"] == 0.0


def test_a_negative_bias_is_acne_on_every_lit_surface_and_no_peter_panning():
    dscene, view = _slab_view()
    ground, inside, to_outline, step = _footprint_distances(view)
    frame = render_shadow(dscene, view, _bias_only(-0.05))
    maps = reference_maps(frame)
    errors = bias_errors(frame, maps)
    compared = maps.compared.sum()
    band = frame.maps.cascades.margin_texels * float(np.max(frame.maps.cascades.cascades[0].texel_size))
    lit_ground = ground & ~inside & maps.compared
    # The flat ground faces the light: moved 5 cm away from it, all of it falls behind its own depth.
    assert np.count_nonzero(maps.diff == 1) == np.count_nonzero(lit_ground)
    surely_counted = np.count_nonzero(lit_ground & (to_outline > band + 2.0 * step))
    assert surely_counted > 0.5 * np.count_nonzero(lit_ground)
    assert surely_counted / compared <= errors["acne"] <= np.count_nonzero(lit_ground) / compared
    assert errors["peter_panning"] == 0.0


@pytest.mark.parametrize("bias_constant", [3.5, -0.05, 0.01])
def test_bias_errors_count_the_wrong_pixels_farther_than_the_band_from_every_boundary_point_by_all_pairs(
        bias_constant):
    # Wrong pixels that are boundary points themselves are not queried (0 away): the counts must be
    # those of every wrong pixel's distance to every boundary point (at 0.01 m every wrong pixel is one).
    dscene, view = _slab_view()
    frame = render_shadow(dscene, view, _bias_only(bias_constant))
    maps = reference_maps(frame)
    errors = bias_errors(frame, maps)
    boundary = reference_boundary(maps.reference_shadowed, maps.compared)
    wrong = maps.diff != 0
    assert (wrong & boundary).any()
    light_xy = view.gbuffer.position @ frame.maps.cascades.basis[:2].T
    distance = np.linalg.norm(light_xy[wrong][:, None, :] - light_xy[boundary][None, :, :], axis=-1).min(axis=1)
    band = frame.maps.cascades.margin_texels * float(np.max(frame.maps.cascades.cascades[0].texel_size))
    outside = np.zeros_like(wrong)
    outside[wrong] = distance > band
    compared = maps.compared.sum()
    assert errors["acne"] == np.count_nonzero(outside & (maps.diff == 1)) / compared
    assert errors["peter_panning"] == np.count_nonzero(outside & (maps.diff == -1)) / compared


def _sloped_plane_view():
    """A plane alone (nothing casts: no reference boundary), the light 45.6° off its normal."""
    from csmlab.scene.shapes import height_field, scene_from_parts

    grid = np.linspace(-10.0, 10.0, 2)
    dscene = prepare_scene(scene_from_parts([height_field(grid, grid, np.zeros((2, 2)), albedo=(0.5, 0.5, 0.5))],
                                            name="plane"))
    eye = np.array([0.0, 3.0, 4.0])
    pose = CameraPose(position=eye, orientation=rotation_looking_at(-eye), aspect=1.5, far=50.0)
    light = np.array([0.5, -0.7, 0.3]) / np.linalg.norm([0.5, -0.7, 0.3])
    return dscene, render_view(dscene, pose, light, width=96, height=64)


def test_zero_bias_on_a_plane_sloped_to_the_light_is_acne_where_the_texel_centre_lies_nearer_the_light():
    dscene, view = _sloped_plane_view()
    frame = render_shadow(dscene, view, _bias_only(0.0))
    maps = reference_maps(frame)
    errors = bias_errors(frame, maps)
    # The plane y = 0 seen along the light: the depth stored at the centre of the texel a point falls
    # in, against the point's own depth (no bias; nothing else casts, so no boundary and no band).
    cascades = frame.maps.cascades
    cascade = cascades.cascades[0]
    right, up, d = cascades.basis
    points = cascades.to_light(view.gbuffer.position[maps.compared])
    centre = (cascade.origin + np.floor(points[:, :2] / cascade.texel_size - cascade.origin) + 0.5) * cascade.texel_size
    centre_depth = -(centre[:, 0] * right[1] + centre[:, 1] * up[1]) / d[1]
    expected = np.count_nonzero(points[:, 2] > centre_depth) / points.shape[0]
    assert 0.3 < expected < 0.7
    assert errors["acne"] == pytest.approx(expected, abs=0.01)
    assert errors["peter_panning"] == 0.0


def test_false_shadow_where_the_far_fade_reaches_is_not_counted_as_acne():
    dscene, view = _sloped_plane_view()
    # The fade's weight rises over the whole shadow distance: above 0 at every pixel in front of the camera.
    frame = render_shadow(dscene, view, _bias_only(0.0).replace(fade_out=1.0))
    maps = reference_maps(frame)
    assert np.count_nonzero(maps.diff == 1) > 0.2 * maps.compared.sum()  # the near half of the weights leaves S ≤ 0.5
    assert bias_errors(frame, maps) == {"acne": 0.0, "peter_panning": 0.0}


def test_methods_of_one_view_sharing_the_reference_side_get_each_their_own_all_pairs_values():
    # Three shadows of one view: the reference's boundary and its k-d trees are kept by the view and
    # read by the next method that compares the same pixels; one that compares fewer pixels (a part
    # without a cascade) must not read them. Each value is checked against all pairs.
    dscene, view = _slab_view()
    frames = [render_shadow(dscene, view, _bias_only(bias)) for bias in (3.5, -0.05, 0.01)]
    fewer = frames[2].shadow.lit.copy()
    fewer[:, : fewer.shape[1] // 3] = np.nan
    frames.append(Frame(view=view, settings=frames[2].settings, maps=frames[2].maps,
                        shadow=ShadowLookup(lit=fewer, cascade=np.where(np.isfinite(fewer), 0, -1).astype(np.int8),
                                            blend=frames[2].shadow.blend)))
    light_xy = view.gbuffer.position @ frames[0].maps.cascades.basis[:2].T
    band = frames[0].maps.cascades.margin_texels * float(np.max(frames[0].maps.cascades.cascades[0].texel_size))
    for frame in frames:
        maps = reference_maps(frame)
        summary = reference_summary(maps, view=view)
        errors = bias_errors(frame, maps)
        compared = maps.compared.sum()
        method_boundary = boundary_pixels(maps.shadowed, maps.compared)
        ref_boundary = boundary_pixels(maps.reference_shadowed, maps.compared)
        assert ref_boundary.any()
        expected = (_brute_force_mean_distance(method_boundary, ref_boundary) if method_boundary.any()
                    else float("nan"))
        assert summary["ref_boundary_px"] == pytest.approx(expected, rel=1e-12, nan_ok=True)
        boundary = reference_boundary(maps.reference_shadowed, maps.compared)
        wrong = (maps.diff != 0) & ~boundary
        distance = np.linalg.norm(light_xy[wrong][:, None, :] - light_xy[boundary][None, :, :], axis=-1).min(axis=1)
        outside = np.zeros_like(wrong)
        outside[wrong] = distance > band
        assert errors["acne"] == np.count_nonzero(outside & (maps.diff == 1)) / compared
        assert errors["peter_panning"] == np.count_nonzero(outside & (maps.diff == -1)) / compared
    assert not np.array_equal(reference_maps(frames[3]).compared, reference_maps(frames[2]).compared)
    assert sum(key[0] in ("reference_boundary", "reference_boundary_px") for key in view.derived) == 4
