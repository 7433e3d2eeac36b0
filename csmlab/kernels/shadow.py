"""Shadow lookup: cascade selection, receiver depth test, filtering, blend band (CSM model step 6).

Receivers arrive either converted — int64 fixed-point coordinates in ``2**-bits`` texels of each
cascade (already moved along their normal), a biased float32 depth and a receiver-plane slope per
cascade (:func:`csmlab.texels.receiver_lookup`, :func:`receiver_coordinates`) — or as world points
and normals (:func:`shadow_lookup_world`) that the lookup converts itself, with the same functions
(:func:`receiver_light` once, :func:`receiver_in` per cascade), into the cascades it reads only.
Filter taps come from the integer texel index and the fixed-point remainder — exactly
representable — never from float texel centres, so a box moved by whole texels gives
bit-identical results at fixed receivers.

Selection methods (:data:`csmlab.lookup_choices.SELECTION_METHODS`):

- ``interval`` — cascade i for view depth in ``[z_i, z_{i+1})`` of the splits.
- ``map`` — the first cascade whose box, less ``margin`` texels on each side, contains the point.
- ``best_resolution`` — among those containing cascades, the one with the smallest texel area
  (Zhang et al., seed 003, "optimized cascade selection"); the first on ties.
- ``sphere`` — the first cascade whose split sphere holds the world point, ``|X − c_i|² < r_i²``
  (Unity: built-in ``getCascadeWeights_splitSpheres``, URP ``ComputeCascadeIndex``), found per
  receiver by :func:`split_sphere_cascades` and handed to the lookup as ``sphere_cascade``.

Every selection also requires the selected box to hold all of the filter's taps, so clamping never
changes a tap (the box filters' :func:`box_count` reads them unclamped); a point that no cascade
holds gets cascade −1 (S is NaN there).

The box filters (the ``box`` family of :data:`csmlab.lookup_choices.FILTER_METHODS`), S = lit
fraction in [0, 1], run here with the selection; :func:`select_cascades` makes the same selection
for the filters that run after it (:mod:`csmlab.kernels.pcf`, :mod:`csmlab.kernels.moments`):

- ``none`` — the one texel that contains the point.
- ``pcf`` — the N×N texels centred on it (N = ``filter_size``, odd), equal weights.
- ``pcf_bilinear`` — the 2×2 texels around it, weighted by the fixed-point fraction of its
  position between their centres (hardware bilinear percentage-closer filtering).

Blend band: within the last ``blend_band`` fraction of the selected cascade's split interval, S
moves linearly toward cascade i + 1's S (when i + 1 holds the point's taps), reaching it at ``z_{i+1}``.
``band_start`` (one start per cascade, metres) places the bands elsewhere, the band of cascade i
ending where the selection's ``splits`` leave it (:func:`csmlab.cascades.fit.transition_bands`),
and ``blend_curve`` (:data:`csmlab.lookup_choices.BLEND_SMOOTHSTEP`) shapes the weight.

References
----------
- Reeves, Salesin, Cook, "Rendering Antialiased Shadows with Depth Maps", SIGGRAPH 1987 — PCF.
- Zhang, Zaprjagaev, Bentham, "Practical Cascaded Shadow Maps", ShaderX7 (seed 003).
"""

from __future__ import annotations

from string import Template
from typing import Any

import numpy as np
import warp as wp

from csmlab.kernels import checked_device
from csmlab.kernels.bias import BiasSettings, ReceiverBias, receiver_bias
from csmlab.kernels.engine import (WINDOW_FLOAT32, EngineBoxes, EngineReceivers, WindowPoint, engine_receivers,
                                   window_in, window_point)
from csmlab.kernels.floats import is_nan
from csmlab.lookup_choices import (BLEND_SMOOTHSTEP, BOX_BILINEAR, NORMAL_NONE,
                                   NORMAL_ONE_MINUS_COS_LATERAL, NORMAL_SIN, SELECT_BEST_RESOLUTION, SELECT_INTERVAL,
                                   SELECT_MAP, SELECT_SPHERE, SELECTION_METHODS, family_code)
from csmlab.registry import check_name

__all__ = ["receiver_coordinates", "select_cascades", "select_window_cascades", "select_world_cascades",
           "shadow_lookup", "shadow_lookup_window", "shadow_lookup_world", "split_sphere_cascades", "world_receivers"]

wp.set_module_options({"fuse_fp": False})


@wp.func
def tap(depth: wp.array3d(dtype=wp.float32), c: int, i: wp.int64, j: wp.int64, receiver: wp.float32,
        slope: wp.vec2d, x: wp.int64, y: wp.int64, unit: wp.int64, inverse_span: wp.float64) -> int:
    """1 where the receiver plane is not behind the caster stored at texel (i, j), else 0 (also for a NaN receiver).

    The receiver's depth is carried along its tangent plane (``slope``, metres per texel) from its
    own fixed-point position ``(x, y)`` to the texel's centre; both offsets are exact fractions of
    ``unit``, so the result does not depend on where the box lies. ``inverse_span`` is
    ``1 / (2·unit)``, a power of two, so multiplying by it is the exact division.
    """
    top = wp.int64(depth.shape[1] - 1)
    ii = int(wp.clamp(i, wp.int64(0), top))
    jj = int(wp.clamp(j, wp.int64(0), top))
    plane = receiver
    if slope[0] != wp.float64(0.0) or slope[1] != wp.float64(0.0):
        di = wp.float64((wp.int64(2) * i + wp.int64(1)) * unit - wp.int64(2) * x) * inverse_span
        dj = wp.float64((wp.int64(2) * j + wp.int64(1)) * unit - wp.int64(2) * y) * inverse_span
        plane = wp.float32(wp.float64(receiver) + slope[0] * di + slope[1] * dj)
    if plane <= depth[c, jj, ii]:
        return 1
    return 0


@wp.func
def bilinear_corner(x: wp.int64, unit: wp.int64):
    """The texel centre at or before fixed-point ``x`` (``unit`` per texel) on one axis, and the exact fraction
    of ``x`` between it and the next centre: the index and weight of a bilinear footprint."""
    # Texel centres sit at (2i + 1)·unit in doubled units, so the division is exact in integers.
    x2 = wp.int64(2) * x - unit
    span = wp.int64(2) * unit
    i0 = x2 // span
    return i0, wp.float64(x2 - i0 * span) / wp.float64(span)


@wp.func
def bilinear_corner_shifted(x: wp.int64, unit: wp.int64, bits: int, inverse_span: wp.float64):
    """:func:`bilinear_corner` of ``unit = 2**bits``, without a division: the same index and fraction.

    The floor division by ``2·unit`` is an arithmetic shift (which floors, as ``//`` does), and the
    remainder's product with ``inverse_span = 1 / (2·unit)``, a power of two, is its exact quotient.
    """
    x2 = wp.int64(2) * x - unit
    i0 = x2 >> wp.int64(bits + 1)
    return i0, wp.float64(x2 - i0 * (wp.int64(2) * unit)) * inverse_span


@wp.func
def bilinear_taps(depth: wp.array3d(dtype=wp.float32), c: int, i0: wp.int64, wx: wp.float64, j0: wp.int64,
                  wy: wp.float64, receiver: wp.float32, slope: wp.vec2d, x: wp.int64, y: wp.int64, unit: wp.int64,
                  inverse_span: wp.float64) -> wp.float64:
    """The 2×2 texels from (i0, j0), each a :func:`tap` of the receiver at ``(x, y)``, weighted bilinearly by the
    fractions ``wx, wy`` (:func:`bilinear_corner_shifted`): a bilinear-compare tap whose footprint is known."""
    one = wp.int64(1)
    s00 = wp.float64(tap(depth, c, i0, j0, receiver, slope, x, y, unit, inverse_span))
    s10 = wp.float64(tap(depth, c, i0 + one, j0, receiver, slope, x, y, unit, inverse_span))
    s01 = wp.float64(tap(depth, c, i0, j0 + one, receiver, slope, x, y, unit, inverse_span))
    s11 = wp.float64(tap(depth, c, i0 + one, j0 + one, receiver, slope, x, y, unit, inverse_span))
    w1 = wp.float64(1.0)
    return (w1 - wy) * ((w1 - wx) * s00 + wx * s10) + wy * ((w1 - wx) * s01 + wx * s11)


@wp.func
def bilinear_tap(depth: wp.array3d(dtype=wp.float32), c: int, qx: wp.int64, qy: wp.int64, receiver: wp.float32,
                 slope: wp.vec2d, x: wp.int64, y: wp.int64, unit: wp.int64, bits: int,
                 inverse_span: wp.float64) -> wp.float64:
    """One hardware bilinear-compare tap at fixed point ``(qx, qy)``: the 2×2 texels around it, each a :func:`tap`
    of the receiver at ``(x, y)``, weighted bilinearly by the exact fraction of ``(qx, qy)`` between their centres.

    What a comparison sampler with linear filtering returns (``SampleCmpLevelZero``,
    ``textureProj(sampler2DShadow)``, ``textureSampleCompareLevel``), at the fixed point's precision
    rather than the hardware's 8 sub-texel bits.
    """
    i0, wx = bilinear_corner_shifted(qx, unit, bits, inverse_span)
    j0, wy = bilinear_corner_shifted(qy, unit, bits, inverse_span)
    return bilinear_taps(depth, c, i0, wx, j0, wy, receiver, slope, x, y, unit, inverse_span)


