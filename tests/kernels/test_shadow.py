"""Shadow lookup: cascade selection, filters against a NumPy reference, blend band, shift invariance."""

import numpy as np
import pytest

from csmlab.cascades import Cascade, CascadeSet
from csmlab.frame import ShadowMaps
from csmlab.geometry import light_basis
from csmlab.kernels.bias import BiasSettings
from csmlab.kernels.raster import rasterize_depth
from csmlab.kernels.shadow import receiver_coordinates, select_cascades, shadow_lookup
from csmlab.lookup_choices import FILTER_METHODS, SELECTION_METHODS, family_filters
from csmlab.render import lookup_shadow
from csmlab.settings import ShadowSettings
from csmlab.texels import fixed_point_coordinates, light_depth, texel_coordinates

BITS = 8
UNIT = 2**BITS
LIGHT = np.array([0.42, -0.71, -0.33])


def radius(filter, filter_size):
    """The taps' radius of a box filter of ``filter_size``, from its record."""
    return FILTER_METHODS[filter].radius_of(ShadowSettings(filter=filter, filter_size=filter_size))


def lookup(depth, coords, receiver_depth, view_depth, *, splits, selection="interval", filter="none", filter_size=1,
           margin=1, blend_band=0.0, texel_area=None, device="cpu"):
    count = depth.shape[0]
    return shadow_lookup(depth, coords, receiver_depth, view_depth, splits=splits,
                         texel_area=np.ones(count) if texel_area is None else texel_area, selection=selection,
                         filter=filter, radius=radius(filter, filter_size) if filter in FILTER_METHODS else 0,
                         margin=margin, blend_band=blend_band, bits=BITS, device=device)


def test_interval_selection_picks_cascade_i_exactly_on_its_split_interval(device):
    splits = np.array([0.5, 3.0, 10.25, 40.0, 100.0])
    depth = np.full((4, 16, 16), np.inf, dtype=np.float32)
    below = np.nextafter(splits[1:], -np.inf)
    below32 = np.nextafter(splits[1:].astype(np.float32), np.float32(-np.inf))
    z = np.concatenate([splits[:-1], below, below32, [0.25, 100.0, 1e9, np.nan]])
    expected = np.concatenate([np.arange(4), np.arange(4), np.arange(4), [-1, -1, -1, -1]])
    n = z.shape[0]
    coords = np.full((4, n, 2), 8 * UNIT, dtype=np.int64)
    cascade = lookup(depth, coords, np.zeros((4, n), np.float32), z, splits=splits, device=device)[1]
    np.testing.assert_array_equal(cascade, expected)


def cascade_set(*, origins, texels, resolution, direction=LIGHT, zref=0.0, margin=2) -> CascadeSet:
    cascades = tuple(
        Cascade(split_near=0.1, split_far=50.0, slice_near=0.1, slice_far=50.0, texel_size=np.array([t, t]),
                origin=np.asarray(o, dtype=np.float64), resolution=resolution, depth_near=-1e3, depth_far=1e3)
        for o, t in zip(origins, texels)
    )
    return CascadeSet(basis=light_basis(direction), zref=zref, splits=np.linspace(0.1, 50.0, len(origins) + 1),
                      cascades=cascades, margin_texels=margin)


@pytest.mark.parametrize("selection", ["map", "best_resolution"])
def test_box_selection_picks_only_boxes_that_contain_the_point(selection, device):
    rng = np.random.default_rng(17)
    resolution, margin = 32, 2
    # Three overlapping boxes of texel areas 0.01, 0.09 and 0.04 m²: the first inside the second,
    # the third reaching beyond the second.
    cs = cascade_set(origins=[(-30, -10), (-20, -20), (-5, -25)], texels=[0.1, 0.3, 0.2], resolution=resolution,
                     margin=margin)
    light = rng.uniform(-8.0, 8.0, (3000, 2))
    points = np.column_stack([light, rng.uniform(0, 5, 3000)]) @ cs.basis
    normals = np.tile(-cs.direction.astype(np.float32), (3000, 1))
    settings = ShadowSettings(cascades=3, resolution=resolution, selection=selection, filter="pcf", filter_size=3,
                              normal_offset=0.0, bias_slope=0.0)
    maps = ShadowMaps(cascades=cs, depth=np.full((3, resolution, resolution), np.inf, np.float32), texels_rasterized=0)
    result = lookup_shadow(maps, points=points, normals=normals, view_depth=np.full(3000, 1.0), settings=settings,
                           device=device)

    tc = np.stack([texel_coordinates(cs, c, points) for c in range(3)])
    contains = np.all((tc >= margin) & (tc < resolution - margin), axis=2)
    clear = np.all(np.abs(tc - margin) > 1e-2, axis=2) & np.all(np.abs(tc - (resolution - margin)) > 1e-2, axis=2)
    robust = np.all(clear, axis=0)
    chosen = result.cascade.astype(int)
    picked = chosen >= 0
    assert np.all(contains[chosen[picked], np.flatnonzero(picked)] | ~robust[picked])
    any_box = contains.any(axis=0)
    np.testing.assert_array_equal(picked[robust], any_box[robust])
    if selection == "map":
        expected = np.where(any_box, np.argmax(contains, axis=0), -1)
    else:
        area = np.array([0.01, 0.09, 0.04])[:, None]
        expected = np.where(any_box, np.argmin(np.where(contains, area, np.inf), axis=0), -1)
    np.testing.assert_array_equal(chosen[robust], expected[robust])
    assert np.all(np.isnan(result.lit[~picked])) and np.all(result.lit[picked] == 1.0)
    assert len(set(expected[robust])) == 4


