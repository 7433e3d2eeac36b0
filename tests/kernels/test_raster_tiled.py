"""The tiled rasterizer (csmlab.kernels.raster.tiled) gives the walk's maps and counts bit for bit, and a brute force's.

The walk (csmlab.kernels.raster.schedule on the CPU) is the rasterizer every earlier test checks
against ray casts; here the tiled one, on each device, must equal it exactly (+inf included) on the
shipped scenes through the whole depth pass (caster offsets, scrolled regions, alpha masks) and on
triangle soups made to hit every corner (odd map sizes, triangles across tile borders and off the
map, zero-area and huge triangles). An independent brute force (integer point-in-triangle at every
texel centre, depth from the plane through the three vertices) checks a handful of triangles.
"""

import numpy as np
import pytest

from csmlab.kernels.raster import light_space_mesh, rasterize_cascades, region_chunks, schedule, triangle_bounds
from csmlab.kernels.raster.dispatch import device_rasterizer, rasterizer_chosen
from csmlab.kernels.raster.kernels import STEPPED_EXTENT
from csmlab.kernels.raster.tiled import rasterize_tiled
from csmlab.scene.core import AlphaMask

BITS = 8


def soup(seed: int, *, count: int, resolution: int, size: float, cascades: int = 2):
    """``count`` random triangles (random windings) over ``cascades`` boxes of ``resolution``² texels, some beyond the
    maps, ``size`` texels across at most; plus a repeated vertex and a collinear sliver.

    Returns the mesh's light-plane x/y (metres), depths, triangles and the box keyword arguments.
    """
    rng = np.random.default_rng(seed)
    texel = 0.0731
    centre = rng.uniform(-6.0, resolution + 6.0, (count, 1, 2))
    corners = (centre + rng.uniform(-size, size, (count, 3, 2))).reshape(-1, 2)
    corners = np.concatenate([corners, corners[[0, 0, 1]], [[3.1, 4.7], [9.3, 14.1], [15.5, 23.5]]])
    xy = corners * texel + 1.37
    depth = np.repeat(rng.uniform(1.0, 30.0, len(xy) // 3), 3) + rng.uniform(-2.0, 2.0, len(xy))
    triangles = np.arange(len(xy)).reshape(-1, 3)
    origins = (np.array([[1.37, 1.37], [1.37 + 5.3 * texel, 1.37 - 2.1 * texel]])[:cascades] / texel * 2**BITS)
    box = dict(texel_size=np.full((cascades, 2), texel), origin=np.round(origins).astype(np.int64),
               resolution=resolution, bits=BITS)
    return xy, depth, triangles, box


def walked(mesh, **how):
    """The walk's maps and counts, on the CPU."""
    return schedule.rasterize_cascades(mesh, device="cpu", **how)


@pytest.mark.parametrize("resolution, size", [(37, 3.0), (64, 12.0), (61, 40.0), (16, 0.7), (45, 200.0)])
def test_tiles_give_the_walks_maps_and_counts_on_triangle_soups(resolution, size, device):
    """Odd and whole-tile sizes, triangles smaller than a texel to larger than the map, across tile borders."""
    xy, depth, triangles, box = soup(resolution, count=int(np.clip(4000 / size, 40, 800)), resolution=resolution,
                                     size=size)
    mesh = light_space_mesh(xy, depth, triangles)
    expected, expected_count = walked(mesh, **box)
    tiled, count = rasterize_tiled(mesh, device=device, **box)
    assert np.isfinite(expected).any()
    assert np.array_equal(tiled, expected)
    np.testing.assert_array_equal(count, expected_count)


@pytest.mark.parametrize("constant, slope", [(0.0, 1.5), (0.02, 0.0), (0.013, 2.5)])
def test_tiles_give_the_walks_maps_with_caster_offsets(constant, slope, device):
    xy, depth, triangles, box = soup(3, count=300, resolution=50, size=9.0)
    mesh = light_space_mesh(xy, depth, triangles)
    offset = dict(caster_constant=np.array([constant, 2.0 * constant]), caster_slope=slope)
    expected, expected_count = walked(mesh, **offset, **box)
    tiled, count = rasterize_tiled(mesh, device=device, **offset, **box)
    plain, _ = walked(mesh, **box)
    assert not np.array_equal(expected, plain)
    assert np.array_equal(tiled, expected)
    np.testing.assert_array_equal(count, expected_count)


def test_tiles_give_the_walks_maps_across_the_large_triangle_path(device):
    """Triangles spanning more than STEPPED_EXTENT (the walk's rounded large-triangle path) at 16 sub-texel bits."""
    rng = np.random.default_rng(5)
    span = STEPPED_EXTENT / 2 ** 17  # texels: the doubled extent at 16 bits
    corners = rng.uniform(-2.0 * span, 2.0 * span, (40, 3, 2)) + 20.0
    xy = corners.reshape(-1, 2) * 0.5
    mesh = light_space_mesh(xy, rng.uniform(-5.0, 5.0, len(xy)), np.arange(len(xy)).reshape(-1, 3))
    box = dict(texel_size=np.full((1, 2), 0.5), origin=np.zeros((1, 2), np.int64), resolution=41, bits=16)
    expected, expected_count = walked(mesh, **box)
    tiled, count = rasterize_tiled(mesh, device=device, **box)
    assert np.isfinite(expected).all()
    assert np.array_equal(tiled, expected)
    np.testing.assert_array_equal(count, expected_count)


def test_tiles_give_the_walks_maps_through_alpha_masks(device):
    """Masked triangles: covered centres are counted whether the mask keeps them or not, as the walk counts them."""
    xy, depth, triangles, box = soup(8, count=200, resolution=47, size=15.0)
    rng = np.random.default_rng(8)
    alpha = (rng.uniform(0.0, 1.0, (9, 7)) > 0.5).astype(np.float32)
    uv = rng.uniform(-1.0, 2.0, (len(xy), 2))
    vertex_mask = np.where(np.arange(len(xy)) // 3 % 2 == 0, 0, -1).astype(np.int32)
    mesh = light_space_mesh(xy, depth, triangles, uv=uv, vertex_mask=vertex_mask, alpha=(AlphaMask(alpha, 0.5),))
    expected, expected_count = walked(mesh, **box)
    tiled, count = rasterize_tiled(mesh, device=device, **box)
    opaque, _ = walked(light_space_mesh(xy, depth, triangles), **box)
    assert not np.array_equal(expected, opaque)
    assert np.array_equal(tiled, expected)
    np.testing.assert_array_equal(count, expected_count)


def test_tiles_rasterize_regions_afresh_keep_the_rest_and_count_alone_as_the_walk(device):
    """Regions cut across tile borders, culled chunks, stale maps and counting alone, as scrolling asks."""
    xy, depth, triangles, box = soup(11, count=400, resolution=53, size=8.0)
    mesh = light_space_mesh(xy, depth, triangles)
    regions = np.array([[(c, 0, 53, 0, 3), (c, 0, 53, 3, 20), (c, 0, 1, 20, 53), (c, 1, 37, 20, 53),
                         (c, 37, 53, 20, 53)] for c in range(2)]).reshape(-1, 5)[:-2]
    corner = box["origin"] / 2.0**BITS
    chunks = region_chunks(triangle_bounds(xy, triangles), texel_size=box["texel_size"], origin=corner,
                           regions=regions)
    stale = np.full((2, 53, 53), -7.0, np.float32)
    expected, expected_count = walked(mesh, regions=regions, chunks=chunks, depth=stale.copy(), **box)
    tiled, count = rasterize_tiled(mesh, regions=regions, chunks=chunks, depth=stale.copy(), device=device, **box)
    assert np.any(expected == -7.0) and np.isfinite(expected).any()
    assert np.array_equal(tiled, expected)
    np.testing.assert_array_equal(count, expected_count)
    none, counted = rasterize_tiled(mesh, regions=regions, chunks=chunks, count_only=True, device=device, **box)
    assert none is None
    np.testing.assert_array_equal(counted, expected_count)


@pytest.mark.parametrize("threads", [2, 3])
def test_tiles_launched_on_several_cpu_threads_give_the_same_maps(threads):
    xy, depth, triangles, box = soup(21, count=500, resolution=70, size=6.0)
    mesh = light_space_mesh(xy, depth, triangles)
    one, one_count = rasterize_tiled(mesh, **box)
    many, many_count = rasterize_tiled(mesh, threads=threads, **box)
    assert np.array_equal(many, one)
    np.testing.assert_array_equal(many_count, one_count)


def brute_force_depth(points, depth, triangles, resolution):
    """Per texel centre the nearest covering triangle's depth (+inf where none) and the coverage count, centre by
    centre.

    ``points`` ``(V, 2)`` integer fixed point (``2**-BITS`` texels); a centre is covered when it lies
    strictly inside, or on an edge that is a top edge or a left edge of the triangle as drawn with
    y up (Python integers: exact); depth is the plane through the three vertices solved in float64.
    """
    best = np.full((resolution, resolution), np.inf)
    count = 0
    unit = 2**BITS
    for tri in triangles:
        v = [(int(points[k, 0]), int(points[k, 1])) for k in tri]
        twice = (v[1][0] - v[0][0]) * (v[2][1] - v[0][1]) - (v[1][1] - v[0][1]) * (v[2][0] - v[0][0])
        if twice == 0:
            continue
        if twice < 0:
            v = [v[0], v[2], v[1]]
            tri = [tri[0], tri[2], tri[1]]
        plane = np.linalg.solve(np.array([[x, y, 1.0] for x, y in v]), depth[list(tri)])
        for j in range(resolution):
            for i in range(resolution):
                # Centres at (i + ½, j + ½) texels, doubled so as to stay integers.
                p = ((2 * i + 1) * unit, (2 * j + 1) * unit)
                inside = True
                for (sx, sy), (ex, ey) in zip(v, v[1:] + v[:1]):
                    e = (ex - sx) * (p[1] - 2 * sy) - (ey - sy) * (p[0] - 2 * sx)
                    top_or_left = ey < sy or (ey == sy and ex < sx)
                    inside &= e > 0 or (e == 0 and top_or_left)
                if inside:
                    count += 1
                    best[j, i] = min(best[j, i], plane @ [p[0] / 2.0, p[1] / 2.0, 1.0])
    return best, count


def test_a_handful_of_triangles_cover_what_a_brute_force_covers_at_the_depth_of_their_planes(device):
    """Shared edges and a fan around a vertex on texel centres (the tie rule), tile borders, and a triangle off the
    map."""
    unit = 2**BITS
    corners = np.array([
        [2.5, 2.5], [17.5, 2.5], [17.5, 17.5], [2.5, 17.5],  # two triangles sharing a diagonal through centres
        [24.5, 9.5], [30.0, 3.2], [33.7, 14.9], [21.1, 15.3],  # a fan around a centre, across the tile border at 32
        [40.0, 40.0], [60.0, 41.0], [50.0, 55.0],  # off the 37² map
        [5.0, 30.25], [36.9, 21.0], [12.3, 36.6],  # long and thin, over several tiles
    ])
    points = np.round(corners * unit).astype(np.int64)
    depth = np.array([3.0, 4.0, 5.0, 6.0, 1.0, 2.0, 2.5, 1.5, 0.5, 0.5, 0.5, 7.0, 0.25, 9.0])
    triangles = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7], [4, 7, 5], [8, 9, 10], [11, 12, 13]])
    expected, expected_count = brute_force_depth(points, depth, triangles, 37)
    texel = 0.1
    mesh = light_space_mesh(corners * texel, depth, triangles)
    box = dict(texel_size=np.full((1, 2), texel), origin=np.zeros((1, 2), np.int64), resolution=37, bits=BITS)
    tiled, count = rasterize_tiled(mesh, device=device, **box)
    covered = np.isfinite(expected)
    assert covered.sum() > 200 and count.sum() == expected_count > covered.sum()
    np.testing.assert_array_equal(np.isfinite(tiled[0]), covered)
    np.testing.assert_allclose(tiled[0][covered], expected[covered], rtol=2e-7, atol=1e-6)


