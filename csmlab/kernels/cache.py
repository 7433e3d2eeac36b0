"""Warp's kernel cache filled ahead of a run: every csmlab kernel module compiled for a device.

Warp compiles a module's kernels the first time one of them is launched and keeps the result in its
kernel cache (``~/.cache/warp/<version>/`` unless ``WARP_CACHE_PATH`` or
``warp.config.kernel_cache_dir`` says otherwise); later processes load the cached binary. A new
user's first ``csmlab run`` in a fresh clone paid that compilation inside the run, in every pool
process at once, on top of the frames (the default run: 61 s first, 36 s after). ``./setup.sh``
calls :func:`build_kernel_cache`, so the first run finds the cache built.

A module's cache entry is named by a hash of its code: a module edited since the cache was built
compiles again on its next launch, as before; the cache is never wrong, only cold.
"""

from __future__ import annotations

import importlib
import os
import pkgutil

import warp as wp

import csmlab.kernels
from csmlab.kernels import checked_device, start_warp

__all__ = ["build_kernel_cache", "kernel_modules"]


def kernel_modules() -> list[str]:
    """Names of every module under :mod:`csmlab.kernels` that defines a Warp kernel, imported, sorted.

    Walks the package's files (subpackages too), so a kernel module added later is found without
    being listed here.
    """
    names = []
    for info in pkgutil.walk_packages(csmlab.kernels.__path__, prefix="csmlab.kernels."):
        module = importlib.import_module(info.name)
        # A kernel imported from another module belongs to that one (its Warp module is named after it).
        if any(isinstance(value, wp.Kernel) and value.module.name == info.name for value in vars(module).values()):
            names.append(info.name)
    return sorted(names)


def build_kernel_cache(device: str = "cpu") -> list[str]:
    """Compile (or load from the cache) every csmlab kernel module on ``device``; the module names.

    Parameters
    ----------
    device : str
        ``"cpu"`` or a CUDA device name (:func:`csmlab.kernels.checked_device`).

    Returns
    -------
    list of str
        :func:`kernel_modules`, each now in Warp's kernel cache for ``device``.

    Raises
    ------
    ValueError
        On a device Warp cannot use.
    """
    start_warp()
    device = checked_device(device)
    names = kernel_modules()
    # All at once, one compiler per core (Warp's default compiles one module after another).
    wp.load_module("csmlab.kernels", device=device, recursive=True, max_workers=os.cpu_count() or 1)
    return names
