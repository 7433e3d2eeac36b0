"""The shadow lookup, read top to bottom (CSM model step 6), and the inputs its filters read.

:func:`lookup_shadow` is the one way in (:mod:`csmlab.render` calls it, and the temporal metric
through it). Each step is decided once, in the order it runs:

1. **The filter's record** — :data:`csmlab.lookup_choices.FILTER_METHODS` ``[settings.filter]``:
   its family, its radius (the texels its taps reach, which every selected box must hold, so that
   no tap is ever clamped: docs/design.md "Exact zero"), the width of its weights per cascade, its tap
   offsets and what it reads besides the depth maps.
2. **Receivers** — the points with a finite position and view depth (:class:`Receivers`), with
   their pixel where the filter reads pixels and their 2×2 quad where it reads mips. The others
   keep S = NaN and cascade −1.
3. **Texel coordinates** — every receiver in every cascade's fixed point, moved along its normal,
   with its biased depth and receiver-plane slope (:func:`texel_coordinates`).
4. **Cascade selection** — the ``selection`` method with the margin and the filter's radius, and the
   blend band toward the next cascade (:func:`csmlab.kernels.shadow.select_cascades`).
5. **The family's kernel** (:data:`FAMILY_LOOKUPS`) — ``box`` filters run inside the selection
   kernel itself (:func:`csmlab.kernels.shadow.shadow_lookup`; over unwarped cascades of one size
   it converts world receivers itself, into the cascades it reads only, on the float64 grid or in
   an engine's window space: steps 3–5 in one launch); ``weighted`` filters run
   :func:`csmlab.kernels.pcf.weighted_pcf` at the selected cascade (there too, on the rows the
   selection picked for it, :func:`csmlab.kernels.shadow.select_world_cascades`,
   :func:`~csmlab.kernels.shadow.select_window_cascades`) and ``moment`` filters
   :func:`csmlab.kernels.moments.moment_lookup` (or its mip-chain lookup).
6. **Fade** — toward lit over the end of the shadow distance (:func:`csmlab.fades.faded`).

Width per cascade: in texels from ``filter_size`` / ``filter_sigma``, or, with ``filter_width_m > 0``,
the same width in metres in every cascade (the records' ``width``, :mod:`csmlab.lookup_choices`).
The moment filters read moment maps and, with ``moment_mips``, their mip chain, both made once per
frame in the cascade pass (:func:`filter_inputs`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from csmlab.camera import CameraPose
from csmlab.cascades import CascadeSet
from csmlab.clipmaps import light_space, read_levels, wanted_levels
from csmlab.cascades.borders import dithered_sphere_cascades
from csmlab.cascades.fit import BLEND_CURVES, transition_bands
from csmlab.fades import FADE_METHODS, faded
from csmlab.frame import ShadowLookup, ShadowMaps
from csmlab.kernels.bias import BiasSettings
from csmlab.kernels.moments import blur_moments, moment_lookup, moment_maps, moment_mip_chain, moment_mip_lookup
from csmlab.kernels.pages import page_lookup
from csmlab.kernels.pcf import weighted_pcf
from csmlab.kernels.shadow import (receiver_coordinates, select_cascades, select_window_cascades,
                                   select_world_cascades, shadow_lookup, shadow_lookup_window, shadow_lookup_world,
                                   split_sphere_cascades)
from csmlab.lookup_choices import FILTER_METHODS, OUTSIDE_METHODS, Filter
from csmlab.quads import Quads, quad_derivatives
from csmlab.registry import check_name
from csmlab.settings import ShadowSettings
from csmlab.kernels.engine import warped_receivers, window_receivers
from csmlab.texels import fixed_point_origin, receiver_lookup, uses_global_grid, window_boxes

__all__ = ["FAMILY_LOOKUPS", "Receivers", "clipmap_radius", "filter_inputs", "interleaved_gradient_noise",
           "lookup_shadow", "noise_frame", "receiver_rows", "screen_pixels", "texel_coordinates", "uses_pixels"]


@dataclass(frozen=True)
class Receivers:
    """The points a lookup shades, flattened, and what the filter reads of them.

    Attributes
    ----------
    points : ndarray, shape (M, 3), float64
        Every point given, world metres (NaN rows are no receivers).
    normals : ndarray, shape (M, 3), float32
        Their unit normals.
    index : ndarray, shape (N,), int
        The rows of ``points`` that are receivers.
    view_depth : ndarray, shape (N,), float64
        The receivers' view depth under the camera whose cascade selection is wanted, metres.
    pixels : ndarray, shape (N, 2), float64, or None
        Each receiver's pixel (x = column, y = row) in the image being shaded, where the filter
        reads pixels.
    quads : Quads or None
        Each receiver's 2×2 pixel quad (``position`` ``(N, 4, 3)``), where the filter reads mips.
    quad_view_depth : ndarray, shape (N, 4), float64, or None
        The quad lanes' view depths under the selecting camera.
    noise_frame : int
        The frame term of a per-pixel rotation's noise (:func:`noise_frame`); 0: the same every frame.
    """

    points: np.ndarray
    normals: np.ndarray
    index: np.ndarray
    view_depth: np.ndarray
    pixels: np.ndarray | None = None
    quads: Quads | None = None
    quad_view_depth: np.ndarray | None = None
    noise_frame: int = 0


def lookup_shadow(maps: ShadowMaps, *, points, normals, view_depth, settings: ShadowSettings,
                  pixels=None, quads: Quads | None = None, quad_view_depth=None, noise_frame: int = 0,
                  rows=None, device: str = "cpu") -> ShadowLookup:
    """One method's shadow at receiver points: the filter's record, receivers, selection, the filter, fade.

    Parameters
    ----------
    maps : ShadowMaps
        The cascades and depth maps to look up (and the moments a moment filter reads).
    points : array_like, shape (N, 3) or (H, W, 3), float64
        World positions in metres; NaN rows are not receivers.
    normals : array_like, same shape as ``points``, float32
        Unit receiver normals (facing the camera).
    view_depth : array_like, shape (N,) or (H, W)
        View depth in metres under the camera whose cascade selection is wanted (the temporal
        metric passes ``pose_{t-1}.view_depth(points)``); non-finite where no receiver.
    settings : ShadowSettings
        Selection, filter, bias, normal offset, blend band, fade and sub-texel bits.
    pixels : array_like, shape (N, 2) or (H, W, 2), optional
        Each point's pixel (x, y) in the image being shaded, for filters rotated per pixel; None:
        an ``(H, W, 3)`` image of points is at its own pixels.
    quads : Quads, optional
        ``moment_mips``: each point's 2×2 pixel quad (:func:`csmlab.quads.quad_lanes`), shaped like
        ``view_depth`` plus ``(4, 3)``.
    quad_view_depth : array_like, shape (..., 4), optional
        The lanes' view depths under the camera whose cascade selection is wanted.
    noise_frame : int
        Frame term of a per-pixel rotation's noise (:func:`noise_frame` of the frame shaded).
    rows : ndarray, shape (K,), int, optional
        :func:`receiver_rows` of ``points`` and ``view_depth``, when the caller keeps it (a view's
        methods look up the same points); None finds them.
    device : str
        ``"cpu"`` or ``"cuda"``.

    Returns
    -------
    ShadowLookup
        Arrays shaped like ``view_depth``.

    Raises
    ------
    ValueError
        On an unknown filter, shapes that do not match, or maps or receivers without what the
        filter reads (moments, mips and quads, pixels).
    """
    if maps.pages is not None:
        return _clipmap_lookup(maps, points=points, normals=normals, settings=settings, device=device)
    record = FILTER_METHODS[check_name(settings.filter, FILTER_METHODS, field="filter")]
    reads = record.reads_of(settings)
    if settings.selection == "sphere_dither":
        reads = reads | {"pixels"}
    receivers = dataclasses.replace(
        _receivers(points, normals, view_depth, pixels=pixels, quads=quads, quad_view_depth=quad_view_depth,
                   reads=reads, rows=rows), noise_frame=int(noise_frame))
    _check_maps(maps, reads)
    radius = record.radius_of(settings)
    selection = _selection(maps.cascades, settings, radius=radius)
    if settings.selection in ("sphere", "sphere_dither"):
        selection["sphere_cascade"] = _sphere_cascades(maps.cascades, receivers.points[receivers.index], device=device)
    if settings.selection == "sphere_dither":
        selection["sphere_cascade"] = _dithered_cascades(maps.cascades, receivers, selection["sphere_cascade"],
                                                         settings=settings)
    found = FAMILY_LOOKUPS[record.family](maps, receivers, record=record, radius=radius, selection=selection,
                                          settings=settings, device=device)
    return _shadow_of_points(found, receivers, np.asarray(view_depth, dtype=np.float64), settings=settings,
                             far=float(maps.cascades.splits[-1]), eye=maps.cascades.eye)


def clipmap_radius(settings: ShadowSettings) -> int:
    """Texels a virtual clipmap's taps reach about the receiver's texel: 0 for ``none``, ``filter_size // 2`` for
    ``pcf``."""
    return 0 if settings.filter == "none" else settings.filter_size // 2


def _clipmap_lookup(maps: ShadowMaps, *, points, normals, settings: ShadowSettings, device: str) -> ShadowLookup:
    """A virtual clipmap's shadow at ``points``: each receiver at the first level from the one its distance to
    the maps' camera wants whose pages hold all its taps (:func:`csmlab.clipmaps.read_levels`), read through the
    page table (:func:`csmlab.kernels.pages.page_lookup`). ``cascade`` is the level index; no blend band, no fade.

    The maps' camera (:attr:`csmlab.clipmaps.Clipmap.eye`) chooses the levels, so frame t−1's maps
    are looked up at frame t's points as frame t−1 would have: a point that camera did not see may
    find no resident page at its level and take a coarser one, or none (S = NaN, cascade −1).
    """
    pages = maps.pages
    clip = pages.clipmap
    p = np.asarray(points, dtype=np.float64)
    n = np.asarray(normals, dtype=np.float64)
    shape = p.shape[:-1]
    flat, flat_n = p.reshape(-1, 3), n.reshape(-1, 3)
    index = np.flatnonzero(np.isfinite(flat[:, 0]) & np.isfinite(flat[:, 1]) & np.isfinite(flat[:, 2]))
    radius = clipmap_radius(settings)
    table = pages.table
    level, coordinates, depth = read_levels(clip, light_space(flat[index], clip.basis),
                                            light_space(flat_n[index], clip.basis), wanted_levels(clip, flat[index]),
                                            settings=settings, radius=radius, table=table, device=device)
    lit = np.full(flat.shape[0], np.nan, dtype=np.float32)
    cascade = np.full(flat.shape[0], -1, dtype=np.int8)
    lit[index] = page_lookup(maps.depth, table, clip.origin_page, level, coordinates, depth, radius=radius,
                             bits=settings.subtexel_bits, device=device)
    cascade[index] = level
    return ShadowLookup(lit=lit.reshape(shape), cascade=cascade.reshape(shape), blend=np.zeros(shape, dtype=bool))


def receiver_rows(points, view_depth) -> np.ndarray:
    """The receivers among ``points``: the flat indices ``(K,)`` int64, in order, of the rows whose three
    coordinates are finite and whose view depth is not NaN.

    Parameters
    ----------
    points : array_like, shape (N, 3) or (H, W, 3), float64
        World positions in metres.
    view_depth : array_like, shape (N,) or (H, W)
        The points' view depths.
    """
    flat = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    # Component by component: np.all over a length-3 axis is ten times slower than three columns.
    finite = np.isfinite(flat[:, 0]) & np.isfinite(flat[:, 1]) & np.isfinite(flat[:, 2])
    return np.flatnonzero(finite & ~np.isnan(np.asarray(view_depth, dtype=np.float64).reshape(-1)))


def _receivers(points, normals, view_depth, *, pixels, quads: Quads | None, quad_view_depth, reads,
               rows=None) -> Receivers:
    """Step 2: the receivers among ``points`` (``rows``, else :func:`receiver_rows`), with the pixels and quads the
    filter reads."""
    p = np.asarray(points, dtype=np.float64)
    n = np.asarray(normals, dtype=np.float32)
    z = np.asarray(view_depth, dtype=np.float64)
    if p.shape[-1:] != (3,) or n.shape != p.shape or z.shape != p.shape[:-1]:
        raise ValueError(f"points, normals, view_depth: expected shapes (..., 3), (..., 3), (...); "
                         f"got {p.shape}, {n.shape}, {z.shape}")
    flat_z = z.reshape(-1)
    flat = p.reshape(-1, 3)
    index = receiver_rows(flat, flat_z) if rows is None else np.asarray(rows)
    at = None
    if "pixels" in reads:
        if pixels is None and p.ndim == 3:
            ys, xs = np.indices(p.shape[:2])
            pixels = np.stack([xs, ys], axis=-1)
        if pixels is None:
            raise ValueError("pixels: a filter rotated per pixel needs each receiver's pixel")
        at = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)[index]
    lanes = lane_depth = None
    if "mips" in reads:
        if quads is None or quad_view_depth is None:
            raise ValueError("quads, quad_view_depth: moment_mips takes its level of detail from each point's "
                             "pixel quad")
        lanes = Quads(position=quads.position.reshape(-1, 4, 3)[index], slot=quads.slot.reshape(-1)[index])
        lane_depth = np.asarray(quad_view_depth, dtype=np.float64).reshape(-1, 4)[index]
    return Receivers(points=flat, normals=n.reshape(-1, 3), index=index, view_depth=flat_z[index], pixels=at,
                     quads=lanes, quad_view_depth=lane_depth)


def _check_maps(maps: ShadowMaps, reads) -> None:
    """The maps hold what the filter reads (:func:`filter_inputs` made them under the same settings)."""
    if "moments" in reads and (maps.moments is None or not maps.depth_span > 0):
        raise ValueError("maps: a moment filter needs the moment maps and their depth span (filter_inputs)")
    if "mips" in reads and maps.mips is None:
        raise ValueError("maps: moment_mips needs the moments' mip chain (filter_inputs)")


def _selection(cascades: CascadeSet, settings: ShadowSettings, *, radius: int) -> dict:
    """The cascade-selection arguments of the selection kernel (:mod:`csmlab.kernels.shadow`).

    ``margin`` is the cascades' selection margin, widened to the filter's ``radius`` so that a
    selected box holds every tap.
    The interval selection switches cascade where ``transition`` puts the end of each band
    (:func:`csmlab.cascades.fit.transition_bands`), and each band starts at ``band_start``.
    """
    select, start = transition_bands(cascades.switch_depths, blend_band=settings.blend_band,
                                     transition=settings.transition)
    if check_name(settings.outside, OUTSIDE_METHODS, field="outside") == "last":
        # The last cascade's interval runs on past the last split (Stride, MJP).
        select[-1] = np.inf
    return dict(splits=select, texel_area=np.array([np.prod(c.texel_size) for c in cascades.cascades]),
                selection=settings.selection, blend_band=settings.blend_band, band_start=start,
                blend_curve=BLEND_CURVES[check_name(settings.blend_curve, BLEND_CURVES, field="blend_curve")][0],
                bits=settings.subtexel_bits,
                margin=max(cascades.margin_texels, radius))


def _sphere_cascades(cascades: CascadeSet, points: np.ndarray, *, device: str) -> np.ndarray:
    """``selection = "sphere"``: each point's first cascade whose split sphere holds it, −1 where none."""
    return split_sphere_cascades(points, centres=np.stack([c.sphere_centre for c in cascades.cascades]),
                                 radii=np.array([c.sphere_radius for c in cascades.cascades]), device=device)


