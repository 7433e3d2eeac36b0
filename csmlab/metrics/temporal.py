"""Temporal shadow change (flicker) between consecutive frames of one method.

Definition (docs/design.md, "Metrics", a contract). Keep frame t−1's cascades, depth maps and camera.
For every visible point X of frame t, evaluate S_{t−1}(X) with frame t−1's state — its own
cascade selection, from ``pose_{t−1}.view_depth(X)`` — and count X only where it lies inside a
t−1 cascade (and frame t has a shadow value there too). Then

- flicker = mean |S_t(X) − S_{t−1}(X)|;
- flip rate = fraction of counted points whose state ``S > 0.5`` changes;

each also split into *same cascade* (both frames select the same cascade and neither blends:
swimming from re-rasterization) and *cascade changed* (the selections differ, or the point lies
in a blend band in either frame, where the blend weight follows the camera).

When the shadow's light moved between t−1 and t (the direction its maps were built with,
``maps.cascades.direction``, differs: the view's light every frame, or a sun policy's, held between
updates or quantized, :mod:`csmlab.shadow_policies`), the reference's own change is subtracted: ``ΔS − ΔR``
with ``ΔR = R_t(X) − R_{t−1}(X)``, and a flip is a change of state that differs from the reference's change of
state. R_{t−1}(X) is cast afresh: a shadow ray
from frame t's point X toward frame t−1's light (``View.previous_reference``, from
:func:`csmlab.render.render_view` given ``previous_light_direction``). When the camera did not move
either, frame t−1's reference image is the same cast (the same pixel sees the same point) and is
used as it is. No value is reprojected from frame t−1's image, so the subtraction is exact: where
the shadow maps agree with the reference in both frames, the change is exactly 0. A shadow held
still while the true sun moves (a sun policy between updates) changes by nothing, and its flicker is
exactly 0 there; at an update its pop is what it changed beyond the reference's one-frame change.

Exact stabilization must give exactly 0.0 same-cascade flicker under a static light.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from csmlab.camera import CameraPose
from csmlab.filters import noise_frame, receiver_rows, screen_pixels, uses_pixels
from csmlab.frame import Frame
from csmlab.kernels.temporal import change_maps
from csmlab.metric_registry import finite_mean
from csmlab.quads import quad_lanes
from csmlab.render import lookup_shadow

__all__ = ["TemporalMaps", "previous_reference_at", "temporal_maps", "temporal_summary"]


@dataclass(frozen=True)
class TemporalMaps:
    """Per-pixel shadow change of frame t against frame t−1, at frame t's visible points.

    Attributes
    ----------
    previous_lit : ndarray, shape (H, W), float32
        S_{t−1}(X): frame t−1's lit fraction at frame t's point; NaN where X is not inside a
        t−1 cascade or the pixel missed.
    change : ndarray, shape (H, W), float64
        S_t − S_{t−1} (minus R_t − R_{t−1} when the light moved); NaN where not counted.
    flipped : ndarray, shape (H, W), bool
        The lit/shadowed state changed (beyond the reference's change when the light moved).
    counted : ndarray, shape (H, W), bool
        Pixels that enter the means.
    same_cascade : ndarray, shape (H, W), bool
        Counted pixels whose cascade is the same in both frames, outside any blend band.
    light_moved : bool
        The shadow's light direction (its maps') differs between the two frames.
    """

    previous_lit: np.ndarray
    change: np.ndarray
    flipped: np.ndarray
    counted: np.ndarray
    same_cascade: np.ndarray
    light_moved: bool


def temporal_maps(frame: Frame, previous: Frame, *, device: str = "cpu") -> TemporalMaps:
    """Shadow change of ``frame`` (t) against ``previous`` (t−1) of the same method.

    Parameters
    ----------
    frame, previous : Frame
        Consecutive frames of one method over the same static scene, with the same image size.
    device : str
        Warp device for the lookup of frame t−1's maps.

    Returns
    -------
    TemporalMaps

    Raises
    ------
    ValueError
        If the two frames' images differ in size, or if camera and light both moved and frame t's
        view holds no reference cast under frame t−1's light (:func:`previous_reference_at`).
    """
    g = frame.view.gbuffer
    if previous.view.gbuffer.shape != g.shape:
        raise ValueError(f"previous frame: expected an image of {g.shape} pixels, got {previous.view.gbuffer.shape}")
    # The visible points, their normals and their depth from frame t−1's camera: the same for every
    # method, kept by the view under what they depend on (not frame t−1's view itself, which would
    # keep every earlier view alive in a chain).
    visible, rows, points, normals = frame.view.shared(("visible_points",), lambda: _visible_points(g))
    camera = previous.view.pose
    seen_from = (camera.position.tobytes(), camera.forward.tobytes())
    earlier_depth = frame.view.shared(("view_depth_from",) + seen_from, lambda: camera.view_depth(points))
    quads = quad_view_depth = None
    if previous.maps.mips is not None:
        # Frame t's pixel quads, each lane selecting with frame t−1's camera (csmlab.quads).
        quads = quad_lanes(frame.view.pose, g.position, g.normal, width=g.shape[1], height=g.shape[0])[visible]
        quad_view_depth = previous.view.pose.view_depth(quads.position)
    earlier = lookup_shadow(previous.maps, points=points, normals=normals, view_depth=earlier_depth,
                            settings=previous.settings,
                            pixels=(screen_pixels(previous.view.pose, points, width=g.shape[1], height=g.shape[0],
                                                  jitter=previous.view.jitter)
                                    if uses_pixels(previous.settings) else None),
                            quads=quads, quad_view_depth=quad_view_depth,
                            noise_frame=noise_frame(previous.settings, frame=previous.view.index,
                                                    taa=previous.view.jitter is not None),
                            rows=frame.view.shared(("receiver_rows_from",) + seen_from,
                                                   lambda: receiver_rows(points, earlier_depth)),
                            device=device)
    light_moved = not np.array_equal(frame.maps.cascades.direction, previous.maps.cascades.direction)
    # Under a moving light the reference's own change is subtracted (module docstring).
    references = ({"reference": frame.view.reference, "previous_reference": previous_reference_at(frame, previous)}
                  if light_moved else {})
    maps = change_maps(rows, earlier.lit, earlier.cascade, earlier.blend, lit=frame.shadow.lit,
                       cascade=frame.shadow.cascade, blend=frame.shadow.blend, **references)
    return TemporalMaps(**maps, light_moved=light_moved)


def _visible_points(g) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The visible pixels of a G-buffer: their mask ``(H, W)``, flat indices ``(N,)`` in row-major order,
    world positions ``(N, 3)`` float64 and normals ``(N, 3)`` float32 — ``position[valid]`` and
    ``normal[valid]``, the same rows in the same order, gathered by index (a 2-D boolean mask over
    a 3-channel array takes NumPy's slow path: 2.8 ms against 0.45 ms each at 640×360)."""
    visible = g.valid
    rows = np.flatnonzero(visible)
    return (visible, rows, np.take(g.position.reshape(-1, 3), rows, axis=0),
            np.take(g.normal.reshape(-1, 3), rows, axis=0))


