"""Base-colour textures at the camera's hits: the albedo of each pixel of a textured scene.

A pixel's albedo is its triangle's albedo (the material's base colour factor) times the linear RGB
of the texture (:class:`csmlab.scene.core.ColourTexture`) at the hit's texture coordinates. The
coordinates are the triangle's vertex coordinates interpolated with the hit's barycentric weights,
found here from the hit position and the triangle's corners (the G-buffer keeps the position and
the triangle, not the weights).

Sampling is the nearest texel, as the alpha test samples masks (:mod:`csmlab.kernels.alpha`):
coordinates repeat (``u − ⌊u⌋``), column ``⌊u·W⌋``, row ``⌊v·H⌋`` (row 0 at v = 0); a glTF
sampler's wrap modes and filters are not read (``CLAMP_TO_EDGE`` and ``MIRRORED_REPEAT`` repeat too). The texel is
decoded from 8-bit sRGB to linear RGB (IEC 61966-2-1, a 256-entry table) before it multiplies the
factor, so the shading is linear as an engine's sRGB texture fetch makes it. Engines filter
bilinearly from a mip chain; nearest texels without mips alias where a texture is minified (far
ground) — the same in the shadow image and the reference shading, so it is no difference between
methods (docs/design.md, "Metrics").
"""

from __future__ import annotations

import colour
import numpy as np
import warp as wp

__all__ = ["srgb_decoding_table", "textured_albedo"]

# Products and sums rounded one by one on both devices (clang and NVRTC may otherwise contract them).
wp.set_module_options({"fuse_fp": False})


def srgb_decoding_table() -> np.ndarray:
    """Linear value ``(256,)`` float32 of each 8-bit sRGB code (the sRGB EOTF of ``code / 255``)."""
    return np.asarray(colour.cctf_decoding(np.arange(256) / 255.0, function="sRGB"), dtype=np.float32)


@wp.func
def hit_weights(a: wp.vec3d, b: wp.vec3d, c: wp.vec3d, p: wp.vec3d) -> wp.vec3d:
    """Barycentric weights of ``p`` (on the triangle's plane) for the corners ``a``, ``b``, ``c``."""
    e0 = b - a
    e1 = c - a
    e2 = p - a
    d00 = wp.dot(e0, e0)
    d01 = wp.dot(e0, e1)
    d11 = wp.dot(e1, e1)
    d20 = wp.dot(e2, e0)
    d21 = wp.dot(e2, e1)
    det = d00 * d11 - d01 * d01
    wb = (d11 * d20 - d01 * d21) / det
    wc = (d00 * d21 - d01 * d20) / det
    return wp.vec3d(wp.float64(1.0) - wb - wc, wb, wc)


@wp.kernel
def textured_albedo_kernel(
    triangle: wp.array(dtype=wp.int32),
    position: wp.array(dtype=wp.vec3d),
    vertices: wp.array(dtype=wp.vec3d),
    triangles: wp.array(dtype=wp.int32, ndim=2),
    uv: wp.array(dtype=wp.vec2d),
    vertex_texture: wp.array(dtype=wp.int32),
    factor: wp.array(dtype=wp.vec3f),
    texels: wp.array(dtype=wp.uint8),
    offset: wp.array(dtype=wp.int64),
    width: wp.array(dtype=wp.int32),
    height: wp.array(dtype=wp.int32),
    decode: wp.array(dtype=wp.float32),
    albedo: wp.array(dtype=wp.vec3f),
):
    k = wp.tid()
    t = triangle[k]
    if t < 0:
        albedo[k] = wp.vec3f(0.0, 0.0, 0.0)
        return
    i0 = triangles[t, 0]
    m = vertex_texture[i0]
    if m < 0:
        albedo[k] = factor[t]
        return
    i1 = triangles[t, 1]
    i2 = triangles[t, 2]
    w = hit_weights(vertices[i0], vertices[i1], vertices[i2], position[k])
    st = uv[i0] * w[0] + uv[i1] * w[1] + uv[i2] * w[2]
    cols = width[m]
    rows = height[m]
    col = wp.min(int((st[0] - wp.floor(st[0])) * wp.float64(cols)), cols - 1)
    row = wp.min(int((st[1] - wp.floor(st[1])) * wp.float64(rows)), rows - 1)
    at = offset[m] + (wp.int64(row) * wp.int64(cols) + wp.int64(col)) * wp.int64(3)
    f = factor[t]
    albedo[k] = wp.vec3f(f[0] * decode[int(texels[at])], f[1] * decode[int(texels[at + wp.int64(1)])],
                         f[2] * decode[int(texels[at + wp.int64(2)])])


