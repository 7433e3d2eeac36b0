"""Every frame's per-pixel record for the interactive report, and the whole-run world maps.

The interactive page lets one scrub through every frame of every method and read the values of
the pixel under the cursor, so the run keeps, for each frame, the metrics' own per-pixel arrays
sampled on a regular grid of pixels — every ``stride``-th row and column, ``stride`` =
``ceil(W / VIEW_WIDTH)`` — not averaged: pixel ``(i, j)`` of the record *is* pixel
``(stride·i, stride·j)`` of the frame, and its numbers are those of :func:`csmlab.metrics.measure_frame`
there, quantized as stated in :func:`frame_pixels`.

It also keeps what the page's 3D view needs per frame (camera, frustum slices, cascade boxes) and,
at full resolution, what the whole-run maps add up: |ΔS| and lit/shadow flips per ground cell of a
fixed top-down :class:`WorldGrid` (Y up: cells over world x and z), and a histogram of log2 ρ per
cascade. Frames are summed in frame order in float64, so the totals do not depend on chunking.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from csmlab.frame import Frame, View
from csmlab.geometry import frustum_slice_corners
from csmlab.srgb import srgb_encoded

__all__ = [
    "NO_VALUE",
    "RHO_EDGES",
    "RHO_STEPS",
    "VIEW_WIDTH",
    "ViewPixels",
    "WORLD_CELLS",
    "WorldGrid",
    "box_corners",
    "code_rho",
    "decode_rho",
    "frame_pixels",
    "frustum_corners",
    "stack_pixels",
    "taa_pixels",
    "view_pixels",
    "world_grid",
]

VIEW_WIDTH = 320
"""Largest width in pixels of a frame's per-pixel record."""
WORLD_CELLS = 192
"""Ground cells along the longer side of the world grid."""
RHO_EDGES = np.linspace(-8.0, 8.0, 129)
"""Bin edges of the ρ histograms, in log2 ρ (1/8 octave); values outside fall in the end bins."""
NO_VALUE = 255
"""The code of "no value" in the uint8 planes."""
RHO_STEPS = 16
"""Codes per octave of the stored ρ (:func:`code_rho`)."""


@dataclass(frozen=True)
class WorldGrid:
    """A top-down grid of square ground cells over world x (columns) and z (rows).

    Attributes
    ----------
    x0, z0 : float
        World x and z of the grid's minimum corner, metres.
    cell : float
        Cell side, metres.
    nx, nz : int
        Cells along x and z.
    """

    x0: float
    z0: float
    cell: float
    nx: int
    nz: int

    def index(self, positions) -> np.ndarray:
        """Flat cell index ``row · nx + column`` of world ``positions`` (..., 3); -1 outside or NaN
        (:func:`csmlab.kernels.records.grid_cells`)."""
        from csmlab.kernels.records import grid_cells

        p = np.asarray(positions, dtype=np.float64)
        image = p if p.ndim == 3 else p.reshape(1, -1, 3)
        return grid_cells(image, x0=self.x0, z0=self.z0, cell=self.cell, nx=self.nx, nz=self.nz).reshape(p.shape[:-1])


def world_grid(camera_positions, *, reach: float, cells: int = WORLD_CELLS) -> WorldGrid:
    """The ground cells the shadows of a run can fall in: the camera path's x–z bounds grown by ``reach``.

    Parameters
    ----------
    camera_positions : array_like, shape (N, 3)
        World positions of the camera over the run, metres.
    reach : float, keyword-only
        How far from the camera a shadow is drawn (the largest shadow distance), metres.
    cells : int, keyword-only
        Cells along the longer side.
    """
    p = np.asarray(camera_positions, dtype=np.float64).reshape(-1, 3)
    low = p[:, [0, 2]].min(axis=0) - reach
    high = p[:, [0, 2]].max(axis=0) + reach
    cell = float(np.max(high - low)) / cells
    nx, nz = (int(np.ceil((high - low)[k] / cell)) for k in (0, 1))
    return WorldGrid(x0=float(low[0]), z0=float(low[1]), cell=cell, nx=max(nx, 1), nz=max(nz, 1))


