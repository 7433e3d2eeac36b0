"""Every metric column of ``metrics.csv``, declared once: name, label, unit, which way is better, tolerance.

:data:`METRICS` is the one place a metric's meaning lives: its label, unit, display scale, direction
and tolerance. ``metrics.csv``'s column order (:func:`metric_columns`), the regression gate's and
``csmlab compare``'s directions and tolerances (:mod:`csmlab.regress`, :mod:`csmlab.compare`), the
tuner's objectives and tables (:mod:`csmlab.tune`, :mod:`csmlab.report.tune_page`), the report's
tables, best-marks, at-a-glance lines, plots and Explore curves (:mod:`csmlab.report`) and the
headline of ``csmlab run`` all read it. Adding a column is one :class:`Metric` here plus the
function that computes it (its key in the dict that function returns, merged by
:func:`csmlab.metrics.measure_frame`). :data:`DERIVED` holds the metrics the report computes from
columns (``ref_error``, the sum of false shadow and false light): registered, never a column.

This module imports neither Warp nor the metrics' code, so that reading a TOML file or a results
directory does not load the kernels.

Which way is better (:data:`BETTER`):

- ``lower``: flicker, errors, cost;
- ``higher``: utilization, SSIM, the worst-pixel ρ (p05, σ_min);
- ``one``: closest to 1 on a log scale, ``|ln ρ|`` smallest — ρ is texels per pixel, and ρ = 1 is
  the 1:1 ideal: below it shadows are blocky, far above it resolution is wasted. ρ = 0.5 and ρ = 2
  are equally far from it;
- ``either``: no better direction; shown, never judged, marked or tuned.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

__all__ = ["BETTER", "BETTER_TEXT", "CASCADE_PLACES", "DERIVED", "HEADLINE", "METRICS", "Metric", "PLOTS",
           "SELECTION_BRACKET", "SELECTION_SAMPLE", "SELECTION_WHOLE_BELOW", "best_mask", "finite_mean",
           "format_number", "is_metric_column", "is_per_cascade", "linear_percentiles", "metric_columns",
           "metric_named", "metric_of", "metric_values", "number_or_none", "order_statistics", "run_value",
           "temporal_columns"]


def _distance_from_one(value: float) -> float:
    if math.isnan(value):
        return value
    return abs(math.log(value)) if value > 0 else math.inf


BETTER: dict[str, Callable[[float], float] | None] = {
    "lower": lambda value: value,
    "higher": lambda value: -value,
    "one": _distance_from_one,
    "either": None,
}
"""Which way is better, by name: the score to minimise of a value (None: no better direction)."""

BETTER_TEXT = {
    "lower": "lower is better",
    "higher": "higher is better",
    "one": "closest to 1 is better",
    "either": "no better side",
}
"""How each :data:`BETTER` name reads in a table title, a verdict or a report."""

CASCADE_PLACES = ("", "beside", "tail")
"""Where a metric's per-cascade columns ``NAME_c{i}`` go: none; right after ``NAME``; or after every
other column, cascade by cascade (``rho_median_c0, rho_p05_c0, …, rho_median_c1, …``)."""

PLOTS = ("frames", "sweep")
"""The report's plots a metric can be drawn in: per-frame curves, and against each swept field."""


