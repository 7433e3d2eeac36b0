"""World points to a cascade's texel grid: texel coordinates, fixed point, receiver lookups.

Everything here is host NumPy and feeds the Warp kernels (docs/design.md, "Exact zero by
construction"); csmlab's own conversion is float64, and :data:`PRECISION_METHODS` also emulates an
engine's float32 pipeline (its matrices, positions, window coordinates and depths). The per-point
conversions (:func:`fixed_point_coordinates`, :func:`vertex_depth`, :func:`window_positions`,
:func:`receiver_lookup`) are the statement the kernels repeat bit for bit (:mod:`csmlab.kernels.raster`,
:func:`csmlab.kernels.shadow.receiver_coordinates`, :mod:`csmlab.kernels.engine`) and the tests'
oracle; a run calls one of them itself only for the receivers of a set that mixes warped and unwarped
cascades (:func:`receiver_lookup`). A world point X
has light-space coordinates ``(right·X, up·X)`` in metres; divided by a cascade's texel size they
become *global* texel units, which depend on the light direction and the texel size only — never on
where the box lies. Snapped to ``2**bits`` steps per texel they
become int64 fixed point; subtracting the box origin (an integer number of texels for the exact
and quantized stabilizations) gives the local coordinates a kernel sees. Moving a box by k whole
texels then shifts every local coordinate by exactly ``k · 2**bits`` and changes no rounding.

Units: texel coordinates are in texels of the cascade, texel ``(i, j)`` spanning ``[i, i + 1)`` ×
``[j, j + 1)``, its centre at ``(i + ½, j + ½)``; fixed-point coordinates are in ``2**-bits``
texels; depths are metres along the light direction, ``d·X − zref``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from csmlab.cascades import CascadeSet
from csmlab.cascades.warp import warped_texel_jacobian, warped_texels
from csmlab.lookup_choices import NORMAL_NONE, NORMAL_OFFSET_SCALES, NORMAL_ONE_MINUS_COS_LATERAL, NORMAL_SIN
from csmlab.registry import check_name

if TYPE_CHECKING:
    from csmlab.kernels.engine import EngineBoxes

__all__ = ["PRECISION_METHODS", "Precision", "VERTEX_SNAPS", "WINDOW_BOX_ROWS", "engine_matrix", "engine_origin",
           "engine_positions", "fixed_point_coordinates", "fixed_point_origin", "light_depth",
           "light_plane_coordinates", "receiver_lookup", "texel_coordinates", "uploaded_boxes", "uses_global_grid",
           "vertex_depth", "window_box_inputs", "window_box_slice", "window_boxes", "window_depth_metres",
           "window_positions", "window_rectangles"]


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
        :func:`csmlab.kernels.shadow.receiver_coordinates`). False: an engine's float32 pipeline,
        stated here in NumPy (:func:`engine_matrix`, :func:`window_positions`) and run by the
        window-space kernels with the same bits (:mod:`csmlab.kernels.engine`, :func:`window_boxes`).
    camera_relative : bool
        The float32 positions and matrices are taken relative to an origin rebased near the camera
        (:func:`engine_origin`), not to the world origin.
    """

    description: str
    global_grid: bool
    camera_relative: bool = False


PRECISION_METHODS: dict[str, Precision] = {
    "float64": Precision("global texel coordinates in float64, less an integer origin: world-locked at any distance",
                         global_grid=True),
    "float32": Precision("an engine's float32 pipeline on absolute world positions: light view and projection "
                         "built in float32 on the host, float32 vertices and G-buffer positions, float32 window "
                         "position and depth normalized per cascade (Godot 4, Unity URP and built-in, Bevy, "
                         "Stride, MJP, three.js's GPU side)", global_grid=False),
    "camera_relative": Precision("the float32 pipeline relative to an origin rebased near the camera "
                                 "(rebase_distance): world positions less the origin in float64, then float32 "
                                 "(Unreal 5's translated world, Unity HDRP's camera-relative rendering, "
                                 "Filament's camera_at_origin)", global_grid=False, camera_relative=True),
}
"""How world points reach a cascade's texel grid (``[shadow] engine_precision``), by name.

``float32`` is what an engine that keeps world positions in float32 runs: the host builds each
cascade's light view (eye at the box centre) and orthographic projection in float32 from float32
inputs; the GPU applies that matrix in float32 to float32 absolute world positions, vertices and
receivers alike (a receiver's position as a float32 G-buffer holds it), maps the clip position to
a float32 window position and normalizes depth per cascade to [0, 1] in float32. Far from the
origin (10⁶ m: a float32 step of 6 cm) the eye's rounding changes as a box moves by whole texels,
and the receivers' positions are off by up to half a step: the shadow swims and acne and leaks
appear. ``camera_relative`` runs the same float32 pipeline on positions less an origin near the
camera, subtracted in float64 (:func:`engine_origin`), so its numbers stay small at any distance.
"""

