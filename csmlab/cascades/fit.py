"""Fit modes: which part of the view frustum each cascade must cover.

Reference: Microsoft, "Cascaded Shadow Maps" (seed 002): *fit to cascade* covers only the
cascade's own slice ``[z_i, z_{i+1}]``; *fit to scene* covers ``[z_0, z_{i+1}]`` so each
cascade contains all nearer ones. Registered in :data:`FIT_METHODS`.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from csmlab.registry import check_name

__all__ = ["FIT_METHODS", "fit_cascade", "fit_scene", "slice_intervals"]


def fit_cascade(splits: np.ndarray, i: int) -> tuple[float, float]:
    """View-depth interval of cascade ``i``'s own slice."""
    return float(splits[i]), float(splits[i + 1])


def fit_scene(splits: np.ndarray, i: int) -> tuple[float, float]:
    """View-depth interval from the near plane to cascade ``i``'s far end."""
    return float(splits[0]), float(splits[i + 1])


FIT_METHODS: dict[str, Callable[[np.ndarray, int], tuple[float, float]]] = {
    "cascade": fit_cascade,
    "scene": fit_scene,
}
"""Fit modes by name."""


def slice_intervals(splits: np.ndarray, *, method: str, blend_band: float = 0.0) -> np.ndarray:
    """View-depth interval ``(C, 2)`` in metres that each cascade's box must contain.

    With a blend band ``b`` the slice of cascade ``i > 0`` starts ``b · (z_i - z_{i-1})`` earlier,
    so that the band at the end of cascade ``i - 1``, where the two are blended, lies in both.
    """
    check_name(method, FIT_METHODS, field="fit")
    count = len(splits) - 1
    out = np.array([FIT_METHODS[method](splits, i) for i in range(count)], dtype=np.float64)
    for i in range(1, count):
        out[i, 0] = min(out[i, 0], splits[i] - blend_band * (splits[i] - splits[i - 1]))
    return out