@dataclass(frozen=True)
class Metric:
    """One metric column of ``metrics.csv``.

    Attributes
    ----------
    name : str
        The column name (a contract: docs/design.md "Interfaces").
    label : str
        What a person reads in a table header or on a plot axis.
    unit : str
        The unit of the shown value, ``value * scale``.
    better : str
        A key of :data:`BETTER`.
    tolerance : tuple of (float, float)
        The regression gate's ``(abs, rel)``: the value may move the wrong way by at most
        ``max(abs, rel · |baseline|)`` in its stored units (:mod:`csmlab.regress`).
    temporal : bool
        Measured between frames t−1 and t: empty at frame 0 (and NaN in a one-frame run).
    cascades : str
        A key of :data:`CASCADE_PLACES`: whether and where ``NAME_c{i}`` columns follow.
    scale : float
        Display factor from the stored value (100 shows a fraction as %).
    headline : bool
        Shown in the summary tables (``csmlab run``'s and the report's).
    plots : tuple of str
        Entries of :data:`PLOTS` it is drawn in.
    glance : str
        The report's at-a-glance line naming the method best at it; empty: none.
    curve : str
        The label of its per-frame curve on the report's Explore page; empty: no curve.
    sum_of : tuple of str
        A derived metric (:data:`DERIVED`): the per-frame sum of these columns.
    peak_of : str
        A derived metric (:data:`DERIVED`): the largest single-frame value of this column over a run
        (:func:`run_value`), where the others are means over frames.
    """

    name: str
    label: str
    unit: str
    better: str
    tolerance: tuple[float, float] = (0.0, 0.0)
    temporal: bool = False
    cascades: str = ""
    scale: float = 1.0
    headline: bool = False
    plots: tuple[str, ...] = ()
    glance: str = ""
    curve: str = ""
    sum_of: tuple[str, ...] = ()
    peak_of: str = ""

    def __post_init__(self):
        if self.better not in BETTER:
            raise ValueError(f"{self.name}: better: expected one of {list(BETTER)}, got {self.better!r}")
        if self.cascades not in CASCADE_PLACES:
            raise ValueError(f"{self.name}: cascades: expected one of {CASCADE_PLACES}, got {self.cascades!r}")
        if not set(self.plots) <= set(PLOTS):
            raise ValueError(f"{self.name}: plots: expected entries of {PLOTS}, got {self.plots!r}")

    @property
    def title(self) -> str:
        """``label (unit)``, for a plot axis."""
        return f"{self.label} ({self.unit})"

    def shown(self, value, *, digits: int = 3) -> str:
        """``value`` (stored units) as a person reads it in :attr:`unit`: times :attr:`scale`, :func:`format_number`."""
        return format_number(None if value is None else float(value) * self.scale, digits=digits)

    def score(self, value: float) -> float:
        """The value's badness, to minimise: ``value``, ``-value`` or ``|ln value|`` by :attr:`better`.

        Raises
        ------
        ValueError
            For a metric with no better direction.
        """
        score = BETTER[self.better]
        if score is None:
            raise ValueError(f"{self.name} has no better direction")
        return score(value)


_RHO = "texels/pixel"
_PIXELS = "% pixels"
_DS = "mean |ΔS|"

