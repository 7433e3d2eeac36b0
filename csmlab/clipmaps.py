"""Unreal 5's virtual shadow map clipmap for a directional light: levels, pages, marking and the page cache.

``[shadow] shadow_map = "virtual_clipmap"`` replaces the cascades by a clipmap as Unreal Engine 5
documents its Virtual Shadow Maps ("Virtual Shadow Maps", docs.unrealengine.com/5.1): every level
is a virtual shadow map of ``virtual_resolution``² texels (16k²) cut into pages of ``page_size``²
texels (128²); a page is rasterized only when a visible pixel needs it (marked from the G-buffer)
and is kept between frames until the light moves. Levels follow the console variables
``r.Shadow.Virtual.Clipmap.FirstLevel`` .. ``LastLevel`` (6 .. 22).

- **Levels.** Level n covers a square of half-side ``2**n`` cm around the camera, so its texel is
  ``2**(n + 1) cm / virtual_resolution``. Its grid is the global texel grid of that texel size in
  light space (the light's basis and origin, as the cascades', :func:`csmlab.geometry.light_basis`),
  and its box starts on a whole page: the page holding the camera less half the level's pages
  (:func:`clipmap_levels`). Texels and pages are world-locked; only which pages exist follows the camera.
- **Level per pixel.** A pixel at distance ``D`` from the camera has a footprint of
  ``D · 2 tan(fov_y / 2) / height`` metres; it wants the level whose texel is that footprint times
  ``2**lod_bias`` (``r.Shadow.Virtual.ResolutionLodBiasDirectional``), rounded to the finer level:
  ``n = floor(log2(footprint · virtual_resolution / 2 cm) + lod_bias)``, clamped to the levels
  (:func:`wanted_levels`). Like Unreal's ``CalcClipmapLevel`` it depends on the distance only. A
  receiver whose taps leave that level's box, or (looking up) whose pages are not resident, takes
  the next coarser level that holds them (:func:`read_levels`).
- **Marking.** The pages under every tap of every visible pixel at its level (:func:`marked_pages`).
  When more are marked than the pool holds (``physical_pages``), the coarsest levels' pages are kept
  first, so that the pixels whose pages did not fit fall back to a coarser level.
- **Cache.** The pages resident after a frame are those it marked; the next frame of the same method
  rasterizes only the pages it marks that are not among them (:func:`page_cache`). A change of
  light direction (or of the stored depth's offset) invalidates every page. csmlab's scenes have no
  moving casters, so no page is invalidated by one. Keeping only the last frame's pages (Unreal keeps
  unrequested pages while the pool has room) makes a frame's pages a function of that frame and the
  one before, the same however a run is cut into chunks.

The levels and pages are host NumPy, but for the level each receiver reads, a kernel
(:func:`read_levels`, :mod:`csmlab.kernels.levels`) whose host reference is :func:`chosen_levels`;
the pages are rasterized by :func:`csmlab.render.render_shadow` with the cascades' rasterizer, one
page per map, and looked up by :mod:`csmlab.kernels.pages`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from csmlab.camera import CameraPose
from csmlab.cascades import Cascade, CascadeSet
from csmlab.geometry import light_basis
from csmlab.kernels.levels import MAX_TAN, receiver_levels
from csmlab.settings import ShadowSettings
from csmlab.storage import texel_bytes

__all__ = ["Clipmap", "PageCache", "VirtualPages", "chosen_levels", "clipmap_cascades", "clipmap_levels",
           "footprint_scale", "light_space", "marked_pages", "page_cache", "page_table", "pool_bytes",
           "read_levels", "receiver_texels", "resident_pages", "wanted_levels"]

CENTIMETRE = 0.01
"""Metres in a centimetre, Unreal's world unit: level n covers ``2**n`` of them."""

