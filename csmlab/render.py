"""One frame on one Warp device, in the order of docs/design.md's CSM model.

What depends on the camera and the light only — the G-buffer (step 5) and the ray-traced
reference (step 7) — is :func:`render_view`, computed once per frame and shared by every shadow
method. Each method then runs :func:`render_shadow`: cascades (steps 1–3), depth maps in fixed
point (step 4) and the shadow lookup at every visible pixel (step 6, :func:`csmlab.filters.lookup_shadow`,
which this module also offers as :func:`lookup_shadow`; its fade is :mod:`csmlab.fades`). :func:`render_frame`
does both. Each stage's wall-clock time goes into the records' ``timings``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from csmlab.camera import CameraPose
from csmlab.clipmaps import (VirtualPages, clipmap_cascades, clipmap_levels, footprint_scale, light_space,
                             marked_pages, page_cache, page_table, pool_bytes, resident_pages, wanted_levels)
from csmlab.culling import culled_triangles
from csmlab.cascades import CascadeSet, build_cascades
from csmlab.cascades.bounds import BOUNDS_METHODS, DEPTH_RANGE_METHODS, visible_depth_range
from csmlab.cascades.warp import warped_texels
from csmlab.filters import clipmap_radius, filter_inputs, lookup_shadow, noise_frame, receiver_rows
from csmlab.frame import Frame, GBuffer, ShadowMaps, View
from csmlab.geometry import light_basis, normalized
from csmlab.kernels.engine import warped_vertices, window_chunk_vertices, window_vertices
from csmlab.kernels.raster import (BANDS_PER_THREAD, LightSpaceMesh, banded_regions, chunk_vertices,
                                  chunks_meeting_regions, converted_region_chunks, light_space_mesh,
                                  rasterize_cascades, rasterize_depth, region_chunks, whole_map_regions, z_ordered)
from csmlab.kernels.alpha import masked_mesh
from csmlab.kernels.reference import hard_shadow
from csmlab.kernels.threads import checked_threads
from csmlab.kernels.texture import textured_albedo
from csmlab.kernels.visibility import MeshBVH, camera_hits, mesh_bvh
from csmlab.quads import quad_lanes
from csmlab.registry import dispatch, parameters
from csmlab.scene.core import Scene
from csmlab.scrolling import RasterizedMaps, StoredMaps, kept_stored, reused_cascades, scroll_plan
from csmlab.settings import ShadowSettings
from csmlab.storage import DEPTH_FORMATS, DEPTH_QUANTIZATION_METHODS, polygon_offset_unit, stored_depth
from csmlab.texels import (WINDOW_BOX_ROWS, fixed_point_coordinates, fixed_point_origin, light_depth,
                           light_plane_coordinates, uploaded_boxes, uses_global_grid, vertex_depth, window_box_inputs,
                           window_box_slice, window_rectangles)

__all__ = ["DeviceScene", "caster_offsets", "caster_scene", "clipped_casters", "clipped_triangles", "host_depth_maps",
           "lookup_shadow", "prepare_scene", "render_frame", "render_shadow", "render_view", "shadow_maps",
           "virtual_shadow_maps", "visible_depth", "warped_depth_map"]


LIGHT_SPACE_MESHES = 8
"""Light-space meshes a :class:`DeviceScene` keeps, the least recently used dropped first. The methods of
one run build their light bases and depth references each their own way (five for the thirteen methods
of ``experiments/engines.toml``), and a worker renders them in turn every frame: keeping one light's
meshes only made 29 of 51 calls of a 4-frame walk there build theirs again (a pass over every vertex and
a Z-order sort, ~40 ms on the terrain). A light that moves every frame makes a new key every frame,
which the bound keeps from piling up."""
LIGHT_SPACE_BYTES = 512 * 2 ** 20
"""Bytes of the light-space meshes a :class:`DeviceScene` keeps beside the newest, which is always kept: the
terrain's take ~10 MB each, a 3M-triangle level's ~110 MB (its vertices' light-space x/y and depth, its
triangles, and its float64 vertices in their order), of which eight would hold ~0.9 GB in every process."""


@dataclass(frozen=True)
class DeviceScene:
    """A scene uploaded once to a Warp device.

    Attributes
    ----------
    scene : Scene
        The host scene (float64 vertices, used for the fixed-point conversion of every frame).
    bvh : MeshBVH
        Its BVH and vertices on the device, relative to a float64 anchor.
    device : str
    corners : ndarray, shape (8, 3), float64
        The scene's bounding-box corners, metres (:meth:`Scene.corners`, a pass over every
        vertex: taken once here, not twice per frame and method).
    light_space : dict
        The scene in the light spaces last used (what the cascade pass needs of every vertex and
        triangle, which a static light leaves unchanged from frame to frame), keyed by the light
        basis, its depth offset and the face cull (``settings.cull``), least recently used first, at
        most :data:`LIGHT_SPACE_MESHES` and :data:`LIGHT_SPACE_BYTES`.
    ordered_vertices : dict
        Beside each mesh of ``light_space``, under the same key: the scene's float64 world vertices
        ``(V, 3)`` in that mesh's vertex order (what an engine's float32 pipeline transforms).
    chunk_boxes : dict
        Beside those, once an engine's pipeline has read them: the world box ``(lo, hi)`` ``(K, 3)`` of
        each chunk of the mesh's triangles (:func:`_chunk_world_boxes`).
    casters : dict
        The scene as a depth pass casts it under a ``[shadow] blend_casters`` rule that changes its
        blended triangles (:func:`caster_scene`), uploaded once per rule, by rule.
    threads : int
        CPU threads a frame's kernels may use at once (one Warp CPU launch runs on one thread):
        1 where processes already share out the cores (:mod:`csmlab.executor`).
    albedo_table : ndarray, shape (T + 1, 3), float32, or None
        Each triangle's albedo and a row of 0 after them, that the G-buffer gathers by hit triangle
        (a miss, −1, reads the 0); None for a textured scene, whose albedo is sampled at the hits.
    """

    scene: Scene
    bvh: MeshBVH
    device: str
    corners: np.ndarray = field(compare=False, repr=False)
    light_space: dict = field(default_factory=dict, compare=False, repr=False)
    threads: int = 1
    ordered_vertices: dict = field(default_factory=dict, compare=False, repr=False)
    chunk_boxes: dict = field(default_factory=dict, compare=False, repr=False)
    casters: dict = field(default_factory=dict, compare=False, repr=False)
    albedo_table: np.ndarray | None = field(default=None, compare=False, repr=False)


def prepare_scene(scene: Scene, *, device: str = "cpu", threads: int = 1) -> DeviceScene:
    """Upload ``scene`` to ``device`` (``"cpu"`` or ``"cuda"``) and build its BVH; ``threads`` as
    :class:`DeviceScene`."""
    return DeviceScene(scene=scene, bvh=mesh_bvh(scene.vertices, scene.triangles, uv=scene.uv,
                                                 vertex_mask=scene.vertex_mask, alpha=scene.alpha, device=device),
                       device=device,
                       corners=scene.corners(), threads=checked_threads(threads, device),
                       albedo_table=None if scene.textured else _albedo_table(scene))


def _albedo_table(scene: Scene) -> np.ndarray:
    """``(T + 1, 3)`` float32: each triangle's albedo, then a row of 0 that a miss (triangle −1) reads."""
    return np.vstack([np.asarray(scene.albedo, dtype=np.float32), np.zeros((1, 3), dtype=np.float32)])