@wp.func
def lit_fraction(depth: wp.array3d(dtype=wp.float32), c: int, x: wp.int64, y: wp.int64, receiver: wp.float32,
                 slope: wp.vec2d, bits: int, inverse_span: wp.float64, filter_code: int, radius: int) -> wp.float64:
    """S of a receiver at fixed point ``(x, y)`` in cascade c: bilinear (``BOX_BILINEAR``), else a box of ``radius``.

    ``bits`` sub-texel bits (``unit = 2**bits``), ``inverse_span`` ``1 / (2·unit)``, as in :func:`tap`.
    """
    unit = wp.int64(1) << wp.int64(bits)
    if filter_code == BOX_BILINEAR:
        return bilinear_tap(depth, c, x, y, receiver, slope, x, y, unit, bits, inverse_span)
    # BOX_TAPS: the (2r + 1)² texels centred on the one that contains the point (r = 0: none).
    count = int(0)
    if radius == 1:
        count = box_count_3x3(depth, c, x, y, receiver, slope, bits, inverse_span)
    else:
        count = box_count(depth, c, x, y, receiver, slope, bits, inverse_span, radius)
    return wp.float64(count) / wp.float64((2 * radius + 1) * (2 * radius + 1))


@wp.func
def box_count(depth: wp.array3d(dtype=wp.float32), c: int, x: wp.int64, y: wp.int64, receiver: wp.float32,
              slope: wp.vec2d, bits: int, inverse_span: wp.float64, radius: int) -> int:
    """How many of the (2r + 1)² texels centred on the one holding fixed point ``(x, y)`` pass :func:`tap`.

    The same comparisons as :func:`tap` at each texel, with what does not change from tap to tap
    done once: ``x // unit`` is a shift (``unit = 2**bits``), the texel centre's offset from the
    point steps by the exact integer ``2·unit``, the plane's x term is shared along a column, and
    the taps lie inside the box (the selection's ``reach``), so no index is clamped. The count is
    an integer, so the visiting order is free.

    A flat receiver (zero slope) takes the plane's arithmetic too: ``float32(d + 0·di + 0·dj)``
    is ``d`` for every float32 ``d`` (a signed zero aside, which compares alike), so it passes
    exactly where :func:`tap`'s unmoved ``receiver`` does, and no tap branches on the slope.
    """
    shift = wp.int64(bits)
    unit = wp.int64(1) << shift
    step = wp.int64(2) * unit
    r = wp.int64(radius)
    i = x >> shift
    j = y >> shift
    # (2i' + 1)·unit − 2x at the first column and row, tap's integers in tap's order.
    ex = (wp.int64(2) * (i - r) + wp.int64(1)) * unit - wp.int64(2) * x
    ey0 = (wp.int64(2) * (j - r) + wp.int64(1)) * unit - wp.int64(2) * y
    near = wp.float64(receiver)
    count = int(0)
    # `while` loops: a range known only at run time costs Warp's CPU code several times more per step.
    ii = int(i - r)
    last = int(i + r)
    while ii <= last:
        column = near + slope[0] * (wp.float64(ex) * inverse_span)
        ey = ey0
        jj = int(j - r)
        top = int(j + r)
        while jj <= top:
            if wp.float32(column + slope[1] * (wp.float64(ey) * inverse_span)) <= depth[c, jj, ii]:
                count += 1
            ey += step
            jj += 1
        ex += step
        ii += 1
    return count


_NINE_TAPS = """
int count = 0;
#if !defined(__CUDA_ARCH__)
{
#pragma clang fp contract(off)
    // A row's three taps side by side: the plane's column terms plus the row's term, each sum rounded
    // to float32 and compared with the texel, as Warp's scalar code does them one at a time.
    typedef double v4d __attribute__((ext_vector_type(4)));
    typedef float v4f __attribute__((ext_vector_type(4)));
    typedef int v4i __attribute__((ext_vector_type(4)));
    const v4d columns = {c0, c1, c2, c2};
    const double rows[3] = {r0, r1, r2};
    for (int t = 0; t < 3; ++t) {
        v4f texels = 0.0f;
        __builtin_memcpy(&texels, &wp::index(depth, c, j - 1 + t, i - 1), 12);
        const v4i passes = __builtin_convertvector(columns + rows[t], v4f) <= texels;
        count -= passes[0] + passes[1] + passes[2];
    }
}
#else
    const double columns[3] = {c0, c1, c2};
    const double rows[3] = {r0, r1, r2};
    for (int t = 0; t < 3; ++t) {
        for (int u = 0; u < 3; ++u) {
            count += static_cast<float>(columns[u] + rows[t]) <= wp::index(depth, c, j - 1 + t, i - 1 + u) ? 1 : 0;
        }
    }
#endif
return count;
"""


@wp.func_native(_NINE_TAPS)
def nine_taps(depth: wp.array3d(dtype=wp.float32), c: int, i: int, j: int, c0: wp.float64, c1: wp.float64,
              c2: wp.float64, r0: wp.float64, r1: wp.float64, r2: wp.float64) -> int:
    """How many of the 3×3 texels centred on (i, j) of cascade c are not nearer than the receiver plane
    ``float32(c_u + r_t)`` at column u and row t: :func:`box_count_3x3`'s comparisons, a row's three at once
    on the CPU (native code, so that clang puts them in one vector), one at a time on a GPU."""
    ...


@wp.func
def box_count_3x3(depth: wp.array3d(dtype=wp.float32), c: int, x: wp.int64, y: wp.int64, receiver: wp.float32,
                  slope: wp.vec2d, bits: int, inverse_span: wp.float64) -> int:
    """:func:`box_count` of radius 1 (PCF 3×3), its loops unrolled: the three column and three row terms of
    the plane are each computed once and the nine taps compared in :func:`nine_taps`."""
    shift = wp.int64(bits)
    unit = wp.int64(1) << shift
    step = wp.int64(2) * unit
    i = x >> shift
    j = y >> shift
    ex = (wp.int64(2) * (i - wp.int64(1)) + wp.int64(1)) * unit - wp.int64(2) * x
    ey = (wp.int64(2) * (j - wp.int64(1)) + wp.int64(1)) * unit - wp.int64(2) * y
    near = wp.float64(receiver)
    c0 = near + slope[0] * (wp.float64(ex) * inverse_span)
    c1 = near + slope[0] * (wp.float64(ex + step) * inverse_span)
    c2 = near + slope[0] * (wp.float64(ex + wp.int64(2) * step) * inverse_span)
    r0 = slope[1] * (wp.float64(ey) * inverse_span)
    r1 = slope[1] * (wp.float64(ey + step) * inverse_span)
    r2 = slope[1] * (wp.float64(ey + wp.int64(2) * step) * inverse_span)
    return nine_taps(depth, c, int(i), int(j), c0, c1, c2, r0, r1, r2)


@wp.func
def holds(x: wp.int64, y: wp.int64, inset: wp.int64, top: wp.int64) -> bool:
    """The point lies in ``[inset, top)`` on both axes (fixed point)."""
    return x >= inset and x < top and y >= inset and y < top


@wp.struct
class FixedReceivers:
    """Receivers already in every cascade's fixed point (:func:`receiver_coordinates`, or an engine's window space:
    :func:`csmlab.kernels.engine.window_receivers`); ``planar`` 0: every receiver a flat plane, and ``slope`` one
    element that no kernel reads."""

    coords: wp.array3d(dtype=wp.int64)
    depth: wp.array2d(dtype=wp.float32)
    slope: wp.array2d(dtype=wp.vec2d)
    planar: int


@wp.struct
class WorldReceivers:
    """Receivers as world points, taken into a cascade's fixed point where a kernel reads them.

    ``to_fixed = 2**bits / texel_size`` is per cascade, ``bias`` the normal offset and depth bias
    (:class:`csmlab.kernels.bias.ReceiverBias`); ``planar`` 0 gives every receiver a flat plane (no
    receiver-plane bias).
    """

    points: wp.array(dtype=wp.vec3d)
    normals: wp.array(dtype=wp.vec3)
    index: wp.array(dtype=wp.int32)
    basis: wp.mat33d
    texel_size: wp.array2d(dtype=wp.float64)
    to_fixed: wp.array2d(dtype=wp.float64)
    origin_fixed: wp.array2d(dtype=wp.int64)
    zref: wp.float64
    limit: wp.float64
    bias: ReceiverBias
    planar: int


@wp.struct
class LightReceiver:
    """A world receiver in the light's basis (metres): what :func:`receiver_in` needs whatever the cascade.

    ``cos`` is the cosine of the normal's angle to the light, ``tan`` its tangent capped at
    ``max_tan`` (NaN turned from the light), ``plane_x, plane_y`` the tangent plane's depth change
    per metre along x and y (0 turned from the light).
    """

    px: wp.float64
    py: wp.float64
    pz: wp.float64
    nx: wp.float64
    ny: wp.float64
    nz: wp.float64
    cos: wp.float64
    tan: wp.float64
    plane_x: wp.float64
    plane_y: wp.float64


@wp.func
def receiver_light(r: FixedReceivers, k: int) -> LightReceiver:
    """Converted receivers need nothing from the light's basis."""
    return LightReceiver()


