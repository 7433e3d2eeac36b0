"""Depth rasterization against a float64 ray cast through every texel centre, and its exactness.

The oracle casts a line along the light direction through each texel centre and intersects it
with each triangle by Möller–Trumbore in float64, using the *dequantized snapped* vertices (the
geometry the rasterizer is defined on). It works in light space, where the line through texel
(i, j) is x = i + ½, y = j + ½ (texels) and the hit's third coordinate is the stored depth.
"""

import os
import subprocess
import sys

import numpy as np
import pytest
import warp as wp

from csmlab.cascades import Cascade, CascadeSet
from csmlab.geometry import light_basis
from csmlab.kernels.raster import light_space_mesh, rasterize_depth
from csmlab.texels import fixed_point_coordinates, light_depth

BITS = 8
DOWN = np.array([0.0, -1.0, 0.0])
OBLIQUE = np.array([0.42, -0.71, -0.33])


def cascade_set(*, direction, origins, texel, resolution, zref=0.0) -> CascadeSet:
    cascades = tuple(
        Cascade(split_near=0.1, split_far=50.0, slice_near=0.1, slice_far=50.0, texel_size=np.array([texel, texel]),
                origin=np.asarray(o, dtype=np.float64), resolution=resolution, depth_near=-1e3, depth_far=1e3)
        for o in origins
    )
    return CascadeSet(basis=light_basis(direction), zref=zref, splits=np.linspace(0.1, 50.0, len(origins) + 1),
                      cascades=cascades, margin_texels=2)


def triangle_soup(rng, cs: CascadeSet, *, count: int, lo, hi, size: float, offset=(0.0, 0.0, 0.0)):
    """``count`` random triangles (random windings) with corners in light-space texels [lo, hi) of cascade 0."""
    t = cs.cascades[0].texel_size[0]
    centre = rng.uniform(lo, hi, (count, 1, 2)) + cs.cascades[0].origin
    corners = centre + rng.uniform(-size, size, (count, 3, 2))
    depth = rng.uniform(1.0, 30.0, (count, 1)) + rng.uniform(-2.0, 2.0, (count, 3))
    light = np.concatenate([corners * t, depth[..., None]], axis=-1).reshape(-1, 3)
    vertices = light @ cs.basis + np.asarray(offset)
    return vertices, np.arange(3 * count).reshape(count, 3)


def rasterize(cs: CascadeSet, vertices, triangles, *, device, paths=None):
    points = np.stack([fixed_point_coordinates(cs, c, vertices, bits=BITS) for c in range(len(cs))])
    return rasterize_depth(points, light_depth(cs, vertices), triangles, resolution=cs.cascades[0].resolution,
                           bits=BITS, paths=paths, device=device)


def ray_cast_depth(corners, depth, resolution):
    """Nearest hit depth per texel centre (+inf where none) and the texels within 1e-6 texel of an edge.

    ``corners``: (T, 3, 2) float64 texels from the box origin; ``depth``: (T, 3) float64 metres.
    """
    best = np.full((resolution, resolution), np.inf)
    ambiguous = np.zeros((resolution, resolution), dtype=bool)
    direction = np.array([0.0, 0.0, 1.0])
    for tri, z in zip(corners, depth):
        lo = np.clip(np.floor(tri.min(axis=0) - 0.5).astype(int), 0, resolution - 1)
        hi = np.clip(np.ceil(tri.max(axis=0) + 0.5).astype(int), 0, resolution - 1)
        jj, ii = np.mgrid[lo[1]:hi[1] + 1, lo[0]:hi[0] + 1]
        p = np.stack([ii + 0.5, jj + 0.5], axis=-1).reshape(-1, 2)
        v = np.concatenate([tri, z[:, None]], axis=1)
        e1, e2 = v[1] - v[0], v[2] - v[0]
        h = np.cross(direction, e2)
        a = e1 @ h
        near_edge = np.zeros(p.shape[0], dtype=bool)
        for k in range(3):
            s0, s1 = tri[k], tri[(k + 1) % 3]
            seg = s1 - s0
            f = np.clip(((p - s0) @ seg) / max(seg @ seg, 1e-300), 0.0, 1.0)
            near_edge |= np.linalg.norm(p - (s0 + f[:, None] * seg), axis=1) < 1e-6
        ambiguous[jj.ravel()[near_edge], ii.ravel()[near_edge]] = True
        if abs(a) < 1e-12:
            continue
        s = np.concatenate([p, np.zeros((p.shape[0], 1))], axis=1) - v[0]
        u = (s @ h) / a
        q = np.cross(s, e1)
        w = (q @ direction) / a
        t = (q @ e2) / a
        hit = (u >= 0) & (w >= 0) & (u + w <= 1)
        rows, cols = jj.ravel()[hit], ii.ravel()[hit]
        np.minimum.at(best, (rows, cols), t[hit])
    return best, ambiguous


@pytest.mark.parametrize("direction", [DOWN, OBLIQUE], ids=["down", "oblique"])
@pytest.mark.parametrize("resolution", [64, 128])
def test_depth_equals_ray_cast_through_every_texel_centre(direction, resolution, device):
    rng = np.random.default_rng(resolution + int(direction[0] * 100))
    cs = cascade_set(direction=direction, origins=[(-37.0, 912.0)], texel=0.0731, resolution=resolution)
    vertices, triangles = triangle_soup(rng, cs, count=1200, lo=-8, hi=resolution + 8, size=resolution / 12)
    # Zero-area triangles ride along: a repeated vertex and a sliver collinear in light space.
    n = vertices.shape[0]
    vertices = np.concatenate([vertices, vertices[[0, 0, 1]], vertices[3] + np.outer([0, 1, 2], cs.basis[2])])
    triangles = np.concatenate([triangles, np.arange(n, n + 6).reshape(2, 3)])
    depth, texels = rasterize(cs, vertices, triangles, device=device)

    fixed = fixed_point_coordinates(cs, 0, vertices, bits=BITS)
    expected, ambiguous = ray_cast_depth(fixed[triangles] / 2**BITS, light_depth(cs, vertices)[triangles], resolution)
    covered = np.isfinite(expected)
    compare = ~ambiguous
    print(f"R={resolution} light={direction.tolist()}: {ambiguous.sum()} of {resolution**2} texel centres "
          f"within 1e-6 texel of an edge excluded; {texels} texels rasterized")
    assert covered[compare].mean() > 0.5
    assert np.array_equal(np.isfinite(depth[0])[compare], covered[compare])
    both = compare & covered
    tolerance = np.spacing(np.abs(expected[both]).astype(np.float32))
    assert np.all(np.abs(depth[0][both] - expected[both]) <= tolerance)
    assert not np.any(np.isnan(depth))