def lit_reference(depth, coords, receiver, *, filter, size):
    """Expected S from the texel-unit position p = coords / 2**bits, in float64."""
    p = coords / UNIT
    top = depth.shape[0] - 1
    lit = lambda i, j: receiver <= depth[np.clip(j, 0, top), np.clip(i, 0, top)]  # noqa: E731
    if filter == "pcf_bilinear":
        q = p - 0.5
        base = np.floor(q).astype(int)
        f = q - base
        i, j = base[:, 0], base[:, 1]
        return ((1 - f[:, 0]) * (1 - f[:, 1]) * lit(i, j) + f[:, 0] * (1 - f[:, 1]) * lit(i + 1, j)
                + (1 - f[:, 0]) * f[:, 1] * lit(i, j + 1) + f[:, 0] * f[:, 1] * lit(i + 1, j + 1))
    i, j = np.floor(p[:, 0]).astype(int), np.floor(p[:, 1]).astype(int)
    r = size // 2 if filter == "pcf" else 0
    total = sum(lit(i + di, j + dj) for di in range(-r, r + 1) for dj in range(-r, r + 1))
    return total / (2 * r + 1) ** 2


@pytest.mark.parametrize("filter,size", [("none", 1), ("pcf", 3), ("pcf", 5), ("pcf_bilinear", 1)])
def test_filters_match_a_numpy_reference_on_random_depth_maps(filter, size, device):
    rng = np.random.default_rng(size + len(filter))
    resolution = 24
    depth = rng.uniform(0.0, 1.0, (1, resolution, resolution)).astype(np.float32)
    depth[0, rng.integers(0, resolution, 40), rng.integers(0, resolution, 40)] = np.inf
    n = 4000
    coords = rng.integers(3 * UNIT, (resolution - 3) * UNIT, (1, n, 2))
    receiver = rng.uniform(0.0, 1.0, (1, n)).astype(np.float32)
    lit, cascade, blend = lookup(depth, coords, receiver, np.ones(n), splits=np.array([0.0, 2.0]), filter=filter,
                                 filter_size=size, device=device)
    assert np.all(cascade == 0) and not np.any(blend)
    expected = lit_reference(depth[0], coords[0], receiver[0], filter=filter, size=size)
    np.testing.assert_allclose(lit, expected, rtol=1e-6, atol=1e-7)
    assert lit.min() >= 0.0 and lit.max() <= 1.0 and 0.0 < lit.mean() < 1.0


@pytest.mark.parametrize("n", [1, 63, 64, 65, 200])
def test_every_receiver_is_looked_up_whatever_the_count_of_a_thread_run(n, device):
    """A CPU thread looks up a run of receivers: each, the last of a short run too, as it would alone."""
    rng = np.random.default_rng(n)
    depth = rng.uniform(0.0, 1.0, (1, 24, 24)).astype(np.float32)
    coords = rng.integers(3 * UNIT, 21 * UNIT, (1, n, 2))
    receiver = rng.uniform(0.0, 1.0, (1, n)).astype(np.float32)
    together = lookup(depth, coords, receiver, np.ones(n), splits=np.array([0.0, 2.0]), filter="pcf", filter_size=3,
                      device=device)[0]
    alone = [lookup(depth, coords[:, k:k + 1], receiver[:, k:k + 1], np.ones(1), splits=np.array([0.0, 2.0]),
                    filter="pcf", filter_size=3, device=device)[0][0] for k in range(n)]
    np.testing.assert_array_equal(together, alone)


