"""Stabilization: the light-space x/y box of one cascade, and whether it may move.

Each method maps a slice's light-space footprint to a texel size ``(tx, ty)`` in metres and a
box origin in whole or fractional texels; the box is then
``[origin · t, (origin + R) · t]`` on each axis. Every method keeps ``margin`` texels free inside
each edge so that the widest filter never reads outside the box (docs/design.md, "Exact zero").

References
----------
- Valient, "Stable Rendering of Cascaded Shadow Maps", ShaderX6 — bounding sphere, texel snap.
- Zhang, Zaprjagaev, Bentham, "Practical Cascaded Shadow Maps", ShaderX7 (seed 003), listing
  4.1.1 (exact) and 4.1.2 (quantized scale, 64 levels, snapped offset).

Extent hysteresis (``[shadow] extent_hysteresis``, ``none`` only): the tight box's size is *held*
over frames — it grows at once and shrinks only when the tight size falls a fraction below it
(:func:`held_extents`) — so that its texel size does not change with every small turn of the camera.
"""

from __future__ import annotations

from dataclasses import dataclass
from collections.abc import Callable

import numpy as np

from csmlab.registry import check_name, dispatch

__all__ = ["QUANTIZED_BASES", "SNAP_METHODS", "STABILIZATION_METHODS", "SliceFootprint", "check_resolution",
           "held_extents", "stabilize", "stabilize_exact", "stabilize_none", "stabilize_quantized",
           "stabilize_tight_snapped"]


@dataclass(frozen=True)
class SliceFootprint:
    """What stabilization needs to know of one frustum slice, in light-space metres.

    Attributes
    ----------
    lo, hi : ndarray, shape (2,)
        Tight x/y bounds of the slice's eight corners.
    centre : ndarray, shape (2,)
        x/y of the slice's bounding-sphere centre.
    radius : float
        The bounding sphere's radius, already rounded up to a quantum (bit-stable).
    frustum_extent : ndarray, shape (2,)
        x/y extent of the whole view frustum up to the shadow distance (quantized ``frustum`` base).
    """

    lo: np.ndarray
    hi: np.ndarray
    centre: np.ndarray
    radius: float
    frustum_extent: np.ndarray


def stabilize_none(fp: SliceFootprint, *, resolution: int, margin: int,
                   held_extent=None) -> tuple[np.ndarray, np.ndarray]:
    """Tight box around the slice every frame: texel size and origin follow the camera continuously.

    With ``held_extent`` ``(2,)`` metres (extent hysteresis, :func:`held_extents`), the box has that
    size instead of the tight one, centred on the tight box: the texel size holds while the extent
    is held, the origin still follows the camera.
    """
    tight = np.maximum(fp.hi - fp.lo, 1e-9)
    if held_extent is None:
        texel = tight / (resolution - 2 * margin)
        return texel, fp.lo / texel - margin
    extent = np.maximum(np.asarray(held_extent, dtype=np.float64), tight)
    texel = extent / (resolution - 2 * margin)
    return texel, (0.5 * (fp.lo + fp.hi) - 0.5 * extent) / texel - margin


def held_extents(extents, *, hysteresis: float) -> np.ndarray:
    """The box extent a tight (``none``) cascade with extent hysteresis uses in each frame.

    Frame 0 holds its own tight extent. Later, on each axis of each cascade, the held extent grows at
    once to a larger tight extent and falls to the tight one only when that lies below ``(1 - h)``
    of the held one. ``h = 0`` gives the tight extents themselves.

    Parameters
    ----------
    extents : array_like, shape (N, C, 2)
        Tight light-space x/y extent in metres of every cascade in every frame.
    hysteresis : float
        ``h`` in ``[0, 1)``.

    Returns
    -------
    ndarray, shape (N, C, 2), float64
    """
    e = np.asarray(extents, dtype=np.float64)
    if not 0.0 <= hysteresis < 1.0:
        raise ValueError(f"extent_hysteresis: expected a fraction in [0, 1), got {hysteresis}")
    keep = 1.0 - hysteresis
    out = e.copy()
    for i in range(1, e.shape[0]):
        held = out[i - 1]
        out[i] = np.where((e[i] > held) | (e[i] < keep * held), e[i], held)
    return out


