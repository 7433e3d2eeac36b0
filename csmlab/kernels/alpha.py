"""Alpha masks on a device: the masked mesh's texture coordinates and masks, and the alpha test every pass runs.

A masked triangle (:class:`csmlab.scene.core.AlphaMask`, glTF ``alphaMode = MASK``) is a hole
wherever the mask's texel nearest to its interpolated texture coordinates is below the cutoff:
the depth pass (:mod:`csmlab.kernels.raster`), the camera pass (:mod:`csmlab.kernels.visibility`)
and the reference (:mod:`csmlab.kernels.reference`) all call :func:`alpha_passes` with the
coordinates they interpolate from their own barycentric weights, so the three see the same holes.

The texel is the nearest one (point sampling): coordinates repeat (``u − ⌊u⌋``), texel column
``⌊u·W⌋`` and row ``⌊v·H⌋`` (row 0 at v = 0). Engines sample the mask bilinearly from a mip chain
before the test (docs/engines.md, known differences); nearest texels keep the hole's edges where
the mask draws them, the same for every pass and testable against a ray cast texel for texel.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from csmlab.kernels import checked_device

__all__ = ["AlphaTextures", "MaskedMesh", "alpha_passes", "masked_mesh", "no_masks"]

# Products and sums rounded one by one on both devices (clang and NVRTC may otherwise contract them).
wp.set_module_options({"fuse_fp": False})


@wp.struct
class AlphaTextures:
    """Every mask of a scene, packed: mask m is ``height[m] × width[m]`` texels from ``offset[m]``, row by row."""

    texels: wp.array(dtype=wp.float32)
    """Coverage in [0, 1] of every mask's texels, one after another."""
    offset: wp.array(dtype=wp.int64)
    """First texel of each mask in ``texels``."""
    width: wp.array(dtype=wp.int32)
    """Texels per row (u) of each mask."""
    height: wp.array(dtype=wp.int32)
    """Rows (v) of each mask."""
    cutoff: wp.array(dtype=wp.float32)
    """Each mask's cutoff: opaque where coverage ≥ cutoff."""


@wp.func
def alpha_passes(textures: AlphaTextures, m: int, u: wp.float64, v: wp.float64) -> bool:
    """Whether mask ``m`` is opaque at texture coordinates ``(u, v)``; every point of an opaque triangle (m < 0) is."""
    if m < 0:
        return True
    w = textures.width[m]
    h = textures.height[m]
    i = wp.min(int((u - wp.floor(u)) * wp.float64(w)), w - 1)
    j = wp.min(int((v - wp.floor(v)) * wp.float64(h)), h - 1)
    return textures.texels[textures.offset[m] + wp.int64(j) * wp.int64(w) + wp.int64(i)] >= textures.cutoff[m]


@dataclass(frozen=True)
class MaskedMesh:
    """A scene's masks on a device, in the scene's vertex order.

    Attributes
    ----------
    uv : wp.array, shape (V,), vec2d
        Texture coordinates of each vertex (zero-length when nothing is masked).
    vertex_mask : wp.array, shape (V,), int32
        Each vertex's mask, −1 for opaque (zero-length when nothing is masked: every triangle opaque).
    textures : AlphaTextures
    """

    uv: wp.array
    vertex_mask: wp.array
    textures: AlphaTextures


def _textures(masks, device: str) -> AlphaTextures:
    textures = AlphaTextures()
    alphas = [np.ascontiguousarray(m.alpha, dtype=np.float32) for m in masks]
    sizes = np.array([a.size for a in alphas], dtype=np.int64)
    textures.texels = wp.array(np.concatenate([a.reshape(-1) for a in alphas]) if alphas else np.zeros(0, np.float32),
                               dtype=wp.float32, device=device)
    textures.offset = wp.array(np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64) if alphas
                               else np.zeros(0, np.int64), dtype=wp.int64, device=device)
    textures.width = wp.array(np.array([a.shape[1] for a in alphas], dtype=np.int32), dtype=wp.int32, device=device)
    textures.height = wp.array(np.array([a.shape[0] for a in alphas], dtype=np.int32), dtype=wp.int32, device=device)
    textures.cutoff = wp.array(np.array([m.cutoff for m in masks], dtype=np.float32), dtype=wp.float32, device=device)
    return textures


def masked_mesh(uv, vertex_mask, masks, *, device: str = "cpu") -> MaskedMesh:
    """A :class:`MaskedMesh` of per-vertex coordinates ``(V, 2)`` and masks ``(V,)`` and the :class:`AlphaMask` records.

    ``uv`` and ``vertex_mask`` None: :func:`no_masks` (every triangle opaque). ``device`` is checked by
    :func:`csmlab.kernels.checked_device` before any upload.
    """
    device = checked_device(device)
    if vertex_mask is None:
        return no_masks(device=device)
    return MaskedMesh(uv=wp.array(np.ascontiguousarray(uv, dtype=np.float64), dtype=wp.vec2d, device=device),
                      vertex_mask=wp.array(np.ascontiguousarray(vertex_mask, dtype=np.int32), dtype=wp.int32,
                                           device=device),
                      textures=_textures(tuple(masks), device))


def no_masks(*, device: str = "cpu") -> MaskedMesh:
    """The :class:`MaskedMesh` of a scene without masks: zero-length arrays, which the kernels read as "opaque"."""
    device = checked_device(device)
    return MaskedMesh(uv=wp.zeros(0, dtype=wp.vec2d, device=device), vertex_mask=wp.zeros(0, dtype=wp.int32,
                                                                                            device=device),
                      textures=_textures((), device))