@wp.func
def receiver_light(r: WorldReceivers, k: int) -> LightReceiver:  # noqa: F811  (a Warp overload, by receiver type)
    """Receiver k's point and normal in the light's basis and its normal's slope: computed once per receiver,
    however many cascades the selection converts it into (:func:`receiver_in`)."""
    zero = wp.float64(0.0)
    point = r.points[r.index[k]]
    normal = wp.vec3d(r.normals[r.index[k]])
    light = LightReceiver()
    light.px = light_space(point, r.basis, 0)
    light.py = light_space(point, r.basis, 1)
    light.pz = light_space(point, r.basis, 2)
    light.nx = light_space(normal, r.basis, 0)
    light.ny = light_space(normal, r.basis, 1)
    light.nz = light_space(normal, r.basis, 2)
    cos = -light.nz
    light.cos = cos
    light.tan = wp.float64(wp.nan)
    light.plane_x = zero
    light.plane_y = zero
    if cos > zero:
        light.tan = wp.min(wp.sqrt(wp.max(wp.float64(1.0) - cos * cos, zero)) / cos, r.bias.max_tan)
        light.plane_x = light.nx / cos
        light.plane_y = light.ny / cos
    return light


@wp.func
def receiver_in(r: FixedReceivers, light: LightReceiver, c: int, k: int):
    """Receiver k in cascade c: fixed-point ``x, y``, biased depth and receiver-plane slope."""
    slope = wp.vec2d()
    if r.planar != 0:
        slope = r.slope[c, k]
    return r.coords[c, k, 0], r.coords[c, k, 1], r.depth[c, k], slope


@wp.func
def receiver_in(r: WorldReceivers, light: LightReceiver, c: int, k: int):  # noqa: F811  (a Warp overload)
    """Receiver k, ``light`` its :func:`receiver_light`, in cascade c: fixed-point ``x, y``, biased depth and
    receiver-plane slope.

    csmlab.texels.receiver_lookup's operations in its order, one at a time (Warp emits one
    statement per operation, so no multiply-add is fused): the same bits as the host.
    """
    zero = wp.float64(0.0)
    cos = light.cos
    slope = wp.vec2d(zero, zero)
    if r.planar != 0:
        slope = wp.vec2d(wp.clamp(light.plane_x, -r.bias.max_tan, r.bias.max_tan) * r.texel_size[c, 0],
                         wp.clamp(light.plane_y, -r.bias.max_tan, r.bias.max_tan) * r.texel_size[c, 1])
    moved = r.bias.offset[c]
    along = wp.float64(1.0)
    if r.bias.normal_scale != NORMAL_NONE:
        # csmlab.texels.receiver_lookup's scale of the offset by the normal's angle to the light.
        if r.bias.normal_scale == NORMAL_SIN:
            moved = moved * wp.sqrt(wp.max(wp.float64(1.0) - cos * cos, zero))
        elif r.bias.normal_scale == NORMAL_ONE_MINUS_COS_LATERAL:
            moved = moved * (wp.float64(1.0) - wp.max(-cos, zero))
            along = zero
        else:
            moved = moved * (wp.float64(1.0) - wp.max(cos, zero))
    x = fixed_point(light.nx * moved + light.px, r.to_fixed[c, 0], r.limit) - r.origin_fixed[c, 0]
    y = fixed_point(light.ny * moved + light.py, r.to_fixed[c, 1], r.limit) - r.origin_fixed[c, 1]
    bias = r.bias.bias_constant[c] + r.bias.slope_bias[c] * light.tan
    if r.bias.plane_offset[c] > zero:
        # MJP's static receiver-plane offset: the plane's depth change over a texel in x and one in y, capped.
        sx = wp.clamp(light.plane_x, -r.bias.max_tan, r.bias.max_tan) * r.texel_size[c, 0]
        sy = wp.clamp(light.plane_y, -r.bias.max_tan, r.bias.max_tan) * r.texel_size[c, 1]
        bias = bias + wp.min(wp.abs(sx) + wp.abs(sy), r.bias.plane_offset[c])
    return x, y, wp.float32(light.pz + along * moved * light.nz - r.zref - bias), slope


@wp.struct
class WindowReceivers:
    """Receivers as world points, taken into an engine's window space (:mod:`csmlab.kernels.engine`) where a kernel
    reads them; ``planar`` 0 gives every receiver a flat plane."""

    receivers: EngineReceivers
    boxes: EngineBoxes
    planar: int


@wp.func
def receiver_light(r: WindowReceivers, k: int) -> WindowPoint:  # noqa: F811  (a Warp overload)
    """Receiver k as every cascade's window-space conversion reads it (:func:`csmlab.kernels.engine.window_point`):
    computed once per receiver."""
    return window_point(r.receivers, r.boxes, k)


@wp.func
def receiver_in(r: WindowReceivers, light: WindowPoint, c: int, k: int):  # noqa: F811  (a Warp overload)
    """Receiver k, ``light`` its :func:`receiver_light`, in cascade c's window space
    (:func:`csmlab.kernels.engine.window_in`, as :func:`csmlab.kernels.engine.window_receivers` takes it)."""
    x, y, d, sx, sy = window_in(r.receivers, r.boxes, light, c)
    slope = wp.vec2d()
    if r.planar != 0:
        slope = wp.vec2d(sx, sy)
    return x, y, d, slope


@wp.func
def selected_cascade(receivers: Any, light: Any, k: int, z: wp.float64, selection: int, count: int,
                     splits: wp.array(dtype=wp.float64), texel_area: wp.array(dtype=wp.float64),
                     sphere_cascade: wp.array(dtype=wp.int32), tap_lo: wp.int64, tap_hi: wp.int64,
                     select_lo: wp.int64, select_hi: wp.int64):
    """Receiver k's cascade under ``selection`` (−1: none) and the receiver there (:func:`receiver_in`): fixed-point
    ``x, y``, biased depth and slope.

    A box holds a point for sampling when every tap is inside ``[tap_lo, tap_hi)``, and for ``map``
    selection when the point is also inside ``[select_lo, select_hi)`` (fixed point).
    """
    chosen = int(-1)
    x = wp.int64(0)
    y = wp.int64(0)
    receiver = wp.float32(0.0)
    slope = wp.vec2d()
    if selection == SELECT_INTERVAL or selection == SELECT_SPHERE:
        if selection == SELECT_SPHERE:
            chosen = int(sphere_cascade[k])
        c = int(0)
        while c < count and selection == SELECT_INTERVAL:
            if z >= splits[c] and z < splits[c + 1]:
                chosen = c
            c += 1
        if chosen >= 0:
            x, y, receiver, slope = receiver_in(receivers, light, chosen, k)
            if not holds(x, y, tap_lo, tap_hi):
                chosen = -1
    else:
        best = wp.float64(wp.inf)
        c = int(0)
        while c < count:
            xc, yc, rc, sc = receiver_in(receivers, light, c, k)
            if holds(xc, yc, select_lo, select_hi):
                if (selection == SELECT_MAP and chosen < 0) or (selection == SELECT_BEST_RESOLUTION
                                                                 and texel_area[c] < best):
                    best = texel_area[c]
                    chosen = c
                    x = xc
                    y = yc
                    receiver = rc
                    slope = sc
            c += 1
    return chosen, x, y, receiver, slope


@wp.func
def band_weight(z: wp.float64, chosen: int, count: int, splits: wp.array(dtype=wp.float64),
                band_start: wp.array(dtype=wp.float64), blend_curve: int) -> wp.float64:
    """The next cascade's weight in [0, 1) at view depth ``z`` in cascade ``chosen``'s blend band; −1 outside it.

    The band of cascade ``chosen`` runs from ``band_start[chosen]`` (+inf: none) to where the
    selection leaves it (:func:`csmlab.cascades.fit.transition_bands`).
    """
    nxt = chosen + 1
    w = wp.float64(-1.0)
    if nxt < count:
        z1 = splits[nxt]
        start = band_start[chosen]
        if z >= start and z < z1:
            w = (z - start) / (z1 - start)
            if blend_curve == BLEND_SMOOTHSTEP:
                w = w * w * (wp.float64(3.0) - wp.float64(2.0) * w)
    return w


BLOCK = 8
"""World receivers a CPU thread selects at once (:func:`world_block`), in the lanes of its vectors."""

WorldBlock = wp.types.matrix(shape=(6, BLOCK), dtype=wp.float64)
""":data:`BLOCK` world receivers at their ``interval`` cascade (:func:`world_block`), a column each: rows the cascade
(−1: none, or its box does not hold the taps), fixed-point ``x, y`` (exact in float64: inside the box), the biased
float32 depth and the receiver plane's slope ``(x, y)``."""

