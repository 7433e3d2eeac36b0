"""The engine pipelines on the kernels' path equal the host NumPy pipeline bit for bit.

The oracle is the host's statement of each engine's float32 arithmetic (:mod:`csmlab.texels`:
:func:`~csmlab.texels.fixed_point_coordinates`, :func:`~csmlab.texels.vertex_depth`,
:func:`~csmlab.texels.receiver_lookup`) and its whole-map, one-cascade-at-a-time rasterization
(:func:`csmlab.render.host_depth_maps`). The kernels (:mod:`csmlab.kernels.engine`, the chunked and
banded rasterizer) must give the same integers, depths and counts on the shipped scenes: terrain
(every engine preset, Filament's LiSPSM warp), foliage (alpha-tested casters) and terrain 10⁶ m from
the origin (where float32 rounds at 6 cm, so any difference in operation order shows).

Each kernel test runs on every device (the ``device`` fixture); the views, cascades and the host's
oracle are made on the CPU, so CUDA's kernels are held to the same bits as the CPU's.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from csmlab import filters, render
from csmlab.cascades import build_cascades
from csmlab.cascades.bounds import visible_depth_range
from csmlab.config import load_experiment
from csmlab.experiment import build_workload
from csmlab.frame import ShadowMaps
from csmlab.cascades.warp import warped_texels
from csmlab.kernels.bias import BiasSettings
from csmlab.kernels.engine import warped_vertices, window_chunk_vertices, window_receivers, window_vertices
from csmlab.kernels.raster import (chunk_vertices, converted_region_chunks, light_space_mesh, rasterize_cascades,
                                  region_chunks, whole_map_regions)
from csmlab.texels import fixed_point_coordinates, receiver_lookup, vertex_depth, window_boxes
from tests.locations import ROOT

RESOLUTION = 128
"""Map side the presets are shrunk to: small maps, the same arithmetic."""


@dataclasses.dataclass
class Case:
    """An experiment's methods and workload, its scene uploaded to each device a test asks for, once."""

    methods: dict
    workload: object
    scenes: dict = dataclasses.field(default_factory=dict)

    def on(self, device: str) -> render.DeviceScene:
        """The scene on ``device`` (the kernels' side of a comparison)."""
        if device not in self.scenes:
            self.scenes[device] = render.prepare_scene(self.workload.scene, device=device, threads=2)
        return self.scenes[device]

    @property
    def dscene(self) -> render.DeviceScene:
        """The scene on the CPU: the views, cascades and host oracle every device is compared against."""
        return self.on("cpu")


def _case(experiment: str) -> Case:
    exp = load_experiment(ROOT / "experiments" / experiment)
    methods = {m.name: m.settings for m in exp.methods if m.settings.shadow_map != "virtual_clipmap"}
    return Case(methods=methods, workload=build_workload(exp))


@pytest.fixture(scope="module")
def terrain() -> Case:
    return _case("engines.toml")


@pytest.fixture(scope="module")
def foliage() -> Case:
    return _case("foliage.toml")


@pytest.fixture(scope="module")
def far() -> Case:
    return _case("hard_far_origin.toml")


def _frame(case: Case, name: str, frame: int, **changes):
    settings = dataclasses.replace(case.methods[name], resolution=min(case.methods[name].resolution, RESOLUTION),
                                   **changes).validated()
    view = render.render_view(case.dscene, case.workload.path.pose(frame), case.workload.light.direction(frame),
                              width=96, height=54, reference=False)
    cascades = build_cascades(pose=view.pose, light_direction=view.light_direction, scene_corners=case.dscene.corners,
                              settings=settings, visible_depth=visible_depth_range(view.gbuffer.view_depth))
    return settings, view, cascades


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and a.dtype == b.dtype and np.array_equal(a.view(np.uint8), b.view(np.uint8))


ENGINE_PRESETS = ["ue5", "unity_builtin_stable", "unity_builtin_close", "unity_urp", "unity_hdrp", "godot4", "bevy",
                  "threejs_csm", "stride", "mjp"]


def _assert_maps_equal_the_host(case: Case, name: str, frame: int, device: str, **changes) -> None:
    settings, _, cascades = _frame(case, name, frame, **changes)
    assert not cascades.warped
    host, host_texels = render.host_depth_maps(case.dscene, cascades, settings)
    kernels, texels = render._window_depth_maps(case.on(device), cascades, settings,
                                                inputs=render._window_inputs(cascades, settings))
    assert _same_bits(kernels, host)
    assert texels.sum() == host_texels > 0