METRICS: dict[str, Metric] = {m.name: m for m in (
    Metric("rho_median", "median ρ", _RHO, "one", (1e-6, 0.005), cascades="tail", headline=True,
           plots=("frames", "sweep"), glance="Closest to one texel per pixel (median ρ)",
           curve="median ρ (texels / pixel)"),
    Metric("rho_p05", "ρ, 5th percentile", _RHO, "higher", (1e-6, 0.005), cascades="tail"),
    Metric("rho_p95", "ρ, 95th percentile", _RHO, "one", (1e-6, 0.005), cascades="tail"),
    Metric("rho_frac_lt1", "ρ < 1", _PIXELS, "lower", (1e-3, 0.02), cascades="tail", scale=100.0, headline=True),
    Metric("rho_frac_lt05", "ρ < 0.5", _PIXELS, "lower", (1e-3, 0.02), cascades="tail", scale=100.0),
    Metric("sigma_min_p05", "σ_min, 5th percentile", _RHO, "higher", (1e-6, 0.005)),
    Metric("utilization", "utilization", "% texels", "higher", (1e-4, 0.01), cascades="beside", scale=100.0,
           headline=True, glance="Least wasted shadow map (utilization)"),
    Metric("flicker", "flicker", _DS, "lower", (1e-6, 0.05), temporal=True, curve="flicker (mean |ΔS|)"),
    Metric("flicker_same", "flicker, same cascade", _DS, "lower", (1e-6, 0.05), temporal=True, headline=True,
           plots=("frames", "sweep"), glance="Steadiest texels (same-cascade flicker)"),
    Metric("flicker_changed", "flicker, cascade changed", _DS, "lower", (1e-6, 0.05), temporal=True, headline=True,
           plots=("frames", "sweep"), glance="Calmest cascade transitions (cascade-changed flicker)"),
    Metric("flip_rate", "flip rate", _PIXELS, "lower", (1e-6, 0.05), temporal=True, scale=100.0, headline=True,
           plots=("frames", "sweep"), curve="flip rate (%)"),
    Metric("flip_same", "flip rate, same cascade", _PIXELS, "lower", (1e-6, 0.05), temporal=True, scale=100.0),
    Metric("flip_changed", "flip rate, cascade changed", _PIXELS, "lower", (1e-6, 0.05), temporal=True, scale=100.0),
    Metric("flicker_taa", "flicker after TAA", _DS, "lower", (1e-6, 0.05), temporal=True,
           curve="flicker after TAA (mean |Δ(S − R)|)"),
    Metric("flicker_same_taa", "flicker after TAA, same cascade", _DS, "lower", (1e-6, 0.05), temporal=True,
           headline=True),
    Metric("flicker_changed_taa", "flicker after TAA, cascade changed", _DS, "lower", (1e-6, 0.05), temporal=True),
    Metric("flip_rate_taa", "flip rate after TAA", _PIXELS, "lower", (1e-6, 0.05), temporal=True, scale=100.0,
           headline=True),
    Metric("flip_same_taa", "flip rate after TAA, same cascade", _PIXELS, "lower", (1e-6, 0.05), temporal=True,
           scale=100.0),
    Metric("flip_changed_taa", "flip rate after TAA, cascade changed", _PIXELS, "lower", (1e-6, 0.05),
           temporal=True, scale=100.0),
    Metric("de2000_mean", "mean ΔE2000", "ΔE", "lower", (1e-3, 0.05), temporal=True, headline=True,
           plots=("frames",)),
    Metric("de2000_p99", "ΔE2000, 99th percentile", "ΔE", "lower", (1e-3, 0.05), temporal=True),
    Metric("de2000_frac_jnd", "ΔE2000 > 1 JND", _PIXELS, "lower", (1e-5, 0.05), temporal=True, scale=100.0),
    Metric("ssim", "SSIM", "1 = same", "higher", (1e-4, 0.01), temporal=True, headline=True),
    Metric("flip", "ꟻLIP", "mean", "lower", (1e-5, 0.05), temporal=True, headline=True),
    Metric("ref_false_shadow", "false shadow", _PIXELS, "lower", (1e-4, 0.05), scale=100.0),
    Metric("ref_false_light", "false light", _PIXELS, "lower", (1e-4, 0.05), scale=100.0),
    Metric("acne", "acne", _PIXELS, "lower", (1e-4, 0.05), scale=100.0),
    Metric("peter_panning", "peter-panning", _PIXELS, "lower", (1e-4, 0.05), scale=100.0),
    Metric("ref_boundary_px", "shadow boundary distance", "pixels", "lower", (1e-3, 0.10)),
    Metric("ref_seam_error", "error at split boundaries", "mean |S − R|", "lower", (1e-4, 0.05)),
    Metric("memory_bytes", "memory", "MiB", "lower", (0.0, 0.0), scale=2.0 ** -20, headline=True,
           plots=("sweep",)),
    Metric("texels_rasterized", "texels rasterized", "texels", "lower", (0.0, 0.10)),
    Metric("pages_marked", "pages marked", "pages", "lower", (0.0, 0.0)),
    Metric("pages_rendered", "pages rendered", "pages", "lower", (0.0, 0.0)),
    Metric("pool_bytes", "resident pool", "MiB", "lower", (0.0, 0.0), scale=2.0 ** -20),
)}
"""Every metric column, in ``metrics.csv`` order (docs/design.md "Interfaces")."""

