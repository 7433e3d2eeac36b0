"""What a reference shadow ray is, for both methods: its start's offset along the normal, its length, and
the receivers checked and flattened (:mod:`csmlab.kernels.reference`)."""

from __future__ import annotations

import numpy as np

from csmlab.geometry import light_basis

__all__ = ["RAY_LENGTH", "RAY_OFFSET", "checked_receivers"]

RAY_OFFSET = 1e-5
"""Ray start offset along the normal, as a fraction of the scene's bounding-box diagonal."""


RAY_LENGTH = 4.0
"""Length of a shadow ray, as a multiple of the scene's bounding-box diagonal (beyond every occluder)."""


def checked_receivers(points, normals, light_direction) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``points`` (float64) and ``normals`` (float32) as contiguous ``(N, 3)`` arrays, and the light basis."""
    p = np.asarray(points, dtype=np.float64)
    n = np.asarray(normals, dtype=np.float32)
    if p.shape[-1:] != (3,) or n.shape != p.shape:
        raise ValueError(f"points, normals: expected two arrays of shape (..., 3), got {p.shape} and {n.shape}")
    d = np.asarray(light_direction, dtype=np.float64)
    if d.shape != (3,) or not np.all(np.isfinite(d)) or np.linalg.norm(d) == 0.0:
        raise ValueError(f"light_direction: expected a finite non-zero vector (3,), got {light_direction!r}")
    return np.ascontiguousarray(p.reshape(-1, 3)), np.ascontiguousarray(n.reshape(-1, 3)), light_basis(d)
