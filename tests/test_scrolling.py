"""Scrolled depth maps equal maps rasterized whole, bit for bit, and count the same coverage tests."""

from dataclasses import replace

import numpy as np
import pytest

from csmlab import render
from csmlab.light import direction_from_angles
from csmlab.render import prepare_scene, render_shadow, render_view
from csmlab.scrolling import RasterizedMaps, StoredMaps, kept_stored, reused_cascades, scroll_plan
from csmlab.settings import ShadowSettings
from csmlab.storage import cascade_stored_depth, stored_depth
from tests.test_render import camera, scattered_boxes, scene_of

# Eyes along a walk: small steps (whole-texel moves of the near boxes), a repeated pose (no box
# moves), a turn, and a jump farther than the near boxes are wide (rasterized whole).
EYES = [(-3.0, 6.0, 14.0), (-2.9, 6.0, 13.9), (-2.9, 6.0, 13.9), (-2.5, 6.1, 13.4), (-1.2, 6.2, 12.0),
        (14.0, 6.0, -9.0), (14.3, 6.1, -9.4)]
TARGETS = [(2.0, 0.0, -4.0)] * 4 + [(3.0, 0.0, -5.0), (3.0, 0.0, -5.0), (2.5, 0.0, -5.5)]


def walk_frames(dscene, settings, *, lights):
    """Per pose: the frame rasterized whole, and the frame scrolled from the previous scrolled one."""
    previous = None
    for eye, target, light in zip(EYES, TARGETS, lights):
        view = render_view(dscene, camera(48, 32, eye=eye, target=target), light, width=48, height=32, reference=False)
        whole = render_shadow(dscene, view, settings, lookup=False)
        scrolled = render_shadow(dscene, view, settings, lookup=False,
                                 scroll_from=None if previous is None else previous.maps)
        yield whole, scrolled, previous
        previous = scrolled


@pytest.fixture(scope="module")
def dscene():
    return prepare_scene(scene_of(scattered_boxes(3), plane_half=60.0))


def test_two_threads_scroll_the_same_maps_as_one(dscene):
    threaded = prepare_scene(dscene.scene, threads=2)
    settings = ShadowSettings(cascades=3, resolution=96, shadow_distance=50.0, stabilization="exact")
    light = direction_from_angles(elevation_deg=35.0, azimuth_deg=120.0)
    for (whole, _, _), (_, scrolled, _) in zip(walk_frames(dscene, settings, lights=[light] * len(EYES)),
                                               walk_frames(threaded, settings, lights=[light] * len(EYES))):
        np.testing.assert_array_equal(scrolled.maps.depth, whole.maps.depth)
        assert scrolled.maps.texels_rasterized == whole.maps.texels_rasterized


@pytest.mark.parametrize("stabilization, sizes", [("exact", ()), ("quantized", ()), ("exact", (128, 96, 64))])
def test_scrolled_maps_equal_the_maps_rasterized_whole_along_a_walk(dscene, stabilization, sizes):
    settings = ShadowSettings(cascades=3, resolution=128, cascade_resolutions=sizes, shadow_distance=50.0,
                              stabilization=stabilization, filter="pcf", filter_size=3)
    light = direction_from_angles(elevation_deg=35.0, azimuth_deg=120.0)
    moved = kept = 0
    for whole, scrolled, previous in walk_frames(dscene, settings, lights=[light] * len(EYES)):
        np.testing.assert_array_equal(scrolled.maps.depth, whole.maps.depth)
        assert scrolled.maps.texels_rasterized == whole.maps.texels_rasterized > 0
        assert scrolled.maps.raster is not None
        if previous is not None:
            shifts = scrolled.maps.raster.origin - previous.maps.raster.origin
            moved += int(np.any(shifts != 0))
            kept += int(not np.any(shifts))
    assert moved >= 3 and kept >= 1  # the walk scrolled some boxes and kept others still


def test_a_frame_whose_boxes_did_not_move_keeps_the_previous_maps_themselves(dscene):
    settings = ShadowSettings(cascades=3, resolution=64, shadow_distance=50.0, stabilization="exact")
    light = direction_from_angles(elevation_deg=35.0, azimuth_deg=120.0)
    frames = list(walk_frames(dscene, settings, lights=[light] * len(EYES)))
    _, scrolled, previous = frames[2]  # the repeated pose
    assert scrolled.maps.depth is previous.maps.depth
    assert not scrolled.maps.depth.flags.writeable