def snap_origin(fp: SliceFootprint, *, resolution: int, margin: int) -> tuple[np.ndarray, np.ndarray]:
    """The box's minimum corner floored to whole texels (Valient; DirectX CSM11; Unreal).

    ``t = 2r / (R - 2m - 1)``: one spare texel leaves room for the snap.
    """
    t = 2.0 * fp.radius / (resolution - 2 * margin - 1)
    texel = np.array([t, t])
    return texel, np.floor((fp.centre - fp.radius) / texel) - margin


def snap_centre(fp: SliceFootprint, *, resolution: int, margin: int) -> tuple[np.ndarray, np.ndarray]:
    """The box's centre floored to whole texels and the box laid around it, the filter margins kept inside.

    Bevy's and three.js's own box is :func:`snap_centre_full` (texel D/R, no margin). With ``h = floor(R / 2)`` the box
    spans ``[k - h, k - h + R)`` texels around the snapped centre ``k = floor(c / t)``; ``t = 2r / (2 (h - m - 1))``
    keeps the sphere and the margins inside on both sides whatever ``c - k t ∈ [0, t)`` is.
    """
    half = resolution // 2
    t = fp.radius / (half - margin - 1)
    texel = np.array([t, t])
    return texel, np.floor(fp.centre / texel) - half


def snap_centre_nearest(fp: SliceFootprint, *, resolution: int, margin: int) -> tuple[np.ndarray, np.ndarray]:
    """The box's centre rounded to the *nearest* whole texel and the box laid around it (Stride's
    ``ProjectionSnapping``).

    Stride (``LightDirectionalShadowMapRenderer.Collect``) takes the shadow projection's translation in
    shadow-map pixels, ``shadowPixelPosition = viewProjection.TranslationVector · size · 0.5``, rounds it
    and adds the difference back: the world origin lands on a texel boundary and the box centre moves
    to within half a texel of the sphere's centre. Here ``k = floor(c / t + 1/2)`` and the box spans
    ``[k - h, k - h + R)`` with ``h = floor(R / 2)`` and :func:`snap_centre`'s texel.
    """
    half = resolution // 2
    t = fp.radius / (half - margin - 1)
    texel = np.array([t, t])
    return texel, np.floor(fp.centre / texel + 0.5) - half


