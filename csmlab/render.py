"""One frame on one Warp device, in the order of DESIGN.md's CSM model.

What depends on the camera and the light only — the G-buffer (step 5) and the ray-traced
reference (step 7) — is :func:`render_view`, computed once per frame and shared by every shadow
method. Each method then runs :func:`render_shadow`: cascades (steps 1–3), depth maps in fixed
point (step 4) and the shadow lookup at every visible pixel (step 6). :func:`render_frame` does
both. Each stage's wall-clock time goes into the records' ``timings``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from csmlab.camera import CameraPose
from csmlab.cascades import CascadeSet, build_cascades
from csmlab.filters import filter_moments, filtered_shadow_lookup, uses_pixels
from csmlab.frame import Frame, GBuffer, ShadowLookup, ShadowMaps, View
from csmlab.geometry import normalized
from csmlab.kernels.raster import cascade_candidates, rasterize_cascades, triangle_bounds
from csmlab.kernels.reference import hard_shadow
from csmlab.kernels.shadow import receiver_coordinates
from csmlab.kernels.visibility import MeshBVH, camera_hits, mesh_bvh
from csmlab.scene.core import Scene
from csmlab.settings import ShadowSettings
from csmlab.storage import stored_depth
from csmlab.texels import fixed_point_origin, light_depth, light_plane_coordinates, light_space

__all__ = ["DeviceScene", "lookup_shadow", "prepare_scene", "render_frame", "render_shadow", "render_view",
           "shadow_maps"]


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
        frame), keyed by the light basis.
    """

    scene: Scene
    bvh: MeshBVH
    device: str
    corners: np.ndarray = field(compare=False, repr=False)
    light_space: dict = field(default_factory=dict, compare=False, repr=False)


def prepare_scene(scene: Scene, *, device: str = "cpu") -> DeviceScene:
    """Upload ``scene`` to ``device`` (``"cpu"`` or ``"cuda"``) and build its BVH."""
    return DeviceScene(scene=scene, bvh=mesh_bvh(scene.vertices, scene.triangles, device=device), device=device,
                       corners=scene.corners())