VERTEX_SNAPS: dict[str, str] = {
    "world": "world-locked fixed point: the global texel coordinate snapped to 2**-subtexel_bits texels, less the "
             "box origin (csmlab's, invariant under whole-texel box moves)",
    "window": "the rasterizer's rule: the window position (texels from the box's corner) snapped to "
              "2**-subtexel_bits of a texel (GPUs: 8 sub-pixel bits), which follows a fractional box origin",
}
"""Where float64 vertices and receivers are snapped to fixed point (``[shadow] vertex_snap``), by name.

The float32 pipelines (``engine_precision`` other than ``float64``) always snap the float32 window
position, as the hardware does; for boxes on whole texels (exact, quantized) in float64 both rules
give the same bits, since the window position is then the global one less an integer.
"""


def uses_global_grid(*, precision: str, snap: str) -> bool:
    """The global grid's kernels may finish the conversion themselves (float64 and world-locked snapping); else the
    window-space ones (:mod:`csmlab.kernels.engine`) convert from the host's matrices (:func:`window_boxes`)."""
    return (PRECISION_METHODS[check_name(precision, PRECISION_METHODS, field="engine_precision")].global_grid
            and check_name(snap, VERTEX_SNAPS, field="vertex_snap") == "world")


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


def engine_origin(eye, *, precision: str, rebase_distance: float = 0.0) -> np.ndarray:
    """The origin ``(3,)`` float64 in world metres that an engine's float32 positions are taken from.

    The world origin for ``float64`` and ``float32``. For ``camera_relative``, the camera
    position ``eye`` itself when ``rebase_distance`` is 0 (rebased every frame: Unreal 5's
    PreViewTranslation, HDRP's camera-relative rendering), else ``eye`` rounded to the nearest
    multiple of ``rebase_distance`` metres per axis (an origin rebased only when the camera has
    moved about that far, as a floating-origin scheme does).
    """
    record = PRECISION_METHODS[check_name(precision, PRECISION_METHODS, field="engine_precision")]
    if not record.camera_relative or eye is None:
        return np.zeros(3)
    eye = np.asarray(eye, dtype=np.float64)
    if rebase_distance == 0.0:
        return eye.copy()
    return np.floor(eye / rebase_distance + 0.5) * rebase_distance


def engine_positions(points, origin) -> np.ndarray:
    """World points ``(..., 3)`` as an engine's float32 buffers hold them.

    ``points − origin`` in float64, rounded once to float32 (world metres relative to ``origin``).
    """
    return (np.asarray(points, dtype=np.float64) - np.asarray(origin, dtype=np.float64)).astype(np.float32)


def engine_matrix(cascades: CascadeSet, index: int, *, origin) -> np.ndarray:
    """Cascade ``index``'s world-to-clip matrix ``(3, 4)`` float32 as an engine builds it on the host.

    Built in float32 from float32 inputs: the light basis rows ``R`` and the eye ``e`` (the box
    centre on its near side, ``centre − origin`` subtracted in float64 then rounded); the view
    translation ``−R·e`` summed in float32; the orthographic scales ``2 / (R_c · texel)`` in x and y
    and ``1 / (far − near)`` in depth; their product with the view, once rounded per entry. Rows:
    clip x and y in [−1, 1] across the box, depth in [0, 1] from the box's near to its far side
    (a [0, 1] clip-depth convention, D3D's and Vulkan's).
    """
    cascade = cascades.cascades[index]
    f = np.float32
    half = 0.5 * cascade.resolution
    centre = np.array([*((cascade.origin + half) * cascade.texel_size), cascade.depth_near])
    eye = engine_positions(cascades.basis.T @ centre, origin)
    rows = cascades.basis.astype(f)
    translation = -((rows[:, 0] * eye[0] + rows[:, 1] * eye[1]) + rows[:, 2] * eye[2])
    size = f(cascade.resolution) * cascade.texel_size.astype(f)
    scale = np.array([f(2.0) / size[0], f(2.0) / size[1], f(1.0) / f(cascade.depth_far - cascade.depth_near)],
                     dtype=f)
    return np.concatenate([rows * scale[:, None], (translation * scale)[:, None]], axis=1).astype(f)