def caster_scene(dscene: DeviceScene, rule: str) -> DeviceScene:
    """The scene a depth pass rasterizes under ``[shadow] blend_casters = rule``.

    ``rule``: a key of :data:`csmlab.culling.BLEND_CASTER_RULES`.

    ``dscene`` itself for ``"scene"`` and wherever the rule leaves its casters as they are (a level
    without blended triangles: bit for bit the level's maps); else the casters of
    :meth:`csmlab.scene.core.Scene.casters` uploaded once (kept in ``dscene.casters``), with the
    level's bounding corners (the cascades fit the level, not its casters). The camera pass and the
    reference keep ``dscene``.
    """
    if rule == "scene":
        return dscene
    if rule not in dscene.casters:
        casters = dscene.scene.casters(rule)
        dscene.casters[rule] = dscene if casters is dscene.scene else replace(
            prepare_scene(casters, device=dscene.device, threads=dscene.threads), corners=dscene.corners)
    return dscene.casters[rule]


def render_view(dscene: DeviceScene, pose: CameraPose, light_direction, *, width: int, height: int,
                index: int = 0, previous_light_direction=None, reference: bool = True, jitter=None,
                light_colour=None) -> View:
    """The G-buffer and the ray-traced reference of one camera and light (shared by all methods).

    Parameters
    ----------
    dscene : DeviceScene
    pose : CameraPose
    light_direction : array_like, shape (3,)
        From the light toward the scene.
    width, height : int
        Image size in pixels.
    index : int
        Frame number recorded in the view.
    previous_light_direction : array_like, shape (3,), optional
        The previous frame's light: where it differs from ``light_direction``, the reference is
        also cast with it from this view's points (``View.previous_reference``, the temporal
        metric's R_{t−1}).
    reference : bool
        Cast the reference. False leaves ``View.reference`` None: a frame rendered only as the
        previous frame of the temporal metrics (a chunk's first, :mod:`csmlab.experiment`) needs
        its cascades, not its reference.
    jitter : tuple of float, optional
        Sub-pixel camera jitter ``(x, y)`` in pixels for temporal anti-aliasing (``View.jitter``);
        None: pixel centres, no TAA.
    light_colour : array_like, shape (3,), optional
        Linear RGB of the light (``View.light_colour``, for the shading); None: white.

    Returns
    -------
    View
        ``timings`` holds ``visibility``, ``reference`` (and ``reference_previous``) in seconds.
    """
    d = normalized(light_direction, name="light direction")
    start = time.perf_counter()
    hits = camera_hits(dscene.bvh, position=pose.position, rotation=pose.rotation, fov_y_deg=pose.fov_y_deg,
                       aspect=pose.aspect, far=pose.far, width=width, height=height, threads=dscene.threads,
                       jitter=(0.0, 0.0) if jitter is None else jitter)
    if dscene.scene.textured:
        albedo = textured_albedo(dscene.scene, hits.triangle, hits.position, device=dscene.device).astype(np.float32)
    else:
        # One gather, a miss (−1) reading the table's last row, 0: no masks, no copies (3.9 → 0.6 ms).
        table = _albedo_table(dscene.scene) if dscene.albedo_table is None else dscene.albedo_table
        albedo = np.take(table, hits.triangle, axis=0)
    gbuffer = GBuffer(hits=hits, albedo=albedo)
    timings = {"visibility": time.perf_counter() - start}
    before = previous = cast = None
    if reference:
        start = time.perf_counter()
        cast = hard_shadow(dscene.bvh, points=gbuffer.position, normals=gbuffer.normal, light_direction=d,
                           threads=dscene.threads)
        timings["reference"] = time.perf_counter() - start
    if reference and previous_light_direction is not None:
        before = normalized(previous_light_direction, name="previous light direction")
    if before is not None and not np.array_equal(before, d):
        start = time.perf_counter()
        previous = hard_shadow(dscene.bvh, points=gbuffer.position, normals=gbuffer.normal, light_direction=before,
                               threads=dscene.threads)
        timings["reference_previous"] = time.perf_counter() - start
    else:
        before = None
    return View(index=index, pose=pose, light_direction=d, gbuffer=gbuffer, reference=cast, timings=timings,
                previous_light_direction=before, previous_reference=previous,
                jitter=None if jitter is None else (float(jitter[0]), float(jitter[1])),
                light_colour=None if light_colour is None else np.asarray(light_colour, dtype=np.float64))


def _scene_in_light_space(dscene: DeviceScene, cascades: CascadeSet, cull: str = "none") -> LightSpaceMesh:
    """The scene as the depth pass reads it (light-space x/y and depth of vertices, triangles), made once per light.

    Only the triangles ``cull`` keeps (:func:`csmlab.culling.culled_triangles`, judged by ``d``
    alone) are handed on, listed with their vertices along a Z-order curve in light space
    (:func:`csmlab.kernels.raster.z_ordered`): the same mesh, rasterized place by place. The last
    :data:`LIGHT_SPACE_MESHES` meshes used are kept (fewer where they would hold over
    :data:`LIGHT_SPACE_BYTES`), under their light basis, depth reference and cull.
    """
    key = (cascades.basis.tobytes(), cascades.zref, cull)
    if key in dscene.light_space:
        # Most recently used last: the first key is the one to drop.
        dscene.light_space[key] = dscene.light_space.pop(key)
    else:
        vertices = dscene.scene.vertices
        xy = light_plane_coordinates(cascades, vertices)
        order, triangles = z_ordered(xy, culled_triangles(vertices, dscene.scene.triangles, cascades.direction, cull))
        scene = dscene.scene
        masks = {} if scene.vertex_mask is None else dict(uv=scene.uv[order], vertex_mask=scene.vertex_mask[order],
                                                          alpha=scene.alpha)
        mesh = light_space_mesh(xy[order], light_depth(cascades, vertices)[order], triangles, **masks)
        ordered = np.ascontiguousarray(vertices[order], dtype=np.float64)
        kept = _light_space_bytes(mesh, ordered) + sum(_light_space_bytes(dscene.light_space[k],
                                                                          dscene.ordered_vertices.get(k))
                                                       for k in dscene.light_space)
        while dscene.light_space and (len(dscene.light_space) >= LIGHT_SPACE_MESHES or kept > LIGHT_SPACE_BYTES):
            dropped = next(iter(dscene.light_space))
            kept -= _light_space_bytes(dscene.light_space.pop(dropped), dscene.ordered_vertices.pop(dropped, None))
            dscene.chunk_boxes.pop(dropped, None)
        dscene.light_space[key] = mesh
        dscene.ordered_vertices[key] = ordered
    return dscene.light_space[key]


def _chunk_world_boxes(dscene: DeviceScene, key: tuple, mesh: LightSpaceMesh) -> tuple[np.ndarray, np.ndarray]:
    """The world box ``(lo, hi)`` ``(K, 3)`` float64 of each chunk of ``mesh`` (the mesh of ``dscene.light_space`` under
    ``key``), over its vertices ``dscene.ordered_vertices[key]``; made once per mesh."""
    if key not in dscene.chunk_boxes:
        listed = mesh.chunk_vertices
        corners = dscene.ordered_vertices[key][listed.vertices]
        starts = listed.starts[:-1]
        dscene.chunk_boxes[key] = (np.minimum.reduceat(corners, starts, axis=0),
                                   np.maximum.reduceat(corners, starts, axis=0))
    return dscene.chunk_boxes[key]


def _light_space_bytes(mesh: LightSpaceMesh, ordered: np.ndarray | None) -> int:
    """Bytes of a kept light-space mesh's arrays and its ordered float64 vertices."""
    arrays = (mesh.xy, mesh.depth, mesh.triangles, mesh.uv, mesh.vertex_mask, ordered)
    return sum(a.nbytes for a in arrays if a is not None)