@pytest.mark.parametrize("name", ENGINE_PRESETS)
def test_every_engine_presets_depth_maps_equal_the_host_pipelines_on_terrain(terrain, name, device):
    _assert_maps_equal_the_host(terrain, name, 5, device)


@pytest.mark.parametrize("name", ["unity_urp", "threejs_csm", "ue5"])
def test_alpha_tested_casters_give_the_host_pipelines_maps_on_foliage(foliage, name, device):
    assert foliage.dscene.scene.vertex_mask is not None
    _assert_maps_equal_the_host(foliage, name, 2, device)


@pytest.mark.parametrize("name", ["exact_float32", "none_float32", "exact_camera_relative",
                                  "quantized_camera_relative"])
def test_maps_equal_the_host_pipelines_far_from_the_origin(far, name, device):
    _assert_maps_equal_the_host(far, name, 4, device)


def test_camera_relative_rebased_in_steps_and_window_snapping_equal_the_host(far, terrain, device):
    _assert_maps_equal_the_host(far, "none_camera_relative", 3, device, rebase_distance=64.0)
    _assert_maps_equal_the_host(terrain, "exact", 3, device, vertex_snap="window", stabilization="none")


def test_casters_clipped_at_a_slice_without_pancaking_equal_the_host_in_float64(terrain, device):
    """``depth_range = "slice"`` and ``depth_clamp = false`` on csmlab's own float64 grid: the same path, no window."""
    _assert_maps_equal_the_host(terrain, "exact", 6, device, depth_range="slice", depth_clamp=False)


@pytest.mark.parametrize("name, experiment", [("exact_float32", "far"), ("none_camera_relative", "far"),
                                              ("bevy", "terrain")])
def test_window_vertices_are_twice_the_hosts_fixed_point_and_its_depth(name, experiment, device, request):
    case = request.getfixturevalue(experiment)
    settings, _, cascades = _frame(case, name, 1, rebase_distance=16.0)
    vertices = case.dscene.scene.vertices
    boxes = window_boxes(cascades, bits=settings.subtexel_bits, precision=settings.engine_precision,
                         snap=settings.vertex_snap, rebase_distance=settings.rebase_distance, device=device)
    points, depth = window_vertices(boxes, positions=vertices, threads=2, device=device)
    how = dict(precision=settings.engine_precision, rebase_distance=settings.rebase_distance)
    for c in range(len(cascades)):
        assert np.array_equal(points[c], 2 * fixed_point_coordinates(cascades, c, vertices, bits=settings.subtexel_bits,
                                                                     **how))
        assert _same_bits(depth[c], vertex_depth(cascades, c, vertices, **how))


@pytest.mark.parametrize("name, experiment", [("exact_float32", "far"), ("ue5", "terrain")])
def test_window_chunk_vertices_are_window_vertices_at_the_pairs_chunks_and_their_rectangles(name, experiment, device,
                                                                                             request):
    """Every vertex of a pair's chunk is :func:`window_vertices`'s in the pair's cascade (the rest 0), and each pair's
    rectangle spans its chunk's points there (the other pairs' are empty), on any split of the pairs over threads."""
    case = request.getfixturevalue(experiment)
    settings, _, cascades = _frame(case, name, 1)
    mesh = render._scene_in_light_space(case.dscene, cascades, settings.cull)
    positions = case.dscene.ordered_vertices[(cascades.basis.tobytes(), cascades.zref, settings.cull)]
    boxes = window_boxes(cascades, bits=settings.subtexel_bits, precision=settings.engine_precision,
                         snap=settings.vertex_snap, rebase_distance=settings.rebase_distance, device=device)
    every_point, every_depth = window_vertices(boxes, positions=positions, device=device)
    listed = mesh.chunk_vertices
    chunks = listed.starts.size - 1
    rng = np.random.default_rng(3)
    pairs = np.argwhere(rng.random((len(cascades), chunks)) < 0.3)
    points, depth, low, high = window_chunk_vertices(boxes, positions=positions, vertices=listed, pairs=pairs,
                                                     threads=3, device=device)
    written = np.zeros((len(cascades), len(positions)), dtype=bool)
    for c, k in pairs:
        mine = listed.vertices[listed.starts[k]:listed.starts[k + 1]]
        written[c, mine] = True
        assert np.array_equal(low[c, k], every_point[c, mine].min(axis=0))
        assert np.array_equal(high[c, k], every_point[c, mine].max(axis=0))
    assert np.array_equal(points[written], every_point[written]) and _same_bits(depth[written], every_depth[written])
    assert not points[~written].any() and not depth[~written].any()
    unpaired = np.ones((len(cascades), chunks), dtype=bool)
    unpaired[pairs[:, 0], pairs[:, 1]] = False
    assert np.all(low[unpaired] > high[unpaired])
    with pytest.raises(ValueError, match="pairs: expected rows of a cascade in"):
        window_chunk_vertices(boxes, positions=positions, vertices=listed, pairs=[[len(cascades), 0]], device=device)


