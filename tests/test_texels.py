"""Host fixed-point conversion: texel coordinates, snapping, receiver offset and bias."""

import numpy as np
import pytest

from csmlab.cascades import Cascade, CascadeSet
from csmlab.geometry import light_basis
from csmlab.texels import fixed_point_coordinates, light_depth, receiver_lookup, texel_coordinates

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
