"""Scrolled depth maps: a cascade box moved by whole texels keeps the depths it already holds.

A texel's depth depends only on the triangles and on their fixed-point coordinates relative to the
texel (:mod:`csmlab.kernels.raster`). A box that moves by whole texels, in the same light space with
the same texel size, therefore holds at every texel it shares with its previous position the same
depth, bit for bit. Those texels are copied from the previous frame's maps, and only the newly
exposed strips are rasterized: at most a band of rows and a band of columns per cascade. A box that
did not move is copied whole.

The exact and quantized stabilizations move their boxes in whole texels. Along the default walk,
0.1 % (exact) and 7 % (quantized) of their texels need rasterizing per frame. Engines cache and
scroll static shadow maps in the same way. Here it changes no value, only the time.

The stored maps scroll too. A texel's stored depth (pancaked, in the depth format) is a function of
its raw depth and of its cascade's storage inputs alone — the depth format and quantization, the
span or the box's near/far its levels divide, the pancaking near side (``storage`` keys,
:func:`csmlab.render.shadow_maps` composes them). A cascade whose raw texels scrolled and whose
key is the previous frame's keeps its stored texels shifted the same way (:func:`kept_stored`): only
the strips rasterized this frame are stored afresh, not the whole map every frame.

``texels_rasterized`` still counts the work of rasterizing every map whole, the cost an engine pays
without scrolling: a cascade's count is its previous count, less the coverage tests of the texels
its box left (counted in the previous box), plus those of the texels it newly covers. The coverage
of a texel centre, like its depth, depends only on the fixed-point differences.

An engine's float32 pipeline (and window-space snapping) cannot scroll: its roundings change as a
box moves. What it can keep is a whole cascade whose every input is the same, bit for bit, as the
previous frame's — the same window transform, light space, casters, caster offsets, near cut,
depth range and format (:class:`StoredMaps`, :func:`reused_cascades`): the same computation gives
the same stored map and the same count. A stabilized box moves only when the camera crosses one
of its texels, so far cascades keep theirs for frames on end.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["RasterizedMaps", "ScrollPlan", "StoredMaps", "kept_stored", "reused_cascades", "scroll_plan"]


@dataclass(frozen=True)
class RasterizedMaps:
    """One frame's raw depth maps and where their boxes lie, kept for the next frame of the same method.

    Attributes
    ----------
    basis : ndarray, shape (3, 3)
        The light space (:attr:`csmlab.cascades.CascadeSet.basis`).
    zref : float
        Depth offset in metres of the stored depths.
    bits : int
        Sub-texel bits of the fixed-point grid.
    texel_size : ndarray, shape (C, 2), float64
        Metres per texel of each cascade.
    origin : ndarray, shape (C, 2), int64
        Each box origin in ``2**-bits`` texels (:func:`csmlab.texels.fixed_point_origin`).
    resolution : ndarray, shape (C,), int
        Texels per side of each cascade's map (in the corner of maps of the largest side).
    depth : ndarray, shape (C, R, R), float32
        Rasterized depth ``d·X − zref`` in metres, before the depth format; +inf where empty. Read-only.
    texels : ndarray, shape (C,), int64
        Coverage tests that pass in each cascade's whole map (its ``texels_rasterized``).
    caster_constant : ndarray, shape (C,), float64
        Metres each cascade's casters were pushed away from the light (the polygon offset's constant
        part, :func:`csmlab.kernels.raster.rasterize_cascades`).
    caster_slope : float
        The polygon offset's slope factor.
    stored : ndarray, shape (C, R, R), float32, optional
        The maps as stored (pancaked, in the depth format; ``depth`` itself where that changes
        nothing), +inf where empty. Read-only. None: not kept.
    storage : tuple of bytes, length C
        Each cascade's storage inputs, bit for bit, that ``stored`` was made with: equal keys, equal
        stored texels of equal raw texels (:func:`kept_stored`).
    """

    basis: np.ndarray
    zref: float
    bits: int
    texel_size: np.ndarray
    origin: np.ndarray
    resolution: np.ndarray
    depth: np.ndarray
    texels: np.ndarray
    caster_constant: np.ndarray | None = None
    caster_slope: float = 0.0
    stored: np.ndarray | None = None
    storage: tuple[bytes, ...] = ()

    def offset_of(self, c: int) -> tuple[float, float]:
        """Cascade c's caster offset ``(constant metres, slope factor)``; a map without one has ``(0, 0)``."""
        return (0.0 if self.caster_constant is None else float(self.caster_constant[c]), float(self.caster_slope))