def _dithered_cascades(cascades: CascadeSet, receivers: Receivers, cascade: np.ndarray, *,
                       settings: ShadowSettings) -> np.ndarray:
    """``selection = "sphere_dither"``: each receiver's split sphere, or the next one over its border where its
    pixel's noise is at most the border weight (:func:`csmlab.cascades.borders.dithered_sphere_cascades`)."""
    borders = settings.cascade_borders or (0.0,) * len(cascades)
    return dithered_sphere_cascades(
        cascade, receivers.points[receivers.index], centres=np.stack([c.sphere_centre for c in cascades.cascades]),
        radii=np.array([c.sphere_radius for c in cascades.cascades]), borders=borders, eye=cascades.eye,
        noise=interleaved_gradient_noise(receivers.pixels, frame=receivers.noise_frame))


def _conversion(cascades: CascadeSet, settings: ShadowSettings) -> dict:
    """What takes world receivers into the cascades' fixed point: the keyword arguments ``basis, texel_size,
    origin_fixed, zref, bias`` of :func:`csmlab.kernels.shadow.receiver_coordinates` and
    :func:`csmlab.kernels.shadow.shadow_lookup_world`, ``bias`` the :class:`csmlab.kernels.bias.BiasSettings` of
    ``settings``."""
    bits = settings.subtexel_bits
    return dict(basis=cascades.basis, texel_size=np.stack([c.texel_size for c in cascades.cascades]),
                origin_fixed=np.stack([fixed_point_origin(cascades, c, bits=bits) for c in range(len(cascades))]),
                zref=cascades.zref,
                bias=BiasSettings(normal_offset=settings.normal_offset, bias_constant=_cascade_bias(cascades, settings),
                                  bias_slope=settings.bias_slope, normal_scale=settings.normal_offset_scale,
                                  plane_offset=_plane_offset(cascades, settings),
                                  normal_offset_m=settings.normal_offset_m))