def visible_depth(dscene: DeviceScene, pose: CameraPose, *, width: int, height: int) -> tuple[float, float] | None:
    """The view-depth range ``(z_min, z_max)`` in metres of the G-buffer :func:`render_view` would make (SDSM)."""
    hits = camera_hits(dscene.bvh, position=pose.position, rotation=pose.rotation, fov_y_deg=pose.fov_y_deg,
                       aspect=pose.aspect, far=pose.far, width=width, height=height, threads=dscene.threads)
    return visible_depth_range(hits.view_depth)


def shadow_maps(dscene: DeviceScene, cascades: CascadeSet, settings: ShadowSettings, *,
                scroll_from: ShadowMaps | None = None) -> ShadowMaps:
    """Rasterize every cascade's depth map from the scene's vertices in fixed point, stored in
    ``settings.depth_format``.

    Pancaked slice boxes (``depth_range = "slice"``) are clamped to their near side; the moments
    and their mips follow when the filter reads them (:func:`csmlab.filters.filter_inputs`). ``scroll_from``, the
    same method's previous maps, lends the texels its boxes already covered (:mod:`csmlab.scrolling`), raw
    and as stored (:func:`_scrolled_stored_maps`), or, on a window-space path, the stored maps of the
    cascades whose every input is unchanged: the same maps, less rasterization and storing. The casters are
    ``settings.blend_casters``' (:func:`caster_scene`).
    """
    dscene = caster_scene(dscene, settings.blend_casters)
    previous = None if scroll_from is None else scroll_from.raster
    span = float(np.ptp(cascades.to_light(dscene.corners)[:, 2]))
    cut = DEPTH_RANGE_METHODS[settings.depth_range].cuts_casters
    if cascades.warped:
        depth, texels = _warped_window_depth_maps(dscene, cascades, settings)
        depth, raster = _stored_maps(depth, cascades, settings, span=span), None
    elif uses_global_grid(precision=settings.engine_precision, snap=settings.vertex_snap) \
            and not (cut and not settings.depth_clamp):
        depth, texels, raster, shifts = _culled_depth_maps(dscene, cascades, settings, previous=previous)
        depth, raster = _scrolled_stored_maps(depth, raster, cascades, settings, span=span, shifts=shifts,
                                              previous=previous)
    else:
        depth, texels, raster = _window_stored_maps(dscene, cascades, settings, span=span, previous=previous)
    moments, mips = filter_inputs(depth, cascades, span=span, settings=settings, device=dscene.device)
    return ShadowMaps(cascades=cascades, depth=depth, texels_rasterized=texels, moments=moments, depth_span=span,
                      mips=mips, raster=raster)


def _stored_maps(depth: np.ndarray, cascades: CascadeSet, settings: ShadowSettings, *, span: float, first: int = 0,
                 last: int | None = None, regions: np.ndarray | None = None,
                 out: np.ndarray | None = None) -> np.ndarray:
    """Rasterized maps ``(C', R, R)`` of cascades ``[first, last)`` as stored: pancaked, then in the depth format.

    ``span``: the scene's light-space depth range in metres (:data:`csmlab.storage.DEPTH_QUANTIZATION_METHODS`'
    ``scene`` quantization). Each cascade's stored map depends only on its own rasterized map, its
    near and far side, ``span`` and the settings (:func:`_storage_keys`). ``regions`` ``(G, 5)``: only
    those rectangles ``(c, i0, i1, j0, j1)`` are stored, into ``out`` ``(C', R, R)`` (writeable, its other
    texels kept), which is returned; a format and range that store the raw depths as they are
    (``float32``, no pancaking) write nothing there and return ``depth``.
    """
    boxes = cascades.cascades[first:last]
    near = [c.depth_near - cascades.zref for c in boxes]
    if _pancaked(settings):
        # Pancaking is a per-fragment clamp max(z, near); the stored minimum of clamped fragments
        # is the clamped minimum, so clamping the map is exact.
        floor = np.array(near, dtype=np.float32)
        if regions is None:
            # In place where the maps are this call's own (not kept read-only for the next frame's scrolling):
            # a fresh (C, R, R) array costs its page faults, more than the comparisons.
            depth = np.maximum(depth, floor[:, None, None], out=depth if depth.flags.writeable else None)
        else:
            for c, i0, i1, j0, j1 in regions:
                np.maximum(depth[c, j0:j1, i0:i1], floor[c], out=out[c, j0:j1, i0:i1])
            depth = out
    # The unorm levels in place too, where the maps are this call's own.
    return dispatch(DEPTH_QUANTIZATION_METHODS, settings.depth_quantization, depth, field="depth_quantization",
                    depth_format=settings.depth_format, overwrite=bool(depth.flags.writeable), regions=regions,
                    out=out, offered=dict(span=span, near=near, far=[c.depth_far - cascades.zref for c in boxes]))


def _pancaked(settings: ShadowSettings) -> bool:
    """Whether the maps are stored clamped to each box's near side (a range that cuts casters, ``depth_clamp``)."""
    return DEPTH_RANGE_METHODS[settings.depth_range].cuts_casters and settings.depth_clamp


def _storage_keys(cascades: CascadeSet, settings: ShadowSettings, *, span: float) -> tuple[bytes, ...]:
    """Each cascade's inputs to :func:`_stored_maps` besides its raw map, bit for bit, as bytes.

    The depth format, quantization and pancaking, and the values they read: the box's near side
    where it is pancaked, and for a unorm format what its quantization method declares of ``span``
    (``scene``) and the box's near and far side (``cascade``).
    """
    pancaked = _pancaked(settings)
    unorm = DEPTH_FORMATS[settings.depth_format][0] is not None
    declared = parameters(DEPTH_QUANTIZATION_METHODS[settings.depth_quantization]) if unorm else ()
    shared = repr((settings.depth_format, settings.depth_quantization, pancaked,
                   span if "span" in declared else None)).encode()
    keys = []
    for cascade in cascades.cascades:
        near, far = cascade.depth_near - cascades.zref, cascade.depth_far - cascades.zref
        values = [near] if pancaked or "near" in declared else []
        keys.append(shared + np.array(values + ([far] if "far" in declared else []), dtype=np.float64).tobytes())
    return tuple(keys)


def _scrolled_stored_maps(raw: np.ndarray, raster: RasterizedMaps | None, cascades: CascadeSet,
                          settings: ShadowSettings, *, span: float, shifts,
                          previous) -> tuple[np.ndarray, RasterizedMaps | None]:
    """``(C, R, R)`` stored maps of the global grid's raw maps ``raw``, and ``raster`` keeping them for the next frame.

    Where the raw maps scrolled (``shifts``, :attr:`csmlab.scrolling.ScrollPlan.shifts`), a cascade stored
    under the same keys (:func:`_storage_keys`) in ``previous`` keeps its stored texels, shifted as the raw
    ones (:func:`csmlab.scrolling.kept_stored`): only the texels rasterized this frame are pancaked and
    quantized, not every texel of every map each frame. Boxes off whole texels (``raster`` None) store
    their own maps in place. ``float32`` without pancaking stores the raw maps themselves.
    """
    if raster is None:
        return _stored_maps(raw, cascades, settings, span=span), None
    storage = _storage_keys(cascades, settings, span=span)
    if not (_pancaked(settings) or DEPTH_FORMATS[settings.depth_format][0] is not None):
        return raw, replace(raster, stored=raw, storage=storage)
    depth, regions = kept_stored(previous, shifts=shifts, storage=storage, resolution=raster.resolution)
    if depth is None:
        depth = _stored_maps(raw, cascades, settings, span=span)
    elif len(regions):
        depth = _stored_maps(raw, cascades, settings, span=span, regions=regions, out=depth)
    depth.flags.writeable = False
    return depth, replace(raster, stored=depth, storage=storage)


