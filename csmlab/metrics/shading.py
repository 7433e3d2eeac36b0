"""Shading of a shadow image: what a player sees, for the perceptual metrics and the report.

Linear RGB ``albedo × (ambient + S · max(0, n · l) · c)`` with ``l = −d`` the unit vector toward the
light and ``c`` the light's linear RGB colour (white unless a glTF sun names one; the ambient is
left uncoloured), encoded for display and for ꟻLIP by :mod:`csmlab.srgb` (docs/design.md, "Metrics"). The
albedo is the G-buffer's, per pixel: the triangle's base colour times its texture at the hit
(:mod:`csmlab.kernels.texture`). The per-pixel arithmetic runs in :mod:`csmlab.kernels.shading`, on the host.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from csmlab.geometry import normalized
from csmlab.kernels.shading import shaded_pair, shaded_pixels

AMBIENT = 0.25
"""The ambient term of a run's shading, in units of the direct light: the perceptual metrics
(:func:`csmlab.metrics.measure_frame`) and the report's shaded views (before and after TAA) use it."""

__all__ = ["AMBIENT", "ShadingTerms", "shaded_rgb", "shaded_rgb_pair", "shading_terms", "view_shading_terms"]


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
    _check_ambient(ambient)
    if terms is None:
        terms = shading_terms(albedo, normal, light_direction=light_direction)
    return shaded_pixels(terms.albedo, terms.cosine, lit, light=terms.light, ambient=ambient)


def shaded_rgb_pair(lit, other_lit, *, terms: ShadingTerms, ambient: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`shaded_rgb` of two shadows of the same view, ``(H, W, 3)`` float64 each, in one pass.

    ``lit`` and ``other_lit`` ``(H, W)`` float32 (frame t's S and frame t−1's at frame t's points, for
    the perceptual metrics): a pixel whose two S are equal or both NaN is shaded once for both, the
    others twice; the values are those of two :func:`shaded_rgb` calls, bit for bit.
    """
    _check_ambient(ambient)
    return shaded_pair(terms.albedo, terms.cosine, lit, other_lit, light=terms.light, ambient=ambient)


def _check_ambient(ambient: float) -> None:
    if not (np.isfinite(ambient) and ambient >= 0):
        raise ValueError(f"ambient: expected a non-negative fraction of the direct light, got {ambient}")


def view_shading_terms(view) -> ShadingTerms:
    """:func:`shading_terms` of a :class:`csmlab.frame.View`'s G-buffer and light, computed once per view."""
    g = view.gbuffer
    return view.shared(("shading_terms",), lambda: shading_terms(g.albedo, g.normal,
                                                                  light_direction=view.light_direction,
                                                                  light_colour=view.light_colour))
