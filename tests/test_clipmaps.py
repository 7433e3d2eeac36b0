"""Virtual shadow map clipmaps (csmlab.clipmaps): world-locked pages, marking, the page cache and the lookup."""

import math
from dataclasses import replace

import numpy as np
import pytest

from csmlab.camera import CameraPose
from csmlab.clipmaps import Clipmap, chosen_levels, light_space, read_levels, wanted_levels
from csmlab.config import load_experiment
from csmlab.errors import InputError
from csmlab.geometry import rotation_looking_at
from csmlab.invariants import FLICKER_SAME_ZERO, WorkloadFacts, promised_invariants
from csmlab.kernels.pages import page_lookup
from csmlab.light import direction_from_angles
from csmlab.metrics import measure_frame
from csmlab.metrics.aliasing import utilization
from csmlab.metrics.cost import shadow_memory_bytes
from csmlab.metrics.temporal import temporal_maps
from csmlab.render import prepare_scene, render_shadow, render_view
from csmlab.settings import ShadowSettings
from tests.test_render import camera, scattered_boxes, scene_of, silhouette_distance

# A scaled-down clipmap: 1024² texels per level in 32² pages, levels 2 cm .. 164 m.
CLIPMAP = ShadowSettings(shadow_map="virtual_clipmap", virtual_resolution=1024, page_size=32, clipmap_first_level=1,
                         clipmap_last_level=14, lod_bias=0.0, filter="none", physical_pages=4096)
LIGHT = direction_from_angles(elevation_deg=35.0, azimuth_deg=120.0)
BOXES = scattered_boxes(3)


@pytest.fixture(scope="module")
def dscene():
    return prepare_scene(scene_of(BOXES, plane_half=60.0))


def frames(dscene, settings, poses, lights, *, cached=True, size=(96, 64)):
    """Each pose's frame under its light, every frame cached from the one before (or rasterized whole)."""
    out, previous = [], None
    for pose, light in zip(poses, lights):
        view = render_view(dscene, pose, light, width=size[0], height=size[1])
        frame = render_shadow(dscene, view, settings, scroll_from=previous.maps if cached and previous else None)
        out.append(frame)
        previous = frame
    return out


def dolly(count, *, step=(0.137, 0.0, -0.093)):
    """A camera translating along ``step`` metres per frame, its orientation fixed."""
    return [camera(96, 64, eye=np.add((6.0, 1.9, 3.5), np.multiply(step, i)),
                   target=np.add((2.0, 0.4, -2.0), np.multiply(step, i))) for i in range(count)]


def test_a_camera_translating_over_static_geometry_gives_zero_same_level_flicker(dscene):
    shots = frames(dscene, CLIPMAP.replace(filter="pcf", filter_size=3), dolly(4), [LIGHT] * 4)
    for previous, frame in zip(shots, shots[1:]):
        same = temporal_maps(frame, previous).same_cascade
        assert same.sum() > 1000  # most pixels keep their level: the zero below is measured, not vacuous
        assert measure_frame(frame, previous).values["flicker_same"] == 0.0


def test_a_receiver_seen_twice_reads_the_same_texel_bits_in_the_same_level(dscene):
    """World-locked pages: a point at the same level in two frames gets the same S from either frame's pages,
    though each frame placed its levels around its own camera (the boxes moved by whole pages)."""
    first, second = frames(dscene, CLIPMAP, dolly(2, step=(1.7, 0.0, -1.1)), [LIGHT] * 2)
    assert not np.array_equal(first.maps.pages.clipmap.origin_page, second.maps.pages.clipmap.origin_page)
    same = temporal_maps(second, first).same_cascade
    earlier = temporal_maps(second, first).previous_lit
    assert same.sum() > 1000
    assert np.array_equal(earlier[same], second.shadow.lit[same])


def _disk_in_square(r: float, a: float) -> float:
    """Area of a disk of radius r and a square of half-side a, both centred at the origin."""
    if r <= a:
        return math.pi * r * r
    if r >= a * math.sqrt(2.0):
        return 4.0 * a * a
    return math.pi * r * r - 4.0 * (r * r * math.acos(a / r) - a * math.sqrt(r * r - a * a))


def _boundary_in_square(r_in: float, r_out: float, a: float) -> float:
    """Length of the boundary of the ring ``r_in ≤ ρ < r_out`` cut by that square: arcs inside it, edges inside the
    ring."""
    def arc(r):
        return 2 * math.pi * r if r <= a else max(2 * math.pi * r - 8 * r * math.acos(min(a / r, 1.0)), 0.0)

    def edge(r):
        return math.sqrt(min(max(r * r - a * a, 0.0), a * a))
    return arc(r_in) + arc(r_out) + 8.0 * (edge(r_out) - edge(r_in))


