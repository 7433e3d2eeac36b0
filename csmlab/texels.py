"""World points to a cascade's texel grid: texel coordinates, fixed point, receiver lookups.

Everything here is host float64 NumPy and feeds the Warp kernels (docs/design.md, "Exact zero by
construction"). A world point X has light-space coordinates ``(right·X, up·X)`` in metres; divided
by a cascade's texel size they become *global* texel units, which depend on the light direction
and the texel size only — never on where the box lies. Snapped to ``2**bits`` steps per texel they
become int64 fixed point; subtracting the box origin (an integer number of texels for the exact
and quantized stabilizations) gives the local coordinates a kernel sees. Moving a box by k whole
texels then shifts every local coordinate by exactly ``k · 2**bits`` and changes no rounding.

Units: texel coordinates are in texels of the cascade, texel ``(i, j)`` spanning ``[i, i + 1)`` ×
``[j, j + 1)``, its centre at ``(i + ½, j + ½)``; fixed-point coordinates are in ``2**-bits``
texels; depths are metres along the light direction, ``d·X − zref``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from csmlab.cascades import CascadeSet
from csmlab.cascades.warp import warped_texel_jacobian, warped_texels
from csmlab.lookup_choices import NORMAL_NONE, NORMAL_OFFSET_SCALES, NORMAL_ONE_MINUS_COS_LATERAL, NORMAL_SIN
from csmlab.registry import check_name

__all__ = ["PRECISION_METHODS", "Precision", "fixed_point_coordinates", "fixed_point_origin", "light_depth",
           "light_plane_coordinates", "receiver_lookup", "texel_coordinates"]


@dataclass(frozen=True)
class Precision:
    """How world points reach a cascade's texel grid.

    Attributes
    ----------
    description : str
    global_grid : bool
        Texel coordinates are *global* float64 texel coordinates less an integer origin, so a
        kernel handed light-space coordinates finishes the conversion itself with the same bits
        (the depth pass, :mod:`csmlab.kernels.raster`; the receivers,
        :func:`csmlab.kernels.shadow.receiver_coordinates`). False: only the host functions here
        convert.
    """

    description: str
    global_grid: bool


PRECISION_METHODS: dict[str, Precision] = {
    "float64": Precision("global texel coordinates in float64, less an integer origin: world-locked at any distance",
                         global_grid=True),
    "float32": Precision("an engine's float32 light view (eye at the box centre) and projection applied to float32 "
                         "positions", global_grid=False),
}
"""How world points reach a cascade's texel grid (``[shadow] engine_precision``), by name.

