"""The depth raster's Warp code: one triangle's coverage and depth, the vertex pass, and the three kernels.

Pure Warp (the host side is :mod:`csmlab.kernels.raster.schedule`). A triangle takes one of three
paths, chosen by :class:`TrianglePaths` (defaults :data:`ONE_CENTRE`, :data:`STEPPED_EXTENT`,
:data:`SOLVED_COLUMNS`), which give the same depths and counts bit for bit wherever more than one
applies:

- **one centre**: a bounding box that holds a single texel centre (most triangles of a far
  cascade) has that centre tested without the walk's set-up (:func:`centre_covered`);
- **walk**: a triangle small enough for exact integer edge functions in float64 is walked row by
  row, each row's run of centres by :func:`walk_run` (edge functions stepped by one addition per
  texel); across a box wide enough, each row's run is first solved for (:func:`run_bounds`);
- **large triangle**: a larger one has each edge function evaluated afresh at every centre, with
  float64 rounding, and the top-left rule applied to the rounded values.

An alpha-tested triangle (a vertex mask ≥ 0, :mod:`csmlab.kernels.alpha`) takes a fourth path,
:func:`rasterize_masked_triangle`: the large triangle's test at every centre of its box, the same
depth, kept only where the mask is opaque at the coordinates interpolated with the same edge
functions. Its covered centres are counted whether or not the mask keeps them (the fragments a GPU
rasterizes, then discards). Opaque triangles never reach it: a mask of all ones gives the maps of
the opaque triangle, bit for bit.
"""

from __future__ import annotations

import warp as wp

from csmlab.kernels.alpha import AlphaTextures, alpha_passes
from csmlab.kernels.floats import is_nan

__all__ = ["ONE_CENTRE", "SOLVED_COLUMNS", "STEPPED_EXTENT", "Boxes", "CasterOffset", "ChunkRows", "FixedPoint",
           "chunk_rectangles_kernel",
           "LightMesh", "TrianglePaths", "VertexPass", "caster_offset", "fixed_point_vertices_kernel",
           "rasterize_chunks_kernel", "rasterize_depth_kernel", "triangle_paths", "vec2l"]

# Products and sums rounded one by one on both devices (clang and NVRTC may otherwise contract them): a
# CUDA build may not contract them into fused multiply-adds, or its bits differ from the CPU's.
wp.set_module_options({"fuse_fp": False})

vec2l = wp.types.vector(length=2, dtype=wp.int64)
"""A vertex's two fixed-point coordinates (x, y): read and written as one 16-byte value."""

ONE_CENTRE = True
"""Whether a bounding box that holds one texel centre is tested without the walk's set-up.

A far cascade's triangles are mostly smaller than a texel: the walk's three steps, biases and first
row cost more than the one test they serve. The test is the walk's own arithmetic on the same exact
integers, so the choice changes no depth and no count, only time.
"""

STEPPED_EXTENT = 2**26
"""Triangles whose bounding box spans less than this, in doubled ``2**-bits`` texels (``2**(25 − bits)``
texels: 131,072 at 8 bits), are walked with stepped exact integer edge functions; larger ones take
the large-triangle path.

Why this value: every centre walked lies in the bounding box, so each product of coordinate
differences is below ``extent²`` and each edge function below ``2·extent² = 2**53``, the last
integer float64 holds exactly. Below it, stepping one texel by adding a constant gives the same bits
as evaluating afresh, and "inside or owned" is one comparison against a bias of −½ or 0. Above it,
the products may round, and a stepped walk would carry its roundings from texel to texel, so the large
path evaluates each centre afresh. A larger value would leave exactness unproven (tests/kernels/test_raster.py
checks the bound, and that every path forced gives the same maps); a smaller one only slows large
triangles down.
"""

SOLVED_COLUMNS = 16
"""A walked bounding box at least this many columns wide (beyond the first) has each row's run of
inside centres solved for from its three edges (:func:`run_bounds`) before it is walked; a
narrower one is walked whole.

Why this value: solving costs three divisions per triangle and three bounds per row, repaid only
across wide boxes. Seventeen columns: 2-5 % less time than from nine, as much as from 33; never
solving took 3-27 % more (~1M and 136k triangles, 4 × 1024² and 2048², interleaved A/B). The
bounds are widened against rounding and the exact test decides every centre walked, so the value
changes no depth and no count, only time.
"""


@wp.struct
class TrianglePaths:
    """Which of a triangle's three paths it takes (the module's docstring; tests force each in turn)."""

    one_centre: wp.int32
    """1: a box holding one texel centre takes the one-centre path (:data:`ONE_CENTRE`); 0: it is walked."""
    stepped_extent: wp.int64
    """Boxes spanning less than this (doubled ``2**-bits`` texels) are walked (:data:`STEPPED_EXTENT`)."""
    solved_columns: wp.int32
    """Walked boxes at least this many columns wide have their runs solved for (:data:`SOLVED_COLUMNS`)."""


def triangle_paths(*, one_centre: bool = ONE_CENTRE, stepped_extent: int = STEPPED_EXTENT,
                   solved_columns: int = SOLVED_COLUMNS) -> TrianglePaths:
    """A :class:`TrianglePaths` of the module's thresholds, or of others (tests force each path with them)."""
    paths = TrianglePaths()
    paths.one_centre = int(bool(one_centre))
    paths.stepped_extent = int(stepped_extent)
    paths.solved_columns = int(solved_columns)
    return paths