def test_a_light_that_moves_rasterizes_whole_and_equals_the_whole_maps(dscene):
    settings = ShadowSettings(cascades=2, resolution=64, shadow_distance=50.0, stabilization="exact")
    lights = [direction_from_angles(elevation_deg=35.0 + 2.0 * k, azimuth_deg=120.0) for k in range(len(EYES))]
    for whole, scrolled, _ in walk_frames(dscene, settings, lights=lights):
        np.testing.assert_array_equal(scrolled.maps.depth, whole.maps.depth)
        assert scrolled.maps.texels_rasterized == whole.maps.texels_rasterized


def test_boxes_off_whole_texels_keep_nothing_to_scroll_from(dscene):
    settings = ShadowSettings(cascades=2, resolution=64, shadow_distance=50.0, stabilization="none")
    light = direction_from_angles(elevation_deg=35.0, azimuth_deg=120.0)
    for whole, scrolled, _ in walk_frames(dscene, settings, lights=[light] * 3):
        assert scrolled.maps.raster is None
        np.testing.assert_array_equal(scrolled.maps.depth, whole.maps.depth)


def kept_maps(rng, *, sizes, bits=8) -> RasterizedMaps:
    side = max(sizes)
    return RasterizedMaps(basis=np.eye(3), zref=-3.0, bits=bits, texel_size=np.full((len(sizes), 2), 0.25),
                          origin=rng.integers(-50, 50, (len(sizes), 2)) << bits, resolution=np.array(sizes),
                          depth=rng.random((len(sizes), side, side)).astype(np.float32),
                          texels=rng.integers(0, 1000, len(sizes)))


def covered_once(regions, shape) -> np.ndarray:
    hits = np.zeros(shape, dtype=int)
    for c, i0, i1, j0, j1 in regions:
        hits[c, j0:j1, i0:i1] += 1
    return hits


@pytest.mark.parametrize("seed", range(6))
def test_kept_texels_and_regions_tile_each_map_and_left_regions_tile_what_the_box_left(seed):
    rng = np.random.default_rng(seed)
    sizes = [32, 24, 16]
    previous = kept_maps(rng, sizes=sizes)
    shift = rng.integers(-20, 21, (3, 2))
    shift[1] = 0
    origin = previous.origin + (shift << 8)
    plan = scroll_plan(previous, basis=np.eye(3), zref=-3.0, bits=8, texel_size=previous.texel_size, origin=origin,
                       resolution=sizes)
    rasterize = covered_once(plan.regions, previous.depth.shape)
    left = covered_once(plan.left, previous.depth.shape)
    for c, size in enumerate(sizes):
        dx, dy = shift[c]
        if max(abs(dx), abs(dy)) >= size:
            assert rasterize[c, :size, :size].min() == 1 and plan.kept_texels[c] == 0
            continue
        j, i = np.mgrid[0:size, 0:size]
        inside = (i + dx >= 0) & (i + dx < size) & (j + dy >= 0) & (j + dy < size)
        # Every texel is either kept from the previous map, at its shifted place, or rasterized.
        np.testing.assert_array_equal(rasterize[c, :size, :size], ~inside)
        np.testing.assert_array_equal(plan.depth[c, :size, :size][inside],
                                      previous.depth[c, :size, :size][(j + dy)[inside], (i + dx)[inside]])
        # The previous texels no new texel maps to are exactly the left regions.
        seen = np.zeros((size, size), dtype=bool)
        seen[(j + dy)[inside], (i + dx)[inside]] = True
        np.testing.assert_array_equal(left[c, :size, :size], ~seen)
        assert plan.kept_texels[c] == previous.texels[c]
        assert np.all(np.isinf(plan.depth[c, size:, :])) and np.all(np.isinf(plan.depth[c, :, size:]))
    assert rasterize.max() <= 1 and left.max() <= 1


@pytest.mark.parametrize("change", ["basis", "zref", "bits", "texel_size", "fraction", "resolution"])
def test_any_change_but_a_whole_texel_move_rasterizes_the_cascade_whole(change):
    rng = np.random.default_rng(1)
    sizes = [32, 32]
    previous = kept_maps(rng, sizes=sizes)
    box = dict(basis=np.eye(3), zref=-3.0, bits=8, texel_size=previous.texel_size.copy(),
               origin=previous.origin + (1 << 8), resolution=sizes)
    if change == "basis":
        box["basis"] = np.eye(3)[[1, 0, 2]]
    elif change == "zref":
        box["zref"] = -2.5
    elif change == "bits":
        box["bits"] = 4
    elif change == "texel_size":
        box["texel_size"][0, 0] = 0.5
    elif change == "fraction":
        box["origin"] = previous.origin + 3
    else:
        box["resolution"] = [32, 16]
    plan = scroll_plan(previous, **box)
    c = 1 if change == "resolution" else 0
    size = box["resolution"][c]
    assert (c, 0, size, 0, size) in [tuple(r) for r in plan.regions]
    assert plan.kept_texels[c] == 0