def interpolated_depth_map(points, depth, triangles, resolution):
    """The depth map as specified, centre by centre in NumPy: ``float32((w_a·za + w_b·zb + w_c·zc) / area)``.

    ``points`` ``(V, 2)`` int64 fixed point (``2**-BITS`` texels), ``depth`` ``(V,)``; edge functions
    in exact integers at the centres (doubled units), the top-left rule on counter-clockwise edges.
    """
    best = np.full((resolution, resolution), np.inf, dtype=np.float32)
    unit = 2**BITS
    for t in triangles:
        (ax, ay), (bx, by), (cx, cy) = (2 * points[t]).tolist()
        za, zb, zc = depth[t]
        area = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
        if area == 0:
            continue
        if area < 0:
            (bx, by, zb), (cx, cy, zc), area = (cx, cy, zc), (bx, by, zb), -area
        jj, ii = np.mgrid[0:resolution, 0:resolution]
        px, py = (2 * ii + 1) * unit, (2 * jj + 1) * unit
        inside = np.ones((resolution, resolution), dtype=bool)
        weights = []
        for (sx, sy), (ex, ey) in (((ax, ay), (bx, by)), ((bx, by), (cx, cy)), ((cx, cy), (ax, ay))):
            w = (ex - sx) * (py - sy) - (ey - sy) * (px - sx)
            owns = ey - sy < 0 or (ey == sy and ex - sx < 0)
            inside &= (w > 0) | ((w == 0) & owns)
            weights.append(w.astype(np.float64))
        w_c, w_a, w_b = weights
        z = ((w_a * za + w_b * zb + w_c * zc) / float(area)).astype(np.float32)
        best = np.where(inside, np.minimum(best, z), best)
    return best


@pytest.mark.parametrize("size", [0.7, 3.0, 9.0, 30.0])
def test_every_depth_is_the_edge_function_interpolation_rounded_once_bit_for_bit(size, device):
    """Runs of every length (a vector's width and its masked tail, narrow and solved runs) give the specified bits."""
    rng = np.random.default_rng(int(size * 10))
    resolution = 48
    count = int(np.clip(1500 / size, 60, 1500))
    corners = rng.uniform(-4.0, resolution + 4.0, (count, 1, 2)) + rng.uniform(-size, size, (count, 3, 2))
    points = np.round(corners.reshape(-1, 2) * 2**BITS).astype(np.int64)
    depth = rng.uniform(-30.0, 30.0, len(points))
    triangles = np.arange(len(points)).reshape(-1, 3)
    rasterized, _ = rasterize_depth(points[None], depth, triangles, resolution=resolution, bits=BITS, device=device)
    expected = interpolated_depth_map(points, depth, triangles, resolution)
    assert np.isfinite(expected).sum() > 100
    np.testing.assert_array_equal(rasterized[0], expected)


def oversized_triangle(cs: CascadeSet):
    """World vertices ``(3, 3)`` of one triangle millions of texels across, behind the box: the large-triangle path."""
    t = cs.cascades[0].texel_size[0]
    corners = np.array([[-1e7, -1e7], [1e7, -1e7], [0.0, 1e7]]) + cs.cascades[0].origin
    return np.concatenate([corners * t, np.full((3, 1), 50.0)], axis=1) @ cs.basis


def path_test_triangles(rng, resolution: int):
    """Fixed-point triangles ``(V, 2)`` int64 (``2**-BITS`` texels), their depths ``(V,)`` and indices ``(T, 3)``:
    boxes holding one centre or none, small and wide walks, and triangles of 2**16 to 2**19 texels across the map.

    Half of the small ones have their corners on a quarter-texel grid, so that many texel centres lie exactly on
    an edge or a corner and the top-left rule decides them.
    """
    corners = [rng.uniform(-2.0, resolution + 2.0, (count, 1, 2)) + rng.uniform(-size, size, (count, 3, 2))
               for size, count in ((0.6, 3000), (3.0, 600), (12.0, 200), (40.0, 30))]
    corners = np.concatenate(corners)
    corners[::2] = np.round(corners[::2] * 4.0) / 4.0
    span = 2.0 ** np.array([16.0, 17.0, 17.5, 18.0, 19.0])
    big = np.stack([np.stack([-span + 0.375, -0.8125 * span + 3.25], 1), np.tile([[resolution - 2.5, 30.0625]],
                                                                                (len(span), 1)),
                    np.stack([0.625 * span, -span + 1.5], 1)], axis=1)
    points = np.round(np.concatenate([corners, big]).reshape(-1, 2) * 2**BITS).astype(np.int64)
    depth = rng.uniform(-30.0, 30.0, len(points))
    return points, depth, np.arange(len(points)).reshape(-1, 3)


FORCED_PATHS = {
    "one centre off": dict(one_centre=False),
    "runs always solved": dict(solved_columns=0),
    "runs never solved": dict(solved_columns=2**30),
    "walk only": dict(one_centre=False, solved_columns=0),
    "large triangle only": dict(stepped_extent=0),
    "walk everything": dict(stepped_extent=2**62),
}
"""Each of a triangle's paths forced on every triangle it can take (:func:`csmlab.kernels.raster.triangle_paths`)."""


@pytest.mark.parametrize("forced", FORCED_PATHS, ids=list(FORCED_PATHS))
def test_every_triangle_path_forced_gives_the_default_maps_bit_for_bit(forced, device):
    """One centre, walk (runs solved or not) and large triangle agree on the same triangles: depths and counts.

    So a changed threshold (:data:`csmlab.kernels.raster.kernels.ONE_CENTRE`, ``STEPPED_EXTENT``,
    ``SOLVED_COLUMNS``) that changes a result fails here, and forcing any path changes nothing.
    """
    from csmlab.kernels.raster import triangle_paths

    points, depth, triangles = path_test_triangles(np.random.default_rng(41), 48)
    expected, expected_count = rasterize_depth(points[None], depth, triangles, resolution=48, bits=BITS,
                                               device=device)
    assert np.isfinite(expected).mean() > 0.9 and expected_count > 48 * 48
    forced_maps, forced_count = rasterize_depth(points[None], depth, triangles, resolution=48, bits=BITS,
                                                paths=triangle_paths(**FORCED_PATHS[forced]), device=device)
    np.testing.assert_array_equal(forced_maps, expected)
    assert forced_count == expected_count


def test_every_path_gives_the_specified_depths_and_the_walk_its_exact_integers(device):
    """The default paths give :func:`interpolated_depth_map` (exact integer edge functions) on the small triangles,
    and the walk's threshold keeps every edge function below 2**53, where float64 integers are exact."""
    from csmlab.kernels.raster.kernels import STEPPED_EXTENT

    points, depth, triangles = path_test_triangles(np.random.default_rng(43), 32)
    small = triangles[:-5]
    rasterized, _ = rasterize_depth(points[None], depth, small, resolution=32, bits=BITS, device=device)
    np.testing.assert_array_equal(rasterized[0], interpolated_depth_map(points, depth, small, 32))
    assert 2 * STEPPED_EXTENT**2 <= 2**53