def _cascade_bias(cascades: CascadeSet, settings: ShadowSettings):
    """The constant depth bias in metres: ``bias_constant``, or per cascade ``(C,)`` with a bias model's scaling.

    ``bias_constant + bias_depth_range · (depth_far − depth_near) + bias_texels · texel`` of each
    cascade: a fraction of its light-space depth range (Godot 4's ``shadow_bias / 100 ×
    soft_shadow_scale × (z_max − z_min)``, Stride's ``DepthBias`` in normalized depth) and texels of
    it (Unity URP's depth bias, ``ShadowUtils.GetShadowBias``). Neither set: the scalar itself.
    """
    if settings.bias_depth_range == 0.0 and settings.bias_texels == 0.0:
        return settings.bias_constant
    span = np.array([c.depth_far - c.depth_near for c in cascades.cascades], dtype=np.float64)
    texel = np.array([float(np.max(c.texel_size)) for c in cascades.cascades])
    return settings.bias_constant + settings.bias_depth_range * span + settings.bias_texels * texel


def _plane_offset(cascades: CascadeSet, settings: ShadowSettings):
    """The cap in metres of MJP's static receiver-plane offset per cascade ``(C,)``: ``receiver_plane_offset`` of
    each cascade's light-space depth range (MJP: ``min(fractionalSamplingError, 0.01f)`` in normalized depth); 0:
    none."""
    if settings.receiver_plane_offset == 0.0:
        return 0.0
    return settings.receiver_plane_offset * np.array([c.depth_far - c.depth_near for c in cascades.cascades])