@dataclass(frozen=True)
class ScrollPlan:
    """What a frame starts its rasterization from.

    Attributes
    ----------
    depth : ndarray, shape (C, R, R), float32
        The texels kept from the previous frame, +inf beyond a smaller cascade's own map; the
        texels of ``regions`` are left unset (the rasterization empties them itself).
    regions : ndarray, shape (G, 5), int32
        Rows ``(c, i0, i1, j0, j1)``: texel columns ``[i0, i1)`` and rows ``[j0, j1)`` of cascade c
        still to rasterize (:func:`csmlab.kernels.raster.rasterize_cascades`).
    kept_texels : ndarray, shape (C,), int64
        Coverage tests the previous frame counted in each cascade, 0 for a cascade rasterized whole.
    left : ndarray, shape (L, 5), int32
        Regions of the *previous* boxes that the new boxes left, as ``regions``: their coverage
        tests, counted in the previous boxes, come off ``kept_texels``.
    shifts : tuple, length C
        Each cascade's whole-texel move ``(dx, dy)`` (ints) since the previous frame, or None for a
        cascade rasterized whole.
    """

    depth: np.ndarray
    regions: np.ndarray
    kept_texels: np.ndarray
    left: np.ndarray
    shifts: tuple


@dataclass(frozen=True)
class StoredMaps:
    """One frame's stored depth maps, each cascade beside every input it was made from, kept for the next frame.

    Attributes
    ----------
    keys : tuple of bytes, length C
        Each cascade's inputs, bit for bit (:func:`csmlab.render.shadow_maps` composes them): equal
        keys of the same ``mesh``, equal maps and counts.
    depth : ndarray, shape (C, R, R), float32
        The maps as stored (pancaked, quantized to the depth format), +inf where empty. Read-only.
    texels : ndarray, shape (C,), int64
        Coverage tests that pass in each cascade's whole map (its ``texels_rasterized``).
    mesh : object
        The scene in light space the maps were rasterized from
        (:class:`csmlab.kernels.raster.LightSpaceMesh`), compared by identity: the same scene, casters,
        light and face cull.
    """

    keys: tuple[bytes, ...]
    depth: np.ndarray
    texels: np.ndarray
    mesh: object


def reused_cascades(previous, keys, *, side: int, mesh) -> np.ndarray:
    """``(C,)`` bool: which cascades take their map and count from ``previous``, whose inputs were ``keys``.

    Parameters
    ----------
    previous : StoredMaps or None
        The same method's previous frame; None or another kind of maps (a path that scrolls, or
        none): no cascade is reused.
    keys : sequence of bytes, length C
        This frame's inputs of each cascade, composed as ``previous.keys`` were.
    side : int
        Texels per side R of this frame's maps ``(C, R, R)``.
    mesh : object
        The scene in light space this frame rasterizes (:attr:`StoredMaps.mesh`).
    """
    count = len(keys)
    if (not isinstance(previous, StoredMaps) or previous.mesh is not mesh
            or previous.depth.shape != (len(previous.keys), side, side)):
        return np.zeros(count, dtype=bool)
    return np.array([c < len(previous.keys) and previous.keys[c] == key for c, key in enumerate(keys)], dtype=bool)