@pytest.mark.parametrize("name, experiment, changes", [
    ("ue5", "terrain", {}),
    ("unity_urp", "terrain", {}),
    ("stride", "terrain", {"normal_offset_scale": "sin", "normal_offset": 1.5}),
    ("mjp", "terrain", {"normal_offset_scale": "one_minus_cos_lateral", "normal_offset": 1.0,
                        "normal_offset_m": 0.01, "receiver_plane_offset": 0.01}),
    ("exact_float32", "far", {}),
    ("none_camera_relative", "far", {"rebase_distance": 32.0, "normal_offset_scale": "one_minus_cos"}),
    ("exact", "terrain", {"vertex_snap": "window", "stabilization": "none", "normal_offset": 0.7,
                          "normal_offset_scale": "one_minus_cos"}),
])
def test_window_receivers_equal_the_hosts_receiver_lookup(name, experiment, changes, device, request):
    case = request.getfixturevalue(experiment)
    settings, view, cascades = _frame(case, name, 4, **changes)
    g = view.gbuffer
    points, normals = g.position.reshape(-1, 3), g.normal.reshape(-1, 3)
    rows = np.flatnonzero(g.valid.reshape(-1))
    kernels = filters.texel_coordinates(cascades, points, normals, rows, settings=settings, device=device)
    host = receiver_lookup(cascades, points[rows], normals[rows], bits=settings.subtexel_bits,
                           normal_offset=settings.normal_offset,
                           bias_constant=filters._cascade_bias(cascades, settings),
                           bias_slope=settings.bias_slope, normal_scale=settings.normal_offset_scale,
                           plane_offset=filters._plane_offset(cascades, settings),
                           normal_offset_m=settings.normal_offset_m, precision=settings.engine_precision,
                           snap=settings.vertex_snap, rebase_distance=settings.rebase_distance)
    assert all(_same_bits(a, b) for a, b in zip(kernels, host))
    boxes = window_boxes(cascades, bits=settings.subtexel_bits, precision=settings.engine_precision,
                         snap=settings.vertex_snap, rebase_distance=settings.rebase_distance, device=device)
    none = BiasSettings(normal_offset=0.0, bias_constant=0.0, bias_slope=0.0)
    assert window_receivers(boxes, points, normals, receivers=rows[:0], basis=cascades.basis,
                            texel_size=np.stack([c.texel_size for c in cascades.cascades]), zref=cascades.zref,
                            bias=none, device=device)[0].shape == (len(cascades), 0, 2)


WINDOW_LOOKUPS = [("ue5", {}), ("unity_builtin_stable", {}), ("unity_urp", {}), ("unity_hdrp", {}), ("godot4", {}),
                  ("bevy", {}), ("mjp", {}), ("filament", {"warp": "none", "engine_precision": "float32"}),
                  ("stride", {"receiver_plane_bias": True, "blend_band": 0.2}),
                  ("unity_builtin_close", {"selection": "map", "blend_band": 0.3, "receiver_plane_bias": True}),
                  ("threejs_csm", {"filter": "pcf", "filter_size": 5, "receiver_plane_bias": True, "blend_band": 0.2})]
"""Every engine preset in window space, and changes that reach the other selections, the blend band, the
receiver-plane bias and a box filter of taps."""