DERIVED: dict[str, Metric] = {m.name: m for m in (
    Metric("ref_error", "vs. reference", "% pixels wrong", "lower", (1e-4, 0.05), scale=100.0,
           glance="Closest to the ray-traced shadow", curve="vs. reference (% of pixels)",
           sum_of=("ref_false_shadow", "ref_false_light")),
    Metric("flicker_peak", "largest frame flicker", _DS, "lower", (1e-6, 0.05), temporal=True, peak_of="flicker"),
)}
"""Metrics computed from columns, never columns themselves: ``ref_error``, the fraction of pixels whose
shadow state differs from the reference either way (false shadow + false light); ``flicker_peak``, the
largest single-frame flicker of a run (the pop of a sun policy's update, which a mean over frames
spreads thin)."""

HEADLINE: tuple[Metric, ...] = tuple(m for m in METRICS.values() if m.headline)
"""The metrics a summary table leads with, in column order."""

_PER_CASCADE = re.compile(r"^(?P<name>.+)_c(?P<cascade>\d+)$")


def metric_columns(cascades: int) -> tuple[str, ...]:
    """Every metric column of ``metrics.csv``, in order, for ``cascades`` cascades.

    :data:`METRICS` in order, each ``beside`` metric followed by its ``NAME_c0 … NAME_c{C-1}``,
    then, for each cascade i in turn, ``NAME_c{i}`` of every ``tail`` metric.
    """
    if not (isinstance(cascades, (int, np.integer)) and cascades >= 1):
        raise ValueError(f"cascades: expected a positive integer, got {cascades!r}")
    out = []
    for m in METRICS.values():
        out.append(m.name)
        if m.cascades == "beside":
            out += [f"{m.name}_c{c}" for c in range(cascades)]
    tail = [m.name for m in METRICS.values() if m.cascades == "tail"]
    out += [f"{name}_c{c}" for c in range(cascades) for name in tail]
    return tuple(out)


def metric_of(column: str) -> Metric | None:
    """The :class:`Metric` a column measures (``utilization_c2`` → ``utilization``); None if unknown."""
    if column in METRICS:
        return METRICS[column]
    match = _PER_CASCADE.match(column)
    metric = METRICS.get(match["name"]) if match else None
    return metric if metric is not None and metric.cascades else None


def metric_named(name: str) -> Metric | None:
    """The :class:`Metric` of a column (:func:`metric_of`) or of a :data:`DERIVED` metric; None if unknown."""
    return metric_of(name) if name not in DERIVED else DERIVED[name]


def metric_values(name: str, columns) -> np.ndarray | None:
    """Per-frame values ``(N,)`` of a column or a :data:`DERIVED` metric; None when a column it needs is absent.

    Parameters
    ----------
    name : str
    columns : mapping
        Column name → ``(N,)`` float64 array (``metrics.csv`` rows of one method × point, or all of them);
        a column is returned as it is, a derived metric summed in the order of ``sum_of``, a peak its
        column (whose largest value :func:`run_value` takes).
    """
    if name not in DERIVED:
        return columns[name] if name in columns else None
    peak = DERIVED[name].peak_of
    if peak:
        return columns[peak] if peak in columns else None
    parts = DERIVED[name].sum_of
    if not all(part in columns for part in parts):
        return None
    return sum((columns[part] for part in parts[1:]), start=columns[parts[0]])


def run_value(name: str, values) -> float:
    """A run's value of metric ``name`` from its per-frame values ``(N,)`` (:func:`metric_values`).

    The largest finite value for a peak (``peak_of``), else the mean of the finite ones
    (:func:`finite_mean`); NaN when there is none.
    """
    if name in DERIVED and DERIVED[name].peak_of:
        values = np.asarray(values, dtype=np.float64)
        finite = values[np.isfinite(values)]
        return float(finite.max()) if finite.size else math.nan
    return finite_mean(values)


def is_per_cascade(column: str) -> bool:
    """``column`` is one cascade's column of a metric (``utilization_c2``), not the metric's own."""
    return column not in METRICS and metric_of(column) is not None