def textured_albedo(scene, triangle, position, *, device: str = "cpu") -> np.ndarray:
    """Linear RGB albedo ``(H, W, 3)`` float32 of each camera hit of a scene with colour textures.

    Parameters
    ----------
    scene : csmlab.scene.core.Scene
        Its ``albedo`` (per triangle) and ``colour`` (:class:`~csmlab.scene.core.ColourTextures`,
        not None).
    triangle : ndarray, shape (H, W), int32
        Hit triangle of each pixel, −1 on a miss.
    position : ndarray, shape (H, W, 3), float64
        World position of each hit, metres (any value on a miss).
    device : str
        Warp device.

    Returns
    -------
    ndarray, shape (H, W, 3), float32
        ``albedo[triangle] × decoded texel`` where the triangle is textured, ``albedo[triangle]``
        where it is not, 0 on a miss.

    Raises
    ------
    ValueError
        On a scene without colour textures, or mismatched or mistyped ``triangle`` and ``position``.
    """
    if scene.colour is None:
        raise ValueError(f"{scene.name}: colour: expected a scene with colour textures")
    triangle = np.asarray(triangle)
    position = np.asarray(position)
    if triangle.dtype != np.int32 or triangle.ndim != 2:
        raise ValueError(f"triangle: expected an (H, W) int32 array, got {triangle.dtype} {triangle.shape}")
    if position.dtype != np.float64 or position.shape != triangle.shape + (3,):
        raise ValueError(f"position: expected a {triangle.shape + (3,)} float64 array, got "
                         f"{position.dtype} {position.shape}")
    if triangle.size and int(triangle.max()) >= scene.triangle_count:
        raise ValueError(f"triangle: expected indices below {scene.triangle_count}, got {int(triangle.max())}")
    colour_textures = scene.colour
    images = [t.srgb for t in colour_textures.textures]
    sizes = np.array([image.size for image in images], dtype=np.int64)
    texels = np.concatenate([image.reshape(-1) for image in images]) if images else np.zeros(1, np.uint8)
    count = triangle.size
    out = wp.zeros(count, dtype=wp.vec3f, device=device)
    wp.launch(textured_albedo_kernel, dim=count, inputs=[
        wp.array(triangle.reshape(-1), dtype=wp.int32, device=device),
        wp.array(np.ascontiguousarray(position.reshape(-1, 3)), dtype=wp.vec3d, device=device),
        wp.array(scene.vertices, dtype=wp.vec3d, device=device),
        wp.array(scene.triangles, dtype=wp.int32, device=device),
        wp.array(colour_textures.uv, dtype=wp.vec2d, device=device),
        wp.array(colour_textures.vertex_texture, dtype=wp.int32, device=device),
        wp.array(scene.albedo, dtype=wp.vec3f, device=device),
        wp.array(texels, dtype=wp.uint8, device=device),
        wp.array(np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64) if images else np.zeros(1, np.int64),
                 dtype=wp.int64, device=device),
        wp.array(np.array([image.shape[1] for image in images] or [1], np.int32), dtype=wp.int32, device=device),
        wp.array(np.array([image.shape[0] for image in images] or [1], np.int32), dtype=wp.int32, device=device),
        wp.array(srgb_decoding_table(), dtype=wp.float32, device=device),
    ], outputs=[out], device=device)
    return out.numpy().reshape(triangle.shape + (3,))
