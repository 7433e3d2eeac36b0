"""The shadow lookup's choices by name, the integer codes the kernels switch on, and each filter's margin.

The Warp kernels (:mod:`csmlab.kernels.shadow`, :mod:`csmlab.kernels.pcf`,
:mod:`csmlab.kernels.moments`) take a cascade selection or a filter as an ``int``; the constants
below are those codes, read by the kernels and by the tables that map a ``[shadow]`` name to them.
This module imports neither Warp nor the kernels, so the config loader checks ``selection`` and
``filter`` and computes margins without compiling anything.
"""

from __future__ import annotations

from csmlab.registry import check_name

__all__ = ["BOX_BILINEAR", "BOX_FILTERS", "BOX_NONE", "BOX_PCF", "FILTER_METHODS", "MOMENT_EVSM2", "MOMENT_EVSM4",
           "MOMENT_METHODS", "MOMENT_VSM", "PCF_GAUSSIAN", "PCF_KERNELS", "PCF_PCSS", "PCF_POISSON", "PCF_TENT",
           "SELECTION_METHODS", "SELECT_BEST_RESOLUTION", "SELECT_INTERVAL", "SELECT_MAP", "filter_radius"]

SELECT_INTERVAL = 0
"""Selection code: the cascade whose split interval holds the view depth."""
SELECT_MAP = 1
"""Selection code: the first cascade whose box holds the point inside its margins."""
SELECT_BEST_RESOLUTION = 2
"""Selection code: of the boxes that hold the point, the one with the smallest texels."""

SELECTION_METHODS: dict[str, int] = {"interval": SELECT_INTERVAL, "map": SELECT_MAP,
                                     "best_resolution": SELECT_BEST_RESOLUTION}
"""Cascade selection methods by name, mapped to the kernel's code."""

BOX_NONE = 0
"""Box filter code: the one texel holding the point."""
BOX_PCF = 1
"""Box filter code: N×N texels, equal weights."""
BOX_BILINEAR = 2
"""Box filter code: 2×2 texels, bilinear weights."""

BOX_FILTERS: dict[str, int] = {"none": BOX_NONE, "pcf": BOX_PCF, "pcf_bilinear": BOX_BILINEAR}
"""The filters :func:`csmlab.kernels.shadow.shadow_lookup` runs itself, mapped to its code."""

PCF_GAUSSIAN = 0
PCF_TENT = 1
PCF_POISSON = 2
PCF_PCSS = 3

PCF_KERNELS: dict[str, int] = {"pcf_gaussian": PCF_GAUSSIAN, "pcf_tent": PCF_TENT, "pcf_poisson": PCF_POISSON,
                               "pcss": PCF_PCSS}
"""Weighted PCF filters by name, mapped to the code of :func:`csmlab.kernels.pcf.weighted_pcf`."""

MOMENT_VSM = 0
MOMENT_EVSM2 = 1
MOMENT_EVSM4 = 2

MOMENT_METHODS: dict[str, int] = {"vsm": MOMENT_VSM, "evsm2": MOMENT_EVSM2, "evsm4": MOMENT_EVSM4}
"""Moment filters by name, mapped to the code of the :mod:`csmlab.kernels.moments` kernels."""

FILTER_METHODS: dict[str, str] = {
    "none": "the one texel holding the point",
    "pcf": "N×N texels, equal weights",
    "pcf_bilinear": "2×2 texels, bilinear weights (hardware comparison sampler)",
    "pcf_gaussian": "N×N texels, Gaussian weights of σ = filter_sigma (DirectX CascadedShadowMaps11)",
    "pcf_tent": "tent of half-width N/2 integrated over each texel (Unity's 3×3/5×5/7×7 tents)",
    "pcf_poisson": "poisson_taps taps of a fixed Poisson disk of radius N/2 (optionally rotated per pixel)",
    "pcss": "blocker search over N×N, penumbra from light_size_deg, then a tent (PCSS)",
    "vsm": "variance shadow map: blurred (z, z²), Chebyshev bound (DirectX VarianceShadows11)",
    "evsm2": "exponential VSM, positive warp (MJP, Filament)",
    "evsm4": "exponential VSM, positive and negative warps (MJP, Filament)",
}
"""Filters by name (the ``[shadow] filter`` values) and what each does."""


def filter_radius(filter: str, filter_size: int, *, moment_blur: int = 1, mips: tuple[int, int] | None = None) -> int:
    """Texels a filter reads beyond the one holding the point (``filter_size`` N, odd).

    ``none`` 0; ``pcf``, ``pcf_gaussian`` and ``pcss`` N // 2; ``pcf_bilinear`` 1; ``pcf_tent`` and
    ``pcf_poisson`` N // 2 + 1 (a width of N/2 texels around a point anywhere in its texel); the
    moment filters ``moment_blur // 2 + 1`` (a bilinear lookup of blurred moments), and with
    ``mips = (max_lod, anisotropy)`` ``⌈(anisotropy + 2) / 2 · 2^max_lod⌉ + moment_blur // 2``: a
    bilinear lookup at level l reads within 1.5 · 2^l texels of its probe, and the probes spread
    over at most ``(anisotropy − 1) / 2 · 2^max_lod`` texels on each side (csmlab.kernels.moments).

    Raises
    ------
    ValueError
        On a name not in :data:`FILTER_METHODS`.
    """
    check_name(filter, FILTER_METHODS, field="filter")
    half = filter_size // 2
    if filter in MOMENT_METHODS and mips is not None:
        max_lod, anisotropy = mips
        return -(-(anisotropy + 2) * 2**max_lod // 2) + moment_blur // 2
    if filter in MOMENT_METHODS:
        # The bilinear lookup reads one texel beyond the point, each blurred from moment_blur // 2 more.
        return moment_blur // 2 + 1
    return {"none": 0, "pcf": half, "pcf_bilinear": 1, "pcf_gaussian": half, "pcss": half, "pcf_tent": half + 1,
            "pcf_poisson": half + 1}[filter]