def _local_texels_warped(cascades: CascadeSet, index: int, points) -> np.ndarray:
    """Local texel coordinates ``(..., 2)`` of world points in a warped cascade (:mod:`csmlab.cascades.warp`).

    Points behind the warp's eye (``w ≤ 0``, never on the map) get NaN, snapped far outside.
    """
    texels, w = warped_texels(cascades.cascades[index].warp.homography,
                              _light_space(np.asarray(points, dtype=np.float64), cascades.basis[:2]))
    return np.where((w > 0.0)[..., None], texels, np.nan)


def window_positions(matrix: np.ndarray, positions: np.ndarray, *, resolution: int) -> np.ndarray:
    """Float32 window positions ``(..., 3)`` of float32 positions ``(..., 3)`` under a :func:`engine_matrix`.

    Clip coordinates summed in float32 as ``((m0·x + m1·y) + m2·z) + m3`` (no fused multiply-add);
    x and y to the viewport as ``clip · R/2 + R/2`` in float32 — texels from the box's minimum
    corner, texel ``(i, j)`` spanning ``[i, i + 1) × [j, j + 1)`` — and depth kept as the clip depth
    in [0, 1] across the box's depth range.
    """
    m = matrix
    p = np.asarray(positions, dtype=np.float32)
    x, y, z = p[..., 0, None], p[..., 1, None], p[..., 2, None]
    clip = ((x * m[:, 0] + y * m[:, 1]) + z * m[:, 2]) + m[:, 3]
    half = np.float32(0.5 * resolution)
    clip[..., :2] = clip[..., :2] * half + half
    return clip


_UNIT_ROUNDOFF_32 = 2.0**-24
"""Float32's unit roundoff u: an operation's result is the exact one times (1 + δ), |δ| ≤ u."""


