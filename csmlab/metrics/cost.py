"""Cost of a method in one frame: texture memory, rasterization work and wall-clock time per stage.

Memory and texels rasterized are results (deterministic, in ``metrics.csv``); seconds per stage
are not (they go to ``timings.csv``, docs/design.md "Interfaces").
"""

from __future__ import annotations

from csmlab.frame import Frame
from csmlab.settings import ShadowSettings
from csmlab.storage import memory_bytes

__all__ = ["cost_summary", "shadow_memory_bytes"]


def shadow_memory_bytes(settings: ShadowSettings) -> int:
    """Texture memory of the depth maps in bytes as the engine allocates it (:func:`csmlab.storage.memory_bytes`).

    A texture array of equal cascades: ``C · R² · bytes``.
    """
    return memory_bytes(settings)


def cost_summary(frame: Frame) -> dict[str, float]:
    """``memory_bytes``, ``texels_rasterized`` and a virtual clipmap's page counts of one frame, as floats.

    ``pages_marked``, ``pages_rendered`` (the cache misses) and ``pool_bytes`` (its resident pages'
    bytes) are NaN for cascades, which have no pages (:mod:`csmlab.clipmaps`).
    """
    pages = frame.maps.pages
    return {
        "memory_bytes": float(shadow_memory_bytes(frame.settings)),
        "texels_rasterized": float(frame.maps.texels_rasterized),
        "pages_marked": float("nan") if pages is None else float(pages.marked),
        "pages_rendered": float("nan") if pages is None else float(pages.rendered),
        "pool_bytes": float("nan") if pages is None else float(pages.resident_bytes),
    }