def is_metric_column(column: str) -> bool:
    """``column`` is a metric column of ``metrics.csv`` for some number of cascades."""
    return metric_of(column) is not None


def temporal_columns() -> tuple[str, ...]:
    """The columns measured between frames (empty at frame 0)."""
    return tuple(m.name for m in METRICS.values() if m.temporal)


def number_or_none(value) -> float | None:
    """A summary value as a float; None for a missing one (None or NaN, as ``summary.json``'s null reads back)."""
    return None if value is None or (isinstance(value, float) and math.isnan(value)) else float(value)


def finite_mean(values) -> float:
    """Mean of the finite entries of ``values`` in float64; NaN when there is none.

    ``values`` is array-like; None entries count as NaN (a missing value, e.g. frame 0's flicker).
    Float32 entries are summed in float64.
    """
    values = np.asarray(values)
    if values.dtype.kind != "f":
        values = values.astype(np.float64)
    finite = np.isfinite(values)
    # All finite (the usual case): the same entries in the same order, without copying them out.
    finite = values if finite.all() else values[finite]
    return float(np.mean(finite, dtype=np.float64)) if finite.size else math.nan


def linear_percentiles(values: np.ndarray, q: tuple[float, ...]) -> np.ndarray:
    """``np.percentile(values, q)`` (linear interpolation, NumPy's default) in float64, bit for bit, ``(len(q),)``.

    Parameters
    ----------
    values : ndarray, shape (N,), float32 or float64
        A scratch array, which may be reordered in place. Float32 values are selected as they are
        (the order statistics of their float64 conversion are the same values, half the bytes
        moved) and interpolated in float64, as NumPy interpolates the float64 array.
    q : tuple of float
        Percentiles in [0, 100].

    Returns
    -------
    ndarray, shape (len(q),), float64
        NumPy's interpolation between the order statistics at ``floor((N − 1)·q/100)`` and the next,
        its weight and its two forms (from below under ½, from above from ½ on) repeated; all NaN
        when ``values`` holds a NaN (NumPy's too) or is empty. What NumPy's ``np.percentile`` adds
        around this — reductions over axes, its checks, a partition of the whole array at every
        rank — is not paid (:func:`order_statistics`).
    """
    count = values.size
    quantiles = np.true_divide(np.asarray(q, dtype=np.float64), 100)
    if count == 0:
        return np.full(quantiles.shape, np.nan)
    virtual = (count - 1) * quantiles
    below = np.floor(virtual)
    above = below + 1
    # From the last rank on, both neighbours are the largest value (NumPy's index −1, its weight from it).
    last = virtual >= count - 1
    below[last] = -1
    above[last] = -1
    gamma = virtual - below
    below, above = below.astype(np.intp) % count, above.astype(np.intp) % count
    ranks = np.unique(np.concatenate((below, above)))
    statistics = order_statistics(values, ranks)
    if statistics is None:
        return np.full(quantiles.shape, np.nan)
    a = statistics[np.searchsorted(ranks, below)].astype(np.float64)
    b = statistics[np.searchsorted(ranks, above)].astype(np.float64)
    difference = b - a
    out = a + difference * gamma
    np.subtract(b, difference * (1 - gamma), out=out, where=gamma >= 0.5)
    return out


SELECTION_SAMPLE: int = 4096
"""Values :func:`order_statistics` sorts to bracket each rank: every ``N // 4096``-th value."""

SELECTION_BRACKET: int = 128
"""Sample positions on each side of a rank's place in the sorted sample that bracket its value. The
sample values below a rank's number about ``rank · 4096 / N``, give or take ``sqrt(4096 · p(1 − p))
≤ 32`` for a sample drawn at random (``p = rank / N``): 128 is four times that, and a bracket that
misses its rank all the same costs a partition of the whole array, not a wrong value."""

SELECTION_WHOLE_BELOW: int = 20000
"""Values below which :func:`order_statistics` partitions the whole array: NumPy partitions a short
one faster than the brackets pass over it (float32 at 6 ranks, ms: 20k values 0.05 partitioned,
0.13 bracketed; 24k 0.34 and 0.14; 65k 1.0 and 0.44; 196k 3.5 and 1.3)."""


