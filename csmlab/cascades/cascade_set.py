"""Build the cascades of one frame: splits → slices → footprints → stabilized boxes.

Reads top to bottom like docs/design.md's CSM model, steps 1–3. The result, a :class:`CascadeSet`,
is all the Warp kernels need to know of where each cascade lies.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from csmlab.camera import CameraPose
from csmlab.cascades.bounds import DEPTH_RANGE_METHODS, shadow_end, split_range
from csmlab.cascades.extent import EXTENT_METHODS, radius_rounded_up
from csmlab.cascades.fit import selection_depths, slice_intervals
from csmlab.cascades.focus import focused_volume
from csmlab.cascades.splits import split_distances
from csmlab.cascades.stabilize import SliceFootprint, stabilize
from csmlab.cascades.warp import Warp, cascade_warp
from csmlab.geometry import LIGHT_BASIS_METHODS, frustum_slice_corners, slice_bounding_sphere
from csmlab.registry import check_name, dispatch, parameters
from csmlab.settings import ShadowSettings
from csmlab.shadow_policies import shadow_fov_deg

__all__ = ["Cascade", "CascadeSet", "build_cascades", "fitted_pose", "radius_rounded_up", "tight_extents"]


@dataclass(frozen=True)
class Cascade:
    """One cascade's box in light space: orthographic, or warped by a perspective (``warp``).

    Attributes
    ----------
    split_near, split_far : float
        The split interval ``[z_i, z_{i+1})`` in metres of view depth (interval selection).
    slice_near, slice_far : float
        The fitted view-depth interval the box covers (fit mode and blend band applied).
    texel_size : ndarray, shape (2,)
        Metres per texel along light-space x and y; for a warped cascade, along the map's axes at
        the camera's eye (what biases and offsets in texels are scaled by, as in Filament).
    origin : ndarray, shape (2,)
        Box minimum corner in texels of ``texel_size`` (whole numbers for exact and quantized);
        zero for a warped cascade, whose texels are placed by ``warp.homography`` alone (its
        ``box_min``, ``box_max`` and ``extent`` then describe no box).
    resolution : int
        Texels per side R.
    depth_near, depth_far : float
        Depth range in metres along the light direction (``dot(X, d)``, not relative to zref).
    warp : Warp, optional
        The perspective warp of ``warp = "lispsm"`` (:mod:`csmlab.cascades.warp`); None: orthographic.
    sphere_centre : ndarray, shape (3,), optional
        World centre in metres of the fitted slice's smallest bounding sphere: the split sphere of
        ``selection = "sphere"`` (Unity's culling sphere).
    sphere_radius : float
        Its radius in metres, rounded up as the ``sphere`` extent's (0 where not built).
    """

    split_near: float
    split_far: float
    slice_near: float
    slice_far: float
    texel_size: np.ndarray
    origin: np.ndarray
    resolution: int
    depth_near: float
    depth_far: float
    warp: Warp | None = None
    sphere_centre: np.ndarray | None = None
    sphere_radius: float = 0.0

    @property
    def homography(self) -> np.ndarray:
        """Light-space ``(x, y, 1)`` metres to ``(i·w, j·w, w)`` local texels ``(3, 3)``: the warp's, or the
        box's (w = 1)."""
        if self.warp is not None:
            return self.warp.homography
        return np.array([[1.0 / self.texel_size[0], 0.0, -self.origin[0]],
                         [0.0, 1.0 / self.texel_size[1], -self.origin[1]],
                         [0.0, 0.0, 1.0]])

    @property
    def box_min(self) -> np.ndarray:
        """Light-space x/y ``(2,)`` of the box's minimum corner, metres."""
        return self.origin * self.texel_size

    @property
    def box_max(self) -> np.ndarray:
        """Light-space x/y ``(2,)`` of the box's maximum corner, metres."""
        return (self.origin + self.resolution) * self.texel_size

    @property
    def extent(self) -> np.ndarray:
        """Box size ``(2,)`` in metres."""
        return self.texel_size * self.resolution


@dataclass(frozen=True)
class CascadeSet:
    """Every cascade of one frame and the light space they share.

    Attributes
    ----------
    basis : ndarray, shape (3, 3)
        Rows (right, up, d): world to light space; depends on the light direction only
        (``settings.light_basis``, :data:`csmlab.geometry.LIGHT_BASIS_METHODS`).
    zref : float
        Depth offset in metres subtracted from ``dot(X, d)`` before storing (fixed per light and
        scene, never per box, so a moved box stores the same depths).
    splits : ndarray, shape (C + 1,)
        Split distances in metres of view depth.
    cascades : tuple of Cascade
    margin_texels : int
        Texels kept free inside each box edge for the filter.
    eye : ndarray, shape (3,), optional
        World position of the camera the cascades were built for (the radial fades' centre).
    selection_splits : ndarray, shape (C + 1,), optional
        View depths in metres where the interval selection switches cascade when they are not the
        splits (``fit = "cascade_lerp"``: three.js's ``b (f - n)``, :func:`csmlab.cascades.fit.selection_depths`);
        None: the splits.
    """

    basis: np.ndarray
    zref: float
    splits: np.ndarray
    cascades: tuple[Cascade, ...]
    margin_texels: int
    eye: np.ndarray | None = None
    selection_splits: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.cascades)

    @property
    def warped(self) -> bool:
        """Whether any cascade is perspective-warped (its texels placed by a homography, on the host)."""
        return any(c.warp is not None for c in self.cascades)

    @property
    def switch_depths(self) -> np.ndarray:
        """View depths ``(C + 1,)`` in metres where the interval selection switches cascade."""
        return self.splits if self.selection_splits is None else self.selection_splits

    @property
    def direction(self) -> np.ndarray:
        """Unit light direction ``(3,)`` (light toward scene)."""
        return self.basis[2]

    def projection(self, index: int) -> np.ndarray:
        """Cascade ``index``'s light projection, a general 4×4 ``(4, 4)`` from world ``(X, 1)`` to ``(i·w, j·w, z, w)``.

        After the projective divide: local texel coordinates ``(i, j)`` and ``z / w`` with
        ``z = d·X − zref`` the stored light depth in metres (affine across a triangle in ``(i, j)``,
        what the rasterizer interpolates). Orthographic cascades have ``w = 1``.
        """
        h = self.cascades[index].homography
        rows = [h[k, 0] * self.basis[0] + h[k, 1] * self.basis[1] for k in range(3)]
        return np.array([[*rows[0], h[0, 2]], [*rows[1], h[1, 2]], [*self.basis[2], -self.zref], [*rows[2], h[2, 2]]])

    def to_light(self, points) -> np.ndarray:
        """Light-space coordinates ``(..., 3)`` (x, y metres; depth ``dot(X, d)`` metres) of world points."""
        return np.asarray(points, dtype=np.float64) @ self.basis.T


