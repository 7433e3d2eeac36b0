"""What the report keeps of each rendered frame, and the files it is kept in.

A run renders frames in worker processes and throws the frames away; :func:`capture_frame` keeps
the little the report needs from each one as a small picklable record, and the parent process
hands each method × sweep point's records, in frame order, to :func:`write_captures`.

Files written under the results directory (all deterministic: same captures, same bytes;
``<method>__<point>`` is :func:`capture_stem`, the names made file-safe, a sweep label's ``/``
becoming ``_``):

``cascades.csv``
    One row per frame × method × point × cascade: ``frame, method, point, cascade, texel_x,
    texel_y`` (metres per texel), ``origin_x, origin_y`` (box minimum corner in texels of that
    frame's texel size; whole numbers once snapped), ``extent_x, extent_y`` (box size, metres),
    ``split_near, split_far`` (the cascade's split interval, metres of view depth). Rows are
    sorted by method, point, frame, cascade, so the file does not depend on the order in which
    method × point pairs were written, and writing a pair again replaces its rows.
``anim/<method>__<point>.npz``
    The animation frames (every frame of the run, or the even sample a long path keeps images of,
    :data:`csmlab.experiment.IMAGE_FRAMES`): ``frame`` (N,) int64, ``time_s`` (N,) float64, ``shadow`` and ``dS``
    (N, h, w) uint8 — the lit fraction S and the per-pixel temporal change |ΔS|, block-reduced to
    at most :data:`ANIM_WIDTH` pixels wide (mean of S, max of |ΔS| so that one flickering pixel
    stays visible) and coded ``round(254 · v)``, with 255 where there is no value (no surface, or
    frame 0 for |ΔS|); ``method``, ``point`` (0-d str).
``snapshots/<method>__<point>__f<frame>.npz``
    One snapshot frame at full resolution: ``frame``, ``time_s``, ``method``, ``point``;
    ``valid`` (H, W) bool (the ray hit the scene); ``shaded`` (H, W, 3) float32 linear RGB
    (NaN where no shadow is defined); ``cascade`` (H, W) int8 (-1 none); ``rho`` (H, W) float32
    texels per pixel; ``dS`` (H, W) float32 (NaN undefined); ``ref_diff`` (H, W) int8 (+1 false
    shadow, -1 false light);
    and for the 3D view, in world metres: ``camera_position`` (3,), ``light_direction`` (3,),
    ``frustum_corners`` (C, 8, 3) (each cascade's split slice, corner order of
    :func:`csmlab.geometry.frustum_slice_corners`), ``box_corners`` (C, 8, 3) (each cascade's
    light-space box: x, y, depth each low/high, x fastest), ``points`` (P, 3) float32 (visible
    surface points, every :data:`POINT_STRIDE`-th pixel) and ``point_cascade`` (P,) int8.

``pixels/<method>__<point>.npz``
    Every frame's per-pixel record for the interactive page, when the run kept one: the arrays
    of :func:`csmlab.report.pixels.stack_pixels` (values sampled every ``stride``-th pixel,
    per-frame cascade geometry, whole-run world-cell sums and ρ histograms; with ``[taa]`` on, the
    after-TAA planes of :func:`csmlab.report.pixels.taa_pixels` too) with ``frame`` (N,)
    int64 and ``time_s`` (N,) float64.
``casters.npz``
    ``points`` (P, 3) float32: centroids of an even sample of the scene's triangles (world
    metres), drawn as the casters of the interactive 3D view (:func:`write_casters`).

The 3D view draws the scene as the camera sees it — the visible surface points — so the
results directory alone is enough to redraw it; no scene is rebuilt.
"""

from __future__ import annotations

import csv
import io
import re
import threading
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from csmlab.files import write_atomic
from csmlab.frame import Frame
from csmlab.report.pixels import WorldGrid, box_corners, frame_pixels, frustum_corners, stack_pixels

if TYPE_CHECKING:
    from csmlab.metrics import FrameMeasures