@wp.struct
class FixedPoint:
    """The fixed-point grid vertices are snapped to: ``2**-bits`` texels."""

    scale: wp.float64
    """``2**bits``: fixed-point steps per texel."""
    limit: wp.float64
    """The clip of global fixed-point values, ±``limit`` (:mod:`csmlab.texels`)."""
    unit: wp.int64
    """``2**bits`` as an integer: in doubled units, texel centres lie at its odd multiples."""
    bits: wp.int64
    """Sub-texel bits (0..16)."""


@wp.struct
class Boxes:
    """Every cascade's box: its texel size and its origin."""

    texel_size: wp.array(dtype=wp.vec2d)
    """Metres per texel of each cascade, x and y."""
    origin_fixed: wp.array(dtype=vec2l)
    """Each box's minimum corner in global ``2**-bits`` texels (:func:`csmlab.texels.fixed_point_origin`)."""


@wp.struct
class CasterOffset:
    """The depth offset a triangle is rasterized with, away from the light: a polygon offset per cascade.

    A triangle of cascade c is stored ``constant[c] + slope · m`` metres farther from the light, m its
    largest light-space depth change over one texel along x or y (metres per texel, from its
    fixed-point vertices): Direct3D's ``DepthBias · r + SlopeScaledDepthBias · MaxDepthSlope``, in
    metres (:func:`csmlab.kernels.raster.schedule.caster_offsets`).
    """

    constant: wp.array(dtype=wp.float64)
    """Metres of each cascade's constant offset."""
    slope: wp.float64
    """Times the triangle's largest depth change per texel; 0: no slope offset."""


@wp.struct
class LightMesh:
    """The mesh in light space (:class:`csmlab.kernels.raster.mesh.LightSpaceMesh` on a device)."""

    xy: wp.array(dtype=wp.vec2d)
    """Vertices' light-space x/y, metres."""
    depth: wp.array(dtype=wp.float64)
    """``d·X − zref`` of each vertex, metres."""
    triangles: wp.array2d(dtype=wp.int32)
    """Vertex indices, ``(T, 3)``; either winding."""
    uv: wp.array(dtype=wp.vec2d)
    """Texture coordinates of each vertex (zero-length: no masks)."""
    vertex_mask: wp.array(dtype=wp.int32)
    """Each vertex's alpha mask, −1 opaque (zero-length: every triangle opaque)."""
    textures: AlphaTextures
    """The masks (:mod:`csmlab.kernels.alpha`)."""


@wp.struct
class VertexPass:
    """The vertices the vertex pass converted (:func:`fixed_point_vertices_kernel`, or an engine's window-space pass,
    :mod:`csmlab.kernels.engine`), for which cascades, and which casters each cascade keeps."""

    points: wp.array2d(dtype=vec2l)
    """``points[s, v]``: vertex v in doubled fixed point of the cascade of slot s."""
    slots: wp.array(dtype=wp.int32)
    """Each cascade's slot in ``points``, −1 where its vertices are converted triangle by triangle."""
    depth: wp.array2d(dtype=wp.float64)
    """``depth[s, v]``: vertex v's stored depth in the cascade of slot s, metres (an engine's float32 window
    depth); zero rows: every cascade stores the mesh's own ``d·X − zref``."""
    near: wp.array(dtype=wp.float64)
    """Per cascade, the mesh depth (``d·X − zref``, metres) a triangle's farthest vertex must reach for the cascade
    to keep it: casters wholly nearer than a slice's near side clipped away (:func:`csmlab.render.clipped_casters`);
    zero-length: every cascade keeps every triangle."""


@wp.struct
class ChunkRows:
    """One launch's work: (region, chunk) rows, each chunk cut into runs of triangles a thread takes."""

    regions: wp.array2d(dtype=wp.int32)
    """Rows ``(c, i0, i1, j0, j1)``: texel columns ``[i0, i1)`` and rows ``[j0, j1)`` of cascade c."""
    chunks: wp.array2d(dtype=wp.int32)
    """(region, chunk) rows; chunk k holds triangles ``[k·2**chunk_bits, (k + 1)·2**chunk_bits)``."""
    chunk_bits: int
    """``log2`` of the triangles in a chunk (:data:`csmlab.kernels.raster.mesh.CHUNK_BITS`)."""
    run_bits: int
    """``log2`` of the triangles a thread takes, at most ``chunk_bits``."""


@wp.func
def edge_owns_centre(dx: wp.int64, dy: wp.int64) -> bool:
    """Top-left tie-break of a counter-clockwise edge with direction ``(dx, dy)``."""
    return dy < wp.int64(0) or (dy == wp.int64(0) and dx < wp.int64(0))


@wp.func
def edge_inside(e: wp.float64, owns: bool) -> bool:
    return e > wp.float64(0.0) or (e == wp.float64(0.0) and owns)


@wp.func
def owned_bias(owns: bool) -> wp.float64:
    """The bound an exact integer edge function must exceed: −½ (≥ 0) for an owning edge, else 0."""
    if owns:
        return wp.float64(-0.5)
    return wp.float64(0.0)


@wp.func
def reciprocal(x: wp.float64) -> wp.float64:
    """``1 / x``, 0 for 0 (an edge parallel to the rows, which :func:`run_bounds` handles apart)."""
    if x == wp.float64(0.0):
        return wp.float64(0.0)
    return wp.float64(1.0) / x