@dataclass(frozen=True)
class Clipmap:
    """Where every level of one frame's clipmap lies.

    Attributes
    ----------
    first_level : int
        The level n of index 0 (``clipmap_first_level``); index k is level ``first_level + k``.
    texel : ndarray, shape (L,), float64
        Metres per texel of each level, ``2**(n + 1) cm / virtual_resolution``.
    origin_page : ndarray, shape (L, 2), int64
        Each level's first page (its box's minimum corner) as a global page index along light x, y.
    pages_per_side : int
        ``virtual_resolution / page_size``.
    page_size : int
        Texels per side of a page.
    footprint : float
        Metres of a pixel's footprint per metre of distance, ``2 tan(fov_y / 2) / height``.
    lod_bias : float
    eye : ndarray, shape (3,), float64
        World position of the camera the levels were placed around and the levels are chosen from.
    basis : ndarray, shape (3, 3)
        The light space (:attr:`csmlab.cascades.CascadeSet.basis`).
    zref : float
        Depth offset in metres of the stored depths.
    """

    first_level: int
    texel: np.ndarray
    origin_page: np.ndarray
    pages_per_side: int
    page_size: int
    footprint: float
    lod_bias: float
    eye: np.ndarray
    basis: np.ndarray
    zref: float

    def __len__(self) -> int:
        return len(self.texel)


@dataclass(frozen=True)
class VirtualPages:
    """One frame's resident pages: the page table the lookup reads and the counts the metrics report.

    The pages' depths are :attr:`csmlab.frame.ShadowMaps.depth`, ``(P, page_size, page_size)`` float32
    in the order of :attr:`keys` (``depth[p, j, i]``: texel column i, row j of page p).

    Attributes
    ----------
    clipmap : Clipmap
    keys : ndarray, shape (P, 3), int64
        ``(level index, global page x, global page y)`` of each resident page, by level, page row, page column.
    table : ndarray, shape (L, pages_per_side, pages_per_side), int32
        ``table[k, y, x]``: the resident page at page ``(x, y)`` of level k's box, -1 where none.
    marked : int
        Pages the frame's visible pixels marked.
    rendered : int
        Pages rasterized this frame (resident and not in the cache: the cache misses).
    resident_bytes : int
        Bytes of the resident pages in the pool.
    """

    clipmap: Clipmap
    keys: np.ndarray
    table: np.ndarray
    marked: int
    rendered: int
    resident_bytes: int


@dataclass(frozen=True)
class PageCache:
    """What the previous frame's pages lend this frame: which keys are kept and where their depths lie.

    Attributes
    ----------
    kept : ndarray, shape (P,), bool
        The resident pages (in key order) whose depths come from the previous frame.
    source : ndarray, shape (P,), int64
        For a kept page, its index in the previous frame's pages; -1 for one to rasterize.
    """

    kept: np.ndarray
    source: np.ndarray


def footprint_scale(pose: CameraPose, *, height: int) -> float:
    """Metres of one pixel's footprint per metre of distance from the camera: ``2 tan(fov_y / 2) / height``."""
    return 2.0 * float(np.tan(np.radians(pose.fov_y_deg) / 2.0)) / float(height)


def clipmap_levels(*, eye, light_direction, zref: float, footprint: float, settings: ShadowSettings) -> Clipmap:
    """The levels of a clipmap around ``eye`` (world metres): texel sizes and page-aligned box origins.

    Parameters
    ----------
    eye : array_like, shape (3,)
        The camera's world position, metres.
    light_direction : array_like, shape (3,)
        From the light toward the scene.
    zref : float
        Depth offset in metres of the stored depths (the scene's least light depth).
    footprint : float
        :func:`footprint_scale` of the camera and image.
    settings : ShadowSettings
        ``virtual_resolution``, ``page_size``, ``clipmap_first_level``, ``clipmap_last_level``, ``lod_bias``.
    """
    basis = light_basis(light_direction)
    levels = np.arange(settings.clipmap_first_level, settings.clipmap_last_level + 1)
    texel = np.ldexp(2.0 * CENTIMETRE, levels) / settings.virtual_resolution
    pages = settings.virtual_resolution // settings.page_size
    centre = light_space(np.asarray(eye, dtype=np.float64)[None], basis)[0, :2]
    page_width = texel * settings.page_size
    origin = np.floor(centre[None, :] / page_width[:, None]).astype(np.int64) - pages // 2
    return Clipmap(first_level=settings.clipmap_first_level, texel=texel, origin_page=origin, pages_per_side=pages,
                   page_size=settings.page_size, footprint=float(footprint), lod_bias=float(settings.lod_bias),
                   eye=np.array(eye, dtype=np.float64), basis=basis, zref=float(zref))