def test_blend_band_moves_linearly_toward_the_next_cascade(device):
    splits = np.array([1.0, 10.0, 20.0])
    depth = np.stack([np.full((8, 8), -np.inf), np.full((8, 8), np.inf)]).astype(np.float32)
    z = np.array([5.0, 8.2, 8.65, 9.1, 9.99, 10.0, 19.5])
    coords = np.full((2, z.shape[0], 2), 4 * UNIT, dtype=np.int64)
    lit, cascade, blend = lookup(depth, coords, np.zeros((2, z.shape[0]), np.float32), z, splits=splits,
                                 blend_band=0.2, device=device)
    weight = np.clip((z - 8.2) / 1.8, 0.0, 1.0)
    np.testing.assert_allclose(lit[:5], weight[:5], rtol=1e-6)
    np.testing.assert_array_equal(cascade, [0, 0, 0, 0, 0, 1, 1])
    np.testing.assert_array_equal(blend, [False, True, True, True, True, False, False])
    assert lit[5] == 1.0 and lit[6] == 1.0
    # The selection a weighted or moment filter runs after: the same cascades and band, and the weights.
    chosen, blend_weight, band = select_cascades(depth, coords, np.zeros((2, z.shape[0]), np.float32), z,
                                                 splits=splits, texel_area=np.ones(2), selection="interval", radius=0,
                                                 margin=1, blend_band=0.2, bits=BITS, device=device)
    np.testing.assert_array_equal(chosen, cascade)
    np.testing.assert_array_equal(band, blend)
    np.testing.assert_allclose(blend_weight, np.where(blend, weight, 0.0), rtol=1e-12)


def test_selection_for_a_filter_keeps_its_taps_inside_the_box(device):
    # A receiver 2 texels inside the edge of cascade 0 (interval-selected) holds the taps of a
    # radius-2 filter, not those of a radius-3 one.
    depth = np.full((2, 16, 16), np.inf, np.float32)
    coords = np.array([[[2 * UNIT + 9, 8 * UNIT]], [[8 * UNIT, 8 * UNIT]]], np.int64)
    args = (depth, coords, np.zeros((2, 1), np.float32), np.array([9.5]))
    common = dict(splits=np.array([1.0, 10.0, 20.0]), texel_area=np.ones(2), selection="interval", margin=1,
                  blend_band=0.2, bits=BITS, device=device)
    assert select_cascades(*args, radius=2, **common)[0].tolist() == [0]
    assert select_cascades(*args, radius=3, **common)[0].tolist() == [-1]


def test_unknown_names_list_the_valid_ones():
    args = (np.zeros((1, 8, 8), np.float32), np.zeros((1, 1, 2), np.int64), np.zeros((1, 1), np.float32), np.ones(1))
    with pytest.raises(ValueError, match=r"selection: expected one of \['best_resolution', 'interval', 'map', "
                                         r"'sphere', 'sphere_dither'\]"):
        lookup(*args, splits=np.array([0.0, 2.0]), selection="nearest")
    with pytest.raises(ValueError, match=r"filter: expected one of \['none', 'pcf', 'pcf_bilinear'\]"):
        lookup(*args, splits=np.array([0.0, 2.0]), filter="gaussian")
    with pytest.raises(ValueError, match=r"filter: expected one of \['none', 'pcf', 'pcf_bilinear'\]"):
        lookup(*args, splits=np.array([0.0, 2.0]), filter="pcf_tent")
    with pytest.raises(ValueError, match="radius: expected a non-negative integer"):
        shadow_lookup(*args, splits=np.array([0.0, 2.0]), texel_area=np.ones(1), selection="interval", filter="pcf",
                      radius=-1, margin=1, blend_band=0.0, bits=BITS)
    assert sorted(SELECTION_METHODS) == ["best_resolution", "interval", "map", "sphere", "sphere_dither"]
    assert sorted(family_filters("box")) == ["none", "pcf", "pcf_bilinear"]


@pytest.mark.parametrize("offset", [(0.0, 0.0, 0.0), (2e5, 0.0, -1e5)], ids=["origin", "far"])
def test_moving_the_box_by_whole_texels_keeps_S_bit_identical_at_fixed_receivers(offset, device):
    rng = np.random.default_rng(23)
    resolution, texel = 1100, 0.0371
    shifts = np.array([[0, 0], [1000, -1000], [-999, 7], [3, 1]])
    basis = light_basis(LIGHT)
    anchor = np.floor((basis @ np.asarray(offset))[:2] / texel)
    cs = cascade_set(origins=[anchor + s for s in shifts], texels=[texel] * 4, resolution=resolution, margin=3)
    # A soup of casters over every box, denser where the first box overlaps each moved one, stacked
    # 0-30 m deep along the light.
    lo = np.maximum(shifts[1:], 0)
    hi = np.minimum(shifts[1:], 0) + resolution
    overlap = rng.uniform(lo, hi, (1500, 3, 2)).reshape(-1, 1, 2)
    spread = rng.uniform(-1000, resolution + 1000, (1500, 1, 2))
    centre = (anchor + np.concatenate([overlap, spread])) * texel
    corners = centre + rng.uniform(-1.5, 1.5, (6000, 3, 2))
    depth = rng.uniform(0.0, 30.0, (6000, 1, 1)) + rng.uniform(-0.5, 0.5, (6000, 3, 1))
    vertices = np.concatenate([corners, depth], axis=-1).reshape(-1, 3) @ basis
    triangles = np.arange(18000).reshape(-1, 3)
    points = np.stack([fixed_point_coordinates(cs, c, vertices, bits=BITS) for c in range(4)])
    maps, _ = rasterize_depth(points, light_depth(cs, vertices), triangles, resolution=resolution, bits=BITS,
                              device=device)
    # Receivers on the casters (random barycentrics), with their normals.
    w = rng.dirichlet(np.ones(3), 6000)
    v = vertices[triangles]
    receivers = np.einsum("tk,tkd->td", w, v)
    normals = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    normals = (normals / np.linalg.norm(normals, axis=1, keepdims=True)).astype(np.float32)
    for filter, size in (("none", 1), ("pcf", 3), ("pcf", 5), ("pcf_bilinear", 1)):
        settings = ShadowSettings(cascades=1, resolution=resolution, selection="map", filter=filter, filter_size=size,
                                  bias_constant=0.002, bias_slope=1.0, normal_offset=0.5)
        results = []
        for c in range(4):
            one = CascadeSet(basis=cs.basis, zref=cs.zref, splits=cs.splits[:2], cascades=(cs.cascades[c],),
                             margin_texels=3)
            results.append(lookup_shadow(ShadowMaps(one, maps[c:c + 1], 0), points=receivers, normals=normals,
                                         view_depth=np.ones(6000), settings=settings, device=device))
        for c in range(1, 4):
            both = (results[0].cascade == 0) & (results[c].cascade == 0)
            assert both.sum() > 50
            assert 0.0 < results[0].lit[both].mean() < 1.0
            assert np.array_equal(results[0].lit[both], results[c].lit[both]), (filter, size, shifts[c])


