"""The records one rendered frame is made of: what the camera sees, the shadow maps, the lookup.

Plain frozen dataclasses of NumPy arrays, produced by :mod:`csmlab.render` and consumed by
:mod:`csmlab.metrics` and :mod:`csmlab.report`. Image arrays are ``(H, W, …)`` with row 0 at
the top of the image; pixel ``(row, col)`` has its centre at ``(col + 0.5, row + 0.5)``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from csmlab.camera import CameraPose
from csmlab.cascades import CascadeSet
from csmlab.settings import ShadowSettings

if TYPE_CHECKING:
    # Only for the annotation: the record lives beside the kernel that fills it, and loading
    # csmlab.frame does not load Warp.
    from csmlab.kernels.visibility import CameraHits
    from csmlab.clipmaps import VirtualPages
    from csmlab.scrolling import RasterizedMaps

__all__ = ["Frame", "GBuffer", "ShadowLookup", "ShadowMaps", "View"]


@dataclass(frozen=True)
class GBuffer:
    """Per-pixel first hit of the camera rays: the hits record of the visibility kernel and the albedo.

    The arrays are the ones :func:`csmlab.kernels.visibility.camera_hits` returned, held, not
    copied; the properties below read them.

    Attributes
    ----------
    hits : CameraHits
        ``position`` (H, W, 3) float64 world metres, NaN on a miss; ``normal`` (H, W, 3) float32
        unit geometric normal facing the camera, 0 on a miss; ``triangle`` (H, W) int32, -1 on a
        miss; ``view_depth`` (H, W) float32 ``-z_view`` in metres, +inf on a miss
        (:class:`csmlab.kernels.visibility.CameraHits`).
    albedo : ndarray, shape (H, W, 3), float32
        Linear RGB reflectance of the hit triangle; 0 on a miss.
    """

    hits: CameraHits
    albedo: np.ndarray

    @property
    def position(self) -> np.ndarray:
        """``(H, W, 3)`` float64: world position of the hit, metres; NaN on a miss."""
        return self.hits.position

    @property
    def normal(self) -> np.ndarray:
        """``(H, W, 3)`` float32: unit normal of the hit triangle, facing the camera; 0 on a miss."""
        return self.hits.normal

    @property
    def triangle(self) -> np.ndarray:
        """``(H, W)`` int32: index of the hit triangle; -1 on a miss."""
        return self.hits.triangle

    @property
    def view_depth(self) -> np.ndarray:
        """``(H, W)`` float32: ``-z_view`` of the hit in metres; +inf on a miss."""
        return self.hits.view_depth

    @property
    def valid(self) -> np.ndarray:
        """``(H, W)`` bool: the ray hit the scene."""
        return self.hits.triangle >= 0

    @property
    def shape(self) -> tuple[int, int]:
        return self.hits.triangle.shape


@dataclass(frozen=True)
class View:
    """What depends on the camera and the light but not on the shadow method: shared by all methods.

    Attributes
    ----------
    index : int
        Frame number.
    pose : CameraPose
    light_direction : ndarray, shape (3,), float64
        Unit direction from the light toward the scene.
    gbuffer : GBuffer
    reference : ndarray, shape (H, W), float32, or None
        Ray-traced hard shadow R: 1 lit, 0 shadowed, NaN on a miss; None when not cast
        (:func:`csmlab.render.render_view` ``reference=False``).
    timings : dict of str to float
        Seconds per stage (``visibility``, ``reference``, ``reference_previous``).
    previous_light_direction : ndarray, shape (3,), float64, or None
        The previous frame's light direction when it differs from ``light_direction``.
    previous_reference : ndarray, shape (H, W), float32, or None
        R_{t−1} at this view's points: the ray-traced hard shadow under ``previous_light_direction``
        (1 lit, 0 shadowed, NaN on a miss); None when the light did not move or was not given.
    jitter : tuple of float, or None
        The sub-pixel camera jitter ``(x, y)`` in pixels (x right, y down) this view was rendered
        with for temporal anti-aliasing (:mod:`csmlab.metrics.taa`): pixel ``(row, col)`` saw the
        image point ``(col + ½ + x, row + ½ + y)``; None without TAA.
    light_colour : ndarray, shape (3,), float64, or None
        Linear RGB of the light (:attr:`csmlab.light.LightPath.colour`); None: white.
    derived : dict
        Quantities of this view alone computed for the metrics, by :meth:`shared`; not part of
        the view's identity.
    """

    index: int
    pose: CameraPose
    light_direction: np.ndarray
    gbuffer: GBuffer
    reference: np.ndarray | None
    timings: dict = field(default_factory=dict)
    previous_light_direction: np.ndarray | None = None
    previous_reference: np.ndarray | None = None
    jitter: tuple[float, float] | None = None
    light_colour: np.ndarray | None = None
    derived: dict = field(default_factory=dict, init=False, compare=False, repr=False)

    def shared(self, key: tuple, compute: Callable[[], Any]) -> Any:
        """``compute()``, kept in :attr:`derived` under ``key``: what every method measures of this view
        alone (its surface differentials, its points seen from the previous camera) is computed
        by the first method that needs it and read by the others."""
        if key not in self.derived:
            self.derived[key] = compute()
        return self.derived[key]


@dataclass(frozen=True)
class ShadowMaps:
    """One method's cascades and their rasterized depth maps for one frame.

    Attributes
    ----------
    cascades : CascadeSet
    depth : ndarray, shape (C, R, R), float32
        ``dot(X, d) - zref`` in metres of the nearest caster at each texel centre; +inf where
        empty. ``depth[c, j, i]`` is texel column ``i`` (light x), row ``j`` (light y) of cascade c.
    texels_rasterized : int
        Texel-centre coverage tests that passed (work done by the rasterizer).
    moments : ndarray, shape (C, R, R, 4), float32, optional
        Blurred moment maps of the moment filters (:mod:`csmlab.kernels.moments`); None otherwise.
    depth_span : float
        The scene's light-space depth range in metres that stored depth and moments are taken over.
    mips : list of ndarray, optional
        ``moment_mips``: the moments' mip chain, level l of shape ``(C, S_l, S_l, 4)`` float32
        (:func:`csmlab.kernels.moments.moment_mip_chain`); None otherwise.
    raster : RasterizedMaps, optional
        The raw maps and their coverage counts, which the next frame of boxes on whole texels
        scrolls from (:mod:`csmlab.scrolling`); None for other boxes.
    pages : VirtualPages, optional
        ``shadow_map = "virtual_clipmap"``: the page table of the resident pages, whose depths are
        ``depth`` ``(P, page_size, page_size)``, and the frame's page counts; ``cascades`` then holds
        one box per clipmap level (:mod:`csmlab.clipmaps`). None for cascades.
    """

    cascades: CascadeSet
    depth: np.ndarray
    texels_rasterized: int
    moments: np.ndarray | None = None
    depth_span: float = 0.0
    mips: list | None = None
    raster: RasterizedMaps | None = None
    pages: VirtualPages | None = None


@dataclass(frozen=True)
class ShadowLookup:
    """The shadow of one method at a set of receiver points.

    Attributes
    ----------
    lit : ndarray, shape (...), float32
        Lit fraction S in [0, 1]; NaN where there is no receiver or no cascade contains it.
    cascade : ndarray, shape (...), int8
        Selected cascade; -1 where none.
    blend : ndarray, shape (...), bool
        The point lies in a blend band (its S mixes two cascades).
    """

    lit: np.ndarray
    cascade: np.ndarray
    blend: np.ndarray


@dataclass(frozen=True)
class Frame:
    """One frame of one method: the shared view, the method's shadow maps and its shadow.

    Attributes
    ----------
    view : View
    settings : ShadowSettings
    maps : ShadowMaps
    shadow : ShadowLookup or None
        Lookup at every pixel of ``view.gbuffer`` (shape (H, W)); None when not looked up
        (:func:`csmlab.render.render_shadow` ``lookup=False``).
    timings : dict of str to float
        Seconds per method stage (``cascades``, ``raster``, ``shadow``).
    """

    view: View
    settings: ShadowSettings
    maps: ShadowMaps
    shadow: ShadowLookup | None
    timings: dict = field(default_factory=dict)