def caster_offsets(cascades: CascadeSet, settings: ShadowSettings) -> np.ndarray:
    """``(C,)`` metres each cascade's casters are pushed away from the light, the constant part of their offset.

    ``caster_bias_texels`` texels of the cascade (the larger side) plus ``caster_bias_units`` steps of
    ``depth_format`` over its light-space depth range (:func:`csmlab.storage.polygon_offset_unit`); the
    slope part, ``caster_bias_slope``, is the raster's per triangle.
    """
    return np.array([settings.caster_bias_texels * float(np.max(c.texel_size)) + settings.caster_bias_units
                     * polygon_offset_unit(c.depth_far - c.depth_near, depth_format=settings.depth_format)
                     for c in cascades.cascades], dtype=np.float64)


def _culled_depth_maps(dscene: DeviceScene, cascades: CascadeSet, settings: ShadowSettings, *,
                       previous: RasterizedMaps | None) -> tuple[np.ndarray, int, RasterizedMaps | None, tuple | None]:
    """``(C, R, R)`` depth maps, texels rasterized and, for boxes on whole texels, what the next frame scrolls from
    and each cascade's whole-texel move (:attr:`csmlab.scrolling.ScrollPlan.shifts`).

    Only the chunks of triangles whose light-space rectangle meets a region go to that region's
    rasterization (:func:`csmlab.kernels.raster.region_chunks`); the others cover none of its
    texels. Cascades of unequal size are each rasterized at their own size into the corner of a
    map of the largest, the rest left empty (the lookup never selects a box there, csmlab.filters).
    Boxes whose origins lie on whole texels (exact, quantized) scroll from ``previous``, rasterizing
    only the texels they newly cover and counting those they left (:mod:`csmlab.scrolling`); the
    others are rasterized whole.
    """
    bits = settings.subtexel_bits
    mesh = _scene_in_light_space(dscene, cascades, settings.cull)
    bounds = mesh.bounds
    texel_size = np.stack([c.texel_size for c in cascades.cascades])
    # Box origins in texels (where the chunks' rectangles are measured) and in 2**-bits texels (the
    # fixed point the vertices are snapped to): one origin, named by its unit.
    origin_texels = np.stack([c.origin for c in cascades.cascades])
    origin_fixed = np.stack([fixed_point_origin(cascades, c, bits=bits) for c in range(len(cascades))])
    sizes = [c.resolution for c in cascades.cascades]
    offset = dict(caster_constant=caster_offsets(cascades, settings), caster_slope=settings.caster_bias_slope)

    def rasterized(origin_texels, origin_fixed, regions, **how):
        # Boxes beyond the first C (counted only, stored_cascades) have the texel size and offset of the first C.
        repeat = (len(origin_fixed) // len(sizes), 1)
        size = np.tile(texel_size, repeat)
        if dscene.threads > 1:
            # Each region cut in bands (BANDS_PER_THREAD per thread), which the threads take in turn.
            regions = banded_regions(regions, parts=BANDS_PER_THREAD * dscene.threads, axis=bounds.narrow_axis)
        chunks = region_chunks(bounds, texel_size=size, origin=origin_texels, regions=regions)
        depth, texels = rasterize_cascades(mesh, texel_size=size, origin=origin_fixed, resolution=max(sizes),
                                           bits=bits, regions=regions, chunks=chunks, threads=dscene.threads,
                                           device=dscene.device, caster_constant=np.tile(offset["caster_constant"],
                                                                                         repeat[0]),
                                           caster_slope=offset["caster_slope"], **how)
        return depth, np.bincount(regions[:, 0], weights=texels, minlength=len(origin_fixed)).astype(np.int64)

    if np.any(origin_fixed % (1 << bits)):
        depth, texels = rasterized(origin_texels, origin_fixed, whole_map_regions(sizes))
        return depth, int(texels.sum()), None, None
    plan = scroll_plan(previous, basis=cascades.basis, zref=cascades.zref, bits=bits, texel_size=texel_size,
                       origin=origin_fixed, resolution=sizes, **offset)
    if len(plan.left):
        # The strips the previous boxes left, counted where those boxes lay (scroll_plan keeps only boxes of this
        # texel size and offset), in the same call: as cascades C..2C−1, whose depths are not stored.
        count = len(sizes)
        depth, texels = rasterized(np.concatenate([origin_texels, previous.origin / float(1 << bits)]),
                                   np.concatenate([origin_fixed, previous.origin]),
                                   np.concatenate([plan.regions, plan.left + [count, 0, 0, 0, 0]]),
                                   depth=plan.depth, stored_cascades=count)
        per_cascade = plan.kept_texels + texels[:count] - texels[count:]
    else:
        depth, texels = rasterized(origin_texels, origin_fixed, plan.regions, depth=plan.depth)
        per_cascade = plan.kept_texels + texels
    depth.flags.writeable = False
    raster = RasterizedMaps(basis=cascades.basis, zref=cascades.zref, bits=bits, texel_size=texel_size,
                            origin=origin_fixed, resolution=np.array(sizes), depth=depth, texels=per_cascade,
                            **offset)
    return depth, int(per_cascade.sum()), raster, plan.shifts


def _window_stored_maps(dscene: DeviceScene, cascades: CascadeSet, settings: ShadowSettings, *, span: float,
                        previous) -> tuple[np.ndarray, int, StoredMaps]:
    """``(C, R, R)`` stored maps, texels rasterized and what the next frame reuses, of the window-space path.

    A cascade whose inputs (:func:`_window_cascade_keys`) equal, bit for bit, those of the same
    cascade in ``previous`` (:class:`csmlab.scrolling.StoredMaps`, the method's previous frame) has the
    same stored map and count: they are taken from there (:func:`csmlab.scrolling.reused_cascades`).
    The others, each run of consecutive cascades at once, are rasterized whole
    (:func:`_window_depth_maps`) and stored (:func:`_stored_maps`).
    """
    inputs = _window_inputs(cascades, settings)
    mesh = _scene_in_light_space(dscene, cascades, settings.cull)
    keys = _window_cascade_keys(cascades, settings, span=span, inputs=inputs)
    side = max(c.resolution for c in cascades.cascades)
    reused = reused_cascades(previous, keys, side=side, mesh=mesh)
    if reused.all():
        return previous.depth, int(previous.texels.sum()), previous
    if not reused.any():
        raw, texels = _window_depth_maps(dscene, cascades, settings, inputs=inputs)
        depth = _stored_maps(raw, cascades, settings, span=span)
    else:
        # The kept cascades copied once into this frame's maps, each run of the others rasterized into its place.
        depth = np.empty((len(keys), side, side), dtype=np.float32)
        depth[reused] = previous.depth[reused]
        texels = previous.texels.copy()
        for first, last in _runs(~reused):
            own = depth[first:last]
            for part, cascade in zip(own, cascades.cascades[first:last]):
                part[cascade.resolution:, :] = np.inf
                part[:cascade.resolution, cascade.resolution:] = np.inf
            raw, texels[first:last] = _window_depth_maps(dscene, cascades, settings, inputs=inputs, first=first,
                                                         last=last, depth=own)
            stored = _stored_maps(raw, cascades, settings, span=span, first=first, last=last)
            if stored is not own:
                own[...] = stored
    depth.flags.writeable = False
    return depth, int(texels.sum()), StoredMaps(keys=tuple(keys), depth=depth, texels=texels, mesh=mesh)


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """The runs ``[first, last)`` of consecutive True entries of ``mask`` ``(C,)`` bool, in order."""
    edges = np.flatnonzero(np.diff(np.concatenate([[False], mask, [False]]).astype(np.int8)))
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2])]


