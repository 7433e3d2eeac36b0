"""Temporal anti-aliasing of each method's shadow and of the reference, and the temporal change after it.

The model (docs/design.md, "The CSM model", TAA; the ``[taa]`` table,
:class:`csmlab.config.TaaConfig`): frame t is rendered with the camera moved by a sub-pixel jitter,
the Halton (2, 3) point ``1 + t mod phases`` less ½ (:func:`halton_jitter`). Each method's lit
fraction S_t and the ray-traced R_t are each resolved against their own history, the previous
frame's output, by :func:`csmlab.kernels.taa.resolve_taa`: history reprojected with the exact
motion of each visible point (its world position from the G-buffer, projected into frame t−1's
camera), dropped where frame t−1 did not see that point (depth test), clamped to the current 3×3
neighbourhood and blended ``h + α (c − h)``. The first frame's output is its input.

After TAA, the change at the same world point is the output T_t minus the reprojected history
T_{t−1}(X) (the resolve's ``reprojected``), counted where both are defined. It is measured as the
change of the error, ``(T^S_t − T^S_{t−1}(X)) − (T^R_t − T^R_{t−1}(X))``: R goes through the same
jitter, reprojection and blend, so what TAA itself smears or lags (and a moving light's true motion)
is not counted as the method's flicker. A flip is a change of the state ``T > 0.5`` of S's output
that differs from R's. Same-cascade and cascade-changed split as before TAA (frame t's and t−1's
selections at X, :class:`csmlab.metrics.temporal.TemporalMaps`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from csmlab.frame import View
from csmlab.metric_registry import finite_mean
from csmlab.metrics.temporal import TemporalMaps

__all__ = ["TAA_COLUMNS", "TaaResolve", "halton", "halton_jitter", "resolve_view", "taa_summary"]

TAA_COLUMNS = ("flicker_taa", "flicker_same_taa", "flicker_changed_taa", "flip_rate_taa", "flip_same_taa",
               "flip_changed_taa")
"""The ``metrics.csv`` columns :func:`taa_summary` fills, in registry order."""

_KERNEL_CLAMP = {"ycocg_minmax": "minmax", "variance": "variance", "none": "none"}


def halton(index: int, base: int) -> float:
    """The radical inverse of ``index`` (≥ 1) in ``base``: the Halton sequence's ``index``-th value in (0, 1)."""
    out, scale = 0.0, 1.0
    while index > 0:
        scale /= base
        index, digit = divmod(index, base)
        out += digit * scale
    return out


def halton_jitter(frame: int, *, phases: int) -> tuple[float, float]:
    """Frame ``frame``'s sub-pixel camera jitter ``(x, y)`` in pixels, in (−½, ½): Halton (2, 3) point
    ``1 + frame mod phases`` less ½ (Unreal's and Godot's TAA sequences; index 0, the origin, skipped)."""
    index = 1 + int(frame) % int(phases)
    return halton(index, 2) - 0.5, halton(index, 3) - 0.5


@dataclass(frozen=True)
class TaaResolve:
    """One signal's TAA output at frame t.

    Attributes
    ----------
    out : ndarray, shape (H, W), float32
        The resolved image T_t; NaN where the input is.
    reprojected : ndarray, shape (H, W), float32
        T_{t−1} at frame t's points before the clamp; NaN where disoccluded or at the first frame.
    """

    out: np.ndarray
    reprojected: np.ndarray


def resolve_view(current, view: View, previous_view: View | None, history: TaaResolve | None, *, taa,
                 device: str = "cpu") -> TaaResolve:
    """The TAA resolve of ``current`` (S or R of ``view``) against ``history``, frame t−1's resolve.

    Parameters
    ----------
    current : array_like, shape (H, W), float32
        Frame t's signal, NaN where it has none.
    view, previous_view : View
        Frames t and t−1 (``previous_view`` None at the first frame or after a cut: no history).
    history : TaaResolve or None
        Frame t−1's resolve of the same signal.
    taa : TaaConfig
        ``alpha``, ``clamp``, ``gamma``, ``depth_tolerance``.
    device : str

    Returns
    -------
    TaaResolve
    """
    from csmlab.kernels.taa import resolve_taa

    c = np.asarray(current, dtype=np.float32)
    if history is None or previous_view is None:
        return TaaResolve(out=c.copy(), reprojected=np.full(c.shape, np.nan, dtype=np.float32))
    pose = previous_view.pose
    out, reprojected = resolve_taa(c, position=view.gbuffer.position, history=history.out,
                                   history_depth=previous_view.gbuffer.view_depth, eye=pose.position,
                                   rotation=pose.rotation, fov_y_deg=pose.fov_y_deg, aspect=pose.aspect,
                                   jitter=view.jitter or (0.0, 0.0), alpha=taa.alpha, clamp=_KERNEL_CLAMP[taa.clamp],
                                   gamma=taa.gamma, depth_tolerance=taa.depth_tolerance, device=device)
    return TaaResolve(out=out, reprojected=reprojected)


def taa_summary(shadow: TaaResolve, reference: TaaResolve, temporal: TemporalMaps) -> dict[str, float]:
    """Flicker and flip rate after TAA, overall, same-cascade and cascade-changed (:data:`TAA_COLUMNS`).

    Parameters
    ----------
    shadow, reference : TaaResolve
        Frame t's resolve of the method's S and of R.
    temporal : TemporalMaps
        The method's change before TAA at frame t (its ``counted`` and ``same_cascade`` split the
        pixels as before TAA).

    Returns
    -------
    dict of str to float
        Means in float64 over the pixels counted before TAA whose history both resolves kept; NaN
        for an empty subset.
    """
    s, s0 = shadow.out.astype(np.float64), shadow.reprojected.astype(np.float64)
    r, r0 = reference.out.astype(np.float64), reference.reprojected.astype(np.float64)
    counted = temporal.counted & np.isfinite(s) & np.isfinite(s0) & np.isfinite(r) & np.isfinite(r0)
    change = np.abs((s - s0) - (r - r0))
    flipped = ((s > 0.5).astype(np.int8) - (s0 > 0.5).astype(np.int8)) != (
        (r > 0.5).astype(np.int8) - (r0 > 0.5).astype(np.int8))
    same = counted & temporal.same_cascade
    changed = counted & ~temporal.same_cascade
    out = {}
    for name, subset in (("", counted), ("_same", same), ("_changed", changed)):
        out[f"flicker{name}_taa"] = finite_mean(change[subset])
        out[("flip_rate" if not name else f"flip{name}") + "_taa"] = finite_mean(flipped[subset].astype(np.float64))
    return {key: out[key] for key in TAA_COLUMNS}