@pytest.mark.parametrize("name, changes", WINDOW_LOOKUPS)
def test_window_lookups_equal_the_hosts_receivers_looked_up(terrain, name, changes, device, monkeypatch):
    """The selection kernel takes each receiver into window space only in the cascades it reads
    (shadow_lookup_window, select_window_cascades then weighted_pcf of the picked rows): the same S, cascade and
    blend, bit for bit, as the host's receiver_lookup of every receiver into every cascade, looked up by the
    kernels of converted receivers on the same device."""
    settings, view, cascades = _frame(terrain, name, 4, **changes)
    assert filters._converted_in_kernel(ShadowMaps(cascades=cascades, depth=np.zeros((1, 128, 128), np.float32),
                                                   texels_rasterized=0), settings) == "window"
    maps = ShadowMaps(cascades=cascades, depth=render.host_depth_maps(terrain.dscene, cascades, settings)[0],
                      texels_rasterized=0)
    g = view.gbuffer
    looked_up = dict(points=g.position, normals=g.normal, view_depth=g.view_depth, settings=settings, device=device)
    fused = filters.lookup_shadow(maps, **looked_up)

    def host_coordinates(cascades, points, normals, rows, *, settings, device):
        return receiver_lookup(cascades, points[rows], normals[rows], bits=settings.subtexel_bits,
                               normal_offset=settings.normal_offset,
                               bias_constant=filters._cascade_bias(cascades, settings),
                               bias_slope=settings.bias_slope, normal_scale=settings.normal_offset_scale,
                               plane_offset=filters._plane_offset(cascades, settings),
                               normal_offset_m=settings.normal_offset_m, precision=settings.engine_precision,
                               snap=settings.vertex_snap, rebase_distance=settings.rebase_distance)

    monkeypatch.setattr(filters, "_converted_in_kernel", lambda maps, settings: None)
    monkeypatch.setattr(filters, "texel_coordinates", host_coordinates)
    host = filters.lookup_shadow(maps, **looked_up)
    for field in ("lit", "cascade", "blend"):
        assert _same_bits(getattr(fused, field), getattr(host, field)), field
    lit = fused.lit[np.isfinite(fused.lit)]
    assert lit.size > 1000 and 0.0 < lit.mean() < 1.0
    assert len(set(np.unique(fused.cascade).tolist()) - {-1}) >= min(2, len(cascades))
    assert fused.blend.any() or settings.blend_band == 0.0


def test_window_lookup_names_maps_or_view_depths_that_do_not_match_its_boxes(terrain):
    from csmlab.kernels.shadow import shadow_lookup_window

    settings, view, cascades = _frame(terrain, "unity_urp", 4)
    conversion = filters._window_conversion(ShadowMaps(cascades=cascades, depth=np.zeros((1, 1, 1), np.float32),
                                                       texels_rasterized=0),
                                            filters._receivers(view.gbuffer.position, view.gbuffer.normal,
                                                               view.gbuffer.view_depth, pixels=None, quads=None,
                                                               quad_view_depth=None, reads=set()),
                                            settings, device="cpu")
    selection = filters._selection(cascades, settings, radius=1)
    with pytest.raises(ValueError, match="depth: expected the depth maps of the boxes' 4 cascades"):
        shadow_lookup_window(np.zeros((3, 128, 128), np.float32), **conversion, filter="pcf_bilinear", radius=1,
                             **selection)
    conversion["view_depth"] = conversion["view_depth"][:-1]
    with pytest.raises(ValueError, match="view_depth: expected one view depth per receiver"):
        shadow_lookup_window(np.zeros((4, 128, 128), np.float32), **conversion, filter="pcf_bilinear", radius=1,
                             **selection)


def _random_mesh(seed: int, triangles: int = 3000):
    rng = np.random.default_rng(seed)
    centres = rng.uniform(0.0, 40.0, (triangles, 1, 2))
    xy = (centres + rng.normal(0.0, 0.6, (triangles, 3, 2))).reshape(-1, 2)
    depth = rng.uniform(-5.0, 5.0, xy.shape[0])
    return light_space_mesh(xy, depth, np.arange(xy.shape[0]).reshape(-1, 3))