def order_statistics(values: np.ndarray, ranks: np.ndarray) -> np.ndarray | None:
    """The values of ``ranks`` (sorted, distinct, in ``[0, N)``) in ``values`` ``(N,)`` sorted ascending; None when
    ``values`` holds a NaN.

    NumPy's ``partition`` at the ranks, the same bits, for less: an array of
    :data:`SELECTION_WHOLE_BELOW` values or more is first narrowed to the values between two of a
    sorted sample's (:data:`SELECTION_SAMPLE`, :data:`SELECTION_BRACKET`) around each rank. They
    hold the rank when the values below the lower one are fewer than the rank and those up to the
    upper one more; that is counted, and only the values between are partitioned. Where a count
    shows a bracket missing its rank, or a bracket holds a negative zero (equal to +0, whose bits a
    partition's order of ties would choose), the whole array is partitioned, reordering ``values``
    in place.
    """
    if np.isnan(values.max()):
        return None
    count = values.size
    if count >= SELECTION_WHOLE_BELOW:
        statistics = _bracketed_statistics(values, ranks)
        if statistics is not None:
            return statistics
    # The largest rank too, as before the brackets: the same partition, the same ties chosen.
    values.partition(np.unique(np.concatenate(([count - 1], ranks))))
    return values[ranks]


def _bracketed_statistics(values: np.ndarray, ranks: np.ndarray) -> np.ndarray | None:
    """:func:`order_statistics` from the values between sample brackets, or None where a bracket misses its rank."""
    count = values.size
    sample = np.sort(values[::count // SELECTION_SAMPLE])
    # The ends open (±inf) where a bracket reaches past the sample, so that the extreme ranks are held.
    places = ranks * sample.size // count
    low = places - SELECTION_BRACKET
    high = places + SELECTION_BRACKET
    statistics = np.empty(ranks.size, dtype=values.dtype)
    start = 0
    while start < ranks.size:
        # Ranks whose brackets overlap share one pass over the array.
        stop = start + 1
        while stop < ranks.size and low[stop] <= high[stop - 1]:
            stop += 1
        lo = sample[low[start]] if low[start] > 0 else -np.inf
        hi = sample[high[stop - 1]] if high[stop - 1] < sample.size - 1 else np.inf
        below = values < lo
        held = values[~below & (values <= hi)]
        at = ranks[start:stop] - np.count_nonzero(below)
        if at[0] < 0 or at[-1] >= held.size or np.signbit(held[held == 0]).any():
            return None
        held.partition(at)
        statistics[start:stop] = held[at]
        start = stop
    return statistics


def format_number(value, *, digits: int = 3) -> str:
    """A value for a person to read: ``digits`` significant digits, whole numbers from 1000 up with
    thousands separators; an exact zero stays ``0`` (exact's same-cascade flicker is zero, not
    small, and a table must say so); None, NaN and infinities are ``—``.
    """
    if value is None or not math.isfinite(float(value)):
        return "—"
    value = float(value)
    return f"{value:,.0f}" if abs(value) >= 1000 else f"{value:.{digits}g}"


def best_mask(values, *, better: str) -> np.ndarray:
    """``(N,)`` bool: the rows holding the best finite value; none when fewer than two values differ.

    Parameters
    ----------
    values : array_like, shape (N,)
    better : str
        A key of :data:`BETTER`; ``either`` marks nothing, ``one`` ignores values ≤ 0.
    """
    values = np.asarray(values, dtype=np.float64)
    score = BETTER[better]
    finite = np.isfinite(values) & ((values > 0) if better == "one" else True)
    if score is None or len(np.unique(values[finite])) < 2:
        return np.zeros(values.shape, dtype=bool)
    scores = np.array([score(v) if ok else math.inf for v, ok in zip(values.tolist(), finite)])
    return finite & (scores == scores.min())