def clipmap_cascades(clip: Clipmap, *, scene_depth: tuple[float, float], margin: int) -> CascadeSet:
    """The levels as a :class:`CascadeSet`, one cascade per level, for what reads boxes (ρ, reports).

    A level's ``split_near``/``split_far`` (and slice) are the distances from the camera, in metres,
    over which :func:`wanted_levels` chooses it (the first from 0; the last is chosen beyond its far end
    too, which stays where its bias would end it, so that a frustum drawn to it is finite); its origin
    is its box corner in texels, its resolution ``virtual_resolution``; ``scene_depth`` is the
    ``(least, greatest)`` light depth ``dot(X, d)`` of the scene.
    """
    count = len(clip)
    levels = clip.first_level + np.arange(count + 1)
    # The distance at which the wanted level reaches n: log2(D · footprint · V / 2 cm) + bias = n.
    splits = np.ldexp(2.0 * CENTIMETRE, levels) * 2.0 ** -clip.lod_bias / (
        clip.footprint * clip.pages_per_side * clip.page_size)
    splits[0] = 0.0
    cascades = tuple(Cascade(split_near=float(splits[k]), split_far=float(splits[k + 1]),
                             slice_near=float(splits[k]), slice_far=float(splits[k + 1]),
                             texel_size=np.full(2, clip.texel[k]),
                             origin=(clip.origin_page[k] * clip.page_size).astype(np.float64),
                             resolution=clip.pages_per_side * clip.page_size, depth_near=float(scene_depth[0]),
                             depth_far=float(scene_depth[1])) for k in range(count))
    return CascadeSet(basis=clip.basis, zref=clip.zref, splits=splits, cascades=cascades, margin_texels=margin,
                      eye=clip.eye)


def light_space(points, basis) -> np.ndarray:
    """Light-space ``(..., 3)`` (x, y, ``dot(X, d)``, metres) of world points or directions ``(..., 3)``.

    Elementwise, ``(x·r_x + z·r_z) + y·r_y`` per row as :mod:`csmlab.texels` sums it, not a BLAS product.
    """
    p = np.asarray(points, dtype=np.float64)
    b = np.asarray(basis, dtype=np.float64)
    return np.stack([(p[..., 0] * b[k, 0] + p[..., 2] * b[k, 2]) + p[..., 1] * b[k, 1] for k in range(3)], axis=-1)


def wanted_levels(clip: Clipmap, points) -> np.ndarray:
    """The level index ``(N,)`` int64 each world point ``(N, 3)`` wants from its distance to the camera.

    ``floor(log2(D · footprint · V / 2 cm) + lod_bias) − first_level``, clamped to the levels
    (a point at the camera takes the finest).
    """
    distance = np.linalg.norm(np.asarray(points, dtype=np.float64) - clip.eye, axis=-1)
    resolution = clip.pages_per_side * clip.page_size
    with np.errstate(divide="ignore"):
        level = np.floor(np.log2(distance * clip.footprint * resolution / (2.0 * CENTIMETRE)) + clip.lod_bias)
    level = np.nan_to_num(level, nan=0.0, neginf=-1e9, posinf=1e9) - clip.first_level
    return np.clip(level, 0, len(clip) - 1).astype(np.int64)