def _lit_ground_fraction_with_partial_shadow(*, receiver_plane_bias: bool) -> float:
    """Fraction of ray-traced-lit ground pixels whose PCF result is not fully lit (shadow acne)."""
    from csmlab.camera import CameraPose
    from csmlab.geometry import rotation_looking_at
    from csmlab.light import direction_from_angles
    from csmlab.render import render_frame
    from csmlab.scene import make_scene

    scene = make_scene("plane_box", box_center=(40.0, 40.0))
    pose = CameraPose(position=(0.0, 3.0, 0.0), orientation=rotation_looking_at((0.3, -0.5, -1.0)), aspect=2.0)
    settings = ShadowSettings(cascades=2, resolution=256, filter="pcf", filter_size=5, bias_slope=0.25,
                              normal_offset=0.0, shadow_distance=60.0, receiver_plane_bias=receiver_plane_bias)
    frame = render_frame(scene, pose, direction_from_angles(elevation_deg=25.0, azimuth_deg=70.0), settings,
                         width=96, height=48)
    lit_ground = (frame.view.reference == 1.0) & (frame.shadow.cascade >= 0)
    assert lit_ground.sum() > 1000
    return float(np.mean(frame.shadow.lit[lit_ground] < 1.0))


def test_receiver_plane_bias_leaves_a_lit_plane_fully_lit_under_a_wide_filter():
    # Oracle: the ray-traced reference says the ground is lit; a planar receiver compared against its
    # own tangent plane at every tap has nothing to self-shadow. Without the plane bias, the 5x5 taps
    # two texels away fall behind the stored depth of a surface sloped to the light: acne.
    assert _lit_ground_fraction_with_partial_shadow(receiver_plane_bias=True) == 0.0
    assert _lit_ground_fraction_with_partial_shadow(receiver_plane_bias=False) > 0.05


def test_receiver_coordinates_on_the_device_equal_the_host_receiver_lookup_bit_for_bit(device):
    """The kernel finishing csmlab.texels.receiver_lookup gives its coordinates, depths and slopes exactly."""
    from csmlab.cascades import Cascade, CascadeSet
    from csmlab.geometry import light_basis
    from csmlab.texels import fixed_point_origin, receiver_lookup

    rng = np.random.default_rng(5)
    cascades = tuple(Cascade(split_near=0.1, split_far=50.0, slice_near=0.1, slice_far=50.0,
                             texel_size=np.array([t, 1.3 * t]), origin=np.array(o), resolution=64, depth_near=-1e3,
                             depth_far=1e3)
                     for t, o in ((0.0371, (2.0e4, -17.0)), (0.3, (-250.0, 31.0)), (1.7, (3.0, 4.0))))
    cs = CascadeSet(basis=light_basis([0.3, -0.8, 0.2]), zref=-3.25, splits=np.array([0.1, 5.0, 20.0, 50.0]),
                    cascades=cascades, margin_texels=2)
    points = rng.uniform(-1e3, 1e3, (5000, 3)) + np.array([7.5e5, 0.0, 0.0])
    normals = rng.normal(size=(5000, 3)).astype(np.float32)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)  # about half turned from the light
    # The last: a bias model's constant per cascade (csmlab.filters: depth range and texel scaling).
    for bits, offset, constant, slope in ((8, 0.5, 0.0, 1.0), (12, 1.25, 0.013, 2.5),
                                          (10, 2.0, np.array([0.092, 0.137, 0.52]), 0.0)):
        expected = receiver_lookup(cs, points, normals, bits=bits, normal_offset=offset, bias_constant=constant,
                                   bias_slope=slope)
        got = receiver_coordinates(
            points, normals, basis=cs.basis, texel_size=np.stack([c.texel_size for c in cs.cascades]),
            origin_fixed=np.stack([fixed_point_origin(cs, c, bits=bits) for c in range(len(cs))]), zref=cs.zref,
            bits=bits, bias=BiasSettings(offset, constant, slope), device=device)
        assert np.isnan(expected[1]).any()
        for e, g in zip(expected, got):
            np.testing.assert_array_equal(g, e)
        picked = np.array([4999, 3, 3, 1200])
        for e, g in zip(expected, receiver_coordinates(
                points, normals, basis=cs.basis, texel_size=np.stack([c.texel_size for c in cs.cascades]),
                origin_fixed=np.stack([fixed_point_origin(cs, c, bits=bits) for c in range(len(cs))]), zref=cs.zref,
                bits=bits, bias=BiasSettings(offset, constant, slope), receivers=picked, device=device)):
            np.testing.assert_array_equal(g, e[:, picked])


