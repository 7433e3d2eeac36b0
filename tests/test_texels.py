"""Host fixed-point conversion: texel coordinates, snapping, receiver offset and bias."""

import numpy as np
import pytest

from csmlab.cascades import Cascade, CascadeSet
from csmlab.geometry import light_basis
from csmlab.texels import (engine_matrix, engine_origin, engine_positions, fixed_point_coordinates, light_depth,
                           receiver_lookup, texel_coordinates, vertex_depth, window_positions)

LIGHT = np.array([0.3, -0.8, 0.45])


def cascade_set(*, origins, texel=0.0371, resolution=64, zref=-3.0, direction=LIGHT) -> CascadeSet:
    cascades = tuple(
        Cascade(split_near=0.1, split_far=50.0, slice_near=0.1, slice_far=50.0, texel_size=np.array([texel, texel]),
                origin=np.asarray(o, dtype=np.float64), resolution=resolution, depth_near=-100.0, depth_far=100.0)
        for o in origins
    )
    return CascadeSet(basis=light_basis(direction), zref=zref, splits=np.linspace(0.1, 50.0, len(origins) + 1),
                      cascades=cascades, margin_texels=2)


def world_from_light(cs: CascadeSet, x, y, depth) -> np.ndarray:
    """World points whose light-space coordinates are (x, y) metres and depth ``d·X``."""
    return np.stack([x, y, depth], axis=-1) @ cs.basis


def test_texel_coordinates_of_texel_centres_are_half_integers():
    cs = cascade_set(origins=[(1234.0, -567.0)])
    i, j = np.meshgrid(np.arange(64), np.arange(64), indexing="xy")
    t = cs.cascades[0].texel_size[0]
    points = world_from_light(cs, (1234 + i + 0.5) * t, (-567 + j + 0.5) * t, np.full(i.shape, 7.0))
    coords = texel_coordinates(cs, 0, points)
    np.testing.assert_allclose(coords[..., 0], i + 0.5, atol=1e-9)
    np.testing.assert_allclose(coords[..., 1], j + 0.5, atol=1e-9)


def test_fixed_point_moves_by_exact_integers_when_the_box_moves_by_whole_texels():
    rng = np.random.default_rng(3)
    points = rng.uniform(-20.0, 20.0, (500, 3)) + np.array([1e5, 0.0, -1e5])
    cs = cascade_set(origins=[(2.7e6, -2.7e6), (2.7e6 + 1000, -2.7e6 - 999), (2.7e6 - 3, -2.7e6 + 1)])
    bits = 8
    base = fixed_point_coordinates(cs, 0, points, bits=bits)
    for c in (1, 2):
        k = (cs.cascades[c].origin - cs.cascades[0].origin).astype(np.int64)
        moved = fixed_point_coordinates(cs, c, points, bits=bits)
        assert np.array_equal(base - moved, np.broadcast_to(k * 2**bits, base.shape))


def test_fixed_point_is_the_texel_coordinate_rounded_to_the_grid():
    rng = np.random.default_rng(4)
    cs = cascade_set(origins=[(10.0, 20.0)])
    points = rng.uniform(-3.0, 3.0, (1000, 3))
    for bits in (0, 8, 12):
        fixed = fixed_point_coordinates(cs, 0, points, bits=bits)
        assert fixed.dtype == np.int64
        assert np.max(np.abs(fixed / 2**bits - texel_coordinates(cs, 0, points))) <= 0.5 / 2**bits + 1e-9


def test_light_depth_is_distance_along_the_light_minus_zref():
    cs = cascade_set(origins=[(0.0, 0.0)], zref=-3.0)
    points = np.array([[0.0, 0.0, 0.0], [1.0, 2.0, 3.0]])
    d = LIGHT / np.linalg.norm(LIGHT)
    np.testing.assert_allclose(light_depth(cs, points), points @ d + 3.0, rtol=1e-15)


def test_receiver_lookup_offsets_along_the_normal_and_biases_by_the_slope():
    cs = cascade_set(origins=[(0.0, 0.0)], texel=0.05)
    d = cs.direction
    toward = -d
    # A normal 30 degrees from the light: tan = 1/sqrt(3).
    side = np.cross(toward, cs.basis[0])
    side /= np.linalg.norm(side)
    normal = np.cos(np.radians(30.0)) * toward + np.sin(np.radians(30.0)) * side
    point = world_from_light(cs, 1.0, 1.0, 2.0)
    coords, depth, _ = receiver_lookup(cs, point[None], normal[None], bits=16, normal_offset=0.5, bias_constant=0.01,
                                    bias_slope=2.0)
    moved = point + normal * 0.5 * 0.05
    np.testing.assert_allclose(coords[0, 0] / 2**16, texel_coordinates(cs, 0, moved[None])[0], atol=1e-4)
    expected = light_depth(cs, moved[None])[0] - 0.01 - 2.0 * 0.05 / np.sqrt(3.0)
    assert depth.dtype == np.float32
    np.testing.assert_allclose(depth[0, 0], expected, rtol=1e-6)


