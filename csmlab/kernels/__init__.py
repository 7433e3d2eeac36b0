"""Warp kernels, each beside its one typed NumPy-in/NumPy-out host wrapper.

- :mod:`csmlab.kernels.raster` — depth rasterization of every cascade (fixed-point, top-left rule).
- :mod:`csmlab.kernels.visibility` — the scene's BVH on a device and the camera G-buffer.
- :mod:`csmlab.kernels.shadow` — cascade selection, receiver depth test, filtering, blend band.
- :mod:`csmlab.kernels.pcf` — weighted PCF at a selected cascade: Gaussian, tent, Poisson disk, PCSS.
- :mod:`csmlab.kernels.moments` — VSM/EVSM moments, their separable blur, mip chain and the Chebyshev lookup
  (bilinear, trilinear or anisotropic).
- :mod:`csmlab.kernels.reference` — the ray-traced hard shadow (ground truth).
- :mod:`csmlab.kernels.footprint` — texel footprint of a screen pixel (aliasing metric).
- :mod:`csmlab.kernels.threads` — CPU launches split over threads, each writing its own outputs.

Every wrapper takes ``device=`` (``"cpu"`` by default, ``"cuda"`` when asked) and checks it with
:func:`checked_device` before any upload.
"""

from __future__ import annotations

import numpy as np
import warp as wp

__all__ = ["checked_device", "device_empty"]


def checked_device(device: str) -> str:
    """Return ``device`` after checking that Warp can run on it.

    Raises
    ------
    ValueError
        If ``device`` is not ``"cpu"`` or a CUDA device name, or names a GPU that is not present.
    """
    name = str(device)
    if name != "cpu" and not name.startswith("cuda"):
        raise ValueError(f"device: expected 'cpu' or 'cuda' (or 'cuda:N'), got {device!r}")
    if name.startswith("cuda") and wp.get_cuda_device_count() == 0:
        raise ValueError(f"device: {device!r} was asked for but Warp finds no CUDA device; use device='cpu'")
    try:
        wp.get_device(name)
    except (RuntimeError, ValueError) as error:
        raise ValueError(f"device: Warp cannot use {device!r}: {error}") from None
    return name


def device_empty(shape, dtype, device: str) -> wp.array:
    """An uninitialized Warp array of ``shape`` and Warp ``dtype`` on ``device``.

    On the CPU its memory is NumPy's, which gives arrays of a few MiB transparent huge pages: a
    kernel's first writes then fault in 2 MiB at a time, not 4 KiB (Warp's own allocation costs a
    fresh page fault per 4 KiB, a large share of a kernel that writes a big output once).
    """
    if not wp.get_device(device).is_cpu:
        return wp.empty(shape, dtype=dtype, device=device)
    shape = (shape,) if isinstance(shape, int) else tuple(shape)
    scalar = getattr(dtype, "_wp_scalar_type_", dtype)
    lanes = tuple(getattr(dtype, "_shape_", ()))
    return wp.array(np.empty(shape + lanes, dtype=wp.dtype_to_numpy(scalar)), dtype=dtype, copy=False)
