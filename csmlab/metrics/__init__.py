"""The measures of one frame of one method: aliasing, temporal change, perceptual change, error, cost.

Each module is a pure function of :class:`csmlab.frame.Frame` records that returns per-pixel maps
and a summary dict; :func:`measure_frame` composes them into one row of ``metrics.csv``. The
definitions are docs/design.md's "Metrics" section (a contract).

Columns: :func:`csmlab.metric_registry.metric_columns`, declared in
:data:`csmlab.metric_registry.METRICS`. The columns measured between frames (``temporal``) are NaN
at the first frame; any mean over an empty set of pixels (no pixel changed cascade, no pixel
selected cascade i) is NaN too.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from csmlab.frame import Frame
from csmlab.metric_registry import metric_columns, temporal_columns
from csmlab.metrics.aliasing import aliasing_maps, aliasing_summary, utilization
from csmlab.metrics.cost import cost_summary
from csmlab.metrics.perceptual import perceptual_maps, perceptual_summary
from csmlab.metrics.reference import bias_errors, reference_maps, reference_summary, seam_error
from csmlab.metrics.shading import AMBIENT, shaded_rgb, view_shading_terms
from csmlab.metrics.taa import TAA_COLUMNS, taa_summary
from csmlab.metrics.temporal import temporal_maps, temporal_summary

__all__ = ["FrameMeasures", "measure_frame", "metric_columns"]


@dataclass(frozen=True)
class FrameMeasures:
    """The measures of one frame of one method.

    Attributes
    ----------
    values : dict of str to float
        One value per :func:`metric_columns` entry, in that order; NaN where undefined.
    pixels : dict of str to ndarray
        Per-pixel maps for the report: ``rho`` (H, W) float32 texels per pixel; ``dS`` (H, W)
        float64 |ΔS| (reference change subtracted when the light moved), NaN where not counted or
        at the first frame; ``shaded`` (H, W, 3) float64 linear RGB of frame t, NaN where S is
        undefined; ``ref_diff`` (H, W) int8, +1 false shadow, −1 false light, 0 otherwise;
        ``de2000`` (H, W) float64, NaN where not compared or at the first frame; ``flipped`` (H, W)
        bool, the lit/shadowed state changed (all False at the first frame).
    """

    values: dict[str, float]
    pixels: dict[str, np.ndarray]


def _mean_utilization(share: np.ndarray) -> float:
    """The mean of the maps' utilizations ``(C,)``, over those that have texels (a clipmap level without resident
    pages has none: NaN); NaN when none has."""
    if np.all(np.isfinite(share)):
        return float(np.mean(share))
    return float(np.nanmean(share)) if np.isfinite(share).any() else float("nan")


def measure_frame(frame: Frame, previous: Frame | None = None, *, ambient: float = AMBIENT,
                  device: str = "cpu", taa: tuple | None = None) -> FrameMeasures:
    """Every metric of ``frame``; the temporal and perceptual ones against ``previous``.

    Parameters
    ----------
    frame : Frame
        Frame t of one method.
    previous : Frame or None
        Frame t−1 of the same method (same settings); None at the first frame.
    ambient : float
        Ambient term of the shading used by the perceptual metrics, in units of the direct light.
    device : str
        Warp device for the footprint kernel and the lookup of frame t−1's maps.
    taa : tuple of TaaResolve, optional
        Frame t's TAA resolves of the method's S and of R (:mod:`csmlab.metrics.taa`): the
        ``*_taa`` columns (empty without them, and at the first frame).

    Returns
    -------
    FrameMeasures

    Raises
    ------
    ValueError
        If ``previous`` was rendered with other shadow settings or another image size.
    """
    if previous is not None and previous.settings != frame.settings:
        raise ValueError("previous: expected frame t-1 of the same method (equal shadow settings), "
                         f"got settings that differ from frame {frame.view.index}'s")
    cascades = len(frame.maps.cascades)
    alias = aliasing_maps(frame, device=device)
    share = utilization(frame, device=device)
    errors = reference_maps(frame)
    values = {**aliasing_summary(alias, cascades=cascades), "utilization": _mean_utilization(share),
              **{f"utilization_c{c}": float(u) for c, u in enumerate(share)},
              **reference_summary(errors, view=frame.view), **bias_errors(frame, errors), **seam_error(frame),
              **cost_summary(frame),
              **dict.fromkeys(TAA_COLUMNS, float("nan"))}
    g = frame.view.gbuffer
    if previous is None:
        values.update(dict.fromkeys(temporal_columns(), float("nan")))
        lit = np.where(g.valid, frame.shadow.lit, np.nan)
        shaded = shaded_rgb(g.albedo, g.normal, lit, light_direction=frame.view.light_direction, ambient=ambient,
                            terms=view_shading_terms(frame.view))
        change = np.full(g.shape, np.nan)
        de2000 = np.full(g.shape, np.nan)
        flipped = np.zeros(g.shape, dtype=bool)
    else:
        temporal = temporal_maps(frame, previous, device=device)
        perceptual = perceptual_maps(frame, temporal.previous_lit, ambient=ambient)
        values.update(temporal_summary(temporal))
        values.update(perceptual_summary(perceptual, device=device))
        if taa is not None:
            values.update(taa_summary(*taa, temporal))
        shaded, change, de2000 = perceptual.shaded, np.abs(temporal.change), perceptual.de2000
        flipped = temporal.flipped
    pixels = {"rho": alias.rho, "dS": change, "shaded": shaded, "ref_diff": errors.diff, "de2000": de2000,
              "flipped": flipped}
    return FrameMeasures(values={key: values[key] for key in metric_columns(cascades)}, pixels=pixels)
