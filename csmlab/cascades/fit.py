"""Fit modes: which part of the view frustum each cascade must cover.

Reference: Microsoft, "Cascaded Shadow Maps" (seed 002): *fit to cascade* covers only the
cascade's own slice ``[z_i, z_{i+1}]``; *fit to scene* covers ``[z_0, z_{i+1}]`` so each
cascade contains all nearer ones. Registered in :data:`FIT_METHODS`.

Transitions (``[shadow] transition``, with ``blend_band > 0``): where the band in which cascade
``i`` blends into cascade ``i + 1`` lies, registered in :data:`TRANSITION_METHODS`. Each gives the
depths the selection switches cascade at and where each band starts; the band of cascade ``i`` ends
where the selection leaves it, and the boxes are fitted so that both cascades hold it.
"""

from __future__ import annotations

from dataclasses import dataclass
from collections.abc import Callable

import numpy as np

from csmlab.lookup_choices import BLEND_LINEAR, BLEND_SMOOTHSTEP
from csmlab.registry import check_name

__all__ = ["BLEND_CURVES", "TRANSITION_METHODS", "FIT_METHODS", "Transition", "fit_cascade", "fit_cascade_lerp",
           "fit_scene", "GODOT_BLEND_SPLITS", "selection_depths", "slice_intervals", "transition_bands"]


def fit_cascade(splits: np.ndarray, i: int) -> tuple[float, float]:
    """View-depth interval of cascade ``i``'s own slice."""
    return float(splits[i]), float(splits[i + 1])


def fit_cascade_lerp(splits: np.ndarray, i: int) -> tuple[float, float]:
    """Cascade ``i``'s slice with its ends lerped from the near plane: ``n + b (f - n)`` with ``b = z / f``.

    three.js (``CSMFrustum.split``): each cascade's near and far vertices are
    ``lerpVectors(near_j, far_j, breaks[i])``, the breaks being the splits as fractions of the far end
    (``CSM._getBreaks``), the first cascade starting at the near plane and the last ending at the far.
    Each slice ends ``n (1 - b)`` beyond the split the selection switches at.
    """
    near, far = float(splits[0]), float(splits[-1])

    def end(k: int) -> float:
        return near if k == 0 else far if k == len(splits) - 1 else near + float(splits[k]) / far * (far - near)

    return end(i), end(i + 1)


def selection_depths(splits: np.ndarray, *, method: str) -> np.ndarray:
    """The view depths ``(C + 1,)`` in metres where the interval selection switches cascade under the fit ``method``.

    The splits themselves, but for ``cascade_lerp``: three.js selects by ``linearDepth = vViewPosition.z /
    (shadowFar - cameraNear)`` in ``[breaks[i - 1], breaks[i])`` (``CSMShader.js`` ``lights_fragment_begin``,
    ``CSM_cascades`` from ``CSM.getExtendedBreaks``), so cascade ``i`` ends at ``b (f - n)`` with ``b = z / f``:
    ``n b`` before the split, ``n`` before its slice's end (:func:`fit_cascade_lerp`); a point beyond
    ``f - n`` is in no cascade (three.js shades it lit). The first entry stays the near plane.
    """
    check_name(method, FIT_METHODS, field="fit")
    z = np.array(splits, dtype=np.float64)
    if method == "cascade_lerp":
        near, far = float(z[0]), float(z[-1])
        z[1:] = z[1:] / far * (far - near)
    return z


def fit_scene(splits: np.ndarray, i: int) -> tuple[float, float]:
    """View-depth interval from the near plane to cascade ``i``'s far end."""
    return float(splits[0]), float(splits[i + 1])


FIT_METHODS: dict[str, Callable[[np.ndarray, int], tuple[float, float]]] = {
    "cascade": fit_cascade,
    "cascade_lerp": fit_cascade_lerp,
    "scene": fit_scene,
}
"""Fit modes by name."""


def _backward(z: np.ndarray, b: float) -> tuple[np.ndarray, np.ndarray]:
    return z, z[1:] - b * (z[1:] - z[:-1])


def _far_bound(z: np.ndarray, b: float) -> tuple[np.ndarray, np.ndarray]:
    return z, (1.0 - b) * z[1:]


def _forward(z: np.ndarray, b: float) -> tuple[np.ndarray, np.ndarray]:
    select = z.copy()
    select[1:-1] = np.minimum(z[1:-1] + b * (z[1:-1] - z[:-2]), z[2:])
    return select, z[1:].copy()