def _shift(previous: RasterizedMaps, c: int, *, basis, zref: float, bits: int, texel_size, origin,
           resolution: int, offset: tuple[float, float]) -> tuple[int, int] | None:
    """Whole-texel move ``(dx, dy)`` of cascade c's box since ``previous``, or None when its texels cannot be kept."""
    if (previous.bits != bits or previous.zref != zref or not np.array_equal(previous.basis, basis)
            or c >= len(previous.resolution) or int(previous.resolution[c]) != resolution
            or not np.array_equal(previous.texel_size[c], texel_size[c]) or previous.offset_of(c) != offset):
        return None
    moved = np.asarray(origin[c], dtype=np.int64) - previous.origin[c]
    if np.any(moved % (1 << bits)):
        return None
    shift = moved >> bits
    return (int(shift[0]), int(shift[1])) if np.all(np.abs(shift) < resolution) else None


def scroll_plan(previous: RasterizedMaps | None, *, basis, zref: float, bits: int, texel_size, origin,
                resolution, caster_constant=None, caster_slope: float = 0.0) -> ScrollPlan:
    """The texels each cascade keeps from ``previous`` and the regions left to rasterize.

    Parameters
    ----------
    previous : RasterizedMaps or None
        The same method's previous frame; None (or maps of another path, :class:`StoredMaps`): every
        map is rasterized whole.
    basis : ndarray, shape (3, 3)
    zref : float
    bits : int
    texel_size : ndarray, shape (C, 2), float64
    origin : ndarray, shape (C, 2), int64
        This frame's boxes, as in :class:`RasterizedMaps`.
    resolution : sequence of int, length C
        Texels per side of each cascade; the maps are ``(C, R, R)`` with R the largest.
    caster_constant : array_like, shape (C,), float64, optional
    caster_slope : float
        This frame's caster offset (:class:`RasterizedMaps`); None: 0 in every cascade.

    Returns
    -------
    ScrollPlan
        A cascade whose box moved by whole texels less than its side keeps the texels both boxes
        cover: new texel ``(i, j)`` is old texel ``(i + dx, j + dy)``. A cascade whose light space,
        texel size, resolution or caster offset changed, or that moved by a fraction of a texel,
        starts empty and is rasterized whole. When no box moved, the previous arrays themselves are
        returned.
    """
    if not isinstance(previous, RasterizedMaps):
        previous = None
    sizes = [int(r) for r in resolution]
    count, side = len(sizes), max(sizes)
    box = dict(basis=basis, zref=zref, bits=bits, texel_size=texel_size, origin=origin)
    offsets = [(0.0 if caster_constant is None else float(caster_constant[c]), float(caster_slope))
               for c in range(count)]
    shifts = tuple(None if previous is None else _shift(previous, c, resolution=sizes[c], offset=offsets[c], **box)
                   for c in range(count))
    kept_texels = np.array([0 if shift is None else previous.texels[c] for c, shift in enumerate(shifts)],
                           dtype=np.int64)
    if previous is not None and _unmoved(previous.depth, shifts, side):
        no_regions = np.zeros((0, 5), np.int32)
        return ScrollPlan(depth=previous.depth, regions=no_regions, kept_texels=kept_texels, left=no_regions,
                          shifts=shifts)
    depth, regions = _shifted(None if previous is None else previous.depth, shifts, sizes)
    left = []
    for c, (size, shift) in enumerate(zip(sizes, shifts)):
        if shift is not None:
            (dx, dy), (i0, i1, j0, j1) = shift, _kept_window(size, shift)
            left += _outside(c, size, i0 + dx, i1 + dx, j0 + dy, j1 + dy)
    return ScrollPlan(depth=depth, regions=regions, kept_texels=kept_texels,
                      left=np.array(left, dtype=np.int32).reshape(-1, 5), shifts=shifts)