def receiver_texels(clip: Clipmap, light_points: np.ndarray, light_normals: np.ndarray, level: np.ndarray, *,
                    settings: ShadowSettings) -> tuple[np.ndarray, np.ndarray]:
    """Where receivers look up level ``level`` ``(N,)``: fixed-point texel coordinates and biased depth.

    As the cascades' lookup (:func:`csmlab.texels.receiver_lookup`) in the level's texels: the point
    moved ``normal_offset`` texels along its normal, rounded to the global ``2**-subtexel_bits``
    grid; its depth pulled toward the light by ``bias_constant + bias_slope · texel · tan θ`` (tan
    clamped to 10), NaN when the receiver is turned from the light (no direct light: S = 0).

    Returns
    -------
    coordinates : ndarray, shape (N, 2), int64
        Global fixed-point coordinates along light x, y in ``2**-bits`` texels of the level.
    depth : ndarray, shape (N,), float32
        ``d·X' − zref − bias`` in metres.
    """
    texel = clip.texel[level]
    offset = (settings.normal_offset * texel)[:, None]
    moved = light_points + light_normals * offset
    cos = -light_normals[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        tan = np.sqrt(np.maximum(1.0 - cos * cos, 0.0)) / cos
    tan = np.where(cos > 0.0, np.minimum(tan, MAX_TAN), np.nan)
    scale = float(2**settings.subtexel_bits)
    coordinates = np.rint(moved[:, :2] / texel[:, None] * scale).astype(np.int64)
    depth = moved[:, 2] - clip.zref - (settings.bias_constant + settings.bias_slope * texel * tan)
    return coordinates, depth.astype(np.float32)


def _tap_pages(clip: Clipmap, coordinates: np.ndarray, *, radius: int, bits: int) -> np.ndarray:
    """The global pages ``(N, 4, 2)`` of the four corners of each receiver's taps, texels ``±radius`` about its own."""
    texel = coordinates >> bits
    corners = np.array([[-radius, -radius], [radius, -radius], [-radius, radius], [radius, radius]], dtype=np.int64)
    return (texel[:, None, :] + corners[None]) // clip.page_size


def chosen_levels(clip: Clipmap, light_points: np.ndarray, light_normals: np.ndarray, wanted: np.ndarray, *,
                  settings: ShadowSettings, radius: int,
                  holds: Callable[[int, np.ndarray], np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The level each receiver reads: the first from its wanted level whose pages ``holds`` every tap.

    The host reference of :func:`read_levels` (the run's path), which its tests hold it to bit for bit.

    Parameters
    ----------
    clip : Clipmap
    light_points, light_normals : ndarray, shape (N, 3)
        Receivers and their unit normals in light space (:func:`light_space`).
    wanted : ndarray, shape (N,), int
        :func:`wanted_levels`.
    settings : ShadowSettings
    radius : int
        Texels the filter's taps reach about the receiver's texel.
    holds : callable
        ``holds(k, pages)``: for level k and local pages ``(M, 4, 2)`` (page x, y in the level's box),
        whether each receiver's four corner pages are all there ``(M,)``.

    Returns
    -------
    level : ndarray, shape (N,), int64
        -1 where no level holds the taps.
    coordinates : ndarray, shape (N, 2), int64
        :func:`receiver_texels` at that level.
    depth : ndarray, shape (N,), float32
    """
    count = wanted.shape[0]
    level = np.full(count, -1, dtype=np.int64)
    coordinates = np.zeros((count, 2), dtype=np.int64)
    depth = np.full(count, np.nan, dtype=np.float32)
    for k in range(int(wanted.min(initial=len(clip))), len(clip)):
        rows = np.flatnonzero((level < 0) & (wanted <= k))
        if rows.size == 0:
            continue
        at = np.full(rows.size, k)
        coords, z = receiver_texels(clip, light_points[rows], light_normals[rows], at, settings=settings)
        local = _tap_pages(clip, coords, radius=radius, bits=settings.subtexel_bits) - clip.origin_page[k]
        inside = np.all((local >= 0) & (local < clip.pages_per_side), axis=(1, 2))
        good = inside.copy()
        good[inside] = holds(k, local[inside])
        level[rows[good]], coordinates[rows[good]], depth[rows[good]] = k, coords[good], z[good]
    return level, coordinates, depth


def read_levels(clip: Clipmap, light_points: np.ndarray, light_normals: np.ndarray, wanted: np.ndarray, *,
                settings: ShadowSettings, radius: int, table: np.ndarray | None,
                device: str = "cpu") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`chosen_levels` in a kernel (:func:`csmlab.kernels.levels.receiver_levels`), bit for bit.

    ``table`` (:attr:`VirtualPages.table`, ``(L, Q, Q)`` int32) holds a page where it is ``>= 0``;
    None holds every page of a level's box (marking). Returns ``level`` ``(N,)`` int64 (-1: none),
    ``coordinates`` ``(N, 2)`` int64 and ``depth`` ``(N,)`` float32, as :func:`chosen_levels`.
    """
    return receiver_levels(light_points, light_normals, wanted, texel=clip.texel, origin_page=clip.origin_page,
                           page_size=clip.page_size, pages_per_side=clip.pages_per_side, table=table,
                           normal_offset=settings.normal_offset, zref=clip.zref, bias_constant=settings.bias_constant,
                           bias_slope=settings.bias_slope, bits=settings.subtexel_bits, radius=radius, device=device)


def marked_pages(clip: Clipmap, light_points: np.ndarray, light_normals: np.ndarray, wanted: np.ndarray, *,
                 settings: ShadowSettings, radius: int) -> np.ndarray:
    """The pages the receivers need, ``(M, 3)`` int64 rows ``(level index, global page x, global page y)``.

    Each receiver marks the pages under the corners of its taps at the first level from its wanted
    one whose box holds them all (:func:`read_levels`), in a page mask of every level's box, as
    Unreal's page-marking pass fills its page-request flags; the rows are the marks in level, page
    row, page column order.
    """
    level, coordinates, _ = read_levels(clip, light_points, light_normals, wanted, settings=settings, radius=radius,
                                        table=None)
    used = level >= 0
    side = clip.pages_per_side
    local = _tap_pages(clip, coordinates[used], radius=radius, bits=settings.subtexel_bits) \
        - clip.origin_page[level[used]][:, None, :]
    mask = np.zeros(len(clip) * side * side, dtype=bool)
    mask[(level[used][:, None] * side + local[..., 1]) * side + local[..., 0]] = True
    k, rest = np.divmod(np.flatnonzero(mask), side * side)
    row, column = np.divmod(rest, side)
    return np.stack([k, column + clip.origin_page[k, 0], row + clip.origin_page[k, 1]], axis=1).astype(np.int64)


def resident_pages(marked: np.ndarray, *, pool: int) -> np.ndarray:
    """The marked pages ``(P, 3)`` the pool of ``pool`` pages holds, in their order: all, or the coarsest levels' first
    (within the last level kept, the first in page row, page column order)."""
    if len(marked) <= pool:
        return marked
    order = np.lexsort((marked[:, 1], marked[:, 2], -marked[:, 0]))
    return marked[np.sort(order[:pool])]


def page_table(clip: Clipmap, keys: np.ndarray) -> np.ndarray:
    """``(L, pages_per_side, pages_per_side)`` int32: each resident page's index in ``keys`` at its place, -1
    elsewhere."""
    table = np.full((len(clip), clip.pages_per_side, clip.pages_per_side), -1, dtype=np.int32)
    local = keys[:, 1:] - clip.origin_page[keys[:, 0]]
    table[keys[:, 0], local[:, 1], local[:, 0]] = np.arange(len(keys), dtype=np.int32)
    return table


def page_cache(keys: np.ndarray, clip: Clipmap, previous: VirtualPages | None) -> PageCache:
    """Which of this frame's resident pages ``keys`` the previous frame's pages hold, under the same light.

    Every page is a miss without a previous frame or when its light space (basis, depth offset)
    differs: a moved light invalidates the whole cache.
    """
    source = np.full(len(keys), -1, dtype=np.int64)
    if previous is not None and np.array_equal(previous.clipmap.basis, clip.basis) \
            and previous.clipmap.zref == clip.zref and len(previous.keys):
        index = {tuple(key): p for p, key in enumerate(previous.keys.tolist())}
        source = np.array([index.get(tuple(key), -1) for key in keys.tolist()], dtype=np.int64)
    return PageCache(kept=source >= 0, source=source)


def pool_bytes(pages: int, settings: ShadowSettings) -> int:
    """Bytes of ``pages`` pages of the pool: ``pages · page_size² · bytes per texel``."""
    return pages * settings.page_size * settings.page_size * texel_bytes(settings)