def fixed_point_triangles(corners_texels):
    """One cascade of fixed-point corners ``(1, 3T, 2)`` from texel positions ``(T, 3, 2)`` (multiples of 2**-BITS)."""
    c = np.asarray(corners_texels, dtype=np.float64) * 2**BITS
    assert np.array_equal(c, np.round(c))
    return c.astype(np.int64).reshape(1, -1, 2)


def coverage(corners_texels, resolution, *, device):
    """Per triangle, the boolean coverage map (rasterized one at a time)."""
    out = []
    for tri in np.asarray(corners_texels, dtype=np.float64):
        depth, _ = rasterize_depth(fixed_point_triangles([tri]), np.zeros(3), [[0, 1, 2]], resolution=resolution,
                                   bits=BITS, device=device)
        out.append(np.isfinite(depth[0]))
    return np.array(out)


def strictly_inside(corners, resolution):
    """Texel centres strictly inside a counter-clockwise convex polygon, in exact integer arithmetic."""
    c = (np.asarray(corners) * 2 * 2**BITS).astype(np.int64)
    j, i = np.mgrid[0:resolution, 0:resolution]
    px, py = (2 * i + 1) * 2**BITS, (2 * j + 1) * 2**BITS
    inside = np.ones((resolution, resolution), dtype=bool)
    for k in range(len(c)):
        (ax, ay), (bx, by) = c[k], c[(k + 1) % len(c)]
        inside &= (bx - ax) * (py - ay) - (by - ay) * (px - ax) > 0
    return inside


def test_two_triangles_sharing_an_edge_cover_each_texel_centre_once(device):
    # The shared diagonal A-C runs through texel centres every 2 texels; the outer edges miss every
    # centre (their corners sit at 37/256 and 91/256 of a texel), so the quad's interior and its
    # diagonal are exactly the centres that must be covered once.
    a, c = (2.5, 3.5), (42.5, 23.5)
    b, d = (40 + 37 / 256, 1 + 91 / 256), (4 + 91 / 256, 25 + 37 / 256)
    for first, second in (([a, b, c], [a, c, d]), ([a, c, b], [a, d, c]), ([a, b, c], [c, a, d])):
        maps = coverage([first, second], 48, device=device)
        assert not np.any(maps[0] & maps[1])
        expected = strictly_inside([a, b, c, d], 48)
        for corner in (a, c):
            expected[int(corner[1]), int(corner[0])] = (maps[0] | maps[1])[int(corner[1]), int(corner[0])]
        assert np.array_equal(maps[0] | maps[1], expected)
        assert maps[0].sum() > 100 and maps[1].sum() > 100


@pytest.mark.parametrize("span", [2**14, 2**17 - 64, 2**17, 2**19], ids=["stepped", "stepped-limit", "afresh",
                                                                          "afresh-far"])
def test_large_triangles_cover_exactly_the_centres_inside_them(span, device):
    # A triangle spanning about `span` texels: below 2**17 texels (2**26 doubled fixed-point units
    # at 8 bits) the rasterizer steps its edge functions texel to texel, from there on it evaluates
    # them afresh. Either way the covered centres are those strictly inside, in exact integers.
    resolution = 160
    # Two edges cross the map at odd slopes, so that many centres lie a fraction of a texel from them.
    tri = np.array([[-span + 0.375, -0.8125 * span + 3.25], [157.5, 150.0625], [0.625 * span, -span + 1.5]])
    (ux, uy), (vx, vy) = tri[1] - tri[0], tri[2] - tri[0]
    corners = tri if ux * vy - uy * vx > 0 else tri[::-1]
    covered = coverage([tri], resolution, device=device)[0]
    inside = strictly_inside(corners, resolution)
    assert 0 < inside.sum() < resolution**2
    assert np.array_equal(covered, inside)


def test_a_fan_around_a_texel_centre_covers_it_once(device):
    centre = np.array([16.5, 16.5])
    # Every spoke runs through further texel centres (its texel offsets share a factor of 2).
    spokes = np.array([[8, 2], [4, 6], [-6, 8], [-8, -2], [-2, -8], [6, -6]], dtype=np.float64)
    rim = centre + spokes
    fan = [[centre, rim[k], rim[(k + 1) % 6]] for k in range(6)]
    fan[2] = fan[2][::-1]
    maps = coverage(fan, 32, device=device)
    counts = maps.sum(axis=0)
    assert counts[16, 16] == 1
    inside = strictly_inside(rim, 32)
    assert np.all(counts[inside] == 1)
    assert counts.max() == 1


def test_triangles_smaller_than_a_texel_equal_the_ray_cast(device):
    # Most boxes hold one texel centre or none, as in a far cascade: the one-centre test and the walk
    # must both agree with the oracle.
    rng = np.random.default_rng(5)
    resolution = 48
    cs = cascade_set(direction=OBLIQUE, origins=[(3.0, -41.0)], texel=0.0731, resolution=resolution)
    vertices, triangles = triangle_soup(rng, cs, count=12000, lo=-1, hi=resolution + 1, size=0.6)
    depth, texels = rasterize(cs, vertices, triangles, device=device)
    fixed = fixed_point_coordinates(cs, 0, vertices, bits=BITS) / 2**BITS
    one_centre = np.all(np.floor(fixed[triangles].max(axis=1) - 0.5) == np.ceil(fixed[triangles].min(axis=1) - 0.5),
                        axis=1)
    assert one_centre.mean() > 0.3
    expected, ambiguous = ray_cast_depth(fixed[triangles], light_depth(cs, vertices)[triangles], resolution)
    compare = ~ambiguous
    assert np.array_equal(np.isfinite(depth[0])[compare], np.isfinite(expected)[compare])
    both = compare & np.isfinite(expected)
    assert both.mean() > 0.3
    assert np.all(np.abs(depth[0][both] - expected[both]) <= np.spacing(np.abs(expected[both]).astype(np.float32)))


def test_a_fan_smaller_than_a_texel_around_its_centre_covers_it_once(device):
    centre = np.array([16.5, 16.5])
    # Each triangle's box holds this one centre, on a vertex shared by all six.
    spokes = np.array([[0.5, 0.125], [0.25, 0.375], [-0.375, 0.5], [-0.5, -0.125], [-0.125, -0.5], [0.375, -0.375]])
    rim = centre + spokes
    fan = [[centre, rim[k], rim[(k + 1) % 6]] for k in range(6)]
    fan[4] = fan[4][::-1]
    counts = coverage(fan, 32, device=device).sum(axis=0)
    assert counts[16, 16] == 1
    assert counts.sum() == 1