def render_view(dscene: DeviceScene, pose: CameraPose, light_direction, *, width: int, height: int,
                index: int = 0, previous_light_direction=None) -> View:
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

    Returns
    -------
    View
        ``timings`` holds ``visibility``, ``reference`` (and ``reference_previous``) in seconds.
    """
    d = normalized(light_direction, name="light direction")
    start = time.perf_counter()
    hits = camera_hits(dscene.bvh, position=pose.position, rotation=pose.rotation, fov_y_deg=pose.fov_y_deg,
                       aspect=pose.aspect, far=pose.far, width=width, height=height)
    valid = hits.triangle >= 0
    albedo = np.where(valid[..., None], dscene.scene.albedo[np.maximum(hits.triangle, 0)], np.float32(0.0))
    gbuffer = GBuffer(position=hits.position, normal=hits.normal, triangle=hits.triangle,
                      view_depth=hits.view_depth, dpdx=hits.dpdx, dpdy=hits.dpdy, albedo=albedo.astype(np.float32))
    visibility = time.perf_counter() - start
    start = time.perf_counter()
    reference = hard_shadow(dscene.bvh, points=gbuffer.position, normals=gbuffer.normal, light_direction=d)
    timings = {"visibility": visibility, "reference": time.perf_counter() - start}
    before = previous = None
    if previous_light_direction is not None:
        before = normalized(previous_light_direction, name="previous light direction")
    if before is not None and not np.array_equal(before, d):
        start = time.perf_counter()
        previous = hard_shadow(dscene.bvh, points=gbuffer.position, normals=gbuffer.normal, light_direction=before)
        timings["reference_previous"] = time.perf_counter() - start
    else:
        before = None
    return View(index=index, pose=pose, light_direction=d, gbuffer=gbuffer, reference=reference, timings=timings,
                previous_light_direction=before, previous_reference=previous)


def _scene_in_light_space(dscene: DeviceScene, cascades: CascadeSet) -> tuple:
    """Vertices' light-space x/y and depth, triangles' light-space rectangles: computed once per light."""
    key = (cascades.basis.tobytes(), cascades.zref)
    if key not in dscene.light_space:
        vertices = dscene.scene.vertices
        xy = light_plane_coordinates(cascades, vertices)
        dscene.light_space.clear()
        dscene.light_space[key] = (xy, light_depth(cascades, vertices), *triangle_bounds(xy, dscene.scene.triangles))
    return dscene.light_space[key]


def shadow_maps(dscene: DeviceScene, cascades: CascadeSet, settings: ShadowSettings) -> ShadowMaps:
    """Rasterize every cascade's depth map from the scene's vertices in fixed point, stored in ``settings.depth_format``.

    Only the triangles whose light-space rectangle meets a cascade's box go to that cascade's
    rasterization (:func:`csmlab.kernels.raster.cascade_candidates`); the others cover none of
    its texels. Cascades of unequal size are each rasterized at their own size into the corner of
    a map of the largest, the rest left empty (the lookup never selects a box there, csmlab.filters).
    """
    bits = settings.subtexel_bits
    xy, depth_of_vertex, lo, hi = _scene_in_light_space(dscene, cascades)
    texel_size = np.stack([c.texel_size for c in cascades.cascades])
    box_origin = np.stack([c.origin for c in cascades.cascades])
    origin = np.stack([fixed_point_origin(cascades, c, bits=bits) for c in range(len(cascades))])
    sizes = [c.resolution for c in cascades.cascades]
    groups = [list(range(len(sizes)))] if len(set(sizes)) == 1 else [[c] for c in range(len(sizes))]
    depth, texels = None, 0
    for group in groups:
        size = sizes[group[0]]
        candidates = cascade_candidates(lo, hi, texel_size=texel_size[group], origin=box_origin[group], resolution=size)
        own, count = rasterize_cascades(xy, depth_of_vertex, dscene.scene.triangles, texel_size=texel_size[group],
                                        origin=origin[group], resolution=size, bits=bits, candidates=candidates,
                                        device=dscene.device)
        if len(groups) == 1:
            depth = own
        else:
            if depth is None:
                depth = np.full((len(sizes), max(sizes), max(sizes)), np.inf, dtype=np.float32)
            depth[group, :size, :size] = own
        texels += count
    span = float(np.ptp(cascades.to_light(dscene.corners)[:, 2]))
    depth = stored_depth(depth, span=span, depth_format=settings.depth_format)
    return ShadowMaps(cascades=cascades, depth=depth, texels_rasterized=texels,
                      moments=filter_moments(depth, span=span, settings=settings, device=dscene.device),
                      depth_span=span)


def lookup_shadow(maps: ShadowMaps, *, points, normals, view_depth, settings: ShadowSettings,
                  pixels=None, device: str = "cpu") -> ShadowLookup:
    """One method's shadow at receiver points: cascade selection, biased depth test, filter, blend.

    Parameters
    ----------
    maps : ShadowMaps
        The cascades and depth maps to look up.
    points : array_like, shape (N, 3) or (H, W, 3), float64
        World positions in metres; NaN rows are not receivers.
    normals : array_like, same shape as ``points``, float32
        Unit receiver normals (facing the camera).
    view_depth : array_like, shape (N,) or (H, W)
        View depth in metres under the camera whose cascade selection is wanted (the temporal
        metric passes ``pose_{t-1}.view_depth(points)``); non-finite where no receiver.
    settings : ShadowSettings
        Selection, filter, bias, normal offset, blend band and sub-texel bits.
    pixels : array_like, shape (N, 2) or (H, W, 2), optional
        Each point's pixel (x, y) in the image being shaded, for filters rotated per pixel; None:
        an ``(H, W, 3)`` image of points is at its own pixels.
    device : str
        ``"cpu"`` or ``"cuda"``.

    Returns
    -------
    ShadowLookup
        Arrays shaped like ``view_depth``.
    """
    p = np.asarray(points, dtype=np.float64)
    n = np.asarray(normals, dtype=np.float32)
    z = np.asarray(view_depth, dtype=np.float64)
    if p.shape[-1:] != (3,) or n.shape != p.shape or z.shape != p.shape[:-1]:
        raise ValueError(f"points, normals, view_depth: expected shapes (..., 3), (..., 3), (...); "
                         f"got {p.shape}, {n.shape}, {z.shape}")
    # Only receivers go to the kernels: points with a NaN (misses) keep S = NaN and cascade -1.
    flat_z = z.reshape(-1)
    receivers = np.flatnonzero(np.all(np.isfinite(p.reshape(-1, 3)), axis=1) & ~np.isnan(flat_z))
    cascades = maps.cascades
    bits = settings.subtexel_bits
    # csmlab.texels.receiver_lookup, its per-cascade part in a kernel (the same bits).
    coordinates, receiver_depth, receiver_slope = receiver_coordinates(
        light_space(cascades, p.reshape(-1, 3)[receivers]),
        light_space(cascades, n.reshape(-1, 3)[receivers].astype(np.float64)),
        texel_size=np.stack([c.texel_size for c in cascades.cascades]),
        origin=np.stack([fixed_point_origin(cascades, c, bits=bits) for c in range(len(cascades))]),
        zref=cascades.zref, bits=bits, normal_offset=settings.normal_offset, bias_constant=settings.bias_constant,
        bias_slope=settings.bias_slope, device=device,
    )
    if pixels is None and p.ndim == 3 and uses_pixels(settings):
        rows, cols = np.indices(p.shape[:2])
        pixels = np.stack([cols, rows], axis=-1)
    found = filtered_shadow_lookup(
        maps.depth, coordinates, receiver_depth, flat_z[receivers], cascades=cascades, settings=settings,
        moments=maps.moments, span=maps.depth_span,
        receiver_slope=receiver_slope if settings.receiver_plane_bias else None,
        pixels=None if pixels is None else np.asarray(pixels, dtype=np.float64).reshape(-1, 2)[receivers],
        device=device,
    )
    lit = np.full(flat_z.shape, np.nan, dtype=np.float32)
    cascade = np.full(flat_z.shape, -1, dtype=np.int8)
    blend = np.zeros(flat_z.shape, dtype=bool)
    lit[receivers], cascade[receivers], blend[receivers] = found
    shape = z.shape
    return ShadowLookup(lit=lit.reshape(shape), cascade=cascade.reshape(shape), blend=blend.reshape(shape))


def render_shadow(dscene: DeviceScene, view: View, settings: ShadowSettings) -> Frame:
    """One shadow method on a shared view: cascades → depth maps → lookup at every pixel.

    Returns
    -------
    Frame
        ``timings`` holds ``cascades``, ``raster`` and ``shadow`` in seconds.
    """
    settings = settings.validated()
    start = time.perf_counter()
    cascades = build_cascades(pose=view.pose, light_direction=view.light_direction,
                              scene_corners=dscene.corners, settings=settings)
    timings = {"cascades": time.perf_counter() - start}
    start = time.perf_counter()
    maps = shadow_maps(dscene, cascades, settings)
    timings["raster"] = time.perf_counter() - start
    start = time.perf_counter()
    g = view.gbuffer
    shadow = lookup_shadow(maps, points=g.position, normals=g.normal, view_depth=g.view_depth, settings=settings,
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