def test_pages_marked_on_flat_ground_equal_the_analytic_ring_area_per_level():
    """A camera h above a flat ground looking straight down under a light straight down sees the square of
    half-side h (fov 90°); the points at distance D in [D_n, D_n+1) of level n are the ring of radii
    sqrt(D² − h²) in it. The pages marked cover that area up to the pages its boundary cuts:
    |marked · page area − ring area| ≤ √2 · page width · boundary length + 4 page areas."""
    ground = prepare_scene(scene_of([], plane_half=200.0))
    h, side = 20.0, 256
    pose = CameraPose(position=np.array([0.37, h, -0.61]), orientation=rotation_looking_at((0.0, -1.0, 0.0)),
                      fov_y_deg=90.0, aspect=1.0, near=0.1, far=400.0)
    settings = ShadowSettings(shadow_map="virtual_clipmap", virtual_resolution=2048, page_size=8,
                              clipmap_first_level=0, clipmap_last_level=16, lod_bias=-1.0, filter="none",
                              normal_offset=0.0, physical_pages=65536)
    view = render_view(ground, pose, (0.0, -1.0, 0.0), width=side, height=side, reference=False)
    maps = render_shadow(ground, view, settings, lookup=False).maps
    marked = np.bincount(maps.pages.keys[:, 0], minlength=len(maps.cascades))
    assert maps.pages.marked == len(maps.pages.keys)
    levels = np.flatnonzero(marked)
    assert len(levels) == 2  # distances h .. h√3 span two levels of ratio 2 here
    for k in levels:
        level = maps.cascades.cascades[k]
        r_in, r_out = (math.sqrt(max(d * d - h * h, 0.0)) for d in (level.split_near, level.split_far))
        area = _disk_in_square(r_out, h) - _disk_in_square(r_in, h)
        width = level.texel_size[0] * settings.page_size
        tolerance = math.sqrt(2.0) * width * _boundary_in_square(r_in, r_out, h) + 4 * width * width
        assert tolerance < 0.25 * area
        assert abs(marked[k] * width * width - area) <= tolerance, (k, marked[k] * width * width, area, tolerance)


def test_a_light_that_rotates_invalidates_every_cached_page(dscene):
    pose = dolly(1)[0]
    turned = direction_from_angles(elevation_deg=35.0, azimuth_deg=121.0)
    first, second = frames(dscene, CLIPMAP, [pose, pose], [LIGHT, turned])
    kept = {tuple(k) for k in first.maps.pages.keys.tolist()} & {tuple(k) for k in second.maps.pages.keys.tolist()}
    assert kept  # pages of the same place exist in both: only the light makes them stale
    assert second.maps.pages.rendered == len(second.maps.pages.keys) == second.maps.pages.marked
    (whole,) = frames(dscene, CLIPMAP, [pose], [turned])
    assert np.array_equal(second.maps.depth, whole.maps.depth)


def test_a_static_light_and_scene_rerender_no_page_after_the_first_frame(dscene):
    pose = dolly(1)[0]
    shots = frames(dscene, CLIPMAP, [pose] * 3, [LIGHT] * 3)
    assert shots[0].maps.pages.rendered == shots[0].maps.pages.marked > 0
    assert [f.maps.pages.rendered for f in shots[1:]] == [0, 0]
    assert [f.maps.texels_rasterized for f in shots[1:]] == [0, 0]
    assert all(np.array_equal(f.maps.depth, shots[0].maps.depth) for f in shots[1:])


def test_a_moving_camera_renders_only_the_pages_it_did_not_hold_and_the_cache_changes_no_bit(dscene):
    poses = dolly(3, step=(0.9, 0.0, -0.6))
    cached = frames(dscene, CLIPMAP, poses, [LIGHT] * 3)
    whole = frames(dscene, CLIPMAP, poses, [LIGHT] * 3, cached=False)
    for previous, frame, fresh in zip(cached, cached[1:], whole[1:]):
        before = {tuple(k) for k in previous.maps.pages.keys.tolist()}
        new = sum(tuple(k) not in before for k in frame.maps.pages.keys.tolist())
        assert 0 < frame.maps.pages.rendered == new < len(frame.maps.pages.keys)
        assert np.array_equal(frame.maps.depth, fresh.maps.depth)
        assert np.array_equal(frame.shadow.lit, fresh.shadow.lit, equal_nan=True)