def window_rectangles(inputs: dict, lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """Rectangles in each cascade's doubled window fixed point that hold every point of K world boxes, the float32
    pipeline's roundings included.

    A point of box k, taken through cascade c's float32 pipeline as :func:`fixed_point_coordinates`
    takes it (:func:`engine_positions`, :func:`window_positions`, ``2**bits``, rounded) and doubled,
    lies in ``[low[c, k], high[c, k]]``. The exact window position is affine in the point, so the
    box's corners bound it; each of the pipeline's float32 operations moves it by at most u of its
    magnitude, which over a clip row's four terms and the viewport's two operations is within
    ``R/2 · u · (7 S + 2)`` texels, S the sum of the row's terms' magnitudes over the box (the
    float32 position's rounding, then γ₄ of the products and sums); the rectangles are wider by
    twice that, and a fixed-point step for the rounding to it.

    Parameters
    ----------
    inputs : dict
        :func:`window_box_inputs` of an engine's float32 precision (``mode = "float32"``), C cascades.
    lo, hi : array_like, shape (K, 3), float64
        Each box's lowest and highest corner, world metres.

    Returns
    -------
    low, high : ndarray, shape (C, K, 2), int64
        Doubled fixed point, ``2**bits`` steps a texel from the box's minimum corner.
    """
    if inputs.get("mode") != "float32":
        raise ValueError(f"inputs: expected an engine's float32 pipeline (mode 'float32'), got {inputs.get('mode')!r}")
    m = np.asarray(inputs["matrices"], dtype=np.float64)[:, :2]
    origin = np.asarray(inputs["origin"], dtype=np.float64)
    low_corner = np.asarray(lo, dtype=np.float64)
    high_corner = np.asarray(hi, dtype=np.float64)
    # Each box as its centre and half extent from the origin; rows (c, x or y) as columns of one product.
    centre = 0.5 * (low_corner + high_corner) - origin
    extent = 0.5 * (high_corner - low_corner)
    rows = m[..., :3].reshape(-1, 3).T
    offset = m[..., 3].reshape(1, -1)
    middle = centre @ rows + offset
    spread = extent @ np.abs(rows)
    # The magnitude of a row's terms over the box, |m|·(|centre| + extent) + |m3|, the largest of |m|·|p − o|.
    size = (np.abs(centre) + extent) @ np.abs(rows) + np.abs(offset)
    half = np.repeat(0.5 * np.asarray(inputs["resolution"], dtype=np.float64), 2)[None]
    scale = float(2 ** int(inputs["bits"]))
    reach = scale * half * _UNIT_ROUNDOFF_32 * (16.0 * size + 4.0) + 1.0
    low = np.clip(((middle - spread) * half + half) * scale - reach, -_FIXED_LIMIT, _FIXED_LIMIT)
    high = np.clip(((middle + spread) * half + half) * scale + reach, -_FIXED_LIMIT, _FIXED_LIMIT)
    # (K, C·2) columns → (C, K, 2).
    shape = (low.shape[0], m.shape[0], 2)
    return ((2 * np.floor(low).astype(np.int64)).reshape(shape).transpose(1, 0, 2),
            (2 * np.ceil(high).astype(np.int64)).reshape(shape).transpose(1, 0, 2))


def window_depth_metres(cascades: CascadeSet, index: int, depth) -> np.ndarray:
    """Stored depth ``(...)`` float64 metres (``d·X − zref``) of cascade ``index``'s window depths in [0, 1].

    The float32 pipeline's depths taken back to csmlab's unit for storage and comparison: one
    monotone map per cascade, the same for casters and receivers.
    """
    cascade = cascades.cascades[index]
    return (cascade.depth_near - cascades.zref) + np.asarray(depth, dtype=np.float64) * (
        cascade.depth_far - cascade.depth_near)


def _engine_texels(cascades: CascadeSet, index: int, points, *, precision: str,
                   rebase_distance: float) -> np.ndarray:
    """Float32 window positions ``(..., 3)`` of float64 world points in cascade ``index`` (:func:`window_positions`)."""
    origin = engine_origin(cascades.eye, precision=precision, rebase_distance=rebase_distance)
    matrix = engine_matrix(cascades, index, origin=origin)
    return window_positions(matrix, engine_positions(points, origin), resolution=cascades.cascades[index].resolution)


def fixed_point_coordinates(cascades: CascadeSet, index: int, points, *, bits: int, precision: str = "float64",
                            snap: str = "world", rebase_distance: float = 0.0) -> np.ndarray:
    """Snapped local texel coordinates ``(..., 2)`` int64 of world points, in ``2**-bits`` texels.

    ``round(u · 2**bits) − round(origin · 2**bits)`` with ``u`` the global texel coordinate
    computed in float64: the same world point gets the same global value whatever the box, so a
    box moved by whole texels shifts the result by an exact integer. Non-finite points give
    ``-2**50`` less the origin (outside every box). ``snap = "window"`` rounds ``(u − origin) · 2**bits``
    instead (:data:`VERTEX_SNAPS`); an engine's float32 ``precision`` rounds its float32 window
    position (:func:`window_positions`, relative to :func:`engine_origin` with ``rebase_distance``).
    """
    if _warped(cascades, index):
        return _snapped(_local_texels_warped(cascades, index, points) * float(2**bits))
    scale = float(2**bits)
    if not PRECISION_METHODS[check_name(precision, PRECISION_METHODS, field="engine_precision")].global_grid:
        window = _engine_texels(cascades, index, points, precision=precision, rebase_distance=rebase_distance)
        return _snapped(window[..., :2] * scale)
    if check_name(snap, VERTEX_SNAPS, field="vertex_snap") == "window":
        return _snapped(texel_coordinates(cascades, index, points) * scale)
    snapped = _snapped(_global_texels(cascades, index, points) * scale)
    return snapped - fixed_point_origin(cascades, index, bits=bits)


def vertex_depth(cascades: CascadeSet, index: int, points, *, precision: str = "float64",
                 rebase_distance: float = 0.0) -> np.ndarray:
    """Stored depth ``(...)`` float64 metres (``d·X − zref``) of world points in cascade ``index``'s depth pass.

    :func:`light_depth` in float64; for an engine's float32 ``precision``, the float32 window depth
    normalized over the cascade's depth range, taken back to metres (:func:`window_depth_metres`).
    """
    if PRECISION_METHODS[check_name(precision, PRECISION_METHODS, field="engine_precision")].global_grid:
        return light_depth(cascades, points)
    window = _engine_texels(cascades, index, points, precision=precision, rebase_distance=rebase_distance)
    return window_depth_metres(cascades, index, window[..., 2])


def light_depth(cascades: CascadeSet, points) -> np.ndarray:
    """Stored light-space depth ``d·X − zref`` ``(...)`` float64 in metres of world points ``(..., 3)``."""
    p = np.asarray(points, dtype=np.float64)
    return _light_space(p, cascades.basis[2:])[..., 0] - cascades.zref


def receiver_lookup(cascades: CascadeSet, points, normals, *, bits: int, normal_offset: float, bias_constant,
                    bias_slope: float, precision: str = "float64",
                    normal_scale: str = "none", plane_offset=0.0,
                    normal_offset_m: float = 0.0, snap: str = "world",
                    rebase_distance: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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
        A key of :data:`PRECISION_METHODS`: ``float32`` and ``camera_relative`` take the receivers
        as float32 positions (a float32 G-buffer's, relative to :func:`engine_origin`), move them
        along their float32 normals in float32 and map them with the cascade's float32 matrix
        (:func:`engine_matrix`, :func:`window_positions`); their depth is the float32 window depth
        (:func:`window_depth_metres`) less the bias.
    snap : str
        A key of :data:`VERTEX_SNAPS` (float64 only): ``window`` snaps the local texel coordinate.
    rebase_distance : float
        ``camera_relative``: metres between the origins it rebases to (0: at the camera).
    normal_scale : str
        A key of :data:`csmlab.lookup_choices.NORMAL_OFFSET_SCALES`: the offset times ``1 − max(0, cos θ)``
        or ``sin θ`` per receiver, or with ``one_minus_cos_lateral`` times ``1 − max(0, −cos θ)`` across
        the light only (its depth unchanged).
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
    window_snap = check_name(snap, VERTEX_SNAPS, field="vertex_snap") == "window"
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
    elif code == NORMAL_ONE_MINUS_COS_LATERAL:
        # Godot's light_dir points toward the light: 1 − max(0, dot(light_dir, −N)) is 1 on every lit face.
        factor = 1.0 - np.maximum(-cos, 0.0)
    elif code != NORMAL_NONE:
        factor = 1.0 - np.maximum(cos, 0.0)
    along = 0.0 if code == NORMAL_ONE_MINUS_COS_LATERAL else 1.0
    if not global_grid:
        origin = engine_origin(cascades.eye, precision=precision, rebase_distance=rebase_distance)
        p32 = engine_positions(p, origin)
        n32 = n.astype(np.float32)
    for c, cascade in enumerate(cascades.cascades):
        texel = float(np.max(cascade.texel_size))
        offset = normal_offset * texel
        if normal_offset_m != 0.0:
            offset = offset + normal_offset_m
        if factor is not None:
            offset = (offset * factor)[:, None]
        if cascade.warp is not None:
            coordinates[c] = _snapped(_local_texels_warped(cascades, c, p + n * offset) * scale)
            # A warped texel's size changes across the map: the slope bias and the receiver plane's
            # change per texel step take the receiver's own, from the homography's Jacobian there.
            texel, step = _warped_texel_steps(cascade.warp.homography, light_p[:, :2], plane_slope)
            bias = constant[c] + bias_slope * texel * tan
        else:
            step = plane_slope * cascade.texel_size
            bias = constant[c] + bias_slope * texel * tan
            if not global_grid:
                matrix = engine_matrix(cascades, c, origin=origin)
                moved = p32 + n32 * np.asarray(offset, dtype=np.float32)
                window = window_positions(matrix, moved, resolution=cascade.resolution)
                coordinates[c] = _snapped(window[:, :2] * scale)
                if along == 0.0:
                    window = window_positions(matrix, p32, resolution=cascade.resolution)
                if cap[c] > 0.0:
                    bias = bias + np.minimum(np.abs(step[:, 0]) + np.abs(step[:, 1]), cap[c])
                depth[c] = window_depth_metres(cascades, c, window[:, 2]) - bias
                slope[c] = step
                continue
            u = light_n[:, :2] * offset
            u += light_p[:, :2]
            if window_snap:
                u /= cascade.texel_size
                u -= cascade.origin
                u *= scale
                coordinates[c] = _snapped(u)
            else:
                u *= scale / cascade.texel_size
                coordinates[c] = _snapped(u) - fixed_point_origin(cascades, c, bits=bits)
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


WINDOW_BOX_ROWS = ("matrices", "resolution", "depth_near", "depth_span", "texel_size", "corner")
"""The inputs of :func:`window_box_inputs` that hold one row per cascade (the others are shared)."""


def window_box_inputs(cascades: CascadeSet, *, bits: int, precision: str = "float64", snap: str = "world",
                      rebase_distance: float = 0.0) -> dict:
    """The host arrays :func:`window_boxes` uploads, keyed as :func:`csmlab.kernels.engine.engine_boxes` takes them.

    For an engine's float32 ``precision`` (``mode = "float32"``): each cascade's :func:`engine_matrix`
    ``(C, 3, 4)`` float32 (built here on the host, as an engine builds it) relative to
    :func:`engine_origin` ``(3,)``, its ``resolution`` and the depth range ``depth_near``,
    ``depth_span`` ``(C,)`` metres that :func:`window_depth_metres` maps window depth to. For
    ``snap = "window"`` in float64 (``mode = "float64"``): each cascade's ``texel_size`` ``(C, 2)``
    metres and box origin ``corner`` ``(C, 2)`` texels. The names of :data:`WINDOW_BOX_ROWS` hold one
    row per cascade. Not for warped cascades, nor for the global grid (:func:`uses_global_grid`),
    which other kernels finish themselves.
    """
    if any(c.warp is not None for c in cascades.cascades):
        raise ValueError("cascades: expected no warped cascade (window_boxes serves the unwarped window space)")
    if uses_global_grid(precision=precision, snap=snap):
        raise ValueError(f"precision, snap: expected a window-space pipeline, got {precision!r} with {snap!r}")
    if not PRECISION_METHODS[precision].global_grid:
        origin = engine_origin(cascades.eye, precision=precision, rebase_distance=rebase_distance)
        return dict(mode="float32", bits=bits, origin=origin,
                    matrices=np.stack([engine_matrix(cascades, c, origin=origin) for c in range(len(cascades))]),
                    resolution=np.array([c.resolution for c in cascades.cascades]),
                    depth_near=np.array([c.depth_near - cascades.zref for c in cascades.cascades]),
                    depth_span=np.array([c.depth_far - c.depth_near for c in cascades.cascades]))
    return dict(mode="float64", bits=bits, texel_size=np.stack([c.texel_size for c in cascades.cascades]),
                corner=np.stack([c.origin for c in cascades.cascades]))


def window_boxes(cascades: CascadeSet, *, bits: int, precision: str = "float64", snap: str = "world",
                 rebase_distance: float = 0.0, device: str = "cpu") -> EngineBoxes:
    """The cascades as the window-space kernels read them (:mod:`csmlab.kernels.engine`), on ``device``:
    :func:`window_box_inputs` uploaded by :func:`uploaded_boxes`."""
    return uploaded_boxes(window_box_inputs(cascades, bits=bits, precision=precision, snap=snap,
                                            rebase_distance=rebase_distance), device=device)


def uploaded_boxes(inputs: dict, *, first: int = 0, last: int | None = None, device: str = "cpu") -> EngineBoxes:
    """Cascades ``[first, last)`` of :func:`window_box_inputs` ``inputs`` as an
    :class:`~csmlab.kernels.engine.EngineBoxes` on ``device`` (default: every cascade)."""
    # Imported here: loading an experiment reads this module's tables (PRECISION_METHODS) and must not start Warp.
    from csmlab.kernels.engine import engine_boxes

    return engine_boxes(**window_box_slice(inputs, first=first, last=last), device=device)


def window_box_slice(inputs: dict, *, first: int = 0, last: int | None = None) -> dict:
    """Cascades ``[first, last)`` of :func:`window_box_inputs` ``inputs``: its :data:`WINDOW_BOX_ROWS` cut, the rest
    shared."""
    return {name: value[first:last] if name in WINDOW_BOX_ROWS else value for name, value in inputs.items()}