@wp.func
def run_bounds(w: wp.float64, step: wp.float64, inverse_step: wp.float64, bias: wp.float64, start: wp.float64,
               lo: wp.float64, hi: wp.float64):
    """``[lo, hi]`` (texel columns, whole numbers in float64) narrowed to where ``w − step·(i − start) > bias``
    may hold.

    ``w`` is the edge function at column ``start``. The bound ``⌊(w − bias)·(1 / step)⌋`` is off by
    far less than a column (|w| < 2**53, a few roundings); the upper bound is widened by one
    column, and the lower one is ``⌊·⌋`` of a quantity whose true value exceeds it by more than
    the error, so the run is never cut: the exact test decides every column in it.
    """
    if step == wp.float64(0.0):
        if not (w > bias):
            hi = lo - wp.float64(1.0)
        return lo, hi
    q = wp.floor((w - bias) * inverse_step)
    if step > wp.float64(0.0):
        hi = wp.min(hi, start + q + wp.float64(1.0))
    else:
        lo = wp.max(lo, start + q - wp.float64(1.0))
    return lo, hi


@wp.func
def first_centre(lo: wp.int64, unit: wp.int64, bits: wp.int64, begin: int, end: int) -> int:
    """First texel whose centre, ``(2k + 1)·unit`` in doubled units, is at or above ``lo``, clamped to ``[begin, end]``.

    ``unit = 2**bits``: the floor division by ``2·unit`` is an arithmetic shift by ``bits + 1``.
    """
    k = -((unit - lo) >> (bits + wp.int64(1)))
    return int(wp.clamp(k, wp.int64(begin), wp.int64(end)))


@wp.func
def last_centre(hi: wp.int64, unit: wp.int64, bits: wp.int64, begin: int, end: int) -> int:
    """Last texel whose centre is at or below ``hi``, clamped to ``[begin − 1, end − 1]``."""
    k = (hi - unit) >> (bits + wp.int64(1))
    return int(wp.clamp(k, wp.int64(begin - 1), wp.int64(end - 1)))


@wp.func
def centre_box(ax: wp.int64, ay: wp.int64, bx: wp.int64, by: wp.int64, cx: wp.int64, cy: wp.int64, fixed: FixedPoint,
               window: wp.vec4i):
    """The texels ``i0, i1, j0, j1`` of ``window`` whose centres the triangle's bounding box holds (doubled
    fixed-point vertices): columns ``i0..i1``, rows ``j0..j1``, none where ``i0 > i1`` or ``j0 > j1``."""
    return (first_centre(wp.min(wp.min(ax, bx), cx), fixed.unit, fixed.bits, window[0], window[1]),
            last_centre(wp.max(wp.max(ax, bx), cx), fixed.unit, fixed.bits, window[0], window[1]),
            first_centre(wp.min(wp.min(ay, by), cy), fixed.unit, fixed.bits, window[2], window[3]),
            last_centre(wp.max(wp.max(ay, by), cy), fixed.unit, fixed.bits, window[2], window[3]))


@wp.func
def doubled_area(ax: wp.int64, ay: wp.int64, bx: wp.int64, by: wp.int64, cx: wp.int64, cy: wp.int64) -> wp.float64:
    """Twice the signed area of triangle abc (fixed-point units²), positive counter-clockwise; exact below
    ``STEPPED_EXTENT``."""
    return wp.float64(bx - ax) * wp.float64(cy - ay) - wp.float64(by - ay) * wp.float64(cx - ax)


@wp.func
def owned_edges(ax: wp.int64, ay: wp.int64, bx: wp.int64, by: wp.int64, cx: wp.int64, cy: wp.int64):
    """Whether edges ab, bc and ca of a counter-clockwise triangle own the centres on them (top-left rule)."""
    return edge_owns_centre(bx - ax, by - ay), edge_owns_centre(cx - bx, cy - by), edge_owns_centre(ax - cx, ay - cy)


@wp.func
def edge_values(px: wp.int64, ax: wp.int64, ay: wp.int64, bx: wp.int64, by: wp.int64, cx: wp.int64, cy: wp.int64,
                row_ab: wp.float64, row_bc: wp.float64, row_ca: wp.float64):
    """The three edge functions at the centre of column ``px`` (doubled units) of a row, from the row's terms."""
    return (row_ab - wp.float64(by - ay) * wp.float64(px - ax), row_bc - wp.float64(cy - by) * wp.float64(px - bx),
            row_ca - wp.float64(ay - cy) * wp.float64(px - cx))


_KEEP_NEARER = """
#if defined(__CUDA_ARCH__)
    if (covered) wp::atomic_min(&wp::index(depth, c, j, i), z);
#else
    // Raw addressing skips Warp's debug-mode bounds checks: these asserts stand in for them (debug builds only).
    assert(c >= 0 && c < depth.shape[0] && j >= 0 && j < depth.shape[1] && i >= 0 && i < depth.shape[2]);
    float* texel = reinterpret_cast<float*>(reinterpret_cast<char*>(depth.data) + c * size_t(depth.strides[0])
                                            + j * size_t(depth.strides[1]) + i * size_t(depth.strides[2]));
    const float held = *texel;
    *texel = (covered && z < held) ? z : held;
#endif
"""


@wp.func_native(_KEEP_NEARER)
def keep_nearer(depth: wp.array3d(dtype=wp.float32), c: int, j: int, i: int, z: wp.float32, covered: bool):
    """Texel (i, j) of cascade c keeps the nearer of its depth and ``z`` (metres) where ``covered``; else its own.

    On a GPU an atomic minimum, for many threads meet at a texel. A CPU launch writes texels no
    other launch writes (:func:`~csmlab.kernels.raster.schedule.rasterize_cascades`), so there it is
    a plain load, compare and store at an address made from the strides (the indices are never
    negative: no wrap), without the atomic's NaN handling (no depth is NaN): 5-8 % faster walks
    than ``wp.atomic_min``.
    """
    ...


