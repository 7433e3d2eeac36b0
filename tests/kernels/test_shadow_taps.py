"""The box lookup's taps, bit for bit: the hoisted and unrolled tap loops against NumPy's texel-by-texel comparison.

:func:`csmlab.kernels.shadow.box_count` and :func:`~csmlab.kernels.shadow.box_count_3x3` compute
what :func:`~csmlab.kernels.shadow.tap` computes at each texel of the box with the shared terms
taken out of the loop; the oracle here is the receiver-plane comparison written out in NumPy
(IEEE float64 and float32, one operation at a time, in tap's order), on maps whose texels lie
within an ulp of the receivers' planes, so that any change of rounding changes the count.
"""

import numpy as np
import pytest
import warp as wp

from csmlab.geometry import light_basis
from csmlab.kernels.bias import BiasSettings
from csmlab.kernels.shadow import (box_count, box_count_3x3, receiver_coordinates, shadow_lookup, shadow_lookup_world,
                                   split_sphere_cascades, tap)
from csmlab.lookup_choices import SELECTION_METHODS

wp.set_module_options({"fuse_fp": False})

BITS = 8
UNIT = 2**BITS
INVERSE_SPAN = 1.0 / (2 * UNIT)


@wp.kernel
def counts_kernel(depth: wp.array3d(dtype=wp.float32), c: wp.array(dtype=wp.int32), xy: wp.array2d(dtype=wp.int64),
                  receiver: wp.array(dtype=wp.float32), slope: wp.array(dtype=wp.vec2d), radius: int,
                  by_tap: wp.array(dtype=wp.int32), by_box: wp.array(dtype=wp.int32),
                  by_3x3: wp.array(dtype=wp.int32)):
    k = wp.tid()
    unit = wp.int64(UNIT)
    inverse_span = wp.float64(INVERSE_SPAN)
    x = xy[k, 0]
    y = xy[k, 1]
    i = x // unit
    j = y // unit
    count = int(0)
    for dj in range(-radius, radius + 1):
        for di in range(-radius, radius + 1):
            count += tap(depth, c[k], i + wp.int64(di), j + wp.int64(dj), receiver[k], slope[k], x, y, unit,
                         inverse_span)
    by_tap[k] = count
    by_box[k] = box_count(depth, c[k], x, y, receiver[k], slope[k], BITS, inverse_span, radius)
    if radius == 1:
        by_3x3[k] = box_count_3x3(depth, c[k], x, y, receiver[k], slope[k], BITS, inverse_span)


def plane_depths(xy, receiver, slope, radius):
    """NumPy: each receiver's float32 plane depth at each of its (2r + 1)² texels ``(N, side, side)`` ``[j, i]``,
    and those texels' indices — tap's arithmetic, one IEEE operation at a time."""
    i = xy[:, 0] // UNIT
    j = xy[:, 1] // UNIT
    offsets = np.arange(-radius, radius + 1)
    ti = i[:, None] + offsets[None, :]
    tj = j[:, None] + offsets[None, :]
    di = ((2 * ti + 1) * UNIT - 2 * xy[:, :1]).astype(np.float64) * INVERSE_SPAN
    dj = ((2 * tj + 1) * UNIT - 2 * xy[:, 1:]).astype(np.float64) * INVERSE_SPAN
    near = receiver.astype(np.float64)[:, None, None]
    moved = (near + slope[:, 0, None, None] * di[:, None, :]) + slope[:, 1, None, None] * dj[:, :, None]
    flat = (slope[:, 0] == 0.0) & (slope[:, 1] == 0.0)
    plane = moved.astype(np.float32)
    plane[flat] = receiver[flat, None, None]
    return plane, ti, tj


def near_plane_maps(rng, shape, c, xy, receiver, slope, radius):
    """Maps of random depths with each receiver's texels overwritten by its plane depth, one ulp either side or
    equal."""
    maps = rng.uniform(-1.0, 1.0, shape).astype(np.float32)
    plane, ti, tj = plane_depths(xy, receiver, slope, radius)
    step = rng.integers(-1, 2, plane.shape)
    value = np.where(step < 0, np.nextafter(plane, np.float32(-np.inf)),
                     np.where(step > 0, np.nextafter(plane, np.float32(np.inf)), plane))
    side = 2 * radius + 1
    cc = np.broadcast_to(c[:, None, None], (c.shape[0], side, side))
    maps[cc, np.broadcast_to(tj[:, :, None], cc.shape), np.broadcast_to(ti[:, None, :], cc.shape)] = value
    return maps


