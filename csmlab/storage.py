"""How the depth maps are stored: the depth format's precision and the bytes an engine allocates.

Depth formats (:data:`DEPTH_FORMATS`): ``float32`` keeps the rasterized metres; ``unorm16`` and
``unorm24`` store an integer level over the box's near/far, so a deep box loses precision (acne
where the stored caster rounds up past the biased receiver, peter-panning where it rounds down).

The near/far a box quantizes over is the light-space depth range of the scene's bounds,
``[zref, zref + span]`` — the box's near side is pushed there anyway ("pancaking"), and every
caster and receiver lies inside it. That range is fixed per light and scene and never moves with
the camera, and the level step is rounded up to a power of two, ``step = 2^⌈log₂(span / (2^b − 1))⌉``
metres, so each stored value ``round(z / step) · step`` is exact in float32 and a whole-texel box
move changes no level: ``exact`` keeps its zero same-cascade flicker (docs/design.md, "Exact zero").
The power-of-two step costs up to one bit against a step of exactly ``span / (2^b − 1)``.

That is ``depth_quantization = "scene"`` (:data:`DEPTH_QUANTIZATION_METHODS`). Engines quantize each
cascade's map over its *own* light camera's near/far instead — ``"cascade"``
(:func:`cascade_stored_depth`): level ``round((z − near_c) / step_c)`` with ``step_c = (far_c −
near_c) / (2^b − 1)``, the D16/D24 conversion of a depth normalized to the box (Godot's
directional atlas, ``16_bits``; URP's 16-bit shadowmap tiles; Filament's DEPTH16; three.js's
DEPTH_COMPONENT24 per light camera). A near cascade's box is shallow, so its levels are finer than
the scene's; a box whose near/far follows the camera moves its levels with it, so it promises no
zero flicker (:mod:`csmlab.invariants`).

Memory (:func:`memory_bytes`): a texture ``array`` holds C slices of the largest cascade's size;
an ``atlas`` holds a grid of equal tiles of that size (:data:`ATLAS_LAYOUTS`), empty tiles included.

References
----------
- Zhang, Zaprjagaev, Bentham, "Practical Cascaded Shadow Maps" (seed 003), "Storage strategy" and
  Listing 4.1.3 (Unigine's 2×2 atlas, split 1 below split 0).
- Microsoft, "Cascaded Shadow Maps" (seed 002): PCF on an atlas in Direct3D 10, arrays in 10.1.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from csmlab.registry import check_name
from csmlab.settings import ShadowSettings

__all__ = ["ATLAS_LAYOUTS", "DEPTH_FORMATS", "DEPTH_QUANTIZATION_METHODS", "MOMENT_BYTES", "cascade_stored_depth",
           "depth_step", "memory_bytes", "polygon_offset_unit", "stored_depth", "texel_bytes"]

DEPTH_FORMATS: dict[str, tuple[int | None, int]] = {"float32": (None, 4), "unorm24": (24, 4), "unorm16": (16, 2)}
"""Depth formats by name: (bits of the unorm level or None for float, bytes per texel as allocated; D24 pads to 4)."""

ATLAS_LAYOUTS: dict[str, tuple[tuple[int, int], ...]] = {
    "2x2": ((0, 0), (1, 0), (0, 1), (1, 1)),
    "1x4": ((0, 0), (1, 0), (2, 0), (3, 0)),
    "unigine": ((0, 0), (0, 1), (1, 0), (1, 1)),
}
"""Atlas layouts by name: the (column, row) tile of each cascade; the atlas is the whole grid."""


def depth_step(span: float, *, depth_format: str) -> float:
    """Metres between stored levels for a near/far ``span`` metres deep: a power of two; 0 for ``float32``."""
    check_name(depth_format, DEPTH_FORMATS, field="depth_format")
    bits = DEPTH_FORMATS[depth_format][0]
    if bits is None:
        return 0.0
    if not (math.isfinite(span) and span > 0):
        raise ValueError(f"span: expected a positive depth range in metres, got {span!r}")
    return math.ldexp(1.0, math.ceil(math.log2(span / (2**bits - 1))))


def polygon_offset_unit(span: float, *, depth_format: str) -> float:
    """Metres of one unit of a polygon offset's constant (Direct3D's ``DepthBias``, OpenGL's ``units``) over a
    depth range ``span`` metres deep.

    Direct3D's r: the smallest stored value above 0 — ``1 / (2^n − 1)`` of the range for an n-bit unorm;
    for ``float32``, ``2^(e − 23)`` with e the exponent of the primitive's largest depth, taken here
    at the largest depths of ``[0, 1]`` (e = −1): ``2^-24`` of the range.
    """
    check_name(depth_format, DEPTH_FORMATS, field="depth_format")
    if not (math.isfinite(span) and span >= 0):
        raise ValueError(f"span: expected a non-negative depth range in metres, got {span!r}")
    bits = DEPTH_FORMATS[depth_format][0]
    return span * (2.0**-24 if bits is None else 1.0 / (2**bits - 1))


def stored_depth(depth, *, span: float, depth_format: str, overwrite: bool = False, regions=None,
                 out: np.ndarray | None = None) -> np.ndarray:
    """Depth maps as the format stores them, back in metres.

    Parameters
    ----------
    depth : array_like, shape (C, R, R), float32
        Rasterized depth ``d·X − zref``, metres; +inf where empty.
    span : float
        Depth of the near/far range in metres (the scene's light-space depth extent).
    depth_format : str
        A key of :data:`DEPTH_FORMATS`.
    overwrite : bool
        Whether ``depth`` may hold the result (quantized in place where it is a writeable
        C-contiguous float32 array: no fresh maps).
    regions : array_like, shape (G, 5), integer, optional
        Rectangles ``(c, i0, i1, j0, j1)`` of ``(C, R, R)`` maps to store, the other texels kept as
        ``out`` holds them (:func:`csmlab.kernels.depth_storage.unorm_stored_depth`); None: every texel.
    out : ndarray, shape (C, R, R), float32, optional
        Writeable C-contiguous maps the stored texels are written into and returned (``depth``
        itself allowed). Left as it is by ``float32``, which returns ``depth``.

    Returns
    -------
    ndarray, shape (C, R, R), float32
        ``round(z / step) · step`` (half to even, as a float-to-unorm conversion rounds to
        nearest), clamped to the format's levels; empty texels stay +inf. ``float32``: unchanged
        (``depth`` itself).
    """
    maps = np.asarray(depth, dtype=np.float32)
    step = depth_step(span, depth_format=depth_format)
    if step == 0.0:
        return maps
    top = float(2 ** DEPTH_FORMATS[depth_format][0] - 1)
    # Imported here: loading an experiment reads this module's tables and must not start Warp.
    from csmlab.kernels.depth_storage import unorm_stored_depth

    if regions is not None or out is not None:
        return unorm_stored_depth(maps, step=step, top=top, overwrite=overwrite, regions=regions, out=out)
    # Any shape, as rows of one map: every texel has the same levels.
    rows = maps.reshape(1, -1, maps.shape[-1]) if maps.ndim else maps.reshape(1, 1, 1)
    return unorm_stored_depth(rows, step=step, top=top, overwrite=overwrite).reshape(maps.shape)


def cascade_stored_depth(depth, *, near, far, depth_format: str, overwrite: bool = False, regions=None,
                         out: np.ndarray | None = None) -> np.ndarray:
    """Depth maps quantized over each cascade's own near/far, as an engine's unorm depth buffer stores them.

    Parameters
    ----------
    depth : array_like, shape (C, R, R), float32
        Rasterized depth ``d·X − zref``, metres; +inf where empty.
    near, far : array_like, shape (C,)
        Each cascade's box near and far side in the same metres (``depth_near − zref``, ``depth_far − zref``).
    depth_format : str
        A key of :data:`DEPTH_FORMATS`.
    overwrite, regions, out
        As :func:`stored_depth`'s.

    Returns
    -------
    ndarray, shape (C, R, R), float32
        ``near_c + round((z − near_c) / step_c) · step_c`` with ``step_c = (far_c − near_c) / (2^b − 1)``
        (half to even, as a float-to-unorm conversion rounds to nearest), clamped to levels
        ``0 … 2^b − 1`` (a caster beyond the far side stores the far side, as the cleared buffer
        does where the engine clips it); empty texels stay +inf. ``float32``: unchanged.

    Raises
    ------
    ValueError
        On ``near``/``far`` of another length than the maps' cascades or a box with ``far <= near``.
    """
    maps = np.asarray(depth, dtype=np.float32)
    bits = DEPTH_FORMATS[check_name(depth_format, DEPTH_FORMATS, field="depth_format")][0]
    if bits is None:
        return maps
    lo = np.asarray(near, dtype=np.float64).reshape(-1, 1, 1)
    hi = np.asarray(far, dtype=np.float64).reshape(-1, 1, 1)
    if lo.shape[0] != maps.shape[0] or hi.shape[0] != maps.shape[0] or not np.all(hi > lo):
        raise ValueError(f"near, far: expected {maps.shape[0]} boxes with far > near, got {lo.ravel()}, {hi.ravel()}")
    top = float(2**bits - 1)
    # Imported here: loading an experiment reads this module's tables and must not start Warp.
    from csmlab.kernels.depth_storage import unorm_stored_depth

    return unorm_stored_depth(maps, lo=lo.ravel(), step=((hi - lo) / top).ravel(), top=top, overwrite=overwrite,
                              regions=regions, out=out)


def _scene_quantized(depth, *, span: float, depth_format: str, overwrite: bool = False, regions=None,
                     out=None) -> np.ndarray:
    return stored_depth(depth, span=span, depth_format=depth_format, overwrite=overwrite, regions=regions, out=out)


def _cascade_quantized(depth, *, near, far, depth_format: str, overwrite: bool = False, regions=None,
                       out=None) -> np.ndarray:
    return cascade_stored_depth(depth, near=near, far=far, depth_format=depth_format, overwrite=overwrite,
                                regions=regions, out=out)


DEPTH_QUANTIZATION_METHODS: dict[str, Callable[..., np.ndarray]] = {
    "scene": _scene_quantized,
    "cascade": _cascade_quantized,
}
"""The range a unorm depth format's levels divide, by name (``[shadow] depth_quantization``):
``scene`` (the scene's fixed light-space span in power-of-two steps, :func:`stored_depth`) or
``cascade`` (each box's own near/far, :func:`cascade_stored_depth`). Each is
``f(depth, *, depth_format, span | near, far, overwrite=False, regions=None, out=None) -> stored maps``
(``overwrite``: the maps may be quantized in place; ``regions``, ``out``: only those rectangles, stored
into ``out``, as :func:`stored_depth`'s)."""


MOMENT_BYTES: dict[str, int] = {"vsm": 8, "evsm2": 8, "evsm4": 16}
"""Bytes per texel of the moment filters' float32 moment maps (RG32F, RG32F, RGBA32F), beside the depth."""


def texel_bytes(settings: ShadowSettings) -> int:
    """Bytes per texel: the depth (``depth_bytes`` when set, else what ``depth_format`` allocates) plus the moments."""
    return (settings.depth_bytes or DEPTH_FORMATS[settings.depth_format][1]) + MOMENT_BYTES.get(settings.filter, 0)


def memory_bytes(settings: ShadowSettings) -> int:
    """Texture memory the engine allocates for the depth maps, padding included.

    ``array``: ``C · R_max² · bytes`` (every slice of an array has one size). ``atlas``: the whole
    grid of :data:`ATLAS_LAYOUTS` ``[atlas_layout]`` in tiles of ``R_max``, empty tiles included.
    A virtual clipmap (``shadow_map = "virtual_clipmap"``): its physical pool, ``physical_pages ·
    page_size² · bytes``, allocated whole however few pages are resident (:mod:`csmlab.clipmaps`).
    """
    if settings.shadow_map == "virtual_clipmap":
        return settings.physical_pages * settings.page_size * settings.page_size * texel_bytes(settings)
    size = max(settings.cascade_resolutions or (settings.resolution,))
    if settings.storage == "array":
        return settings.cascades * size * size * texel_bytes(settings)
    tiles = ATLAS_LAYOUTS[settings.atlas_layout]
    columns = 1 + max(col for col, _ in tiles)
    rows = 1 + max(row for _, row in tiles)
    return columns * rows * size * size * texel_bytes(settings)