def test_the_clipmap_shadow_equals_the_ray_cast_away_from_silhouettes(dscene):
    """Against the ray-traced hard shadow: every receiver lit from the front and more than four texels of its level
    (beyond the normal offset and bias) from a box's silhouette in light space gets the reference's state."""
    (frame,) = frames(dscene, CLIPMAP, [camera(160, 96)], [LIGHT], size=(160, 96))
    g = frame.view.gbuffer
    level = frame.shadow.cascade
    lit, reference = frame.shadow.lit, frame.view.reference
    seen = g.valid & (level >= 0) & (np.einsum("...k,k->...", g.normal, -frame.view.light_direction) > 0.2)
    texel = np.where(level >= 0, frame.maps.pages.clipmap.texel[np.maximum(level, 0)], np.inf)
    far_from_edges = silhouette_distance(frame.maps.cascades, g.position[seen], BOXES) > 4.0 * texel[seen]
    assert far_from_edges.sum() > 5000
    assert np.array_equal(lit[seen][far_from_edges] > 0.5, reference[seen][far_from_edges] > 0.5)


def _page_lookup_numpy(pool, table, origin_page, level, coordinates, depth, *, radius, bits):
    """The page-table PCF written out per receiver: texel = coordinate >> bits, page = texel // S."""
    side = pool.shape[1]
    out = np.full(len(level), np.nan, dtype=np.float32)
    for r, (k, (u, v), z) in enumerate(zip(level, coordinates, depth)):
        taps = []
        for dj in range(-radius, radius + 1):
            for di in range(-radius, radius + 1):
                i, j = (u >> bits) + di, (v >> bits) + dj
                slot = table[k, j // side - origin_page[k, 1], i // side - origin_page[k, 0]]
                taps.append(np.nan if slot < 0 else float(z <= pool[slot, j % side, i % side]))
        out[r] = np.float32(np.mean(taps)) if k >= 0 else np.nan
    return out


@pytest.mark.parametrize("radius", [0, 1, 2])
def test_the_page_lookup_kernel_equals_the_page_table_read_in_numpy(radius):
    rng = np.random.default_rng(7)
    side, levels, per_side, bits = 8, 3, 4, 4
    pool = rng.uniform(0.0, 1.0, (20, side, side)).astype(np.float32)
    pool[rng.uniform(size=pool.shape) < 0.1] = np.inf
    table = np.where(rng.uniform(size=(levels, per_side, per_side)) < 0.8,
                     rng.integers(0, 20, (levels, per_side, per_side)), -1).astype(np.int32)
    origin_page = rng.integers(-5, 5, (levels, 2))
    count = 400
    level = rng.integers(-1, levels, count)
    local = rng.integers(radius, per_side * side - radius, (count, 2))
    coordinates = ((local + origin_page[np.maximum(level, 0)] * side) << bits) + rng.integers(0, 1 << bits, (count, 2))
    depth = rng.uniform(0.0, 1.0, count).astype(np.float32)
    got = page_lookup(pool, table, origin_page, level, coordinates, depth, radius=radius, bits=bits)
    want = _page_lookup_numpy(pool, table, origin_page, level, coordinates, depth, radius=radius, bits=bits)
    assert np.isnan(want).sum() > 10 and np.isfinite(want).sum() > 100
    assert np.array_equal(got, want, equal_nan=True)


def test_a_pool_too_small_keeps_the_coarsest_pages_and_the_other_pixels_fall_back_or_go_without(dscene):
    """The pixels whose pages did not fit read the next coarser level whose resident pages hold their taps, or
    none (S = NaN, level −1: Unreal's pool overflow); the others read what they read with the pool whole."""
    (full,) = frames(dscene, CLIPMAP, [camera(96, 64)], [LIGHT])
    levels = full.maps.pages.keys[:, 0]
    pool = int(np.sum(levels >= np.sort(levels)[len(levels) // 2]))
    (small,) = frames(dscene, CLIPMAP.replace(physical_pages=pool), [camera(96, 64)], [LIGHT])
    pages = small.maps.pages
    assert pages.marked == full.maps.pages.marked > len(pages.keys) == pool
    assert pages.keys[:, 0].min() >= np.sort(levels)[len(levels) - pool]
    assert pages.resident_bytes == pool * 32 * 32 * 4
    seen = small.view.gbuffer.valid
    kept = seen & (small.shadow.cascade == full.shadow.cascade)
    assert np.array_equal(small.shadow.lit[kept], full.shadow.lit[kept])
    moved = seen & ~kept
    coarser = moved & (small.shadow.cascade > full.shadow.cascade)
    assert np.all(coarser | (moved & (small.shadow.cascade == -1)) == moved)
    assert np.all(np.isnan(small.shadow.lit[moved & ~coarser])) and np.all(np.isfinite(small.shadow.lit[coarser]))
    assert coarser.sum() > 0 and kept.sum() > 0


def test_a_clipmap_with_a_filter_it_cannot_look_up_is_bad_input(tmp_path):
    path = tmp_path / "exp.toml"
    path.write_text('[scene]\nkind = "plane_box"\n[camera]\npath = "walk"\nframes = 2\n'
                    '[shadow]\nshadow_map = "virtual_clipmap"\nfilter = "vsm"\n')
    with pytest.raises(InputError, match="filter"):
        load_experiment(path)
    path.write_text('[scene]\nkind = "plane_box"\n[camera]\npath = "walk"\nframes = 2\n[shadow]\npage_size = 64\n')
    with pytest.raises(InputError, match="page_size"):
        load_experiment(path)


def test_utilization_counts_each_levels_distinct_texels_over_its_resident_texels(dscene):
    (frame,) = frames(dscene, CLIPMAP, [camera(160, 96)], [LIGHT], size=(160, 96))
    g, clip = frame.view.gbuffer, frame.maps.pages.clipmap
    chosen = g.valid & (frame.shadow.cascade >= 0)
    xy = g.position[chosen] @ clip.basis[:2].T
    looked = {(int(k), int(np.floor(x / clip.texel[k])), int(np.floor(y / clip.texel[k])))
              for (x, y), k in zip(xy, frame.shadow.cascade[chosen])}
    counts = np.bincount([k for k, _, _ in looked], minlength=len(clip))
    resident = np.bincount(frame.maps.pages.keys[:, 0], minlength=len(clip)) * CLIPMAP.page_size ** 2
    want = np.where(resident > 0, counts / np.maximum(resident, 1), np.nan)
    got = utilization(frame)
    assert np.isfinite(got).sum() >= 2
    assert np.allclose(got, want, rtol=0, atol=0, equal_nan=True)


def test_utilization_counts_the_texels_of_pages_the_table_does_not_hold_as_well(dscene):
    # A page looked up but not resident (a marking that missed it) still has its texels counted, in its level.
    (frame,) = frames(dscene, CLIPMAP, [camera(160, 96)], [LIGHT], size=(160, 96))
    pages, clip = frame.maps.pages, frame.maps.pages.clipmap
    level, x, y = (int(v) for v in pages.keys[len(pages.keys) // 2])
    table = pages.table.copy()
    table[level, y - clip.origin_page[level, 1], x - clip.origin_page[level, 0]] = -1
    dropped = replace(frame, maps=replace(frame.maps, pages=replace(pages, table=table)))
    np.testing.assert_array_equal(utilization(dropped), utilization(frame))
    g = frame.view.gbuffer
    chosen = g.valid & (frame.shadow.cascade == level)
    xy = g.position[chosen] @ clip.basis[:2].T
    page = np.floor(xy / clip.texel[level]).astype(np.int64) // CLIPMAP.page_size
    assert np.any((page[:, 0] == x) & (page[:, 1] == y))


def test_a_clipmaps_memory_is_its_whole_pool_and_its_pool_bytes_its_resident_pages(dscene):
    assert shadow_memory_bytes(CLIPMAP.replace(physical_pages=2048, page_size=128)) == 2048 * 128 * 128 * 4
    assert shadow_memory_bytes(CLIPMAP.replace(depth_format="unorm16")) == 4096 * 32 * 32 * 2
    (frame,) = frames(dscene, CLIPMAP, [camera(96, 64)], [LIGHT])
    values = measure_frame(frame).values
    assert values["memory_bytes"] == 4096 * 32 * 32 * 4
    assert values["pool_bytes"] == len(frame.maps.pages.keys) * 32 * 32 * 4 < values["memory_bytes"]
    assert values["pages_marked"] == values["pages_rendered"] == len(frame.maps.pages.keys)


def test_a_clipmap_promises_zero_same_level_flicker_whatever_the_cascades_fields_under_a_static_light():
    static = WorkloadFacts(light_static=True, fov_fixed=False)
    loose = CLIPMAP.replace(stabilization="none", bounds="sdsm", depth_range="slice")
    assert promised_invariants(loose, workload=static)[FLICKER_SAME_ZERO].promised
    assert not promised_invariants(loose.replace(shadow_map="cascades"), workload=static)[FLICKER_SAME_ZERO].promised
    moving = promised_invariants(loose, workload=WorkloadFacts(light_static=False, fov_fixed=True))
    assert not moving[FLICKER_SAME_ZERO].promised


def _random_clipmap(rng, *, levels=6, side=4, page_size=8):
    """A clipmap of ``levels`` levels of ``side``² pages of ``page_size``² texels, 5 cm texels and up."""
    return Clipmap(first_level=0, texel=0.05 * 2.0 ** np.arange(levels), origin_page=rng.integers(-3, 0, (levels, 2)),
                   pages_per_side=side, page_size=page_size, footprint=0.002, lod_bias=0.0, eye=np.zeros(3),
                   basis=np.eye(3), zref=-1.5)


def _receivers(rng, count):
    """Light-space receivers over the clipmap's boxes and past them, with unit normals some turned from the light."""
    points = np.column_stack([rng.uniform(-12.0, 12.0, (count, 2)), rng.uniform(-3.0, 3.0, count)])
    normals = rng.normal(size=(count, 3))
    normals[: count // 10] = (0.0, 0.0, -1.0)
    normals[count // 10: count // 5] = (0.0, 1.0, 0.0)
    return points, normals / np.linalg.norm(normals, axis=1, keepdims=True)


@pytest.mark.parametrize("radius", [0, 1, 3])
@pytest.mark.parametrize("resident", [False, True])
def test_the_level_kernel_equals_the_host_level_choice_bit_for_bit(radius, resident, device):
    """read_levels equals chosen_levels (the host reference): level, coordinates and depth bits, with the
    page table or without it, receivers outside every box, at the box edges and turned from the light."""
    rng = np.random.default_rng(11 + radius)
    clip = _random_clipmap(rng)
    points, normals = _receivers(rng, 3000)
    wanted = rng.integers(0, len(clip) + 1, len(points))
    table = np.where(rng.uniform(size=(len(clip), 4, 4)) < 0.7, rng.integers(0, 50, (len(clip), 4, 4)), -1)
    settings = ShadowSettings(normal_offset=0.7, bias_constant=0.003, bias_slope=1.3, subtexel_bits=5)

    def holds(k, local):
        if not resident:
            return np.ones(len(local), dtype=bool)
        return np.all(table[k, local[..., 1], local[..., 0]] >= 0, axis=1)

    want = chosen_levels(clip, points, normals, wanted, settings=settings, radius=radius, holds=holds)
    got = read_levels(clip, points, normals, wanted, settings=settings, radius=radius,
                      table=table if resident else None, device=device)
    level = want[0]
    assert (level == -1).sum() > 50 and (level >= 0).sum() > 500 and np.isnan(want[2][level >= 0]).sum() > 50
    assert len(np.unique(level)) >= len(clip) and np.any(level > wanted)
    for g, w in zip(got, want):
        assert g.dtype == w.dtype and np.array_equal(g, w, equal_nan=True)
    assert np.array_equal(got[2].view(np.int32), want[2].view(np.int32))


def test_the_level_kernel_equals_the_host_level_choice_on_a_rendered_frame(dscene, device):
    """On a frame's own receivers and resident pages (S_t) and on the next frame's receivers (S_{t-1}'s case)."""
    first, second = frames(dscene, CLIPMAP.replace(filter="pcf", filter_size=3), dolly(2), [LIGHT, LIGHT])
    pages = first.maps.pages
    clip = pages.clipmap
    for frame in (first, second):
        g = frame.view.gbuffer
        points = light_space(g.position[g.valid], clip.basis)
        normals = light_space(g.normal[g.valid], clip.basis)
        wanted = wanted_levels(clip, g.position[g.valid])
        want = chosen_levels(clip, points, normals, wanted, settings=CLIPMAP, radius=1,
                             holds=lambda k, local: np.all(pages.table[k, local[..., 1], local[..., 0]] >= 0, axis=1))
        got = read_levels(clip, points, normals, wanted, settings=CLIPMAP, radius=1, table=pages.table,
                          device=device)
        assert (want[0] >= 0).sum() > 1000
        for g_, w in zip(got, want):
            assert np.array_equal(g_, w, equal_nan=True)


def test_the_level_kernel_refuses_negative_wanted_levels_and_a_table_of_the_wrong_shape():
    rng = np.random.default_rng(3)
    clip = _random_clipmap(rng)
    points, normals = _receivers(rng, 10)
    with pytest.raises(ValueError, match="wanted"):
        read_levels(clip, points, normals, np.full(10, -1), settings=CLIPMAP, radius=0, table=None)
    with pytest.raises(ValueError, match="table"):
        read_levels(clip, points, normals, np.zeros(10, dtype=int), settings=CLIPMAP, radius=0,
                    table=np.zeros((2, 4, 4), dtype=np.int32))