def numpy_counts(maps, c, xy, receiver, slope, radius):
    plane, ti, tj = plane_depths(xy, receiver, slope, radius)
    stored = maps[c[:, None, None], tj[:, :, None], ti[:, None, :]]
    return (plane <= stored).sum(axis=(1, 2))


def random_receivers(rng, *, count, size, radius):
    """One receiver per (2r + 2)² block of texels of each cascade, so that no two share a texel, its
    taps inside the block; flat, tilted and steep slopes; some NaN depths."""
    block = 2 * radius + 2
    blocks = size // block
    c, bj, bi = (a.ravel() for a in np.meshgrid(np.arange(count), np.arange(blocks), np.arange(blocks), indexing="ij"))
    n = c.shape[0]
    fraction = rng.integers(0, UNIT, (n, 2))
    receiver = rng.uniform(-0.5, 0.5, n).astype(np.float32)
    receiver[rng.random(n) < 0.02] = np.nan
    slope = rng.normal(scale=0.03, size=(n, 2)) * rng.choice([0.0, 1e-7, 1.0, 40.0, 3e10], (n, 1))
    # Opposite slopes at a point on the diagonal of its texel cancel at the diagonal taps: with steep
    # ones (3e10) the plane's float64 terms are a billion times its depth, so how they are summed
    # shows in float32.
    opposite = rng.random(n) < 0.3
    slope[opposite, 1] = -slope[opposite, 0]
    fraction[opposite, 1] = fraction[opposite, 0]
    slope[rng.random(n) < 0.1, 0] = 0.0
    xy = (np.column_stack([bi, bj]) * block + radius) * UNIT + fraction
    return c.astype(np.int32), xy.astype(np.int64), receiver, slope


@pytest.mark.parametrize("radius", [0, 1, 2, 3])
def test_box_taps_count_what_numpy_counts_texel_by_texel(radius, device):
    rng = np.random.default_rng(40 + radius)
    count, size = 3, 96
    c, xy, receiver, slope = random_receivers(rng, count=count, size=size, radius=radius)
    n = c.shape[0]
    maps = near_plane_maps(rng, (count, size, size), c, xy, receiver, slope, radius)
    outputs = [wp.zeros(n, dtype=wp.int32, device=device) for _ in range(3)]
    wp.launch(counts_kernel, dim=n, device=device,
              inputs=(wp.array(maps, dtype=wp.float32, device=device), wp.array(c, dtype=wp.int32, device=device),
                      wp.array(xy, dtype=wp.int64, device=device), wp.array(receiver, dtype=wp.float32, device=device),
                      wp.array(slope, dtype=wp.vec2d, device=device), radius),
              outputs=outputs)
    by_tap, by_box, by_3x3 = (o.numpy() for o in outputs)
    expected = numpy_counts(maps, c, xy, receiver, slope, radius)
    side = 2 * radius + 1
    if radius:
        # The maps sit on the planes: counts fall strictly between none and all for most receivers.
        assert np.mean((expected > 0) & (expected < side * side)) > 0.5
    np.testing.assert_array_equal(by_tap, expected)
    np.testing.assert_array_equal(by_box, expected)
    if radius == 1:
        np.testing.assert_array_equal(by_3x3, expected)


def bilinear_lit(maps, c, xy, receiver, slope):
    """NumPy: the 2×2 bilinear-compare tap at each receiver's own fixed point (bilinear_tap's operations)."""
    x2 = 2 * xy - UNIT
    span = 2 * UNIT
    i0 = x2 // span
    w = (x2 - i0 * span).astype(np.float64) / float(span)
    s = {}
    for a in (0, 1):
        for b in (0, 1):
            ti = i0[:, 0] + a
            tj = i0[:, 1] + b
            di = ((2 * ti + 1) * UNIT - 2 * xy[:, 0]).astype(np.float64) * INVERSE_SPAN
            dj = ((2 * tj + 1) * UNIT - 2 * xy[:, 1]).astype(np.float64) * INVERSE_SPAN
            plane = ((receiver.astype(np.float64) + slope[:, 0] * di) + slope[:, 1] * dj).astype(np.float32)
            flat = (slope[:, 0] == 0.0) & (slope[:, 1] == 0.0)
            plane[flat] = receiver[flat]
            s[a, b] = (plane <= maps[c, tj, ti]).astype(np.float64)
    wx, wy = w[:, 0], w[:, 1]
    return (1.0 - wy) * ((1.0 - wx) * s[0, 0] + wx * s[1, 0]) + wy * ((1.0 - wx) * s[0, 1] + wx * s[1, 1])


