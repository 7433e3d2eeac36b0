"""The receiver bias record holds each cascade's bias in metres from the fields in texels and metres."""

from __future__ import annotations

import numpy as np
import pytest

from csmlab.kernels.bias import BiasSettings, receiver_bias
from csmlab.lookup_choices import NORMAL_OFFSET_SCALES


def test_receiver_bias_scales_texel_fields_by_each_cascade_texel():
    texel = np.array([0.25, 0.5, 2.0])
    settings = BiasSettings(normal_offset=1.5, bias_constant=0.01, bias_slope=2.0, normal_scale="sin",
                            plane_offset=np.array([0.0, 0.1, 0.2]), normal_offset_m=0.125)
    bias = receiver_bias(texel, settings, device="cpu")
    # 1.5 texels + 0.125 m, 2 texels of slope: exact in binary, so the expected values are exact.
    np.testing.assert_array_equal(bias.offset.numpy(), [0.5, 0.875, 3.125])
    np.testing.assert_array_equal(bias.slope_bias.numpy(), [0.5, 1.0, 4.0])
    np.testing.assert_array_equal(bias.bias_constant.numpy(), [0.01, 0.01, 0.01])
    np.testing.assert_array_equal(bias.plane_offset.numpy(), [0.0, 0.1, 0.2])
    assert bias.bias_slope == 2.0 and bias.max_tan == 10.0
    assert bias.normal_scale == NORMAL_OFFSET_SCALES["sin"]


def test_receiver_bias_keeps_a_per_cascade_constant_bias():
    settings = BiasSettings(normal_offset=0.0, bias_constant=np.array([0.5, 0.75]), bias_slope=0.0)
    bias = receiver_bias(np.array([1.0, 2.0]), settings, device="cpu")
    np.testing.assert_array_equal(bias.bias_constant.numpy(), [0.5, 0.75])
    np.testing.assert_array_equal(bias.offset.numpy(), [0.0, 0.0])


def test_receiver_bias_refuses_an_unknown_normal_offset_scale():
    with pytest.raises(ValueError, match="normal_offset_scale"):
        receiver_bias(np.array([1.0]), BiasSettings(normal_offset=0.0, bias_constant=0.0, bias_slope=0.0,
                                                    normal_scale="cosine"), device="cpu")
