"""The far fade: the shadow's weight toward lit over the end of the shadow distance (lookup step 6).

Engines fade the shadow out before the last cascade ends so that its edge does not show as a line;
they differ in what the fade is a function of and in its shape. Each shape is a :class:`Fade` record
in :data:`FADE_METHODS` (``[shadow] fade``), NumPy only, so the config loader checks the name
without loading Warp; :func:`faded` applies one to a lookup's lit fractions.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from csmlab.registry import check_name

__all__ = ["FADE_METHODS", "Fade", "faded"]


@dataclass(frozen=True)
class Fade:
    """One shape of the far fade: the weight toward lit over the last ``fade_out`` of the shadow distance ``d``.

    Attributes
    ----------
    weight : callable
        ``weight(z, r, *, far, fade_out) -> w`` in [0, 1] from the view depth ``z`` and the distance
        ``r`` to the camera (None unless :attr:`radial`), metres.
    radial : bool
        The weight reads the distance to the camera, not the view depth.
    what : str
        The shape in words, and whose it is.
    """

    weight: Callable[..., np.ndarray]
    radial: bool
    what: str


def _ramp(u: np.ndarray, lo: float, hi: float) -> np.ndarray:
    return np.clip((u - lo) / max(hi - lo, 1e-12), 0.0, 1.0)


def _fade_linear(z, r, *, far: float, fade_out: float) -> np.ndarray:
    return _ramp(np.asarray(z, dtype=np.float64), far * (1.0 - fade_out), far)


def _fade_smoothstep(z, r, *, far: float, fade_out: float) -> np.ndarray:
    t = _fade_linear(z, r, far=far, fade_out=fade_out)
    return t * t * (3.0 - 2.0 * t)


def _fade_radial(z, r, *, far: float, fade_out: float) -> np.ndarray:
    return _ramp(np.asarray(r, dtype=np.float64), far * (1.0 - fade_out), far)


def _fade_squared_radial(z, r, *, far: float, fade_out: float) -> np.ndarray:
    r2 = np.square(np.asarray(r, dtype=np.float64))
    return _ramp(r2, (far * (1.0 - fade_out)) ** 2, far * far)


FADE_METHODS: dict[str, Fade] = {
    "linear": Fade(_fade_linear, False, "linear in view depth from d (1 - f) to d (Unreal "
                                        "ShadowDistanceFadeoutFraction; Unity built-in Close Fit)"),
    "smoothstep": Fade(_fade_smoothstep, False, "smoothstep in view depth from d (1 - f) to d (Godot 4: "
                                                "smoothstep(fade_from, fade_to, vertex.z), light_storage.cpp "
                                                "fade_from = -split_offsets[3] · fade_start)"),
    "radial": Fade(_fade_radial, True, "linear in the distance to the camera from d (1 - f) to d (Unity built-in "
                                       "Stable Fit's spherical fade, UnityComputeShadowFadeDistance; its centre is "
                                       "set natively, taken here as the camera)"),
    "squared_radial": Fade(_fade_squared_radial, True, "linear in the squared distance to the camera from "
                                                       "(d (1 - f))² to d² (Unity URP: ShadowUtils."
                                                       "GetScaleAndBiasForLinearDistanceFade, GetMainLightShadowFade)"),
}
"""Far-fade shapes by name (``[shadow] fade``)."""


def faded(lit: np.ndarray, view_depth: np.ndarray, *, far: float, fade_out: float, fade: str = "linear",
          distance=None) -> tuple[np.ndarray, np.ndarray]:
    """``lit`` ``(N,)`` faded toward 1 over the last ``fade_out`` fraction of ``far``.

    With ``fade = "linear"`` the weight rises linearly in view depth from 0 at ``far (1 - fade_out)``
    to 1 at ``far`` (Unreal's ``ShadowDistanceFadeoutFraction``); the other shapes are those of
    :data:`FADE_METHODS`, the radial ones reading ``distance`` ``(N,)``, each receiver's distance to
    the camera in metres.

    Returns
    -------
    lit : ndarray, shape (N,), float32
    fading : ndarray, shape (N,), bool
        The weight is above 0.
    """
    record = FADE_METHODS[check_name(fade, FADE_METHODS, field="fade")]
    if record.radial and distance is None:
        raise ValueError(f"distance: fade = {fade!r} needs each receiver's distance to the camera")
    weight = record.weight(view_depth, distance, far=far, fade_out=fade_out)
    return (lit + (1.0 - lit) * weight).astype(np.float32), weight > 0.0