def _window_inputs(cascades: CascadeSet, settings: ShadowSettings) -> dict | None:
    """The window transform of every cascade (:func:`csmlab.texels.window_box_inputs`); None on the global grid."""
    if uses_global_grid(precision=settings.engine_precision, snap=settings.vertex_snap):
        return None
    return window_box_inputs(cascades, bits=settings.subtexel_bits, precision=settings.engine_precision,
                             snap=settings.vertex_snap, rebase_distance=settings.rebase_distance)


def _window_cascade_keys(cascades: CascadeSet, settings: ShadowSettings, *, span: float,
                         inputs: dict | None) -> list[bytes]:
    """Each cascade's inputs to :func:`_window_depth_maps` and :func:`_stored_maps`, bit for bit, as bytes.

    The settings those read, the light space and ``span``; each cascade's resolution, texel size,
    box origin (in texels and in fixed point), near and far side, caster offset, and its rows of the
    window transform ``inputs`` (:func:`csmlab.texels.window_box_inputs`: an engine's float32 matrix,
    with the shared rebase origin). The scene itself, its casters and cull are the light-space mesh,
    compared by identity (:func:`csmlab.scrolling.reused_cascades`).
    """
    bits = settings.subtexel_bits
    shared = repr((settings.blend_casters, settings.cull, bits, settings.engine_precision, settings.vertex_snap,
                   settings.caster_bias_slope, settings.depth_range, settings.depth_clamp,
                   settings.depth_quantization, settings.depth_format, span, cascades.zref,
                   None if inputs is None else (inputs["mode"], inputs["bits"])))
    shared = shared.encode() + np.ascontiguousarray(cascades.basis, dtype=np.float64).tobytes()
    if inputs is not None and "origin" in inputs:
        shared += np.asarray(inputs["origin"], dtype=np.float64).tobytes()
    offsets = caster_offsets(cascades, settings)
    keys = []
    for c, cascade in enumerate(cascades.cascades):
        rows = [np.array([cascade.resolution], dtype=np.int64), np.asarray(cascade.texel_size, dtype=np.float64),
                np.asarray(cascade.origin, dtype=np.float64), fixed_point_origin(cascades, c, bits=bits),
                np.array([cascade.depth_near, cascade.depth_far, offsets[c]], dtype=np.float64)]
        if inputs is not None:
            rows += [np.asarray(value[c]) for name, value in inputs.items() if name in WINDOW_BOX_ROWS]
        keys.append(shared + b"".join(np.ascontiguousarray(row).tobytes() for row in rows))
    return keys