def _slices(pose: CameraPose, settings: ShadowSettings, visible_depth) -> tuple:
    """``(near, far, splits, intervals)`` of one frame: the range the splits divide, the splits, the fitted slices."""
    end = shadow_end(method=settings.shadow_distance_from, shadow_distance=settings.shadow_distance,
                     max_shadow_distance=settings.max_shadow_distance, camera_far=pose.far, visible=visible_depth)
    near, far = split_range(near=pose.near, far=end, visible=visible_depth, method=settings.bounds)
    splits = split_distances(near=near, far=far, count=settings.cascades, method=settings.split,
                             lambda_=settings.lambda_, splits=settings.splits,
                             distribution_exponent=settings.distribution_exponent,
                             first_cascade_far=settings.first_cascade_far)
    return near, far, splits, slice_intervals(splits, method=settings.fit, blend_band=settings.blend_band,
                                              transition=settings.transition)


def fitted_pose(pose: CameraPose, settings: ShadowSettings) -> CameraPose:
    """The camera the cascades are fitted to: ``pose`` with the field of view of ``settings.zoom_policy``.

    The camera renders at its own field of view; with ``zoom_policy = "min_fov"`` its slices, boxes
    and splits are those of a camera at ``max(fov, min_fov_deg)`` (same position, orientation,
    aspect and clip distances: :mod:`csmlab.shadow_policies`).
    """
    fov = shadow_fov_deg(pose.fov_y_deg, policy=settings.zoom_policy, min_fov_deg=settings.min_fov_deg)
    return pose if fov == pose.fov_y_deg else replace(pose, fov_y_deg=fov)


def tight_extents(*, pose: CameraPose, light_direction, settings: ShadowSettings,
                  visible_depth: tuple[float, float] | None = None) -> np.ndarray:
    """Light-space x/y extent ``(C, 2)`` in metres of each cascade's slice: the size of a tight (``none``) box.

    What :func:`csmlab.cascades.stabilize.held_extents` holds over a path for extent hysteresis.
    """
    pose = fitted_pose(pose, settings)
    basis = dispatch(LIGHT_BASIS_METHODS, settings.light_basis, field="light_basis", direction=light_direction)
    _, _, _, intervals = _slices(pose, settings, visible_depth)
    out = []
    for z0, z1 in intervals:
        corners = _slice_light_corners(pose, basis, z0, z1)
        out.append(corners[:, :2].max(axis=0) - corners[:, :2].min(axis=0))
    return np.array(out, dtype=np.float64)