def _world_case(device, bias=BiasSettings(normal_offset=0.75, bias_constant=0.01, bias_slope=1.5)):
    """Receivers about three nested boxes' centre and maps in their depth range (the world lookups' tests), moved
    and biased by ``bias``."""

    rng = np.random.default_rng(11)
    size, count = 32, 3
    texel = np.array([[0.05, 0.06], [0.2, 0.2], [0.9, 0.8]])
    # Nested boxes about one light-space centre, as a camera's cascades are.
    centre = np.array([1500.0, -800.0])
    origin = np.rint((centre / texel - size / 2) * UNIT).astype(np.int64)
    basis = light_basis([0.3, -0.8, 0.2])
    # Receivers about the centre, each box's share spread over it (some outside every box), normals
    # of every kind; each one's view depth in its box's split interval, many in its blend band.
    splits = np.array([0.1, 4.0, 15.0, 60.0])
    light = np.concatenate([np.column_stack([centre + rng.normal(scale=size * t.max() * 0.3, size=(400, 2)),
                                             rng.normal(size=400)]) for t in texel])
    depths = np.concatenate([rng.uniform(splits[c] + 0.4 * (splits[c + 1] - splits[c]), splits[c + 1], 400)
                             for c in range(count)])
    points = light @ basis
    normals = rng.normal(size=points.shape).astype(np.float32)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    receivers = rng.permutation(points.shape[0])[:900]
    view_depth = depths[receivers]
    conversion = dict(basis=basis, texel_size=texel, origin_fixed=origin, zref=-2.0, bits=BITS, bias=bias,
                      device=device)
    coords, receiver_depth, slope = receiver_coordinates(points, normals, receivers=receivers, **conversion)
    finite = receiver_depth[np.isfinite(receiver_depth)]
    maps = rng.uniform(finite.min(), finite.max(), (count, size, size)).astype(np.float32)
    maps[:, ::5, ::3] = np.inf
    return dict(size=size, count=count, texel=texel, centre=centre, basis=basis, splits=splits, points=points,
                normals=normals, receivers=receivers, view_depth=view_depth, conversion=conversion, coords=coords,
                receiver_depth=receiver_depth, slope=slope, maps=maps)


def _split_spheres(case, device):
    """A split sphere about the boxes' centre per cascade, as wide as 0.4 of its box."""
    from csmlab.kernels.shadow import split_sphere_cascades

    return split_sphere_cascades(
        case["points"][case["receivers"]], centres=np.tile(np.append(case["centre"], 0.0) @ case["basis"],
                                                           (case["count"], 1)),
        radii=0.4 * case["size"] * case["texel"].max(axis=1), device=device)


@pytest.mark.parametrize("selection", sorted(SELECTION_METHODS))
def test_world_receivers_look_up_the_same_bits_as_converted_ones(selection, device):
    """shadow_lookup_world converts each receiver where it reads it; receiver_coordinates + shadow_lookup gives the
    same."""
    from csmlab.kernels.shadow import shadow_lookup_world

    case = _world_case(device)
    maps, splits, texel, conversion = case["maps"], case["splits"], case["texel"], case["conversion"]
    coords, receiver_depth, slope = case["coords"], case["receiver_depth"], case["slope"]
    points, normals, receivers, view_depth = case["points"], case["normals"], case["receivers"], case["view_depth"]
    for filter, filter_size, blend_band, plane in (("none", 1, 0.0, True), ("pcf", 3, 0.3, True),
                                                   ("pcf", 5, 0.0, False), ("pcf_bilinear", 1, 0.2, True)):
        common = dict(splits=splits, texel_area=np.prod(texel, axis=1), selection=selection, filter=filter,
                      radius=radius(filter, filter_size), margin=2, blend_band=blend_band, bits=BITS, device=device)
        if selection in ("sphere", "sphere_dither"):
            # sphere_dither: the kernel reads the cascade csmlab.cascades.borders chose, as for sphere.
            common["sphere_cascade"] = _split_spheres(case, device)
        converted = shadow_lookup(maps, coords, receiver_depth, view_depth, receiver_slope=slope if plane else None,
                                  **common)
        world = shadow_lookup_world(maps, points, normals, view_depth, receivers=receivers,
                                    receiver_plane_bias=plane,
                                    **{k: v for k, v in conversion.items() if k not in ("bits", "device")},
                                    **common)
        for a, b in zip(converted, world):
            np.testing.assert_array_equal(a, b)
        lit, chosen, blended = world
        assert np.isfinite(lit).sum() > 100 and 0 < np.mean(lit[np.isfinite(lit)]) < 1
        assert len(set(chosen.tolist()) - {-1}) >= 2
        assert blended.any() == (blend_band > 0.0)