@pytest.mark.parametrize("offset", [(0.0, 0.0, 0.0), (1e5, 20.0, -1e5)], ids=["origin", "far"])
def test_moving_the_box_by_whole_texels_shifts_the_depth_map_bit_for_bit(offset, device):
    rng = np.random.default_rng(11)
    resolution = 1100
    shifts = np.array([[0, 0], [1000, -1000], [-999, 7], [3, 1]])
    probe = cascade_set(direction=OBLIQUE, origins=[(0.0, 0.0)], texel=0.0371, resolution=resolution)
    anchor = np.floor((probe.basis @ np.asarray(offset))[:2] / 0.0371)
    cs = cascade_set(direction=OBLIQUE, origins=[anchor + s for s in shifts], texel=0.0371, resolution=resolution)
    vertices, triangles = triangle_soup(rng, cs, count=4000, lo=-1000, hi=resolution + 1000, size=40.0)
    depth, _ = rasterize(cs, vertices, triangles, device=device)
    for c, (kx, ky) in enumerate(shifts[1:], start=1):
        # Texel (i, j) of the moved box is texel (i + kx, j + ky) of the first one.
        i0, i1 = max(0, kx), min(resolution, resolution + kx)
        j0, j1 = max(0, ky), min(resolution, resolution + ky)
        window = depth[0, j0:j1, i0:i1]
        assert np.isfinite(window).mean() > 0.1
        assert np.array_equal(depth[c, j0 - ky:j1 - ky, i0 - kx:i1 - kx], window)


def test_degenerate_near_plane_crossing_and_oversized_triangles_stay_finite_and_in_bounds(device):
    cs = cascade_set(direction=OBLIQUE, origins=[(100.0, -50.0)], texel=0.05, resolution=64, zref=-5.0)
    t = 0.05
    to_world = lambda x, y, z: np.array([x * t, y * t, z]) @ cs.basis  # noqa: E731
    vertices = np.array([
        # Zero area: three collinear corners, and one corner three times.
        to_world(110, -40, 1.0), to_world(120, -30, 2.0), to_world(130, -20, 3.0),
        to_world(140, -20, 1.0), to_world(140, -20, 1.0), to_world(140, -20, 1.0),
        # Crossing the box's near plane (depth_near = -1000 m) by far: depth from -5000 to +5000 m.
        to_world(105, -45, -5000.0), to_world(125, -45, 5000.0), to_world(105, -25, 0.0),
        # Millions of texels across, far behind everything: covers the whole map.
        to_world(-1e7, -1e7, 50.0), to_world(1e7, -1e7, 50.0), to_world(0, 1e7, 50.0),
    ])
    depth, texels = rasterize(cs, vertices, np.arange(12).reshape(4, 3), device=device)
    assert depth.shape == (1, 64, 64)
    assert np.all(np.isfinite(depth))
    assert texels >= 64 * 64
    plane = light_depth(cs, to_world(0, 0, 50.0)[None])[0]
    near = depth[0] < plane
    assert 50 < near.sum() < 400
    np.testing.assert_array_equal(depth[0][~near], np.float32(plane))


def test_an_empty_scene_leaves_every_texel_empty(device):
    depth, texels = rasterize_depth(np.zeros((2, 3, 2), dtype=np.int64), np.zeros(3), [[0, 1, 2]], resolution=16,
                                    bits=BITS, device=device)
    assert depth.shape == (2, 16, 16) and np.all(depth == np.inf) and texels == 0


def test_bad_input_names_the_argument():
    with pytest.raises(ValueError, match="points: expected fixed-point vertices"):
        rasterize_depth(np.zeros((3, 2)), np.zeros(3), [[0, 1, 2]], resolution=16, bits=8)
    with pytest.raises(ValueError, match=r"triangles: expected indices in \[0, 3\)"):
        rasterize_depth(np.zeros((1, 3, 2), dtype=np.int64), np.zeros(3), [[0, 1, 3]], resolution=16, bits=8)
    with pytest.raises(ValueError, match="device: expected 'cpu' or 'cuda'"):
        rasterize_depth(np.zeros((1, 3, 2), dtype=np.int64), np.zeros(3), [[0, 1, 2]], resolution=16, bits=8,
                        device="tpu")
    with pytest.raises(ValueError, match="paths: expected a TrianglePaths"):
        rasterize_depth(np.zeros((1, 3, 2), dtype=np.int64), np.zeros(3), [[0, 1, 2]], resolution=16, bits=8,
                        paths="walk")


def test_a_light_space_mesh_refuses_vertices_that_are_not_finite_and_indices_outside_it():
    """Every value is checked; finite values near the float64 limit are accepted. The maps to rasterize into must be
    C-contiguous (the runs are walked along their rows)."""
    from csmlab.kernels.raster import rasterize_cascades

    box = dict(texel_size=[[1.0, 1.0]], origin=[[0, 0]], resolution=8, bits=8)
    xy = np.array([[1.0, 1.0], [6.0, 1.0], [1.0, 6.0], [1e308, 1e308], [1e308, 1e308]])
    z = np.array([1.0, 1.0, 1.0, 1e308, 1e308])
    depth, texels = rasterize_cascades(light_space_mesh(xy, z, [[0, 1, 2]]), **box)
    assert texels.sum() > 0 and np.isfinite(depth).sum() == texels.sum()
    for bad_xy, bad_z in ((np.where(np.arange(10).reshape(5, 2) == 7, np.nan, xy), z),
                          (xy, np.where(np.arange(5) == 3, -np.inf, z))):
        with pytest.raises(ValueError, match="expected 5 finite vertices and depths"):
            light_space_mesh(bad_xy, bad_z, [[0, 1, 2]])
    for bad in ([[0, 1, 5]], [[0, -1, 2]]):
        with pytest.raises(ValueError, match=r"triangles: expected indices of shape \(T, 3\) in \[0, 5\)"):
            light_space_mesh(xy, z, bad)
    with pytest.raises(ValueError, match="mesh: expected a LightSpaceMesh"):
        rasterize_cascades(xy, **box)
    with pytest.raises(ValueError, match="read-only"):
        light_space_mesh(xy, z, [[0, 1, 2]]).xy[0, 0] = 7.0
    strided = np.full((1, 8, 16), np.inf, dtype=np.float32)[:, :, ::2]
    with pytest.raises(ValueError, match="depth: expected C-contiguous float32 maps"):
        rasterize_cascades(light_space_mesh(xy, z, [[0, 1, 2]]), depth=strided, **box)


@pytest.mark.cuda
@pytest.mark.skipif(wp.get_cuda_device_count() == 0, reason="no CUDA device")
def test_cpu_and_cuda_rasterize_the_same_depth_bit_for_bit():
    """Every path on both devices (tiny, small, large and oversized triangles): the same maps and counts, bit for bit
    (the CUDA build fuses no multiply-add: tests/kernels/test_kernels.py)."""
    rng = np.random.default_rng(5)
    cs = cascade_set(direction=OBLIQUE, origins=[(3.0, 4.0), (-50.0, 20.0)], texel=0.0731, resolution=128)
    soups = [triangle_soup(rng, cs, count=2000, lo=-60, hi=190, size=size) for size in (0.6, 12.0)]
    vertices = np.concatenate([v for v, _ in soups] + [oversized_triangle(cs)])
    triangles = np.arange(len(vertices)).reshape(-1, 3)
    cpu, cpu_texels = rasterize(cs, vertices, triangles, device="cpu")
    cuda, cuda_texels = rasterize(cs, vertices, triangles, device="cuda:0")
    assert cpu_texels == cuda_texels
    np.testing.assert_array_equal(cpu, cuda)


