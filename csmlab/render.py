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
from dataclasses import dataclass, field

import numpy as np

from csmlab.camera import CameraPose
from csmlab.culling import culled_triangles
from csmlab.cascades import CascadeSet, build_cascades
from csmlab.cascades.bounds import BOUNDS_METHODS, DEPTH_RANGE_METHODS, visible_depth_range
from csmlab.filters import filter_inputs, lookup_shadow, noise_frame
from csmlab.frame import Frame, GBuffer, ShadowMaps, View
from csmlab.geometry import normalized
from csmlab.kernels.raster import (BANDS_PER_THREAD, LightSpaceMesh, banded_regions, light_space_mesh,
                                  rasterize_cascades, rasterize_depth, region_chunks, whole_map_regions, z_ordered)
from csmlab.kernels.reference import hard_shadow
from csmlab.kernels.threads import checked_threads
from csmlab.kernels.visibility import MeshBVH, camera_hits, mesh_bvh
from csmlab.quads import quad_lanes
from csmlab.scene.core import Scene
from csmlab.scrolling import RasterizedMaps, scroll_plan
from csmlab.settings import ShadowSettings
from csmlab.storage import stored_depth
from csmlab.texels import (PRECISION_METHODS, fixed_point_coordinates, fixed_point_origin, light_depth,
                           light_plane_coordinates)

