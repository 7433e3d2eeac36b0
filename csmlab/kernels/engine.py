"""An engine's float32 pipeline on the device: vertices and receivers to window space, bit for bit as the host's.

:mod:`csmlab.texels` states the pipeline in NumPy (:func:`csmlab.texels.engine_matrix`,
:func:`~csmlab.texels.window_positions`, :func:`~csmlab.texels.receiver_lookup`); the host builds
each cascade's float32 matrix (twelve numbers), and the kernels here apply it to every vertex and
receiver with the same float32 operations in the same order, one rounding per operation
(``fuse_fp`` off: no fused multiply-add on either device). Window-space snapping of float64
coordinates (``vertex_snap = "window"``) is the same pass with float64 light-space input.

- :func:`window_vertices`: every vertex in every cascade's doubled fixed point and its depth in
  metres, what :func:`csmlab.kernels.raster.rasterize_cascades` takes as converted vertices;
  :func:`window_chunk_vertices` the same for the vertices of chosen chunks of triangles only, with
  the chunks' rectangles;
- :func:`window_receivers`: receivers' fixed point, biased depth and receiver-plane slope, what
  :func:`csmlab.kernels.shadow.shadow_lookup` reads;
- :func:`warped_vertices`, :func:`warped_receivers`: vertices and receivers through a
  perspective-warped cascade's homography (``warp``, :mod:`csmlab.cascades.warp`), in float64 as
  the host's :func:`csmlab.render.warped_depth_map` and :func:`csmlab.texels.receiver_lookup`.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from csmlab.kernels import checked_device, device_empty
from csmlab.kernels.bias import BiasSettings, ReceiverBias, receiver_bias
from csmlab.kernels.floats import is_nan
from csmlab.kernels.raster.kernels import vec2l
from csmlab.kernels.raster.mesh import checked_chunk_vertices
from csmlab.kernels.threads import LaunchPool, checked_threads, split_range
from csmlab.lookup_choices import NORMAL_NONE, NORMAL_ONE_MINUS_COS_LATERAL, NORMAL_SIN

__all__ = ["EngineBoxes", "EngineReceivers", "engine_boxes", "engine_receivers", "warped_receivers", "warped_vertices",
           "window_chunk_vertices", "window_receivers", "window_vertices"]

# Products and sums rounded one by one on both devices, as NumPy rounds them.
wp.set_module_options({"fuse_fp": False})

mat34f = wp.types.matrix(shape=(3, 4), dtype=wp.float32)
"""A cascade's world-to-clip matrix (:func:`csmlab.texels.engine_matrix`)."""

WINDOW_FLOAT32 = 0
"""Mode of :class:`EngineBoxes`: float32 positions through the float32 matrices (``engine_precision``)."""
WINDOW_FLOAT64 = 1
"""Mode of :class:`EngineBoxes`: float64 light-space coordinates snapped in window space (``vertex_snap``)."""


@wp.struct
class EngineBoxes:
    """Every cascade as the window-space pass reads it."""

    mode: int
    """:data:`WINDOW_FLOAT32` or :data:`WINDOW_FLOAT64`."""
    matrix: wp.array(dtype=mat34f)
    """Each cascade's float32 world-to-clip matrix (float32 mode)."""
    half: wp.array(dtype=wp.float32)
    """``R_c / 2`` of each cascade in float32: the viewport's scale and offset (float32 mode)."""
    origin: wp.vec3d
    """The world origin the float32 positions are taken from, metres (:func:`csmlab.texels.engine_origin`)."""
    depth_near: wp.array(dtype=wp.float64)
    """``depth_near − zref`` of each cascade, metres: window depth 0 (float32 mode)."""
    depth_span: wp.array(dtype=wp.float64)
    """``depth_far − depth_near`` of each cascade, metres: window depth 1 less depth 0 (float32 mode)."""
    texel_size: wp.array(dtype=wp.vec2d)
    """Metres per texel of each cascade (float64 mode)."""
    corner: wp.array(dtype=wp.vec2d)
    """Each box's minimum corner in texels (float64 mode)."""
    scale: wp.float32
    """``2**bits``: fixed-point steps per texel."""
    limit: wp.float64
    """The clip of fixed-point values, ±2**50 (:mod:`csmlab.texels`)."""


