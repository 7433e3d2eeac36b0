"""csmlab's sRGB encoding (csmlab.srgb) against colour-science's, the library it follows."""

import colour
import numpy as np

from csmlab.srgb import srgb_encoded


def test_srgb_encoding_is_colour_sciences_bit_for_bit():
    # The breakpoint's neighbours, the ends, subnormals, values outside [0, 1] and non-finite ones
    # (clipped or kept NaN alike), and a dense random sweep of the display range.
    rng = np.random.default_rng(7)
    edges = np.array([0.0, -0.0, 5e-324, 1e-310, 0.0031308, 1.0, 1.5, -0.25, np.inf, -np.inf, np.nan])
    around = np.nextafter(0.0031308, np.array([0.0, 1.0]))
    values = np.concatenate([edges, around, rng.random(2_000_000), rng.random(200_000) * 0.004,
                             rng.random(10_000).astype(np.float32)])
    expected = np.asarray(colour.cctf_encoding(np.clip(values, 0.0, 1.0), function="sRGB"))
    encoded = srgb_encoded(values)
    assert encoded.dtype == np.float64
    np.testing.assert_array_equal(encoded.view(np.uint64), expected.view(np.uint64))


def test_srgb_encoding_keeps_the_images_shape():
    rgb = np.linspace(0.0, 1.0, 2 * 5 * 3).reshape(2, 5, 3)
    assert srgb_encoded(rgb).shape == (2, 5, 3)
    assert srgb_encoded(0.5).shape == ()
