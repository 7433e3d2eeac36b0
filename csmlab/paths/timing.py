"""Recorded time stamps as they come: repeated stamps resolved by a rule, tracking gaps found and handled.

Real recordings are not the clean, evenly clocked sequences that resampling assumes. A
motion-capture logger writes two different poses under one stamp when its clock did not advance;
a tracker that loses its target leaves a gap of seconds after which the camera is somewhere else.

- **Repeated stamps** (``[camera] duplicate_times``, :data:`DUPLICATE_RULES`): ``first`` keeps
  the pose the file gives first for that stamp (the default: what ``pandas.drop_duplicates`` and
  ``numpy.unique`` keep, and the pose TUM's ``associate.py`` matches first), ``last`` the last one,
  ``mean`` their mean (positions averaged, quaternions sign-aligned, averaged and normalised),
  ``error`` refuses the file at the second line of the first repeat. A stamp that goes back in
  time is always refused: that is a broken file, not a repeat.
- **Gaps** (``[camera] max_gap``, seconds; unset: 10 × the file's median time step): consecutive
  poses further apart in time than ``max_gap``. ``gaps`` (:data:`GAP_RULES`) says what to do:
  ``interpolate`` bridges them as resampling always did (a slow glide over the gap, reported),
  ``cut`` renders no frame inside a gap and starts the temporal metrics afresh at the first frame
  after it (the camera jumped: it is not a frame-to-frame change), ``error`` refuses the file.

Both are reported (:class:`TimingReport`): how many, where (the run's clock and the file's
lines), how long, and how far the camera moved.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from csmlab.errors import InputError
from csmlab.paths.recorded import RecordedPoses
from csmlab.registry import check_name

__all__ = [
    "DUPLICATE_RULES",
    "GAP_FACTOR",
    "GAP_RULES",
    "Duplicate",
    "Gap",
    "TimingReport",
    "find_gaps",
    "frames_outside_gaps",
    "resolve_duplicates",
    "timing_lines",
]

DUPLICATE_RULES: tuple[str, ...] = ("first", "last", "mean", "error")
"""How poses under a repeated time stamp become one (module docstring)."""

GAP_RULES: tuple[str, ...] = ("interpolate", "cut", "error")
"""What a tracking gap longer than ``max_gap`` does to the path (module docstring)."""

GAP_FACTOR = 10.0
"""With ``max_gap`` unset, a gap is a step longer than this many times the file's median time step."""


@dataclass(frozen=True)
class Duplicate:
    """Poses of a file under one time stamp.

    Attributes
    ----------
    time_s : float
        The stamp on the file's clock, seconds.
    lines : tuple of int
        The file's 1-based lines that carry it.
    spread_m : float
        Largest distance between their positions, in the file's length unit.
    """

    time_s: float
    lines: tuple[int, ...]
    spread_m: float


@dataclass(frozen=True)
class Gap:
    """A step between consecutive poses longer than ``max_gap``.

    Attributes
    ----------
    start_s, end_s : float
        Time of the poses before and after it on the run's clock (seconds).
    lines : tuple of int
        Their 1-based lines in the file.
    jump_m : float
        Distance between their positions, csmlab metres (after scale).
    """

    start_s: float
    end_s: float
    lines: tuple[int, int]
    jump_m: float

    @property
    def duration_s(self) -> float:
        return self.end_s - self.start_s