def spatially_sorted(xy, triangles):
    """A soup's triangles listed by their first corner's light-space x, as meshes list neighbours together."""
    return triangles[np.argsort(xy[triangles[:, 0], 0], kind="stable")]


def test_device_fixed_point_and_culled_rasterization_equal_the_host_path_bit_for_bit(device):
    """rasterize_cascades (fixed point on the device, culled chunks) gives rasterize_depth's maps exactly."""
    from csmlab.kernels.raster import CHUNK_BITS, rasterize_cascades, region_chunks, triangle_bounds, whole_map_regions
    from csmlab.texels import fixed_point_origin, light_plane_coordinates

    rng = np.random.default_rng(11)
    cs = cascade_set(direction=OBLIQUE, origins=[(1000.0, -37.0), (1040.0, -20.0), (990.0, -60.0)], texel=0.0371,
                     resolution=48)
    vertices, triangles = triangle_soup(rng, cs, count=400, lo=-40.0, hi=90.0, size=9.0)
    xy = light_plane_coordinates(cs, vertices)
    triangles = spatially_sorted(xy, triangles)
    expected, expected_count = rasterize(cs, vertices, triangles, device=device)
    bounds = triangle_bounds(xy, triangles)
    texel_size = np.stack([c.texel_size for c in cs.cascades])
    origin = np.stack([c.origin for c in cs.cascades])
    chunks = region_chunks(bounds, texel_size=texel_size, origin=origin, regions=whole_map_regions([48] * 3))
    assert 0 < len(chunks) < 3 * -(-len(triangles) // (1 << CHUNK_BITS))  # culling removed some chunks, kept others
    fixed_origin = np.stack([fixed_point_origin(cs, c, bits=BITS) for c in range(len(cs))])
    mesh = light_space_mesh(xy, light_depth(cs, vertices), triangles)
    for rows in (chunks, None):
        depth, count = rasterize_cascades(mesh, texel_size=texel_size, origin=fixed_origin, resolution=48, bits=BITS,
                                          chunks=rows, device=device)
        np.testing.assert_array_equal(depth, expected)
        assert count.sum() == expected_count


def test_culled_chunks_hold_every_triangle_that_covers_a_texel():
    from csmlab.kernels.raster import CHUNK_BITS, region_chunks, triangle_bounds, whole_map_regions
    from csmlab.texels import light_plane_coordinates

    rng = np.random.default_rng(12)
    cs = cascade_set(direction=DOWN, origins=[(0.0, 0.0), (30.0, 10.0)], texel=0.5, resolution=32)
    vertices, triangles = triangle_soup(rng, cs, count=300, lo=-30.0, hi=70.0, size=4.0)
    xy = light_plane_coordinates(cs, vertices)
    triangles = spatially_sorted(xy, triangles)
    bounds = triangle_bounds(xy, triangles)
    chunks = {tuple(p) for p in region_chunks(bounds, texel_size=[[0.5, 0.5]] * 2,
                                              origin=[c.origin for c in cs.cascades],
                                              regions=whole_map_regions([32, 32]))}
    assert len(chunks) < 2 * len(bounds.chunks[0])  # some chunks were culled
    for t in range(len(triangles)):
        alone, covered = rasterize(cs, vertices, triangles[t:t + 1], device="cpu")
        for c in range(len(cs)):
            if np.isfinite(alone[c]).any():
                assert (c, t >> CHUNK_BITS) in chunks


def test_chunk_rectangles_bound_their_triangles_and_the_last_chunk_only_its_own():
    from csmlab.kernels.raster import CHUNK_BITS, triangle_bounds

    rng = np.random.default_rng(14)
    size = 1 << CHUNK_BITS
    xy = rng.uniform(-5.0, 5.0, (3 * (2 * size + 3), 2))
    bounds = triangle_bounds(xy, np.arange(len(xy)).reshape(-1, 3))
    lo_x, lo_y, hi_x, hi_y = bounds.chunks
    assert len(lo_x) == 3
    for k in range(3):
        mine = slice(k * size, (k + 1) * size)
        np.testing.assert_array_equal([lo_x[k], lo_y[k]], bounds.lo[mine].min(axis=0))
        np.testing.assert_array_equal([hi_x[k], hi_y[k]], bounds.hi[mine].max(axis=0))
    assert all(len(a) == 0 for a in triangle_bounds(xy[:0], np.zeros((0, 3), int)).chunks)


def test_chunk_vertices_list_each_chunks_corners_once_and_every_corner_in_order_when_not_distinct():
    from csmlab.kernels.raster import CHUNK_BITS, chunk_vertices

    size = 1 << CHUNK_BITS
    # A 9 × 9 grid of quads (162 triangles sharing vertices, the last chunk shorter), listed row by row.
    corner = np.arange(9)[:, None] * 10 + np.arange(9)[None, :]
    quads = np.stack([corner, corner + 1, corner + 10, corner + 11], axis=-1).reshape(-1, 4)
    triangles = np.concatenate([quads[:, [0, 1, 2]], quads[:, [1, 3, 2]]], axis=1).reshape(-1, 3)
    listed = chunk_vertices(triangles)
    assert listed.starts.size == -(-len(triangles) // size) + 1 and listed.starts[0] == 0
    for k in range(listed.starts.size - 1):
        mine = listed.vertices[listed.starts[k]:listed.starts[k + 1]]
        assert len(set(mine.tolist())) == len(mine)
        assert set(mine.tolist()) == set(triangles[k * size:(k + 1) * size].ravel().tolist())
    assert listed.vertices.size < triangles.size / 2
    every = chunk_vertices(triangles, distinct=False)
    np.testing.assert_array_equal(every.vertices, triangles.ravel())
    np.testing.assert_array_equal(every.starts, np.minimum(np.arange(listed.starts.size) * 3 * size, triangles.size))
    assert chunk_vertices(np.zeros((0, 3), int)).starts.tolist() == [0]


def test_chunk_vertex_lists_with_an_empty_chunk_a_vertex_outside_or_offsets_past_the_end_are_refused():
    from csmlab.kernels.raster.mesh import ChunkVertices, checked_chunk_vertices

    good = ChunkVertices(starts=np.array([0, 2, 3]), vertices=np.array([4, 1, 0]))
    starts, listed = checked_chunk_vertices(good, vertex_count=5)
    assert starts.dtype == listed.dtype == np.int32 and listed.tolist() == [4, 1, 0]
    for bad, count in ((ChunkVertices(starts=np.array([0, 2, 2, 3]), vertices=np.array([4, 1, 0])), 5),
                       (good, 4),
                       (ChunkVertices(starts=np.array([0, 2, 4]), vertices=np.array([4, 1, 0])), 5),
                       (ChunkVertices(starts=np.array([1, 2, 3]), vertices=np.array([4, 1, 0])), 5)):
        with pytest.raises(ValueError, match="vertices: expected chunks of at least one vertex each"):
            checked_chunk_vertices(bad, vertex_count=count)


@pytest.mark.parametrize("threads", [1, 2, 3])
def test_the_vertex_pass_is_twice_the_host_fixed_point(threads, device):
    from csmlab.kernels.raster import fixed_point_vertices
    from csmlab.texels import fixed_point_origin, light_plane_coordinates

    rng = np.random.default_rng(15)
    cs = cascade_set(direction=OBLIQUE, origins=[(1e5, -37.0), (7.25, 3.0), (-40.0, 1e6)], texel=0.0371,
                     resolution=48)
    vertices, _ = triangle_soup(rng, cs, count=101, lo=-1e3, hi=1e3, size=50.0)
    # A vertex beyond the fixed-point clip (±2**50 steps) is clipped as on the host.
    vertices = np.concatenate([vertices, [[4e13, 0.0, -3e13]]])
    origin = np.stack([fixed_point_origin(cs, c, bits=BITS) for c in range(len(cs))])
    texel_size = np.stack([c.texel_size for c in cs.cascades])
    xy = light_plane_coordinates(cs, vertices)
    points = fixed_point_vertices(xy, texel_size=texel_size, origin=origin, bits=BITS, cascades=[2, 0],
                                  threads=threads, device=device)
    assert points.shape == (2, len(vertices), 2) and points.dtype == np.int64
    for slot, c in enumerate([2, 0]):
        np.testing.assert_array_equal(points[slot], 2 * fixed_point_coordinates(cs, c, vertices, bits=BITS))
    with pytest.raises(ValueError, match="cascades"):
        fixed_point_vertices(xy, texel_size=texel_size, origin=origin, bits=BITS, cascades=[3])


def test_the_vertex_pass_rounds_every_coordinate_as_the_host_formula_for_any_texel_size(device):
    """``rint(u / texel · 2**bits)`` (NumPy, float64) whatever the texel: the kernel divides by ``texel / 2**bits``
    instead, which must round alike — on ties (half steps, to even), beyond the clip and for NaN and infinities."""
    from csmlab.kernels.raster import fixed_point_vertices

    rng = np.random.default_rng(23)
    bits = 8
    texel_size = 10.0 ** rng.uniform(-4.0, 3.0, (6, 2))
    origin = rng.integers(-2**40, 2**40, (6, 2))
    u = rng.choice([-1.0, 1.0], (4000, 2)) * 10.0 ** rng.uniform(-6.0, 16.0, (4000, 2))
    # Exact half steps of cascade 0 (rint's ties), and coordinates that are not numbers.
    ties = (rng.integers(-2**20, 2**20, (500, 2)) + 0.5) * (texel_size[0] / 2.0**bits)
    odd = np.array([[np.nan, 1.0], [np.inf, -np.inf], [-np.inf, np.nan], [1e300, -1e300]])
    xy = np.concatenate([u, ties, odd])
    expected = np.clip(xy[None] / texel_size[:, None] * 2.0**bits, -2.0**50, 2.0**50)
    expected = np.where(np.isnan(expected), -2.0**50, np.rint(expected)).astype(np.int64)
    expected = 2 * (expected - origin[:, None])
    np.testing.assert_array_equal(fixed_point_vertices(xy, texel_size=texel_size, origin=origin, bits=bits,
                                                       device=device), expected)


def two_cascade_soup(seed: int, *, device: str = "cpu"):
    """A triangle soup over two 40² cascades, listed by light-space x: the cascades, vertices, triangles,
    light-plane x/y, bounds, the keyword arguments of rasterize_cascades on ``device`` (but depths) and the box
    corners in texels."""
    from csmlab.kernels.raster import triangle_bounds
    from csmlab.texels import fixed_point_origin, light_plane_coordinates

    rng = np.random.default_rng(seed)
    cs = cascade_set(direction=OBLIQUE, origins=[(7.0, -3.0), (20.0, 11.0)], texel=0.0411, resolution=40)
    vertices, triangles = triangle_soup(rng, cs, count=300, lo=-10.0, hi=60.0, size=7.0)
    xy = light_plane_coordinates(cs, vertices)
    triangles = spatially_sorted(xy, triangles)
    box = dict(texel_size=np.stack([c.texel_size for c in cs.cascades]),
               origin=np.stack([fixed_point_origin(cs, c, bits=BITS) for c in range(len(cs))]), resolution=40,
               bits=BITS, device=device)
    return cs, vertices, triangles, xy, triangle_bounds(xy, triangles), box, np.stack([c.origin for c in cs.cascades])


def test_a_map_rasterized_region_by_region_is_the_whole_map_and_counting_alone_counts_the_same(device):
    """Regions tiling each map (as scrolling makes them) give its depths bit for bit and the same coverage tests,
    whatever the maps held in them before."""
    from csmlab.kernels.raster import rasterize_cascades, region_chunks

    cs, vertices, triangles, xy, bounds, box, corner = two_cascade_soup(13, device=device)
    mesh = light_space_mesh(xy, light_depth(cs, vertices), triangles)
    whole, whole_count = rasterize_cascades(mesh, **box)
    # Bands of rows, then bands of columns within the rest, as scroll_plan cuts a moved map.
    regions = np.array([[(c, 0, 40, 0, 3), (c, 0, 40, 3, 17), (c, 0, 1, 17, 40), (c, 1, 29, 17, 40),
                         (c, 29, 40, 17, 40)] for c in range(2)]).reshape(-1, 5)
    chunks = region_chunks(bounds, texel_size=box["texel_size"], origin=corner, regions=regions)
    stale = np.full_like(whole, -7.0)
    depth, counts = rasterize_cascades(mesh, regions=regions, chunks=chunks, depth=stale, **box)
    np.testing.assert_array_equal(depth, whole)
    assert counts.sum() == whole_count.sum() > 0
    np.testing.assert_array_equal(np.bincount(regions[:, 0], weights=counts), whole_count)
    none, counted = rasterize_cascades(mesh, regions=regions, chunks=chunks, count_only=True, **box)
    assert none is None
    np.testing.assert_array_equal(counted, counts)
    # Texels outside the regions keep what they held.
    part, _ = rasterize_cascades(mesh, regions=regions[1:2], chunks=None, depth=np.full_like(whole, -7.0), **box)
    np.testing.assert_array_equal(part[0, 3:17], whole[0, 3:17])
    assert np.all(part[0, :3] == -7.0) and np.all(part[1] == -7.0)


def test_cascades_beyond_the_stored_ones_are_counted_where_their_boxes_lie_and_store_nothing(device):
    """Cascades ``[S, C)`` of a call with ``stored_cascades = S`` count what they count rasterized alone, at their own
    boxes, while the maps of ``[0, S)`` are those of a call without them, bit for bit."""
    from csmlab.kernels.raster import rasterize_cascades

    cs, vertices, triangles, xy, _, box, _ = two_cascade_soup(17, device=device)
    mesh = light_space_mesh(xy, light_depth(cs, vertices), triangles)
    constant = np.array([0.01, 0.02])
    whole, whole_count = rasterize_cascades(mesh, caster_constant=constant, **box)
    moved = dict(box, origin=box["origin"] + np.array([[3, -5], [-11, 2]]) * (1 << BITS))
    _, moved_count = rasterize_cascades(mesh, caster_constant=constant, **moved)
    assert moved_count.sum() > 0 and not np.array_equal(moved_count, whole_count)
    both = dict(box, texel_size=np.tile(box["texel_size"], (2, 1)),
                origin=np.concatenate([box["origin"], moved["origin"]]))
    # The counted regions lie over the stored ones, as a scrolled frame's left strips lie over its new boxes.
    regions = np.array([(c, 0, 40, 0, 40) for c in range(4)])
    depth, counts = rasterize_cascades(mesh, regions=regions, stored_cascades=2, caster_constant=np.tile(constant, 2),
                                       depth=np.full_like(whole, -7.0), **both)
    np.testing.assert_array_equal(depth, whole)
    np.testing.assert_array_equal(counts, np.concatenate([whole_count, moved_count]))
    with pytest.raises(ValueError, match="stored_cascades"):
        rasterize_cascades(mesh, regions=regions, stored_cascades=5, **both)


def test_vertices_converted_once_or_per_triangle_rasterize_the_same_maps(monkeypatch, device):
    """A cascade with many triangles gets its vertices converted in one pass, one with few per triangle: the same bits.

    Unused vertices appended to the mesh make the pass too costly for every cascade, so the same
    triangles go the other way.
    """
    from csmlab.kernels import raster
    from csmlab.kernels.raster import schedule

    cs, vertices, triangles, xy, _, box, _ = two_cascade_soup(16, device=device)
    passes = []
    vertex_pass = schedule._vertex_pass

    def spy(pool, xy, boxes, cascades, *args, **kwargs):
        passes.append(cascades.tolist())
        return vertex_pass(pool, xy, boxes, cascades, *args, **kwargs)

    monkeypatch.setattr(schedule, "_vertex_pass", spy)
    once, once_count = raster.rasterize_cascades(raster.light_space_mesh(xy, light_depth(cs, vertices), triangles),
                                                 **box)
    far = np.full((20 * len(xy), 2), 1e4)
    each, each_count = raster.rasterize_cascades(raster.light_space_mesh(
        np.concatenate([xy, far]), np.concatenate([light_depth(cs, vertices), np.zeros(len(far))]), triangles), **box)
    assert passes == [[0, 1], []]
    np.testing.assert_array_equal(each, once)
    np.testing.assert_array_equal(each_count, once_count)
    assert once_count.sum() > 0


@pytest.mark.parametrize("parts", [1, 2, 3, 5])
def test_bands_tile_each_region_exactly(parts):
    from csmlab.kernels.raster import banded_regions

    regions = np.array([(0, 0, 40, 0, 40), (1, 0, 40, 0, 3), (1, 0, 2, 3, 40), (2, 5, 6, 7, 8)], np.int32)
    bands = banded_regions(regions, parts=parts)
    assert np.all(bands[:, 2] > bands[:, 1]) and np.all(bands[:, 4] > bands[:, 3])
    for c in range(3):
        hits, expected = np.zeros((40, 40), int), np.zeros((40, 40), int)
        for _, a0, a1, b0, b1 in bands[bands[:, 0] == c]:
            hits[b0:b1, a0:a1] += 1
        for _, a0, a1, b0, b1 in regions[regions[:, 0] == c]:
            expected[b0:b1, a0:a1] += 1
        np.testing.assert_array_equal(hits, expected)
    assert len(bands[(bands[:, 0] == 0)]) == parts
    assert len(bands[(bands[:, 0] == 2)]) == 1


@pytest.mark.parametrize("threads", [2, 3])
def test_threads_rasterize_the_same_maps_and_counts_as_one(threads, device):
    from csmlab.kernels.raster import banded_regions, rasterize_cascades, region_chunks, whole_map_regions

    cs, vertices, triangles, xy, bounds, box, corner = two_cascade_soup(17, device=device)
    mesh = light_space_mesh(xy, light_depth(cs, vertices), triangles)
    one, one_count = rasterize_cascades(mesh, **box)
    for parts in (1, threads, 4 * threads):
        regions = banded_regions(whole_map_regions([40, 40]), parts=parts)
        chunks = region_chunks(bounds, texel_size=box["texel_size"], origin=corner, regions=regions)
        many, counts = rasterize_cascades(mesh, regions=regions, chunks=chunks, threads=threads, **box)
        np.testing.assert_array_equal(many, one)
        np.testing.assert_array_equal(np.bincount(regions[:, 0], weights=counts), one_count)
    with pytest.raises(ValueError, match="threads"):
        rasterize_cascades(mesh, threads=0, **box)


def test_z_order_lists_the_same_triangles_neighbours_together_and_vertices_by_first_use():
    from csmlab.kernels.raster import CHUNK_BITS, triangle_bounds, z_ordered

    # A 40 × 40 grid of cells listed row by row, plus an unused vertex: rows make long, thin chunks.
    n = 40
    x, y = np.meshgrid(np.arange(n + 1.0), np.arange(n + 1.0))
    xy = np.concatenate([np.stack([x.ravel(), 3.0 * y.ravel()], axis=1), [[1e3, 1e3]]])
    k = (np.arange(n)[:, None] * (n + 1) + np.arange(n)[None, :]).ravel()
    triangles = np.concatenate([np.stack([k, k + 1, k + n + 2], 1), np.stack([k, k + n + 2, k + n + 1], 1)])
    order, ordered = z_ordered(xy, triangles)
    assert sorted(order) == list(range(len(xy))) and order[-1] == len(xy) - 1
    # The same triangles, corner for corner, in a new order.
    same = {tuple(t) for t in order[ordered]}
    assert same == {tuple(t) for t in triangles} and len(same) == len(triangles)
    # Vertices are numbered in the order the triangles first use them.
    firsts = [v for v in dict.fromkeys(ordered.ravel())]
    assert firsts == list(range(len(firsts)))
    # Chunks are compact: far smaller rectangles than the rows' chunks.
    def chunk_area(points, tris):
        lo_x, lo_y, hi_x, hi_y = triangle_bounds(points, tris).chunks
        return np.median((hi_x - lo_x) * (hi_y - lo_y))
    assert chunk_area(xy[order], ordered) < chunk_area(xy, triangles) / 2
    assert len(triangles) > 2 << CHUNK_BITS


def test_bands_follow_the_axis_asked_for_when_the_region_is_long_enough():
    from csmlab.kernels.raster import banded_regions

    regions = np.array([(0, 0, 40, 0, 40), (0, 0, 40, 40, 43), (1, 0, 3, 0, 40)], np.int32)
    columns = banded_regions(regions, parts=4, axis=0)
    assert all(b[3] == 0 and b[4] == 40 for b in columns[:4])  # the square map: bands of columns
    assert len(columns) == 12 and all(b[3] == 40 and b[4] == 43 for b in columns[4:8])
    assert all(b[1] == 0 and b[2] == 3 for b in columns[8:])  # 3 columns only: cut across its rows
    rows = banded_regions(regions, parts=4, axis=1)
    assert all(b[1] == 0 and b[2] == 40 for b in rows[:4])


def test_the_narrow_axis_is_the_one_across_the_rows_of_a_grid_listed_row_by_row():
    from csmlab.kernels.raster import triangle_bounds

    n = 64
    x, y = np.meshgrid(np.arange(n + 1.0), np.arange(n + 1.0))
    xy = np.stack([x.ravel(), y.ravel()], axis=1)
    k = (np.arange(n)[:, None] * (n + 1) + np.arange(n)[None, :]).ravel()
    by_rows = np.stack([k, k + 1, k + n + 2], 1)  # rows along x: chunks long in x, narrow in y
    assert triangle_bounds(xy, by_rows).narrow_axis == 1
    assert triangle_bounds(xy[:, ::-1], by_rows).narrow_axis == 0


@pytest.mark.parametrize("threads", [1, 2, 3])
def test_the_culled_z_ordered_cascade_pass_equals_the_host_path_on_the_scene_as_listed(threads):
    """render's cascade pass (z-ordered mesh, chunks, vertex pass, bands on threads) gives the maps and counts
    of rasterize_depth on the scene's own triangle order and host fixed point, bit for bit."""
    from csmlab.cascades import build_cascades
    from csmlab.light import direction_from_angles
    from csmlab.render import prepare_scene, shadow_maps
    from csmlab.settings import ShadowSettings
    from tests.test_render import camera, scattered_boxes, scene_of

    scene = scene_of(scattered_boxes(5), plane_half=60.0)
    dscene = prepare_scene(scene, threads=threads)
    settings = ShadowSettings(cascades=3, resolution=96, shadow_distance=50.0, stabilization="exact")
    light = direction_from_angles(elevation_deg=35.0, azimuth_deg=120.0)
    cs = build_cascades(pose=camera(48, 32), light_direction=light, scene_corners=scene.corners(), settings=settings)
    maps = shadow_maps(dscene, cs, settings)
    points = np.stack([fixed_point_coordinates(cs, c, scene.vertices, bits=settings.subtexel_bits)
                       for c in range(len(cs))])
    expected, count = rasterize_depth(points, light_depth(cs, scene.vertices), scene.triangles, resolution=96,
                                      bits=settings.subtexel_bits)
    np.testing.assert_array_equal(maps.raster.depth, expected)
    assert maps.texels_rasterized == count > 0


@pytest.mark.parametrize("constant, slope", [(0.0, 0.0), (0.05, 0.0), (0.0, 2.0), (0.013, 2.5)])
def test_a_caster_offset_pushes_a_sloped_plane_by_its_constant_and_slope_times_its_depth_change_per_texel(
        constant, slope, device):
    """A plane z = 7 + 0.3 x − 0.8 y (light space, metres) over a whole 32² map, its corners on the texel grid:
    each texel stores the plane's depth at its centre plus the polygon offset constant + slope · max(|∂z/∂x|,
    |∂z/∂y|) · texel, on both raster paths."""
    from csmlab.kernels.raster import rasterize_cascades
    from csmlab.texels import fixed_point_origin, light_plane_coordinates

    texel, resolution = 0.25, 32
    cs = cascade_set(direction=OBLIQUE, origins=[(-16.0, -16.0)], texel=texel, resolution=resolution)
    corners = np.array([[-20.0, -20.0], [20.0, -20.0], [20.0, 20.0], [-20.0, 20.0]]) * texel

    def plane(x, y):
        return 7.0 + 0.3 * x - 0.8 * y

    light = np.column_stack([corners, plane(corners[:, 0], corners[:, 1])])
    vertices = light @ cs.basis
    triangles = np.array([[0, 1, 2], [0, 2, 3]])
    centres = (np.arange(resolution) - 16.0 + 0.5) * texel
    x, y = np.meshgrid(centres, centres)  # depth[c, j, i]: row j is light y, column i light x
    expected = plane(x, y) + constant + slope * 0.8 * texel
    points = fixed_point_coordinates(cs, 0, vertices, bits=BITS)[None]
    depth, count = rasterize_depth(points, light_depth(cs, vertices), triangles, resolution=resolution, bits=BITS,
                                   caster_constant=[constant], caster_slope=slope, device=device)
    np.testing.assert_allclose(depth[0], expected, rtol=0, atol=4e-6)
    assert count == resolution**2
    mesh = light_space_mesh(light_plane_coordinates(cs, vertices), light_depth(cs, vertices), triangles)
    culled, counts = rasterize_cascades(mesh, texel_size=np.array([[texel, texel]]),
                                        origin=fixed_point_origin(cs, 0, bits=BITS)[None], resolution=resolution,
                                        bits=BITS, caster_constant=[constant], caster_slope=slope, device=device)
    np.testing.assert_array_equal(culled, depth)
    assert counts.sum() == count


_RUN_PAST_THE_EDGE = '''
import sys
import warp as wp
wp.config.quiet = True
wp.config.mode = "debug"
wp.config.kernel_cache_dir = sys.argv[1]
from csmlab.kernels.raster.kernels import walk_run

@wp.kernel
def walk(depth: wp.array3d(dtype=wp.float32), hi: int, count: wp.array(dtype=wp.int32)):
    one = wp.float64(1.0)
    zero = wp.float64(0.0)
    count[0] = walk_run(depth, 0, 1, 0, hi, one, one, one, zero, zero, zero, zero, zero, zero, one, one, one, one)

depth = wp.full((1, 2, 4), 9.0, dtype=wp.float32, device="cpu")
count = wp.zeros(1, dtype=wp.int32, device="cpu")
for hi in (3, int(sys.argv[2])):
    wp.launch(walk, dim=1, inputs=(depth, hi), outputs=(count,), device="cpu")
    print("walked", count.numpy()[0], flush=True)
'''


@pytest.mark.parametrize("hi, walked", [(3, ["walked 4", "walked 4"]), (4, ["walked 4"])])
def test_a_native_run_past_the_maps_edge_trips_warps_debug_mode(tmp_path, hi, walked):
    # walk_run and keep_nearer address texels through raw pointers, which Warp's debug-mode bounds
    # checks do not see: their own asserts must stop a run past the row's last texel (hi = 4 of 4).
    script = tmp_path / "run_past_the_edge.py"
    script.write_text(_RUN_PAST_THE_EDGE)
    done = subprocess.run([sys.executable, str(script), str(tmp_path / "kernels"), str(hi)], capture_output=True,
                          text=True, timeout=300, env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
    assert [line for line in done.stdout.splitlines() if line.startswith("walked")] == walked
    assert (done.returncode == 0) == (hi == 3), done.stderr[-2000:]
    assert ("Assertion failed" in done.stdout + done.stderr) == (hi == 4)