_WORLD_BLOCK = Template("""
wp::mat_t<6, $BLOCK, double> out;
#if !defined(__CUDA_ARCH__)
{
#pragma clang fp contract(off)
    // receiver_light, the interval selection and receiver_in of eight receivers, each step over the eight
    // lanes at once: the same operations in the same order as Warp's code, so the same bits.
    double px[$BLOCK], py[$BLOCK], pz[$BLOCK], nx[$BLOCK], ny[$BLOCK], nz[$BLOCK], cs[$BLOCK], tn[$BLOCK], plx[$BLOCK],
           ply[$BLOCK], z[$BLOCK];
    int chosen[$BLOCK];
    const wp::mat_t<3, 3, double> b = r.basis;
    for (int l = 0; l < $BLOCK; ++l) {
        const int m = wp::index(r.index, k + l);
        const wp::vec_t<3, double> p = wp::index(r.points, m);
        const wp::vec_t<3, float> nf = wp::index(r.normals, m);
        const double n0 = static_cast<double>(nf[0]), n1 = static_cast<double>(nf[1]), n2 = static_cast<double>(nf[2]);
        px[l] = (p[0] * b.data[0][0] + p[2] * b.data[0][2]) + p[1] * b.data[0][1];
        py[l] = (p[0] * b.data[1][0] + p[2] * b.data[1][2]) + p[1] * b.data[1][1];
        pz[l] = (p[0] * b.data[2][0] + p[2] * b.data[2][2]) + p[1] * b.data[2][1];
        nx[l] = (n0 * b.data[0][0] + n2 * b.data[0][2]) + n1 * b.data[0][1];
        ny[l] = (n0 * b.data[1][0] + n2 * b.data[1][2]) + n1 * b.data[1][1];
        nz[l] = (n0 * b.data[2][0] + n2 * b.data[2][2]) + n1 * b.data[2][1];
        z[l] = wp::index(view_depth, k + l);
    }
    for (int l = 0; l < $BLOCK; ++l) {
        const double cos = -nz[l];
        const bool facing = cos > 0.0;
        cs[l] = cos;
        tn[l] = facing ? wp::min(wp::sqrt(wp::max(1.0 - cos * cos, 0.0)) / cos, r.bias.max_tan) : NAN;
        plx[l] = facing ? nx[l] / cos : 0.0;
        ply[l] = facing ? ny[l] / cos : 0.0;
        chosen[l] = -1;
    }
    const int count = splits.shape[0] - 1;
    for (int c = 0; c < count; ++c) {
        const double lo = wp::index(splits, c), hi = wp::index(splits, c + 1);
        for (int l = 0; l < $BLOCK; ++l) {
            chosen[l] = (z[l] >= lo && z[l] < hi) ? c : chosen[l];
        }
    }
    const double max_tan = r.bias.max_tan;
    for (int l = 0; l < $BLOCK; ++l) {
        const int c = chosen[l] < 0 ? 0 : chosen[l];
        const double cos = cs[l];
        const double tx = wp::index(r.texel_size, c, 0), ty = wp::index(r.texel_size, c, 1);
        double sx = 0.0, sy = 0.0;
        if (r.planar != 0) {
            sx = wp::clamp(plx[l], -max_tan, max_tan) * tx;
            sy = wp::clamp(ply[l], -max_tan, max_tan) * ty;
        }
        double moved = wp::index(r.bias.offset, c);
        double along = 1.0;
        if (r.bias.normal_scale != $NORMAL_NONE) {
            if (r.bias.normal_scale == $NORMAL_SIN) {
                moved = moved * wp::sqrt(wp::max(1.0 - cos * cos, 0.0));
            } else if (r.bias.normal_scale == $NORMAL_ONE_MINUS_COS_LATERAL) {
                moved = moved * (1.0 - wp::max(-cos, 0.0));
                along = 0.0;
            } else {
                moved = moved * (1.0 - wp::max(cos, 0.0));
            }
        }
        double ux = wp::rint(wp::clamp((nx[l] * moved + px[l]) * wp::index(r.to_fixed, c, 0), -r.limit, r.limit));
        double uy = wp::rint(wp::clamp((ny[l] * moved + py[l]) * wp::index(r.to_fixed, c, 1), -r.limit, r.limit));
        ux = ux != ux ? -r.limit : ux;
        uy = uy != uy ? -r.limit : uy;
        const long long x = static_cast<long long>(ux) - wp::index(r.origin_fixed, c, 0);
        const long long y = static_cast<long long>(uy) - wp::index(r.origin_fixed, c, 1);
        double bias = wp::index(r.bias.bias_constant, c) + wp::index(r.bias.slope_bias, c) * tn[l];
        const double cap = wp::index(r.bias.plane_offset, c);
        if (cap > 0.0) {
            const double ox = wp::clamp(plx[l], -max_tan, max_tan) * tx;
            const double oy = wp::clamp(ply[l], -max_tan, max_tan) * ty;
            bias = bias + wp::min(wp::abs(ox) + wp::abs(oy), cap);
        }
        const float receiver = static_cast<float>(pz[l] + along * moved * nz[l] - r.zref - bias);
        const bool held = chosen[l] >= 0 && x >= tap_lo && x < tap_hi && y >= tap_lo && y < tap_hi;
        out.data[0][l] = held ? static_cast<double>(chosen[l]) : -1.0;
        out.data[1][l] = held ? static_cast<double>(x) : 0.0;
        out.data[2][l] = held ? static_cast<double>(y) : 0.0;
        out.data[3][l] = static_cast<double>(receiver);
        out.data[4][l] = sx;
        out.data[5][l] = sy;
    }
}
#endif
return out;
""").substitute(BLOCK=BLOCK, NORMAL_NONE=NORMAL_NONE, NORMAL_SIN=NORMAL_SIN,
                 NORMAL_ONE_MINUS_COS_LATERAL=NORMAL_ONE_MINUS_COS_LATERAL)


@wp.func_native(_WORLD_BLOCK)
def world_block(r: WorldReceivers, view_depth: wp.array(dtype=wp.float64), splits: wp.array(dtype=wp.float64),
                k: int, tap_lo: wp.int64, tap_hi: wp.int64) -> WorldBlock:
    """Receivers k … k + 7 at their ``interval`` cascade, on the CPU: :func:`selected_cascade` of each, bit for bit.

    Native code so that clang takes the eight receivers through :func:`receiver_light`, the
    selection and :func:`receiver_in` in vectors of eight float64 (about half of the kernel's time
    went to these, a receiver at a time); floating-point contraction off, as in the rest of the
    module. A GPU's threads take a receiver each and never call it.
    """
    ...


@wp.func
def interval_block(r: WorldReceivers, view_depth: wp.array(dtype=wp.float64), splits: wp.array(dtype=wp.float64),
                   k: int, tap_lo: wp.int64, tap_hi: wp.int64) -> WorldBlock:
    """:func:`world_block` of world receivers; the other receivers' overloads are never called
    (:func:`has_blocks`)."""
    return world_block(r, view_depth, splits, k, tap_lo, tap_hi)


@wp.func
def interval_block(r: FixedReceivers, view_depth: wp.array(dtype=wp.float64),  # noqa: F811
                   splits: wp.array(dtype=wp.float64), k: int, tap_lo: wp.int64, tap_hi: wp.int64) -> WorldBlock:
    """Converted receivers have no block (:func:`has_blocks`): what the generic kernel's code compiles to."""
    return WorldBlock()


@wp.func
def interval_block(r: WindowReceivers, view_depth: wp.array(dtype=wp.float64),  # noqa: F811
                   splits: wp.array(dtype=wp.float64), k: int, tap_lo: wp.int64, tap_hi: wp.int64) -> WorldBlock:
    """An engine's window receivers have no block (:func:`has_blocks`): what the generic kernel's code compiles to."""
    return WorldBlock()


@wp.func
def has_blocks(r: WorldReceivers) -> bool:
    """World receivers are selected :data:`BLOCK` at a time on the CPU (:func:`world_block`)."""
    return True


@wp.func
def has_blocks(r: FixedReceivers) -> bool:  # noqa: F811
    """Converted receivers are read a receiver at a time."""
    return False


@wp.func
def has_blocks(r: WindowReceivers) -> bool:  # noqa: F811
    """An engine's window receivers are converted a receiver at a time."""
    return False


@wp.func
def write_lookup(depth: wp.array3d(dtype=wp.float32), receivers: Any, k: int, z: wp.float64, chosen: int, x: wp.int64,
                 y: wp.int64, receiver: wp.float32, slope: wp.vec2d, splits: wp.array(dtype=wp.float64),
                 band_start: wp.array(dtype=wp.float64), blend_curve: int, bits: int, inverse_span: wp.float64,
                 filter_code: int, radius: int, tap_lo: wp.int64, tap_hi: wp.int64, lit: wp.array(dtype=wp.float32),
                 cascade: wp.array(dtype=wp.int32), blend: wp.array(dtype=wp.int32)):
    """Receiver k's S, cascade and blend flag, the receiver at ``(x, y)`` with ``receiver`` depth and ``slope`` in its
    selected cascade ``chosen`` (−1: none, S 0): filtered there and, in the cascade's blend band, blended with the next
    cascade where that holds the taps (``[tap_lo, tap_hi)``, fixed point)."""
    cascade[k] = chosen
    blend[k] = 0
    if chosen < 0:
        lit[k] = 0.0
        return
    s = lit_fraction(depth, chosen, x, y, receiver, slope, bits, inverse_span, filter_code, radius)
    w = band_weight(z, chosen, depth.shape[0], splits, band_start, blend_curve)
    if w >= wp.float64(0.0):
        # The receiver in the light's basis again: only a band's receivers read a second cascade.
        xn, yn, rn, sn = receiver_in(receivers, receiver_light(receivers, k), chosen + 1, k)
        if holds(xn, yn, tap_lo, tap_hi):
            s = (wp.float64(1.0) - w) * s + w * lit_fraction(depth, chosen + 1, xn, yn, rn, sn, bits, inverse_span,
                                                             filter_code, radius)
            blend[k] = 1
    lit[k] = wp.float32(s)