@dataclass(frozen=True)
class TimingReport:
    """What the time stamps of a recorded file held and what was done about it.

    Attributes
    ----------
    file : str
    duplicate_times : str
        The rule applied to repeated stamps.
    duplicates : tuple of Duplicate
    max_gap : float
        The gap threshold used, seconds (given, or derived from the median step).
    gaps_rule : str
        The rule applied to gaps.
    gaps : tuple of Gap
    """

    file: str
    duplicate_times: str
    duplicates: tuple[Duplicate, ...]
    max_gap: float
    gaps_rule: str
    gaps: tuple[Gap, ...]

    def as_dict(self, *, listed: int = 20) -> dict:
        """A JSON-ready record for ``summary.json``: counts, totals and the first ``listed`` of each."""
        return {
            "file": self.file,
            "duplicate_times": self.duplicate_times,
            "duplicates": len(self.duplicates),
            "duplicate_list": [{"time_s": d.time_s, "lines": list(d.lines), "spread_m": d.spread_m}
                               for d in self.duplicates[:listed]],
            "max_gap_s": self.max_gap,
            "gaps_rule": self.gaps_rule,
            "gaps": len(self.gaps),
            "gap_total_s": float(sum(g.duration_s for g in self.gaps)),
            "gap_list": [{"start_s": g.start_s, "end_s": g.end_s, "duration_s": g.duration_s, "lines": list(g.lines),
                          "jump_m": g.jump_m} for g in sorted(self.gaps, key=lambda g: -g.duration_s)[:listed]],
        }


def timing_lines(record: dict | None) -> list[str]:
    """What a recording's timing record (:meth:`TimingReport.as_dict`) says, one line per finding, for the terminal.

    Empty for ``None`` (a generated path) or a file without repeats or gaps.
    """
    if not record:
        return []
    out = []
    if record["duplicates"]:
        first = record["duplicate_list"][0]
        out.append(f"{record['file']}: {record['duplicates']} repeated time stamp(s), resolved by duplicate_times = "
                   f"'{record['duplicate_times']}'; the first at {first['time_s']!r} s (lines "
                   f"{', '.join(map(str, first['lines']))}), poses {first['spread_m']:.3g} apart")
    if record["gaps"]:
        longest = record["gap_list"][0]
        action = {"interpolate": "bridged by interpolation",
                  "cut": "cut: no frame inside, temporal metrics restart after each"}[record["gaps_rule"]]
        out.append(f"{record['file']}: {record['gaps']} tracking gap(s) over max_gap = {record['max_gap_s']:.3g} s, "
                   f"{record['gap_total_s']:.3g} s in all, {action}; the longest {longest['duration_s']:.3g} s from "
                   f"t = {longest['start_s']:.3f} s (lines {longest['lines'][0]}-{longest['lines'][1]}), a "
                   f"{longest['jump_m']:.3g} m jump")
    return out


def _mean_quaternion(q: np.ndarray) -> np.ndarray:
    aligned = q * np.where(q @ q[0] < 0.0, -1.0, 1.0)[:, None]
    mean = aligned.mean(axis=0)
    return mean / np.linalg.norm(mean)