def test_receiver_lookup_clamps_grazing_slopes_and_shadows_receivers_turned_from_the_light():
    cs = cascade_set(origins=[(0.0, 0.0)], texel=0.05)
    point = world_from_light(cs, 1.0, 1.0, 2.0)
    grazing = np.cos(np.radians(89.9)) * -cs.direction + np.sin(np.radians(89.9)) * cs.basis[0]
    away = np.cos(np.radians(90.1)) * -cs.direction + np.sin(np.radians(90.1)) * cs.basis[0]
    normals = np.stack([grazing, away, cs.direction])
    _, depth, _ = receiver_lookup(cs, np.stack([point] * 3), normals, bits=8, normal_offset=0.0, bias_constant=0.0,
                               bias_slope=1.0)
    np.testing.assert_allclose(depth[0, 0], light_depth(cs, point[None])[0] - 10.0 * 0.05, rtol=1e-6)
    assert np.all(np.isnan(depth[0, 1:]))


def test_non_finite_receivers_fall_outside_every_box():
    cs = cascade_set(origins=[(0.0, 0.0)])
    coords, _, _ = receiver_lookup(cs, np.full((2, 3), np.nan), np.zeros((2, 3)), bits=8, normal_offset=0.5,
                                bias_constant=0.0, bias_slope=1.0)
    assert np.all(coords < 0)


def test_a_wrong_cascade_index_names_the_valid_range():
    cs = cascade_set(origins=[(0.0, 0.0)])
    with pytest.raises(ValueError, match=r"cascade index: expected 0\.\.0"):
        texel_coordinates(cs, 1, np.zeros((1, 3)))


def test_engine_window_positions_put_the_box_corners_at_0_and_r_and_its_depth_range_at_0_and_1():
    """An engine's float32 matrix maps the box's minimum corner on its near side to window (0, 0, 0) and the
    opposite corner to (R, R, 1): the orthographic box of docs/design.md, to float32 precision."""
    cs = cascade_set(origins=[(-40.0, 25.0)])
    cascade = cs.cascades[0]
    t = cascade.texel_size[0]
    low = world_from_light(cs, -40.0 * t, 25.0 * t, cascade.depth_near)
    high = world_from_light(cs, (-40.0 + 64) * t, (25.0 + 64) * t, cascade.depth_far)
    matrix = engine_matrix(cs, 0, origin=np.zeros(3))
    assert matrix.dtype == np.float32 and matrix.shape == (3, 4)
    window = window_positions(matrix, engine_positions(np.stack([low, high]), np.zeros(3)), resolution=64)
    np.testing.assert_allclose(window, [[0.0, 0.0, 0.0], [64.0, 64.0, 1.0]], atol=1e-4)


def test_engine_origin_is_the_world_origin_or_the_camera_rebased_every_frame_or_in_steps():
    eye = np.array([1234.5, 10.0, -2600.2])
    assert np.array_equal(engine_origin(eye, precision="float32"), np.zeros(3))
    assert np.array_equal(engine_origin(eye, precision="float64"), np.zeros(3))
    assert np.array_equal(engine_origin(eye, precision="camera_relative"), eye)
    assert np.array_equal(engine_origin(eye, precision="camera_relative", rebase_distance=1000.0),
                          [1000.0, 0.0, -3000.0])


def _shifted_pair(offset: float):
    """A cascade at the origin and the same cascade with the world moved ``offset`` metres along x and z.

    The box is moved by the whole number of texels nearest the offset; the points and the camera move
    by that same light-space amount, so in exact arithmetic every texel coordinate is unchanged."""
    here = cascade_set(origins=[(-32.0, -32.0)])
    t = here.cascades[0].texel_size[0]
    shift = here.basis @ np.array([offset, 0.0, offset])
    whole = np.round(shift[:2] / t)
    moved_light = np.array([*(whole * t), shift[2]])
    there = CascadeSet(basis=here.basis, zref=here.zref, splits=here.splits,
                       cascades=(Cascade(**{**here.cascades[0].__dict__, "origin": here.cascades[0].origin + whole,
                                            "depth_near": -100.0 + shift[2], "depth_far": 100.0 + shift[2]}),),
                       margin_texels=2, eye=moved_light @ here.basis)
    here = CascadeSet(basis=here.basis, zref=here.zref, splits=here.splits, cascades=here.cascades, margin_texels=2,
                      eye=np.zeros(3))
    return here, there, moved_light @ here.basis