@wp.kernel
def shadow_lookup_kernel(
    depth: wp.array3d(dtype=wp.float32),
    receivers: Any,
    view_depth: wp.array(dtype=wp.float64),
    splits: wp.array(dtype=wp.float64),
    texel_area: wp.array(dtype=wp.float64),
    sphere_cascade: wp.array(dtype=wp.int32),
    bits: int,
    selection: int,
    reach: int,
    margin: int,
    band_start: wp.array(dtype=wp.float64),
    blend_curve: int,
    filter_code: int,
    radius: int,
    run: int,
    lit: wp.array(dtype=wp.float32),
    cascade: wp.array(dtype=wp.int32),
    blend: wp.array(dtype=wp.int32),
):
    # A run of receivers per thread (one on a GPU): a CPU thread's start copies every argument, the
    # receivers' struct among them, which cost about as much as a receiver's selection.
    unit = wp.int64(1) << wp.int64(bits)
    inverse_span = wp.float64(1.0) / wp.float64(wp.int64(2) * unit)
    count = depth.shape[0]
    size = wp.int64(depth.shape[1])
    tap_lo = wp.int64(reach) * unit
    tap_hi = (size - wp.int64(reach)) * unit
    k = wp.tid() * run
    last = wp.min(k + run, view_depth.shape[0])
    blocks = run > 1 and selection == SELECT_INTERVAL and has_blocks(receivers)
    while k < last:
        if blocks and k + BLOCK <= last:
            block = interval_block(receivers, view_depth, splits, k, tap_lo, tap_hi)
            lane = int(0)
            while lane < BLOCK:
                write_lookup(depth, receivers, k + lane, view_depth[k + lane], int(block[0, lane]),
                             wp.int64(block[1, lane]), wp.int64(block[2, lane]), wp.float32(block[3, lane]),
                             wp.vec2d(block[4, lane], block[5, lane]),
                             splits, band_start, blend_curve, bits, inverse_span, filter_code, radius, tap_lo, tap_hi,
                             lit, cascade, blend)
                lane += 1
            k += BLOCK
        else:
            z = view_depth[k]
            chosen, x, y, receiver, slope = selected_cascade(
                receivers, receiver_light(receivers, k), k, z, selection, count, splits, texel_area, sphere_cascade,
                tap_lo, tap_hi, wp.int64(margin) * unit, (size - wp.int64(margin)) * unit)
            write_lookup(depth, receivers, k, z, chosen, x, y, receiver, slope, splits, band_start, blend_curve, bits,
                         inverse_span, filter_code, radius, tap_lo, tap_hi, lit, cascade, blend)
            k += 1


@wp.kernel
def selection_kernel(
    depth: wp.array3d(dtype=wp.float32),
    receivers: Any,
    view_depth: wp.array(dtype=wp.float64),
    splits: wp.array(dtype=wp.float64),
    texel_area: wp.array(dtype=wp.float64),
    sphere_cascade: wp.array(dtype=wp.int32),
    bits: int,
    selection: int,
    reach: int,
    margin: int,
    band_start: wp.array(dtype=wp.float64),
    blend_curve: int,
    keep_picked: int,
    cascade: wp.array(dtype=wp.int32),
    blend: wp.array(dtype=wp.int32),
    blend_weight: wp.array(dtype=wp.float64),
    picked_coords: wp.array3d(dtype=wp.int64),
    picked_depth: wp.array2d(dtype=wp.float32),
    picked_slope: wp.array2d(dtype=wp.vec2d),
):
    """:func:`shadow_lookup_kernel`'s selection and blend band without a filter: each receiver's cascade, blend and
    blend weight, and (``keep_picked``) the receiver at its selected cascade (row 0) and, in the blend band, the next
    (row 1): what a filter run after the selection reads."""
    k = wp.tid()
    unit = wp.int64(1) << wp.int64(bits)
    count = depth.shape[0]
    size = wp.int64(depth.shape[1])
    z = view_depth[k]
    light = receiver_light(receivers, k)
    chosen, x, y, receiver, slope = selected_cascade(
        receivers, light, k, z, selection, count, splits, texel_area, sphere_cascade, wp.int64(reach) * unit,
        (size - wp.int64(reach)) * unit, wp.int64(margin) * unit, (size - wp.int64(margin)) * unit)
    cascade[k] = chosen
    blend[k] = 0
    blend_weight[k] = wp.float64(0.0)
    if chosen < 0:
        return
    if keep_picked != 0:
        picked_coords[0, k, 0] = x
        picked_coords[0, k, 1] = y
        picked_depth[0, k] = receiver
        picked_slope[0, k] = slope
    w = band_weight(z, chosen, count, splits, band_start, blend_curve)
    if w >= wp.float64(0.0):
        xn, yn, rn, sn = receiver_in(receivers, light, chosen + 1, k)
        if holds(xn, yn, wp.int64(reach) * unit, (size - wp.int64(reach)) * unit):
            blend[k] = 1
            blend_weight[k] = w
            if keep_picked != 0:
                picked_coords[1, k, 0] = xn
                picked_coords[1, k, 1] = yn
                picked_depth[1, k] = rn
                picked_slope[1, k] = sn


wp.overload(shadow_lookup_kernel, {"receivers": FixedReceivers})
wp.overload(shadow_lookup_kernel, {"receivers": WorldReceivers})
wp.overload(shadow_lookup_kernel, {"receivers": WindowReceivers})
wp.overload(selection_kernel, {"receivers": FixedReceivers})
wp.overload(selection_kernel, {"receivers": WorldReceivers})
wp.overload(selection_kernel, {"receivers": WindowReceivers})


def shadow_lookup(depth, coords, receiver_depth, view_depth, *, splits, texel_area, selection: str,
                  filter: str, radius: int, margin: int, blend_band: float, bits: int,
                  receiver_slope=None, band_start=None, blend_curve: int = 0, sphere_cascade=None,
                  device: str = "cpu") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Lit fraction S and selected cascade at receiver points under a box filter.

    Parameters
    ----------
    depth : array_like, shape (C, R, R), float32
        Depth maps (``depth[c, j, i]``, metres, +inf where empty).
    coords : array_like, shape (C, N, 2), int64
        Each receiver's position in each cascade in ``2**-bits`` texels from the box origin,
        after the normal offset.
    receiver_depth : array_like, shape (C, N), float32
        Each receiver's biased depth in each cascade, metres; NaN (turned from the light) is
        shadowed by every texel.
    view_depth : array_like, shape (N,), float64
        View depth in metres under the camera whose selection is wanted; NaN where no receiver.
    splits : array_like, shape (C + 1,), float64
        Split distances, metres of view depth.
    texel_area : array_like, shape (C,), float64
        Texel area of each cascade, m² (``best_resolution``).
    selection : str
        A key of :data:`csmlab.lookup_choices.SELECTION_METHODS`.
    filter : str
        A filter of the ``box`` family (:data:`csmlab.lookup_choices.FILTER_METHODS`).
    radius : int
        Texels the filter's taps reach beyond the one holding the point, its record's
        ``radius_of`` (``pcf``: the box is (2·radius + 1)² texels; ``none`` 0, ``pcf_bilinear`` 1).
    margin : int
        ``map`` and ``best_resolution``: texels of each box edge that do not count as inside
        (at least ``radius``).
    blend_band : float
        Fraction in [0, 0.5] of a split interval blended toward the next cascade.
    bits : int
        Sub-texel bits of ``coords``.
    band_start : array_like, shape (C,), float64, optional
        Where each cascade's band toward the next starts, metres of view depth (+inf: none); it ends
        at the cascade's far split. None: the last ``blend_band`` of each split interval.
    blend_curve : int
        :data:`csmlab.lookup_choices.BLEND_LINEAR` or :data:`csmlab.lookup_choices.BLEND_SMOOTHSTEP`: the next
        cascade's weight over the band.
    receiver_slope : array_like, shape (C, N, 2), float64, optional
        Receiver-plane depth change per texel along x and y, metres
        (:func:`csmlab.texels.receiver_lookup`); each tap compares the plane's depth at its texel
        centre. None compares the receiver's own depth at every tap.
    sphere_cascade : array_like, shape (N,), int32, optional
        ``sphere``: each receiver's first split sphere holding it, −1 where none
        (:func:`split_sphere_cascades`); required there, ignored by the other selections.
    device : str
        ``"cpu"`` or ``"cuda"``.

    Returns
    -------
    lit : ndarray, shape (N,), float32
        S in [0, 1]; NaN where no cascade was selected.
    cascade : ndarray, shape (N,), int8
        Selected cascade, −1 where none.
    blend : ndarray, shape (N,), bool
        S mixes the selected cascade with the next one.

    Raises
    ------
    ValueError
        On an unknown selection or a filter outside the box family (the message lists the valid
        names), a negative ``radius``, or shapes that do not match.
    """
    device = checked_device(device)
    code = family_code(filter, family="box")
    receivers = _fixed_receivers(depth, coords, receiver_depth, view_depth, receiver_slope, device=device)
    lit, cascade, blend = _launch(depth, receivers, view_depth, splits=splits, texel_area=texel_area,
                                  selection=selection, code=code, radius=radius, reach=radius, margin=margin,
                                  blend_band=blend_band, band_start=band_start, blend_curve=blend_curve,
                                  sphere_cascade=sphere_cascade, bits=bits, device=device)
    return lit, cascade.astype(np.int8), blend


def select_cascades(depth, coords, receiver_depth, view_depth, *, splits, texel_area, selection: str, radius: int,
                    margin: int, blend_band: float, bits: int, band_start=None, blend_curve: int = 0,
                    sphere_cascade=None, device: str = "cpu") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The cascade selection of :func:`shadow_lookup` for a filter that runs after it, and its blend band.

    The same kernel and rules: a box is selected only where it holds every tap of a filter
    reaching ``radius`` texels, and the blend band blends toward the next cascade only where that
    box holds them too.

    Parameters
    ----------
    depth, coords, receiver_depth, view_depth, splits, texel_area, selection, margin, blend_band, bits, sphere_cascade,
    device
        As :func:`shadow_lookup`.
    radius : int
        Texels the filter's taps reach beyond the one holding the point.

    Returns
    -------
    cascade : ndarray, shape (N,), int32
        Selected cascade, −1 where none.
    blend_weight : ndarray, shape (N,), float64
        Weight in [0, 1) of cascade ``cascade + 1`` in the blend band, 0 outside it.
    blend : ndarray, shape (N,), bool
        The receiver lies in a blend band (its weight may be 0 at the band's start).
    """
    device = checked_device(device)
    receivers = _fixed_receivers(depth, coords, receiver_depth, view_depth, None, device=device)
    cascade, blend, weight, _ = _launch_selection(depth, receivers, view_depth, splits=splits, texel_area=texel_area,
                                                  selection=selection, reach=radius, margin=margin,
                                                  blend_band=blend_band, band_start=band_start, blend_curve=blend_curve,
                                                  sphere_cascade=sphere_cascade, bits=bits, picked=False,
                                                  device=device)
    return cascade, weight, blend


