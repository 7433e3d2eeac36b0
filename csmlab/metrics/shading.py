"""Shading of a shadow image: what a player sees, for the perceptual metrics and the report.

Linear RGB ``albedo × (ambient + S · max(0, n · l))`` with ``l = −d`` the unit vector toward the
light (DESIGN.md, "Metrics"), and its sRGB encoding for display and for ꟻLIP.
"""

from __future__ import annotations

import colour
import numpy as np

from csmlab.geometry import normalized

__all__ = ["shaded_rgb", "srgb_encoded"]


def shaded_rgb(albedo, normal, lit, *, light_direction, ambient: float) -> np.ndarray:
    """Linear RGB of each pixel lit by a directional light through the shadow ``lit``.

    Parameters
    ----------
    albedo : array_like, shape (H, W, 3)
        Linear RGB reflectance in [0, 1].
    normal : array_like, shape (H, W, 3)
        Unit surface normal, world space.
    lit : array_like, shape (H, W)
        Lit fraction S in [0, 1]; NaN where undefined.
    light_direction : array_like, shape (3,)
        From the light toward the scene, world space; normalized here.
    ambient : float
        Ambient term in units of the direct light's irradiance, ≥ 0.

    Returns
    -------
    ndarray, shape (H, W, 3), float64
        Linear RGB, in [0, 1 + ambient] for albedo in [0, 1]; NaN where ``lit`` is NaN.

    Raises
    ------
    ValueError
        On a negative or non-finite ``ambient`` or a zero light direction.
    """
    if not (np.isfinite(ambient) and ambient >= 0):
        raise ValueError(f"ambient: expected a non-negative fraction of the direct light, got {ambient}")
    towards_light = -normalized(light_direction, name="light_direction")
    cosine = np.maximum(np.asarray(normal, dtype=np.float64) @ towards_light, 0.0)
    irradiance = ambient + np.asarray(lit, dtype=np.float64) * cosine
    return np.asarray(albedo, dtype=np.float64) * irradiance[..., None]


def srgb_encoded(rgb) -> np.ndarray:
    """sRGB-encoded display values ``(..., 3)`` in [0, 1] of linear RGB, clipped to the display range first."""
    return np.asarray(colour.cctf_encoding(np.clip(np.asarray(rgb, dtype=np.float64), 0.0, 1.0), function="sRGB"))