``float32`` emulates an engine that places each cascade's light eye at the box centre and applies
its view and projection in float32, as a vertex shader does: the eye's rounding depends on where
the box lies, so far from the origin (10⁶ m: a float32 step of 6 cm) a box moved by whole texels
moves its texel grid by a fraction of a texel, and the shadow swims although the box is snapped.
"""

# Global fixed-point values are clipped to ±2**50 so that, less a box origin, doubled and
# differenced in the rasterizer (which takes ±2**52), they can neither overflow int64 nor lose
# determinism; only geometry over 10**10 texels from the world origin reaches the clip.
_FIXED_LIMIT = float(2**50)
_MAX_TAN = 10.0


def _light_space(points: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """``points (..., 3)`` projected on each of ``rows (K, 3)``: ``(..., K)`` float64.

    Summed as ``(x·r_x + z·r_z) + y·r_y``, one rounding per operation, stated so that the receiver
    kernel (:func:`csmlab.kernels.shadow.receiver_coordinates`) can repeat it bit for bit (it is
    also the order NumPy's einsum used here before). Elementwise rather than a BLAS product: BLAS
    threads spin when the process pool already keeps every core busy, and fused multiply-adds
    would change the bits.
    """
    x, y, z = points[..., 0, None], points[..., 1, None], points[..., 2, None]
    return (x * rows[:, 0] + z * rows[:, 2]) + y * rows[:, 1]


def light_plane_coordinates(cascades: CascadeSet, points) -> np.ndarray:
    """Light-space x/y ``(..., 2)`` float64 in metres of world points ``(..., 3)``.

    Divided by a cascade's texel size this is exactly the global texel coordinate that
    :func:`fixed_point_coordinates` snaps (the same operations in the same order), so a kernel
    that finishes the conversion on the device gives the same fixed-point values.
    """
    return _light_space(np.asarray(points, dtype=np.float64), cascades.basis[:2])


def _warped(cascades: CascadeSet, index: int) -> bool:
    """Whether cascade ``index`` (checked) is perspective-warped."""
    if not 0 <= index < len(cascades):
        raise ValueError(f"cascade index: expected 0..{len(cascades) - 1}, got {index}")
    return cascades.cascades[index].warp is not None


def _global_texels(cascades: CascadeSet, index: int, points) -> np.ndarray:
    if not 0 <= index < len(cascades):
        raise ValueError(f"cascade index: expected 0..{len(cascades) - 1}, got {index}")
    p = np.asarray(points, dtype=np.float64)
    if p.shape[-1:] != (3,):
        raise ValueError(f"points: expected world positions of shape (..., 3), got {p.shape}")
    return _light_space(p, cascades.basis[:2]) / cascades.cascades[index].texel_size


def _snapped(u: np.ndarray) -> np.ndarray:
    """Global fixed-point values (overwritten) rounded to int64, half to even; NaN far outside."""
    np.clip(u, -_FIXED_LIMIT, _FIXED_LIMIT, out=u)
    np.rint(u, out=u)
    u[np.isnan(u)] = -_FIXED_LIMIT
    return u.astype(np.int64)


def fixed_point_origin(cascades: CascadeSet, index: int, *, bits: int) -> np.ndarray:
    """Cascade ``index``'s box origin ``(2,)`` int64 in ``2**-bits`` texels.

    Exact for the integer origins of the exact and quantized stabilizations; a fractional origin
    (``none``) is rounded to the grid, which moves that box by at most half a grid step.
    """
    return np.rint(cascades.cascades[index].origin * float(2**bits)).astype(np.int64)


def texel_coordinates(cascades: CascadeSet, index: int, points) -> np.ndarray:
    """Texel coordinates ``(..., 2)`` float64 of world points in cascade ``index``.

    Parameters
    ----------
    cascades : CascadeSet
    index : int
        The cascade.
    points : array_like, shape (..., 3)
        World positions in metres.

    Returns
    -------
    ndarray, shape (..., 2), float64
        Light-space x/y in texels relative to the box's minimum corner: texel ``(i, j)`` spans
        ``[i, i + 1) × [j, j + 1)`` (through the homography for a warped cascade). Not snapped to
        the fixed-point grid. For a fractional
        origin (``none``) the rasterizer's grid sits up to half a fixed-point step from this one
        (see :func:`fixed_point_origin`).
    """
    if _warped(cascades, index):
        return _local_texels_warped(cascades, index, points)
    return _global_texels(cascades, index, points) - cascades.cascades[index].origin


def _local_texels_float32(cascades: CascadeSet, index: int, points) -> np.ndarray:
    """Local texel coordinates ``(..., 2)`` as an engine's float32 light view and projection give them.

    The light's eye sits at the (snapped) box centre; the engine stores it as a float32 world
    position, subtracts it from float32 world positions, rotates into light space and scales to
    texels, all in float32. Far from the origin the eye's float32 rounding (6 cm at 10⁶ m) differs
    from one snapped box position to the next, so the texel grid slides by fractions of a texel.
    """
    cascade = cascades.cascades[index]
    half = 0.5 * cascade.resolution
    centre = np.array([*((cascade.origin + half) * cascade.texel_size), cascade.depth_near])
    eye = (cascades.basis.T @ centre).astype(np.float32)
    rows = cascades.basis[:2].astype(np.float32)
    p = np.asarray(points, dtype=np.float64).astype(np.float32) - eye
    u = np.einsum("...k,jk->...j", p, rows, dtype=np.float32)
    u /= cascade.texel_size.astype(np.float32)
    u += np.float32(half)
    return u.astype(np.float64)


def _local_texels_warped(cascades: CascadeSet, index: int, points) -> np.ndarray:
    """Local texel coordinates ``(..., 2)`` of world points in a warped cascade (:mod:`csmlab.cascades.warp`).

    Points behind the warp's eye (``w ≤ 0``, never on the map) get NaN, snapped far outside.
    """
    texels, w = warped_texels(cascades.cascades[index].warp.homography,
                              _light_space(np.asarray(points, dtype=np.float64), cascades.basis[:2]))
    return np.where((w > 0.0)[..., None], texels, np.nan)


def fixed_point_coordinates(cascades: CascadeSet, index: int, points, *, bits: int,
                            precision: str = "float64") -> np.ndarray:
    """Snapped local texel coordinates ``(..., 2)`` int64 of world points, in ``2**-bits`` texels.

    ``round(u · 2**bits) − round(origin · 2**bits)`` with ``u`` the global texel coordinate
    computed in float64: the same world point gets the same global value whatever the box, so a
    box moved by whole texels shifts the result by an exact integer. Non-finite points give
    ``-2**50`` less the origin (outside every box). ``precision = "float32"`` rounds the local
    coordinates of an engine's float32 matrix instead (:data:`PRECISION_METHODS`).
    """
    if _warped(cascades, index):
        return _snapped(_local_texels_warped(cascades, index, points) * float(2**bits))
    if not PRECISION_METHODS[check_name(precision, PRECISION_METHODS, field="engine_precision")].global_grid:
        return _snapped(_local_texels_float32(cascades, index, points) * float(2**bits))
    snapped = _snapped(_global_texels(cascades, index, points) * float(2**bits))
    return snapped - fixed_point_origin(cascades, index, bits=bits)


def light_depth(cascades: CascadeSet, points) -> np.ndarray:
    """Stored light-space depth ``d·X − zref`` ``(...)`` float64 in metres of world points ``(..., 3)``."""
    p = np.asarray(points, dtype=np.float64)
    return _light_space(p, cascades.basis[2:])[..., 0] - cascades.zref


def receiver_lookup(cascades: CascadeSet, points, normals, *, bits: int, normal_offset: float, bias_constant,
                    bias_slope: float, precision: str = "float64",
                    normal_scale: str = "none", plane_offset=0.0,
                    normal_offset_m: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where receivers look every cascade up: fixed-point coordinates, biased depth, depth slope.

    In cascade c the receiver is moved ``normal_offset`` texels along its normal before the
    fixed-point snap, then its depth is pulled toward the light by
    ``bias_constant + bias_slope · texel · tan θ``, θ the angle between the normal and ``-d``
    (tan clamped to 10). ``texel`` is the larger side of the cascade's texels, the one that sets
    the depth error across a texel. Offset and bias are in texels of the cascade, so they do not
    change when an exact box moves.

    A receiver turned away from the light (``n·(−d) ≤ 0``) gets no direct light whatever the map
    holds — as in the ray-traced reference — and no bias could be right for it: its depth is NaN,
    which fails every depth test, so its S is 0.

    Parameters
    ----------
    cascades : CascadeSet
    points : array_like, shape (N, 3)
        World positions in metres; rows with a NaN are no receivers.
    normals : array_like, shape (N, 3)
        Unit normals (facing the camera).
    bits : int
        Sub-texel bits of the fixed-point grid.
    normal_offset, bias_constant, bias_slope : float
        Texels, metres, texels (docs/design.md ``[shadow]``); ``bias_constant`` may be one value per
        cascade ``(C,)`` (a bias model's per-cascade scaling, csmlab.filters).
    precision : str
        A key of :data:`PRECISION_METHODS`: float32 maps the moved points as an engine's float32
        matrix does.
    normal_scale : str
        A key of :data:`csmlab.lookup_choices.NORMAL_OFFSET_SCALES`: the offset times ``1 − max(0, cos θ)``
        or ``sin θ`` per receiver, and with ``one_minus_cos_lateral`` across the light only (its
        depth unchanged).
    normal_offset_m : float
        Metres added to the normal offset in every cascade (Stride's world-space offset).
    plane_offset : float or array_like, shape (C,)
        Metres per cascade: where positive, the depth is also pulled toward the light by its tangent
        plane's depth change over one texel in x plus one in y, at most this much (MJP's static
        receiver-plane offset for a single hardware compare, ``Mesh.hlsl`` ``SampleShadowMapFixedSizePCF``).

    Returns
    -------
    coordinates : ndarray, shape (C, N, 2), int64
        As :func:`fixed_point_coordinates` of the moved points (far outside every box for no receiver).
    depth : ndarray, shape (C, N), float32
        Biased receiver depth ``d·X' − zref − bias`` in metres, rounded once to float32 so that it
        compares with the float32 depth map exactly as stored; NaN where turned from the light.
    slope : ndarray, shape (C, N, 2), float64
        Depth change of the receiver's tangent plane per texel along light x and y, metres
        (``-n_x / n_z · texel_x``, ``-n_y / n_z · texel_y`` in light space, clamped like tan θ):
        the receiver-plane depth bias that lets a filter tap one texel away compare against
        the plane's depth there instead of the receiver's own (Isidoro, "Shadow Mapping: GPU-based
        Tips and Techniques", GDC 2006; the derivative-based bias of seed 002). Box-independent.
    """
    global_grid = PRECISION_METHODS[check_name(precision, PRECISION_METHODS, field="engine_precision")].global_grid
    p = np.asarray(points, dtype=np.float64)
    n = np.asarray(normals, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or n.shape != p.shape:
        raise ValueError(f"points, normals: expected two (N, 3) arrays, got {p.shape} and {n.shape}")
    # Light-space coordinates of points and normals once; the offset point of cascade c is then
    # p + o_c·n in light space too (the same for every box of that texel size).
    light_p = _light_space(p, cascades.basis)
    light_n = _light_space(n, cascades.basis)
    cos = -light_n[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        tan = np.sqrt(np.maximum(1.0 - cos * cos, 0.0)) / cos
    tan = np.where(cos > 0.0, np.minimum(tan, _MAX_TAN), np.nan)
    count = len(cascades)
    constant = np.broadcast_to(np.asarray(bias_constant, dtype=np.float64), (count,))
    cap = np.broadcast_to(np.asarray(plane_offset, dtype=np.float64), (count,))
    coordinates = np.empty((count, p.shape[0], 2), dtype=np.int64)
    depth = np.empty((count, p.shape[0]), dtype=np.float32)
    slope = np.empty((count, p.shape[0], 2), dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        plane_slope = np.where(cos[:, None] > 0.0, light_n[:, :2] / cos[:, None], 0.0)
    plane_slope = np.clip(plane_slope, -_MAX_TAN, _MAX_TAN)
    scale = float(2**bits)
    code = NORMAL_OFFSET_SCALES[check_name(normal_scale, NORMAL_OFFSET_SCALES, field="normal_offset_scale")]
    factor = None
    if code == NORMAL_SIN:
        factor = np.sqrt(np.maximum(1.0 - cos * cos, 0.0))
    elif code != NORMAL_NONE:
        factor = 1.0 - np.maximum(cos, 0.0)
    along = 0.0 if code == NORMAL_ONE_MINUS_COS_LATERAL else 1.0
    for c, cascade in enumerate(cascades.cascades):
        texel = float(np.max(cascade.texel_size))
        offset = normal_offset * texel
        if normal_offset_m != 0.0:
            offset = offset + normal_offset_m
        if factor is not None:
            offset = (offset * factor)[:, None]
        if cascade.warp is not None:
            coordinates[c] = _snapped(_local_texels_warped(cascades, c, p + n * offset) * scale)
        elif global_grid:
            u = light_n[:, :2] * offset
            u += light_p[:, :2]
            u *= scale / cascade.texel_size
            coordinates[c] = _snapped(u) - fixed_point_origin(cascades, c, bits=bits)
        else:
            coordinates[c] = _snapped(_local_texels_float32(cascades, c, p + n * offset) * scale)
        step = plane_slope * cascade.texel_size
        if cascade.warp is not None:
            # A warped texel's size changes across the map: the slope bias and the receiver plane's
            # change per texel step take the receiver's own, from the homography's Jacobian there.
            texel, step = _warped_texel_steps(cascade.warp.homography, light_p[:, :2], plane_slope)
        bias = constant[c] + bias_slope * texel * tan
        if cap[c] > 0.0:
            bias = bias + np.minimum(np.abs(step[:, 0]) + np.abs(step[:, 1]), cap[c])
        depth[c] = light_p[:, 2] + (along * offset if factor is None else along * offset[:, 0]) * light_n[:, 2] \
            - cascades.zref - bias
        slope[c] = step
    return coordinates, depth, slope


def _warped_texel_steps(homography: np.ndarray, light_xy: np.ndarray,
                        plane_slope: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per receiver of a warped cascade: its texel's larger side ``(N,)`` in metres and its plane's depth change per
    texel step along the map's two axes ``(N, 2)``, from the inverse of the homography's Jacobian at ``light_xy``."""
    j = warped_texel_jacobian(homography, light_xy)
    det = j[:, 0, 0] * j[:, 1, 1] - j[:, 0, 1] * j[:, 1, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        # Columns: light x/y metres per texel step along the map's i and j axes (the 2×2 inverse).
        along_i = np.column_stack([j[:, 1, 1], -j[:, 1, 0]]) / det[:, None]
        along_j = np.column_stack([-j[:, 0, 1], j[:, 0, 0]]) / det[:, None]
    texel = np.maximum(np.hypot(along_i[:, 0], along_i[:, 1]), np.hypot(along_j[:, 0], along_j[:, 1]))
    step = np.column_stack([np.sum(plane_slope * along_i, axis=1), np.sum(plane_slope * along_j, axis=1)])
    return texel, step