def build_cascades(*, pose: CameraPose, light_direction, scene_corners, settings: ShadowSettings,
                   visible_depth: tuple[float, float] | None = None, held_extents=None) -> CascadeSet:
    """The cascades of one frame, as an engine computes them on the CPU.

    Parameters
    ----------
    pose : CameraPose
        The camera; the cascades are fitted to :func:`fitted_pose` (its field of view under
        ``settings.zoom_policy``).
    light_direction : array_like, shape (3,)
        From the light toward the scene; need not be unit length, must not be zero.
    scene_corners : array_like, shape (K, 3)
        Points bounding every shadow caster (e.g. the eight corners of the scene's bounds), metres.
    settings : ShadowSettings
        Split scheme, fit, stabilization and resolution.
    visible_depth : (float, float), optional
        ``bounds = "sdsm"``: the view-depth range ``(z_min, z_max)`` in metres the splits divide (the
        frame's G-buffer range, or the held range with hysteresis); ignored with ``bounds = "frustum"``.
    held_extents : array_like, shape (C, 2), optional
        ``extent_hysteresis``: each tight box's held light-space x/y size in metres this frame
        (:func:`csmlab.cascades.stabilize.held_extents`); ignored unless ``stabilization = "none"``.

    Returns
    -------
    CascadeSet
    """
    settings.validated()
    pose = fitted_pose(pose, settings)
    basis = dispatch(LIGHT_BASIS_METHODS, settings.light_basis, field="light_basis", direction=light_direction)
    scene_light = np.asarray(scene_corners, dtype=np.float64).reshape(-1, 3) @ basis.T
    near, far, splits, intervals = _slices(pose, settings, visible_depth)
    frustum_light = _slice_light_corners(pose, basis, near, far)
    frustum_extent = frustum_light[:, :2].max(axis=0) - frustum_light[:, :2].min(axis=0)
    margin = settings.margin_texels
    check_name(settings.extent, EXTENT_METHODS, field="extent")
    check_name(settings.depth_range, DEPTH_RANGE_METHODS, field="depth_range")

    cascades = []
    for i, (z0, z1) in enumerate(intervals):
        corners = _slice_light_corners(pose, basis, z0, z1)
        volume = focused_volume(settings.focus, corners=corners, scene_light=scene_light) \
            if settings.stabilization == "none" else corners
        centre, radius = dispatch(EXTENT_METHODS, settings.extent, field="extent", pose=pose, basis=basis, z_near=z0,
                                  z_far=z1, corners=corners)
        footprint = SliceFootprint(lo=volume[:, :2].min(axis=0), hi=volume[:, :2].max(axis=0), centre=centre,
                                   radius=radius, frustum_extent=frustum_extent)
        resolution = settings.cascade_resolutions[i] if settings.cascade_resolutions else settings.resolution
        texel, origin = stabilize(footprint, method=settings.stabilization, resolution=resolution,
                                  margin=margin, levels=settings.levels, quantized_base=settings.quantized_base,
                                  snap=settings.snap, held_extent=None if held_extents is None else held_extents[i])
        box_depth = DEPTH_RANGE_METHODS[settings.depth_range].box_depth
        offered = dict(pancake=settings.pancake, corners=corners, light_near=settings.light_near,
                       light_far=settings.light_far, scene_corners=scene_corners, basis=basis,
                       box_lo=origin * texel, box_hi=(origin + resolution) * texel)
        depth_near, depth_far = box_depth(corners[:, 2], scene_light[:, 2],
                                          **{k: v for k, v in offered.items() if k in parameters(box_depth)})
        warp = cascade_warp(settings.warp, basis=basis, volume=volume, pose=pose, resolution=resolution,
                            margin=margin, z_near=z0, z_far=z1, near_hint=settings.lispsm_near_hint,
                            far_hint=settings.lispsm_far_hint)
        if warp is not None:
            texel, origin = warp.texel_size, np.zeros(2)
        cascades.append(Cascade(
            split_near=float(splits[i]), split_far=float(splits[i + 1]), slice_near=float(z0), slice_far=float(z1),
            texel_size=texel, origin=origin, resolution=resolution, depth_near=depth_near,
            depth_far=depth_far, warp=warp, **_split_sphere(pose, z0, z1),
        ))
    switches = selection_depths(splits, method=settings.fit)
    return CascadeSet(basis=basis, zref=float(scene_light[:, 2].min()), splits=splits, cascades=tuple(cascades),
                      margin_texels=margin, eye=np.array(pose.position, dtype=np.float64),
                      selection_splits=None if np.array_equal(switches, splits) else switches)


def _split_sphere(pose: CameraPose, z0: float, z1: float) -> dict:
    """``sphere_centre`` (world, metres) and ``sphere_radius`` of the slice ``[z0, z1]``'s smallest bounding sphere.

    Unity's split spheres are native (``ComputeDirectionalShadowMatricesAndCullingPrimitives``'s
    culling sphere, unverified): csmlab takes the sphere its ``sphere`` extent sizes the box by.
    """
    sphere = slice_bounding_sphere(fov_y_deg=pose.fov_y_deg, aspect=pose.aspect, z_near=z0, z_far=z1)
    return dict(sphere_centre=np.asarray(pose.position, dtype=np.float64) + pose.forward * sphere.centre_depth,
                sphere_radius=radius_rounded_up(sphere.radius))


def _slice_light_corners(pose: CameraPose, basis: np.ndarray, z0: float, z1: float) -> np.ndarray:
    corners = frustum_slice_corners(position=pose.position, orientation=pose.orientation, fov_y_deg=pose.fov_y_deg,
                                    aspect=pose.aspect, z_near=z0, z_far=z1)
    return corners @ basis.T