def snap_view(fp: SliceFootprint, *, resolution: int, margin: int, step: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """The box's centre rounded *up* to a multiple of ``step`` texels (Stride's ``ViewSnapping``).

    Stride (``LightDirectionalShadowMapRenderer.Collect``, ``LightShadowMapStabilizationMode.
    ViewSnapping``) moves the shadow camera's target, the slice's bounding-sphere centre, to
    ``ceil(c · f) / f`` along the light's up and side axes with ``f = R / 2 · 0.25 / r`` — "0.25f to
    stabilize the 4x4 dithered shadow pattern" —, i.e. to whole multiples of ``4 t`` with ``t = 2r / R``,
    and lays the box ``[-r, r]`` around it. Here ``k = ceil(c / (step · t)) · step`` texels and the box
    spans ``[k - h, k - h + R)`` with ``h = floor(R / 2)``; ``t = r / (h - m - step)`` keeps the sphere and
    the margins inside on both sides whatever ``k t - c ∈ [0, step · t)`` is. The grid stays world-locked
    (the box moves by whole texels), only in coarser steps than :func:`snap_centre`.
    """
    half = resolution // 2
    t = fp.radius / (half - margin - step)
    texel = np.array([t, t])
    return texel, np.ceil(fp.centre / (step * texel)) * step - half


def snap_nearest2(fp: SliceFootprint, *, resolution: int, margin: int) -> tuple[np.ndarray, np.ndarray]:
    """The box's edges rounded to the nearest 2-texel unit (Godot 4), the filter's margin laid outside.

    Godot (``RendererSceneCull::_light_instance_setup_directional_shadow``) widens the sphere by one
    texel on each side (``radius *= T / (T - 2)``), takes ``t = 2r' / T`` and snaps each edge with
    ``Math::snapped(c - r', unit)``, ``unit = 4r' / T = 2t`` (``floor(v / s + 0.5) · s``: round to
    nearest). Here that is Godot's box for a map of ``T = R - 2m`` texels — ``t = 2r / (R - 2m - 2)``,
    ``r' = r + t``, edge ``k = 2 floor((c - r') / 2t + 1/2)`` texels — with the ``m`` texels of the
    filter's margin added outside it: the box spans ``[k - m, k + R - m)``. Godot's box holds the
    sphere (its edge moves at most one texel from the widened sphere's), so this one holds the sphere
    and the margins. The grid stays world-locked; the box moves in steps of two texels.
    """
    t = 2.0 * fp.radius / (resolution - 2 * margin - 2)
    texel = np.array([t, t])
    return texel, 2.0 * np.floor((fp.centre - (fp.radius + t)) / (2.0 * texel) + 0.5) - margin


def snap_centre_full(fp: SliceFootprint, *, resolution: int, margin: int) -> tuple[np.ndarray, np.ndarray]:
    """The box's centre floored to whole texels of ``t = 2r / R``: the whole map is the box, no margin kept inside.

    three.js (``CSM.update()``: ``texelWidth = (right − left) / shadowMapSize``, ``_center.x =
    Math.floor(_center.x / texelWidth) · texelWidth``, the camera ``±width / 2`` about it) and Bevy
    (``cascade.rs`` ``calculate_cascade``: ``cascade_texel_size = cascade_diameter / cascade_texture_size``,
    the centre floored to it). The box spans ``[k - h, k - h + R)`` texels with ``k = floor(c / t)`` and
    ``h = floor(R / 2)``; ``margin`` plays no part, so a filter's taps may leave the box near its edge,
    where the lookup then selects no cascade for the point (csmlab never clamps a tap), while the
    engines read the clamped edge.
    """
    t = 2.0 * fp.radius / resolution
    texel = np.array([t, t])
    return texel, np.floor(fp.centre / texel) - resolution // 2


SNAP_METHODS: dict[str, Callable[..., tuple[np.ndarray, np.ndarray]]] = {
    "origin": snap_origin,
    "centre": snap_centre,
    "centre_full": snap_centre_full,
    "view": snap_view,
    "nearest2": snap_nearest2,
    "centre_nearest": snap_centre_nearest,
}
"""What exact snaps to whole texels, by name: ``f(footprint, *, resolution, margin) -> (texel, origin)``."""


def stabilize_exact(fp: SliceFootprint, *, resolution: int, margin: int,
                    snap: str = "origin") -> tuple[np.ndarray, np.ndarray]:
    """Fixed-extent box: diameter ``2r`` (sphere or diagonal), origin an integer texel index.

    The texel size depends on the (bit-stable) radius only, so it is bit-identical from frame to
    frame; snapping the origin (``snap = "origin"``) or the centre (``"centre"``) to whole texels
    (:data:`SNAP_METHODS`) makes the texel grid fixed in the world.
    """
    return dispatch(SNAP_METHODS, snap, fp, field="snap", resolution=resolution, margin=margin)


QUANTIZED_BASES: dict[str, str] = {
    "sphere": "the slice's bounding-sphere diameter (fixed per cascade)",
    "frustum": "the whole frustum's light-space box (seed 003)",
}
"""Base extents of quantized stabilization, by name, with what each is."""


def stabilize_quantized(fp: SliceFootprint, *, resolution: int, margin: int, levels: int = 64,
                        quantized_base: str = "sphere") -> tuple[np.ndarray, np.ndarray]:
    """Tight extent rounded *up* to one of ``levels`` steps of a base extent, origin snapped.

    ``quantized_base = "sphere"`` takes the slice's bounding-sphere diameter (fixed per cascade,
    so the steps never move); ``"frustum"`` takes the whole frustum's light-space box, as seed 003's
    listing does in the light's post-projective space.
    """
    check_name(quantized_base, QUANTIZED_BASES, field="quantized_base")
    if quantized_base == "sphere":
        base = np.array([2.0 * fp.radius, 2.0 * fp.radius])
    else:
        base = np.asarray(fp.frustum_extent, dtype=np.float64)
    step = base / levels
    extent = np.maximum(np.ceil((fp.hi - fp.lo) / step), 1.0) * step
    texel = extent / (resolution - 2 * margin - 1)
    origin = np.floor(fp.lo / texel) - margin
    return texel, origin


def stabilize_tight_snapped(fp: SliceFootprint, *, resolution: int, margin: int) -> tuple[np.ndarray, np.ndarray]:
    """Tight box padded for the filter and snapped to texels of its own size, every frame (DirectX CSM11 fit to
    cascade).

    ``CascadedShadowsManager::InitFrame`` with ``FIT_TO_CASCADES`` and ``m_bMoveLightTexelSize``: the
    light-space AABB of the slice's corners is widened on each side by half of ``(2 · m_iPCFBlurSize +
    1) / m_iBufferSize`` of its size, the world units per texel are that padded size over the buffer
    size, and both ends are floored to them. Here the padding is ``(2m + 1) / R`` of the extent with
    ``m`` the filter's margin (DirectX's 3×3 PCF: m = 3, 7 texels as the sample's blur size 3 gives),
    ``t = padded / R`` per axis and the box ``[floor(lo / t), floor(lo / t) + R)`` texels (the floored
    maximum lies exactly R texels further, the padded size being R texels). The texel size follows
    the slice's light-space extent, so it changes whenever the camera turns: the sample's shimmer.
    """
    tight = np.maximum(fp.hi - fp.lo, 1e-9)
    padded = tight * (1.0 + (2 * margin + 1) / resolution)
    texel = padded / resolution
    return texel, np.floor((fp.lo - 0.5 * (padded - tight)) / texel)


STABILIZATION_METHODS: dict[str, Callable[..., tuple[np.ndarray, np.ndarray]]] = {
    "none": stabilize_none,
    "exact": stabilize_exact,
    "quantized": stabilize_quantized,
    "tight_snapped": stabilize_tight_snapped,
}
"""Stabilization methods by name: ``f(footprint, *, resolution, margin, levels, quantized_base, snap)``."""


def check_resolution(resolution: int, *, margin: int, method: str, snap: str = "origin") -> None:
    """Raise ``ValueError("resolution: …")`` unless a box of ``resolution`` texels leaves texels inside its margins.

    Every method needs ``R - 2m - 3 ≥ 1`` (the snap's spare texel and the rounding of the extent);
    ``exact`` with ``snap = "view"`` moves its centre in 4-texel steps: ``R // 2 - m - 4 ≥ 1``.
    """
    if resolution - 2 * margin - 3 < 1:
        raise ValueError(f"resolution: expected more than {2 * margin + 3} texels for a {margin}-texel margin, "
                         f"got {resolution}")
    if method == "exact" and snap == "view" and resolution // 2 - margin - 4 < 1:
        raise ValueError(f"resolution: expected more than {2 * margin + 9} texels for snap = \"view\" with a "
                         f"{margin}-texel margin, got {resolution}")


def stabilize(fp: SliceFootprint, *, method: str, resolution: int, margin: int, levels: int = 64,
              quantized_base: str = "sphere", snap: str = "origin", held_extent=None) -> tuple[np.ndarray, np.ndarray]:
    """Texel size ``(2,)`` in metres and box origin ``(2,)`` in texels of one cascade.

    ``held_extent`` ``(2,)`` metres: ``none``'s box size under extent hysteresis (ignored otherwise).

    Raises
    ------
    ValueError
        If ``method`` is not a key of :data:`STABILIZATION_METHODS`, or the resolution leaves no
        texel inside the margins.
    """
    check_name(method, STABILIZATION_METHODS, field="stabilization")
    check_resolution(resolution, margin=margin, method=method, snap=snap)
    return dispatch(STABILIZATION_METHODS, method, fp, field="stabilization", resolution=resolution, margin=margin,
                    offered={"levels": levels, "quantized_base": quantized_base, "snap": snap,
                             "held_extent": held_extent})