def frames_of(kind: str, name: str, device: str, *, resolution: int, **bias):
    """Two frames' depth maps and texel counts of a shipped scene under rasterizer ``name``, the second scrolled."""
    from csmlab.camera import CameraPose
    from csmlab.cascades import build_cascades
    from csmlab.geometry import rotation_looking_at
    from csmlab.light import direction_from_angles
    from csmlab.render import prepare_scene, shadow_maps
    from csmlab.scene import make_scene
    from csmlab.settings import ShadowSettings

    scene = make_scene(kind, seed=1)
    dscene = prepare_scene(scene, device=device)
    settings = ShadowSettings(cascades=3, resolution=resolution, shadow_distance=60.0, stabilization="exact", **bias)
    light = direction_from_angles(elevation_deg=35.0, azimuth_deg=120.0)
    out, previous = [], None
    with rasterizer_chosen(name):
        for x in (-20.0, -17.0):
            pose = CameraPose(position=np.array([x, 12.0, 30.0]), orientation=rotation_looking_at([0.6, -0.25, -0.8]),
                              aspect=1.5, near=0.1, far=200.0)
            cs = build_cascades(pose=pose, light_direction=light, scene_corners=scene.corners(), settings=settings)
            previous = shadow_maps(dscene, cs, settings, scroll_from=previous)
            out.append((previous.depth, previous.texels_rasterized))
    return out