def engine_boxes(*, mode: str, bits: int, matrices=None, resolution=None, origin=None, depth_near=None,
                 depth_span=None, texel_size=None, corner=None, device: str = "cpu") -> EngineBoxes:
    """The :class:`EngineBoxes` of C cascades, checked, on ``device``.

    Parameters
    ----------
    mode : str
        ``"float32"``: an engine's pipeline, which reads ``matrices`` ``(C, 3, 4)`` float32
        (:func:`csmlab.texels.engine_matrix`), ``resolution`` ``(C,)`` texels per side,
        ``origin`` ``(3,)`` world metres (:func:`csmlab.texels.engine_origin`), ``depth_near`` and
        ``depth_span`` ``(C,)`` metres (``depth_near − zref``, ``depth_far − depth_near``).
        ``"float64"``: window-space snapping of float64 coordinates, which reads ``texel_size``
        ``(C, 2)`` metres and ``corner`` ``(C, 2)`` texels (the boxes' origins).
    bits : int
        Sub-texel bits (0..16).
    device : str
    """
    device = checked_device(device)
    if not (isinstance(bits, (int, np.integer)) and 0 <= bits <= 16):
        raise ValueError(f"bits: expected an integer in 0..16, got {bits!r}")
    boxes = EngineBoxes()
    boxes.scale = float(2**int(bits))
    boxes.limit = float(2**50)
    empty64 = wp.zeros(0, dtype=wp.float64, device=device)
    empty2 = wp.zeros(0, dtype=wp.vec2d, device=device)
    if mode == "float32":
        m = np.ascontiguousarray(matrices, dtype=np.float32)
        size = np.asarray(resolution, dtype=np.float64).reshape(-1)
        near = np.ascontiguousarray(depth_near, dtype=np.float64).reshape(-1)
        span = np.ascontiguousarray(depth_span, dtype=np.float64).reshape(-1)
        o = np.asarray(origin, dtype=np.float64).reshape(-1)
        if m.ndim != 3 or m.shape[1:] != (3, 4) or size.shape != (m.shape[0],) or near.shape != size.shape \
                or span.shape != size.shape or o.shape != (3,):
            raise ValueError(f"matrices, resolution, depth_near, depth_span, origin: expected shapes (C, 3, 4), (C,), "
                             f"(C,), (C,), (3,); got {m.shape}, {size.shape}, {near.shape}, {span.shape}, {o.shape}")
        boxes.mode = WINDOW_FLOAT32
        boxes.matrix = wp.array(m, dtype=mat34f, device=device)
        boxes.half = wp.array((0.5 * size).astype(np.float32), dtype=wp.float32, device=device)
        boxes.origin = wp.vec3d(*o)
        boxes.depth_near = wp.array(near, dtype=wp.float64, device=device)
        boxes.depth_span = wp.array(span, dtype=wp.float64, device=device)
        boxes.texel_size = empty2
        boxes.corner = empty2
    elif mode == "float64":
        size = np.ascontiguousarray(texel_size, dtype=np.float64)
        c = np.ascontiguousarray(corner, dtype=np.float64)
        if size.ndim != 2 or size.shape[1] != 2 or c.shape != size.shape:
            raise ValueError(f"texel_size, corner: expected shapes (C, 2), (C, 2); got {size.shape}, {c.shape}")
        boxes.mode = WINDOW_FLOAT64
        boxes.matrix = wp.zeros(0, dtype=mat34f, device=device)
        boxes.half = wp.zeros(0, dtype=wp.float32, device=device)
        boxes.origin = wp.vec3d(0.0, 0.0, 0.0)
        boxes.depth_near = empty64
        boxes.depth_span = empty64
        boxes.texel_size = wp.array(size, dtype=wp.vec2d, device=device)
        boxes.corner = wp.array(c, dtype=wp.vec2d, device=device)
    else:
        raise ValueError(f"mode: expected 'float32' or 'float64', got {mode!r}")
    return boxes


@wp.func
def snapped(u: wp.float64, limit: wp.float64) -> wp.int64:
    """``u`` (fixed-point units) clipped to ±``limit`` and rounded half to even; NaN maps to ``-limit``.

    :func:`csmlab.texels._snapped`.
    """
    v = wp.rint(wp.clamp(u, -limit, limit))
    if is_nan(v):
        v = -limit
    return wp.int64(v)


@wp.func
def clip_row(m: mat34f, row: int, x: wp.float32, y: wp.float32, z: wp.float32) -> wp.float32:
    """Clip coordinate ``row`` of a float32 position: ``((m0·x + m1·y) + m2·z) + m3``
    (:func:`csmlab.texels.window_positions`)."""
    return ((x * m[row, 0] + y * m[row, 1]) + z * m[row, 2]) + m[row, 3]


@wp.func
def window_fixed(clip: wp.float32, half: wp.float32, scale: wp.float32, limit: wp.float64) -> wp.int64:
    """A clip x or y to the viewport (``clip · R/2 + R/2``, float32), snapped to ``2**-bits`` texels."""
    window = clip * half + half
    return snapped(wp.float64(window * scale), limit)


@wp.func
def float32_position(p: wp.vec3d, origin: wp.vec3d) -> wp.vec3:
    """``p − origin`` in float64, rounded once to float32 (:func:`csmlab.texels.engine_positions`)."""
    return wp.vec3(wp.float32(p[0] - origin[0]), wp.float32(p[1] - origin[1]), wp.float32(p[2] - origin[2]))


@wp.func
def float32_window_vertex(position: wp.vec3d, origin: wp.vec3d, m: mat34f, half: wp.float32, near: wp.float64,
                          span: wp.float64, scale: wp.float32, limit: wp.float64):
    """A world vertex through a cascade's float32 pipeline: its doubled fixed point and its stored depth in metres."""
    p = float32_position(position, origin)
    x = window_fixed(clip_row(m, 0, p[0], p[1], p[2]), half, scale, limit)
    y = window_fixed(clip_row(m, 1, p[0], p[1], p[2]), half, scale, limit)
    return vec2l(wp.int64(2) * x, wp.int64(2) * y), near + wp.float64(clip_row(m, 2, p[0], p[1], p[2])) * span


