"""Warp kernels, each beside its one typed NumPy-in/NumPy-out host wrapper.

- :mod:`csmlab.kernels.raster` — depth rasterization of every cascade (fixed-point, top-left rule).
- :mod:`csmlab.kernels.visibility` — the scene's BVH on a device and the camera G-buffer.
- :mod:`csmlab.kernels.camera` — the pinhole camera the camera pass and the TAA resolve read.
- :mod:`csmlab.kernels.shadow` — cascade selection, receiver depth test, filtering, blend band.
- :mod:`csmlab.kernels.pcf` — weighted PCF at a selected cascade: Gaussian, tent, Poisson disk, PCSS.
- :mod:`csmlab.kernels.moments` — VSM/EVSM moments, their separable blur, mip chain and the Chebyshev lookup
  (bilinear, trilinear or anisotropic).
- :mod:`csmlab.kernels.reference` — the ray-traced hard shadow (ground truth): what a shadow ray is
  (``shadow_rays``), the BVH ray cast (``ray_cast``), the irregular z-buffer's binned ray starts
  (``ray_grid``) and its triangles that block them (``irregular``).
- :mod:`csmlab.kernels.flip_inputs` — ꟻLIP's inputs: where the filled pair differs, the colours to encode, the
  encoded pair (on the host).
- :mod:`csmlab.kernels.footprint` — texel footprint of a screen pixel (aliasing metric).
- :mod:`csmlab.kernels.levels` — the clipmap level each virtual shadow map receiver reads.
- :mod:`csmlab.kernels.records` — the report's per-frame records: ground cells, their sums, ρ histogram, animation
  blocks (on the host, in NumPy's order).
- :mod:`csmlab.kernels.shading` — the shaded images of the perceptual metrics and the report (on the host, in
  NumPy's order).
- :mod:`csmlab.kernels.temporal` — the temporal metric's per-pixel maps: S_{t−1} at frame t's pixels, the change,
  its subsets (on the host, in NumPy's order).
- :mod:`csmlab.kernels.threads` — CPU launches split over threads, each writing its own outputs.

Every wrapper takes ``device=`` (``"cpu"`` by default, ``"cuda"`` when asked) and checks it with
:func:`checked_device` before any upload — but those of :mod:`csmlab.kernels.records`,
:mod:`csmlab.kernels.shading`, :mod:`csmlab.kernels.temporal` and :mod:`csmlab.kernels.flip_inputs`, which run
on the CPU always: the report's files and the NumPy arrays they fill must not depend on the device.
"""

from __future__ import annotations

import os
import sys
import tempfile

import numpy as np
import warp as wp

__all__ = ["CUDA_DRIVER_WARNING", "checked_device", "device_empty", "host_array", "start_warp"]


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
    The wrapper names the CPU: Warp's default device is ``cuda:0`` wherever a GPU is present, and an
    array left to the default would be a GPU copy, whose pointer a CPU kernel writes through and
    crashes (a segfault, no error: Warp's launches do not check where their arrays live by default).
    """
    if not wp.get_device(device).is_cpu:
        return wp.empty(shape, dtype=dtype, device=device)
    shape = (shape,) if isinstance(shape, int) else tuple(shape)
    scalar = getattr(dtype, "_wp_scalar_type_", dtype)
    lanes = tuple(getattr(dtype, "_shape_", ()))
    return wp.array(np.empty(shape + lanes, dtype=wp.dtype_to_numpy(scalar)), dtype=dtype, device=device,
                    copy=False)


def host_array(array, dtype) -> wp.array:
    """``array`` as a Warp array of Warp ``dtype`` on the CPU, reading and writing the NumPy array's own memory.

    A vector ``dtype`` takes the array's last axis as its lanes (``(..., 3)`` float64 for ``wp.vec3d``). The array
    is copied only where it is not C-contiguous in the dtype's scalar type — and an output passed so would be
    written into that copy: the host kernels' outputs are made C-contiguous of their type (``np.empty``).
    """
    scalar = getattr(dtype, "_wp_scalar_type_", dtype)
    return wp.array(np.ascontiguousarray(array, dtype=wp.dtype_to_numpy(scalar)), dtype=dtype, device="cpu",
                    copy=False)


CUDA_DRIVER_WARNING = "Warp CUDA warning: Could not find or load the NVIDIA CUDA driver"
"""The start of the line Warp's native library writes to file descriptor 2 when it loads no CUDA driver."""


_STARTED = False


def start_warp() -> None:
    """Start Warp's runtime in this process (once), without its greeting or its CUDA-driver warning.

    On a machine without an NVIDIA driver, Warp's native start-up writes :data:`CUDA_DRIVER_WARNING`
    straight to file descriptor 2 (no Python warning or logger to filter), once in every process that
    uses Warp: a pool of N workers printed it N times, though the run was asked for on the CPU.
    csmlab says which device a run uses in its own words (``csmlab run``'s last line), and a request
    for ``--device cuda`` without a GPU is an input error (exit 2) naming the device, so that line is
    dropped here; whatever else Warp writes while it starts is passed on to stderr. Messages below
    Warp's warning level (its greeting, module loads) are kept out too.

    Every process that runs csmlab's work calls this before its first Warp call (the executors do:
    in process, in each pool worker's initializer, on each Dask worker); later calls return at once,
    and a call after Warp was started elsewhere only sets the level (``wp.init`` is then a no-op).
    """
    global _STARTED
    wp.config.log_level = max(wp.config.log_level, wp.LOG_WARNING)
    if _STARTED:
        return
    _STARTED = True
    sys.stderr.flush()
    with tempfile.TemporaryFile() as caught:
        saved = os.dup(2)
        os.dup2(caught.fileno(), 2)
        try:
            wp.init()
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        caught.seek(0)
        lines = caught.read().decode(errors="replace").splitlines(keepends=True)
    passed = "".join(line for line in lines if not line.startswith(CUDA_DRIVER_WARNING))
    if passed:
        sys.stderr.write(passed)
        sys.stderr.flush()