def shadow_lookup_world(depth, points, normals, view_depth, *, receivers, basis, texel_size, origin_fixed, zref: float,
                        bias: BiasSettings, receiver_plane_bias: bool, splits,
                        texel_area, selection: str, filter: str, radius: int, margin: int,
                        blend_band: float, bits: int, band_start=None, blend_curve: int = 0, sphere_cascade=None,
                        device: str = "cpu") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`shadow_lookup` of world receivers, each taken into a cascade's fixed point where the lookup reads it.

    The same results, bit for bit, as :func:`receiver_coordinates` followed by :func:`shadow_lookup`
    (one conversion, :func:`receiver_in`, serves both) without the ``(C, N)`` arrays of every
    receiver in every cascade: a receiver is converted into the cascades its selection tests only.

    Parameters
    ----------
    depth, view_depth, splits, texel_area, selection, filter, radius, margin, blend_band, bits, sphere_cascade, device
        As :func:`shadow_lookup`; ``view_depth`` and ``sphere_cascade`` ``(N,)`` one per receiver.
    points, normals, receivers, basis, texel_size, origin_fixed, zref, bias
        As :func:`receiver_coordinates`.
    receiver_plane_bias : bool
        Compare each tap with the receiver's tangent plane (else with its own depth).

    Returns
    -------
    lit, cascade, blend
        As :func:`shadow_lookup`.
    """
    device = checked_device(device)
    code = family_code(filter, family="box")
    world = world_receivers(points, normals, receivers=receivers, basis=basis, texel_size=texel_size,
                            origin_fixed=origin_fixed,
                            zref=zref, bits=bits, bias=bias, planar=receiver_plane_bias, device=device)
    if world.index.shape[0] != np.shape(view_depth)[0] or np.ndim(view_depth) != 1:
        raise ValueError(f"view_depth: expected one view depth per receiver ({world.index.shape[0]},), "
                         f"got shape {np.shape(view_depth)}")
    lit, cascade, blend = _launch(depth, world, view_depth, splits=splits, texel_area=texel_area,
                                  selection=selection, code=code, radius=radius, reach=radius, margin=margin,
                                  blend_band=blend_band, band_start=band_start, blend_curve=blend_curve,
                                  sphere_cascade=sphere_cascade, bits=bits, device=device)
    return lit, cascade.astype(np.int8), blend


def select_world_cascades(depth, points, normals, view_depth, *, receivers, basis, texel_size, origin_fixed,
                          zref: float, bias: BiasSettings, receiver_plane_bias: bool, splits, texel_area,
                          selection: str, radius: int, margin: int, blend_band: float, bits: int, band_start=None,
                          blend_curve: int = 0, sphere_cascade=None, device: str = "cpu") -> tuple:
    """:func:`select_cascades` of world receivers, with each receiver at the cascades a filter run after the
    selection reads: the one it selects and, in the blend band, the next.

    Bit for bit :func:`receiver_coordinates` followed by :func:`select_cascades`, and the rows of the
    first's arrays at those cascades, without converting every receiver into every cascade.

    Parameters
    ----------
    depth, points, normals, view_depth, receivers, basis, texel_size, origin_fixed, zref, bias, receiver_plane_bias,
    splits, texel_area, selection, margin, blend_band, bits, band_start, blend_curve, sphere_cascade, device
        As :func:`shadow_lookup_world`.
    radius : int
        Texels the filter's taps reach beyond the one holding the point.

    Returns
    -------
    cascade, blend_weight, blend, coordinates, receiver_depth, slope
        As :func:`select_window_cascades`.
    """
    device = checked_device(device)
    world = world_receivers(points, normals, receivers=receivers, basis=basis, texel_size=texel_size,
                            origin_fixed=origin_fixed, zref=zref, bits=bits, bias=bias, planar=receiver_plane_bias,
                            device=device)
    if world.index.shape[0] != np.shape(view_depth)[0] or np.ndim(view_depth) != 1:
        raise ValueError(f"view_depth: expected one view depth per receiver ({world.index.shape[0]},), "
                         f"got shape {np.shape(view_depth)}")
    return _picked_selection(depth, world, view_depth, splits=splits, texel_area=texel_area, selection=selection,
                             radius=radius, margin=margin, blend_band=blend_band, band_start=band_start,
                             blend_curve=blend_curve, sphere_cascade=sphere_cascade, bits=bits,
                             planar=receiver_plane_bias, device=device)


def shadow_lookup_window(depth, boxes: EngineBoxes, points, normals, view_depth, *, receivers, basis, texel_size,
                         zref: float, bias: BiasSettings, receiver_plane_bias: bool, splits, texel_area, selection: str,
                         filter: str, radius: int, margin: int, blend_band: float, bits: int, band_start=None,
                         blend_curve: int = 0, sphere_cascade=None,
                         device: str = "cpu") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`shadow_lookup` of receivers in an engine's window space, each taken into a cascade where the lookup
    reads it.

    The same results, bit for bit, as :func:`csmlab.kernels.engine.window_receivers` followed by
    :func:`shadow_lookup` (one conversion, :func:`csmlab.kernels.engine.window_in`, serves both) without
    converting every receiver into every cascade.

    Parameters
    ----------
    depth, view_depth, splits, texel_area, selection, filter, radius, margin, blend_band, bits, sphere_cascade, device
        As :func:`shadow_lookup`; ``view_depth`` and ``sphere_cascade`` ``(N,)`` one per receiver.
    boxes : EngineBoxes
        :func:`csmlab.kernels.engine.engine_boxes` of the cascades (``2**bits`` its scale), on ``device``.
    points, normals, receivers, basis, texel_size, zref, bias
        As :func:`csmlab.kernels.engine.window_receivers`.
    receiver_plane_bias : bool
        Compare each tap with the receiver's tangent plane (else with its own depth).

    Returns
    -------
    lit, cascade, blend
        As :func:`shadow_lookup`.
    """
    device = checked_device(device)
    code = family_code(filter, family="box")
    window = _window_receivers(depth, boxes, points, normals, view_depth, receivers=receivers, basis=basis,
                               texel_size=texel_size, zref=zref, bias=bias, planar=receiver_plane_bias, device=device)
    lit, cascade, blend = _launch(depth, window, view_depth, splits=splits, texel_area=texel_area,
                                  selection=selection, code=code, radius=radius, reach=radius, margin=margin,
                                  blend_band=blend_band, band_start=band_start, blend_curve=blend_curve,
                                  sphere_cascade=sphere_cascade, bits=bits, device=device)
    return lit, cascade.astype(np.int8), blend


def select_window_cascades(depth, boxes: EngineBoxes, points, normals, view_depth, *, receivers, basis, texel_size,
                           zref: float, bias: BiasSettings, receiver_plane_bias: bool, splits, texel_area,
                           selection: str, radius: int, margin: int, blend_band: float, bits: int, band_start=None,
                           blend_curve: int = 0, sphere_cascade=None, device: str = "cpu") -> tuple:
    """:func:`select_cascades` of receivers in an engine's window space, with each receiver at the cascades a filter
    run after the selection reads: the one it selects and, in the blend band, the next.

    Bit for bit :func:`csmlab.kernels.engine.window_receivers` followed by :func:`select_cascades`, and
    the rows of the first's arrays at those cascades, without converting every receiver into every cascade.

    Parameters
    ----------
    depth, boxes, points, normals, view_depth, receivers, basis, texel_size, zref, bias, receiver_plane_bias, splits,
    texel_area, selection, margin, blend_band, bits, band_start, blend_curve, sphere_cascade, device
        As :func:`shadow_lookup_window`.
    radius : int
        Texels the filter's taps reach beyond the one holding the point.

    Returns
    -------
    cascade, blend_weight, blend
        As :func:`select_cascades`.
    coordinates : ndarray, shape (2, N, 2), int64
        Each receiver's fixed point in its selected cascade (row 0) and the next (row 1, set where
        ``blend_weight`` is set; undefined elsewhere and where no cascade is selected).
    receiver_depth : ndarray, shape (2, N), float32
        Its biased depth there.
    slope : ndarray, shape (2, N, 2), float64, or None
        Its receiver-plane slopes there; None without ``receiver_plane_bias``.
    """
    device = checked_device(device)
    window = _window_receivers(depth, boxes, points, normals, view_depth, receivers=receivers, basis=basis,
                               texel_size=texel_size, zref=zref, bias=bias, planar=receiver_plane_bias, device=device)
    return _picked_selection(depth, window, view_depth, splits=splits, texel_area=texel_area, selection=selection,
                             radius=radius, margin=margin, blend_band=blend_band, band_start=band_start,
                             blend_curve=blend_curve, sphere_cascade=sphere_cascade, bits=bits,
                             planar=receiver_plane_bias, device=device)