@wp.kernel
def window_chunks_kernel(
    positions: wp.array(dtype=wp.vec3d),
    boxes: EngineBoxes,
    starts: wp.array(dtype=wp.int32),
    vertices: wp.array(dtype=wp.int32),
    pairs: wp.array2d(dtype=wp.int32),
    points: wp.array2d(dtype=vec2l),
    depth: wp.array2d(dtype=wp.float64),
    lo: wp.array2d(dtype=vec2l),
    hi: wp.array2d(dtype=vec2l),
):
    """Pair n = (cascade c, chunk k): the chunk's vertices through cascade c's float32 pipeline into ``points[c]`` and
    ``depth[c]``, and their rectangle into ``lo[c, k]``, ``hi[c, k]``; a thread per pair.

    A vertex of several chunks is written by each of their threads, with the same values.
    """
    n = wp.tid()
    c = pairs[n, 0]
    k = pairs[n, 1]
    m = boxes.matrix[c]
    half = boxes.half[c]
    near = boxes.depth_near[c]
    span = boxes.depth_span[c]
    t = starts[k]
    end = starts[k + 1]
    # Every chunk has a vertex: the rectangle starts at the largest and smallest values and shrinks to them.
    big = wp.int64(9223372036854775807)
    low = vec2l(big, big)
    high = vec2l(-big, -big)
    while t < end:
        v = vertices[t]
        point, z = float32_window_vertex(positions[v], boxes.origin, m, half, near, span, boxes.scale, boxes.limit)
        points[c, v] = point
        depth[c, v] = z
        low = vec2l(wp.min(low[0], point[0]), wp.min(low[1], point[1]))
        high = vec2l(wp.max(high[0], point[0]), wp.max(high[1], point[1]))
        t += 1
    lo[c, k] = low
    hi[c, k] = high


@wp.kernel
def window_vertices_kernel(
    positions: wp.array(dtype=wp.vec3d),
    light_xy: wp.array(dtype=wp.vec2d),
    light_depth: wp.array(dtype=wp.float64),
    boxes: EngineBoxes,
    first: int,
    last: int,
    run: int,
    points: wp.array2d(dtype=vec2l),
    depth: wp.array2d(dtype=wp.float64),
):
    """``points[c, v]``, ``depth[c, v]``: vertex v of ``[first, last)`` in cascade c's doubled fixed point and its
    stored depth in metres; a thread per cascade and run of ``run`` vertices."""
    c, k = wp.tid()
    v = first + k * run
    end = wp.min(v + run, last)
    scale = boxes.scale
    limit = boxes.limit
    two = wp.int64(2)
    if boxes.mode == WINDOW_FLOAT32:
        m = boxes.matrix[c]
        half = boxes.half[c]
        near = boxes.depth_near[c]
        span = boxes.depth_span[c]
        while v < end:
            point, z = float32_window_vertex(positions[v], boxes.origin, m, half, near, span, scale, limit)
            points[c, v] = point
            depth[c, v] = z
            v += 1
    else:
        size = boxes.texel_size[c]
        corner = boxes.corner[c]
        fixed = wp.float64(scale)
        while v < end:
            u = light_xy[v]
            x = snapped((u[0] / size[0] - corner[0]) * fixed, limit)
            y = snapped((u[1] / size[1] - corner[1]) * fixed, limit)
            points[c, v] = vec2l(two * x, two * y)
            depth[c, v] = light_depth[v]
            v += 1


_VERTEX_RUN = 256
"""Vertices a CPU thread of :func:`window_vertices` converts (a GPU thread one)."""


