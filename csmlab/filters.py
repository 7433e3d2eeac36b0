"""Every shadow filter by name, the texels each reads, and the lookup that dispatches to its kernel.

:data:`FILTER_METHODS` (:mod:`csmlab.lookup_choices`) maps a ``[shadow] filter`` name to what it is. The box filters ``none``,
``pcf`` and ``pcf_bilinear`` run inside :func:`csmlab.kernels.shadow.shadow_lookup` with the
cascade selection; the weighted PCF filters (:mod:`csmlab.kernels.pcf`) run after it: the
selection is made with the filter's tap radius (so no tap is ever clamped, DESIGN.md "Exact
zero"), then one launch filters each receiver at its cascade and, in a blend band, at the next.

Width per cascade (:func:`filter_widths`): in texels from ``filter_size`` / ``filter_sigma``, or,
with ``filter_width_m > 0``, the same width in metres in every cascade (Unigine's filter width;
seed 003, "self-adjusting filtering kernel size", Listing 4.1.8), i.e. ``filter_width_m / texel``
texels, capped at the taps ``filter_size`` allows. ``pcss`` turns the light's angular diameter into
penumbra texels per metre of blocker distance, ``2 tan(θ_L / 2) / texel``.
"""

from __future__ import annotations

import functools

import numpy as np

from csmlab.camera import CameraPose
from csmlab.cascades import CascadeSet
from csmlab.kernels.moments import blur_moments, moment_lookup, moment_maps, moment_mip_chain, moment_mip_lookup
from csmlab.kernels.pcf import weighted_pcf
from csmlab.kernels.shadow import shadow_lookup, shadow_lookup_world
from csmlab.lookup_choices import FILTER_METHODS, MOMENT_METHODS, PCF_KERNELS, filter_radius
from csmlab.quads import quad_derivatives
from csmlab.settings import ShadowSettings
from csmlab.texels import fixed_point_origin

__all__ = ["FILTER_METHODS", "box_texel_origins", "filter_mips", "filter_moments", "filter_radius", "filter_widths",
           "filtered_shadow_lookup", "interleaved_gradient_noise", "looks_up_world_receivers", "poisson_disk",
           "receiver_conversion", "screen_pixels", "uses_pixels", "world_shadow_lookup"]

def filter_widths(cascades: CascadeSet, settings: ShadowSettings) -> np.ndarray:
    """The ``width`` of :func:`csmlab.kernels.pcf.weighted_pcf` per cascade ``(C,)`` float64.

    Texel size is the larger side of each cascade's texels (the one the depth bias uses too).
    """
    texel = np.array([float(np.max(c.texel_size)) for c in cascades.cascades])
    half = settings.filter_size / 2.0
    if settings.filter == "pcss":
        return np.full(texel.shape, 2.0 * np.tan(np.radians(settings.light_size_deg) / 2.0)) / texel
    if settings.filter == "pcf_gaussian":
        if settings.filter_width_m > 0:
            return settings.filter_width_m / 4.0 / texel
        return np.full(texel.shape, settings.filter_sigma)
    if settings.filter_width_m > 0:
        # A width of zero texels is no filter; the narrowest kept is a hundredth of a texel.
        return np.clip(settings.filter_width_m / 2.0 / texel, 0.01, half)
    return np.full(texel.shape, half)


@functools.lru_cache(maxsize=16)
def _disk(taps: int, seed: int) -> tuple:
    rng = np.random.default_rng(seed)
    points = np.zeros((0, 2))
    for _ in range(taps):
        # Mitchell's best candidate: of 30 uniform candidates in the disk, keep the one farthest
        # from the taps so far — a blue-noise (Poisson-disk-like) set, fixed by the seed.
        r = np.sqrt(rng.random(30))
        a = 2.0 * np.pi * rng.random(30)
        candidates = np.column_stack([r * np.cos(a), r * np.sin(a)])
        if len(points):
            gap = np.min(np.linalg.norm(candidates[:, None] - points[None], axis=2), axis=1)
            best = candidates[np.argmax(gap)]
        else:
            best = candidates[0]
        points = np.vstack([points, best])
    return tuple(map(tuple, points))