def texel_coordinates(cascades: CascadeSet, points: np.ndarray, normals: np.ndarray, rows: np.ndarray, *,
                      settings: ShadowSettings, device: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Step 3: ``points[rows]`` in every cascade's fixed point, moved along ``normals[rows]``.

    :func:`csmlab.texels.receiver_lookup`, bit for bit: on the device where the cascades' grid is the
    global one (float64, world-locked snapping), on the device in window space for an engine's float32
    pipeline (``engine_precision``) and window-space snapping (``vertex_snap``,
    :func:`csmlab.kernels.engine.window_receivers`) and through the homographies of warped cascades
    (``warp``, :func:`csmlab.kernels.engine.warped_receivers`); on the host only for a set that mixes
    warped and unwarped cascades.

    Returns
    -------
    coordinates : ndarray, shape (C, N, 2), int64
        In ``2**-bits`` texels of each cascade.
    depth : ndarray, shape (C, N), float32
        Biased receiver depth, metres.
    slope : ndarray, shape (C, N, 2), float64
        Receiver-plane depth change per texel, metres.
    """
    bits = settings.subtexel_bits
    if uses_global_grid(precision=settings.engine_precision, snap=settings.vertex_snap) and not cascades.warped:
        return receiver_coordinates(points, normals, receivers=rows, bits=bits, **_conversion(cascades, settings),
                                    device=device)
    conversion = _conversion(cascades, settings)
    del conversion["origin_fixed"]
    if not cascades.warped:
        return window_receivers(_window_boxes(cascades, settings, device=device), points, normals, receivers=rows,
                                **conversion, device=device)
    if all(c.warp is not None for c in cascades.cascades):
        return warped_receivers(np.stack([c.warp.homography for c in cascades.cascades]), points, normals,
                                receivers=rows, bits=bits, **conversion, device=device)
    return receiver_lookup(cascades, points[rows], normals[rows], bits=bits, normal_offset=settings.normal_offset,
                           bias_constant=_cascade_bias(cascades, settings), bias_slope=settings.bias_slope,
                           normal_scale=settings.normal_offset_scale, plane_offset=_plane_offset(cascades, settings),
                           normal_offset_m=settings.normal_offset_m,
                           precision=settings.engine_precision, snap=settings.vertex_snap,
                           rebase_distance=settings.rebase_distance)


def _window_boxes(cascades: CascadeSet, settings: ShadowSettings, *, device: str):
    """The :class:`csmlab.kernels.engine.EngineBoxes` of unwarped cascades in an engine's window space
    (``engine_precision``, ``vertex_snap``)."""
    return window_boxes(cascades, bits=settings.subtexel_bits, precision=settings.engine_precision,
                        snap=settings.vertex_snap, rebase_distance=settings.rebase_distance, device=device)


def _converted_in_kernel(maps: ShadowMaps, settings: ShadowSettings) -> str | None:
    """Where the selection kernel converts world receivers itself, into the cascades it reads only: ``"world"``
    (the global float64 grid), ``"window"`` (an engine's window space) or None (the receivers converted into every
    cascade first: warped cascades, or a cascade smaller than the maps, whose corner :func:`_selectable` marks)."""
    cascades = maps.cascades
    if cascades.warped or any(c.resolution != maps.depth.shape[1] for c in cascades.cascades):
        return None
    return "world" if uses_global_grid(precision=settings.engine_precision, snap=settings.vertex_snap) else "window"


def _window_conversion(maps: ShadowMaps, receivers: Receivers, settings: ShadowSettings, *, device: str) -> dict:
    """The keyword arguments that take ``receivers`` into window space in the selection kernel
    (:func:`csmlab.kernels.shadow.shadow_lookup_window`, :func:`csmlab.kernels.shadow.select_window_cascades`)."""
    conversion = _conversion(maps.cascades, settings)
    del conversion["origin_fixed"]
    return dict(boxes=_window_boxes(maps.cascades, settings, device=device), points=receivers.points,
                normals=receivers.normals, view_depth=receivers.view_depth, receivers=receivers.index,
                receiver_plane_bias=settings.receiver_plane_bias, **conversion)


def _selectable(coords: np.ndarray, cascades: CascadeSet, *, margin: int, bits: int, resolution: int) -> np.ndarray:
    """``coords`` ``(C, N, 2)`` with receivers outside a cascade smaller than the maps moved far outside it.

    A cascade of ``R_c < R`` texels fills the corner ``[0, R_c)²`` of its ``R × R`` map; a receiver
    less than ``margin`` texels inside that corner's edges gets ``-2**50`` there, so no selection
    picks the cascade for it and no tap reads the empty rest of the map. Equal cascades: unchanged.
    """
    coords = np.asarray(coords, dtype=np.int64)
    smaller = [c for c, cascade in enumerate(cascades.cascades) if cascade.resolution < resolution]
    if not smaller:
        return coords
    unit = 2**bits
    out = coords.copy()
    for c in smaller:
        size = cascades.cascades[c].resolution
        inside = np.all((out[c] >= margin * unit) & (out[c] < (size - margin) * unit), axis=1)
        out[c][~inside] = -2**50
    return out


def _fixed_receivers(maps: ShadowMaps, receivers: Receivers, *, selection: dict, settings: ShadowSettings,
                     device: str) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Steps 3 and the start of 4: the receivers' fixed point, selectable only inside each cascade's own corner.

    The slope is None without ``receiver_plane_bias`` (each tap compares the receiver's own depth).
    """
    cascades = maps.cascades
    coords, depth, slope = texel_coordinates(cascades, receivers.points, receivers.normals, receivers.index,
                                             settings=settings, device=device)
    coords = _selectable(coords, cascades, margin=selection["margin"], bits=settings.subtexel_bits,
                         resolution=maps.depth.shape[1])
    return coords, depth, slope if settings.receiver_plane_bias else None


def _box_lookup(maps: ShadowMaps, receivers: Receivers, *, record: Filter, radius: int, selection: dict,
                settings: ShadowSettings, device: str) -> tuple:
    """Steps 3–5 for a ``box`` filter: the selection kernel filters at the cascade it selects."""
    cascades = maps.cascades
    converted = _converted_in_kernel(maps, settings)
    if converted == "world":
        # Each receiver converted where the kernel reads it: no (C, N) arrays of every receiver in
        # every cascade (the same bits as texel_coordinates then shadow_lookup).
        return shadow_lookup_world(maps.depth, receivers.points, receivers.normals, receivers.view_depth,
                                   receivers=receivers.index, **_conversion(cascades, settings),
                                   receiver_plane_bias=settings.receiver_plane_bias, filter=record.name, radius=radius,
                                   **selection, device=device)
    if converted == "window":
        return shadow_lookup_window(maps.depth, **_window_conversion(maps, receivers, settings, device=device),
                                    filter=record.name, radius=radius, **selection, device=device)
    coords, depth, slope = _fixed_receivers(maps, receivers, selection=selection, settings=settings, device=device)
    return shadow_lookup(maps.depth, coords, depth, receivers.view_depth, filter=record.name, radius=radius,
                         receiver_slope=slope, **selection, device=device)


def _weighted_lookup(maps: ShadowMaps, receivers: Receivers, *, record: Filter, radius: int, selection: dict,
                     settings: ShadowSettings, device: str) -> tuple:
    """Steps 3–5 for a ``weighted`` filter: select, then weigh the taps at the selected cascade (and the next).

    Where the selection kernel converts receivers itself (:func:`_converted_in_kernel`), it takes each
    into the cascades it reads and hands the filter those rows only (the same bits as converting it
    into every cascade first).
    """
    converted = _converted_in_kernel(maps, settings)
    picked = converted is not None
    if converted == "world":
        chosen, weight, band, coords, depth, slope = select_world_cascades(
            maps.depth, receivers.points, receivers.normals, receivers.view_depth, receivers=receivers.index,
            **_conversion(maps.cascades, settings), receiver_plane_bias=settings.receiver_plane_bias, radius=radius,
            **selection, device=device)
    elif converted == "window":
        chosen, weight, band, coords, depth, slope = select_window_cascades(
            maps.depth, **_window_conversion(maps, receivers, settings, device=device), radius=radius, **selection,
            device=device)
    else:
        coords, depth, slope = _fixed_receivers(maps, receivers, selection=selection, settings=settings,
                                                device=device)
        chosen, weight, band = select_cascades(maps.depth, coords, depth, receivers.view_depth, radius=radius,
                                               **selection, device=device)
    # A disk rotated per pixel reads the pixels; HDRP's dithered borders read them too (sphere_dither), but
    # rotate no filter.
    angle = None if "pixels" not in record.reads_of(settings) else 2.0 * np.pi * interleaved_gradient_noise(
        receivers.pixels, frame=receivers.noise_frame)
    texel = np.array([float(np.max(c.texel_size)) for c in maps.cascades.cascades])
    lit = weighted_pcf(maps.depth, coords, depth, cascade=chosen, filter=record.name,
                       width=record.width_of(texel, settings, maps.cascades.splits[1:]), radius=radius,
                       bits=settings.subtexel_bits,
                       receiver_slope=slope, blend_weight=weight, angle=angle, disk=record.offsets_of(settings),
                       picked=picked, device=device)
    return lit, chosen.astype(np.int8), band


def _moment_lookup(maps: ShadowMaps, receivers: Receivers, *, record: Filter, radius: int, selection: dict,
                   settings: ShadowSettings, device: str) -> tuple:
    """Steps 3–5 for a ``moment`` filter: select, then bound the filtered moments at the selected cascade."""
    coords, depth, _ = _fixed_receivers(maps, receivers, selection=selection, settings=settings, device=device)
    chosen, weight, band = select_cascades(maps.depth, coords, depth, receivers.view_depth, radius=radius,
                                           **selection, device=device)
    bound = dict(method=record.name, span=maps.depth_span, bits=settings.subtexel_bits,
                 exponents=settings.evsm_exponents, min_variance=settings.vsm_min_variance,
                 moment_bias=settings.msm_moment_bias, depth_bias=settings.msm_depth_bias, power=settings.vsm_power,
                 bleed=settings.vsm_bleed, device=device)
    if "mips" not in record.reads_of(settings):
        lit = moment_lookup(maps.moments, coords, depth, cascade=chosen, blend_weight=weight, **bound)
        return lit, chosen.astype(np.int8), band
    used, ddx, ddy = _quad_footprint(maps, receivers, coords, chosen, radius=radius, selection=selection,
                                     settings=settings, device=device)
    # The blend band needs both samples at the cascades the receiver selected.
    band &= used == chosen
    weight = np.where(band, weight, 0.0)
    lit = moment_mip_lookup(maps.mips, coords, depth, origin_texels=_box_origins(maps.cascades, settings),
                            cascade=used, ddx=ddx, ddy=ddy, anisotropy=settings.anisotropy, blend_weight=weight,
                            **bound)
    return lit, used.astype(np.int8), band


def _quad_footprint(maps: ShadowMaps, receivers: Receivers, coords: np.ndarray, chosen: np.ndarray, *, radius: int,
                    selection: dict, settings: ShadowSettings, device: str) -> tuple:
    """The cascade a mip lookup reads and the quad's derivatives there (:func:`csmlab.quads.quad_derivatives`).

    The lanes go through the same coordinates as their receiver (same precision, same grid), so
    their differences are the quad's derivatives; each lane selects its own cascade by the same
    rules (without the filter's radius: a lane is looked up by no tap), the receiver's lane takes
    the receiver's selection.
    """
    cascades = maps.cascades
    count, n = len(cascades), receivers.index.shape[0]
    lane_points = receivers.quads.position.reshape(-1, 3)
    lane_coords, lane_depth, _ = texel_coordinates(cascades, lane_points, np.repeat(receivers.normals[receivers.index],
                                                                                     4, axis=0),
                                                   np.arange(len(lane_points)), settings=settings, device=device)
    flat = _selectable(lane_coords, cascades, margin=selection["margin"], bits=settings.subtexel_bits,
                       resolution=maps.depth.shape[1])
    lanes = dict(selection)
    if "sphere_cascade" in selection:
        lanes["sphere_cascade"] = _sphere_cascades(cascades, lane_points, device=device)
    lane_chosen, _, _ = select_cascades(maps.depth, flat, lane_depth, receivers.quad_view_depth.reshape(-1),
                                        radius=0, **lanes, device=device)
    lane_cascade = lane_chosen.astype(np.int64).reshape(n, 4)
    lane_cascade[np.arange(n), receivers.quads.slot.astype(np.int64)] = chosen
    unit = 2**settings.subtexel_bits
    top = maps.depth.shape[1]
    # Which boxes hold the receiver's taps (quad_consistent moves a receiver only into such a box).
    holds = np.all((coords >= radius * unit) & (coords < (top - radius) * unit), axis=2)
    return quad_derivatives(lane_coords.reshape(count, n, 4, 2), lane_cascade, chosen, method=settings.lod,
                            bits=settings.subtexel_bits, holds=holds)


FAMILY_LOOKUPS = {"box": _box_lookup, "weighted": _weighted_lookup, "moment": _moment_lookup}
"""Steps 3–5 of :func:`lookup_shadow` by filter family (:data:`csmlab.lookup_choices.FAMILIES`).

Each takes the maps, the :class:`Receivers`, the filter's record and radius, the selection's
arguments, the settings and the device, and returns ``(lit, cascade, blend)`` of the receivers.
"""


def _shadow_of_points(found: tuple, receivers: Receivers, view_depth: np.ndarray, *, settings: ShadowSettings,
                      far: float, eye=None) -> ShadowLookup:
    """Step 6: the :class:`ShadowLookup` of every point (shaped like ``view_depth``), faded toward ``far``."""
    shape = view_depth.shape
    index = receivers.index
    # Each in the points' array type before a scatter, which would otherwise cast element by element.
    lit, cascade, blend = (np.asarray(a).astype(t, copy=False) for a, t in zip(found, (np.float32, np.int8, bool)))
    if index.size < view_depth.size:
        lit, cascade, blend = (_scattered(a, index, size=view_depth.size, fill=f)
                               for a, f in ((lit, np.nan), (cascade, -1), (blend, False)))
    # Else every point is a receiver, their rows in order (0 … N − 1, as the temporal lookup's visible points are):
    # the receivers' results are the points'.
    if settings.outside == "lit":
        # Bevy returns 1.0 for a point no cascade holds.
        lit[index] = np.where(cascade[index] < 0, np.float32(1.0), lit[index])
    if settings.fade_out > 0.0:
        radial = None
        if FADE_METHODS[check_name(settings.fade, FADE_METHODS, field="fade")].radial:
            radial = np.linalg.norm(receivers.points[index] - eye, axis=1)
        lit[index], fading = faded(lit[index], receivers.view_depth, far=far, fade_out=settings.fade_out,
                                   fade=settings.fade, distance=radial)
        # Like a blend band, the fade weight follows the camera: the temporal metric counts these
        # points with the transitions, not with same-cascade swimming.
        blend[index] |= fading
    return ShadowLookup(lit=lit.reshape(shape), cascade=cascade.reshape(shape), blend=blend.reshape(shape))


def _scattered(values: np.ndarray, index: np.ndarray, *, size: int, fill) -> np.ndarray:
    """``values`` at rows ``index`` of an array of ``size`` rows of their type, ``fill`` elsewhere."""
    out = np.full(size, fill, dtype=values.dtype)
    out[index] = values
    return out


def _box_origins(cascades: CascadeSet, settings: ShadowSettings) -> np.ndarray:
    """Each box's texel (0, 0) as a global texel index ``(C, 2)`` int64 (the grid a mip chain is anchored to)."""
    bits = settings.subtexel_bits
    return np.stack([fixed_point_origin(cascades, c, bits=bits) for c in range(len(cascades))]) >> bits


def filter_inputs(depth, cascades: CascadeSet, *, span: float, settings: ShadowSettings,
                  device: str = "cpu") -> tuple[np.ndarray | None, list | None]:
    """What the filter reads besides the depth maps, taken once per frame in the cascade pass.

    Parameters
    ----------
    depth : array_like, shape (C, R, R), float32
        The stored depth maps, metres.
    cascades : CascadeSet
    span : float
        The scene's light-space depth range in metres the moments are normalized over.
    settings : ShadowSettings
    device : str

    Returns
    -------
    moments : ndarray, shape (C, R, R, 4), float32, or None
        The blurred moment maps of a moment filter (:mod:`csmlab.kernels.moments`); None for the others.
    mips : list of ndarray, or None
        With ``moment_mips``, their mip chain on the global texel grid; else None.
    """
    record = FILTER_METHODS[check_name(settings.filter, FILTER_METHODS, field="filter")]
    reads = record.reads_of(settings)
    if "moments" not in reads:
        return None, None
    moments = moment_maps(depth, span=span, method=record.name, exponents=settings.evsm_exponents, device=device)
    moments = blur_moments(moments, radius=settings.moment_blur // 2, device=device)
    if "mips" not in reads:
        return moments, None
    return moments, moment_mip_chain(moments, origin_texels=_box_origins(cascades, settings), max_lod=settings.max_lod,
                                     device=device)


def uses_pixels(settings: ShadowSettings) -> bool:
    """Whether :func:`lookup_shadow` under ``settings`` reads each receiver's pixel (a per-pixel rotation, or
    ``selection = "sphere_dither"``'s noise)."""
    return settings.selection == "sphere_dither" or "pixels" in FILTER_METHODS[
        check_name(settings.filter, FILTER_METHODS, field="filter")].reads_of(settings)


def noise_frame(settings: ShadowSettings, *, frame: int, taa: bool) -> int:
    """The frame term of the rotation noise of frame ``frame`` under ``settings.poisson_rotation``.

    ``frame mod 64`` for ``pixel_frame``, and for ``pixel_taa`` where ``taa`` (the view is
    rendered for temporal anti-aliasing, ``View.jitter`` set); 0 otherwise (the same noise every
    frame). Bevy takes ``frame_count % 64`` (utils.wesl ``interleaved_gradient_noise``, @4805ca7).
    """
    if settings.poisson_rotation == "pixel_frame" or (settings.poisson_rotation == "pixel_taa" and taa):
        return int(frame) % 64
    return 0


def interleaved_gradient_noise(pixels, *, frame: int = 0) -> np.ndarray:
    """Jimenez's interleaved gradient noise in [0, 1) at integer pixel positions ``(..., 2)`` (x, y).

    ``fract(52.9829189 · fract(0.06711056 x + 0.00583715 y))`` (Jimenez, "Next Generation
    Post Processing in Call of Duty: Advanced Warfare", SIGGRAPH 2014): the per-pixel rotation
    engines give a Poisson disk before temporal anti-aliasing. ``frame`` (:func:`noise_frame`)
    moves the pixel by ``5.588238 · frame`` along both axes first, as Bevy's temporal filter does,
    so that the pattern changes every frame and TAA averages the rotations.
    """
    p = np.floor(np.asarray(pixels, dtype=np.float64)) + 5.588238 * frame
    inner = 0.06711056 * p[..., 0] + 0.00583715 * p[..., 1]
    inner -= np.floor(inner)
    out = 52.9829189 * inner
    return out - np.floor(out)


def screen_pixels(pose: CameraPose, points, *, width: int, height: int, jitter=None) -> np.ndarray:
    """Pixel positions ``(..., 2)`` (x = column, y = row, row 0 at the top) of world points ``(..., 3)`` under ``pose``.

    Where the camera of frame t−1 saw frame t's points: the screen-space noise of a per-pixel
    rotation moves with the camera, not with the world. ``jitter`` ``(x, y)`` in pixels: the
    frame's sub-pixel camera jitter (``View.jitter``; pixel ``(col, row)`` sampled the image point
    ``(col + ½ + x, row + ½ + y)``), so the point lies at its pixel of the jittered image.
    """
    local = (np.asarray(points, dtype=np.float64) - pose.position) @ pose.rotation
    depth = -local[..., 2]
    tan_y = np.tan(np.radians(pose.fov_y_deg) / 2.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        x = (local[..., 0] / (depth * tan_y * pose.aspect) + 1.0) * 0.5 * width
        y = (1.0 - local[..., 1] / (depth * tan_y)) * 0.5 * height
    if jitter is not None:
        x, y = x - jitter[0], y - jitter[1]
    return np.stack([x, y], axis=-1)