def test_chunks_of_converted_vertices_leave_out_no_triangle_that_covers_a_region(device):
    """Rasterizing only :func:`converted_region_chunks` gives the maps and counts of every chunk, region by region."""
    mesh = _random_mesh(11)
    texel = np.array([[0.1, 0.1], [0.23, 0.19]])
    origin = np.array([[37, -12], [-3, 21]], dtype=np.int64) << 8
    regions = np.array([[0, 0, 64, 0, 20], [0, 0, 64, 20, 64], [1, 5, 40, 0, 64]], dtype=np.int32)
    unit = 2.0**8
    points = np.stack([2 * (np.rint(mesh.xy / (texel[c] / unit)).astype(np.int64) - origin[c]) for c in range(2)])
    how = dict(texel_size=texel, origin=origin, resolution=64, bits=8, regions=regions, points=points, device=device)
    chunks = converted_region_chunks(points, mesh.chunk_vertices, regions=regions, bits=8, device=device)
    every = rasterize_cascades(mesh, **how)
    chosen = rasterize_cascades(mesh, chunks=chunks, **how)
    assert len(chunks) < len(regions) * (-(-mesh.triangles.shape[0] // 32))
    assert _same_bits(chosen[0], every[0]) and np.array_equal(chosen[1], every[1]) and every[1].sum() > 0
    # The same points converted by the rasterizer itself from light space: the same maps.
    converted = rasterize_cascades(mesh, texel_size=texel, origin=origin, resolution=64, bits=8, regions=regions,
                                   device=device)
    assert _same_bits(converted[0], every[0])


def test_chunks_chosen_by_their_distinct_vertices_are_those_chosen_by_their_corners(device):
    """A mesh whose triangles share vertices (a grid): each chunk's rectangle over its distinct vertices is the one over
    its triangles' corners, so :func:`converted_region_chunks` keeps the same (region, chunk) rows."""
    corner = np.arange(40)[:, None] * 41 + np.arange(40)[None, :]
    quads = np.stack([corner, corner + 1, corner + 41, corner + 42], axis=-1).reshape(-1, 4)
    triangles = np.concatenate([quads[:, [0, 1, 2]], quads[:, [1, 3, 2]]], axis=1).reshape(-1, 3)
    rng = np.random.default_rng(13)
    xy = np.stack(np.meshgrid(np.arange(41.0), np.arange(41.0)), axis=-1).reshape(-1, 2) + rng.normal(0, 0.3, (1681, 2))
    mesh = light_space_mesh(xy, np.zeros(len(xy)), triangles)
    points = np.stack([2 * (np.rint(mesh.xy / (size / 2.0**8)).astype(np.int64) - 40) for size in (0.25, 0.7)])
    regions = np.array([[0, 0, 64, 0, 64], [0, 64, 160, 30, 90], [1, 10, 50, 0, 64]], dtype=np.int32)
    distinct = converted_region_chunks(points, mesh.chunk_vertices, regions=regions, bits=8, device=device)
    corners = converted_region_chunks(points, chunk_vertices(mesh.triangles, distinct=False), regions=regions, bits=8,
                                      device=device)
    assert mesh.chunk_vertices.vertices.size < mesh.triangles.size / 2
    np.testing.assert_array_equal(distinct, corners)
    assert 0 < len(distinct) < len(regions) * (-(-len(triangles) // 32))


def test_a_near_cut_drops_exactly_the_triangles_wholly_nearer_than_it(device):
    """``near`` per cascade equals rasterizing the triangle list :func:`csmlab.render.clipped_casters` keeps."""
    mesh = _random_mesh(12)
    texel = np.array([[0.1, 0.1], [0.1, 0.1]])
    origin = np.zeros((2, 2), dtype=np.int64)
    near = np.array([-1.0, 2.5])
    how = dict(texel_size=texel, origin=origin, resolution=400, bits=8, device=device)
    cut = rasterize_cascades(mesh, near=near, **how)
    for c in range(2):
        kept = light_space_mesh(mesh.xy, mesh.depth, render.clipped_casters(mesh.depth, mesh.triangles, near=near[c]))
        alone = rasterize_cascades(kept, regions=whole_map_regions([400]), texel_size=texel[c:c + 1],
                                   origin=origin[c:c + 1], resolution=400, bits=8, device=device)
        assert _same_bits(cut[0][c], alone[0][0]) and cut[1][c] == alone[1][0] > 0
    chunks = region_chunks(mesh.bounds, texel_size=texel, origin=np.zeros((2, 2)), regions=whole_map_regions([400] * 2))
    assert _same_bits(rasterize_cascades(mesh, near=near, chunks=chunks, **how)[0], cut[0])


def test_converted_vertices_of_the_wrong_shape_name_the_argument():
    mesh = _random_mesh(13, triangles=10)
    how = dict(texel_size=np.ones((1, 2)), origin=np.zeros((1, 2), np.int64), resolution=8, bits=4)
    with pytest.raises(ValueError, match="points"):
        rasterize_cascades(mesh, points=np.zeros((1, 5, 2), np.int64), **how)
    with pytest.raises(ValueError, match="vertex_depth"):
        rasterize_cascades(mesh, points=np.zeros((1, 30, 2), np.int64), vertex_depth=np.zeros((1, 29)), **how)
    with pytest.raises(ValueError, match="near"):
        rasterize_cascades(mesh, near=[0.0, 1.0], **how)


@pytest.mark.parametrize("experiment, frame, changes", [
    ("terrain", 5, {}),
    ("terrain", 9, {"cull": "back", "depth_range": "slice", "depth_clamp": False, "cascades": 3}),
    ("foliage", 2, {}),
])
def test_warped_cascades_maps_equal_the_host_pipelines(experiment, frame, changes, device, request):
    """Filament's LiSPSM (``warp = "lispsm"``): clipped at the warp's near plane, through the homography on the
    device, rasterized in bands; the host's :func:`csmlab.render.warped_depth_map` maps and counts bit for bit."""
    case = request.getfixturevalue(experiment)
    settings, _, cascades = _frame(case, "filament", frame, **changes)
    assert cascades.warped
    host, host_texels = render.host_depth_maps(case.dscene, cascades, settings)
    kernels, texels = render._warped_window_depth_maps(case.on(device), cascades, settings)
    assert _same_bits(kernels, host)
    assert texels == host_texels > 0


def test_warped_vertices_are_the_hosts_homography_texels_and_depth_over_w(device):
    rng = np.random.default_rng(14)
    homography = np.array([[3.1, 0.4, 40.0], [0.2, 2.7, 11.0], [0.001, 0.03, 1.5]])
    xy = rng.uniform(-20.0, 20.0, (2000, 2))
    depth = rng.uniform(-5.0, 5.0, 2000)
    points, per_w = warped_vertices(homography, xy, depth, bits=8, device=device)
    texels, w = warped_texels(homography, xy)
    assert np.all(w > 0)
    assert np.array_equal(points, 2 * np.rint(np.clip(texels * 256.0, -2.0**50, 2.0**50)).astype(np.int64))
    assert _same_bits(per_w, depth / w)


@pytest.mark.parametrize("experiment, changes", [
    ("terrain", {}),
    ("terrain", {"bias_slope": 2.0, "normal_offset": 1.0, "normal_offset_scale": "sin"}),
    ("terrain", {"bias_slope": 1.0, "receiver_plane_offset": 0.01, "normal_offset": 0.5, "normal_offset_m": 0.02,
                 "normal_offset_scale": "one_minus_cos_lateral", "cascades": 3}),
    ("foliage", {"normal_offset_scale": "one_minus_cos", "normal_offset": 2.0, "subtexel_bits": 4}),
])
def test_warped_receivers_equal_the_hosts_receiver_lookup(experiment, changes, device, request):
    """Filament's receivers through the homography (texel size from the Jacobian's inverse, NumPy's ``hypot``)."""
    case = request.getfixturevalue(experiment)
    settings, view, cascades = _frame(case, "filament", 6, **changes)
    assert all(c.warp is not None for c in cascades.cascades)
    g = view.gbuffer
    points, normals = g.position.reshape(-1, 3), g.normal.reshape(-1, 3)
    rows = np.flatnonzero(g.valid.reshape(-1))
    kernels = filters.texel_coordinates(cascades, points, normals, rows, settings=settings, device=device)
    host = receiver_lookup(cascades, points[rows], normals[rows], bits=settings.subtexel_bits,
                           normal_offset=settings.normal_offset,
                           bias_constant=filters._cascade_bias(cascades, settings), bias_slope=settings.bias_slope,
                           normal_scale=settings.normal_offset_scale,
                           plane_offset=filters._plane_offset(cascades, settings),
                           normal_offset_m=settings.normal_offset_m)
    assert all(_same_bits(a, b) for a, b in zip(kernels, host))