@pytest.mark.parametrize("kind, resolution, bias", [
    ("plane_box", 61, {}),
    ("terrain", 64, {"caster_bias_texels": 1.0, "caster_bias_slope": 2.0}),
    ("city", 75, {"caster_bias_units": 4.0}),
    ("fence", 48, {"caster_bias_slope": 1.5}),
    ("foliage", 53, {}),
])
def test_the_depth_pass_by_tiles_equals_the_walk_on_the_shipped_scenes(kind, resolution, bias, device):
    """Whole maps, then the scrolled frame's regions, with caster offsets, on the scenes (foliage: alpha masks)."""
    expected = frames_of(kind, "walk", "cpu", resolution=resolution, **bias)
    tiled = frames_of(kind, "tiled", device, resolution=resolution, **bias)
    for (want, want_count), (got, got_count) in zip(expected, tiled):
        assert np.isfinite(want).any()
        assert np.array_equal(got, want)
        assert got_count == want_count > 0


def test_cuda_gets_the_tiles_the_cpu_the_walk_and_a_choice_overrides_both(device, monkeypatch):
    assert device_rasterizer(device) == ("walk" if device == "cpu" else "tiled")
    calls = []
    monkeypatch.setattr("csmlab.kernels.raster.dispatch.rasterize_tiled", lambda mesh, **how: calls.append("tiled"))
    monkeypatch.setattr("csmlab.kernels.raster.dispatch.schedule.rasterize_cascades",
                        lambda mesh, **how: calls.append("walk"))
    rasterize_cascades(None, device=device)
    with rasterizer_chosen("tiled"):
        rasterize_cascades(None, device=device)
        rasterize_cascades(None, paths=object(), device=device)
        rasterize_cascades(None, points=np.zeros((1, 3, 2), np.int64), device=device)
        rasterize_cascades(None, near=np.zeros(1), device=device)
    with rasterizer_chosen("walk"):
        rasterize_cascades(None, device=device)
    assert calls == [device_rasterizer(device), "tiled", "walk", "walk", "walk", "walk"]
    with pytest.raises(ValueError, match="rasterizer"):
        with rasterizer_chosen("scanline"):
            pass