__all__ = ["DeviceScene", "clipped_casters", "lookup_shadow", "prepare_scene", "render_frame", "render_shadow",
           "render_view", "shadow_maps", "visible_depth"]


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
        The scene in the light space of the last light direction seen (what the cascade pass
        needs of every vertex and triangle, which a static light leaves unchanged from frame to
        frame), keyed by the light basis, its depth offset and the face cull (``settings.cull``).
    threads : int
        CPU threads a frame's kernels may use at once (one Warp CPU launch runs on one thread):
        1 where processes already share out the cores (:mod:`csmlab.executor`).
    """

    scene: Scene
    bvh: MeshBVH
    device: str
    corners: np.ndarray = field(compare=False, repr=False)
    light_space: dict = field(default_factory=dict, compare=False, repr=False)
    threads: int = 1


def prepare_scene(scene: Scene, *, device: str = "cpu", threads: int = 1) -> DeviceScene:
    """Upload ``scene`` to ``device`` (``"cpu"`` or ``"cuda"``) and build its BVH; ``threads`` as :class:`DeviceScene`."""
    return DeviceScene(scene=scene, bvh=mesh_bvh(scene.vertices, scene.triangles, device=device), device=device,
                       corners=scene.corners(), threads=checked_threads(threads, device))


def render_view(dscene: DeviceScene, pose: CameraPose, light_direction, *, width: int, height: int,
                index: int = 0, previous_light_direction=None, reference: bool = True, jitter=None) -> View:
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
    valid = hits.triangle >= 0
    albedo = np.where(valid[..., None], dscene.scene.albedo[np.maximum(hits.triangle, 0)], np.float32(0.0))
    gbuffer = GBuffer(hits=hits, albedo=albedo.astype(np.float32))
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
                jitter=None if jitter is None else (float(jitter[0]), float(jitter[1])))


def _scene_in_light_space(dscene: DeviceScene, cascades: CascadeSet, cull: str = "none") -> LightSpaceMesh:
    """The scene as the depth pass reads it (light-space x/y and depth of vertices, triangles), made once per light.

    Only the triangles ``cull`` keeps (:func:`csmlab.culling.culled_triangles`, judged by ``d``
    alone) are handed on, listed with their vertices along a Z-order curve in light space
    (:func:`csmlab.kernels.raster.z_ordered`): the same mesh, rasterized place by place. Meshes of
    the same light under other culls are kept beside it; another light's are dropped.
    """
    light = (cascades.basis.tobytes(), cascades.zref)
    key = (*light, cull)
    if key not in dscene.light_space:
        vertices = dscene.scene.vertices
        xy = light_plane_coordinates(cascades, vertices)
        order, triangles = z_ordered(xy, culled_triangles(vertices, dscene.scene.triangles, cascades.direction, cull))
        for other in [k for k in dscene.light_space if k[:2] != light]:
            del dscene.light_space[other]
        dscene.light_space[key] = light_space_mesh(xy[order], light_depth(cascades, vertices)[order], triangles)
    return dscene.light_space[key]


def visible_depth(dscene: DeviceScene, pose: CameraPose, *, width: int, height: int) -> tuple[float, float] | None:
    """The view-depth range ``(z_min, z_max)`` in metres of the G-buffer :func:`render_view` would make (SDSM)."""
    hits = camera_hits(dscene.bvh, position=pose.position, rotation=pose.rotation, fov_y_deg=pose.fov_y_deg,
                       aspect=pose.aspect, far=pose.far, width=width, height=height, threads=dscene.threads)
    return visible_depth_range(hits.view_depth)


def shadow_maps(dscene: DeviceScene, cascades: CascadeSet, settings: ShadowSettings, *,
                scroll_from: ShadowMaps | None = None) -> ShadowMaps:
    """Rasterize every cascade's depth map from the scene's vertices in fixed point, stored in ``settings.depth_format``.

    Pancaked slice boxes (``depth_range = "slice"``) are clamped to their near side; the moments
    and their mips follow when the filter reads them (:func:`csmlab.filters.filter_inputs`). ``scroll_from``, the
    same method's previous maps, lends the texels its boxes already covered (:mod:`csmlab.scrolling`):
    the same maps, less rasterization.
    """
    raster = None
    cut = DEPTH_RANGE_METHODS[settings.depth_range].cuts_casters
    if PRECISION_METHODS[settings.engine_precision].global_grid and not (cut and not settings.depth_clamp):
        depth, texels, raster = _culled_depth_maps(dscene, cascades, settings,
                                                   previous=None if scroll_from is None else scroll_from.raster)
    else:
        depth, texels = _host_snapped_depth_maps(dscene, cascades, settings)
    if cut and settings.depth_clamp:
        # Pancaking is a per-fragment clamp max(z, near); the stored minimum of clamped fragments
        # is the clamped minimum, so clamping the map is exact.
        near = np.array([c.depth_near - cascades.zref for c in cascades.cascades], dtype=np.float32)
        depth = np.maximum(depth, near[:, None, None])
    span = float(np.ptp(cascades.to_light(dscene.corners)[:, 2]))
    depth = stored_depth(depth, span=span, depth_format=settings.depth_format)
    moments, mips = filter_inputs(depth, cascades, span=span, settings=settings, device=dscene.device)
    return ShadowMaps(cascades=cascades, depth=depth, texels_rasterized=texels, moments=moments, depth_span=span,
                      mips=mips, raster=raster)


def _culled_depth_maps(dscene: DeviceScene, cascades: CascadeSet, settings: ShadowSettings, *,
                       previous: RasterizedMaps | None) -> tuple[np.ndarray, int, RasterizedMaps | None]:
    """``(C, R, R)`` depth maps, texels rasterized and, for boxes on whole texels, what the next frame scrolls from.

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

    def rasterized(origin_texels, origin_fixed, regions, **how):
        if dscene.threads > 1:
            # Each region cut in bands (BANDS_PER_THREAD per thread), which the threads take in turn.
            regions = banded_regions(regions, parts=BANDS_PER_THREAD * dscene.threads, axis=bounds.narrow_axis)
        chunks = region_chunks(bounds, texel_size=texel_size, origin=origin_texels, regions=regions)
        depth, texels = rasterize_cascades(mesh, texel_size=texel_size, origin=origin_fixed, resolution=max(sizes),
                                           bits=bits, regions=regions, chunks=chunks, threads=dscene.threads,
                                           device=dscene.device, **how)
        return depth, np.bincount(regions[:, 0], weights=texels, minlength=len(sizes)).astype(np.int64)

    if np.any(origin_fixed % (1 << bits)):
        depth, texels = rasterized(origin_texels, origin_fixed, whole_map_regions(sizes))
        return depth, int(texels.sum()), None
    plan = scroll_plan(previous, basis=cascades.basis, zref=cascades.zref, bits=bits, texel_size=texel_size,
                       origin=origin_fixed, resolution=sizes)
    depth, texels = rasterized(origin_texels, origin_fixed, plan.regions, depth=plan.depth)
    per_cascade = plan.kept_texels + texels
    if len(plan.left):
        # Counted where the previous boxes lay (scroll_plan keeps only boxes of this texel size).
        per_cascade -= rasterized(previous.origin / float(1 << bits), previous.origin, plan.left, count_only=True)[1]
    depth.flags.writeable = False
    raster = RasterizedMaps(basis=cascades.basis, zref=cascades.zref, bits=bits, texel_size=texel_size,
                            origin=origin_fixed, resolution=np.array(sizes), depth=depth, texels=per_cascade)
    return depth, int(per_cascade.sum()), raster