def _picked_selection(depth, receivers, view_depth, *, splits, texel_area, selection: str, radius: int, margin: int,
                      blend_band: float, band_start, blend_curve: int, sphere_cascade, bits: int, planar: bool,
                      device: str) -> tuple:
    """The selection of ``receivers`` (:class:`WorldReceivers` or :class:`WindowReceivers`) and their rows at the
    selected cascade and the next: :func:`select_window_cascades`' outputs."""
    cascade, blend, weight, rows = _launch_selection(depth, receivers, view_depth, splits=splits,
                                                     texel_area=texel_area, selection=selection, reach=radius,
                                                     margin=margin, blend_band=blend_band, band_start=band_start,
                                                     blend_curve=blend_curve, sphere_cascade=sphere_cascade,
                                                     bits=bits, picked=True, device=device)
    coords, receiver_depth, slope = rows
    return cascade, weight, blend, coords, receiver_depth, slope if planar else None


def _window_receivers(depth, boxes: EngineBoxes, points, normals, view_depth, *, receivers, basis, texel_size,
                      zref: float, bias: BiasSettings, planar: bool, device: str) -> WindowReceivers:
    """The :class:`WindowReceivers` of :func:`shadow_lookup_window`'s arguments, checked against the maps and the
    view depths."""
    count = boxes.matrix.shape[0] if boxes.mode == WINDOW_FLOAT32 else boxes.texel_size.shape[0]
    if np.ndim(depth) != 3 or np.shape(depth)[0] != count:
        raise ValueError(f"depth: expected the depth maps of the boxes' {count} cascades (C, R, R), got shape "
                         f"{np.shape(depth)}")
    window = WindowReceivers()
    window.receivers = engine_receivers(points, normals, basis=basis, texel_size=texel_size, zref=zref, bias=bias,
                                        receivers=receivers, cascades=count, device=device)
    window.boxes = boxes
    window.planar = int(bool(planar))
    n = window.receivers.index.shape[0]
    if np.ndim(view_depth) != 1 or np.shape(view_depth)[0] != n:
        raise ValueError(f"view_depth: expected one view depth per receiver ({n},), got shape {np.shape(view_depth)}")
    return window


def _fixed_receivers(depth, coords, receiver_depth, view_depth, receiver_slope, *, device: str) -> FixedReceivers:
    """The :class:`FixedReceivers` of :func:`shadow_lookup`'s arrays, their shapes checked against the maps."""
    xy = np.ascontiguousarray(coords, dtype=np.int64)
    rd = np.ascontiguousarray(receiver_depth, dtype=np.float32)
    # No slope: a flat plane per receiver, and one element stands in for the array no kernel reads.
    slope = np.zeros((1, 1, 2)) if receiver_slope is None else np.ascontiguousarray(receiver_slope, dtype=np.float64)
    count = np.shape(depth)[0] if np.ndim(depth) == 3 else 0
    n = np.shape(view_depth)[0] if np.ndim(view_depth) == 1 else -1
    if xy.shape != (count, n, 2) or rd.shape != (count, n) or (
            receiver_slope is not None and slope.shape != (count, n, 2)):
        raise ValueError(f"coords, receiver_depth, receiver_slope, view_depth: expected shapes ({count}, N, 2), "
                         f"({count}, N), ({count}, N, 2), (N,); got {xy.shape}, {rd.shape}, {slope.shape}, "
                         f"{np.shape(view_depth)}")
    receivers = FixedReceivers()
    receivers.coords = wp.array(xy, dtype=wp.int64, device=device, copy=False)
    receivers.depth = wp.array(rd, dtype=wp.float32, device=device, copy=False)
    receivers.slope = wp.array(slope, dtype=wp.vec2d, device=device, copy=False)
    receivers.planar = int(receiver_slope is not None)
    return receivers


_RECEIVER_RUN = 64
"""Receivers a CPU thread of :func:`shadow_lookup_kernel` looks up (a GPU thread one)."""