def _same_camera(a: CameraPose, b: CameraPose) -> bool:
    return (np.array_equal(a.position, b.position) and np.array_equal(a.orientation, b.orientation)
            and (a.fov_y_deg, a.aspect) == (b.fov_y_deg, b.aspect))


def previous_reference_at(frame: Frame, previous: Frame) -> np.ndarray:
    """Frame t−1's reference R_{t−1} at frame t's visible points, ``(H, W)`` float32, NaN on a miss.

    The cast of frame t's view under frame t−1's light (``frame.view.previous_reference``) when
    the view holds it for that light; else, for an unmoved camera (and an unmoved light), frame
    t−1's own reference image, which is the same cast pixel for pixel.

    Raises
    ------
    ValueError
        When the camera moved and frame t's view holds no cast under frame t−1's light: render it
        with ``render_view(..., previous_light_direction=...)``.
    """
    g = frame.view.gbuffer
    view, before = frame.view, previous.view
    cast = view.previous_reference
    if cast is not None and np.array_equal(view.previous_light_direction, before.light_direction):
        return np.where(g.valid, cast, np.nan).astype(np.float32)
    if _same_camera(view.pose, before.pose) and before.reference is not None:
        return np.where(g.valid, before.reference, np.nan).astype(np.float32)
    raise ValueError(f"frame {view.index}: expected its view rendered with previous_light_direction = frame "
                     f"{before.index}'s light (the reference R_(t-1) is cast, not reprojected), got "
                     + ("none" if cast is None else f"a cast under another light, {view.previous_light_direction}"))


def temporal_summary(maps: TemporalMaps) -> dict[str, float]:
    """Flicker and flip rate overall, same-cascade and cascade-changed.

    Returns
    -------
    dict of str to float
        ``flicker, flicker_same, flicker_changed, flip_rate, flip_same, flip_changed``: means over
        the counted pixels of each subset, in float64; NaN for an empty subset (e.g. no pixel
        changed cascade).
    """
    changed = maps.counted & ~maps.same_cascade
    magnitude = np.abs(maps.change)
    out = {}
    for suffix, subset in (("", maps.counted), ("_same", maps.same_cascade), ("_changed", changed)):
        out[f"flicker{suffix}"] = finite_mean(magnitude[subset])
        # A count over a count, as the mean of the 0/1 values is, without gathering them.
        size = int(np.count_nonzero(subset))
        flips = int(np.count_nonzero(maps.flipped & subset))
        out["flip_rate" if not suffix else f"flip{suffix}"] = flips / size if size else float("nan")
    return {key: out[key] for key in ("flicker", "flicker_same", "flicker_changed", "flip_rate", "flip_same",
                                      "flip_changed")}
