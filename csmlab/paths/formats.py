"""Recorded camera paths: the formats by name, and reading or writing a :class:`CameraPath`.

:func:`read_path` reads a file in its format (:data:`PATH_FORMATS`), converts its poses from the
format's (or the given) convention into csmlab's (:data:`~csmlab.paths.conventions.CONVENTIONS`),
then scales positions and adds the offset, shifts times, and resamples to a frame rate when
asked. A broken file stops with an :class:`~csmlab.errors.InputError` naming the file, line and
field, before any pose is returned.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from collections.abc import Callable

import numpy as np

from csmlab.camera import CameraPath
from csmlab.documents import MAX_FRAMES, json_value, within_limit
from csmlab.errors import InputError
from csmlab.paths.conventions import convention_named, poses_from_opengl, poses_to_opengl
from csmlab.paths.euroc import read_euroc, write_euroc
from csmlab.paths.gltf import read_gltf_camera, write_gltf_camera
from csmlab.paths.kitti import read_kitti, read_kitti_times, write_kitti
from csmlab.paths.nerfstudio import read_nerfstudio, write_nerfstudio
from csmlab.paths.recorded import RecordedPoses, data_rows, require_poses, text_lines
from csmlab.paths.tabular import read_csv, read_json, write_csv, write_json
from csmlab.paths.timing import GAP_RULES, TimingReport, find_gaps, frames_outside_gaps, resolve_duplicates
from csmlab.paths.tum import read_tum, write_tum
from csmlab.registry import check_name

__all__ = ["ANCHORS", "PATH_FORMATS", "PathFormat", "Recording", "guess_format", "read_path", "read_recording",
           "write_path"]

ANCHORS: tuple[str, ...] = ("", "first")
"""``[camera] anchor``: ``""`` keeps the file's positions (then scale, then offset); ``"first"`` puts the
first pose at ``offset`` (georeferenced paths: UTM eastings/northings of 10⁵–10⁶ m)."""


@dataclass(frozen=True)
class PathFormat:
    """One camera-path file format.

    Attributes
    ----------
    read : callable
        ``read(file) -> RecordedPoses``: the file's poses in its own axes, checked.
    write : callable
        ``write(poses: RecordedPoses, file) -> None``.
    convention : str
        The convention its files are read and written in unless one is given.
    description : str
        One line for ``csmlab list``.
    options : tuple of str
        Keywords of :func:`read_recording` that ``read`` takes as well (glTF: ``camera``, ``fps``).
    """

    read: Callable[..., RecordedPoses]
    write: Callable[..., None]
    convention: str
    description: str
    options: tuple[str, ...] = ()


PATH_FORMATS: dict[str, PathFormat] = {
    "tum": PathFormat(read_tum, write_tum, "tum", "TUM: 'timestamp tx ty tz qx qy qz qw' per line, # comments"),
    "kitti": PathFormat(read_kitti, write_kitti, "kitti",
                        "KITTI odometry: 12 numbers per line (3×4 camera-to-world), times from times_file or fps"),
    "euroc": PathFormat(read_euroc, write_euroc, "euroc",
                        "EuRoC ground truth CSV: #timestamp [ns], p xyz, q wxyz, further columns ignored"),
    "csv": PathFormat(read_csv, write_csv, "opengl",
                      "csmlab CSV: header time,x,y,z then qx,qy,qz,qw or yaw,pitch,roll [,fov_y_deg]"),
    "json": PathFormat(read_json, write_json, "opengl", "csmlab JSON: {\"poses\": [{time, x, y, z, qx, ...}, ...]}"),
    "gltf": PathFormat(read_gltf_camera, write_gltf_camera, "opengl",
                       "glTF 2.0 (.gltf/.glb): an animated camera node sampled at the frame times (camera = its name)",
                       options=("camera", "fps")),
    "nerfstudio": PathFormat(read_nerfstudio, write_nerfstudio, "nerfstudio",
                             "nerfstudio camera-path JSON: camera_path [{camera_to_world (4×4 row-major), fov}], "
                             "seconds, render_width/height"),
}
"""Path formats by name; add an entry to register a new one."""


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def guess_format(file) -> str:
    """The name of ``file``'s format in :data:`PATH_FORMATS`, from its extension and first lines.

    ``.gltf``/``.glb`` → gltf; ``.json`` or a leading ``{`` → nerfstudio when the object has a
    ``camera_path`` key, else json; a ``#timestamp`` header → euroc; a comma-separated
    first row → csv when it is a header of names, euroc when it holds eight or more numbers;
    a whitespace-separated first row of 8 numbers → tum, of 12 → kitti.

    Raises
    ------
    InputError
        If the file is empty or matches no rule.
    """
    if Path(file).suffix.lower() in (".gltf", ".glb"):
        return "gltf"
    lines = text_lines(file)
    first = next((text.strip() for text in lines if text.strip()), "")
    if Path(file).suffix.lower() == ".json" or first.startswith("{"):
        try:
            document = json_value("\n".join(lines), file=file)
        except InputError:
            return "json"  # its reader locates the syntax error (or the nesting too deep)
        return "nerfstudio" if document.is_object() and document.has("camera_path") else "json"
    if first.lower().startswith("#timestamp"):
        return "euroc"
    rows = data_rows(lines)
    require_poses(rows, file=file, line_count=len(lines))
    number, tokens = rows[0]
    text = lines[number - 1]
    if "," in text:
        fields = [f.strip() for f in text.split(",")]
        if not _is_number(fields[0]):
            return "csv"
        if len(fields) >= 8:
            return "euroc"
    elif len(tokens) in (8, 12):
        return "tum" if len(tokens) == 8 else "kitti"
    raise InputError(f"cannot tell the path format from this line; pass format= one of {sorted(PATH_FORMATS)}",
                     file=file, line=number, field="format")


def _format(name: str) -> PathFormat:
    check_name(name, PATH_FORMATS, field="format")
    return PATH_FORMATS[name]


def _times(recorded: RecordedPoses, *, times_file, fps) -> np.ndarray:
    """Time stamps of ``recorded``: its own, else from ``times_file``, else ``i / fps``."""
    if recorded.times is not None:
        if times_file is not None:
            raise ValueError(f"times_file: only for a format without time stamps (kitti); {recorded.file} has its own")
        return recorded.times
    if times_file is not None:
        return read_kitti_times(times_file, count=recorded.positions.shape[0])
    if fps is not None:
        return np.arange(recorded.positions.shape[0], dtype=np.float64) / fps
    raise InputError("this format has no time stamps: give times_file (one time per line) or fps",
                     file=recorded.file, field="times_file")


@dataclass(frozen=True)
class Recording:
    """A recorded path as csmlab renders it, with what its time stamps held.

    Attributes
    ----------
    path : CameraPath
    timing : TimingReport
        Repeated stamps and tracking gaps, and the rules applied.
    restarts : ndarray, shape (K,), float64
        Times (the path's clock) of frames that follow a cut gap: the camera jumped there, so
        their temporal metrics are undefined. Empty unless ``gaps = "cut"``.
    """

    path: CameraPath
    timing: TimingReport
    restarts: np.ndarray


def read_recording(file, *, format: str | None = None, camera: str = "", convention: str | None = None,
                   scale: float = 1.0,
                   offset=(0.0, 0.0, 0.0), anchor: str = "", time_offset: float = 0.0, fps: float | None = None,
                   times_file=None, from_first_pose: bool = False, duplicate_times: str = "first",
                   max_gap: float | None = None, gaps: str = "interpolate", fov_y_deg: float = 60.0,
                   aspect: float = 16.0 / 9.0, near: float = 0.1, far: float = 400.0) -> Recording:
    """Read a recorded camera path into csmlab's convention, resolving repeated stamps and gaps.

    Parameters
    ----------
    file : str or Path
        The path file.
    format : str, optional
        A key of :data:`PATH_FORMATS`; guessed by :func:`guess_format` when ``None``.
    camera : str
        gltf only: the camera node's (or camera's) name; may be empty when the file has one camera.
    convention : str, optional
        A key of :data:`~csmlab.paths.conventions.CONVENTIONS`; the format's own when ``None``
        (tum → ``tum``, kitti → ``kitti``, euroc → ``euroc``, csv/json → ``opengl``).
    scale : float
        Factor on positions after conversion to metres (desk-scale recordings → a scene).
    offset : array_like, shape (3,)
        Metres added to every position after scaling, in csmlab's world.
    anchor : str
        ``""`` or ``"first"`` (:data:`ANCHORS`): with ``"first"`` the first pose's position is
        subtracted in float64 in the file's own coordinates, before any conversion, so the path
        starts at ``offset`` and large (UTM) coordinates keep their millimetres.
    time_offset : float
        Seconds added to every time stamp (``-t0`` starts a path at zero).
    fps : float, optional
        Frame rate in Hz: the path is resampled to it from its first time stamp (positions
        linearly, orientations by slerp). For KITTI without ``times_file`` it sets the time
        stamps ``i / fps`` instead.
    times_file : str or Path, optional
        KITTI only: one time in seconds per pose, one per line.
    from_first_pose : bool
        Measure time from the first pose (which then sits at ``time_offset``) instead of keeping
        the recorded clock (often Unix time); resampling then lands on exact multiples of 1/fps.
    duplicate_times : str
        Rule for poses under one time stamp (:data:`csmlab.paths.timing.DUPLICATE_RULES`).
    max_gap : float, optional
        Seconds between consecutive poses beyond which a step is a tracking gap; ``None``:
        :data:`csmlab.paths.timing.GAP_FACTOR` × the median step.
    gaps : str
        What a gap does (:data:`csmlab.paths.timing.GAP_RULES`).
    fov_y_deg, aspect, near, far : float
        Projection (degrees, width/height, metres, metres); what the file states wins: a
        ``fov_y_deg`` column or ``yfov``/``fov``, an aspect (glTF ``aspectRatio``, nerfstudio's
        render size), clip distances (glTF ``znear``/``zfar``, times ``scale``).

    Returns
    -------
    Recording
        Its path is named after the file.

    Raises
    ------
    InputError
        On a broken file, located (file, line, field); on a repeated stamp with
        ``duplicate_times = "error"`` or a gap with ``gaps = "error"``.
    ValueError
        On a bad argument (unknown format, convention or rule, non-positive scale, fps or max_gap, ...).
    """
    name = format if format is not None else guess_format(file)
    spec = _format(name)
    convention = convention if convention is not None else spec.convention
    convention_named(convention)
    offset = np.asarray(offset, dtype=np.float64)
    if not np.isfinite(scale) or scale <= 0:
        raise ValueError(f"scale: expected a positive factor, got {scale}")
    if offset.shape != (3,) or not np.all(np.isfinite(offset)):
        raise ValueError(f"offset: expected 3 finite coordinates in metres, got {offset.tolist()}")
    check_name(anchor, ANCHORS, field="anchor")
    if not np.isfinite(time_offset):
        raise ValueError(f"time_offset: expected finite seconds, got {time_offset}")
    if fps is not None and (not np.isfinite(fps) or fps <= 0):
        raise ValueError(f"fps: expected a positive frame rate in Hz, got {fps}")
    if max_gap is not None and (not np.isfinite(max_gap) or max_gap <= 0):
        raise ValueError(f"max_gap: expected a positive number of seconds, got {max_gap}")
    check_name(gaps, GAP_RULES, field="gaps")

    if camera and "camera" not in spec.options:
        raise ValueError(f"camera: expected only with a glTF camera file (format gltf), got format {name!r}")
    taken = {"camera": camera, "fps": fps if fps is not None else 30.0}
    recorded, duplicates = resolve_duplicates(spec.read(file, **{k: taken[k] for k in spec.options}),
                                              rule=duplicate_times)
    if recorded.angles_line is not None and convention != "opengl":
        raise InputError(f"yaw/pitch/roll are defined in csmlab's own axes: read this file with convention "
                         f"'opengl', or give quaternions (qx qy qz qw) for convention {convention!r}",
                         file=file, line=recorded.angles_line, field="yaw")
    times = _times(recorded, times_file=times_file, fps=fps)
    if from_first_pose:
        times = times - times[0]
    local = recorded.positions - recorded.positions[0] if anchor == "first" else recorded.positions
    positions, orientations = poses_to_opengl(local, recorded.orientations, convention=convention)
    path = CameraPath(
        times=times + time_offset,
        positions=positions * scale + offset,
        orientations=orientations,
        fov_y_deg=recorded.fov_y_deg if recorded.fov_y_deg is not None else fov_y_deg,
        aspect=recorded.aspect if recorded.aspect is not None else aspect,
        near=recorded.near * scale if recorded.near is not None else near,
        far=recorded.far * scale if recorded.far is not None else far, name=Path(file).name,
    )
    limit, found = find_gaps(path.times, path.positions, recorded.lines, max_gap=max_gap)
    if found and gaps == "error":
        gap = max(found, key=lambda g: g.duration_s)
        raise InputError(f"expected no tracking gap over max_gap = {limit:.6g} s, found {len(found)}; the longest "
                         f"{gap.duration_s:.6g} s after line {gap.lines[0]} (gaps = 'interpolate' or 'cut' "
                         f"accepts them)", file=file, line=gap.lines[1], field="timestamp")
    timing = TimingReport(file=Path(file).name, duplicate_times=duplicate_times, duplicates=duplicates,
                          max_gap=limit, gaps_rule=gaps, gaps=found)
    resample = fps is not None and (recorded.times is not None or times_file is not None)
    if resample:
        with np.errstate(over="ignore"):  # a span of 1e308 s: counted as more frames than the limit
            frames = float(path.times[-1] - path.times[0]) * fps + 1.0
        within_limit(int(min(frames, 1e30)), MAX_FRAMES, what=f"frames at {fps:g} fps (the poses span "
                     f"{float(path.times[-1] - path.times[0]):.6g} s)", file=times_file or file,
                     field=recorded.time_field)
        path = path.resample(fps)
    restarts = np.empty(0)
    if gaps == "cut" and found:
        keep, restart = frames_outside_gaps(path.times, found)
        kept = np.flatnonzero(keep)
        path = CameraPath(times=path.times[kept], positions=path.positions[kept],
                          orientations=path.orientations[kept], fov_y_deg=path.fov_y_deg[kept], aspect=path.aspect,
                          near=path.near, far=path.far, name=path.name)
        restarts = path.times[restart]
    return Recording(path=path, timing=timing, restarts=restarts)


def read_path(file, **options) -> CameraPath:
    """The :class:`CameraPath` of :func:`read_recording` (same keyword options), without its report."""
    return read_recording(file, **options).path


def write_path(path: CameraPath, file, *, format: str, convention: str | None = None) -> None:
    """Write ``path`` as ``format`` in ``convention`` (the format's own when ``None``).

    Reading the file back with the same format and convention gives the same poses (positions and
    rotations to float rounding; KITTI keeps no times, EuRoC rounds them to nanoseconds).
    """
    spec = _format(format)
    positions, orientations = poses_from_opengl(path.positions, path.orientations,
                                                convention=convention or spec.convention)
    spec.write(RecordedPoses(file=str(file), lines=np.arange(1, len(path) + 1), times=path.times,
                             positions=positions, orientations=orientations, fov_y_deg=path.fov_y_deg), file)