def _launch(depth, receivers, view_depth, *, code: int, radius: int, device: str, **selection) -> tuple:
    """Launch :func:`shadow_lookup_kernel` over ``receivers`` (:class:`FixedReceivers`, :class:`WorldReceivers` or
    :class:`WindowReceivers`) with the box filter ``code`` of ``radius`` run at the selected cascade; ``selection``
    the keyword arguments of :func:`_selection_inputs`.

    Returns ``lit`` (NaN where none selected), ``cascade`` int32 and ``blend`` bool as NumPy arrays.
    """
    if selection["reach"] < radius:
        # box_count reads the taps unclamped: the selected box must hold every one of them.
        raise ValueError(f"radius: the taps a selected box holds ({selection['reach']}) must reach the filter's "
                         f"({radius})")
    n, inputs = _selection_inputs(depth, view_depth, device=device, **selection)
    if n == 0:
        return np.zeros(0, np.float32), np.zeros(0, np.int32), np.zeros(0, bool)
    lit = wp.empty(n, dtype=wp.float32, device=device)
    chosen = wp.empty(n, dtype=wp.int32, device=device)
    blended = wp.empty(n, dtype=wp.int32, device=device)
    run = _RECEIVER_RUN if wp.get_device(device).is_cpu else 1
    wp.launch(shadow_lookup_kernel, dim=-(-n // run),
              inputs=(inputs[0], receivers) + inputs[1:] + (code, int(radius), run),
              outputs=(lit, chosen, blended), device=device)
    cascade = chosen.numpy()
    s = lit.numpy()
    s[cascade < 0] = np.nan
    return s, cascade, blended.numpy().astype(bool)


def _launch_selection(depth, receivers, view_depth, *, picked: bool, device: str, **selection) -> tuple:
    """Launch :func:`selection_kernel` over ``receivers``; ``selection`` the keyword arguments of
    :func:`_selection_inputs`.

    Returns ``cascade`` int32, ``blend`` bool, the blend weights float64 and, with ``picked``, the
    receivers at their selected cascade and the next (rows 0 and 1 of coordinates ``(2, N, 2)`` int64,
    depths ``(2, N)`` float32, slopes ``(2, N, 2)`` float64; row 1 set where the blend weight is set;
    else None) as NumPy arrays.
    """
    n, inputs = _selection_inputs(depth, view_depth, device=device, **selection)
    if n == 0:
        rows = (np.zeros((2, 0, 2), np.int64), np.zeros((2, 0), np.float32), np.zeros((2, 0, 2))) if picked else None
        return np.zeros(0, np.int32), np.zeros(0, bool), np.zeros(0), rows
    chosen = wp.empty(n, dtype=wp.int32, device=device)
    blended = wp.empty(n, dtype=wp.int32, device=device)
    weight = wp.empty(n, dtype=wp.float64, device=device)
    # Without picked rows, one element stands in for each array the kernel does not write.
    shape = (2, n) if picked else (1, 1)
    picked_coords = wp.empty(shape + (2,), dtype=wp.int64, device=device)
    picked_depth = wp.empty(shape, dtype=wp.float32, device=device)
    picked_slope = wp.empty(shape, dtype=wp.vec2d, device=device)
    wp.launch(selection_kernel, dim=n, inputs=(inputs[0], receivers) + inputs[1:] + (int(picked),),
              outputs=(chosen, blended, weight, picked_coords, picked_depth, picked_slope), device=device)
    rows = (picked_coords.numpy(), picked_depth.numpy(), picked_slope.numpy()) if picked else None
    return chosen.numpy(), blended.numpy().astype(bool), weight.numpy(), rows


def _selection_inputs(depth, view_depth, *, splits, texel_area, selection: str, reach: int, margin: int,
                      blend_band: float, bits: int, device: str, band_start=None, blend_curve: int = 0,
                      sphere_cascade=None) -> tuple[int, tuple]:
    """The receivers' count and the selection's inputs of :func:`shadow_lookup_kernel` and
    :func:`selection_kernel` (all but ``receivers``, which follows the first), checked.

    ``reach`` is the taps a selected box must hold, ``margin`` the ``map`` selection's inset (widened
    to ``reach``).
    """
    selected = SELECTION_METHODS[check_name(selection, SELECTION_METHODS, field="selection")]
    if not (isinstance(reach, (int, np.integer)) and reach >= 0):
        raise ValueError(f"radius: expected a non-negative integer, got {reach!r}")
    maps = np.ascontiguousarray(depth, dtype=np.float32)
    vd = np.ascontiguousarray(view_depth, dtype=np.float64)
    z = np.ascontiguousarray(splits, dtype=np.float64)
    area = np.ascontiguousarray(texel_area, dtype=np.float64)
    count = maps.shape[0] if maps.ndim == 3 else 0
    if maps.ndim != 3 or maps.shape[1] != maps.shape[2] or count == 0:
        raise ValueError(f"depth: expected depth maps of shape (C, R, R), got {maps.shape}")
    if z.shape != (count + 1,) or area.shape != (count,):
        raise ValueError(f"splits, texel_area: expected shapes ({count + 1},), ({count},), got {z.shape}, {area.shape}")
    if band_start is None:
        # Each cascade's band: the last blend_band of its split interval (+inf: none).
        start = z[1:] - blend_band * (z[1:] - z[:-1]) if blend_band > 0.0 else np.full(count, np.inf)
    else:
        start = np.ascontiguousarray(band_start, dtype=np.float64)
    if start.shape != (count,):
        raise ValueError(f"band_start: expected shape ({count},), got {start.shape}")
    n = vd.shape[0]
    if selected.code == SELECT_SPHERE:
        if sphere_cascade is None or np.shape(sphere_cascade) != (n,):
            found = None if sphere_cascade is None else np.shape(sphere_cascade)
            raise ValueError(f"sphere_cascade: selection = \"sphere\" needs each receiver's split sphere ({n},) "
                             f"(split_sphere_cascades), got {found}")
        spheres = np.ascontiguousarray(sphere_cascade, dtype=np.int32)
    else:
        # The other selections read no sphere: one element stands in for the array.
        spheres = np.full(1, -1, dtype=np.int32)
    inputs = (wp.array(maps, dtype=wp.float32, device=device, copy=False),
              wp.array(vd, dtype=wp.float64, device=device, copy=False),
              wp.array(z, dtype=wp.float64, device=device, copy=False),
              wp.array(area, dtype=wp.float64, device=device, copy=False),
              wp.array(spheres, dtype=wp.int32, device=device, copy=False),
              int(bits), selected.code, int(reach), max(int(margin), int(reach)),
              wp.array(np.ascontiguousarray(start), dtype=wp.float64, device=device, copy=False),
              int(blend_curve))
    return n, inputs


@wp.func
def fixed_point(u: wp.float64, to_fixed: wp.float64, limit: wp.float64) -> wp.int64:
    """``u`` metres in ``2**-bits`` texels, rounded half to even; NaN maps to ``-limit`` (far outside every box)."""
    v = wp.rint(wp.clamp(u * to_fixed, -limit, limit))
    if is_nan(v):
        v = -limit
    return wp.int64(v)


@wp.func
def light_space(v: wp.vec3d, basis: wp.mat33d, row: int) -> wp.float64:
    """Component ``row`` of ``v`` in the light basis, summed in the order of the host's
    ``csmlab.texels._light_space``."""
    return (v[0] * basis[row, 0] + v[2] * basis[row, 2]) + v[1] * basis[row, 1]


@wp.kernel
def receiver_coordinates_kernel(
    receivers: WorldReceivers,
    coords: wp.array3d(dtype=wp.int64),
    depth: wp.array2d(dtype=wp.float32),
    slope: wp.array3d(dtype=wp.float64),
):
    k = wp.tid()
    light = receiver_light(receivers, k)
    c = int(0)
    while c < coords.shape[0]:
        x, y, d, s = receiver_in(receivers, light, c, k)
        coords[c, k, 0] = x
        coords[c, k, 1] = y
        depth[c, k] = d
        slope[c, k, 0] = s[0]
        slope[c, k, 1] = s[1]
        c += 1


def receiver_coordinates(points, normals, *, basis, texel_size, origin_fixed, zref: float, bits: int,
                         bias: BiasSettings, receivers=None,
                         device: str = "cpu") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`csmlab.texels.receiver_lookup` on the device, from world receivers.

    Parameters
    ----------
    points : array_like, shape (M, 3), float64
        World positions in metres.
    normals : array_like, shape (M, 3), float32
        Their unit normals.
    basis : array_like, shape (3, 3), float64
        The light basis (:attr:`csmlab.cascades.CascadeSet.basis`): rows x, y and the light direction.
    texel_size : array_like, shape (C, 2), float64
        Metres per texel of each cascade.
    origin_fixed : array_like, shape (C, 2), int64
        Box origins in ``2**-bits`` texels (:func:`csmlab.texels.fixed_point_origin`).
    zref : float
        The cascades' depth offset, metres.
    bits : int
        Sub-texel bits.
    bias : BiasSettings
        The normal offset and depth bias (docs/design.md ``[shadow]``); its ``bias_constant`` may be one value per
        cascade ``(C,)`` (a bias model's per-cascade scaling, csmlab.filters).
    receivers : array_like, shape (N,), integer, optional
        The rows of ``points`` and ``normals`` that are receivers, in output order; None: all.
    device : str

    Returns
    -------
    coordinates, depth, slope
        As :func:`csmlab.texels.receiver_lookup` of the receivers, bit for bit: ``(C, N, 2)`` int64,
        ``(C, N)`` float32, ``(C, N, 2)`` float64.
    """
    device = checked_device(device)
    world = world_receivers(points, normals, receivers=receivers, basis=basis, texel_size=texel_size,
                            origin_fixed=origin_fixed,
                            zref=zref, bits=bits, bias=bias, planar=True, device=device)
    shape = (world.texel_size.shape[0], world.index.shape[0])
    coords = wp.empty(shape + (2,), dtype=wp.int64, device=device)
    depth = wp.empty(shape, dtype=wp.float32, device=device)
    slope = wp.empty(shape + (2,), dtype=wp.float64, device=device)
    if shape[1]:
        wp.launch(receiver_coordinates_kernel, dim=shape[1], inputs=(world,), outputs=(coords, depth, slope),
                  device=device)
    return coords.numpy(), depth.numpy(), slope.numpy()


def world_receivers(points, normals, *, receivers, basis, texel_size, origin_fixed, zref: float, bits: int,
                    bias: BiasSettings, planar: bool, device: str) -> WorldReceivers:
    """The :class:`WorldReceivers` of :func:`receiver_coordinates`'s arguments, checked (``planar``: receiver-plane
    slopes)."""
    p = np.ascontiguousarray(points, dtype=np.float64)
    n = np.ascontiguousarray(normals, dtype=np.float32)
    rows = np.ascontiguousarray(basis, dtype=np.float64)
    size = np.ascontiguousarray(texel_size, dtype=np.float64)
    corner = np.ascontiguousarray(origin_fixed, dtype=np.int64)
    if p.ndim != 2 or p.shape[1] != 3 or n.shape != p.shape or rows.shape != (3, 3) or size.ndim != 2 \
            or size.shape[1] != 2 or corner.shape != size.shape:
        raise ValueError(f"points, normals, basis, texel_size, origin_fixed: expected shapes (M, 3), (M, 3), (3, 3), "
                         f"(C, 2), (C, 2); got {p.shape}, {n.shape}, {rows.shape}, {size.shape}, {corner.shape}")
    index = np.arange(p.shape[0], dtype=np.int32) if receivers is None else np.ascontiguousarray(receivers, np.int32)
    if index.ndim != 1 or (index.size and (index.min() < 0 or index.max() >= p.shape[0])):
        raise ValueError(f"receivers: expected row indices in [0, {p.shape[0]}), got shape {index.shape}")
    texel = size.max(axis=1)
    world = WorldReceivers()
    world.points = wp.array(p, dtype=wp.vec3d, device=device, copy=False)
    world.normals = wp.array(n, dtype=wp.vec3, device=device, copy=False)
    world.index = wp.array(index, dtype=wp.int32, device=device, copy=False)
    world.basis = wp.mat33d(*rows.reshape(-1))
    world.texel_size = wp.array(size, dtype=wp.float64, device=device)
    world.to_fixed = wp.array(float(2**bits) / size, dtype=wp.float64, device=device)
    world.origin_fixed = wp.array(corner, dtype=wp.int64, device=device)
    world.zref = float(zref)
    world.limit = float(2**50)
    world.bias = receiver_bias(texel, bias, device=device)
    world.planar = int(bool(planar))
    return world


@wp.kernel
def split_sphere_kernel(points: wp.array(dtype=wp.vec3d), centres: wp.array(dtype=wp.vec3d),
                        radii_squared: wp.array(dtype=wp.float64), first: wp.array(dtype=wp.int32)):
    k = wp.tid()
    p = points[k]
    first[k] = -1
    c = int(centres.shape[0]) - 1
    # Scanning down leaves the first sphere holding the point, as Unity's weights.yzw -= weights.xyz does.
    while c >= 0:
        v = p - centres[c]
        if wp.dot(v, v) < radii_squared[c]:
            first[k] = c
        c -= 1


def split_sphere_cascades(points, *, centres, radii, device: str = "cpu") -> np.ndarray:
    """The first cascade whose split sphere holds each point: Unity's sphere selection.

    Unity built-in (``getCascadeWeights_splitSpheres``, Internal-ScreenSpaceShadows.shader) and URP
    (``ComputeCascadeIndex``, Shadows.hlsl) compare ``dot(X − c_i, X − c_i) < r_i²`` for every
    cascade and keep the first that holds the point.

    Parameters
    ----------
    points : array_like, shape (N, 3), float64
        World positions, metres (a NaN point lies in no sphere).
    centres : array_like, shape (C, 3), float64
        Each cascade's split-sphere centre, world metres.
    radii : array_like, shape (C,), float64
        Their radii, metres.
    device : str
        ``"cpu"`` or ``"cuda"``.

    Returns
    -------
    ndarray, shape (N,), int32
        The first cascade ``i`` with ``|X − c_i|² < r_i²``; −1 where none.
    """
    device = checked_device(device)
    p = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3))
    c = np.ascontiguousarray(np.asarray(centres, dtype=np.float64).reshape(-1, 3))
    r = np.asarray(radii, dtype=np.float64).reshape(-1)
    if r.shape[0] != c.shape[0]:
        raise ValueError(f"centres, radii: expected one radius per centre, got {c.shape[0]} and {r.shape[0]}")
    first = wp.empty(p.shape[0], dtype=wp.int32, device=device)
    if p.shape[0]:
        wp.launch(split_sphere_kernel, dim=p.shape[0],
                  inputs=(wp.array(p, dtype=wp.vec3d, device=device), wp.array(c, dtype=wp.vec3d, device=device),
                          wp.array(np.ascontiguousarray(r * r), dtype=wp.float64, device=device)),
                  outputs=(first,), device=device)
    return first.numpy()