def kept_stored(previous: RasterizedMaps | None, *, shifts, storage,
                resolution) -> tuple[np.ndarray | None, np.ndarray | None]:
    """The stored texels each cascade keeps from ``previous`` and the regions left to store.

    Parameters
    ----------
    previous : RasterizedMaps or None
        The previous frame the raw maps scrolled from; None (or maps of another path), or one
        without ``stored``: nothing kept.
    shifts : sequence, length C
        Each cascade's whole-texel move (:attr:`ScrollPlan.shifts`), None where rasterized whole.
    storage : sequence of bytes, length C
        This frame's storage keys, composed as ``previous.storage``.
    resolution : sequence of int, length C
        Texels per side of each cascade.

    Returns
    -------
    depth : ndarray, shape (C, R, R), float32, or None
        A cascade that scrolled under the key it was stored with holds the previous stored texels
        shifted as its raw texels were (:func:`scroll_plan`); texels beyond a smaller cascade's own
        map are +inf; the texels of ``regions`` are left unset. When no cascade moved or changed its
        key, the previous stored array itself. None when no cascade keeps a texel: the maps are
        stored whole.
    regions : ndarray, shape (G, 5), int32, or None
        Rows ``(c, i0, i1, j0, j1)`` to store from this frame's raw maps: the strips a scrolled
        cascade rasterized, every texel of the others. None with ``depth``.
    """
    sizes = [int(r) for r in resolution]
    side = max(sizes)
    kept = isinstance(previous, RasterizedMaps) and previous.stored is not None
    shifts = [shift if kept and c < len(previous.storage) and previous.storage[c] == key else None
              for c, (shift, key) in enumerate(zip(shifts, storage))]
    if all(shift is None for shift in shifts):
        return None, None
    if _unmoved(previous.stored, shifts, side):
        return previous.stored, np.zeros((0, 5), np.int32)
    return _shifted(previous.stored, shifts, sizes)


def _unmoved(maps: np.ndarray, shifts, side: int) -> bool:
    """Whether every cascade keeps ``maps`` ``(C, R, R)`` where they are: all kept, none moved, of this frame's side."""
    return maps.shape == (len(shifts), side, side) and all(shift == (0, 0) for shift in shifts)


def _shifted(maps: np.ndarray | None, shifts, sizes: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """Fresh ``(C, R, R)`` maps holding the texels each cascade keeps of ``maps`` and the regions ``(G, 5)`` int32
    left unset: new texel ``(i, j)`` is old texel ``(i + dx, j + dy)``; a cascade of shift None keeps nothing."""
    count, side = len(sizes), max(sizes)
    depth = np.empty((count, side, side), dtype=np.float32)
    regions = []
    for c, (size, shift) in enumerate(zip(sizes, shifts)):
        # Texels beyond a smaller cascade's own map stay empty.
        depth[c, size:, :] = np.inf
        depth[c, :size, size:] = np.inf
        if shift is None:
            regions.append((c, 0, size, 0, size))
            continue
        dx, dy = shift
        i0, i1, j0, j1 = _kept_window(size, shift)
        depth[c, j0:j1, i0:i1] = maps[c, j0 + dy:j1 + dy, i0 + dx:i1 + dx]
        regions += _outside(c, size, i0, i1, j0, j1)
    return depth, np.array(regions, dtype=np.int32).reshape(-1, 5)


def _kept_window(size: int, shift: tuple[int, int]) -> tuple[int, int, int, int]:
    """``(i0, i1, j0, j1)``: the texel columns ``[i0, i1)`` and rows ``[j0, j1)`` a ``size``² box moved by ``shift``
    ``(dx, dy)`` keeps, in the new box (they lay at ``+dx``, ``+dy`` in the previous one)."""
    dx, dy = shift
    return max(0, -dx), min(size, size - dx), max(0, -dy), min(size, size - dy)


def _outside(c: int, size: int, i0: int, i1: int, j0: int, j1: int) -> list[tuple[int, int, int, int, int]]:
    """The texels of a ``size``² map outside ``[i0, i1) × [j0, j1)``: at most a band of rows and one of columns."""
    strips = [(c, 0, size, 0, j0), (c, 0, size, j1, size), (c, 0, i0, j0, j1), (c, i1, size, j0, j1)]
    return [strip for strip in strips if strip[1] < strip[2] and strip[3] < strip[4]]