@wp.func
def offer_depth(depth: wp.array3d(dtype=wp.float32), c: int, j: int, i: int, inside: int, w_a: wp.float64,
                w_b: wp.float64, w_c: wp.float64, za: wp.float64, zb: wp.float64, zc: wp.float64, area: wp.float64):
    """Texel (i, j) keeps the nearer of its depth and the triangle's if ``inside`` (interpolated with edge functions).

    The depth is computed whether or not the centre is inside: a test as often false as true
    (a small triangle's bounding box) is not worth a branch. A cascade beyond ``depth``'s maps (a
    counted cascade, :func:`~csmlab.kernels.raster.schedule.rasterize_cascades`' ``stored_cascades``;
    every cascade of an empty ``depth``, ``count_only``) stores nothing.
    """
    if c < depth.shape[0]:
        keep_nearer(depth, c, j, i, wp.float32((w_a * za + w_b * zb + w_c * zc) / area), inside > 0)


_WALK_RUN = """
int count = 0;
const int n = hi - lo + 1;
#if defined(__CUDA_ARCH__)
for (int k = 0; k < n; ++k) {
    const double step = static_cast<double>(k);
    const double e_c = w_c - step_c * step;
    const double e_a = w_a - step_a * step;
    const double e_b = w_b - step_b * step;
    if (e_c > bias_ab && e_a > bias_bc && e_b > bias_ca) {
        ++count;
        if (c < depth.shape[0]) {
            const double sum = __dadd_rn(__dadd_rn(__dmul_rn(e_a, za), __dmul_rn(e_b, zb)), __dmul_rn(e_c, zc));
            wp::atomic_min(&wp::index(depth, c, j, lo + k), static_cast<float>(__ddiv_rn(sum, area)));
        }
    }
}
#else
{
#pragma clang fp contract(off)
    // Raw addressing skips Warp's debug-mode bounds checks: these asserts stand in for them (debug builds only).
    assert(n <= 0 || c >= depth.shape[0] || (c >= 0 && c < depth.shape[0] && j >= 0 && j < depth.shape[1] && lo >= 0
                                             && hi < depth.shape[2] && depth.strides[2] == sizeof(float)));
    float* row = reinterpret_cast<float*>(reinterpret_cast<char*>(depth.data) + c * size_t(depth.strides[0])
                                          + j * size_t(depth.strides[1])) + lo;
    const bool store = c < depth.shape[0];
#pragma clang loop vectorize_width(8) interleave_count(1) vectorize_predicate(enable)
    for (int k = 0; k < n; ++k) {
        const double step = static_cast<double>(k);
        const double e_c = w_c - step_c * step;
        const double e_a = w_a - step_a * step;
        const double e_b = w_b - step_b * step;
        const bool inside = (e_c > bias_ab) & (e_a > bias_bc) & (e_b > bias_ca);
        count += inside;
        if (store) {
            const float z = static_cast<float>((e_a * za + e_b * zb + e_c * zc) / area);
            const float held = row[k];
            row[k] = (inside & (z < held)) ? z : held;
        }
    }
}
#endif
return count;
"""


@wp.func_native(_WALK_RUN)
def walk_run(depth: wp.array3d(dtype=wp.float32), c: int, j: int, lo: int, hi: int, w_c: wp.float64,
             w_a: wp.float64, w_b: wp.float64, step_c: wp.float64, step_a: wp.float64, step_b: wp.float64,
             bias_ab: wp.float64, bias_bc: wp.float64, bias_ca: wp.float64, za: wp.float64, zb: wp.float64,
             zc: wp.float64, area: wp.float64) -> int:
    """Texels ``lo..hi`` of row j of cascade c: each centre tested, counted, its depth kept where nearer; the count.

    ``w_c, w_a, w_b`` are a stepped triangle's edge functions at the centre of column ``lo``,
    each falling by its ``step`` per column; a centre is inside where all three exceed their
    bias (:func:`owned_bias`). They are exact integers in float64 (:func:`rasterize_triangle`),
    so ``w − step·k`` is the same number as k subtractions, and the depth
    ``(w_a·za + w_b·zb + w_c·zc) / area`` is rounded in that order, unfused: the map is the same,
    bit for bit, as one walked a texel at a time. The map's rows must be contiguous.

    Native code so that, on a CPU, clang vectorizes the run eight texels at a time (masking the
    last ones): at ~1M triangles, 4 × 1024² on two threads 38.5 → 33.4 ms, at 136k 19.3 → 14.4 ms
    (interleaved A/B, four at a time); eight rather than four: the default run's whole maps
    (`none`, 265k triangles, 4 × 1024², one thread) 16.7 → 16.1 ms, 16 took 18.7 ms, eight without
    masking the last ones 20.8 ms. On a GPU a thread's run is walked a texel at a time, its depth rounded as
    on the CPU (``__dmul_rn``, ``__dadd_rn``: no fused multiply-add) and kept by an atomic minimum.
    """
    ...


@wp.func
def centre_covered(px: wp.int64, py: wp.int64, ax: wp.int64, ay: wp.int64, bx: wp.int64, by: wp.int64, cx: wp.int64,
                   cy: wp.int64, bias_ab: wp.float64, bias_bc: wp.float64, bias_ca: wp.float64, za: wp.float64,
                   zb: wp.float64, zc: wp.float64, area: wp.float64, depth: wp.array3d(dtype=wp.float32), c: int,
                   j: int, i: int) -> int:
    """1 if the centre ``(px, py)`` (doubled units) of texel (i, j) lies in the triangle, else 0.

    The edge functions are exact integers (a stepped triangle's), so each test is one comparison
    against the edge's bias (:func:`owned_bias`), and they are the walk's values bit for bit. The
    depth is stored without a branch (:func:`offer_depth`).
    """
    w_c, w_a, w_b = edge_values(px, ax, ay, bx, by, cx, cy, wp.float64(bx - ax) * wp.float64(py - ay),
                                wp.float64(cx - bx) * wp.float64(py - by), wp.float64(ax - cx) * wp.float64(py - cy))
    inside = int(w_c > bias_ab) * int(w_a > bias_bc) * int(w_b > bias_ca)
    offer_depth(depth, c, j, i, inside, w_a, w_b, w_c, za, zb, zc, area)
    return inside