def _stride(width: int) -> int:
    return max(1, -(-width // VIEW_WIDTH))


def _coded(values) -> np.ndarray:
    """Values in [0, 1] as ``round(254 · v)`` uint8, :data:`NO_VALUE` where NaN (precision ±1/508)."""
    values = np.asarray(values, dtype=np.float64)
    finite = np.isfinite(values)
    coded = np.rint(np.clip(np.where(finite, values, 0.0), 0.0, 1.0) * 254.0).astype(np.uint8)
    return np.where(finite, coded, np.uint8(NO_VALUE))


def code_rho(rho) -> np.ndarray:
    """ρ as uint8 ``round(RHO_STEPS · log2 ρ) + 127`` clipped to [0, 254], :data:`NO_VALUE` where undefined.

    The code covers ρ from ``2^(-127/16)`` ≈ 0.0041 to ``2^(127/16)`` ≈ 245 texels per pixel (values
    beyond are clipped to the ends) in steps of 1/16 octave: relative precision ±2.2 %.
    """
    rho = np.asarray(rho, dtype=np.float64)
    defined = np.isfinite(rho) & (rho > 0)
    steps = np.rint(RHO_STEPS * np.log2(np.where(defined, rho, 1.0))) + 127
    return np.where(defined, np.clip(steps, 0, 254), NO_VALUE).astype(np.uint8)


def decode_rho(coded) -> np.ndarray:
    """float64 ρ of :func:`code_rho`'s codes; NaN where :data:`NO_VALUE`."""
    coded = np.asarray(coded)
    return np.where(coded == NO_VALUE, np.nan, np.exp2((coded.astype(np.float64) - 127) / RHO_STEPS))


def frustum_corners(frame: Frame) -> np.ndarray:
    """World corners ``(C, 8, 3)`` of each cascade's slice of the view frustum (order of
    :func:`csmlab.geometry.frustum_slice_corners`), metres."""
    pose = frame.view.pose
    return np.stack([
        frustum_slice_corners(position=pose.position, orientation=pose.orientation, fov_y_deg=pose.fov_y_deg,
                              aspect=pose.aspect, z_near=c.split_near, z_far=c.split_far)
        for c in frame.maps.cascades.cascades
    ])


def box_corners(cascades) -> np.ndarray:
    """World corners ``(C, 8, 3)`` of each cascade's box: light x, y, depth each low/high, x fastest.

    A warped cascade's (``warp``) are its map's corners taken back through its homography: the
    quadrilateral its texels cover in light x/y, between the same depths.
    """
    high = ((np.arange(8)[:, None] >> np.arange(3)) & 1).astype(bool)
    boxes = []
    for c in cascades.cascades:
        if c.warp is None:
            boxes.append(np.where(high, [*c.box_max, c.depth_far], [*c.box_min, c.depth_near]))
            continue
        texels = np.column_stack([high[:, :2] * float(c.resolution), np.ones(8)])
        light = texels @ np.linalg.inv(c.homography).T
        boxes.append(np.column_stack([light[:, :2] / light[:, 2:], np.where(high[:, 2], c.depth_far, c.depth_near)]))
    return np.stack(boxes) @ cascades.basis


@dataclass(frozen=True)
class ViewPixels:
    """What :func:`frame_pixels` keeps of a view alone, the same for every method (:func:`view_pixels`).

    Attributes
    ----------
    stride : int
        Pixel stride of the sampled planes.
    cells : ndarray, shape (H, W), int64
        Flat ground cell (:meth:`WorldGrid.index`) of each pixel's G-buffer position; -1 outside
        the grid or on a miss.
    valid : ndarray, shape (h, w), bool
        The ray hit the scene, at the sampled pixels.
    reference : ndarray, shape (h, w), uint8
        The ray-traced shadow at the sampled pixels: 1 lit, 0 shadowed, :data:`NO_VALUE` no surface.
    """

    stride: int
    cells: np.ndarray
    valid: np.ndarray
    reference: np.ndarray


def view_pixels(view: View, *, grid: WorldGrid) -> ViewPixels:
    """The view-only part of :func:`frame_pixels`, which keeps it in :meth:`csmlab.frame.View.shared` for the view's
    methods.

    Parameters
    ----------
    view : View
        The rendered view, ``(H, W)`` pixels, with its ray-traced ``reference``.
    grid : WorldGrid, keyword-only
        The run's ground cells.
    """
    g = view.gbuffer
    k = _stride(g.shape[1])
    take = (slice(None, None, k), slice(None, None, k))
    reference = np.asarray(view.reference, dtype=np.float64)[take]
    return ViewPixels(stride=k, cells=grid.index(g.position),
                      valid=g.valid[take],
                      reference=np.where(np.isfinite(reference), reference > 0.5, NO_VALUE).astype(np.uint8))


def frame_pixels(frame: Frame, pixels: dict, *, grid: WorldGrid, taa: tuple | None = None,
                 ambient: float | None = None) -> dict:
    """The per-frame record of one method: sampled per-pixel values, 3D geometry, world-cell sums.

    Parameters
    ----------
    frame : Frame
        The rendered frame, ``(H, W)`` pixels.
    pixels : dict
        ``measures.pixels`` of :func:`csmlab.metrics.measure_frame`: ``rho``, ``dS``, ``shaded``,
        ``ref_diff`` and ``flipped`` (H, W).
    grid : WorldGrid, keyword-only
        The run's ground cells.
    taa : tuple of TaaResolve, keyword-only, optional
        Frame t's TAA resolves of the method's S and of R (:mod:`csmlab.metrics.taa`), when the run
        has ``[taa]`` on: the record then holds the after-TAA planes (:func:`taa_pixels`).
    ambient : float, keyword-only, optional
        The ambient term ``pixels["shaded"]`` was shaded with, in units of the direct light: the
        reference's and the after-TAA views are shaded the same way. None: :data:`csmlab.metrics.shading.AMBIENT`, the
        one runs use.

    Returns
    -------
    dict
        Sampled at pixels ``(stride·i, stride·j)``, shape ``(h, w)`` = ``ceil((H, W) / stride)``:
        ``lit`` and ``dS`` uint8 (``round(254 · v)``, precision ±1/508; 255 no value), ``cascade``
        int8 (-1 none), ``rho`` uint8 (texels per pixel coded by :func:`code_rho`, ±2.2 %),
        ``reference`` uint8 (the ray-traced shadow: 1 lit, 0 shadowed, 255 no surface),
        ``ref_diff`` int8 (+1 false shadow, -1 false light), ``shaded`` (h, w, 3) uint8 sRGB
        (0 where undefined), ``reference_shaded`` the same of the view through the ray-traced
        shadow (when ``pixels`` has it), 0 where the method's S is undefined (beyond its shadow
        distance too), so that the two sequences differ by the shadow alone; ``valid`` bool;
        ``grid`` (the ``grid`` argument); ``stride`` int; ``camera_position`` (3,), ``light_direction`` (3,),
        ``frustum_corners`` and ``box_corners`` (C, 8, 3), world metres;
        ``cells`` (K,) int64 flat indices of the ground cells that counted pixels fall in, with
        ``cell_dS`` (K,) float64 sum of |ΔS|, ``cell_counted`` and ``cell_flips`` (K,) int64, at
        full resolution; ``rho_hist`` (C, len(RHO_EDGES) - 1) int64: pixels per log2 ρ bin and
        selected cascade. The view-only part (:func:`view_pixels`) is computed once per view and
        grid, by the first method of the view. With ``taa``, also the keys of :func:`taa_pixels`.
    """
    from csmlab.kernels.records import cell_sums, log2_histogram

    view = frame.view
    per_view = view.shared(("view_pixels", grid), lambda: view_pixels(view, grid=grid))
    k = per_view.stride
    take = (slice(None, None, k), slice(None, None, k))
    lit = np.where(per_view.valid, frame.shadow.lit[take], np.nan)
    srgb = _srgb_u8(pixels["shaded"], take)
    dS = np.asarray(pixels["dS"], dtype=np.float64)
    dS_sum, counts, flips = cell_sums(per_view.cells, dS, pixels["flipped"], size=grid.nx * grid.nz)
    touched = np.flatnonzero(counts)
    rho = np.asarray(pixels["rho"], dtype=np.float64)
    cascade = np.asarray(frame.shadow.cascade)
    has = np.isfinite(rho) & (rho > 0) & (cascade >= 0)
    # The bin of log2 ρ among RHO_EDGES, whose edges are whole multiples of a power-of-two step
    # (1/8 octave): floor(log2 ρ / step) is exact, as a search among the edges is (log2_histogram).
    # log2 of the whole image (NaN or -inf where ρ is not positive, not read): an element-wise function,
    # the same value at a pixel as of the pixels with ρ alone, without gathering them.
    with np.errstate(divide="ignore", invalid="ignore"):
        log2_rho = np.log2(rho)
    hist = log2_histogram(log2_rho, cascade, has, edges=RHO_EDGES, groups=len(frame.maps.cascades))
    return {
        "grid": grid,
        "stride": k,
        "lit": _coded(lit),
        "dS": _coded(dS[take]),
        "cascade": cascade[take].astype(np.int8),
        "rho": code_rho(rho[take]),
        "reference": per_view.reference,
        "ref_diff": np.asarray(pixels["ref_diff"])[take].astype(np.int8),
        "shaded": srgb,
        **({"reference_shaded": _reference_srgb(view, k, ambient=ambient, defined=np.isfinite(lit))}
           if view.reference is not None else {}),
        "valid": per_view.valid,
        "camera_position": np.asarray(view.pose.position, dtype=np.float64),
        "light_direction": np.asarray(view.light_direction, dtype=np.float64),
        "frustum_corners": frustum_corners(frame),
        "box_corners": box_corners(frame.maps.cascades),
        "cells": touched.astype(np.int64),
        "cell_dS": dS_sum[touched],
        "cell_counted": counts[touched],
        "cell_flips": flips[touched],
        "rho_hist": hist,
        **({} if taa is None else taa_pixels(frame, pixels, *taa, stride=k, ambient=ambient)),
    }


def taa_pixels(frame: Frame, pixels: dict, shadow, reference, *, stride: int, ambient: float | None = None) -> dict:
    """The after-TAA part of :func:`frame_pixels`: the resolved S and R and the change of their difference.

    Parameters
    ----------
    frame : Frame
        The rendered frame, ``(H, W)`` pixels.
    pixels : dict
        ``measures.pixels``: its ``dS`` (H, W), NaN where the change before TAA is not counted.
    shadow, reference : TaaResolve
        Frame t's resolves of the method's S and of R (``out`` and ``reprojected``, (H, W)).
    stride : int, keyword-only
        Pixel stride of the record.
    ambient : float, keyword-only, optional
        Ambient term of the shading, in units of the direct light; None:
        :data:`csmlab.metrics.shading.AMBIENT`.

    Returns
    -------
    dict
        At pixels ``(stride·i, stride·j)``: ``lit_taa`` uint8 T^S_t, ``reference_taa`` uint8 T^R_t
        (the same for every method of a view) and ``dS_taa`` uint8 ``|(T^S_t − T^S_{t−1}(X)) −
        (T^R_t − T^R_{t−1}(X))|``, the change whose mean over the counted pixels is ``flicker_taa``
        (:func:`csmlab.metrics.taa.taa_summary`), clipped to 1 — all ``round(254 · v)``, 255 no
        value (no surface; for ``dS_taa`` also not counted before TAA or history dropped in either
        resolve, and the first frame); ``shaded_taa`` and ``reference_shaded_taa`` (h, w, 3) uint8
        sRGB of the view shaded through T^S and T^R as ``shaded`` is through S
        (:func:`csmlab.metrics.shading.shaded_rgb`), 0 where T^S is undefined.
    """
    from csmlab.metrics.shading import AMBIENT, shaded_rgb, view_shading_terms

    ambient = AMBIENT if ambient is None else ambient

    take = (slice(None, None, stride), slice(None, None, stride))
    s, s0 = (np.asarray(a, dtype=np.float64)[take] for a in (shadow.out, shadow.reprojected))
    r, r0 = (np.asarray(a, dtype=np.float64)[take] for a in (reference.out, reference.reprojected))
    counted = np.isfinite(np.asarray(pixels["dS"], dtype=np.float64)[take])
    with np.errstate(invalid="ignore"):
        change = np.where(counted, np.abs((s - s0) - (r - r0)), np.nan)
    view = frame.view
    full = view_shading_terms(view)
    terms = full.taken(take)
    g = view.gbuffer
    valid = np.asarray(g.valid)[take]

    def srgb(lit) -> np.ndarray:
        linear = shaded_rgb(terms.albedo, np.asarray(g.normal)[take], np.where(valid, lit, np.nan),
                            light_direction=view.light_direction, ambient=ambient, terms=terms)
        return _srgb_u8(linear, (slice(None), slice(None)))

    defined = valid & np.isfinite(s)
    return {
        "lit_taa": _coded(np.where(valid, s, np.nan)),
        "dS_taa": _coded(change),
        "reference_taa": _coded(np.where(valid, r, np.nan)),
        "shaded_taa": srgb(s),
        "reference_shaded_taa": np.where(defined[..., None], srgb(r), np.uint8(0)),
    }


def _srgb_u8(linear, take) -> np.ndarray:
    """uint8 sRGB ``(h, w, 3)`` of linear RGB ``(H, W, 3)`` at the pixels ``take``, 0 where undefined."""
    # The sampled pixels copied out first (contiguous, float64), then worked on in place: NumPy's
    # loops over a strided view cost several times their contiguous ones.
    rgb = np.array(np.asarray(linear)[take], dtype=np.float64, order="C")
    finite = np.isfinite(rgb)
    # Three column tests: np.all over a length-3 last axis is several times slower.
    rgb[~(finite[..., 0] & finite[..., 1] & finite[..., 2])] = 0.0  # 0 where undefined: sRGB(0) = 0
    srgb = srgb_encoded(rgb)
    srgb *= 255.0
    return np.rint(srgb, out=srgb).astype(np.uint8)


def _reference_srgb(view: View, stride: int, *, ambient: float | None, defined) -> np.ndarray:
    """uint8 sRGB ``(h, w, 3)`` of the view shaded through its ray-traced reference at every ``stride``-th pixel, 0
    where not ``defined`` ``(h, w)``.

    Shaded once per view and only at the sampled pixels: :func:`csmlab.metrics.shading.shaded_rgb` is a function of
    each pixel alone, so these are the values of the whole image's shading there, for a quarter of the work at the
    default stride of 2 (no column or map reads the other pixels).
    """
    from csmlab.metrics.shading import AMBIENT, shaded_rgb, view_shading_terms

    ambient = AMBIENT if ambient is None else ambient
    take = (slice(None, None, stride), slice(None, None, stride))

    def srgb() -> np.ndarray:
        terms = view_shading_terms(view).taken(take)
        g = view.gbuffer
        lit = np.where(np.asarray(g.valid)[take], np.asarray(view.reference)[take], np.nan)
        linear = shaded_rgb(terms.albedo, np.asarray(g.normal)[take], lit, light_direction=view.light_direction,
                            ambient=ambient, terms=terms)
        return _srgb_u8(linear, (slice(None), slice(None)))

    return np.where(defined[..., None], view.shared(("reference_srgb", stride, ambient), srgb), np.uint8(0))


_PER_FRAME = ("lit", "dS", "cascade", "rho", "reference", "ref_diff", "shaded", "valid", "camera_position",
              "light_direction", "frustum_corners", "box_corners")
_PER_FRAME_WHEN_KEPT = ("reference_shaded", "lit_taa", "dS_taa", "reference_taa", "shaded_taa",
                        "reference_shaded_taa")
"""Per-frame arrays a record holds only when every frame has them (a view without its ray-traced reference has
none; a run without ``[taa]`` has no after-TAA ones)."""


def stack_pixels(records: list[dict]) -> dict:
    """The arrays of a ``pixels/<method>__<point>.npz`` file from consecutive :func:`frame_pixels` records.

    Returns
    -------
    dict
        Each per-frame array of :func:`frame_pixels` stacked along a new first axis (N, …) (``reference_shaded``
        and the after-TAA ones of :func:`taa_pixels` when every record has them);
        ``stride``; the world grid ``world_origin`` (2,) (x, z metres), ``world_cell`` (metres),
        ``world_dS`` (nz, nx) float64 summed |ΔS|, ``world_counted`` and ``world_flips`` (nz, nx)
        int64 over every frame; ``rho_edges`` and ``rho_hist`` (C, bins) int64 summed.

    Raises
    ------
    ValueError
        If the records differ in world grid, stride, image size or cascade count.
    """
    shapes = {(r["grid"], r["stride"], r["lit"].shape, r["box_corners"].shape) for r in records}
    if len(shapes) != 1:
        raise ValueError(f"pixel records: expected one world grid, stride, image size and cascade count, "
                         f"got {len(shapes)} different ones")
    grid = records[0]["grid"]
    size = grid.nx * grid.nz
    dS, counted, flips = np.zeros(size), np.zeros(size, dtype=np.int64), np.zeros(size, dtype=np.int64)
    for r in records:
        dS[r["cells"]] += r["cell_dS"]
        counted[r["cells"]] += r["cell_counted"]
        flips[r["cells"]] += r["cell_flips"]
    return {
        **{name: np.stack([r[name] for r in records]) for name in _PER_FRAME},
        **{name: np.stack([r[name] for r in records]) for name in _PER_FRAME_WHEN_KEPT
           if all(name in r for r in records)},
        "stride": np.int64(records[0]["stride"]),
        "world_origin": np.array([grid.x0, grid.z0]),
        "world_cell": np.float64(grid.cell),
        "world_dS": dS.reshape(grid.nz, grid.nx),
        "world_counted": counted.reshape(grid.nz, grid.nx),
        "world_flips": flips.reshape(grid.nz, grid.nx),
        "rho_edges": RHO_EDGES.copy(),
        "rho_hist": np.sum([r["rho_hist"] for r in records], axis=0),
    }