def resolve_duplicates(recorded: RecordedPoses, *, rule: str) -> tuple[RecordedPoses, tuple[Duplicate, ...]]:
    """Make the time stamps of ``recorded`` strictly increasing by ``rule`` (:data:`DUPLICATE_RULES`).

    Parameters
    ----------
    recorded : RecordedPoses
        Times non-decreasing (the readers refuse a stamp that goes back), or None (KITTI).
    rule : str

    Returns
    -------
    RecordedPoses
        One pose per stamp; each kept pose keeps the line of the first of its group.
    tuple of Duplicate
        Every repeated stamp, in file order.

    Raises
    ------
    InputError
        With ``rule = "error"``, at the second line of the first repeated stamp.
    ValueError
        On an unknown rule.
    """
    check_name(rule, DUPLICATE_RULES, field="duplicate_times")
    times = recorded.times
    if times is None or times.shape[0] < 2 or np.all(np.diff(times) > 0):
        return recorded, ()
    starts = np.flatnonzero(np.concatenate([[True], np.diff(times) > 0]))
    stops = np.append(starts[1:], times.shape[0])
    repeated = [(a, b) for a, b in zip(starts.tolist(), stops.tolist()) if b - a > 1]
    if rule == "error":
        a, _ = repeated[0]
        raise InputError(f"expected time stamps that strictly increase, got {float(times[a + 1])!r} again "
                         f"(line {int(recorded.lines[a])}); duplicate_times = 'first', 'last' or 'mean' resolves "
                         f"repeats", file=recorded.file, line=int(recorded.lines[a + 1]), field=recorded.time_field)
    duplicates = []
    positions = recorded.positions[starts].copy()
    orientations = recorded.orientations[starts].copy()
    fov = None if recorded.fov_y_deg is None else recorded.fov_y_deg[starts].copy()
    group_of = np.searchsorted(starts, np.arange(times.shape[0]), side="right") - 1
    for a, b in repeated:
        p = recorded.positions[a:b]
        spread = float(np.max(np.linalg.norm(p[:, None] - p[None], axis=-1)))
        duplicates.append(Duplicate(time_s=float(times[a]), lines=tuple(int(x) for x in recorded.lines[a:b]),
                                    spread_m=spread))
        k = group_of[a]
        pick = {"first": a, "last": b - 1}.get(rule)
        if pick is not None:
            positions[k], orientations[k] = recorded.positions[pick], recorded.orientations[pick]
            if fov is not None:
                fov[k] = recorded.fov_y_deg[pick]
        else:
            positions[k] = p.mean(axis=0)
            orientations[k] = _mean_quaternion(recorded.orientations[a:b])
            if fov is not None:
                fov[k] = recorded.fov_y_deg[a:b].mean()
    resolved = RecordedPoses(file=recorded.file, lines=recorded.lines[starts], times=times[starts],
                             positions=positions, orientations=orientations, fov_y_deg=fov,
                             angles_line=recorded.angles_line, time_field=recorded.time_field)
    return resolved, tuple(duplicates)


def find_gaps(times, positions, lines, *, max_gap: float | None) -> tuple[float, tuple[Gap, ...]]:
    """Steps between consecutive poses longer than ``max_gap`` seconds.

    Parameters
    ----------
    times : array_like, shape (N,), float64
        Strictly increasing seconds on the run's clock.
    positions : array_like, shape (N, 3), float64
        csmlab world metres.
    lines : array_like, shape (N,), int
        The file's line of each pose.
    max_gap : float or None
        Seconds; ``None`` takes :data:`GAP_FACTOR` × the median step.

    Returns
    -------
    float
        The threshold used, seconds (``inf`` for a single pose).
    tuple of Gap
        In time order.
    """
    t = np.asarray(times, dtype=np.float64)
    if t.shape[0] < 2:
        return float("inf") if max_gap is None else float(max_gap), ()
    with np.errstate(over="ignore"):  # stamps near 1e308 s: steps and threshold become inf, no gap is found
        step = np.diff(t)
        limit = float(GAP_FACTOR * np.median(step)) if max_gap is None else float(max_gap)
    p = np.asarray(positions, dtype=np.float64)
    gaps = tuple(Gap(start_s=float(t[k]), end_s=float(t[k + 1]), lines=(int(lines[k]), int(lines[k + 1])),
                     jump_m=float(np.linalg.norm(p[k + 1] - p[k]))) for k in np.flatnonzero(step > limit).tolist())
    return limit, gaps


def frames_outside_gaps(frame_times, gaps: tuple[Gap, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Which frame times lie outside every gap, and which kept frames start afresh after one.

    Parameters
    ----------
    frame_times : array_like, shape (F,), float64
        Increasing seconds on the run's clock.
    gaps : tuple of Gap

    Returns
    -------
    keep : ndarray, shape (F,), bool
        Not strictly inside any gap (its poses' own times are kept).
    restart : ndarray, shape (K,), bool
        Per kept frame: the first kept frame after a gap (its temporal metrics are undefined).
    """
    t = np.asarray(frame_times, dtype=np.float64)
    keep = np.ones(t.shape, dtype=bool)
    after = np.zeros(t.shape, dtype=bool)
    for gap in gaps:
        keep &= ~((t > gap.start_s) & (t < gap.end_s))
        following = np.flatnonzero(t >= gap.end_s)
        if following.size:
            after[following[0]] = True
    return keep, after[keep]