def window_walk(dscene, settings, monkeypatch):
    """Per pose of the walk: the maps made afresh, those made from the previous frame's (:class:`StoredMaps`), and the
    cascades the second rasterized (``(first, last)`` runs of :func:`csmlab.render._window_depth_maps`)."""
    light = direction_from_angles(elevation_deg=35.0, azimuth_deg=120.0)
    runs = []
    rasterize = render._window_depth_maps
    monkeypatch.setattr(render, "_window_depth_maps", lambda dscene, cascades, *args, **how: runs.append(
        (how.get("first", 0), how.get("last") or len(cascades))) or rasterize(dscene, cascades, *args, **how))
    previous = None
    for eye, target in zip(EYES, TARGETS):
        view = render_view(dscene, camera(48, 32, eye=eye, target=target), light, width=48, height=32, reference=False)
        fresh = render_shadow(dscene, view, settings, lookup=False)
        runs.clear()
        kept = render_shadow(dscene, view, settings, lookup=False, scroll_from=previous)
        yield fresh.maps, kept.maps, list(runs)
        previous = kept.maps


@pytest.mark.parametrize("changes, steps_keep", [
    (dict(engine_precision="float32"), True),
    (dict(engine_precision="float32", depth_format="unorm16", depth_quantization="cascade", cull="back"), True),
    (dict(engine_precision="float32", cascade_resolutions=(128, 96, 64), depth_range="slice", depth_clamp=True), False),
    (dict(depth_range="slice", depth_clamp=False), False),
    (dict(vertex_snap="window", depth_format="unorm24"), True),
])
def test_window_space_maps_keep_unchanged_cascades_bit_for_bit_and_count_as_rasterized_whole(dscene, changes,
                                                                                          steps_keep, monkeypatch):
    """An engine's float32 pipeline cannot scroll; a cascade whose every input is unchanged is taken from the previous
    frame, the others rasterized, and the maps and counts equal those made afresh (themselves the host pipeline's,
    tests/kernels/test_engine.py). A slice's depth range follows the camera, so only the repeated pose keeps its
    cascades there; elsewhere a small step keeps the far boxes."""
    settings = ShadowSettings(cascades=3, resolution=128, shadow_distance=50.0, stabilization="exact", filter="pcf",
                              filter_size=3, **changes).validated()
    whole = partial = 0
    for fresh, kept, runs in window_walk(dscene, settings, monkeypatch):
        assert isinstance(kept.raster, StoredMaps) and not kept.depth.flags.writeable
        assert kept.depth.tobytes() == fresh.depth.tobytes()
        assert kept.texels_rasterized == fresh.texels_rasterized > 0
        rasterized = sum(last - first for first, last in runs)
        whole += rasterized == 0
        partial += 0 < rasterized < 3
    assert whole >= 1 and (partial >= 1) == steps_keep


def test_a_camera_relative_pipeline_keeps_cascades_only_while_the_camera_stays(dscene, monkeypatch):
    """Rebased at the camera every frame (``rebase_distance = 0``), every float32 position changes as the eye moves:
    only the repeated pose keeps its maps, the previous frame's arrays themselves."""
    settings = ShadowSettings(cascades=3, resolution=64, shadow_distance=50.0, stabilization="exact",
                              engine_precision="camera_relative").validated()
    kept_whole = []
    for fresh, kept, runs in window_walk(dscene, settings, monkeypatch):
        assert kept.depth.tobytes() == fresh.depth.tobytes()
        assert kept.texels_rasterized == fresh.texels_rasterized
        kept_whole.append(runs == [])
    assert kept_whole == [k == 2 for k in range(len(EYES))]


