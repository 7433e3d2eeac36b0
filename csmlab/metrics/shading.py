"""Shading of a shadow image: what a player sees, for the perceptual metrics and the report.

Linear RGB ``albedo × (ambient + S · max(0, n · l) · c)`` with ``l = −d`` the unit vector toward the
light and ``c`` the light's linear RGB colour (white unless a glTF sun names one; the ambient is
left uncoloured), encoded for display and for ꟻLIP by :mod:`csmlab.srgb` (docs/design.md, "Metrics"). The
albedo is the G-buffer's, per pixel: the triangle's base colour times its texture at the hit
(:mod:`csmlab.kernels.texture`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from csmlab.geometry import normalized

AMBIENT = 0.25
"""The ambient term of a run's shading, in units of the direct light: the perceptual metrics
(:func:`csmlab.metrics.measure_frame`) and the report's shaded views (before and after TAA) use it."""

__all__ = ["AMBIENT", "ShadingTerms", "shaded_rgb", "shading_terms", "view_shading_terms"]


@dataclass(frozen=True)
class ShadingTerms:
    """What the shading of a view takes from the view alone, whatever the shadow.

    Attributes
    ----------
    albedo : ndarray, shape (H, W, 3), float64
        Linear RGB reflectance.
    cosine : ndarray, shape (H, W), float64
        ``max(0, n · l)``.
    light : ndarray, shape (3,), float64, or None
        The light's linear RGB colour; None for white (the shading's unit in every channel).
    """

    albedo: np.ndarray
    cosine: np.ndarray
    light: np.ndarray | None = None

    def taken(self, index) -> ShadingTerms:
        """These terms at the pixels ``index`` selects (one index into both arrays' leading axes), the light kept."""
        return ShadingTerms(albedo=self.albedo[index], cosine=self.cosine[index], light=self.light)


def shading_terms(albedo, normal, *, light_direction, light_colour=None) -> ShadingTerms:
    """The shadow-independent terms of :func:`shaded_rgb` (shapes and units as there).

    ``light_colour`` ``(3,)``: the light's linear RGB in [0, 1]; None or white leaves ``light``
    None, the shading exactly as a white light's.
    """
    towards_light = -normalized(light_direction, name="light_direction")
    light = None
    if light_colour is not None:
        light = np.asarray(light_colour, dtype=np.float64)
        if light.shape != (3,) or not np.all((light >= 0.0) & (light <= 1.0)):
            raise ValueError(f"light_colour: expected three linear RGB values in [0, 1], got {light_colour!r}")
        light = None if np.all(light == 1.0) else light
    return ShadingTerms(albedo=np.asarray(albedo, dtype=np.float64),
                        cosine=np.maximum(np.asarray(normal, dtype=np.float64) @ towards_light, 0.0), light=light)


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
    if terms.light is not None:
        coloured = _channels_scaled(np.broadcast_to(terms.light, terms.albedo.shape), irradiance)
        coloured += ambient
        return terms.albedo * coloured
    irradiance += ambient
    return _channels_scaled(terms.albedo, irradiance)


def _channels_scaled(rgb: np.ndarray, factor: np.ndarray) -> np.ndarray:
    """``rgb * factor[..., None]`` ``(..., 3)`` float64, one channel at a time: the same products,
    where a broadcast over the last axis of 3 runs NumPy's inner loop three elements at a time."""
    out = np.empty(np.broadcast_shapes(rgb.shape, factor.shape + (3,)), dtype=np.float64)
    for channel in range(3):
        np.multiply(rgb[..., channel], factor, out=out[..., channel])
    return out


def view_shading_terms(view) -> ShadingTerms:
    """:func:`shading_terms` of a :class:`csmlab.frame.View`'s G-buffer and light, computed once per view."""
    g = view.gbuffer
    return view.shared(("shading_terms",), lambda: shading_terms(g.albedo, g.normal,
                                                                  light_direction=view.light_direction,
                                                                  light_colour=view.light_colour))
