"""The receiver bias as the receiver conversions read it: one record per lookup, per-cascade values as arrays.

:func:`receiver_bias` turns a :class:`BiasSettings` (``[shadow]``'s bias fields: normal offset in
texels and metres, its scale mode, constant and slope bias, the receiver-plane offset cap) and the
cascades' texel sizes into a :class:`ReceiverBias`, which :class:`csmlab.kernels.shadow.WorldReceivers` and
:class:`csmlab.kernels.engine.EngineReceivers` carry to the kernels that move and bias a receiver
(:func:`csmlab.kernels.shadow.receiver_in`, the window-space and warped receiver kernels).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from csmlab.lookup_choices import NORMAL_OFFSET_SCALES
from csmlab.registry import check_name


@wp.struct
class ReceiverBias:
    """What moves a receiver along its normal and lowers its depth, per cascade ``c``.

    ``offset[c]`` is the normal offset in metres (``normal_offset · texel + normal_offset_m``),
    ``bias_constant[c]`` the constant bias in metres, ``slope_bias[c]`` ``bias_slope · texel``,
    ``plane_offset[c]`` the cap in metres of the static receiver-plane offset (0: none);
    ``bias_slope`` is the slope bias in texels, ``max_tan`` the cap of the normal's tangent and
    ``normal_scale`` a :data:`csmlab.lookup_choices.NORMAL_OFFSET_SCALES` code.
    """

    offset: wp.array(dtype=wp.float64)
    slope_bias: wp.array(dtype=wp.float64)
    bias_slope: wp.float64
    bias_constant: wp.array(dtype=wp.float64)
    plane_offset: wp.array(dtype=wp.float64)
    max_tan: wp.float64
    normal_scale: int


@dataclass(frozen=True)
class BiasSettings:
    """The receiver bias of one lookup, as the host wrappers take it (docs/design.md ``[shadow]``).

    ``normal_offset`` and ``bias_slope`` are in texels, ``bias_constant`` in metres (one value per
    cascade ``(C,)`` with a bias model's scaling, csmlab.filters), ``normal_scale`` a
    :data:`csmlab.lookup_choices.NORMAL_OFFSET_SCALES` name, ``plane_offset`` the cap in metres of
    the static receiver-plane offset (scalar or ``(C,)``; 0: none), ``normal_offset_m`` a world
    normal offset in metres, the same in every cascade (Stride).
    """

    normal_offset: float
    bias_constant: float | np.ndarray
    bias_slope: float
    normal_scale: str = "none"
    plane_offset: float | np.ndarray = 0.0
    normal_offset_m: float = 0.0


def receiver_bias(texel, settings: BiasSettings, *, device: str) -> ReceiverBias:
    """The :class:`ReceiverBias` of ``settings`` for cascades of ``texel`` metres.

    Parameters
    ----------
    texel : ndarray, shape (C,), float64
        Each cascade's larger texel side, metres.
    settings : BiasSettings
    device : str
    """
    count = texel.shape
    offset = settings.normal_offset * texel
    if settings.normal_offset_m != 0.0:
        offset = offset + settings.normal_offset_m  # a world distance, the same in every cascade (Stride)
    bias = ReceiverBias()
    bias.offset = wp.array(offset, dtype=wp.float64, device=device)
    bias.slope_bias = wp.array(settings.bias_slope * texel, dtype=wp.float64, device=device)
    bias.bias_slope = float(settings.bias_slope)
    bias.bias_constant = wp.array(np.broadcast_to(np.asarray(settings.bias_constant, dtype=np.float64), count).copy(),
                                  dtype=wp.float64, device=device)
    bias.plane_offset = wp.array(np.broadcast_to(np.asarray(settings.plane_offset, dtype=np.float64), count).copy(),
                                 dtype=wp.float64, device=device)
    bias.max_tan = 10.0
    bias.normal_scale = NORMAL_OFFSET_SCALES[check_name(settings.normal_scale, NORMAL_OFFSET_SCALES,
                                                        field="normal_offset_scale")]
    return bias