@pytest.mark.parametrize("plane", [True, False], ids=["receiver_plane", "flat"])
@pytest.mark.parametrize("filter, radius", [("none", 0), ("pcf", 1), ("pcf", 2), ("pcf_bilinear", 1)])
@pytest.mark.parametrize("selection", sorted(SELECTION_METHODS))
def test_lookup_lit_is_numpys_filter_at_the_selected_cascades(selection, filter, radius, plane, device):
    """Every selection × box filter × receiver-plane choice, world and converted receivers, blend band included."""
    rng = np.random.default_rng(7)
    size, count, n = 40, 3, 1500
    texel = np.array([[0.05, 0.05], [0.15, 0.15], [0.5, 0.5]])
    centre = np.array([300.0, -120.0])
    origin = np.rint((centre / texel - size / 2) * UNIT).astype(np.int64)
    basis = light_basis([0.3, -0.8, 0.2])
    splits = np.array([0.1, 4.0, 15.0, 60.0])
    light = np.concatenate([np.column_stack([centre + rng.normal(scale=size * t.max() * 0.25, size=(n // count, 2)),
                                             rng.normal(size=n // count)]) for t in texel])
    view_depth = np.concatenate([rng.uniform(splits[c], splits[c + 1], n // count) for c in range(count)])
    points = light @ basis
    normals = rng.normal(size=points.shape).astype(np.float32)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    conversion = dict(basis=basis, texel_size=texel, origin_fixed=origin, zref=-2.0,
                      bias=BiasSettings(normal_offset=0.5, bias_constant=0.0, bias_slope=1.0))
    coords, depth, slope = receiver_coordinates(points, normals, bits=BITS, device=device, **conversion)
    if not plane:
        slope = np.zeros_like(slope)
    # Each cascade's map on its receivers' planes (random depths elsewhere).
    maps = np.stack([near_plane_maps(rng, (1, size, size), np.zeros(n, np.int32),
                                     np.clip(coords[c], (radius + 1) * UNIT, (size - radius - 2) * UNIT), depth[c],
                                     slope[c], max(radius, 1))[0] for c in range(count)])
    common = dict(splits=splits, texel_area=np.prod(texel, axis=1), selection=selection, filter=filter,
                  radius=radius, margin=2, blend_band=0.4, bits=BITS, device=device)
    if selection in ("sphere", "sphere_dither"):
        # sphere_dither: the kernel reads the cascade csmlab.cascades.borders chose, as for sphere.
        common["sphere_cascade"] = split_sphere_cascades(points, centres=np.tile(np.append(centre, 0.0) @ basis,
                                                                                 (count, 1)),
                                                         radii=0.3 * size * texel.max(axis=1), device=device)
    world = shadow_lookup_world(maps, points, normals, view_depth, receivers=None, receiver_plane_bias=plane,
                                **conversion, **common)
    converted = shadow_lookup(maps, coords, depth, view_depth, receiver_slope=slope, **common)
    lit, chosen, blended = world
    for a, b in zip(world, converted):
        np.testing.assert_array_equal(a, b)

    def filtered(c, rows):
        """NumPy's S of receivers ``rows`` in cascades ``c[rows]``."""
        k = np.flatnonzero(rows)
        args = (maps, c[k], coords[c[k], k], depth[c[k], k], slope[c[k], k])
        if filter == "pcf_bilinear":
            return bilinear_lit(*args)
        return numpy_counts(*args, radius).astype(np.float64) / float((2 * radius + 1) ** 2)

    selected = chosen >= 0
    s = np.zeros(n)
    s[selected] = filtered(chosen, selected)
    start = splits[1:] - 0.4 * (splits[1:] - splits[:-1])
    nxt = np.minimum(chosen + 1, count - 1)
    w = (view_depth[blended] - start[chosen[blended]]) / (splits[chosen[blended] + 1] - start[chosen[blended]])
    s[blended] = (1.0 - w) * s[blended] + w * filtered(nxt, blended)
    expected = np.where(selected, s.astype(np.float32), np.float32(np.nan))
    np.testing.assert_array_equal(lit, expected)
    assert selected.sum() > n // 3 and blended.sum() > 20
    held = lit[selected]
    assert 0.1 < held.mean() < 0.9
