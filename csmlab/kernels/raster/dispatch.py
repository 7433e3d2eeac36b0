"""Which rasterizer a device gets: the walk on the CPU, the tiles on CUDA (docs/performance.md, the tiled raster).

Both give the same maps and counts bit for bit (tests/kernels/test_raster_tiled.py); they differ only in
how the work is laid out. A CPU thread walks a run of triangles row by row, eight texels at a time
(:mod:`csmlab.kernels.raster.schedule`); a GPU wants a thread per texel, a block per tile
(:mod:`csmlab.kernels.raster.tiled`).
"""

from __future__ import annotations

from contextlib import contextmanager
from contextvars import ContextVar
from collections.abc import Iterator

import numpy as np
import warp as wp

from csmlab.kernels import checked_device
from csmlab.kernels.raster import schedule
from csmlab.kernels.raster.kernels import TrianglePaths
from csmlab.kernels.raster.mesh import LightSpaceMesh
from csmlab.kernels.raster.tiled import rasterize_tiled

__all__ = ["RASTERIZERS", "device_rasterizer", "rasterize_cascades", "rasterizer_chosen"]

RASTERIZERS = ("walk", "tiled")
"""The rasterizers by name: ``walk`` (thread per run of triangles), ``tiled`` (thread per texel of a tile)."""

_CHOSEN: ContextVar[str | None] = ContextVar("csmlab_rasterizer", default=None)


def device_rasterizer(device: str) -> str:
    """The rasterizer ``device`` gets unless one is chosen (:func:`rasterizer_chosen`): ``tiled`` on CUDA, else
    ``walk``."""
    return "walk" if wp.get_device(checked_device(device)).is_cpu else "tiled"


@contextmanager
def rasterizer_chosen(name: str) -> Iterator[None]:
    """Every :func:`rasterize_cascades` inside the block uses rasterizer ``name`` (:data:`RASTERIZERS`) on any device.

    For benchmarks and tests that time or compare both on one device.
    """
    if name not in RASTERIZERS:
        raise ValueError(f"rasterizer: expected one of {', '.join(RASTERIZERS)}, got {name!r}")
    token = _CHOSEN.set(name)
    try:
        yield
    finally:
        _CHOSEN.reset(token)


def rasterize_cascades(mesh: LightSpaceMesh, *, paths: TrianglePaths | None = None, device: str = "cpu",
                       **how) -> tuple[np.ndarray | None, np.ndarray]:
    """:func:`csmlab.kernels.raster.schedule.rasterize_cascades` (parameters, returns) by the device's rasterizer.

    ``paths`` chooses among the walk's paths, so a call that gives it is walked; so is a call with
    vertices an engine's float32 pipeline converted (``points``, :mod:`csmlab.kernels.engine`),
    casters cut at a slice's near side (``near``) or cascades only counted (``stored_cascades``), whose
    set-up the tiles do not yet take.
    """
    name = _CHOSEN.get() or device_rasterizer(device)
    if name == "tiled" and paths is None and all(how.get(k) is None for k in ("points", "near", "stored_cascades")):
        return rasterize_tiled(mesh, device=device, **how)
    return schedule.rasterize_cascades(mesh, paths=paths, device=device, **how)