@pytest.mark.parametrize("scale", ["none", "one_minus_cos", "sin", "one_minus_cos_lateral"])
def test_world_receivers_selected_eight_at_a_time_look_up_the_bits_of_converted_ones(scale, device):
    """On the CPU a thread takes world receivers through the interval selection eight at a time (native vector code,
    csmlab.kernels.shadow.world_block): under every normal-offset scale, with MJP's plane offset and without, with
    NaN normals and view depths, the same bits as receiver_coordinates + shadow_lookup, whose receivers are converted
    one at a time by Warp's code."""
    from csmlab.kernels.shadow import shadow_lookup_world

    for cap in (0.0, 0.02):
        bias = BiasSettings(normal_offset=0.75, bias_constant=0.01, bias_slope=1.5, normal_scale=scale,
                            plane_offset=cap, normal_offset_m=0.003)
        case = _world_case(device, bias)
        normals, view_depth = case["normals"].copy(), case["view_depth"].copy()
        normals[case["receivers"][::97]] = np.nan
        view_depth[5::89] = np.nan
        coords, receiver_depth, slope = (receiver_coordinates(case["points"], normals, receivers=case["receivers"],
                                                              **case["conversion"]))
        for filter, filter_size, blend_band in (("pcf", 3, 0.3), ("pcf", 5, 0.0), ("pcf_bilinear", 1, 0.0)):
            common = dict(splits=case["splits"], texel_area=np.prod(case["texel"], axis=1), selection="interval",
                          filter=filter, radius=radius(filter, filter_size), margin=2, blend_band=blend_band,
                          bits=BITS, device=device)
            converted = shadow_lookup(case["maps"], coords, receiver_depth, view_depth, receiver_slope=slope,
                                      **common)
            world = shadow_lookup_world(case["maps"], case["points"], normals, view_depth,
                                        receivers=case["receivers"], receiver_plane_bias=True,
                                        **{k: v for k, v in case["conversion"].items() if k not in ("bits", "device")},
                                        **common)
            for a, b in zip(converted, world):
                np.testing.assert_array_equal(a, b)
            lit, chosen, _ = world
            assert np.isfinite(lit).sum() > 100 and len(set(chosen.tolist()) - {-1}) == 3
            assert np.isnan(lit[5::89]).all()


@pytest.mark.parametrize("selection", sorted(SELECTION_METHODS))
def test_world_receivers_picked_for_a_weighted_filter_filter_the_same_bits_as_converted_ones(selection, device):
    """select_world_cascades converts each receiver into the cascades it reads and hands weighted_pcf those rows
    (picked): the same cascades, weights, blend and S, bit for bit, as receiver_coordinates, select_cascades and
    weighted_pcf over every cascade's rows."""
    from csmlab.kernels.pcf import weighted_pcf
    from csmlab.kernels.shadow import select_world_cascades

    case = _world_case(device)
    maps, texel, conversion = case["maps"], case["texel"], case["conversion"]
    for filter, width, reach, blend_band, plane in (("pcf_tent_bilinear", 3.5, 5, 0.3, False),
                                                    ("pcf_castano", 2.5, 4, 0.2, True),
                                                    ("pcf_gaussian", 1.0, 2, 0.0, True),
                                                    ("pcf_bilinear_box", 1.5, 3, 0.3, True)):
        common = dict(splits=case["splits"], texel_area=np.prod(texel, axis=1), selection=selection, radius=reach,
                      margin=2, blend_band=blend_band, bits=BITS, device=device)
        if selection in ("sphere", "sphere_dither"):
            common["sphere_cascade"] = _split_spheres(case, device)
        slope = case["slope"] if plane else None
        chosen, weight, band = select_cascades(maps, case["coords"], case["receiver_depth"], case["view_depth"],
                                               **common)
        filtered = dict(filter=filter, width=width, radius=reach, bits=BITS, device=device)
        expected = weighted_pcf(maps, case["coords"], case["receiver_depth"], cascade=chosen, receiver_slope=slope,
                                blend_weight=weight, **filtered)
        picked = select_world_cascades(maps, case["points"], case["normals"], case["view_depth"],
                                       receivers=case["receivers"], receiver_plane_bias=plane,
                                       **{k: v for k, v in conversion.items() if k not in ("bits", "device")},
                                       **common)
        for a, b in zip((chosen, weight, band), picked[:3]):
            np.testing.assert_array_equal(a, b)
        assert (picked[5] is None) == (not plane)
        got = weighted_pcf(maps, picked[3], picked[4], cascade=picked[0], receiver_slope=picked[5],
                           blend_weight=picked[1], picked=True, **filtered)
        np.testing.assert_array_equal(got, expected)
        assert np.isfinite(got).sum() > 100 and 0 < np.nanmean(got) < 1
        assert (weight > 0).any() == (blend_band > 0.0)