__all__ = [
    "ANIM_WIDTH",
    "CASCADE_COLUMNS",
    "CASTER_POINTS",
    "Capture",
    "POINT_STRIDE",
    "capture_frame",
    "capture_stem",
    "decode_u8",
    "default_snapshot_frames",
    "read_npz",
    "safe_name",
    "write_captures",
    "write_casters",
]

ANIM_WIDTH = 320
"""Largest width in pixels of an animation frame."""
POINT_STRIDE = 4
"""Pixel stride of the visible points kept for the 3D view (every 4th row and column)."""
CASCADE_COLUMNS = ("texel_x", "texel_y", "origin_x", "origin_y", "extent_x", "extent_y", "split_near", "split_far")
"""Per-cascade quantities of :func:`capture_frame`'s ``"cascades"`` array, in column order."""
CASTER_POINTS = 6000
"""Most scene points kept for the interactive 3D view's casters."""
_NO_VALUE = 255
_CASCADES_CSV = threading.Lock()
"""Held while ``cascades.csv`` is read, merged and written: variants' captures may be written on
several threads (:func:`csmlab.experiment.run_experiment`), and they share that one file."""
_SNAPSHOT_COUNT = 3


@dataclass(frozen=True)
class Capture:
    """The report's record of one frame of one method (:func:`capture_frame`): small, picklable, plain NumPy.

    Attributes
    ----------
    frame : int
    time_s : float
        The camera pose's time stamp, seconds.
    cascades : ndarray, shape (C, 8), float64
        Per cascade, the columns :data:`CASCADE_COLUMNS`.
    shadow, dS : ndarray, shape (h, w), uint8, or None
        Block-reduced lit fraction S and temporal change |ΔS|, coded as in the module docstring;
        None when the run keeps no images of this frame (a long path keeps an even sample).
    snapshot : dict of str to ndarray or None
        The snapshot file's arrays; None when the frame is not a snapshot frame.
    pixels : dict or None
        The interactive page's per-pixel record (:func:`csmlab.report.pixels.frame_pixels`); None
        when the run keeps none.
    """

    frame: int
    time_s: float
    cascades: np.ndarray
    shadow: np.ndarray | None
    dS: np.ndarray | None
    snapshot: dict | None
    pixels: dict | None


def default_snapshot_frames(n_frames: int) -> list[int]:
    """Frames whose full-resolution images go into the report: three spread over the run.

    Frame 0 has no temporal change, so the spread starts at frame 1 when there is one.

    Parameters
    ----------
    n_frames : int
        Frames in the run, at least 1.

    Returns
    -------
    list of int
        Sorted distinct frame indices in ``[0, n_frames)``.
    """
    if n_frames < 1:
        raise ValueError(f"n_frames: expected at least 1 frame, got {n_frames}")
    if n_frames == 1:
        return [0]
    return sorted({int(round(f)) for f in np.linspace(1, n_frames - 1, _SNAPSHOT_COUNT)})


def capture_frame(frame: Frame, measures: FrameMeasures, *, snapshot: bool,
                  grid: WorldGrid | None = None, images: bool = True, taa: tuple | None = None) -> Capture:
    """The report's record of one frame of one method.

    Parameters
    ----------
    frame : Frame
        The rendered frame.
    measures : FrameMeasures
        Its metrics; ``measures.pixels`` must hold ``"dS"`` (H, W) and, when ``snapshot``,
        ``"rho"`` (H, W), ``"shaded"`` (H, W, 3) and ``"ref_diff"`` (H, W).
    snapshot : bool
        Also keep the full-resolution images and the 3D view's geometry.
    grid : WorldGrid, optional
        The run's ground cells: also keep the interactive page's per-pixel record
        (:func:`csmlab.report.pixels.frame_pixels`; ``measures.pixels`` must then hold
        ``"flipped"`` and ``"shaded"``).
    images : bool
        Keep the animation frame and the per-pixel record; False keeps the cascade rows (and the
        snapshot, when asked) only.
    taa : tuple of TaaResolve, optional
        Frame t's TAA resolves of the method's S and of R, when the run has ``[taa]`` on: the
        per-pixel record also keeps the after-TAA planes (:func:`csmlab.report.pixels.taa_pixels`).

    Returns
    -------
    Capture
        ``pixels`` is None without ``grid`` or ``images``, ``shadow`` and ``dS`` None without
        ``images``, ``snapshot`` None without ``snapshot``.
    """
    pixels = measures.pixels
    shadow, dS = _animation_planes(frame.shadow.lit, pixels["dS"]) if images else (None, None)
    return Capture(
        frame=int(frame.view.index),
        time_s=float(frame.view.pose.time_s),
        cascades=_cascade_rows(frame),
        shadow=shadow,
        dS=dS,
        snapshot=_snapshot(frame, pixels) if snapshot else None,
        pixels=frame_pixels(frame, pixels, grid=grid, taa=taa) if images and grid is not None else None,
    )