@wp.func
def rasterize_triangle(
    ax: wp.int64,
    ay: wp.int64,
    bx: wp.int64,
    by: wp.int64,
    cx: wp.int64,
    cy: wp.int64,
    za: wp.float64,
    zb: wp.float64,
    zc: wp.float64,
    fixed: FixedPoint,
    paths: TrianglePaths,
    depth: wp.array3d(dtype=wp.float32),
    c: int,
    window: wp.vec4i,
) -> int:
    """Rasterize one triangle into texels ``[i0, i1) × [j0, j1)`` (``window``) of cascade c's map.

    The vertices are fixed-point coordinates already doubled (texel centres at odd multiples of
    ``fixed.unit = 2**bits``), with depths ``za, zb, zc``; ``paths`` chooses the path (the module's
    docstring). Returns the number of texel centres covered.
    """
    unit = fixed.unit
    # Cull before any per-texel work: triangles whose bounding box holds no texel centre of the
    # window, and triangles of zero area.
    two = wp.int64(2)
    i0, i1, j0, j1 = centre_box(ax, ay, bx, by, cx, cy, fixed, window)
    if i0 > i1 or j0 > j1:
        return 0
    area = doubled_area(ax, ay, bx, by, cx, cy)
    if area == wp.float64(0.0):
        return 0
    if area < wp.float64(0.0):
        # Turn the triangle counter-clockwise so that one top-left rule serves both windings.
        bx, by, zb, cx, cy, zc = cx, cy, zc, bx, by, zb
        area = -area
    own_ab, own_bc, own_ca = owned_edges(ax, ay, bx, by, cx, cy)
    # Below STEPPED_EXTENT every edge function is an exact integer in float64, and stepping one texel
    # right by adding the constant −dy·2·unit gives the same bits as evaluating afresh: three
    # additions per texel instead of three products.
    extent = wp.max(wp.max(wp.max(ax, bx), cx) - wp.min(wp.min(ax, bx), cx),
                    wp.max(wp.max(ay, by), cy) - wp.min(wp.min(ay, by), cy))
    stepped = extent < paths.stepped_extent
    if stepped and i0 == i1 and j0 == j1 and paths.one_centre != 0:
        # One centre to test (ONE_CENTRE): tested and stored without a branch, as the walk would.
        return centre_covered((two * wp.int64(i0) + wp.int64(1)) * unit, (two * wp.int64(j0) + wp.int64(1)) * unit,
                              ax, ay, bx, by, cx, cy, owned_bias(own_ab), owned_bias(own_bc), owned_bias(own_ca), za,
                              zb, zc, area, depth, c, j0, i0)
    step = two * unit
    count = int(0)
    if stepped:
        step_c = wp.float64(by - ay) * wp.float64(step)
        step_a = wp.float64(cy - by) * wp.float64(step)
        step_b = wp.float64(ay - cy) * wp.float64(step)
        # With exact integer edge functions, "inside or owned" is one comparison against a bias:
        # e > 0, or e ≥ 0 (e > −½) where the edge owns its centres.
        bias_ab = owned_bias(own_ab)
        bias_bc = owned_bias(own_bc)
        bias_ca = owned_bias(own_ca)
        # Runs are solved for only across boxes wide enough to repay it (SOLVED_COLUMNS); a narrow
        # box is walked whole (walk_run, eight texels at a time).
        wide = i1 - i0 >= paths.solved_columns
        inverse_c = wp.float64(0.0)
        inverse_a = wp.float64(0.0)
        inverse_b = wp.float64(0.0)
        if wide:
            inverse_c = reciprocal(step_c)
            inverse_a = reciprocal(step_a)
            inverse_b = reciprocal(step_b)
        # The edge functions at the first centre of the first row; a row up adds dx·2·unit, exactly.
        bottom = (two * wp.int64(j0) + wp.int64(1)) * unit
        row_c, row_a, row_b = edge_values((two * wp.int64(i0) + wp.int64(1)) * unit, ax, ay, bx, by, cx, cy,
                                          wp.float64(bx - ax) * wp.float64(bottom - ay),
                                          wp.float64(cx - bx) * wp.float64(bottom - by),
                                          wp.float64(ax - cx) * wp.float64(bottom - cy))
        rise_c = wp.float64(bx - ax) * wp.float64(step)
        rise_a = wp.float64(cx - bx) * wp.float64(step)
        rise_b = wp.float64(ax - cx) * wp.float64(step)
        start = wp.float64(i0)
        end = wp.float64(i1)
        # `while` loops: a range known only at run time costs Warp's CPU code several times more per step.
        j = j0
        while j <= j1:
            # Each edge function falls by its step per texel, so the centres inside form one run;
            # its ends, solved from the three edges (widened by a texel against rounding), bound
            # the walk, and walk_run's exact test decides every centre in it.
            lo = start
            hi = end
            if wide:
                lo, hi = run_bounds(row_c, step_c, inverse_c, bias_ab, start, lo, hi)
                lo, hi = run_bounds(row_a, step_a, inverse_a, bias_bc, start, lo, hi)
                lo, hi = run_bounds(row_b, step_b, inverse_b, bias_ca, start, lo, hi)
            if lo <= hi:
                skip = lo - start
                w_c = row_c - step_c * skip
                w_a = row_a - step_a * skip
                w_b = row_b - step_b * skip
                count += walk_run(depth, c, j, int(lo), int(hi), w_c, w_a, w_b, step_c, step_a, step_b, bias_ab,
                                  bias_bc, bias_ca, za, zb, zc, area)
            row_c = row_c + rise_c
            row_a = row_a + rise_a
            row_b = row_b + rise_b
            j += 1
    else:
        for j in range(j0, j1 + 1):
            py = (two * wp.int64(j) + wp.int64(1)) * unit
            row_ab = wp.float64(bx - ax) * wp.float64(py - ay)
            row_bc = wp.float64(cx - bx) * wp.float64(py - by)
            row_ca = wp.float64(ax - cx) * wp.float64(py - cy)
            for i in range(i0, i1 + 1):
                w_c, w_a, w_b = edge_values((two * wp.int64(i) + wp.int64(1)) * unit, ax, ay, bx, by, cx, cy, row_ab,
                                            row_bc, row_ca)
                if edge_inside(w_c, own_ab) and edge_inside(w_a, own_bc) and edge_inside(w_b, own_ca):
                    offer_depth(depth, c, j, i, 1, w_a, w_b, w_c, za, zb, zc, area)
                    count += 1
    return count