def _window_depth_maps(dscene: DeviceScene, cascades: CascadeSet, settings: ShadowSettings, *, inputs: dict | None,
                       first: int = 0, last: int | None = None,
                       depth: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``(C', R, R)`` depth maps and ``(C',)`` texels rasterized of unwarped cascades ``[first, last)`` the scrolling
    path does not model (R the largest cascade's side), into ``depth`` where given (as
    :func:`csmlab.kernels.raster.rasterize_cascades`: each cascade's own ``R_c²`` texels overwritten,
    the rest kept).

    An engine's float32 pipeline (``engine_precision``), window-space snapping (``vertex_snap``),
    and casters clipped at a slice's near side without pancaking (``depth_range`` that cuts casters,
    ``depth_clamp = false``): the scene's light-space mesh (:func:`_scene_in_light_space`) taken into
    every cascade's window space on the device (:func:`csmlab.kernels.engine.window_vertices`, the
    boxes of ``inputs``, :func:`csmlab.texels.window_box_inputs`) where the pipeline is not the global
    grid's (``inputs`` None), then rasterized whole map by map, cut into bands for the threads, only
    the chunks that reach a region (:func:`csmlab.kernels.raster.converted_region_chunks`, or
    :func:`~csmlab.kernels.raster.region_chunks` on the global grid). A float32 pipeline takes into a
    cascade only the vertices of the chunks whose world box, bounded in window space with the
    pipeline's roundings (:func:`csmlab.texels.window_rectangles`), may reach one of its regions
    (:func:`csmlab.kernels.engine.window_chunk_vertices`, which finds their exact rectangles too):
    on the terrain, 5–40 % of the chunks a cascade, the others never read. The same maps and counts,
    bit for bit, as the host's :func:`host_depth_maps` (the tests' oracle); no scrolling (the float32
    roundings change as a box moves).
    """
    bits = settings.subtexel_bits
    mesh = _scene_in_light_space(dscene, cascades, settings.cull)
    side = max(c.resolution for c in cascades.cascades)
    boxes = cascades.cascades[first:last]
    regions = whole_map_regions([c.resolution for c in boxes])
    if dscene.threads > 1:
        regions = banded_regions(regions, parts=BANDS_PER_THREAD * dscene.threads, axis=mesh.bounds.narrow_axis)
    texel_size = np.stack([c.texel_size for c in boxes])
    origin_fixed = np.stack([fixed_point_origin(cascades, c, bits=bits) for c in range(len(cascades))][first:last])
    how = dict(caster_constant=caster_offsets(cascades, settings)[first:last], caster_slope=settings.caster_bias_slope,
               threads=dscene.threads, device=dscene.device)
    if DEPTH_RANGE_METHODS[settings.depth_range].cuts_casters and not settings.depth_clamp:
        how["near"] = np.array([c.depth_near - cascades.zref for c in boxes])
    if inputs is None:
        chunks = region_chunks(mesh.bounds, texel_size=texel_size, origin=np.stack([c.origin for c in boxes]),
                               regions=regions)
    elif inputs["mode"] == "float32":
        key = (cascades.basis.tobytes(), cascades.zref, settings.cull)
        ordered = dscene.ordered_vertices[key]
        sliced = window_box_slice(inputs, first=first, last=last)
        # Only the chunks a bound of their window rectangle lets reach a region, and their vertices, go through
        # the float32 pipeline; their exact rectangles then choose among them.
        reaching = chunks_meeting_regions(*window_rectangles(sliced, *_chunk_world_boxes(dscene, key, mesh)),
                                          regions=regions, bits=bits)
        alive = np.zeros((len(boxes), mesh.chunk_vertices.starts.size - 1), dtype=bool)
        alive[regions[reaching[:, 0], 0], reaching[:, 1]] = True
        pairs = np.argwhere(alive)
        how["points"], how["vertex_depth"], low, high = window_chunk_vertices(
            uploaded_boxes(sliced, device=dscene.device), positions=ordered, vertices=mesh.chunk_vertices,
            pairs=pairs, threads=dscene.threads, device=dscene.device)
        chunks = chunks_meeting_regions(low, high, regions=regions, bits=bits)
    else:
        key = (cascades.basis.tobytes(), cascades.zref, settings.cull)
        how["points"], how["vertex_depth"] = window_vertices(uploaded_boxes(inputs, first=first, last=last,
                                                                            device=dscene.device),
                                                             positions=dscene.ordered_vertices[key],
                                                             light_xy=mesh.xy, light_depth=mesh.depth,
                                                             threads=dscene.threads, device=dscene.device)
        chunks = converted_region_chunks(how["points"], mesh.chunk_vertices, regions=regions, bits=bits,
                                         device=dscene.device)
    depth, texels = rasterize_cascades(mesh, texel_size=texel_size, origin=origin_fixed, resolution=side,
                                       bits=bits, regions=regions, chunks=chunks, depth=depth, **how)
    return depth, np.bincount(regions[:, 0], weights=texels, minlength=len(boxes)).astype(np.int64)


def host_depth_maps(dscene: DeviceScene, cascades: CascadeSet, settings: ShadowSettings) -> tuple[np.ndarray, int]:
    """``(C, R, R)`` depth maps and texels rasterized, vertices snapped on the host cascade by cascade.

    The reference NumPy pipeline, stated as plainly as the engines do it: every vertex converted by
    :mod:`csmlab.texels` (an engine's float32 pipeline, its depth per cascade from the float32 window
    depth, ``engine_precision``; snapping of the window position, ``vertex_snap``), casters clipped at
    a slice's near side without pancaking (``depth_range`` that cuts casters, ``depth_clamp = false``)
    by :func:`clipped_casters`, each cascade's whole map rasterized over every triangle on one thread.
    Perspective-warped cascades (``warp``) by :func:`warped_depth_map`. Not a production path: the
    tests' oracle for the kernels' (:func:`_window_depth_maps`, :func:`_warped_window_depth_maps`,
    which give the same maps and counts bit for bit). Faces are culled as on the other paths
    (``settings.cull``, once per call, by ``d`` alone).
    """
    dscene = caster_scene(dscene, settings.blend_casters)
    bits = settings.subtexel_bits
    vertices = dscene.scene.vertices
    depth_of_vertex = light_depth(cascades, vertices)
    sizes = [c.resolution for c in cascades.cascades]
    maps = np.full((len(sizes), max(sizes), max(sizes)), np.inf, dtype=np.float32)
    texels = 0
    kept = culled_triangles(vertices, dscene.scene.triangles, cascades.direction, settings.cull)
    offsets = caster_offsets(cascades, settings)
    for c, cascade in enumerate(cascades.cascades):
        triangles = kept
        if DEPTH_RANGE_METHODS[settings.depth_range].cuts_casters and not settings.depth_clamp:
            triangles = clipped_casters(depth_of_vertex, triangles, near=cascade.depth_near - cascades.zref)
        if triangles.shape[0] == 0:
            continue
        if cascade.warp is not None:
            one, count = warped_depth_map(cascades, c, vertices, depth_of_vertex, triangles, bits=bits,
                                          scene=dscene.scene, caster_constant=float(offsets[c]),
                                          caster_slope=settings.caster_bias_slope, device=dscene.device)
            maps[c, :sizes[c], :sizes[c]] = one
            texels += count
            continue
        how = {"precision": settings.engine_precision, "rebase_distance": settings.rebase_distance}
        points = fixed_point_coordinates(cascades, c, vertices, bits=bits, snap=settings.vertex_snap, **how)
        one, count = rasterize_depth(points[None], vertex_depth(cascades, c, vertices, **how), triangles,
                                     resolution=sizes[c], bits=bits, masks=dscene.bvh.masks,
                                     caster_constant=offsets[c:c + 1], caster_slope=settings.caster_bias_slope,
                                     device=dscene.device)
        maps[c, :sizes[c], :sizes[c]] = one[0]
        texels += count
    return maps, texels


def warped_depth_map(cascades: CascadeSet, index: int, vertices: np.ndarray, depth: np.ndarray,
                     triangles: np.ndarray, *, bits: int, scene: Scene | None = None, caster_constant: float = 0.0,
                     caster_slope: float = 0.0, device: str) -> tuple[np.ndarray, int]:
    """``(R, R)`` depth map and texels rasterized of warped cascade ``index`` (:mod:`csmlab.cascades.warp`).

    Its projection (:meth:`csmlab.cascades.CascadeSet.projection`) takes a vertex to texels
    ``(i, j)`` and ``z / w``, which is affine across the warped image of a triangle (a projective
    map keeps planes planar): the rasterizer interpolates ``z / w`` at texel centres, and each
    texel's value times that centre's ``w`` is the light depth ``d·X − zref`` in metres of the
    surface its ray meets. Triangles are first clipped to ``w ≥ n_opt / 2`` (half the warp's near
    distance: what they lose lies below the map's edge, ``w < n_opt``), as a GPU clips at the warp
    eye's near plane.

    A caster's polygon offset acts as a GPU's does on a warped map: its slope part on the
    interpolated ``z / w`` (the warped depth's change over a texel), its constant part in metres
    on the stored light depth. Alpha masks are tested at texture coordinates interpolated across
    the warped image (affine there, not perspective-correct: a small error inside a card).

    Parameters
    ----------
    cascades : CascadeSet
    index : int
    vertices : ndarray, shape (V, 3)
        World positions, metres.
    depth : ndarray, shape (V,)
        Their light depths ``d·X − zref``, metres.
    triangles : ndarray, shape (T, 3)
    bits : int
        Sub-texel bits.
    scene : Scene, optional
        Whose ``uv``, ``vertex_mask`` and ``alpha`` (in the order of ``vertices``) cut its masked
        casters; None or unmasked: every caster opaque.
    caster_constant : float
        Metres every caster is pushed away from the light (:func:`caster_offsets`).
    caster_slope : float
        ``caster_bias_slope``.
    device : str
    """
    cascade = cascades.cascades[index]
    h = cascade.warp.homography
    xy = light_plane_coordinates(cascades, vertices)
    w = xy[:, 0] * h[2, 0] + xy[:, 1] * h[2, 1] + h[2, 2]
    near = 0.5 * (cascade.warp.n_opt if np.isfinite(cascade.warp.n_opt) else 1.0)
    masked = scene is not None and scene.vertex_mask is not None
    columns = [xy, depth, w] + ([scene.uv, scene.vertex_mask.astype(np.float64)] if masked else [])
    attributes, kept = clipped_triangles(np.column_stack(columns), triangles, column=3, threshold=near)
    if kept.shape[0] == 0:
        return np.full((cascade.resolution,) * 2, np.inf, dtype=np.float32), 0
    texels, w = warped_texels(h, attributes[:, :2])
    points = np.rint(np.clip(texels * float(2**bits), -2.0**50, 2.0**50)).astype(np.int64)
    # A triangle's three vertices share its mask, so the interpolated mask column is that mask exactly.
    masks = masked_mesh(attributes[:, 4:6], attributes[:, 6].astype(np.int32), scene.alpha,
                        device=device) if masked else None
    per_w, count = rasterize_depth(points[None], attributes[:, 2] / w, kept, resolution=cascade.resolution,
                                   bits=bits, masks=masks, caster_slope=caster_slope, device=device)
    return _unwarped_depth(per_w[0], h, caster_constant), count


def _unwarped_depth(per_w: np.ndarray, homography: np.ndarray, caster_constant: float) -> np.ndarray:
    """``(R, R)`` float32 light depths in metres of a warped map's interpolated ``z / w`` ``(R, R)``, pushed away
    from the light by ``caster_constant`` metres: each texel's value times its centre's ``w``."""
    centre = np.arange(per_w.shape[0], dtype=np.float64) + 0.5
    i, j = np.meshgrid(centre, centre)
    inverse = np.linalg.inv(homography)
    w_centre = 1.0 / (inverse[2, 0] * i + inverse[2, 1] * j + inverse[2, 2])
    return (per_w.astype(np.float64) * w_centre + caster_constant).astype(np.float32)


def _warped_window_depth_maps(dscene: DeviceScene, cascades: CascadeSet,
                              settings: ShadowSettings) -> tuple[np.ndarray, int]:
    """``(C, R, R)`` depth maps and texels rasterized of perspective-warped cascades (``warp``) on the kernels' path.

    :func:`warped_depth_map`'s maps and counts bit for bit: the scene's light-space mesh clipped at
    half the warp's near distance (:func:`clipped_triangles`, on the host: few triangles cross it),
    its vertices taken through the homography on the device (:func:`csmlab.kernels.engine.warped_vertices`),
    and the map rasterized cut into bands for the threads, only the chunks that reach a band
    (:func:`csmlab.kernels.raster.converted_region_chunks`). An unwarped cascade of the set takes
    :func:`_window_depth_maps`' or the scrolling path's arithmetic, cascade by cascade as the host does.
    """
    bits = settings.subtexel_bits
    mesh = _scene_in_light_space(dscene, cascades, settings.cull)
    sizes = [c.resolution for c in cascades.cascades]
    maps = np.full((len(sizes), max(sizes), max(sizes)), np.inf, dtype=np.float32)
    offsets = caster_offsets(cascades, settings)
    triangles = mesh.triangles
    texels = 0
    for c, cascade in enumerate(cascades.cascades):
        kept = triangles
        if DEPTH_RANGE_METHODS[settings.depth_range].cuts_casters and not settings.depth_clamp:
            kept = clipped_casters(mesh.depth, triangles, near=cascade.depth_near - cascades.zref)
        if kept.shape[0] == 0:
            continue
        if cascade.warp is None:
            one = CascadeSet(basis=cascades.basis, zref=cascades.zref, splits=cascades.splits[c:c + 2],
                             cascades=(cascade,), margin_texels=cascades.margin_texels, eye=cascades.eye)
            depth, count = _window_depth_maps(dscene, one, settings, inputs=_window_inputs(one, settings))
            count = int(count[0])
        else:
            depth, count = _warped_map(dscene, mesh, kept, cascade, bits=bits, caster_constant=float(offsets[c]),
                                       caster_slope=settings.caster_bias_slope)
        maps[c, :sizes[c], :sizes[c]] = depth[0] if depth.ndim == 3 else depth
        texels += count
    return maps, texels


def _warped_map(dscene: DeviceScene, mesh: LightSpaceMesh, triangles: np.ndarray, cascade, *, bits: int,
                caster_constant: float, caster_slope: float) -> tuple[np.ndarray, int]:
    """``(R, R)`` depth map and texels rasterized of one warped cascade from the mesh's ``triangles`` ``(T, 3)``."""
    h = cascade.warp.homography
    xy = mesh.xy
    w = xy[:, 0] * h[2, 0] + xy[:, 1] * h[2, 1] + h[2, 2]
    near = 0.5 * (cascade.warp.n_opt if np.isfinite(cascade.warp.n_opt) else 1.0)
    masked = mesh.vertex_mask is not None
    columns = [xy, mesh.depth, w] + ([mesh.uv, mesh.vertex_mask.astype(np.float64)] if masked else [])
    attributes, kept = clipped_triangles(np.column_stack(columns), triangles, column=3, threshold=near)
    if kept.shape[0] == 0:
        return np.full((cascade.resolution,) * 2, np.inf, dtype=np.float32), 0
    points, per_w = warped_vertices(h, attributes[:, :2], attributes[:, 2], bits=bits, device=dscene.device)
    # A triangle's three vertices share its mask, so the interpolated mask column is that mask exactly.
    masks = dict(uv=attributes[:, 4:6], vertex_mask=attributes[:, 6].astype(np.int32), alpha=mesh.alpha) if masked \
        else {}
    clipped = light_space_mesh(attributes[:, :2], attributes[:, 2], kept, **masks)
    regions = whole_map_regions([cascade.resolution])
    if dscene.threads > 1:
        regions = banded_regions(regions, parts=BANDS_PER_THREAD * dscene.threads, axis=mesh.bounds.narrow_axis)
    chunks = converted_region_chunks(points[None], chunk_vertices(kept, distinct=False), regions=regions, bits=bits,
                                     device=dscene.device)
    per_w_map, count = rasterize_cascades(clipped, texel_size=np.ones((1, 2)), origin=np.zeros((1, 2), np.int64),
                                          resolution=cascade.resolution, bits=bits, regions=regions, chunks=chunks,
                                          points=points[None], vertex_depth=per_w[None], caster_slope=caster_slope,
                                          threads=dscene.threads, device=dscene.device)
    return _unwarped_depth(per_w_map[0], h, caster_constant), int(count.sum())


def clipped_triangles(attributes: np.ndarray, triangles: np.ndarray, *, column: int,
                      threshold: float) -> tuple[np.ndarray, np.ndarray]:
    """Triangles clipped to the half-space ``attributes[:, column] ≥ threshold`` (one Sutherland–Hodgman plane).

    Parameters
    ----------
    attributes : ndarray, shape (V, K)
        Per-vertex values, affine in space (positions, depths), interpolated along clipped edges.
    triangles : ndarray, shape (T, 3)
    column : int
        The attribute clipped against.
    threshold : float

    Returns
    -------
    attributes : ndarray, shape (V', K)
        The input rows, then the new vertices where edges cross the plane.
    triangles : ndarray, shape (T', 3)
        Whole triangles inside, then one per triangle with one vertex inside and two per triangle
        with two (either winding kept).
    """
    value = attributes[:, column]
    inside = value[triangles] >= threshold
    count = inside.sum(axis=1)
    whole = triangles[count == 3]

    def rotated(which, first):
        k = first[which]
        t = triangles[which]
        r = np.arange(t.shape[0])
        return t[r, k], t[r, (k + 1) % 3], t[r, (k + 2) % 3]

    def crossing(p, q):
        vp, vq = value[p], value[q]
        t = (threshold - vp) / (vq - vp)
        return attributes[p] + t[:, None] * (attributes[q] - attributes[p])

    one = count == 1
    a, b, c = rotated(one, np.argmax(inside, axis=1))
    ab, ac = crossing(a, b), crossing(a, c)
    two = count == 2
    a2, b2, c2 = rotated(two, (np.argmin(inside, axis=1) + 1) % 3)
    bc2, ac2 = crossing(b2, c2), crossing(a2, c2)
    base = attributes.shape[0]
    m, n = a.shape[0], a2.shape[0]
    new = np.vstack([attributes, ab, ac, bc2, ac2])
    i_ab = base + np.arange(m)
    i_ac = i_ab + m
    i_bc2 = base + 2 * m + np.arange(n)
    i_ac2 = i_bc2 + n
    clipped = np.vstack([whole, np.column_stack([a, i_ab, i_ac]), np.column_stack([a2, b2, i_bc2]),
                         np.column_stack([a2, i_bc2, i_ac2])]).astype(triangles.dtype)
    return new, clipped


def clipped_casters(depth: np.ndarray, triangles: np.ndarray, *, near: float) -> np.ndarray:
    """Triangles ``(T', 3)`` a box whose near side lies at stored depth ``near`` keeps without pancaking.

    Those wholly nearer than ``near`` (every vertex depth below it) are clipped away; one that
    crosses the near side is kept whole (a GPU would keep only its part behind the plane).
    """
    return triangles[depth[triangles].max(axis=1) >= near]


def virtual_shadow_maps(dscene: DeviceScene, view: View, settings: ShadowSettings, *,
                        previous: ShadowMaps | None = None, light_direction=None) -> ShadowMaps:
    """A virtual clipmap's resident pages for one view (``shadow_map = "virtual_clipmap"``, :mod:`csmlab.clipmaps`).

    The levels are placed around the camera, every visible pixel of the view's G-buffer marks the
    pages under its taps at its level, and the pages the pool keeps are taken from ``previous`` (the
    same method's previous maps) where it holds them under the same light, the others rasterized,
    each as a map of its own (:func:`_rasterized_pages`). ``light_direction`` ``(3,)``: the shadow's
    light (a sun policy's, :mod:`csmlab.shadow_policies`); None: the view's.

    Returns
    -------
    ShadowMaps
        ``depth`` ``(P, page_size, page_size)`` in the order of ``pages.keys``; ``cascades`` one box
        per level; ``texels_rasterized`` the coverage tests that passed in the pages rasterized this
        frame (the cache misses: the work the frame did).
    """
    g = view.gbuffer
    d = view.light_direction if light_direction is None else normalized(light_direction, name="light direction")
    basis = light_basis(d)
    # The depth offset as build_cascades takes it, bit for bit: the scene's light-space mesh is kept per
    # (basis, zref), so cascades and a clipmap of one light share it.
    scene_depth = (np.asarray(dscene.corners, dtype=np.float64).reshape(-1, 3) @ basis.T)[:, 2]
    clip = clipmap_levels(eye=view.pose.position, light_direction=d,
                          zref=float(scene_depth.min()), footprint=footprint_scale(view.pose, height=g.shape[0]),
                          settings=settings)
    cascades = clipmap_cascades(clip, scene_depth=(float(scene_depth.min()), float(scene_depth.max())),
                                margin=settings.margin_texels)
    valid = g.valid
    points = g.position[valid]
    marked = marked_pages(clip, light_space(points, basis), light_space(g.normal[valid], basis),
                          wanted_levels(clip, points), settings=settings, radius=clipmap_radius(settings))
    keys = resident_pages(marked, pool=settings.physical_pages)
    cache = page_cache(keys, clip, None if previous is None else previous.pages)
    side = settings.page_size
    span = float(np.ptp(scene_depth))
    depth = np.empty((len(keys), side, side), dtype=np.float32)
    if cache.kept.any():
        depth[cache.kept] = previous.depth[cache.source[cache.kept]]
    texels = 0
    missed = ~cache.kept
    if missed.any():
        fresh, texels = _rasterized_pages(dscene, cascades, clip.texel, keys[missed], settings)
        depth[missed] = stored_depth(fresh, span=span, depth_format=settings.depth_format)
    depth.flags.writeable = False
    pages = VirtualPages(clipmap=clip, keys=keys, table=page_table(clip, keys), marked=len(marked),
                         rendered=int(missed.sum()), resident_bytes=pool_bytes(len(keys), settings))
    return ShadowMaps(cascades=cascades, depth=depth, texels_rasterized=texels, depth_span=span, pages=pages)


def _rasterized_pages(dscene: DeviceScene, cascades: CascadeSet, texel: np.ndarray, keys: np.ndarray,
                      settings: ShadowSettings) -> tuple[np.ndarray, int]:
    """``(M, S, S)`` depths of the pages ``keys`` ``(M, 3)`` (level, global page x, y) and the texels rasterized.

    Each page is a map of its own for the cascades' rasterizer: its level's texel size and its
    corner, a whole page of texels, as origin. Its texels are then those of the level's global grid,
    with the same fixed-point vertices wherever the page lies (:mod:`csmlab.kernels.raster`).
    """
    dscene = caster_scene(dscene, settings.blend_casters)
    side = settings.page_size
    bits = settings.subtexel_bits
    mesh = _scene_in_light_space(dscene, cascades, settings.cull)
    texel_size = np.repeat(texel[keys[:, 0]][:, None], 2, axis=1)
    origin = keys[:, 1:] * side
    regions = whole_map_regions([side] * len(keys))
    chunks = region_chunks(mesh.bounds, texel_size=texel_size, origin=origin, regions=regions)
    depth, texels = rasterize_cascades(mesh, texel_size=texel_size, origin=origin << bits, resolution=side, bits=bits,
                                       regions=regions, chunks=chunks, threads=dscene.threads, device=dscene.device)
    return depth, int(texels.sum())


def render_shadow(dscene: DeviceScene, view: View, settings: ShadowSettings, *,
                  visible_depth: tuple[float, float] | None = None, held_extents=None, lookup: bool = True,
                  scroll_from: ShadowMaps | None = None, light_direction=None) -> Frame:
    """One shadow method on a shared view: cascades → depth maps → lookup at every pixel.

    With ``bounds = "sdsm"`` the splits divide ``visible_depth`` when given (the held range of an
    SDSM with hysteresis), else the view's own G-buffer depth range. ``held_extents`` ``(C, 2)``:
    the tight boxes' sizes held by extent hysteresis this frame (``stabilization = "none"``).
    ``lookup = False`` stops after the depth maps (``Frame.shadow`` None): all the temporal
    metrics read of a previous frame. ``scroll_from``: the same method's previous maps, whose texels
    the boxes still cover are copied instead of rasterized (:mod:`csmlab.scrolling`; the same maps).
    With ``shadow_map = "virtual_clipmap"`` the maps are a clipmap's pages (:func:`virtual_shadow_maps`),
    ``scroll_from`` its page cache, and the split, fit and stabilization fields are not read.
    ``light_direction`` ``(3,)``: the light the shadow maps are built with when a sun policy holds or
    quantizes it (:func:`csmlab.shadow_policies.shadow_light_direction`); None: the view's, which the
    shading and the reference use.

    Returns
    -------
    Frame
        ``timings`` holds ``cascades`` (not for a clipmap, whose level placement and page marking
        count in ``raster``), ``raster`` (and ``shadow``) in seconds.
    """
    settings = settings.validated()
    start = time.perf_counter()
    if settings.shadow_map == "virtual_clipmap":
        maps = virtual_shadow_maps(dscene, view, settings, previous=scroll_from, light_direction=light_direction)
        timings = {"raster": time.perf_counter() - start}
    else:
        maps, timings = _cascaded_shadow_maps(dscene, view, settings, visible_depth=visible_depth,
                                              held_extents=held_extents, scroll_from=scroll_from,
                                              light_direction=light_direction)
    if not lookup:
        return Frame(view=view, settings=settings, maps=maps, shadow=None, timings=timings)
    start = time.perf_counter()
    g = view.gbuffer
    quads = quad_view_depth = None
    if maps.mips is not None:
        quads = quad_lanes(view.pose, g.position, g.normal, width=g.shape[1], height=g.shape[0])
        quad_view_depth = view.pose.view_depth(quads.position)
    shadow = lookup_shadow(maps, points=g.position, normals=g.normal, view_depth=g.view_depth, settings=settings,
                           quads=quads, quad_view_depth=quad_view_depth,
                           noise_frame=noise_frame(settings, frame=view.index, taa=view.jitter is not None),
                           rows=view.shared(("receiver_rows",), lambda: receiver_rows(g.position, g.view_depth)),
                           device=dscene.device)
    timings["shadow"] = time.perf_counter() - start
    return Frame(view=view, settings=settings, maps=maps, shadow=shadow, timings=timings)


def _cascaded_shadow_maps(dscene: DeviceScene, view: View, settings: ShadowSettings, *, visible_depth, held_extents,
                          scroll_from: ShadowMaps | None, light_direction=None) -> tuple[ShadowMaps, dict]:
    """:func:`render_shadow`'s cascades and depth maps, and the seconds of each (``cascades``, ``raster``)."""
    start = time.perf_counter()
    if BOUNDS_METHODS[settings.bounds].visible and visible_depth is None:
        visible_depth = visible_depth_range(view.gbuffer.view_depth)
    cascades = build_cascades(pose=view.pose,
                              light_direction=view.light_direction if light_direction is None else light_direction,
                              scene_corners=dscene.corners, settings=settings, visible_depth=visible_depth,
                              held_extents=held_extents)
    timings = {"cascades": time.perf_counter() - start}
    start = time.perf_counter()
    maps = shadow_maps(dscene, cascades, settings, scroll_from=scroll_from)
    timings["raster"] = time.perf_counter() - start
    return maps, timings


def render_frame(scene_or_dscene: Scene | DeviceScene, pose: CameraPose, light_direction,
                 settings: ShadowSettings, *, width: int, height: int, device: str = "cpu") -> Frame:
    """A whole frame of one method: :func:`render_view` then :func:`render_shadow`.

    A :class:`Scene` is uploaded to ``device`` first; a :class:`DeviceScene` is used as it is
    (its own device wins).
    """
    dscene = scene_or_dscene if isinstance(scene_or_dscene, DeviceScene) else prepare_scene(scene_or_dscene,
                                                                                            device=device)
    view = render_view(dscene, pose, light_direction, width=width, height=height)
    return render_shadow(dscene, view, settings)