@pytest.mark.parametrize("offset", [1e5, 1e6])
def test_camera_relative_snaps_far_from_the_origin_as_at_it_and_float32_does_not(offset):
    """The same points, box and camera 10⁵ or 10⁶ m away: camera-relative coordinates stay within one
    sub-texel step of the origin's, float32 ones move by a float32 step of the world position there
    (np.spacing: 1/128 m at 10⁵, 1/16 m at 10⁶), many sub-texel steps."""
    rng = np.random.default_rng(5)
    here, there, move = _shifted_pair(offset)
    points = rng.uniform(-1.0, 1.0, (400, 3))
    bits = 8
    at_origin = fixed_point_coordinates(here, 0, points, bits=bits, precision="camera_relative")
    relative = fixed_point_coordinates(there, 0, points + move, bits=bits, precision="camera_relative")
    absolute = fixed_point_coordinates(there, 0, points + move, bits=bits, precision="float32")
    assert np.max(np.abs(relative - at_origin)) <= 1
    step = float(np.spacing(np.float32(offset))) / here.cascades[0].texel_size[0] * 2**bits
    assert np.max(np.abs(absolute - at_origin)) >= 0.25 * step > 1


def test_float32_depth_is_the_light_depth_to_float32_precision_at_the_origin_and_coarser_far_from_it():
    """At 10⁶ m each float32 world coordinate of the point and of the eye is off by up to half a step of
    1/16 m and the sums round at that step again: a few steps of error in depth, where at the origin
    it is micrometres."""
    rng = np.random.default_rng(6)
    here, there, move = _shifted_pair(1e6)
    points = rng.uniform(-1.0, 1.0, (400, 3))
    near = vertex_depth(here, 0, points, precision="float32")
    np.testing.assert_allclose(near, light_depth(here, points), atol=2e-5)
    far = vertex_depth(there, 0, points + move, precision="float32")
    error = np.abs(far - light_depth(there, points + move))
    step = float(np.spacing(np.float32(1e6)))
    assert step / 4 < error.max() <= 4 * step


def test_window_snapping_equals_world_snapping_on_whole_texel_boxes_and_follows_a_fractional_origin():
    rng = np.random.default_rng(7)
    points = rng.uniform(-3.0, 3.0, (1000, 3)) + np.array([5e4, 0.0, -5e4])
    bits = 8
    whole = cascade_set(origins=[(40000.0, -12000.0)])
    assert np.array_equal(fixed_point_coordinates(whole, 0, points, bits=bits, snap="window"),
                          fixed_point_coordinates(whole, 0, points, bits=bits))
    fractional = cascade_set(origins=[(40000.3, -12000.7)])
    window = fixed_point_coordinates(fractional, 0, points, bits=bits, snap="window")
    assert np.array_equal(window, np.rint(texel_coordinates(fractional, 0, points) * 2**bits).astype(np.int64))
    assert not np.array_equal(window, fixed_point_coordinates(fractional, 0, points, bits=bits))


@pytest.mark.parametrize("precision", ["float32", "camera_relative"])
@pytest.mark.parametrize("offset", [0.0, 1e5, 1e6])
def test_window_rectangles_hold_every_point_of_their_boxes_through_the_float32_pipeline(offset, precision):
    """Points of small world boxes in and around a cascade, at the origin and 10⁵ or 10⁶ m from it, taken through the
    float32 pipeline and snapped (the host's fixed_point_coordinates), doubled, lie in their box's rectangle; the
    rectangle is the points' own span but for the float32 roundings' room, a few steps at the origin."""
    from csmlab.texels import window_box_inputs, window_rectangles

    rng = np.random.default_rng(17)
    _, cs, move = _shifted_pair(offset)
    bits = 8
    inputs = window_box_inputs(cs, bits=bits, precision=precision)
    centres = move + rng.uniform(-4.0, 4.0, (60, 3))
    lo = centres - rng.uniform(0.0, 0.3, (60, 3))
    hi = centres + rng.uniform(0.0, 0.3, (60, 3))
    hi[:5] = lo[:5]  # boxes of one point
    low, high = window_rectangles(inputs, lo, hi)
    assert low.shape == high.shape == (1, 60, 2)
    corners = ((np.arange(8)[:, None] >> np.arange(3)) & 1).astype(bool)
    for k in range(60):
        points = np.concatenate([np.where(corners, hi[k], lo[k]), rng.uniform(lo[k], hi[k], (200, 3))])
        doubled = 2 * fixed_point_coordinates(cs, 0, points, bits=bits, precision=precision)
        assert np.all(doubled >= low[0, k]) and np.all(doubled <= high[0, k])
        if offset == 0.0 or precision == "camera_relative":
            assert np.all(high[0, k] - low[0, k] <= doubled.max(axis=0) - doubled.min(axis=0) + 2 * 2 ** bits)


def test_window_rectangles_need_the_float32_pipelines_inputs():
    from csmlab.texels import window_box_inputs, window_rectangles

    inputs = window_box_inputs(cascade_set(origins=[(0.0, 0.0)]), bits=8, precision="float64", snap="window")
    with pytest.raises(ValueError, match="float32"):
        window_rectangles(inputs, np.zeros((1, 3)), np.ones((1, 3)))