@wp.func
def rasterize_masked_triangle(
    ax: wp.int64,
    ay: wp.int64,
    bx: wp.int64,
    by: wp.int64,
    cx: wp.int64,
    cy: wp.int64,
    za: wp.float64,
    zb: wp.float64,
    zc: wp.float64,
    uva: wp.vec2d,
    uvb: wp.vec2d,
    uvc: wp.vec2d,
    m: int,
    textures: AlphaTextures,
    fixed: FixedPoint,
    depth: wp.array3d(dtype=wp.float32),
    c: int,
    window: wp.vec4i,
) -> int:
    """:func:`rasterize_triangle` of an alpha-tested triangle (mask ``m``, texture coordinates ``uva, uvb, uvc``).

    Every centre of the bounding box is tested as the large-triangle path tests it; a covered
    centre is counted, and its depth kept where nearer and where :func:`~csmlab.kernels.alpha.alpha_passes`
    at ``(w_a·uva + w_b·uvb + w_c·uvc) / area``. The edge functions are those of the other paths
    (exact integers below ``STEPPED_EXTENT``), so a texel the mask keeps holds their depth bit for bit.
    """
    unit = fixed.unit
    two = wp.int64(2)
    i0, i1, j0, j1 = centre_box(ax, ay, bx, by, cx, cy, fixed, window)
    if i0 > i1 or j0 > j1:
        return 0
    area = doubled_area(ax, ay, bx, by, cx, cy)
    if area == wp.float64(0.0):
        return 0
    if area < wp.float64(0.0):
        # Counter-clockwise, as rasterize_triangle turns it; the coordinates follow their vertices.
        bx, by, zb, uvb, cx, cy, zc, uvc = cx, cy, zc, uvc, bx, by, zb, uvb
        area = -area
    own_ab, own_bc, own_ca = owned_edges(ax, ay, bx, by, cx, cy)
    count = int(0)
    j = j0
    while j <= j1:
        py = (two * wp.int64(j) + wp.int64(1)) * unit
        row_ab = wp.float64(bx - ax) * wp.float64(py - ay)
        row_bc = wp.float64(cx - bx) * wp.float64(py - by)
        row_ca = wp.float64(ax - cx) * wp.float64(py - cy)
        i = i0
        while i <= i1:
            w_c, w_a, w_b = edge_values((two * wp.int64(i) + wp.int64(1)) * unit, ax, ay, bx, by, cx, cy, row_ab,
                                        row_bc, row_ca)
            if edge_inside(w_c, own_ab) and edge_inside(w_a, own_bc) and edge_inside(w_b, own_ca):
                count += 1
                uv = (w_a * uva + w_b * uvb + w_c * uvc) / area
                if alpha_passes(textures, m, uv[0], uv[1]):
                    offer_depth(depth, c, j, i, 1, w_a, w_b, w_c, za, zb, zc, area)
            i += 1
        j += 1
    return count


@wp.func
def caster_offset(offset: CasterOffset, c: int, ax: wp.int64, ay: wp.int64, bx: wp.int64, by: wp.int64, cx: wp.int64,
                  cy: wp.int64, za: wp.float64, zb: wp.float64, zc: wp.float64, unit: wp.int64) -> wp.float64:
    """Metres triangle (a, b, c) of cascade c is pushed away from the light (:class:`CasterOffset`).

    Vertices in doubled ``2**-bits`` texels (``unit = 2**bits``); a triangle of zero area takes the
    constant alone (it covers no texel centre anyway).
    """
    push = offset.constant[c]
    if offset.slope != wp.float64(0.0):
        e1x = wp.float64(bx - ax)
        e1y = wp.float64(by - ay)
        e2x = wp.float64(cx - ax)
        e2y = wp.float64(cy - ay)
        det = e1x * e2y - e1y * e2x
        if det != wp.float64(0.0):
            # The plane's depth gradient per doubled unit, times the 2·unit doubled units of a texel.
            gx = ((zb - za) * e2y - (zc - za) * e1y) / det
            gy = (e1x * (zc - za) - e2x * (zb - za)) / det
            push = push + offset.slope * wp.max(wp.abs(gx), wp.abs(gy)) * wp.float64(wp.int64(2) * unit)
    return push


