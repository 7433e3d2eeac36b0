"""Alpha masks read from image files: the alpha channel an OBJ material's ``map_d`` or a glTF texture holds.

:func:`read_alpha_mask` opens an image with Pillow and keeps its coverage: the alpha channel of an
image that has one (RGBA, LA, a palette with transparency), else its luminance (a grey ``map_d``
mask), as values in [0, 1] with row 0 the image's top row (texture coordinate v = 0, glTF's
convention). A file that is missing or that Pillow cannot read is bad input: an
:class:`~csmlab.errors.InputError` naming the file and the field it came from; so is an image whose
header claims more than :data:`~csmlab.documents.MAX_IMAGE_TEXELS` texels, refused before its
texels are decoded (and Pillow's own decompression-bomb check, should it trip first).
:func:`colour_texture_of_image` reads a base-colour texture (glTF ``baseColorTexture``) the same
way, keeping its 8-bit sRGB-encoded RGB.
"""

from __future__ import annotations

from io import BytesIO
from pathlib import Path

import numpy as np

from csmlab.documents import MAX_IMAGE_TEXELS, found_at, is_file, within_limit
from csmlab.errors import InputError
from csmlab.scene.core import AlphaMask, ColourTexture

__all__ = ["alpha_mask_of_image", "colour_texture_of_image", "read_alpha_mask", "read_colour_texture"]


def read_alpha_mask(file, *, cutoff: float = 0.5, field: str = "alpha_mask") -> AlphaMask:
    """The :class:`~csmlab.scene.core.AlphaMask` of an image file's alpha channel (or luminance) and ``cutoff``.

    Parameters
    ----------
    file : str or os.PathLike
        An image Pillow reads (PNG, TGA, …).
    cutoff : float
        Opaque where coverage ≥ cutoff (glTF ``alphaCutoff``; 0.5 by default), in (0, 1].
    field : str
        The configuration field that named the file, for the error.

    Raises
    ------
    InputError
        Naming the file and ``field``: missing, not an image Pillow can read, or empty.
    """
    path = Path(file)
    return alpha_mask_of_image(_image_bytes(path, field, "an alpha mask"), cutoff=cutoff, source=path, field=field)


def read_colour_texture(file, *, field: str = "map_Kd") -> ColourTexture:
    """The :class:`~csmlab.scene.core.ColourTexture` of an image file (an OBJ material's ``map_Kd``).

    Raises
    ------
    InputError
        Naming the file and ``field``: missing, not an image Pillow can read, or empty.
    """
    return colour_texture_of_image(_image_bytes(Path(file), field, "a colour texture"), source=file, field=field)


def _image_bytes(path: Path, field: str, what: str) -> bytes:
    """The bytes of an image file, or an :class:`~csmlab.errors.InputError` naming it and ``field``."""
    if not is_file(path):
        raise InputError(f"expected an existing image file with {what}, found {found_at(path)}", file=path,
                         field=field)
    try:
        return path.read_bytes()
    except OSError as exc:
        raise InputError(f"expected a readable image file, got {exc.strerror or exc}", file=path,
                         field=field) from None


def alpha_mask_of_image(data: bytes, *, cutoff: float = 0.5, source, field: str = "alpha_mask") -> AlphaMask:
    """The :class:`~csmlab.scene.core.AlphaMask` of an encoded image's bytes (as :func:`read_alpha_mask` reads a file).

    ``source`` names the image (its file, or the file that embeds it) in the mask and in the error.
    """
    path = Path(source)
    coverage = _decoded(data, path, field, "an alpha mask", _coverage).astype(np.float32)
    return AlphaMask(coverage / 255.0, cutoff, source=str(path))


def colour_texture_of_image(data: bytes, *, source, field: str = "baseColorTexture") -> ColourTexture:
    """The :class:`~csmlab.scene.core.ColourTexture` (8-bit sRGB RGB, alpha dropped) of an encoded image's bytes.

    ``source`` names the image in the texture and in the error; limits and errors as
    :func:`alpha_mask_of_image`.
    """
    path = Path(source)
    rgb = _decoded(data, path, field, "a colour texture", lambda image: np.asarray(image.convert("RGB"), np.uint8))
    return ColourTexture(rgb, source=str(path))


def _coverage(image) -> np.ndarray:
    """Alpha of an image that has it, else its luminance, 8-bit ``(H, W)``."""
    if "A" in image.getbands() or "transparency" in image.info:
        return np.asarray(image.convert("RGBA"))[..., 3]
    return np.asarray(image.convert("L"))


def _decoded(data: bytes, path: Path, field: str, what: str, texels) -> np.ndarray:
    """``texels(image)`` of the encoded image ``data`` once its claimed size is within the limit."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(BytesIO(data)) as image:
            width, height = image.size
            within_limit(width * height, MAX_IMAGE_TEXELS, what=f"texels (the image claims {width} × {height})",
                         file=path, field=field)
            image.load()
            values = texels(image)
    except InputError:
        raise
    except Image.DecompressionBombError as exc:  # Pillow refuses the header before we see its size
        raise InputError(f"expected at most {MAX_IMAGE_TEXELS:,} texels (docs/design.md, \"Inputs\"); Pillow: {exc}",
                         file=path, field=field) from None
    except (OSError, EOFError, SyntaxError, UnidentifiedImageError, ValueError) as exc:
        raise InputError(f"expected an image file with {what} (PNG, TGA, …) that Pillow can read; "
                         f"reading failed: {exc}", file=path, field=field) from None
    if values.size == 0:
        raise InputError("expected an image of at least one texel", file=path, field=field)
    return values
