"""Animations that let flicker be seen: the shadow image beside its per-pixel change |ΔS|, as a GIF.

One GIF per method × sweep point, played at the run's frame rate. Left: the lit fraction S in
grey (black shadowed, white lit). Right: |ΔS| since the previous frame in viridis on a
square-root scale, as in the image strips (dark: still, yellow: a full flip). Pale blue: no
value (no surface; or frame 0, which has no predecessor).

The palette is fixed for every frame and every GIF (128 greys, 127 viridis steps, one "no
value" colour) and frames are written as palette indices: an encoder that quantized each frame
on its own would pick a slightly different palette per frame and add flicker of its own to an
animation made to show flicker. Pillow (the GIF writer under imageio) is called directly for that.
"""

from __future__ import annotations

import numpy as np
from PIL import Image

from csmlab.report.images import CHANGE_CMAP, NO_SURFACE, change_norm

__all__ = ["ANIMATION_PALETTE", "animation_indices", "write_animation"]

_GREYS = 128
_CHANGES = 127
_NO_VALUE_INDEX = 255
_GAP = 4
ANIMATION_PALETTE = np.rint(np.concatenate([
    np.repeat(np.linspace(0.0, 1.0, _GREYS)[:, None], 3, axis=1),
    CHANGE_CMAP(np.linspace(0.0, 1.0, _CHANGES))[:, :3],
    NO_SURFACE[None],
]) * 255).astype(np.uint8)
"""``(256, 3)`` uint8 sRGB: greys 0–127, viridis 128–254, "no value" 255."""


def animation_indices(shadow: np.ndarray, dS: np.ndarray) -> np.ndarray:
    """Palette indices ``(N, h, 2w + 4)`` uint8 of the side-by-side frames.

    Parameters
    ----------
    shadow, dS : ndarray, shape (N, h, w), uint8
        Coded as in :mod:`csmlab.report.capture`: ``round(254 · v)``, 255 for no value.
    """
    shadow = np.asarray(shadow, dtype=np.uint8)
    dS = np.asarray(dS, dtype=np.uint8)
    frames = np.full(shadow.shape[:2] + (2 * shadow.shape[2] + _GAP,), _NO_VALUE_INDEX, dtype=np.uint8)
    # A code has 256 values: look each pixel's index up in a table of them rather than colour-map every pixel.
    frames[..., :shadow.shape[2]] = _GREY_INDEX[shadow]
    frames[..., shadow.shape[2] + _GAP:] = _CHANGE_INDEX[dS]
    return frames


def _index_tables() -> tuple[np.ndarray, np.ndarray]:
    """Palette index ``(256,)`` uint8 of each shadow code and of each |ΔS| code (255: no value)."""
    codes = np.arange(256)
    grey = np.where(codes == 255, _NO_VALUE_INDEX, np.rint(codes * ((_GREYS - 1) / 254.0)))
    scaled = np.asarray(change_norm()(codes / 254.0))
    change = np.where(codes == 255, _NO_VALUE_INDEX, _GREYS + np.rint(scaled * (_CHANGES - 1)))
    return grey.astype(np.uint8), change.astype(np.uint8)


_GREY_INDEX, _CHANGE_INDEX = _index_tables()


def write_animation(path, *, shadow: np.ndarray, dS: np.ndarray, fps: float) -> None:
    """Write a looping GIF of the shadow image and its |ΔS|, side by side.

    Parameters
    ----------
    path : str or Path
        The ``.gif`` to write.
    shadow, dS : ndarray, shape (N, h, w), uint8
        Coded frames (see :func:`animation_indices`).
    fps : float
        Frames per second of the run; GIF stores delays in 10 ms steps, at least 20 ms.
    """
    if not np.isfinite(fps) or fps <= 0:
        raise ValueError(f"fps: expected a positive frame rate, got {fps}")
    palette = ANIMATION_PALETTE.ravel().tobytes()
    images = []
    for indices in animation_indices(shadow, dS):
        image = Image.fromarray(indices, mode="P")
        image.putpalette(palette)
        images.append(image)
    delay = max(20, int(round(100.0 / fps)) * 10)
    images[0].save(path, save_all=True, append_images=images[1:], duration=delay, loop=0, optimize=False)