def _host_snapped_depth_maps(dscene: DeviceScene, cascades: CascadeSet,
                             settings: ShadowSettings) -> tuple[np.ndarray, int]:
    """``(C, R, R)`` depth maps and texels rasterized, vertices snapped on the host cascade by cascade.

    The path for what the culled kernels do not model: an engine's float32 cascade math
    (``engine_precision``, :mod:`csmlab.texels`) and casters clipped at a slice's near side
    without pancaking (``depth_range = "slice"``, ``depth_clamp = false``). Faces are culled as
    on the other path (``settings.cull``, once per call, by ``d`` alone).
    """
    bits = settings.subtexel_bits
    vertices = dscene.scene.vertices
    depth_of_vertex = light_depth(cascades, vertices)
    sizes = [c.resolution for c in cascades.cascades]
    maps = np.full((len(sizes), max(sizes), max(sizes)), np.inf, dtype=np.float32)
    texels = 0
    kept = culled_triangles(vertices, dscene.scene.triangles, cascades.direction, settings.cull)
    for c, cascade in enumerate(cascades.cascades):
        triangles = kept
        if DEPTH_RANGE_METHODS[settings.depth_range].cuts_casters and not settings.depth_clamp:
            triangles = clipped_casters(depth_of_vertex, triangles, near=cascade.depth_near - cascades.zref)
        if triangles.shape[0] == 0:
            continue
        points = fixed_point_coordinates(cascades, c, vertices, bits=bits, precision=settings.engine_precision)
        one, count = rasterize_depth(points[None], depth_of_vertex, triangles, resolution=sizes[c], bits=bits,
                                     device=dscene.device)
        maps[c, :sizes[c], :sizes[c]] = one[0]
        texels += count
    return maps, texels


def clipped_casters(depth: np.ndarray, triangles: np.ndarray, *, near: float) -> np.ndarray:
    """Triangles ``(T', 3)`` a box whose near side lies at stored depth ``near`` keeps without pancaking.

    Those wholly nearer than ``near`` (every vertex depth below it) are clipped away; one that
    crosses the near side is kept whole (a GPU would keep only its part behind the plane).
    """
    return triangles[depth[triangles].max(axis=1) >= near]


def render_shadow(dscene: DeviceScene, view: View, settings: ShadowSettings, *,
                  visible_depth: tuple[float, float] | None = None, held_extents=None, lookup: bool = True,
                  scroll_from: ShadowMaps | None = None) -> Frame:
    """One shadow method on a shared view: cascades → depth maps → lookup at every pixel.

    With ``bounds = "sdsm"`` the splits divide ``visible_depth`` when given (the held range of an
    SDSM with hysteresis), else the view's own G-buffer depth range. ``held_extents`` ``(C, 2)``:
    the tight boxes' sizes held by extent hysteresis this frame (``stabilization = "none"``).
    ``lookup = False`` stops after the depth maps (``Frame.shadow`` None): all the temporal
    metrics read of a previous frame. ``scroll_from``: the same method's previous maps, whose texels
    the boxes still cover are copied instead of rasterized (:mod:`csmlab.scrolling`; the same maps).

    Returns
    -------
    Frame
        ``timings`` holds ``cascades``, ``raster`` (and ``shadow``) in seconds.
    """
    settings = settings.validated()
    start = time.perf_counter()
    if BOUNDS_METHODS[settings.bounds].visible and visible_depth is None:
        visible_depth = visible_depth_range(view.gbuffer.view_depth)
    cascades = build_cascades(pose=view.pose, light_direction=view.light_direction,
                              scene_corners=dscene.corners, settings=settings, visible_depth=visible_depth,
                              held_extents=held_extents)
    timings = {"cascades": time.perf_counter() - start}
    start = time.perf_counter()
    maps = shadow_maps(dscene, cascades, settings, scroll_from=scroll_from)
    timings["raster"] = time.perf_counter() - start
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
                           device=dscene.device)
    timings["shadow"] = time.perf_counter() - start
    return Frame(view=view, settings=settings, maps=maps, shadow=shadow, timings=timings)


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