@wp.kernel
def rasterize_depth_kernel(
    points: wp.array3d(dtype=wp.int64),
    vertex_depth: wp.array(dtype=wp.float64),
    triangles: wp.array2d(dtype=wp.int32),
    uv: wp.array(dtype=wp.vec2d),
    vertex_mask: wp.array(dtype=wp.int32),
    textures: AlphaTextures,
    fixed: FixedPoint,
    paths: TrianglePaths,
    offset: CasterOffset,
    depth: wp.array3d(dtype=wp.float32),
    covered: wp.array2d(dtype=wp.int32),
):
    """``covered[c, t]``: texel centres of cascade c's whole map that triangle t covers; its depth kept where nearer.

    A thread per cascade and triangle; ``points[c, v]`` is vertex v in cascade c's local fixed point
    (not doubled). Each triangle's depths are pushed away from the light by its ``offset``. A
    triangle whose vertices hold a mask (``vertex_mask``, zero-length: none) is alpha-tested
    (:func:`rasterize_masked_triangle`).
    """
    c, t = wp.tid()
    ia = triangles[t, 0]
    ib = triangles[t, 1]
    ic = triangles[t, 2]
    two = wp.int64(2)
    ax = two * points[c, ia, 0]
    ay = two * points[c, ia, 1]
    bx = two * points[c, ib, 0]
    by = two * points[c, ib, 1]
    cx = two * points[c, ic, 0]
    cy = two * points[c, ic, 1]
    za = vertex_depth[ia]
    zb = vertex_depth[ib]
    zc = vertex_depth[ic]
    push = caster_offset(offset, c, ax, ay, bx, by, cx, cy, za, zb, zc, fixed.unit)
    m = int(-1)
    if vertex_mask.shape[0] > 0:
        m = vertex_mask[ia]
    window = wp.vec4i(0, depth.shape[2], 0, depth.shape[1])
    if m >= 0:
        covered[c, t] = rasterize_masked_triangle(ax, ay, bx, by, cx, cy, za + push, zb + push, zc + push, uv[ia],
                                                  uv[ib], uv[ic], m, textures, fixed, depth, c, window)
    else:
        covered[c, t] = rasterize_triangle(ax, ay, bx, by, cx, cy, za + push, zb + push, zc + push, fixed, paths,
                                           depth, c, window)


@wp.func
def doubled_fixed_point(u: wp.float64, step: wp.float64, limit: wp.float64, origin_fixed: wp.int64) -> wp.int64:
    """Twice a light-space coordinate ``u`` (metres) in local ``2**-bits`` texels; ``step = texel / 2**bits`` metres.

    ``origin_fixed`` is the box origin in global ``2**-bits`` texels.
    :func:`csmlab.texels.fixed_point_coordinates` computes ``rint(u / texel · 2**bits) − origin``.
    Scaling by a power of two commutes with rounding, so ``u / (texel / 2**bits)`` is the same
    float64 (both sides overflow alike, and an underflow differs only below 2**-1000, which rounds
    to 0 anyway): one division, no product. No sum, so no fused multiply-add can change a
    rounding.
    """
    v = wp.rint(wp.clamp(u / step, -limit, limit))
    if is_nan(v):
        v = -limit
    return wp.int64(2) * (wp.int64(v) - origin_fixed)


@wp.func
def doubled_fixed_point_vertex(u: wp.vec2d, step: wp.vec2d, limit: wp.float64, origin_fixed: vec2l) -> vec2l:
    """:func:`doubled_fixed_point` of both coordinates of a vertex."""
    return vec2l(doubled_fixed_point(u[0], step[0], limit, origin_fixed[0]),
                 doubled_fixed_point(u[1], step[1], limit, origin_fixed[1]))


@wp.kernel
def fixed_point_vertices_kernel(
    light_xy: wp.array(dtype=wp.vec2d),
    boxes: Boxes,
    cascades: wp.array(dtype=wp.int32),
    first: int,
    last: int,
    run: int,
    fixed: FixedPoint,
    points: wp.array2d(dtype=vec2l),
):
    """``points[s, v]``: vertex v of ``[first, last)`` in cascade ``cascades[s]``'s doubled fixed point.

    A thread per s and run of ``run`` vertices (on the CPU many, so that a thread's set-up serves
    them all; on a GPU one). A vertex is read and written as one vector of its two coordinates, so
    the index arithmetic is done once per vertex, not per coordinate: at ~500k vertices × 4
    cascades, 15 → 4.5 ms on one thread.
    """
    s, k = wp.tid()
    v = first + k * run
    end = wp.min(v + run, last)
    c = cascades[s]
    step = boxes.texel_size[c] / fixed.scale
    corner = boxes.origin_fixed[c]
    limit = fixed.limit
    while v < end:
        points[s, v] = doubled_fixed_point_vertex(light_xy[v], step, limit, corner)
        v += 1


@wp.func
def doubled_vertex(points: wp.array2d(dtype=vec2l), s: int, light_xy: wp.array(dtype=wp.vec2d), v: int,
                   step: wp.vec2d, corner: vec2l, limit: wp.float64) -> vec2l:
    """Vertex v's doubled fixed point: read from ``points[s]`` when the vertex pass made it (s >= 0), else made here."""
    if s >= 0:
        return points[s, v]
    return doubled_fixed_point_vertex(light_xy[v], step, limit, corner)


@wp.func
def misses_span(u: wp.float64, v: wp.float64, w: wp.float64, origin_fixed: wp.int64, scale: wp.float64,
                size: wp.float64, first: int, end: int) -> bool:
    """Coordinates ``u, v, w`` (metres) all below texel ``first − 1`` or all above texel ``end + 1`` of a box.

    ``origin_fixed`` in ``2**-bits`` texels (``scale = 2**bits``), ``size`` metres per texel. The texel
    of margin is far more than the fixed-point snap and float rounding can move a vertex.
    """
    corner = wp.float64(origin_fixed) / scale
    low = (corner + wp.float64(first - 1)) * size
    high = (corner + wp.float64(end + 1)) * size
    return wp.max(wp.max(u, v), w) < low or wp.min(wp.min(u, v), w) > high