def window_vertices(boxes: EngineBoxes, *, positions=None, light_xy=None, light_depth=None, threads: int = 1,
                    device: str = "cpu") -> tuple[np.ndarray, np.ndarray]:
    """Every vertex in every cascade's window-space fixed point, doubled, and its stored depth.

    Parameters
    ----------
    boxes : EngineBoxes
        :func:`engine_boxes`, on ``device``.
    positions : array_like, shape (V, 3), float64
        World positions, metres (float32 mode).
    light_xy : array_like, shape (V, 2), float64
        Light-space x/y, metres (:func:`csmlab.texels.light_plane_coordinates`; float64 mode).
    light_depth : array_like, shape (V,), float64
        ``d·X − zref``, metres (float64 mode: the stored depth).
    threads : int
        CPU launches run at once, each over its own range of vertices. Ignored on CUDA.
    device : str

    Returns
    -------
    points : ndarray, shape (C, V, 2), int64
        Twice :func:`csmlab.texels.fixed_point_coordinates` (``engine_precision`` float32 or
        camera_relative; or ``vertex_snap = "window"``), bit for bit.
    depth : ndarray, shape (C, V), float64
        :func:`csmlab.texels.vertex_depth`, bit for bit: the float32 window depth in metres, or the
        float64 light depth.
    """
    device = checked_device(device)
    float32 = boxes.mode == WINDOW_FLOAT32
    count = boxes.matrix.shape[0] if float32 else boxes.texel_size.shape[0]
    if float32:
        p = np.ascontiguousarray(positions, dtype=np.float64)
        if p.ndim != 2 or p.shape[1] != 3:
            raise ValueError(f"positions: expected world positions of shape (V, 3), got {p.shape}")
        vertices = p.shape[0]
        inputs = (wp.array(p, dtype=wp.vec3d, device=device, copy=False), wp.zeros(0, dtype=wp.vec2d, device=device),
                  wp.zeros(0, dtype=wp.float64, device=device))
    else:
        xy = np.ascontiguousarray(light_xy, dtype=np.float64)
        z = np.ascontiguousarray(light_depth, dtype=np.float64)
        if xy.ndim != 2 or xy.shape[1] != 2 or z.shape != (xy.shape[0],):
            raise ValueError(f"light_xy, light_depth: expected shapes (V, 2), (V,); got {xy.shape}, {z.shape}")
        vertices = xy.shape[0]
        inputs = (wp.zeros(0, dtype=wp.vec3d, device=device), wp.array(xy, dtype=wp.vec2d, device=device, copy=False),
                  wp.array(z, dtype=wp.float64, device=device, copy=False))
    points = device_empty((count, vertices), vec2l, device)
    depth = device_empty((count, vertices), wp.float64, device)
    if count and vertices:
        run = _VERTEX_RUN if wp.get_device(device).is_cpu else 1

        def launch(lo: int, hi: int) -> None:
            wp.launch(window_vertices_kernel, dim=(count, -(-(hi - lo) // run)), inputs=(*inputs, boxes, lo, hi, run),
                      outputs=(points, depth), device=device)

        parts = checked_threads(threads, device)
        with LaunchPool(parts, kernels=(window_vertices_kernel,), device=device) as pool:
            pool.run([lambda lo=lo, hi=hi: launch(lo, hi) for lo, hi in split_range(vertices, pool.threads)])
    return points.numpy().view(np.int64).reshape(count, vertices, 2), depth.numpy()


def window_chunk_vertices(boxes: EngineBoxes, *, positions, vertices, pairs, threads: int = 1,
                          device: str = "cpu") -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The vertices of chosen chunks in chosen cascades' window space, and the chunks' rectangles there.

    :func:`window_vertices` of an engine's float32 pipeline for the vertices a depth pass will read
    only: those of the chunks of triangles that may reach a cascade's map (chosen on the host from a
    bound, :func:`csmlab.texels.window_rectangles`), with each chunk's exact rectangle
    (:func:`csmlab.kernels.raster.converted_region_chunks`'s) found in the same pass.

    Parameters
    ----------
    boxes : EngineBoxes
        :func:`engine_boxes` in float32 mode, C cascades, on ``device``.
    positions : array_like, shape (V, 3), float64
        World positions, metres.
    vertices : ChunkVertices
        The vertices of each of the K chunks (:func:`csmlab.kernels.raster.mesh.chunk_vertices`).
    pairs : array_like, shape (P, 2), integer
        ``(cascade, chunk)`` rows to convert, each once.
    threads : int
        CPU launches run at once, each over its own pairs. Ignored on CUDA.
    device : str

    Returns
    -------
    points : ndarray, shape (C, V, 2), int64
        :func:`window_vertices`'s at the vertices of the pairs' chunks in their cascades, 0 elsewhere.
    depth : ndarray, shape (C, V), float64
        Likewise its depths, 0 elsewhere.
    low, high : ndarray, shape (C, K, 2), int64
        Each pair's chunk's rectangle of ``points``; an empty one (low above high) for the other pairs.
    """
    device = checked_device(device)
    if boxes.mode != WINDOW_FLOAT32:
        raise ValueError("boxes: expected an engine's float32 pipeline (engine_boxes(mode='float32'))")
    p = np.ascontiguousarray(positions, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"positions: expected world positions of shape (V, 3), got {p.shape}")
    starts, listed = checked_chunk_vertices(vertices, vertex_count=p.shape[0])
    rows = np.ascontiguousarray(pairs, dtype=np.int32).reshape(-1, 2)
    count, chunks = boxes.matrix.shape[0], starts.size - 1
    if rows.size and (rows[:, 0].min() < 0 or rows[:, 0].max() >= count or rows[:, 1].min() < 0
                      or rows[:, 1].max() >= chunks):
        raise ValueError(f"pairs: expected rows of a cascade in [0, {count}) and a chunk in [0, {chunks}), got "
                         f"cascades {rows[:, 0].min()}..{rows[:, 0].max()}, "
                         f"chunks {rows[:, 1].min()}..{rows[:, 1].max()}")
    # Zeros where no pair writes: within every bound the depth pass checks, and never read by it.
    points = np.zeros((count, p.shape[0], 2), dtype=np.int64)
    depth = np.zeros((count, p.shape[0]), dtype=np.float64)
    low = np.full((count, chunks, 2), np.iinfo(np.int64).max, dtype=np.int64)
    high = np.full((count, chunks, 2), np.iinfo(np.int64).min, dtype=np.int64)
    if rows.shape[0]:
        arrays = [wp.array(a, dtype=t, device=device, copy=False)
                  for a, t in ((points, vec2l), (depth, wp.float64), (low, vec2l), (high, vec2l))]
        inputs = (wp.array(p, dtype=wp.vec3d, device=device, copy=False), boxes,
                  wp.array(starts, dtype=wp.int32, device=device, copy=False),
                  wp.array(listed, dtype=wp.int32, device=device, copy=False))

        def launch(lo: int, hi: int) -> None:
            wp.launch(window_chunks_kernel, dim=hi - lo,
                      inputs=(*inputs, wp.array(rows[lo:hi], dtype=wp.int32, device=device)), outputs=arrays,
                      device=device)

        with LaunchPool(checked_threads(threads, device), kernels=(window_chunks_kernel,), device=device) as pool:
            pool.run([lambda lo=lo, hi=hi: launch(lo, hi) for lo, hi in split_range(rows.shape[0], pool.threads)])
        if not wp.get_device(device).is_cpu:
            points, depth, low, high = (a.numpy().reshape(shape) for a, shape in
                                        zip(arrays, (points.shape, depth.shape, low.shape, high.shape)))
    return points, depth, low, high


@wp.struct
class EngineReceivers:
    """Receivers and what takes them into every cascade's window space (:func:`window_receivers`)."""

    points: wp.array(dtype=wp.vec3d)
    normals: wp.array(dtype=wp.vec3)
    index: wp.array(dtype=wp.int32)
    basis: wp.mat33d
    texel_size: wp.array(dtype=wp.vec2d)
    bias: ReceiverBias
    zref: wp.float64
    scale: wp.float64
    """``2**bits`` (the warped receivers' snap; the window boxes hold their own)."""
    limit: wp.float64
    """The clip of fixed-point values, ±2**50."""


@wp.func
def light_space(v: wp.vec3d, basis: wp.mat33d, row: int) -> wp.float64:
    """Component ``row`` of ``v`` in the light basis, summed as ``csmlab.texels._light_space``:
    ``(x·r_x + z·r_z) + y·r_y``."""
    return (v[0] * basis[row, 0] + v[2] * basis[row, 2]) + v[1] * basis[row, 1]


@wp.func
def light_space_xyz(v: wp.vec3d, basis: wp.mat33d):
    """The three components of ``v`` in the light basis, each as :func:`light_space` sums it."""
    return light_space(v, basis, 0), light_space(v, basis, 1), light_space(v, basis, 2)


@wp.func
def receiver_slopes(nx: wp.float64, ny: wp.float64, nz: wp.float64, max_tan: wp.float64, normal_scale: int):
    """A receiver's normal ``(nx, ny, nz)`` in light space (z away from the light) as the biases read it:
    ``tan θ`` (NaN where the normal turns from the light, else at most ``max_tan``), the receiver plane's
    slopes ``(−nx/nz, −ny/nz)`` clamped to ±``max_tan`` (0 where turned away), and the normal offset's
    factor of ``normal_scale`` — :func:`csmlab.texels.receiver_lookup`'s operations in its order."""
    zero = wp.float64(0.0)
    one = wp.float64(1.0)
    cos = -nz
    tan = wp.float64(wp.nan)
    plane_x = zero
    plane_y = zero
    if cos > zero:
        tan = wp.min(wp.sqrt(wp.max(one - cos * cos, zero)) / cos, max_tan)
        plane_x = nx / cos
        plane_y = ny / cos
    plane_x = wp.clamp(plane_x, -max_tan, max_tan)
    plane_y = wp.clamp(plane_y, -max_tan, max_tan)
    factor = one
    if normal_scale == NORMAL_SIN:
        factor = wp.sqrt(wp.max(one - cos * cos, zero))
    elif normal_scale == NORMAL_ONE_MINUS_COS_LATERAL:
        # Godot's light_dir points toward the light: 1 − max(0, dot(light_dir, −N)) (csmlab.texels.receiver_lookup).
        factor = one - wp.max(-cos, zero)
    elif normal_scale != NORMAL_NONE:
        factor = one - wp.max(cos, zero)
    return tan, plane_x, plane_y, factor


@wp.struct
class WindowPoint:
    """One receiver as every cascade's window-space conversion reads it (:func:`window_point`): its point and normal
    in float32 (``p32`` from the boxes' origin, float32 mode) and in the light's basis, and its normal's slopes
    (:func:`receiver_slopes`)."""

    p32: wp.vec3
    n32: wp.vec3
    px: wp.float64
    py: wp.float64
    pz: wp.float64
    nx: wp.float64
    ny: wp.float64
    nz: wp.float64
    tan: wp.float64
    plane_x: wp.float64
    plane_y: wp.float64
    factor: wp.float64


@wp.func
def window_point(r: EngineReceivers, boxes: EngineBoxes, k: int) -> WindowPoint:
    """Receiver k's :class:`WindowPoint`: computed once per receiver, whichever cascades it is taken into."""
    point = r.points[r.index[k]]
    n32 = r.normals[r.index[k]]
    normal = wp.vec3d(n32)
    px, py, pz = light_space_xyz(point, r.basis)
    nx, ny, nz = light_space_xyz(normal, r.basis)
    tan, plane_x, plane_y, factor = receiver_slopes(nx, ny, nz, r.bias.max_tan, r.bias.normal_scale)
    w = WindowPoint()
    w.n32 = n32
    w.px = px
    w.py = py
    w.pz = pz
    w.nx = nx
    w.ny = ny
    w.nz = nz
    w.tan = tan
    w.plane_x = plane_x
    w.plane_y = plane_y
    w.factor = factor
    if boxes.mode == WINDOW_FLOAT32:
        w.p32 = float32_position(point, boxes.origin)
    return w


@wp.func
def window_in(r: EngineReceivers, boxes: EngineBoxes, w: WindowPoint, c: int):
    """The receiver ``w`` in cascade c: fixed-point ``x, y``, biased depth (float32) and receiver-plane slopes
    ``sx, sy`` — :func:`csmlab.texels.receiver_lookup`'s operations in its order."""
    zero = wp.float64(0.0)
    one = wp.float64(1.0)
    size = r.texel_size[c]
    offset = r.bias.offset[c]
    if r.bias.normal_scale != NORMAL_NONE:
        offset = offset * w.factor
    sx = w.plane_x * size[0]
    sy = w.plane_y * size[1]
    bias = r.bias.bias_constant[c] + r.bias.slope_bias[c] * w.tan
    scale = boxes.scale
    limit = boxes.limit
    x = wp.int64(0)
    y = wp.int64(0)
    depth = wp.float32(0.0)
    if boxes.mode == WINDOW_FLOAT32:
        m = boxes.matrix[c]
        half = boxes.half[c]
        o32 = wp.float32(offset)
        p32 = w.p32
        n32 = w.n32
        mx = p32[0] + n32[0] * o32
        my = p32[1] + n32[1] * o32
        mz = p32[2] + n32[2] * o32
        x = window_fixed(clip_row(m, 0, mx, my, mz), half, scale, limit)
        y = window_fixed(clip_row(m, 1, mx, my, mz), half, scale, limit)
        wz = clip_row(m, 2, mx, my, mz)
        if r.bias.normal_scale == NORMAL_ONE_MINUS_COS_LATERAL:
            wz = clip_row(m, 2, p32[0], p32[1], p32[2])
        if r.bias.plane_offset[c] > zero:
            bias = bias + wp.min(wp.abs(sx) + wp.abs(sy), r.bias.plane_offset[c])
        depth = wp.float32((boxes.depth_near[c] + wp.float64(wz) * boxes.depth_span[c]) - bias)
    else:
        # csmlab.texels.receiver_lookup's window snap: u = n·offset + p, then / texel, − corner, · 2**bits.
        corner = boxes.corner[c]
        fixed = wp.float64(scale)
        ux = w.nx * offset + w.px
        uy = w.ny * offset + w.py
        x = snapped(((ux / size[0]) - corner[0]) * fixed, limit)
        y = snapped(((uy / size[1]) - corner[1]) * fixed, limit)
        if r.bias.plane_offset[c] > zero:
            bias = bias + wp.min(wp.abs(sx) + wp.abs(sy), r.bias.plane_offset[c])
        along = one
        if r.bias.normal_scale == NORMAL_ONE_MINUS_COS_LATERAL:
            along = zero
        depth = wp.float32(((w.pz + along * offset * w.nz) - r.zref) - bias)
    return x, y, depth, sx, sy


@wp.kernel
def window_receivers_kernel(
    r: EngineReceivers,
    boxes: EngineBoxes,
    coords: wp.array3d(dtype=wp.int64),
    depth: wp.array2d(dtype=wp.float32),
    slope: wp.array3d(dtype=wp.float64),
):
    """Receiver k in every cascade (:func:`window_in`)."""
    k = wp.tid()
    w = window_point(r, boxes, k)
    c = int(0)
    while c < coords.shape[0]:
        x, y, d, sx, sy = window_in(r, boxes, w, c)
        coords[c, k, 0] = x
        coords[c, k, 1] = y
        depth[c, k] = d
        slope[c, k, 0] = sx
        slope[c, k, 1] = sy
        c += 1


def window_receivers(boxes: EngineBoxes, points, normals, *, basis, texel_size, zref: float, bias: BiasSettings,
                     receivers=None, device: str = "cpu") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`csmlab.texels.receiver_lookup` of window-space cascades on the device (``engine_precision`` float32 or
    camera_relative, or ``vertex_snap = "window"``), bit for bit.

    Parameters
    ----------
    boxes : EngineBoxes
        :func:`engine_boxes` of the cascades, on ``device``.
    points : array_like, shape (M, 3), float64
        World positions in metres.
    normals : array_like, shape (M, 3), float32
        Their unit normals, as a float32 G-buffer holds them.
    basis : array_like, shape (3, 3), float64
        The light basis (:attr:`csmlab.cascades.CascadeSet.basis`).
    texel_size : array_like, shape (C, 2), float64
        Metres per texel of each cascade.
    zref : float
        The cascades' depth offset, metres.
    bias : BiasSettings
        The normal offset and depth bias, as :func:`csmlab.texels.receiver_lookup`'s arguments of those names.
    receivers : array_like, shape (N,), integer, optional
        The rows of ``points`` and ``normals`` that are receivers, in output order; None: all.
    device : str

    Returns
    -------
    coordinates : ndarray, shape (C, N, 2), int64
    depth : ndarray, shape (C, N), float32
    slope : ndarray, shape (C, N, 2), float64
        As :func:`csmlab.texels.receiver_lookup` of ``points[receivers]``, ``normals[receivers]``.
    """
    device = checked_device(device)
    count = boxes.matrix.shape[0] if boxes.mode == WINDOW_FLOAT32 else boxes.texel_size.shape[0]
    r = engine_receivers(points, normals, basis=basis, texel_size=texel_size, zref=zref, bias=bias,
                          receivers=receivers, cascades=count, device=device)
    return _launched(window_receivers_kernel, (r, boxes), count, r.index.shape[0], device)


def engine_receivers(points, normals, *, basis, texel_size, zref: float, bias: BiasSettings, receivers,
                     cascades: int, device: str) -> EngineReceivers:
    """The :class:`EngineReceivers` of :func:`window_receivers`' arguments for ``cascades`` cascades, checked (also
    what :func:`csmlab.kernels.shadow.shadow_lookup_window` takes into window space where it reads them)."""
    p = np.ascontiguousarray(points, dtype=np.float64)
    n = np.ascontiguousarray(normals, dtype=np.float32)
    rows = np.ascontiguousarray(basis, dtype=np.float64)
    size = np.ascontiguousarray(texel_size, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or n.shape != p.shape or rows.shape != (3, 3) or size.ndim != 2 \
            or size.shape[1] != 2:
        raise ValueError(f"points, normals, basis, texel_size: expected shapes (M, 3), (M, 3), (3, 3), (C, 2); got "
                         f"{p.shape}, {n.shape}, {rows.shape}, {size.shape}")
    count = cascades
    if size.shape[0] != count:
        raise ValueError(f"texel_size: expected one row per cascade ({count}), got {size.shape[0]}")
    index = np.arange(p.shape[0], dtype=np.int32) if receivers is None else np.ascontiguousarray(receivers, np.int32)
    if index.ndim != 1 or (index.size and (index.min() < 0 or index.max() >= p.shape[0])):
        raise ValueError(f"receivers: expected row indices in [0, {p.shape[0]}), got shape {index.shape}")
    texel = size.max(axis=1)
    r = EngineReceivers()
    r.points = wp.array(p, dtype=wp.vec3d, device=device, copy=False)
    r.normals = wp.array(n, dtype=wp.vec3, device=device, copy=False)
    r.index = wp.array(index, dtype=wp.int32, device=device, copy=False)
    r.basis = wp.mat33d(*rows.reshape(-1))
    r.texel_size = wp.array(size, dtype=wp.vec2d, device=device)
    r.bias = receiver_bias(texel, bias, device=device)
    r.zref = float(zref)
    r.limit = float(2**50)
    r.scale = 1.0
    return r


def _launched(kernel, inputs: tuple, cascades: int, receivers: int,
              device: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``kernel`` launched a thread per receiver: its coordinates ``(C, N, 2)``, depths ``(C, N)`` and slopes
    ``(C, N, 2)``."""
    shape = (cascades, receivers)
    coords = device_empty(shape + (2,), wp.int64, device)
    depth = device_empty(shape, wp.float32, device)
    slope = device_empty(shape + (2,), wp.float64, device)
    if receivers and cascades:
        wp.launch(kernel, dim=receivers, inputs=inputs, outputs=(coords, depth, slope), device=device)
    return coords.numpy(), depth.numpy(), slope.numpy()


@wp.kernel
def warped_vertices_kernel(
    light_xy: wp.array(dtype=wp.vec2d),
    depth: wp.array(dtype=wp.float64),
    homography: wp.mat33d,
    scale: wp.float64,
    limit: wp.float64,
    points: wp.array(dtype=vec2l),
    per_w: wp.array(dtype=wp.float64),
):
    """Vertex v through a warped cascade's homography: doubled fixed point and ``depth / w``.

    :func:`csmlab.cascades.warp.warped_texels`' sums in its order, ``((x·H0 + y·H1) + H2)``, each
    coordinate divided by ``w``, then :func:`csmlab.render.warped_depth_map`'s
    ``rint(clip(texel · 2**bits))``.
    """
    v = wp.tid()
    q = light_xy[v]
    h = homography
    w = (q[0] * h[2, 0] + q[1] * h[2, 1]) + h[2, 2]
    i = (q[0] * h[0, 0] + q[1] * h[0, 1]) + h[0, 2]
    j = (q[0] * h[1, 0] + q[1] * h[1, 1]) + h[1, 2]
    two = wp.int64(2)
    points[v] = vec2l(two * snapped((i / w) * scale, limit), two * snapped((j / w) * scale, limit))
    per_w[v] = depth[v] / w


def warped_vertices(homography, light_xy, depth, *, bits: int, device: str = "cpu") -> tuple[np.ndarray, np.ndarray]:
    """Vertices of a warped cascade in its doubled fixed point, and their light depth over ``w``.

    Parameters
    ----------
    homography : array_like, shape (3, 3), float64
        Light-space x/y metres to the warped map's homogeneous texels (:mod:`csmlab.cascades.warp`).
    light_xy : array_like, shape (V, 2), float64
        Light-space x/y, metres.
    depth : array_like, shape (V,), float64
        ``d·X − zref``, metres.
    bits : int
    device : str

    Returns
    -------
    points : ndarray, shape (V, 2), int64
        Twice ``rint(clip(texel · 2**bits, ±2**50))`` of :func:`csmlab.cascades.warp.warped_texels`'
        texels (NaN maps to ``-2**50``), bit for bit.
    per_w : ndarray, shape (V,), float64
        ``depth / w``: affine across a triangle's warped image, what the rasterizer interpolates.
    """
    device = checked_device(device)
    h = np.asarray(homography, dtype=np.float64)
    xy = np.ascontiguousarray(light_xy, dtype=np.float64)
    z = np.ascontiguousarray(depth, dtype=np.float64)
    if h.shape != (3, 3) or xy.ndim != 2 or xy.shape[1] != 2 or z.shape != (xy.shape[0],):
        raise ValueError(f"homography, light_xy, depth: expected shapes (3, 3), (V, 2), (V,); got {h.shape}, "
                         f"{xy.shape}, {z.shape}")
    if not (isinstance(bits, (int, np.integer)) and 0 <= bits <= 16):
        raise ValueError(f"bits: expected an integer in 0..16, got {bits!r}")
    points = device_empty(xy.shape[0], vec2l, device)
    per_w = device_empty(xy.shape[0], wp.float64, device)
    if xy.shape[0]:
        wp.launch(warped_vertices_kernel, dim=xy.shape[0],
                  inputs=(wp.array(xy, dtype=wp.vec2d, device=device, copy=False),
                          wp.array(z, dtype=wp.float64, device=device, copy=False), wp.mat33d(*h.reshape(-1)),
                          float(2**int(bits)), float(2**50)), outputs=(points, per_w), device=device)
    return points.numpy().view(np.int64).reshape(-1, 2), per_w.numpy()


_HYPOT = """
#if defined(__CUDA_ARCH__)
return ::hypot(x, y);
#else
return __builtin_hypot(x, y);
#endif
"""


@wp.func_native(_HYPOT)
def hypot(x: wp.float64, y: wp.float64) -> wp.float64:
    """The C library's ``hypot`` (Warp has none): on the CPU the one NumPy's ``np.hypot`` calls, the same bits."""
    ...


@wp.func
def homogeneous(q0: wp.float64, q1: wp.float64, h: wp.mat33d, row: int) -> wp.float64:
    """Row ``row`` of the homography at light-space ``(q0, q1)``: ``(q0·H0 + q1·H1) + H2``, as
    :func:`csmlab.cascades.warp.warped_texels` sums it."""
    return (q0 * h[row, 0] + q1 * h[row, 1]) + h[row, 2]


@wp.func
def numpy_maximum(a: wp.float64, b: wp.float64) -> wp.float64:
    """``np.maximum(a, b)``: NaN if either is NaN (``wp.max`` would drop it)."""
    if a >= b or a != a:
        return a
    return b


@wp.kernel
def warped_receivers_kernel(
    r: EngineReceivers,
    homographies: wp.array(dtype=wp.mat33d),
    coords: wp.array3d(dtype=wp.int64),
    depth: wp.array2d(dtype=wp.float32),
    slope: wp.array3d(dtype=wp.float64),
):
    """Receiver k in every warped cascade: :func:`csmlab.texels.receiver_lookup`'s warped branch in its order."""
    k = wp.tid()
    zero = wp.float64(0.0)
    one = wp.float64(1.0)
    point = r.points[r.index[k]]
    normal = wp.vec3d(r.normals[r.index[k]])
    px, py, pz = light_space_xyz(point, r.basis)
    nx, ny, nz = light_space_xyz(normal, r.basis)
    tan, plane_x, plane_y, factor = receiver_slopes(nx, ny, nz, r.bias.max_tan, r.bias.normal_scale)
    along = one
    if r.bias.normal_scale == NORMAL_ONE_MINUS_COS_LATERAL:
        along = zero
    c = int(0)
    while c < coords.shape[0]:
        h = homographies[c]
        offset = r.bias.offset[c]
        if r.bias.normal_scale != NORMAL_NONE:
            offset = offset * factor
        moved = wp.vec3d(point[0] + normal[0] * offset, point[1] + normal[1] * offset, point[2] + normal[2] * offset)
        mx = light_space(moved, r.basis, 0)
        my = light_space(moved, r.basis, 1)
        w = homogeneous(mx, my, h, 2)
        x = wp.int64(-r.limit)
        y = wp.int64(-r.limit)
        if w > zero:
            x = snapped((homogeneous(mx, my, h, 0) / w) * r.scale, r.limit)
            y = snapped((homogeneous(mx, my, h, 1) / w) * r.scale, r.limit)
        coords[c, k, 0] = x
        coords[c, k, 1] = y
        # The texel's larger side and the plane's change per texel step, from the inverse of the homography's
        # Jacobian at the receiver (csmlab.texels._warped_texel_steps).
        w0 = homogeneous(px, py, h, 2)
        t0 = homogeneous(px, py, h, 0) / w0
        t1 = homogeneous(px, py, h, 1) / w0
        j00 = (h[0, 0] - t0 * h[2, 0]) / w0
        j01 = (h[0, 1] - t0 * h[2, 1]) / w0
        j10 = (h[1, 0] - t1 * h[2, 0]) / w0
        j11 = (h[1, 1] - t1 * h[2, 1]) / w0
        det = j00 * j11 - j01 * j10
        ai0 = j11 / det
        ai1 = -j10 / det
        aj0 = -j01 / det
        aj1 = j00 / det
        texel = numpy_maximum(hypot(ai0, ai1), hypot(aj0, aj1))
        sx = plane_x * ai0 + plane_y * ai1
        sy = plane_x * aj0 + plane_y * aj1
        bias = r.bias.bias_constant[c] + r.bias.bias_slope * texel * tan
        if r.bias.plane_offset[c] > zero:
            bias = bias + wp.min(wp.abs(sx) + wp.abs(sy), r.bias.plane_offset[c])
        depth[c, k] = wp.float32(((pz + along * offset * nz) - r.zref) - bias)
        slope[c, k, 0] = sx
        slope[c, k, 1] = sy
        c += 1


def warped_receivers(homographies, points, normals, *, basis, texel_size, zref: float, bits: int, bias: BiasSettings,
                     receivers=None, device: str = "cpu") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`csmlab.texels.receiver_lookup` of perspective-warped cascades (``warp``) on the device, bit for bit on
    the CPU (on a GPU the texel size takes CUDA's ``hypot``).

    Parameters
    ----------
    homographies : array_like, shape (C, 3, 3), float64
        Each cascade's homography, light-space x/y metres to homogeneous texels (:mod:`csmlab.cascades.warp`).
    points, normals, basis, texel_size, zref, bias, receivers
        As :func:`window_receivers`; ``texel_size`` ``(C, 2)`` the warps' nominal texels (the normal offset's unit).
    bits : int
        Sub-texel bits.
    device : str

    Returns
    -------
    coordinates : ndarray, shape (C, N, 2), int64
    depth : ndarray, shape (C, N), float32
    slope : ndarray, shape (C, N, 2), float64
    """
    device = checked_device(device)
    h = np.ascontiguousarray(homographies, dtype=np.float64)
    if h.ndim != 3 or h.shape[1:] != (3, 3):
        raise ValueError(f"homographies: expected shape (C, 3, 3), got {h.shape}")
    if not (isinstance(bits, (int, np.integer)) and 0 <= bits <= 16):
        raise ValueError(f"bits: expected an integer in 0..16, got {bits!r}")
    r = engine_receivers(points, normals, basis=basis, texel_size=texel_size, zref=zref, bias=bias,
                          receivers=receivers, cascades=h.shape[0], device=device)
    r.scale = float(2**int(bits))
    return _launched(warped_receivers_kernel, (r, wp.array(h, dtype=wp.mat33d, device=device)), h.shape[0],
                     r.index.shape[0], device)