def poisson_disk(taps: int, *, seed: int) -> np.ndarray:
    """A fixed Poisson-disk-like set of ``taps`` offsets ``(taps, 2)`` in the unit disk, the same for the same seed."""
    if not (isinstance(taps, (int, np.integer)) and taps >= 1):
        raise ValueError(f"taps: expected a positive integer, got {taps!r}")
    return np.array(_disk(int(taps), int(seed)), dtype=np.float64)


def interleaved_gradient_noise(pixels) -> np.ndarray:
    """Jimenez's interleaved gradient noise in [0, 1) at integer pixel positions ``(..., 2)`` (x, y).

    ``fract(52.9829189 · fract(0.06711056 x + 0.00583715 y))`` (Jimenez, "Next Generation
    Post Processing in Call of Duty: Advanced Warfare", SIGGRAPH 2014): the per-pixel rotation
    engines give a Poisson disk before temporal anti-aliasing.
    """
    p = np.floor(np.asarray(pixels, dtype=np.float64))
    inner = 0.06711056 * p[..., 0] + 0.00583715 * p[..., 1]
    inner -= np.floor(inner)
    out = 52.9829189 * inner
    return out - np.floor(out)


def filter_moments(depth, *, span: float, settings: ShadowSettings, device: str = "cpu") -> np.ndarray | None:
    """The blurred moment maps ``(C, R, R, 4)`` float32 a moment filter looks up; None for the other filters.

    Taken in the cascade pass, once per frame, from the stored depth normalized over ``span`` metres.
    """
    if settings.filter not in MOMENT_METHODS:
        return None
    moments = moment_maps(depth, span=span, method=settings.filter, exponents=settings.evsm_exponents, device=device)
    return blur_moments(moments, radius=settings.moment_blur // 2, device=device)


def box_texel_origins(cascades: CascadeSet, *, bits: int) -> np.ndarray:
    """Each box's texel (0, 0) as a global texel index ``(C, 2)`` int64 (the grid a mip chain is anchored to)."""
    return np.stack([fixed_point_origin(cascades, c, bits=bits) for c in range(len(cascades))]) >> bits


def filter_mips(moments, cascades: CascadeSet, *, settings: ShadowSettings, device: str = "cpu") -> list | None:
    """The moments' mip chain (:func:`csmlab.kernels.moments.moment_mip_chain`) with ``moment_mips``; else None."""
    if moments is None or not settings.moment_mips:
        return None
    return moment_mip_chain(moments, origin=box_texel_origins(cascades, bits=settings.subtexel_bits),
                            max_lod=settings.max_lod, device=device)


def uses_pixels(settings: ShadowSettings) -> bool:
    """Whether :func:`filtered_shadow_lookup` under ``settings`` reads each receiver's pixel (a per-pixel rotation)."""
    return settings.filter == "pcf_poisson" and settings.poisson_rotation == "pixel"


def screen_pixels(pose: CameraPose, points, *, width: int, height: int) -> np.ndarray:
    """Pixel positions ``(..., 2)`` (x = column, y = row, row 0 at the top) of world points ``(..., 3)`` under ``pose``.

    Where the camera of frame t−1 saw frame t's points: the screen-space noise of a per-pixel
    rotation moves with the camera, not with the world.
    """
    local = (np.asarray(points, dtype=np.float64) - pose.position) @ pose.rotation
    depth = -local[..., 2]
    tan_y = np.tan(np.radians(pose.fov_y_deg) / 2.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        x = (local[..., 0] / (depth * tan_y * pose.aspect) + 1.0) * 0.5 * width
        y = (1.0 - local[..., 1] / (depth * tan_y)) * 0.5 * height
    return np.stack([x, y], axis=-1)


def _holds(coords: np.ndarray, unit: int, inset: int, resolution: int) -> np.ndarray:
    """``(C, N)``: the point lies ``inset`` texels inside each box on both axes (fixed point)."""
    return np.all((coords >= inset * unit) & (coords < (resolution - inset) * unit), axis=2)


def _outside_smaller_boxes(coords: np.ndarray, cascades: CascadeSet, *, unit: int, inset: int,
                           resolution: int) -> np.ndarray:
    """``coords`` with receivers outside a cascade smaller than the maps moved far outside it.

    A cascade of ``R_c < R`` texels fills the corner ``[0, R_c)²`` of its ``R × R`` map; a receiver
    less than ``inset`` texels inside that corner's edges gets ``-2**50`` there, so no selection
    picks the cascade for it and no tap reads the empty rest of the map. Equal cascades: unchanged.
    """
    smaller = [c for c, cascade in enumerate(cascades.cascades) if cascade.resolution < resolution]
    if not smaller:
        return coords
    out = coords.copy()
    for c in smaller:
        size = cascades.cascades[c].resolution
        inside = np.all((out[c] >= inset * unit) & (out[c] < (size - inset) * unit), axis=1)
        out[c][~inside] = -2**50
    return out


def _selection_parameters(cascades: CascadeSet, settings: ShadowSettings) -> dict:
    """The cascade-selection arguments of :func:`csmlab.kernels.shadow.shadow_lookup` for ``settings``.

    ``margin`` is the cascades' selection margin, widened to the filter's tap radius
    (``margin_texels - 1``) so that a selected box holds every tap.
    """
    return dict(splits=cascades.splits, texel_area=np.array([np.prod(c.texel_size) for c in cascades.cascades]),
                selection=settings.selection, blend_band=settings.blend_band, bits=settings.subtexel_bits,
                margin=max(cascades.margin_texels, settings.margin_texels - 1))


def looks_up_world_receivers(cascades: CascadeSet, settings: ShadowSettings, *, resolution: int) -> bool:
    """Whether :func:`world_shadow_lookup` serves ``settings``: a box filter over equal cascades in float64 math.

    The other filters read every receiver in its selected cascade again after the selection, an
    engine's float32 math converts receivers on the host, and a cascade smaller than the maps
    needs its receivers moved out of the empty rest of its map: those take the converted
    receivers of :func:`filtered_shadow_lookup`.
    """
    return (settings.filter not in PCF_KERNELS and settings.filter not in MOMENT_METHODS
            and settings.engine_precision == "float64"
            and all(c.resolution == resolution for c in cascades.cascades))


def world_shadow_lookup(depth, points, normals, view_depth, *, receivers, cascades: CascadeSet,
                        settings: ShadowSettings, device: str = "cpu") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`filtered_shadow_lookup` of world receivers, where :func:`looks_up_world_receivers` holds.

    Parameters
    ----------
    depth : array_like, shape (C, R, R), float32
    points, normals : array_like, shape (M, 3)
        World positions (float64, metres) and unit normals (float32).
    view_depth : array_like, shape (N,)
        View depth of each receiver under the selecting camera.
    receivers : array_like, shape (N,), int
        The rows of ``points`` that are receivers.
    cascades : CascadeSet
    settings : ShadowSettings
    device : str

    Returns
    -------
    lit, cascade, blend
        As :func:`filtered_shadow_lookup`, the same bits.
    """
    return shadow_lookup_world(
        depth, points, normals, view_depth, receivers=receivers, **receiver_conversion(cascades, settings),
        receiver_plane_bias=settings.receiver_plane_bias, filter=settings.filter, filter_size=settings.filter_size,
        **_selection_parameters(cascades, settings), device=device)


def receiver_conversion(cascades: CascadeSet, settings: ShadowSettings) -> dict:
    """What takes world receivers into the cascades' fixed point, sub-texel bits apart.

    The keyword arguments ``basis, texel_size, origin, zref, normal_offset, bias_constant,
    bias_slope`` of :func:`csmlab.kernels.shadow.receiver_coordinates` and
    :func:`csmlab.kernels.shadow.shadow_lookup_world`.
    """
    bits = settings.subtexel_bits
    return dict(basis=cascades.basis, texel_size=np.stack([c.texel_size for c in cascades.cascades]),
                origin=np.stack([fixed_point_origin(cascades, c, bits=bits) for c in range(len(cascades))]),
                zref=cascades.zref, normal_offset=settings.normal_offset, bias_constant=settings.bias_constant,
                bias_slope=settings.bias_slope)


def filtered_shadow_lookup(depth, coords, receiver_depth, view_depth, *, cascades: CascadeSet,
                           settings: ShadowSettings, receiver_slope=None, pixels=None, moments=None,
                           span: float = 0.0, mips=None, lanes=None,
                           device: str = "cpu") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Lit fraction S, selected cascade and blend flag of receivers under ``settings.filter``.

    Parameters
    ----------
    depth, coords, receiver_depth, view_depth, receiver_slope
        As :func:`csmlab.kernels.shadow.shadow_lookup`: ``(C, R, R)`` float32 maps, ``(C, N, 2)``
        int64 fixed-point receivers, ``(C, N)`` float32 biased depths, ``(N,)`` view depths,
        ``(C, N, 2)`` receiver-plane slopes or None.
    cascades : CascadeSet
        Splits, texel sizes and the selection margin.
    settings : ShadowSettings
        Selection, filter and its parameters, blend band, sub-texel bits.
    pixels : array_like, shape (N, 2), optional
        Each receiver's pixel (x = column, y = row) in the image of the camera being shaded; needed
        by ``poisson_rotation = "pixel"`` only.
    moments : array_like, shape (C, R, R, 4), float32, optional
        The moment filters' maps (:func:`filter_moments`).
    span : float
        Depth range in metres the moments were taken over.
    mips : list of ndarray, optional
        ``moment_mips``: the moments' mip chain (:func:`filter_mips`).
    lanes : tuple, optional
        ``moment_mips``: each receiver's quad (:mod:`csmlab.quads`) as ``(coords, receiver_depth,
        view_depth, slot)`` of shapes ``(C, N, 4, 2)`` int64, ``(C, N, 4)`` float32, ``(N, 4)`` and
        ``(N,)``: the lanes' fixed-point coordinates and biased depths (as ``coords`` and
        ``receiver_depth``), their view depths under the selecting camera, and which lane is the
        receiver itself.
    device : str
        ``"cpu"`` or ``"cuda"``.

    Returns
    -------
    lit : ndarray, shape (N,), float32
        S in [0, 1]; NaN where no cascade holds the receiver and every tap.
    cascade : ndarray, shape (N,), int8
    blend : ndarray, shape (N,), bool

    Raises
    ------
    ValueError
        On an unknown filter, or a per-pixel rotation without ``pixels``.
    """
    filter = settings.filter
    radius = settings.margin_texels - 1
    bits = settings.subtexel_bits
    common = dict(**_selection_parameters(cascades, settings), receiver_slope=receiver_slope, device=device)
    margin = common["margin"]
    coords = _outside_smaller_boxes(np.asarray(coords, dtype=np.int64), cascades, unit=2**bits, inset=margin,
                                    resolution=np.shape(depth)[1])
    if filter not in PCF_KERNELS and filter not in MOMENT_METHODS:
        return shadow_lookup(depth, coords, receiver_depth, view_depth, filter=filter,
                             filter_size=settings.filter_size, **common)
    # Selection first (one tap), with the filter's radius as margin; then the taps-inside rule of
    # shadow_lookup for this filter's radius, and the blend band toward a next cascade that holds them.
    _, chosen, _ = shadow_lookup(depth, coords, receiver_depth, view_depth, filter="none", filter_size=1, **common)
    xy = coords
    unit = 2**bits
    count, resolution = depth.shape[0], depth.shape[1]
    holds = _holds(xy, unit, radius, resolution)
    n = chosen.shape[0]
    index = np.arange(n)
    cascade = np.where(chosen >= 0, chosen, 0).astype(np.int64)
    chosen = np.where((chosen >= 0) & holds[cascade, index], chosen, -1).astype(np.int32)
    weight = np.zeros(n)
    band = np.zeros(n, dtype=bool)
    z = np.asarray(view_depth, dtype=np.float64)
    if settings.blend_band > 0:
        splits = np.asarray(cascades.splits, dtype=np.float64)
        nxt = np.minimum(cascade + 1, count - 1)
        z1 = splits[cascade + 1]
        start = z1 - settings.blend_band * (z1 - splits[cascade])
        band = (chosen >= 0) & (cascade + 1 < count) & (z >= start) & (z < z1) & holds[nxt, index]
        weight[band] = (z[band] - start[band]) / (z1[band] - start[band])
    if filter in MOMENT_METHODS and settings.moment_mips:
        if mips is None or lanes is None or not span > 0:
            raise ValueError("mips, lanes, span: moment_mips needs the mip chain, each receiver's quad and the span")
        lane_coords, lane_depth, lane_view_depth, slot = lanes
        lane_coords = np.asarray(lane_coords, dtype=np.int64)
        flat = lane_coords.reshape(count, -1, 2)
        _, lane_chosen, _ = shadow_lookup(depth, _outside_smaller_boxes(flat, cascades, unit=unit, inset=margin,
                                                                        resolution=resolution),
                                          np.asarray(lane_depth, dtype=np.float32).reshape(count, -1),
                                          np.asarray(lane_view_depth, dtype=np.float64).reshape(-1), filter="none",
                                          filter_size=1, **{**common, "receiver_slope": None})
        lane_cascade = lane_chosen.astype(np.int64).reshape(n, 4)
        lane_cascade[index, np.asarray(slot, dtype=np.int64)] = chosen
        used, ddx, ddy = quad_derivatives(lane_coords, lane_cascade, chosen, method=settings.lod, bits=bits,
                                          holds=holds)
        band &= used == chosen
        weight = np.where(band, weight, 0.0)
        lit = moment_mip_lookup(mips, xy, receiver_depth, origin=box_texel_origins(cascades, bits=bits), cascade=used,
                                ddx=ddx, ddy=ddy, method=filter, span=span, bits=bits, anisotropy=settings.anisotropy,
                                exponents=settings.evsm_exponents, min_variance=settings.vsm_min_variance,
                                power=settings.vsm_power, bleed=settings.vsm_bleed, blend_weight=weight,
                                device=device)
        return lit, used.astype(np.int8), band
    if filter in MOMENT_METHODS:
        if moments is None or not span > 0:
            raise ValueError(f"moments, span: filter {filter!r} needs the moment maps and their depth span")
        lit = moment_lookup(moments, xy, receiver_depth, cascade=chosen, method=filter, span=span, bits=bits,
                            exponents=settings.evsm_exponents, min_variance=settings.vsm_min_variance,
                            power=settings.vsm_power, bleed=settings.vsm_bleed, blend_weight=weight, device=device)
        return lit, chosen.astype(np.int8), band
    angle = None
    if uses_pixels(settings):
        if pixels is None:
            raise ValueError("pixels: poisson_rotation = 'pixel' needs each receiver's pixel")
        angle = 2.0 * np.pi * interleaved_gradient_noise(pixels)
    disk = poisson_disk(settings.poisson_taps, seed=settings.poisson_seed) if filter == "pcf_poisson" else None
    lit = weighted_pcf(depth, xy, receiver_depth, cascade=chosen, filter=filter,
                       width=filter_widths(cascades, settings), radius=radius, bits=bits,
                       receiver_slope=receiver_slope, blend_weight=weight, angle=angle, disk=disk, device=device)
    return lit, chosen.astype(np.int8), band