def decode_u8(coded: np.ndarray) -> np.ndarray:
    """Values in [0, 1] as float32 of an array coded by :func:`capture_frame`; NaN where 255."""
    coded = np.asarray(coded)
    return np.where(coded == _NO_VALUE, np.float32(np.nan), coded.astype(np.float32) / 254.0)


def safe_name(name: str) -> str:
    """``name`` fit for a file name: characters outside ``[A-Za-z0-9._=+-]`` made ``_`` (``/`` of sweep labels too)."""
    return re.sub(r"[^A-Za-z0-9._=+-]", "_", str(name)) or "_"


def capture_stem(method: str, point: str) -> str:
    """File-name stem ``<method>__<point>`` of a method × sweep point's capture files."""
    return f"{safe_name(method)}__{safe_name(point)}"


def write_captures(out_dir, *, method: str, point: str, captures: list[Capture]) -> None:
    """Write one method × sweep point's captures, frames in order (files in the module docstring).

    The pair's earlier files are replaced: its rows of ``cascades.csv``, its animation and every
    snapshot of it, so that a run written over an older one keeps no stale frame.

    Parameters
    ----------
    out_dir : str or Path
        The results directory.
    method, point : str
        The method's name and the sweep point's label, as in ``metrics.csv``.
    captures : list of Capture
        :func:`capture_frame` records of consecutive frames, in frame order; the animation and the
        pixel record hold the frames that kept images.

    Raises
    ------
    ValueError
        If ``captures`` is empty, not in increasing frame order, mixes image sizes, or holds pixel
        records for some of the frames that kept images only.
    """
    out = Path(out_dir)
    if not captures:
        raise ValueError(f"captures of {method!r} at {point!r}: expected at least one frame, got none")
    frames = np.array([c.frame for c in captures], dtype=np.int64)
    if np.any(np.diff(frames) <= 0):
        raise ValueError(f"captures of {method!r} at {point!r}: expected increasing frame numbers, "
                         f"got {frames.tolist()}")
    imaged = [c for c in captures if c.shadow is not None]
    shapes = {c.shadow.shape for c in imaged}
    if len(shapes) > 1:
        raise ValueError(f"captures of {method!r} at {point!r}: expected one image size, got {sorted(shapes)}")
    stem = capture_stem(method, point)
    with _CASCADES_CSV:
        _merge_cascades_csv(out / "cascades.csv", method=method, point=point, captures=captures)
    (out / "anim" / f"{stem}.npz").unlink(missing_ok=True)
    if imaged:
        _write_npz(out / "anim" / f"{stem}.npz", {
            "frame": np.array([c.frame for c in imaged], dtype=np.int64),
            "time_s": np.array([c.time_s for c in imaged], dtype=np.float64),
            "shadow": np.stack([c.shadow for c in imaged]),
            "dS": np.stack([c.dS for c in imaged]),
            "method": np.array(method),
            "point": np.array(point),
        })
    kept = [c.pixels for c in imaged if c.pixels is not None]
    if kept and len(kept) != len(imaged):
        raise ValueError(f"captures of {method!r} at {point!r}: expected a pixel record for every frame with images "
                         f"or none, got {len(kept)} of {len(imaged)}")
    (out / "pixels" / f"{stem}.npz").unlink(missing_ok=True)
    if kept:
        _write_npz(out / "pixels" / f"{stem}.npz", {
            "frame": np.array([c.frame for c in imaged], dtype=np.int64),
            "time_s": np.array([c.time_s for c in imaged], dtype=np.float64), **stack_pixels(kept)})
    for stale in sorted((out / "snapshots").glob(f"{stem}__f*.npz")):
        stale.unlink()
    for c in captures:
        if c.snapshot is not None:
            arrays = {"frame": np.int64(c.frame), "time_s": np.float64(c.time_s), "method": np.array(method),
                      "point": np.array(point), **c.snapshot}
            _write_npz(out / "snapshots" / f"{stem}__f{c.frame}.npz", arrays)


