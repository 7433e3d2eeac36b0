"""One frame on one Warp device, in the order of DESIGN.md's CSM model.

What depends on the camera and the light only — the G-buffer (step 5) and the ray-traced
reference (step 7) — is :func:`render_view`, computed once per frame and shared by every shadow
method. Each method then runs :func:`render_shadow`: cascades (steps 1–3), depth maps in fixed
point (step 4) and the shadow lookup at every visible pixel (step 6). :func:`render_frame` does
both. Each stage's wall-clock time goes into the records' ``timings``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from csmlab.camera import CameraPose
from csmlab.cascades import CascadeSet, build_cascades
from csmlab.cascades.bounds import visible_depth_range
from csmlab.frame import Frame, GBuffer, ShadowLookup, ShadowMaps, View
from csmlab.geometry import normalized
from csmlab.kernels.raster import rasterize_depth
from csmlab.kernels.reference import hard_shadow
from csmlab.kernels.shadow import shadow_lookup
from csmlab.kernels.visibility import MeshBVH, camera_hits, mesh_bvh
from csmlab.scene.core import Scene
from csmlab.settings import ShadowSettings
from csmlab.texels import fixed_point_coordinates, light_depth, receiver_lookup

__all__ = ["DeviceScene", "clipped_casters", "faded", "lookup_shadow", "prepare_scene", "render_frame", "render_shadow", "render_view",
           "shadow_maps", "visible_depth"]


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
    """

    scene: Scene
    bvh: MeshBVH
    device: str


def prepare_scene(scene: Scene, *, device: str = "cpu") -> DeviceScene:
    """Upload ``scene`` to ``device`` (``"cpu"`` or ``"cuda"``) and build its BVH."""
    return DeviceScene(scene=scene, bvh=mesh_bvh(scene.vertices, scene.triangles, device=device), device=device)


def render_view(dscene: DeviceScene, pose: CameraPose, light_direction, *, width: int, height: int,
                index: int = 0) -> View:
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

    Returns
    -------
    View
        ``timings`` holds ``visibility`` and ``reference`` in seconds.
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
    return View(index=index, pose=pose, light_direction=d, gbuffer=gbuffer, reference=reference,
                timings={"visibility": visibility, "reference": time.perf_counter() - start})


def visible_depth(dscene: DeviceScene, pose: CameraPose, *, width: int, height: int) -> tuple[float, float] | None:
    """The view-depth range ``(z_min, z_max)`` in metres of the G-buffer :func:`render_view` would make (SDSM)."""
    hits = camera_hits(dscene.bvh, position=pose.position, rotation=pose.rotation, fov_y_deg=pose.fov_y_deg,
                       aspect=pose.aspect, far=pose.far, width=width, height=height)
    return visible_depth_range(hits.view_depth)


def shadow_maps(dscene: DeviceScene, cascades: CascadeSet, settings: ShadowSettings) -> ShadowMaps:
    """Rasterize every cascade's depth map from the scene's vertices in fixed point."""
    bits = settings.subtexel_bits
    vertices = dscene.scene.vertices
    points = np.stack([fixed_point_coordinates(cascades, c, vertices, bits=bits, precision=settings.engine_precision)
                       for c in range(len(cascades))])
    depth = light_depth(cascades, vertices)
    if settings.depth_range == "scene" or settings.depth_clamp:
        maps, texels = rasterize_depth(points, depth, dscene.scene.triangles, resolution=settings.resolution,
                                       bits=bits, device=dscene.device)
        if settings.depth_range == "slice":
            # Pancaking is a per-fragment clamp max(z, near); the stored minimum of clamped fragments
            # is the clamped minimum, so clamping the map is exact.
            near = np.array([c.depth_near - cascades.zref for c in cascades.cascades], dtype=np.float32)
            maps = np.maximum(maps, near[:, None, None])
        return ShadowMaps(cascades=cascades, depth=maps, texels_rasterized=texels)
    maps, texels = [], 0
    for c, cascade in enumerate(cascades.cascades):
        triangles = clipped_casters(depth, dscene.scene.triangles, near=cascade.depth_near - cascades.zref)
        if triangles.shape[0] == 0:
            maps.append(np.full((settings.resolution, settings.resolution), np.inf, dtype=np.float32))
            continue
        one, count = rasterize_depth(points[c:c + 1], depth, triangles, resolution=settings.resolution, bits=bits,
                                     device=dscene.device)
        maps.append(one[0])
        texels += count
    return ShadowMaps(cascades=cascades, depth=np.stack(maps), texels_rasterized=texels)