@wp.kernel
def rasterize_chunks_kernel(
    mesh: LightMesh,
    boxes: Boxes,
    converted: VertexPass,
    work: ChunkRows,
    fixed: FixedPoint,
    paths: TrianglePaths,
    offset: CasterOffset,
    depth: wp.array3d(dtype=wp.float32),
    covered: wp.array(dtype=wp.int64),
):
    """A thread per run of ``2**run_bits`` triangles of a (region, chunk) row of ``work``; ``covered[g]`` sums
    region g's coverage tests passed.

    A chunk is ``2**chunk_bits`` consecutive triangles (the last one shorter), cut into runs
    (``run_bits <= chunk_bits``): on the CPU a run is the whole chunk, so that what a thread reads
    once (its row, region, cascade and box) serves every triangle of the chunk; a GPU wants a
    thread per triangle. A triangle that meets no texel centre of its region returns before any
    per-texel work, so the chunks need only be a superset of the triangles that cover a texel. Each
    triangle's depths are pushed away from the light by its ``offset``.
    """
    chunk_bits = work.chunk_bits
    run_bits = work.run_bits
    regions = work.regions
    light_xy = mesh.xy
    triangles = mesh.triangles
    vertex_depth = mesh.depth
    vertex_mask = mesh.vertex_mask
    masked = vertex_mask.shape[0] > 0
    points = converted.points
    scale = fixed.scale
    limit = fixed.limit
    first = wp.tid() << run_bits
    row = first >> chunk_bits
    t = (work.chunks[row, 1] << chunk_bits) + (first & ((1 << chunk_bits) - 1))
    end = wp.min(t + (1 << run_bits), triangles.shape[0])
    g = work.chunks[row, 0]
    c = regions[g, 0]
    s = converted.slots[c]
    size = boxes.texel_size[c]
    step = size / scale
    corner = boxes.origin_fixed[c]
    window = wp.vec4i(regions[g, 1], regions[g, 2], regions[g, 3], regions[g, 4])
    own_depth = converted.depth.shape[0] > 0
    cut = converted.near.shape[0] > 0
    near = wp.float64(0.0)
    if cut:
        near = converted.near[c]
    n = wp.int64(0)
    while t < end:
        ia = triangles[t, 0]
        ib = triangles[t, 1]
        ic = triangles[t, 2]
        keep = True
        if cut:
            keep = wp.max(wp.max(vertex_depth[ia], vertex_depth[ib]), vertex_depth[ic]) >= near
        if keep and s < 0:
            # Converted here: first drop, in metres, a triangle whose rectangle misses the region
            # widened by a texel, as region_chunks tests chunks (its neighbours in a chunk may not).
            ua = light_xy[ia]
            ub = light_xy[ib]
            uc = light_xy[ic]
            keep = not (misses_span(ua[0], ub[0], uc[0], corner[0], scale, size[0], window[0], window[1])
                        or misses_span(ua[1], ub[1], uc[1], corner[1], scale, size[1], window[2], window[3]))
        if keep:
            a = doubled_vertex(points, s, light_xy, ia, step, corner, limit)
            b = doubled_vertex(points, s, light_xy, ib, step, corner, limit)
            p = doubled_vertex(points, s, light_xy, ic, step, corner, limit)
            za = vertex_depth[ia]
            zb = vertex_depth[ib]
            zc = vertex_depth[ic]
            if own_depth:
                za = converted.depth[s, ia]
                zb = converted.depth[s, ib]
                zc = converted.depth[s, ic]
            push = caster_offset(offset, c, a[0], a[1], b[0], b[1], p[0], p[1], za, zb, zc, fixed.unit)
            m = int(-1)
            if masked:
                m = vertex_mask[ia]
            if m >= 0:
                uv = mesh.uv
                n += wp.int64(rasterize_masked_triangle(a[0], a[1], b[0], b[1], p[0], p[1], za + push, zb + push,
                                                        zc + push, uv[ia], uv[ib], uv[ic], m, mesh.textures, fixed,
                                                        depth, c, window))
            else:
                n += wp.int64(rasterize_triangle(a[0], a[1], b[0], b[1], p[0], p[1], za + push, zb + push, zc + push,
                                                 fixed, paths, depth, c, window))
        t += 1
    if n > wp.int64(0):
        wp.atomic_add(covered, g, n)



@wp.kernel
def chunk_rectangles_kernel(
    points: wp.array2d(dtype=vec2l),
    starts: wp.array(dtype=wp.int32),
    vertices: wp.array(dtype=wp.int32),
    lo: wp.array2d(dtype=vec2l),
    hi: wp.array2d(dtype=vec2l),
):
    """``lo[c, k]``, ``hi[c, k]``: the rectangle of chunk k's vertices ``vertices[starts[k]:starts[k + 1]]``
    (:class:`~csmlab.kernels.raster.mesh.ChunkVertices`, none empty) in cascade c's doubled fixed point ``points[c]``.

    A thread per cascade and chunk.
    """
    c, k = wp.tid()
    t = starts[k]
    end = starts[k + 1]
    low = points[c, vertices[t]]
    high = low
    while t < end:
        p = points[c, vertices[t]]
        low = vec2l(wp.min(low[0], p[0]), wp.min(low[1], p[1]))
        high = vec2l(wp.max(high[0], p[0]), wp.max(high[1], p[1]))
        t += 1
    lo[c, k] = low
    hi[c, k] = high
