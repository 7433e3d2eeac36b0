"""The shading of shadow images on the host: ``albedo × (ambient + S · cos · c)``, each pixel in one pass.

:func:`csmlab.metrics.shading.shaded_rgb` defines the shading; this is its arithmetic. NumPy made it
one channel at a time, each product writing every third value of the image (~1.3 ms a 640×360
image, the perceptual metrics shading two of them a frame and method); here a pixel's three
values are made together. The perceptual metrics shade frame t's S and frame t−1's beside it
(:func:`shaded_pair`): a pixel whose two S are equal (or both undefined) takes the first shading's
value, as a copy of it would, and is shaded again only where they differ.

The values are NumPy's bit for bit: S widened to float64, ``S · cos``, then ``+ ambient`` (white
light) or ``c · (S · cos) + ambient`` (a coloured one), then ``albedo ×`` that, each product and
sum rounded on its own (contraction off). The images are read by NumPy on the host whatever the
run's device: these kernels run on the CPU, a run of pixels a thread.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import warp as wp

from csmlab.kernels import host_array

__all__ = ["shaded_pair", "shaded_pixels"]

# Each product and sum rounded on its own, as NumPy rounds them.
wp.set_module_options({"fuse_fp": False})

_RUN = 2048
"""Pixels a thread shades (a thread's start copies every argument)."""


@wp.func
def shade(albedo: wp.vec3d, irradiance: wp.float64, light: wp.vec3d, coloured: int,
          ambient: wp.float64) -> wp.vec3d:
    """``albedo · (irradiance + ambient)``, or ``albedo · (c · irradiance + ambient)`` under a coloured light."""
    if coloured != 0:
        return wp.vec3d(albedo[0] * (light[0] * irradiance + ambient), albedo[1] * (light[1] * irradiance + ambient),
                        albedo[2] * (light[2] * irradiance + ambient))
    e = irradiance + ambient
    return wp.vec3d(albedo[0] * e, albedo[1] * e, albedo[2] * e)


@wp.kernel
def shaded_kernel(albedo: wp.array(dtype=wp.vec3d), cosine: wp.array(dtype=wp.float64), lit: wp.array(dtype=Any),
                  light: wp.vec3d, coloured: int, ambient: wp.float64, run: int, out: wp.array(dtype=wp.vec3d)):
    k = wp.tid() * run
    end = wp.min(k + run, out.shape[0])
    while k < end:
        out[k] = shade(albedo[k], wp.float64(lit[k]) * cosine[k], light, coloured, ambient)
        k += 1


@wp.kernel
def shaded_pair_kernel(albedo: wp.array(dtype=wp.vec3d), cosine: wp.array(dtype=wp.float64),
                       lit: wp.array(dtype=wp.float32), other: wp.array(dtype=wp.float32), light: wp.vec3d,
                       coloured: int, ambient: wp.float64, run: int, out: wp.array(dtype=wp.vec3d),
                       other_out: wp.array(dtype=wp.vec3d)):
    k = wp.tid() * run
    end = wp.min(k + run, out.shape[0])
    while k < end:
        s = lit[k]
        t = other[k]
        value = shade(albedo[k], wp.float64(s) * cosine[k], light, coloured, ambient)
        out[k] = value
        # NaN is the one value unequal to itself.
        if s == t or (s != s and t != t):
            other_out[k] = value
        else:
            other_out[k] = shade(albedo[k], wp.float64(t) * cosine[k], light, coloured, ambient)
        k += 1


for _dtype in (wp.float32, wp.float64):
    wp.overload(shaded_kernel, {"lit": wp.array(dtype=_dtype)})


def _flat_terms(albedo, cosine, light, shape: tuple) -> tuple[wp.array, wp.array, wp.vec3d, int]:
    """The shading terms as flat Warp arrays on the CPU (read in place when C-contiguous float64) and the light."""
    albedo = np.ascontiguousarray(albedo, dtype=np.float64)
    cosine = np.ascontiguousarray(cosine, dtype=np.float64)
    if albedo.shape != shape + (3,) or cosine.shape != shape:
        raise ValueError(f"albedo, cosine: expected shapes {shape + (3,)} and {shape} (the shadow's), got "
                         f"{albedo.shape} and {cosine.shape}")
    colour = wp.vec3d(0.0, 0.0, 0.0) if light is None else wp.vec3d(*np.asarray(light, dtype=np.float64))
    return (host_array(albedo.reshape(-1, 3), wp.vec3d), host_array(cosine.reshape(-1), wp.float64), colour,
            int(light is not None))


def _lit_array(lit: np.ndarray) -> wp.array:
    return host_array(lit.reshape(-1), wp.float32 if lit.dtype == np.float32 else wp.float64)


def shaded_pixels(albedo, cosine, lit, *, light=None, ambient: float) -> np.ndarray:
    """Linear RGB ``(..., 3)`` float64 of each pixel lit through the shadow ``lit``.

    Parameters
    ----------
    albedo : array_like, shape (..., 3)
        Linear RGB reflectance.
    cosine : array_like, shape (...)
        ``max(0, n · l)`` of each pixel.
    lit : array_like, shape (...)
        Lit fraction S, float32 or float64 (others are taken as float64); NaN where undefined.
    light : array_like, shape (3,), optional
        The light's linear RGB colour; None for white.
    ambient : float
        Ambient term, in units of the direct light.

    Returns
    -------
    ndarray, shape (..., 3), float64
        NaN where ``lit`` is NaN.
    """
    lit = np.ascontiguousarray(lit, dtype=np.float32 if np.asarray(lit).dtype == np.float32 else np.float64)
    albedo, cosine, colour, coloured = _flat_terms(albedo, cosine, light, lit.shape)
    out = np.empty(lit.shape + (3,), dtype=np.float64)
    if lit.size:
        wp.launch(shaded_kernel, dim=-(-lit.size // _RUN),
                  inputs=(albedo, cosine, _lit_array(lit), colour, coloured, wp.float64(ambient), _RUN),
                  outputs=(host_array(out.reshape(-1, 3), wp.vec3d),), device="cpu")
    return out


def shaded_pair(albedo, cosine, lit, other, *, light=None, ambient: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`shaded_pixels` of two shadows of the same pixels, ``(..., 3)`` float64 each.

    ``lit`` and ``other`` ``(...)`` are float32; where the two are equal or both NaN the second
    image's pixel is the first's (the same bits a shading of its own gives).
    """
    lit = np.ascontiguousarray(lit, dtype=np.float32)
    other = np.ascontiguousarray(other, dtype=np.float32)
    if other.shape != lit.shape:
        raise ValueError(f"other: expected the shape of lit {lit.shape}, got {other.shape}")
    albedo, cosine, colour, coloured = _flat_terms(albedo, cosine, light, lit.shape)
    out = np.empty(lit.shape + (3,), dtype=np.float64)
    other_out = np.empty_like(out)
    if lit.size:
        wp.launch(shaded_pair_kernel, dim=-(-lit.size // _RUN),
                  inputs=(albedo, cosine, _lit_array(lit), _lit_array(other), colour, coloured, wp.float64(ambient),
                          _RUN),
                  outputs=(host_array(out.reshape(-1, 3), wp.vec3d), host_array(other_out.reshape(-1, 3), wp.vec3d)),
                  device="cpu")
    return out, other_out