@dataclass(frozen=True)
class Transition:
    """One placement of the blend band between consecutive cascades.

    Attributes
    ----------
    bands : callable
        ``bands(z, b) -> (select, start)``: from the splits ``z`` ``(C + 1,)`` and the band ``b``,
        the depths ``(C + 1,)`` the interval selection switches cascade at and the start ``(C,)`` of
        each cascade's band toward the next (the band of cascade ``i`` is ``[start_i, select_{i+1})``).
    what : str
        The band in words, and whose it is.
    """

    bands: Callable[[np.ndarray, float], tuple[np.ndarray, np.ndarray]]
    what: str


TRANSITION_METHODS: dict[str, Transition] = {
    "backward": Transition(_backward, "the last b of cascade i's width before z_i+1, cascade i + 1 reaching back "
                                      "(DirectX CSM11, Stride's IsBlendingCascades)"),
    "far_bound": Transition(_far_bound, "from (1 - b) z_i+1 to z_i+1: b of the far bound, not of the width (Bevy "
                                        "overlap_proportion: build_directional_light_cascades, "
                                        "fetch_directional_shadow)"),
    "forward": Transition(_forward, "from z_i+1 to z_i+1 + b (z_i+1 - z_i): cascade i reaching forward past its split "
                                    "(Unreal CascadeTransitionFraction, FShadowCascadeSettings' fade plane)"),
}
"""Blend-band placements by name (``[shadow] transition``)."""


BLEND_CURVES: dict[str, tuple[int, str]] = {
    "linear": (BLEND_LINEAR, "the next cascade's weight rises linearly over the band (DirectX CSM11, Bevy, "
                                  "Unreal)"),
    "smoothstep": (BLEND_SMOOTHSTEP, "smoothstep of the linear weight, w² (3 - 2w) (Stride "
                                          "ShadowMapReceiverDirectional: smoothstep(0, 0.2, splitDist); Godot "
                                          "pssm_blend; MJP FilterAcrossCascades)"),
}
"""Blend-band weight curves by name (``[shadow] blend_curve``): the kernel's code and what it is."""


def transition_bands(splits, *, blend_band: float, transition: str = "backward") -> tuple[np.ndarray, np.ndarray]:
    """The selection's switch depths ``(C + 1,)`` and each cascade's band start ``(C,)``, metres of view depth.

    A cascade without a band (the last one, or every one when ``blend_band`` is 0) starts its band at
    ``+inf``. ``blend_band = 0`` gives the splits themselves as switch depths.
    """
    check_name(transition, TRANSITION_METHODS, field="transition")
    z = np.asarray(splits, dtype=np.float64)
    if blend_band <= 0.0:
        return z.copy(), np.full(len(z) - 1, np.inf)
    select, start = TRANSITION_METHODS[transition].bands(z, float(blend_band))
    start = np.asarray(start, dtype=np.float64).copy()
    start[-1] = np.inf
    # A copy: a band scheme may hand back the splits themselves, which the caller may change.
    return np.array(select, dtype=np.float64), start


def slice_intervals(splits: np.ndarray, *, method: str, blend_band: float = 0.0,
                    transition: str = "backward") -> np.ndarray:
    """View-depth interval ``(C, 2)`` in metres that each cascade's box must contain.

    Each box holds where the selection reads it (:func:`transition_bands`) besides its fitted slice:
    with a band of ``transition = "backward"``, the slice of cascade ``i > 0`` starts
    ``b · (z_i - z_{i-1})`` earlier, so that the band at the end of cascade ``i - 1`` lies in both;
    ``"forward"`` extends cascade ``i``'s far end instead.
    """
    check_name(method, FIT_METHODS, field="fit")
    count = len(splits) - 1
    out = np.array([FIT_METHODS[method](splits, i) for i in range(count)], dtype=np.float64)
    select, start = transition_bands(selection_depths(splits, method=method), blend_band=blend_band,
                                     transition=transition)
    for i in range(count):
        out[i, 1] = max(out[i, 1], select[i + 1])
        if i > 0:
            out[i, 0] = min(out[i, 0], start[i - 1])
    return out


GODOT_BLEND_SPLITS: dict = {"blend_band": 0.1, "transition": "far_bound", "blend_curve": "smoothstep"}
"""Godot 4's ``directional_shadow_blend_splits = true`` as ``[shadow]`` fields (``scene_forward_clustered.glsl``
``light_process``, Forward+ 4.2+): in split i a second lookup in split i + 1 mixed in with weight
``smoothstep(z_i+1 − 0.1 · z_i+1, z_i+1, depth_z)`` (``shadow_split_offsets``), none in the last split: the band
from ``(1 − 0.1) z_i+1`` to ``z_i+1`` (``far_bound``), a smoothstep of the linear weight. With blend splits on, the
Vogel radius is not scaled by the first split (``blur_factor + (1 − blur_factor) · blend_splits`` = 1:
``vogel_scale = "none"``)."""