def test_tiles_refuse_what_the_walk_refuses():
    xy, depth, triangles, box = soup(1, count=10, resolution=20, size=3.0)
    mesh = light_space_mesh(xy, depth, triangles)
    with pytest.raises(ValueError, match="mesh"):
        rasterize_tiled(xy, **box)
    with pytest.raises(ValueError, match="regions"):
        rasterize_tiled(mesh, regions=[[0, 0, 21, 0, 5]], **box)
    with pytest.raises(ValueError, match="chunks"):
        rasterize_tiled(mesh, chunks=[[0, 5]], **box)
    with pytest.raises(ValueError, match="depth"):
        rasterize_tiled(mesh, depth=np.zeros((2, 20, 20)), **box)


@pytest.mark.parametrize("region", [(0, 5, 4, 0, 5), (0, 0, 5, 5, 4)])
def test_the_walk_and_the_tiles_refuse_a_region_turned_inside_out(region):
    xy, depth, triangles, box = soup(1, count=10, resolution=20, size=3.0)
    mesh = light_space_mesh(xy, depth, triangles)
    for rasterize in (schedule.rasterize_cascades, rasterize_tiled):
        with pytest.raises(ValueError, match=r"regions: expected rows \(c, i0, i1, j0, j1\)"):
            rasterize(mesh, regions=[region], **box)
    empty, counts = rasterize_tiled(mesh, regions=np.zeros((0, 5), np.int32), **box)
    assert np.isinf(empty).all() and counts.shape == (0,)