def test_reused_cascades_are_those_of_equal_keys_from_the_same_mesh_and_map_size():
    mesh = object()
    depth = np.zeros((3, 8, 8), dtype=np.float32)
    previous = StoredMaps(keys=(b"a", b"b", b"c"), depth=depth, texels=np.arange(3), mesh=mesh)
    assert reused_cascades(previous, [b"a", b"x", b"c"], side=8, mesh=mesh).tolist() == [True, False, True]
    assert reused_cascades(previous, [b"a", b"b", b"c", b"d"], side=8, mesh=mesh).tolist() == [True] * 3 + [False]
    assert not reused_cascades(previous, [b"a", b"b", b"c"], side=16, mesh=mesh).any()
    assert not reused_cascades(previous, [b"a", b"b", b"c"], side=8, mesh=object()).any()
    assert not reused_cascades(None, [b"a"], side=8, mesh=mesh).any()
    assert not reused_cascades(kept_maps(np.random.default_rng(2), sizes=[8, 8, 8]), [b"a", b"b", b"c"], side=8,
                               mesh=mesh).any()


def stored_as_whole(frame, settings) -> np.ndarray:
    """The raw maps of a frame rendered without a previous frame, pancaked and stored whole by :mod:`csmlab.storage`."""
    cascades = frame.maps.cascades
    near = np.array([c.depth_near - cascades.zref for c in cascades.cascades])
    far = np.array([c.depth_far - cascades.zref for c in cascades.cascades])
    raw = frame.maps.raster.depth
    if settings.depth_range == "slice" and settings.depth_clamp:
        raw = np.maximum(raw, near.astype(np.float32)[:, None, None])
    if settings.depth_quantization == "cascade":
        return cascade_stored_depth(raw, near=near, far=far, depth_format=settings.depth_format)
    return stored_depth(raw, span=frame.maps.depth_span, depth_format=settings.depth_format)


def stored_walk(dscene, settings_of, monkeypatch):
    """Per pose of the walk (``settings_of(k)`` at pose k): the frame rendered without a previous frame, the frame
    scrolled from the previous scrolled one, that previous one, and the texels the scrolled frame stored (those of
    :func:`csmlab.render._stored_maps`' regions, every texel of its maps when it stored them whole)."""
    light = direction_from_angles(elevation_deg=35.0, azimuth_deg=120.0)
    stored = []
    store = render._stored_maps

    def spied(depth, *args, regions=None, **how):
        stored.append(depth.size if regions is None else int(np.sum((regions[:, 2] - regions[:, 1])
                                                                    * (regions[:, 4] - regions[:, 3]))))
        return store(depth, *args, regions=regions, **how)

    monkeypatch.setattr(render, "_stored_maps", spied)
    previous = None
    for k, (eye, target) in enumerate(zip(EYES, TARGETS)):
        settings = settings_of(k)
        view = render_view(dscene, camera(48, 32, eye=eye, target=target), light, width=48, height=32, reference=False)
        whole = render_shadow(dscene, view, settings, lookup=False)
        before = None if previous is None else previous.maps.depth.tobytes()
        stored.clear()
        scrolled = render_shadow(dscene, view, settings, lookup=False,
                                 scroll_from=None if previous is None else previous.maps)
        # The previous frame's maps, which the temporal metric still reads, are left as they were.
        assert previous is None or previous.maps.depth.tobytes() == before
        yield whole, scrolled, previous, sum(stored)
        previous = scrolled


@pytest.mark.parametrize("changes, keeps", [
    (dict(depth_format="unorm16"), True),
    (dict(depth_format="unorm16", stabilization="quantized"), True),
    (dict(depth_format="unorm24", cascade_resolutions=(128, 96, 64)), True),
    (dict(depth_format="unorm16", depth_quantization="cascade"), True),
    (dict(depth_range="slice", depth_clamp=True), False),
    (dict(depth_format="unorm16", depth_range="slice", depth_clamp=True, depth_quantization="cascade"), False),
])
def test_scrolled_stored_maps_equal_the_raw_maps_stored_whole_along_a_walk(dscene, changes, keeps, monkeypatch):
    """A cascade that scrolled under unchanged storage inputs keeps its stored texels and stores only the strips it
    rasterized; the maps equal, bit for bit, the maps rasterized and stored whole. A slice's near side (the pancaking,
    the cascade quantization's level 0) follows the camera, so only the repeated pose keeps its stored maps there."""
    settings = ShadowSettings(cascades=3, resolution=128, shadow_distance=50.0, filter="pcf", filter_size=3,
                              **{"stabilization": "exact", **changes}).validated()
    partial = 0
    for k, (whole, scrolled, previous, stored) in enumerate(stored_walk(dscene, lambda k: settings, monkeypatch)):
        expected = stored_as_whole(whole, settings)
        assert scrolled.maps.depth.tobytes() == expected.tobytes() == whole.maps.depth.tobytes()
        assert scrolled.maps.raster.stored is scrolled.maps.depth and not scrolled.maps.depth.flags.writeable
        if k == 2:  # the repeated pose: the previous stored maps themselves, nothing stored
            assert scrolled.maps.depth is previous.maps.depth and stored == 0
        partial += 0 < stored < scrolled.maps.depth.size
    assert partial >= 3 if keeps else partial == 0