def clipped_casters(depth: np.ndarray, triangles: np.ndarray, *, near: float) -> np.ndarray:
    """Triangles ``(T', 3)`` a box whose near side lies at stored depth ``near`` keeps without pancaking.

    Those wholly nearer than ``near`` (every vertex depth below it) are clipped away; one that
    crosses the near side is kept whole (a GPU would keep only its part behind the plane).
    """
    return triangles[depth[triangles].max(axis=1) >= near]


def lookup_shadow(maps: ShadowMaps, *, points, normals, view_depth, settings: ShadowSettings,
                  device: str = "cpu") -> ShadowLookup:
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
    coordinates, receiver_depth, receiver_slope = receiver_lookup(
        cascades, p.reshape(-1, 3)[receivers], n.reshape(-1, 3)[receivers], bits=bits,
        normal_offset=settings.normal_offset, bias_constant=settings.bias_constant, bias_slope=settings.bias_slope,
        precision=settings.engine_precision,
    )
    found = shadow_lookup(
        maps.depth, coordinates, receiver_depth, flat_z[receivers],
        splits=cascades.splits, texel_area=np.array([np.prod(c.texel_size) for c in cascades.cascades]),
        selection=settings.selection, filter=settings.filter, filter_size=settings.filter_size,
        margin=cascades.margin_texels, blend_band=settings.blend_band, bits=bits,
        receiver_slope=receiver_slope if settings.receiver_plane_bias else None, device=device,
    )
    lit = np.full(flat_z.shape, np.nan, dtype=np.float32)
    cascade = np.full(flat_z.shape, -1, dtype=np.int8)
    blend = np.zeros(flat_z.shape, dtype=bool)
    lit[receivers], cascade[receivers], blend[receivers] = found
    if settings.fade_out > 0.0:
        lit[receivers], fading = faded(lit[receivers], flat_z[receivers], far=float(cascades.splits[-1]),
                                       fade_out=settings.fade_out)
        # Like a blend band, the fade weight follows the camera: the temporal metric counts these
        # points with the transitions, not with same-cascade swimming.
        blend[receivers] |= fading
    shape = z.shape
    return ShadowLookup(lit=lit.reshape(shape), cascade=cascade.reshape(shape), blend=blend.reshape(shape))


def faded(lit: np.ndarray, view_depth: np.ndarray, *, far: float, fade_out: float) -> tuple[np.ndarray, np.ndarray]:
    """``lit`` ``(N,)`` faded toward 1 over the last ``fade_out`` fraction of ``far`` in view depth.

    The weight rises linearly from 0 at ``far (1 - fade_out)`` to 1 at ``far`` (Unreal's
    ``ShadowDistanceFadeoutFraction``, Godot's ``1 - directional_shadow_fade_start``).

    Returns
    -------
    lit : ndarray, shape (N,), float32
    fading : ndarray, shape (N,), bool
        The weight is above 0.
    """
    start = far * (1.0 - fade_out)
    weight = np.clip((np.asarray(view_depth, dtype=np.float64) - start) / max(far - start, 1e-12), 0.0, 1.0)
    return (lit + (1.0 - lit) * weight).astype(np.float32), weight > 0.0


def render_shadow(dscene: DeviceScene, view: View, settings: ShadowSettings, *,
                  visible_depth: tuple[float, float] | None = None) -> Frame:
    """One shadow method on a shared view: cascades → depth maps → lookup at every pixel.

    With ``bounds = "sdsm"`` the splits divide ``visible_depth`` when given (the held range of an
    SDSM with hysteresis), else the view's own G-buffer depth range.

    Returns
    -------
    Frame
        ``timings`` holds ``cascades``, ``raster`` and ``shadow`` in seconds.
    """
    settings = settings.validated()
    start = time.perf_counter()
    if settings.bounds == "sdsm" and visible_depth is None:
        visible_depth = visible_depth_range(view.gbuffer.view_depth)
    cascades = build_cascades(pose=view.pose, light_direction=view.light_direction,
                              scene_corners=dscene.scene.corners(), settings=settings, visible_depth=visible_depth)
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