def write_casters(out_dir, vertices, triangles, *, count: int = CASTER_POINTS) -> None:
    """Write ``casters.npz``: the centroids of every ``ceil(T / count)``-th triangle of the scene.

    Parameters
    ----------
    out_dir : str or Path
        The results directory.
    vertices : array_like, shape (V, 3)
        World positions, metres.
    triangles : array_like, shape (T, 3), int
        Vertex indices.
    count : int, keyword-only
        Most points kept.
    """
    triangles = np.asarray(triangles)
    step = max(1, -(-len(triangles) // count))
    centroids = np.asarray(vertices, dtype=np.float64)[triangles[::step]].mean(axis=1)
    _write_npz(Path(out_dir) / "casters.npz", {"points": centroids.astype(np.float32)})


def read_npz(path) -> dict[str, np.ndarray]:
    """Every array of an ``.npz`` capture file, loaded (0-d str arrays become ``str``)."""
    with np.load(path, allow_pickle=False) as data:
        return {k: (str(v) if v.dtype.kind == "U" and v.ndim == 0 else v) for k, v in data.items()}


def _cascade_rows(frame: Frame) -> np.ndarray:
    return np.array([[*c.texel_size, *c.origin, *c.extent, c.split_near, c.split_far]
                     for c in frame.maps.cascades.cascades], dtype=np.float64)


def _anim_factor(width: int) -> int:
    return max(1, -(-width // ANIM_WIDTH))


def _block_reduce(values: np.ndarray, ufunc: np.ufunc, dtype) -> np.ndarray:
    """``ufunc`` over each whole ``k``×``k`` block of ``values`` (H, W): ``(H // k, W // k)`` of ``dtype``.

    Each block's rows are reduced first, then the row results top to bottom: for a sum, the order
    of NumPy's own ``sum(axis=(1, 3))`` over the ``(h, k, w, k)`` blocks, so means keep their bits,
    but as strided whole-image operations instead of a reduction over non-adjacent axes (slow in
    NumPy). A row of fewer than 8 values NumPy sums left to right, as the loop over ``k`` does;
    longer ones it sums pairwise, so those rows are left to its own reduction.
    """
    k = _anim_factor(values.shape[1])
    h, w = values.shape[0] // k, values.shape[1] // k
    cut = values[: h * k, : w * k]
    if k >= 8:
        rows = ufunc.reduce(cut.reshape(h * k, w, k), axis=-1, dtype=dtype)
    else:
        rows = cut[:, 0::k].astype(dtype)
        for b in range(1, k):
            ufunc(rows, cut[:, b::k], out=rows)
    total = rows[0::k].copy()
    for a in range(1, k):
        ufunc(total, rows[a::k], out=total)
    return total


def _animation_planes(lit, change) -> tuple[np.ndarray, np.ndarray]:
    """An animation frame's planes: the coded block mean of S and block maximum of |ΔS| ``(H // k, W // k)`` uint8.

    One kernel pass over the frame (:func:`csmlab.kernels.records.animation_codes`) for blocks under 8
    pixels wide; wider ones (images over 7 × :data:`ANIM_WIDTH`) NumPy sums pairwise, as
    :func:`_block_reduce` does.
    """
    k = _anim_factor(np.shape(lit)[1])
    if k >= 8:
        return _coded_u8(_block_mean(lit)), _coded_u8(_block_max(np.abs(change)))
    from csmlab.kernels.records import animation_codes

    return animation_codes(lit, change, k=k)


def _block_mean(values) -> np.ndarray:
    values = np.asarray(values, dtype=np.float64)
    defined = np.isfinite(values)
    count = _block_reduce(defined, np.add, np.int64)
    total = _block_reduce(np.where(defined, values, 0.0), np.add, np.float64)
    return np.where(count > 0, total / np.maximum(count, 1), np.nan)


def _block_max(values) -> np.ndarray:
    values = np.asarray(values, dtype=np.float64)
    largest = _block_reduce(np.where(np.isfinite(values), values, -1.0), np.maximum, np.float64)
    return np.where(largest >= 0.0, largest, np.nan)


def _coded_u8(values: np.ndarray) -> np.ndarray:
    finite = np.isfinite(values)
    coded = np.rint(np.clip(np.where(finite, values, 0.0), 0.0, 1.0) * 254.0).astype(np.uint8)
    return np.where(finite, coded, np.uint8(_NO_VALUE))


def _snapshot(frame: Frame, pixels: dict) -> dict:
    view, cascades = frame.view, frame.maps.cascades
    valid = view.gbuffer.valid
    stride = (slice(None, None, POINT_STRIDE), slice(None, None, POINT_STRIDE))
    keep = valid[stride]
    return {
        "valid": valid,
        "shaded": np.asarray(pixels["shaded"], dtype=np.float32),
        "cascade": np.asarray(frame.shadow.cascade, dtype=np.int8),
        "rho": np.asarray(pixels["rho"], dtype=np.float32),
        "dS": np.asarray(pixels["dS"], dtype=np.float32),
        "ref_diff": np.asarray(pixels["ref_diff"], dtype=np.int8),
        "camera_position": np.asarray(view.pose.position, dtype=np.float64),
        "light_direction": np.asarray(view.light_direction, dtype=np.float64),
        "frustum_corners": frustum_corners(frame),
        "box_corners": box_corners(cascades),
        "points": np.asarray(view.gbuffer.position[stride][keep], dtype=np.float32),
        "point_cascade": np.asarray(frame.shadow.cascade[stride][keep], dtype=np.int8),
    }


def _merge_cascades_csv(path: Path, *, method: str, point: str, captures: list[Capture]) -> None:
    header = ["frame", "method", "point", "cascade", *CASCADE_COLUMNS]
    rows = []
    if path.exists():
        with open(path, newline="") as f:
            reader = csv.reader(f)
            next(reader, None)
            rows = [r for r in reader if (r[1], r[2]) != (method, point)]
    for c in captures:
        for i, values in enumerate(c.cascades):
            rows.append([str(c.frame), method, point, str(i), *(repr(float(v)) for v in values)])
    rows.sort(key=lambda r: (r[1], r[2], int(r[0]), int(r[3])))
    text = io.StringIO()
    writer = csv.writer(text, lineterminator="\n")
    writer.writerow(header)
    writer.writerows(rows)
    write_atomic(path, text.getvalue().encode())


_ZIP_LEVEL = 2
"""zlib level of the ``.npz`` files. The run-wide records are written after the last frame, while
nothing else runs; zlib's default (6) took 1.38 s over a 240-frame 640×360 run's records (7.9 MB),
level 2 takes 0.45 s (10.4 MB; level 1: 0.44 s, 11.0 MB; level 3: 0.55 s, 9.9 MB). The files
count against the report's size budget (:data:`csmlab.report.explore.BUDGET_BYTES`)."""


def _write_npz(path: Path, arrays: dict) -> None:
    """An ``.npz`` whose bytes depend on the arrays only (numpy's own stamps the time)."""
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", compression=zipfile.ZIP_DEFLATED) as archive:
        for name, value in arrays.items():
            member = io.BytesIO()
            np.lib.format.write_array(member, np.asarray(value), allow_pickle=False)
            info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            archive.writestr(info, member.getvalue(), compresslevel=_ZIP_LEVEL)
    write_atomic(path, buffer.getvalue())