def test_a_frame_whose_storage_changed_stores_its_maps_whole_though_its_raw_maps_scroll(dscene, monkeypatch):
    """The depth format and quantization change from frame to frame (the raw maps, with no caster offset, still
    scroll): a cascade stored under other inputs is stored whole from this frame's raw maps, the repeated pose's
    included; the frames after the same settings store only their strips."""
    looks = [dict(depth_format="unorm16"), dict(depth_format="unorm16"), dict(depth_format="unorm24"),
             dict(depth_format="unorm24", depth_quantization="cascade"), dict(depth_format="float32"),
             dict(depth_format="unorm16"), dict(depth_format="unorm16")]
    settings = [ShadowSettings(cascades=3, resolution=128, shadow_distance=50.0, stabilization="exact", **look)
                .validated() for look in looks]
    for k, (whole, scrolled, _, stored) in enumerate(stored_walk(dscene, settings.__getitem__, monkeypatch)):
        assert scrolled.maps.depth.tobytes() == stored_as_whole(whole, settings[k]).tobytes()
        if k in (2, 3, 5):
            assert stored == scrolled.maps.depth.size
        elif k in (1, 6):
            assert 0 < stored < scrolled.maps.depth.size
        elif k == 4:  # float32 stores the raw maps themselves
            assert scrolled.maps.depth is scrolled.maps.raster.depth and stored == 0


def stored_maps(rng, *, sizes) -> RasterizedMaps:
    previous = kept_maps(rng, sizes=sizes)
    stored = rng.random(previous.depth.shape).astype(np.float32)
    stored.flags.writeable = False
    return replace(previous, stored=stored, storage=tuple(b"key%d" % c for c in range(len(sizes))))


def test_kept_stored_texels_are_shifted_as_the_raw_ones_where_the_key_is_unchanged():
    rng = np.random.default_rng(7)
    sizes = [32, 24, 16]
    previous = stored_maps(rng, sizes=sizes)
    shift = np.array([[3, -2], [1, 4], [-5, 0]])
    plan = scroll_plan(previous, basis=np.eye(3), zref=-3.0, bits=8, texel_size=previous.texel_size,
                       origin=previous.origin + (shift << 8), resolution=sizes)
    storage = (b"key0", b"changed", b"key2")
    depth, regions = kept_stored(previous, shifts=plan.shifts, storage=storage, resolution=sizes)
    # Cascades 0 and 2 store the strips they rasterized; cascade 1, whose key changed, its whole map.
    raw = [tuple(r) for r in plan.regions if r[0] != 1] + [(1, 0, 24, 0, 24)]
    assert sorted(tuple(r) for r in regions) == sorted(raw)
    unset = covered_once(regions, depth.shape).astype(bool)
    for c in (0, 2):
        j, i = np.mgrid[0:sizes[c], 0:sizes[c]]
        dx, dy = plan.shifts[c]
        kept = ~unset[c, :sizes[c], :sizes[c]]
        np.testing.assert_array_equal(depth[c, :sizes[c], :sizes[c]][kept],
                                      previous.stored[c][(j + dy)[kept], (i + dx)[kept]])
    for c, size in enumerate(sizes):
        assert np.all(np.isinf(depth[c, size:, :])) and np.all(np.isinf(depth[c, :, size:]))
    # Nothing moved and no key changed: the previous stored maps themselves. Nothing kept (no stored maps, every
    # key changed, every cascade rasterized whole): None, the maps stored whole.
    still = kept_stored(previous, shifts=[(0, 0)] * 3, storage=previous.storage, resolution=sizes)
    assert still[0] is previous.stored and still[1].shape == (0, 5)
    assert kept_stored(replace(previous, stored=None), shifts=plan.shifts, storage=previous.storage,
                       resolution=sizes) == (None, None)
    assert kept_stored(previous, shifts=plan.shifts, storage=(b"a", b"b", b"c"), resolution=sizes) == (None, None)
    assert kept_stored(previous, shifts=[None] * 3, storage=previous.storage, resolution=sizes) == (None, None)
