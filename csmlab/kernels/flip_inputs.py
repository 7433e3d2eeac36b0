"""ꟻLIP's inputs on the host: where a filled image pair differs, the colours to encode, the encoded pair.

:func:`csmlab.metrics.perceptual.flip_map` hands ꟻLIP (:mod:`csmlab.kernels.flip`) two sRGB images,
encoded from the linear shadings only where ꟻLIP reads them. The pair is *filled* first (every
pixel not compared is the test's there, with NaN as 0 and ±inf as ±the largest float:
``np.nan_to_num``), so the images differ only at compared pixels whose colours differ. These
kernels do, each in one pass over the pixels in one thread, what took a dozen whole-image NumPy
passes (~4 ms of a ``none`` frame):

1. :func:`filled_differences` — where the filled pair differs;
2. :func:`colours_read` — the test's filled colours at the pixels ꟻLIP reads (its reach, in
   row-major order) and the reference's at the pixels that differ, each a compact ``(N, 3)`` array
   that NumPy encodes (:func:`csmlab.srgb.srgb_encoded`, whose ``pow`` is NumPy's);
3. :func:`encoded_pair` — those encoded colours placed back, rounded to float32, 0 elsewhere.

The values are those of the NumPy passes bit for bit (a comparison, ``nan_to_num`` and a cast are
exact). The arrays are NumPy's on the host whatever the run's device: the kernels run on the CPU.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from csmlab.kernels import host_array

__all__ = ["colours_read", "encoded_pair", "filled_differences"]

LARGEST = float(np.finfo(np.float64).max)
"""The largest float64, an argument of the kernels rather than a Warp constant, which the C++ would hold as NumPy
prints it (12 digits once colour-science's import has set NumPy's legacy printing)."""


@wp.func
def filled(x: wp.float64, largest: wp.float64) -> wp.float64:
    """``np.nan_to_num`` of one value: NaN → 0, ±inf → ± the largest float64, others as they are."""
    if x != x:
        return wp.float64(0.0)
    return wp.clamp(x, -largest, largest)


@wp.func
def filled_colour(c: wp.vec3d, fill: int, largest: wp.float64) -> wp.vec3d:
    if fill == 0:
        return c
    return wp.vec3d(filled(c[0], largest), filled(c[1], largest), filled(c[2], largest))


@wp.kernel
def differences_kernel(reference: wp.array(dtype=wp.vec3d), test: wp.array(dtype=wp.vec3d),
                       compared: wp.array(dtype=wp.bool), fill: int, largest: wp.float64,
                       differs: wp.array(dtype=wp.bool)):
    p = int(0)
    while p < differs.shape[0]:
        d = False
        if fill == 0 or compared[p]:
            a = reference[p]
            b = filled_colour(test[p], fill, largest)
            # NaN differs from everything, itself included, as NumPy's != says.
            d = a[0] != b[0] or a[1] != b[1] or a[2] != b[2]
        differs[p] = d
        p += 1


@wp.kernel
def colours_read_kernel(reference: wp.array(dtype=wp.vec3d), test: wp.array(dtype=wp.vec3d),
                        reach: wp.array(dtype=wp.uint8), differs: wp.array(dtype=wp.bool), fill: int,
                        largest: wp.float64, test_read: wp.array(dtype=wp.vec3d),
                        reference_read: wp.array(dtype=wp.vec3d)):
    k = int(0)
    m = int(0)
    p = int(0)
    while p < reach.shape[0]:
        if reach[p] != wp.uint8(0):
            test_read[k] = filled_colour(test[p], fill, largest)
            k += 1
        if differs[p]:
            # A pixel that differs is compared: its filled reference is the reference itself.
            reference_read[m] = reference[p]
            m += 1
        p += 1


@wp.kernel
def encoded_pair_kernel(reach: wp.array(dtype=wp.uint8), differs: wp.array(dtype=wp.bool),
                        test_encoded: wp.array(dtype=wp.vec3d), reference_encoded: wp.array(dtype=wp.vec3d),
                        reference_out: wp.array(dtype=wp.vec3), test_out: wp.array(dtype=wp.vec3)):
    k = int(0)
    m = int(0)
    p = int(0)
    while p < reach.shape[0]:
        value = wp.vec3(0.0, 0.0, 0.0)
        other = value
        if reach[p] != wp.uint8(0):
            value = wp.vec3(test_encoded[k])
            other = value
            k += 1
        if differs[p]:
            other = wp.vec3(reference_encoded[m])
            m += 1
        test_out[p] = value
        reference_out[p] = other
        p += 1


def _colours(name: str, image) -> np.ndarray:
    array = np.asarray(image)
    if array.ndim != 3 or array.shape[2] != 3 or array.dtype != np.float64 or not array.flags.c_contiguous:
        raise ValueError(f"{name}: expected a C-contiguous float64 (H, W, 3) image, got {array.dtype} {array.shape}")
    return array


def _flat(array: np.ndarray, dtype) -> wp.array:
    """An image's or a list's pixels in order, as a 1-D Warp array on the host (a vector ``dtype`` takes the last
    axis: ``(H, W, 3)`` or ``(N, 3)`` as vectors)."""
    return host_array(array.reshape(-1, dtype._length_) if wp.types.type_is_vector(dtype) else array.reshape(-1),
                      dtype)


def filled_differences(reference, test, compared=None) -> np.ndarray:
    """``(H, W)`` bool: where the filled pair of two linear images ``(H, W, 3)`` float64 differs in any channel.

    With ``compared`` (bool ``(H, W)``): compared pixels whose reference differs from the test's
    ``nan_to_num``; without, every pixel whose two colours differ (NaN differs from itself).
    """
    reference, test = _colours("reference", reference), _colours("test", test)
    shape = reference.shape[:2]
    if test.shape != reference.shape:
        raise ValueError(f"test: expected the reference's shape {reference.shape}, got {test.shape}")
    mask = np.zeros(0, dtype=bool) if compared is None else np.ascontiguousarray(compared, dtype=bool)
    if compared is not None and mask.shape != shape:
        raise ValueError(f"compared: expected the images' shape {shape}, got {mask.shape}")
    differs = np.empty(shape, dtype=bool)
    wp.launch(differences_kernel, dim=1,
              inputs=(_flat(reference, wp.vec3d), _flat(test, wp.vec3d), _flat(mask, wp.bool),
                      int(compared is not None), wp.float64(LARGEST)),
              outputs=(_flat(differs, wp.bool),), device="cpu")
    return differs


def colours_read(reference, test, reach, differs, *, fill: bool) -> tuple[np.ndarray, np.ndarray]:
    """The colours ꟻLIP's encoding needs: ``(R, 3)`` the test's at the ``R`` pixels of ``reach`` (uint8
    ``(H, W)``, nonzero where read) and ``(D, 3)`` the reference's at the ``D`` pixels that ``differs``
    (bool ``(H, W)``), float64, each in row-major order; the test's ``nan_to_num``'d with ``fill``."""
    reference, test = _colours("reference", reference), _colours("test", test)
    reach = np.ascontiguousarray(reach, dtype=np.uint8)
    differs = np.ascontiguousarray(differs, dtype=bool)
    if reach.shape != reference.shape[:2] or differs.shape != reach.shape:
        raise ValueError(f"reach, differs: expected the images' shape {reference.shape[:2]}, got {reach.shape} and "
                         f"{differs.shape}")
    test_read = np.empty((np.count_nonzero(reach), 3), dtype=np.float64)
    reference_read = np.empty((np.count_nonzero(differs), 3), dtype=np.float64)
    wp.launch(colours_read_kernel, dim=1,
              inputs=(_flat(reference, wp.vec3d), _flat(test, wp.vec3d), _flat(reach, wp.uint8),
                      _flat(differs, wp.bool), int(fill), wp.float64(LARGEST)),
              outputs=(_flat(test_read, wp.vec3d), _flat(reference_read, wp.vec3d)), device="cpu")
    return test_read, reference_read


def encoded_pair(reach, differs, test_encoded, reference_encoded) -> tuple[np.ndarray, np.ndarray]:
    """The encoded pair ``(H, W, 3)`` float32 each (reference, test): the test's encoded colours
    ``(R, 3)`` at the reach's pixels in both, then the reference's ``(D, 3)`` in the reference where
    the pixels differ, each rounded to float32; 0 elsewhere (arguments as :func:`colours_read`'s)."""
    reach = np.ascontiguousarray(reach, dtype=np.uint8)
    differs = np.ascontiguousarray(differs, dtype=bool)
    test_encoded = np.ascontiguousarray(test_encoded, dtype=np.float64)
    reference_encoded = np.ascontiguousarray(reference_encoded, dtype=np.float64)
    if (test_encoded.shape != (np.count_nonzero(reach), 3) or differs.shape != reach.shape
            or reference_encoded.shape != (np.count_nonzero(differs), 3)):
        raise ValueError(f"test_encoded, reference_encoded: expected a colour per pixel of the reach and per pixel "
                         f"that differs within it, got {test_encoded.shape} and {reference_encoded.shape}")
    pair = np.empty((2,) + reach.shape + (3,), dtype=np.float32)
    wp.launch(encoded_pair_kernel, dim=1,
              inputs=(_flat(reach, wp.uint8), _flat(differs, wp.bool), _flat(test_encoded, wp.vec3d),
                      _flat(reference_encoded, wp.vec3d)),
              outputs=(_flat(pair[0], wp.vec3), _flat(pair[1], wp.vec3)), device="cpu")
    return pair[0], pair[1]