def test_bias_models_scale_the_constant_bias_per_cascade_as_the_engines_do():
    """Godot 4 (light_storage.cpp, update_light_buffers): shadow_bias[j] = SHADOW_BIAS / 100 · bias_scale with
    bias_scale = (z_max − z_min_cam) · soft_shadow_scale (blur 1.0 × Soft Low radius 2.0), SHADOW_BIAS 0.1 by default;
    Stride (ShadowMapReceiverBase.sdsl): DepthBias 0.01 of the normalized [0, 2r] depth; Unity URP
    (ShadowUtils.GetShadowBias): depthBias = bias · frustumSize / resolution, one texel at the default 1."""
    from csmlab.cascades import Cascade, CascadeSet
    from csmlab.filters import _cascade_bias
    from csmlab.geometry import light_basis
    from csmlab.settings import ShadowSettings

    spans = np.array([45.8, 68.4, 141.8, 261.0])
    texels = np.array([0.0126, 0.0236, 0.0594, 0.1177])
    cascades = tuple(Cascade(split_near=0.1, split_far=10.0 * (k + 1), slice_near=0.1, slice_far=10.0 * (k + 1),
                             texel_size=np.array([t, t]), origin=np.zeros(2), resolution=2048, depth_near=-5.0,
                             depth_far=-5.0 + d) for k, (t, d) in enumerate(zip(texels, spans)))
    cs = CascadeSet(basis=light_basis([0.3, -0.8, 0.2]), zref=0.0, splits=np.array([0.1, 10.0, 20.0, 30.0, 40.0]),
                    cascades=cascades, margin_texels=2)
    godot = _cascade_bias(cs, ShadowSettings(bias_depth_range=0.1 / 100.0 * 2.0))
    np.testing.assert_allclose(godot, 0.1 / 100.0 * spans * (1.0 * 2.0), rtol=1e-12)
    np.testing.assert_allclose(godot, [0.0916, 0.1368, 0.2836, 0.522], rtol=1e-12)  # 9.2 / 13.7 / 28.4 / 52.2 cm
    np.testing.assert_allclose(_cascade_bias(cs, ShadowSettings(bias_texels=1.0, bias_constant=0.02)), 0.02 + texels)
    assert _cascade_bias(cs, ShadowSettings(bias_constant=0.02)) == 0.02  # no model: the scalar, bit for bit


