"""Shading of a shadow image: what a player sees, for the perceptual metrics and the report.

Linear RGB ``albedo × (ambient + S · max(0, n · l))`` with ``l = −d`` the unit vector toward the
light (docs/design.md, "Metrics"), and its sRGB encoding for display and for ꟻLIP.
"""

from __future__ import annotations

from dataclasses import dataclass

import colour
import numpy as np

from csmlab.geometry import normalized

AMBIENT = 0.25
"""The ambient term of a run's shading, in units of the direct light: the perceptual metrics
(:func:`csmlab.metrics.measure_frame`) and the report's shaded views (before and after TAA) use it."""

__all__ = ["AMBIENT", "ShadingTerms", "shaded_rgb", "shading_terms", "srgb_encoded", "view_shading_terms"]


@dataclass(frozen=True)
class ShadingTerms:
    """What the shading of a view takes from the view alone, whatever the shadow.

    Attributes
    ----------
    albedo : ndarray, shape (H, W, 3), float64
        Linear RGB reflectance.
    cosine : ndarray, shape (H, W), float64
        ``max(0, n · l)``.
    """

    albedo: np.ndarray
    cosine: np.ndarray


def shading_terms(albedo, normal, *, light_direction) -> ShadingTerms:
    """The shadow-independent terms of :func:`shaded_rgb` (shapes and units as there)."""
    towards_light = -normalized(light_direction, name="light_direction")
    return ShadingTerms(albedo=np.asarray(albedo, dtype=np.float64),
                        cosine=np.maximum(np.asarray(normal, dtype=np.float64) @ towards_light, 0.0))


def shaded_rgb(albedo, normal, lit, *, light_direction, ambient: float,
               terms: ShadingTerms | None = None) -> np.ndarray:
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
    terms : ShadingTerms, optional
        :func:`shading_terms` of ``albedo``, ``normal`` and ``light_direction``, when already
        computed (they are the same for every shadow of a view); the result is the same.

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
    if terms is None:
        terms = shading_terms(albedo, normal, light_direction=light_direction)
    # S · cos in float64 (a float32 S widens exactly, in the loop rather than as a copy), then the
    # ambient added in place: the same products and sums (addition commutes), two temporaries fewer.
    irradiance = np.multiply(np.asarray(lit), terms.cosine, dtype=np.float64)
    irradiance += ambient
    return terms.albedo * irradiance[..., None]


def view_shading_terms(view) -> ShadingTerms:
    """:func:`shading_terms` of a :class:`csmlab.frame.View`'s G-buffer and light, computed once per view."""
    g = view.gbuffer
    return view.shared(("shading_terms",), lambda: shading_terms(g.albedo, g.normal,
                                                                  light_direction=view.light_direction))


def srgb_encoded(rgb) -> np.ndarray:
    """sRGB-encoded display values ``(..., 3)`` in [0, 1] of linear RGB, clipped to the display range first."""
    return np.asarray(colour.cctf_encoding(np.clip(np.asarray(rgb, dtype=np.float64), 0.0, 1.0), function="sRGB"))