@pytest.mark.parametrize("scale", ["none", "one_minus_cos", "sin", "one_minus_cos_lateral"])
def test_normal_offset_scales_are_the_engines_on_host_and_device_bit_for_bit(scale, device):
    """The receiver moved by normal_offset texels along its normal, times the engine's angle term:
    URP ApplyShadowBias / Stride GetShadowPositionOffset ``(1 − saturate(N·L))``, Filament computeLightSpacePosition
    ``sinθ``, Godot 4 ``N (1 − max(0, dot(light_dir, −N)))`` (light_dir toward the light) less its component along
    the light (the depth kept)."""
    from csmlab.cascades import Cascade, CascadeSet
    from csmlab.geometry import light_basis
    from csmlab.texels import fixed_point_origin, receiver_lookup

    texel, offset, bits = 0.25, 2.0, 12
    cascade = Cascade(split_near=0.1, split_far=50.0, slice_near=0.1, slice_far=50.0, texel_size=np.array([texel] * 2),
                      origin=np.array([-40.0, -40.0]), resolution=512, depth_near=-1e3, depth_far=1e3)
    cs = CascadeSet(basis=light_basis([0.3, -0.8, 0.2]), zref=-3.25, splits=np.array([0.1, 50.0]),
                    cascades=(cascade,), margin_texels=2)
    rng = np.random.default_rng(3)
    points = rng.uniform(-5.0, 5.0, (400, 3))
    normals = rng.normal(size=(400, 3)).astype(np.float32)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    args = dict(bits=bits, normal_offset=offset, bias_constant=0.0, bias_slope=0.0, normal_scale=scale)
    # Stride's world-space part of the offset (normal_offset_m) rides along: 2 · NormalOffsetScale / atlas size.
    metres = 2.0 * 10.0 / 4096.0
    args["normal_offset_m"] = metres
    coords, depth, _ = receiver_lookup(cs, points, normals, **args)
    got = receiver_coordinates(points, normals, basis=cs.basis, texel_size=np.array([[texel, texel]]),
                               origin_fixed=np.stack([fixed_point_origin(cs, 0, bits=bits)]), zref=cs.zref,
                               bits=bits, bias=_bias_settings(args), device=device)
    for e, g in zip((coords, depth), got[:2]):
        np.testing.assert_array_equal(g, e)
    # The engines' formulas in light space: cos θ = n · (−d), the offset o = k(θ) · normal_offset · texel · n.
    n = normals.astype(np.float64) @ cs.basis.T
    p = points @ cs.basis.T
    cos = -n[:, 2]
    # Godot's light_dir points toward the light (light_storage.cpp: the light's +Z), in light space (0, 0, −1).
    godot_light_dir = np.array([0.0, 0.0, -1.0])
    k = {"none": np.ones_like(cos), "one_minus_cos": 1.0 - np.clip(cos, 0.0, 1.0), "sin": np.sqrt(1.0 - cos**2),
         "one_minus_cos_lateral": 1.0 - np.maximum(0.0, (-n) @ godot_light_dir)}[scale]
    moved = p + (k * (offset * texel + metres))[:, None] * n
    if scale == "one_minus_cos_lateral":
        moved[:, 2] = p[:, 2]                              # normal_bias -= light_dir · dot(light_dir, normal_bias)
    lit = cos > 0.0
    base, base_depth, _ = receiver_lookup(cs, points, normals, **{**args, "normal_offset": 0.0, "normal_offset_m": 0.0})
    np.testing.assert_allclose((coords[0, lit] - base[0, lit]) / 2.0**bits, (moved - p)[lit, :2] / texel,
                               atol=2.0**-bits)
    np.testing.assert_allclose(depth[0, lit] - base_depth[0, lit], (moved - p)[lit, 2], atol=1e-5)


def test_mjps_receiver_plane_offset_is_its_formula_on_host_and_device_bit_for_bit(device):
    """MJP Mesh.hlsl SampleShadowMapFixedSizePCF with UsePlaneDepthBias: fractionalSamplingError =
    dot((1, 1) · texelSize, |receiverPlaneDepthBias|), lightDepth −= min(fractionalSamplingError, 0.01) in the
    cascade's normalized depth: the plane's depth change over one texel in x plus one in y, capped."""
    from csmlab.cascades import Cascade, CascadeSet
    from csmlab.geometry import light_basis
    from csmlab.texels import fixed_point_origin, receiver_lookup

    texel, bits, span = np.array([0.25, 0.3]), 10, 80.0
    cascade = Cascade(split_near=0.1, split_far=50.0, slice_near=0.1, slice_far=50.0, texel_size=texel,
                      origin=np.array([-40.0, -40.0]), resolution=512, depth_near=-40.0, depth_far=-40.0 + span)
    cs = CascadeSet(basis=light_basis([0.3, -0.8, 0.2]), zref=-3.25, splits=np.array([0.1, 50.0]),
                    cascades=(cascade,), margin_texels=2)
    rng = np.random.default_rng(4)
    points = rng.uniform(-5.0, 5.0, (500, 3))
    normals = rng.normal(size=(500, 3)).astype(np.float32)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    cap = 0.01 * span
    args = dict(bits=bits, normal_offset=0.0, bias_constant=0.0, bias_slope=0.0, plane_offset=np.array([cap]))
    _, depth, _ = receiver_lookup(cs, points, normals, **args)
    got = receiver_coordinates(points, normals, basis=cs.basis, texel_size=texel[None],
                               origin_fixed=np.stack([fixed_point_origin(cs, 0, bits=bits)]), zref=cs.zref,
                               bits=bits, bias=_bias_settings(args), device=device)
    np.testing.assert_array_equal(got[1], depth)
    _, plain, _ = receiver_lookup(cs, points, normals, **{**args, "plane_offset": 0.0})
    n = normals.astype(np.float64) @ cs.basis.T
    cos = -n[:, 2]
    lit = cos > 0.0
    # The receiver plane's depth change per texel: −n_xy / n_z · texel (clamped like tan θ at 10).
    per_texel = np.abs(np.clip(n[lit, :2] / cos[lit, None], -10.0, 10.0) * texel)
    mjp = np.minimum(per_texel.sum(axis=1), cap)
    np.testing.assert_allclose(plain[0, lit] - depth[0, lit], mjp, atol=2e-5)
    assert np.any(mjp == cap) and np.any(mjp < cap)


def _bias_settings(args: dict) -> BiasSettings:
    """The :class:`BiasSettings` of :func:`csmlab.texels.receiver_lookup`'s keyword arguments ``args``."""
    return BiasSettings(**{k: v for k, v in args.items() if k != "bits"})
