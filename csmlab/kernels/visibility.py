"""The scene's BVH on a device, and what the camera sees (docs/design.md, CSM model step 5).

:func:`mesh_bvh` uploads a triangle mesh once: a float32 ``wp.Mesh`` for the BVH traversal, with
vertices taken relative to a float64 anchor (the bounds centre) so that a scene far from the world
origin keeps float32 precision, and the same vertices in float64 for the exact work.

:func:`camera_hits` finds the first triangle met by the ray through every pixel centre (row 0 at
the top) by one of :data:`VISIBILITY_METHODS`:

- ``raster`` — perspective rasterization, one thread per triangle (:func:`camera_hits_raster`):
  the coverage of a pixel centre is the exact float64 ray–triangle test, organised by triangle
  over its screen bounding box (Olano and Greer's homogeneous edge functions), nearest depth wins;
- ``ray`` — one ray per pixel through the BVH (:func:`camera_hits_ray`), the hit triangle found in
  float32 by ``wp.mesh_query_ray``.

Alpha-tested triangles (:mod:`csmlab.kernels.alpha`) are holes to the raster where their mask is
transparent at the coordinates interpolated with the pixel's edge functions (perspective-correct:
each edge function is the opposite vertex's barycentric weight times one common factor); the ray
method finds only the nearest triangle and refuses a masked scene.

Both then take the hit point in float64 as the ray's intersection with the hit triangle's plane,
with the same operations, so positions and view depths are as exact as the float64 geometry and
equal bit for bit wherever the two methods pick the same triangle — everywhere but within float32
rounding of an edge, where the ray cast's float32 test and the raster's float64 one may pick
different neighbours. (The footprint of a pixel on that plane is :mod:`csmlab.kernels.footprint`'s.)

Both take ``threads``: on the CPU, that many concurrent Warp launches share the work, each writing
its own part of the outputs (:mod:`csmlab.kernels.threads`), with the same result for every value.

References
----------
- Olano and Greer, "Triangle Scan Conversion using 2D Homogeneous Coordinates", Graphics Hardware
  1997 — edge functions of a triangle as planes through the eye, no clipping for coverage.
- Microsoft, Direct3D 11 rasterization rules — the top-left rule for centres on an edge.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np
import warp as wp

from csmlab.kernels import checked_device, device_empty
from csmlab.kernels.alpha import AlphaTextures, MaskedMesh, alpha_passes, masked_mesh
from csmlab.kernels.camera import PinholeCamera, pixel_ray, pixel_steps, pixel_x, pixel_y
from csmlab.kernels.threads import LaunchPool, checked_threads, split_range
from csmlab.registry import check_name

__all__ = ["CHUNK", "CameraHits", "MeshBVH", "NEAR_FRACTION", "VISIBILITY_METHODS", "camera_hits",
           "camera_hits_raster", "camera_hits_ray", "chunks_in_view", "mesh_bvh"]

# Products and sums rounded one by one on both devices (clang and NVRTC may otherwise contract them): a
# CUDA build may not contract them into fused multiply-adds, or its bits differ from the CPU's.
wp.set_module_options({"fuse_fp": False})

NEAR_FRACTION = 1e-9
"""The raster's near plane as a fraction of ``far``: hits nearer to the eye (in view depth) are not
rasterized — triangles crossing the camera plane are clipped there to bound the pixels they cover."""

MARGIN = wp.constant(wp.float64(1e-3))
"""Pixels by which the raster grows a triangle's projected bounding box against rounding."""

NO_TRIANGLE = wp.constant(2**31 - 1)
"""A pixel's nearest triangle before any covers it (larger than every index, for the atomic minimum)."""


@dataclass(frozen=True)
class MeshBVH:
    """A triangle mesh uploaded to one Warp device.

    Attributes
    ----------
    mesh : wp.Mesh
        float32 vertices relative to ``anchor``, with its BVH.
    vertices : wp.array, shape (V,), vec3d
        The same vertices in float64, metres relative to ``anchor``.
    triangles : wp.array, shape (T, 3), int32
        Vertex indices.
    anchor : ndarray, shape (3,), float64
        World position in metres that ``vertices`` are relative to (the bounds centre).
    diagonal : float
        Length in metres of the bounds' diagonal (the scene scale).
    device : str
    chunk_lo, chunk_hi : ndarray, shape (⌈T / CHUNK⌉, 3), float64
        Corners of the box around each chunk of :data:`CHUNK` consecutive triangles, metres
        relative to ``anchor``: the camera raster drops a chunk outside the view whole
        (:func:`chunks_in_view`).
    masks : MaskedMesh
        Texture coordinates and alpha masks of the vertices (zero-length arrays: no masks).
    light_space : dict
        What :mod:`csmlab.kernels.reference` derives from the vertices per light direction (their
        light-space coordinates), keyed by the direction: a static light transforms them once.
    """

    mesh: wp.Mesh
    vertices: wp.array
    triangles: wp.array
    anchor: np.ndarray
    diagonal: float
    device: str
    chunk_lo: np.ndarray
    chunk_hi: np.ndarray
    masks: MaskedMesh = field(default=None, compare=False, repr=False)
    light_space: dict = field(default_factory=dict, compare=False, repr=False)

    @property
    def masked(self) -> bool:
        """Whether any vertex carries an alpha mask."""
        return self.masks is not None and self.masks.vertex_mask.shape[0] > 0


@dataclass(frozen=True)
class CameraHits:
    """First hits of the camera rays, one per pixel (see :class:`csmlab.frame.GBuffer`).

    Attributes
    ----------
    position : ndarray, shape (H, W, 3), float64
        World position in metres; NaN on a miss.
    normal : ndarray, shape (H, W, 3), float32
        Unit geometric normal facing the camera; 0 on a miss.
    triangle : ndarray, shape (H, W), int32
        Hit triangle; -1 on a miss.
    view_depth : ndarray, shape (H, W), float32
        ``(X - C)·forward`` in metres; +inf on a miss.
    """

    position: np.ndarray
    normal: np.ndarray
    triangle: np.ndarray
    view_depth: np.ndarray


def mesh_bvh(vertices, triangles, *, uv=None, vertex_mask=None, alpha=(), device: str = "cpu") -> MeshBVH:
    """Upload a triangle mesh and build its BVH.

    Parameters
    ----------
    vertices : array_like, shape (V, 3), float64
        World positions in metres.
    triangles : array_like, shape (T, 3), integer
        Vertex indices.
    uv, vertex_mask, alpha
        The vertices' texture coordinates ``(V, 2)``, alpha masks ``(V,)`` (−1 opaque) and the
        :class:`~csmlab.scene.core.AlphaMask` records (:class:`csmlab.scene.core.Scene`); None: no masks.
    device : str
        ``"cpu"`` or ``"cuda"``.

    Returns
    -------
    MeshBVH

    Raises
    ------
    ValueError
        On empty or mis-shaped input, non-finite vertices or out-of-range indices.
    """
    device = checked_device(device)
    v = np.asarray(vertices, dtype=np.float64)
    t = np.ascontiguousarray(triangles, dtype=np.int32)
    if v.ndim != 2 or v.shape[1] != 3 or v.shape[0] == 0 or not np.all(np.isfinite(v)):
        raise ValueError(f"vertices: expected finite world positions of shape (V, 3), got shape {v.shape}")
    if t.ndim != 2 or t.shape[1] != 3 or t.shape[0] == 0 or t.min() < 0 or t.max() >= v.shape[0]:
        raise ValueError(f"triangles: expected indices of shape (T, 3) in [0, {v.shape[0]}), got shape {t.shape}")
    lo, hi = v.min(axis=0), v.max(axis=0)
    anchor = 0.5 * (lo + hi)
    local = np.ascontiguousarray(v - anchor)
    points = wp.array(local.astype(np.float32), dtype=wp.vec3, device=device)
    indices = wp.array(t.reshape(-1), dtype=wp.int32, device=device)
    # The last chunk is padded with its last triangle, which changes no minimum or maximum.
    chunk = local[t[np.minimum(np.arange(-(-len(t) // CHUNK) * CHUNK), len(t) - 1)]].reshape(-1, 3 * CHUNK, 3)
    return MeshBVH(
        mesh=wp.Mesh(points=points, indices=indices),
        vertices=wp.array(local, dtype=wp.vec3d, device=device),
        triangles=wp.array(t, dtype=wp.int32, device=device),
        anchor=anchor,
        diagonal=float(np.linalg.norm(hi - lo)),
        device=device,
        chunk_lo=chunk.min(axis=1),
        chunk_hi=chunk.max(axis=1),
        masks=masked_mesh(uv, vertex_mask, alpha, device=device),
    )


CHUNK = 32
"""Consecutive triangles the camera raster culls at once against the view (:func:`chunks_in_view`).

Meshes list neighbouring triangles together, so a chunk's box is small; on the default walk three
quarters of the ~1M-triangle terrain lies outside the view, in 72 % of its chunks, which are then
dropped on the host instead of triangle by triangle in the kernel.
"""


def chunks_in_view(bvh: MeshBVH, *, eye, right, up, forward, frustum, near: float, far: float) -> np.ndarray:
    """Chunks (:data:`CHUNK`) not wholly outside one of the camera raster's six half-spaces: ``(K,)`` int32, ascending.

    The half-spaces are those of :func:`camera_space_kernel`'s out-codes (nearer than ``near``,
    beyond ``far``, and beyond the four sides of ``frustum``, each a plane through the eye). A
    chunk is dropped only when its box lies outside one of them by far more than rounding (a
    millionth of the scene's size and distance), so every triangle in it would have been culled
    by its out-codes: the raster covers the same pixels.
    """
    eye = np.array([eye[0], eye[1], eye[2]], dtype=np.float64)
    axes = [np.array([a[0], a[1], a[2]], dtype=np.float64) for a in (right, up, forward)]
    right, up, forward = axes
    frustum = [float(frustum[k]) for k in range(4)]
    # Each half-space as n·(p − eye) > offset; a point is outside where it holds.
    planes = [(-forward, -near), (forward, far), (frustum[0] * forward - right, 0.0),
              (right - frustum[1] * forward, 0.0), (frustum[2] * forward - up, 0.0), (up - frustum[3] * forward, 0.0)]
    centre = 0.5 * (bvh.chunk_lo + bvh.chunk_hi) - eye
    extent = 0.5 * (bvh.chunk_hi - bvh.chunk_lo)
    margin = 1e-6 * (bvh.diagonal + float(np.linalg.norm(eye)) + abs(far))
    outside = np.zeros(len(centre), dtype=bool)
    for n, offset in planes:
        # The box's least value of n·(p − eye): outside when even that exceeds the offset.
        outside |= centre @ n - extent @ np.abs(n) > offset + margin * max(1.0, float(np.abs(n).sum()))
    return np.flatnonzero(~outside).astype(np.int32)


@wp.struct
class CameraSpaceVertices:
    """Every vertex in camera space and its out-code (:func:`camera_space_kernel`)."""

    camera: wp.array(dtype=wp.vec3d)
    """``(x, y, z)`` along right, up and forward relative to the eye, metres."""
    outcode: wp.array(dtype=wp.int32)
    """One bit per half-space of the view the vertex lies outside."""


@wp.struct
class ChunkRuns:
    """One launch's triangles: chunks of ``2**chunk_bits``, a thread per run of ``2**run_bits`` of them."""

    chunks: wp.array(dtype=wp.int32)
    chunk_bits: int
    run_bits: int


@wp.func
def hit_distance(n: wp.vec3d, offset: wp.float64, direction: wp.vec3d, t_max: wp.float64):
    """Ray parameter where ``origin + t·direction`` meets the plane ``n·(X − origin) = offset`` (:func:`face_plane`).

    A ray that meets the plane behind the camera, beyond ``t_max`` or not at all is taken at
    ``t_max`` (the far plane), so grazing differentials stay finite.
    """
    denom = wp.dot(n, direction)
    t = t_max
    if denom != wp.float64(0.0):
        s = offset / denom
        if s > wp.float64(0.0) and s < t_max:
            t = s
    return t


@wp.func
def face_plane(vertices: wp.array(dtype=wp.vec3d), triangles: wp.array2d(dtype=wp.int32), face: int,
               origin: wp.vec3d):
    """The plane of triangle ``face`` (vertices ``A, B, C``) as the rays from ``origin`` meet it: its normal
    ``n = (B − A)×(C − A)``, ``n`` normalized, and ``n·(A − origin)``."""
    a = vertices[triangles[face, 0]]
    b = vertices[triangles[face, 1]]
    c = vertices[triangles[face, 2]]
    n = wp.cross(b - a, c - a)
    return n, wp.normalize(n), wp.dot(n, a - origin)


@wp.func
def store_miss(
    row: int,
    col: int,
    position: wp.array2d(dtype=wp.vec3d),
    normal: wp.array2d(dtype=wp.vec3),
    triangle: wp.array2d(dtype=wp.int32),
    view_depth: wp.array2d(dtype=wp.float32),
):
    """Write a pixel whose ray hits nothing."""
    position[row, col] = wp.vec3d(wp.float64(wp.nan), wp.float64(wp.nan), wp.float64(wp.nan))
    normal[row, col] = wp.vec3(0.0)
    triangle[row, col] = -1
    view_depth[row, col] = wp.inf


@wp.func
def store_plane_hit(
    face: int,
    n: wp.vec3d,
    unit: wp.vec3d,
    offset: wp.float64,
    origin: wp.vec3d,
    direction: wp.vec3d,
    forward: wp.vec3d,
    far: wp.float64,
    edge_on: wp.float64,
    anchor: wp.vec3d,
    row: int,
    col: int,
    position: wp.array2d(dtype=wp.vec3d),
    normal: wp.array2d(dtype=wp.vec3),
    triangle: wp.array2d(dtype=wp.int32),
    view_depth: wp.array2d(dtype=wp.float32),
):
    """Write the hit of ray ``origin + t·direction`` on triangle ``face``, whose plane :func:`face_plane` gave.

    The hit is the ray's float64 intersection with the triangle's plane; a ray the plane does not
    meet in (0, far) — the triangle seen edge-on — is taken at ``edge_on`` instead. ``position``
    gets it in world metres (``+ anchor``), ``view_depth`` relative to the eye.
    """
    t = hit_distance(n, offset, direction, far)
    if t == far:
        t = edge_on
    hit = origin + direction * t
    facing = unit
    if wp.dot(facing, direction) > wp.float64(0.0):
        facing = -facing
    position[row, col] = hit + anchor
    normal[row, col] = wp.vec3(facing)
    triangle[row, col] = face
    view_depth[row, col] = wp.float32(wp.dot(hit - origin, forward))


@wp.kernel
def camera_hits_kernel(
    mesh: wp.uint64,
    vertices: wp.array(dtype=wp.vec3d),
    triangles: wp.array2d(dtype=wp.int32),
    pinhole: PinholeCamera,
    row0: int,
    position: wp.array2d(dtype=wp.vec3d),
    normal: wp.array2d(dtype=wp.vec3),
    triangle: wp.array2d(dtype=wp.int32),
    view_depth: wp.array2d(dtype=wp.float32),
):
    """The rows ``row0 + i`` of the image (a band when the launch is split over threads)."""
    i, col = wp.tid()
    row = row0 + i
    origin = pinhole.eye
    forward = pinhole.forward
    far = pinhole.far
    # The ray's parameter is the view depth (its forward component is 1).
    direction = pixel_ray(pinhole, row, col, position.shape[0], position.shape[1])
    length = wp.length(direction)
    query = wp.mesh_query_ray(mesh, wp.vec3(origin), wp.vec3(direction / length), wp.float32(far * length))
    face = int(-1)
    edge_on = wp.float64(0.0)
    if query.result:
        face = query.face
        # An edge-on hit keeps the BVH's float32 distance.
        edge_on = wp.float64(query.t) / length
    if face < 0:
        store_miss(row, col, position, normal, triangle, view_depth)
    else:
        n, unit, offset = face_plane(vertices, triangles, face, origin)
        store_plane_hit(face, n, unit, offset, origin, direction, forward, far, edge_on, pinhole.anchor, row, col,
                        position, normal, triangle, view_depth)


@wp.kernel
def camera_space_kernel(
    vertices: wp.array(dtype=wp.vec3d),
    pinhole: PinholeCamera,
    camera: wp.array(dtype=wp.vec3d),
    outcode: wp.array(dtype=wp.int32),
):
    v = wp.tid()
    near = pinhole.near
    far = pinhole.far
    frustum = pinhole.frustum
    p = vertices[v] - pinhole.eye
    x = wp.dot(p, pinhole.right)
    y = wp.dot(p, pinhole.up)
    z = wp.dot(p, pinhole.forward)
    camera[v] = wp.vec3d(x, y, z)
    # One bit per half-space through the eye (and the near and far planes) the vertex lies
    # outside; a triangle whose three vertices share a bit lies wholly outside that half-space,
    # and so does every hit on it.
    code = int(0)
    if z < near:
        code = code | 1
    if z > far:
        code = code | 2
    if x < frustum[0] * z:
        code = code | 4
    if x > frustum[1] * z:
        code = code | 8
    if y < frustum[2] * z:
        code = code | 16
    if y > frustum[3] * z:
        code = code | 32
    outcode[v] = code


@wp.func
def grown(box: wp.vec4d, x: wp.float64, y: wp.float64) -> wp.vec4d:
    """``box`` (x lo, x hi, y lo, y hi) grown to hold the point ``(x, y)``."""
    return wp.vec4d(wp.min(box[0], x), wp.max(box[1], x), wp.min(box[2], y), wp.max(box[3], y))


@wp.func
def clipped_bounds(p: wp.vec3d, q: wp.vec3d, near: wp.float64, box: wp.vec4d) -> wp.vec4d:
    """``box`` grown by the image-plane projection of ``p`` if it lies beyond the near plane, and of
    the point where edge ``pq`` crosses the near plane if it does (Sutherland–Hodgman, one plane)."""
    out = box
    if p[2] >= near:
        out = grown(out, p[0] / p[2], p[1] / p[2])
    if (p[2] < near) != (q[2] < near):
        s = (near - p[2]) / (q[2] - p[2])
        out = grown(out, (p[0] + (q[0] - p[0]) * s) / near, (p[1] + (q[1] - p[1]) * s) / near)
    return out


@wp.func
def inward_edge(i: int, j: int, p: wp.vec3d, q: wp.vec3d, orientation: wp.float64) -> wp.vec3d:
    """Normal of the plane through the eye and edge ``ij`` (vertices ``p``, ``q``), pointing into the triangle.

    The cross product is always taken from the lower vertex index to the higher, so that the two
    triangles sharing an edge get the same vector, exactly negated: a pixel centre's edge function
    is then ``+e`` in one and ``−e`` in the other, bit for bit, and the tie rule gives it to one.
    """
    e = wp.cross(q, p)
    if i < j:
        e = wp.cross(p, q)
    if (i < j) != (orientation > wp.float64(0.0)):
        e = -e
    return e


@wp.func
def edge_owns_centre(g: wp.vec3d) -> bool:
    """Top-left rule: a centre exactly on the edge belongs to the triangle it would enter nudged toward
    +x, or slightly −y when the edge is parallel to x (as in :mod:`csmlab.kernels.raster`)."""
    return g[0] > wp.float64(0.0) or (g[0] == wp.float64(0.0) and g[1] < wp.float64(0.0))


@wp.func
def edge_inside(e: wp.float64, owns: bool) -> bool:
    return e > wp.float64(0.0) or (e == wp.float64(0.0) and owns)


@wp.func
def raster_view_triangle(
    face: int,
    camera: wp.array(dtype=wp.vec3d),
    outcode: wp.array(dtype=wp.int32),
    triangles: wp.array2d(dtype=wp.int32),
    step_x: wp.float64,
    step_y: wp.float64,
    near: wp.float64,
    far: wp.float64,
    resolve: int,
    uv: wp.array(dtype=wp.vec2d),
    vertex_mask: wp.array(dtype=wp.int32),
    textures: AlphaTextures,
    depth: wp.array2d(dtype=wp.float64),
    nearest: wp.array2d(dtype=wp.int32),
):
    """Triangle ``face`` into ``depth`` and ``nearest``: the pixels whose centre it covers within ``[near, far]``
    (and where its alpha mask, if any, is opaque)."""
    ia = triangles[face, 0]
    ib = triangles[face, 1]
    ic = triangles[face, 2]
    if (outcode[ia] & outcode[ib] & outcode[ic]) != 0:
        return
    m = int(-1)
    if vertex_mask.shape[0] > 0:
        m = vertex_mask[ia]
    a = camera[ia]
    b = camera[ib]
    c = camera[ic]
    # Plane of the triangle: n·X = n·A. The ray t·(x, y, 1) meets it at depth t = n·A / n·(x, y, 1);
    # n·A = 0 is a plane through the eye, the triangle seen edge-on, which covers no centre.
    n = wp.cross(b - a, c - a)
    plane = wp.dot(n, a)
    if plane == wp.float64(0.0):
        return
    height = depth.shape[0]
    width = depth.shape[1]
    inf = wp.float64(wp.inf)
    box = wp.vec4d(inf, -inf, inf, -inf)
    box = clipped_bounds(a, b, near, box)
    box = clipped_bounds(b, c, near, box)
    box = clipped_bounds(c, a, near, box)
    # Columns and rows whose centre lies in the box grown by a thousandth of a pixel, far more
    # than the projection's rounding: a triangle between centres (the distant terrain's, mostly)
    # returns here. The exact test below decides for the others.
    half = wp.float64(0.5)
    w = wp.float64(width)
    h = wp.float64(height)
    limit = wp.float64(2.0) + wp.max(w, h)
    col0 = wp.max(int(wp.ceil(wp.clamp(box[0] / step_x + half * w - half - MARGIN, -limit, limit))), 0)
    col1 = wp.min(int(wp.floor(wp.clamp(box[1] / step_x + half * w - half + MARGIN, -limit, limit))), width - 1)
    row0 = wp.max(int(wp.ceil(wp.clamp(half * h - half - box[3] / step_y - MARGIN, -limit, limit))), 0)
    row1 = wp.min(int(wp.floor(wp.clamp(half * h - half - box[2] / step_y + MARGIN, -limit, limit))), height - 1)
    if col0 > col1 or row0 > row1:
        return
    # The ray through a centre meets the triangle when it lies on the inner side of the three
    # planes through the eye and an edge: g·(x, y, 1) ≥ 0 for each inward normal g. The sign of
    # n·A (the determinant |A B C|) tells which side is inner, also for a triangle crossing the
    # camera plane, so no clipping enters the coverage test.
    g_ab = inward_edge(ia, ib, a, b, plane)
    g_bc = inward_edge(ib, ic, b, c, plane)
    g_ca = inward_edge(ic, ia, c, a, plane)
    own_ab = edge_owns_centre(g_ab)
    own_bc = edge_owns_centre(g_bc)
    own_ca = edge_owns_centre(g_ca)
    # `while` loops: a range known only at run time costs Warp's CPU code several times more per step.
    row = row0
    while row <= row1:
        y = pixel_y(row, height, step_y)
        k_ab = g_ab[1] * y + g_ab[2]
        k_bc = g_bc[1] * y + g_bc[2]
        k_ca = g_ca[1] * y + g_ca[2]
        k_n = n[1] * y + n[2]
        entered = bool(False)
        col = col0
        while col <= col1:
            x = pixel_x(col, width, step_x)
            if (edge_inside(g_ab[0] * x + k_ab, own_ab) and edge_inside(g_bc[0] * x + k_bc, own_bc)
                    and edge_inside(g_ca[0] * x + k_ca, own_ca)):
                entered = True
                t = plane / (n[0] * x + k_n)
                opaque = bool(True)
                if m >= 0:
                    # Each edge function is its opposite vertex's barycentric weight times one factor.
                    e_ab = g_ab[0] * x + k_ab
                    e_bc = g_bc[0] * x + k_bc
                    e_ca = g_ca[0] * x + k_ca
                    at = (e_bc * uv[ia] + e_ca * uv[ib] + e_ab * uv[ic]) / (e_ab + e_bc + e_ca)
                    opaque = alpha_passes(textures, m, at[0], at[1])
                if opaque and t >= near and t <= far:
                    if resolve == 0:
                        # One thread (Warp's CPU launch): compare and write, nearest then lowest index.
                        best = depth[row, col]
                        if t < best or (t == best and face < nearest[row, col]):
                            depth[row, col] = t
                            nearest[row, col] = face
                    elif resolve == 1:
                        wp.atomic_min(depth, row, col, t)
                    elif t == depth[row, col]:
                        wp.atomic_min(nearest, row, col, face)
            elif entered:
                # Each edge function, rounded, is monotone along the row (a product by the
                # increasing x plus a row constant), so the covered centres form one run.
                break
            col += 1
        row += 1


@wp.kernel
def raster_view_kernel(
    view: CameraSpaceVertices,
    triangles: wp.array2d(dtype=wp.int32),
    pinhole: PinholeCamera,
    resolve: int,
    work: ChunkRuns,
    uv: wp.array(dtype=wp.vec2d),
    vertex_mask: wp.array(dtype=wp.int32),
    textures: AlphaTextures,
    depth: wp.array2d(dtype=wp.float64),
    nearest: wp.array2d(dtype=wp.int32),
):
    """The triangles of ``work``'s chunks (of ``2**chunk_bits`` each), into their own ``depth`` and ``nearest``
    (one pair per concurrent launch).

    A thread per run of ``2**run_bits`` of them: on the CPU a whole chunk, so that a thread's set-up
    serves them all; on a GPU one.
    """
    chunk_bits = work.chunk_bits
    run_bits = work.run_bits
    # The structs' fields as locals: raster_view_triangle runs per triangle, and a struct passed to
    # it would be copied each time (Warp passes structs by value).
    camera = view.camera
    outcode = view.outcode
    step_x = pinhole.step_x
    step_y = pinhole.step_y
    near = pinhole.near
    far = pinhole.far
    first = wp.tid() << run_bits
    face = (work.chunks[first >> chunk_bits] << chunk_bits) + (first & ((1 << chunk_bits) - 1))
    end = wp.min(face + (1 << run_bits), triangles.shape[0])
    while face < end:
        raster_view_triangle(face, camera, outcode, triangles, step_x, step_y, near, far, resolve, uv, vertex_mask,
                             textures, depth, nearest)
        face += 1


@wp.kernel
def raster_hits_kernel(
    vertices: wp.array(dtype=wp.vec3d),
    triangles: wp.array2d(dtype=wp.int32),
    nearest: wp.array3d(dtype=wp.int32),
    depth: wp.array3d(dtype=wp.float64),
    pinhole: PinholeCamera,
    run: int,
    row0: int,
    position: wp.array2d(dtype=wp.vec3d),
    normal: wp.array2d(dtype=wp.vec3),
    triangle: wp.array2d(dtype=wp.int32),
    view_depth: wp.array2d(dtype=wp.float32),
):
    """The rows ``row0 + i``: each pixel's smallest ``(depth, triangle)`` over the raster's buffers, and its hit.

    A thread per run of ``run`` columns of a row: on the CPU the whole row, so that a thread's start
    (which copies every argument, the camera's struct included) serves all of its pixels; on a GPU one.
    """
    i, j = wp.tid()
    row = row0 + i
    height = position.shape[0]
    width = position.shape[1]
    parts = nearest.shape[0]
    eye = pinhole.eye
    forward = pinhole.forward
    right = pinhole.right
    far = pinhole.far
    anchor = pinhole.anchor
    step_x = pinhole.step_x
    # The ray's up part, the same for the whole row (added last, as in pixel_ray).
    lift = pinhole.up * pixel_y(row, height, pinhole.step_y)
    col = j * run
    end = wp.min(col + run, width)
    plane_face = int(-1)
    n = wp.vec3d()
    unit = wp.vec3d()
    offset = wp.float64(0.0)
    # A `while` loop: a range known only at run time costs Warp's CPU code several times more per step.
    while col < end:
        direction = forward + right * pixel_x(col, width, step_x) + lift
        # The order of the triangles does not change a lexicographic minimum: merging the buffers of
        # any split of them gives the pixel one launch over all of them would.
        face = NO_TRIANGLE
        t = wp.float64(wp.inf)
        k = int(0)
        while k < parts:
            d = depth[k, row, col]
            f = nearest[k, row, col]
            if d < t or (d == t and f < face):
                t = d
                face = f
            k += 1
        if face == NO_TRIANGLE:
            store_miss(row, col, position, normal, triangle, view_depth)
        else:
            # Most pixels hit their left neighbour's triangle: its plane is taken once for the run.
            if face != plane_face:
                n, unit, offset = face_plane(vertices, triangles, face, eye)
                plane_face = face
            # An edge-on hit keeps the raster's camera-space depth.
            store_plane_hit(face, n, unit, offset, eye, direction, forward, far, t, anchor, row, col, position, normal,
                            triangle, view_depth)
        col += 1


def _pinhole(bvh: MeshBVH, position, rotation, fov_y_deg: float, aspect: float, far: float, width: int,
             height: int) -> tuple:
    """Checked camera: eye relative to the anchor, right, up, forward (vec3d) and the image-plane pixel steps."""
    if not (isinstance(width, (int, np.integer)) and isinstance(height, (int, np.integer)) and width > 0
            and height > 0):
        raise ValueError(f"width, height: expected positive pixel counts, got {width!r} x {height!r}")
    if not 0.0 < fov_y_deg < 180.0 or not aspect > 0.0 or not far > 0.0:
        raise ValueError(f"camera: expected fov_y_deg in (0, 180), aspect > 0 and far > 0, "
                         f"got {fov_y_deg}, {aspect}, {far}")
    r = np.asarray(rotation, dtype=np.float64)
    eye = np.asarray(position, dtype=np.float64) - bvh.anchor
    if r.shape != (3, 3) or eye.shape != (3,) or not (np.all(np.isfinite(r)) and np.all(np.isfinite(eye))):
        raise ValueError("camera: expected a finite position (3,) and rotation (3, 3)")
    return (wp.vec3d(*eye), wp.vec3d(*r[:, 0]), wp.vec3d(*r[:, 1]), wp.vec3d(*(-r[:, 2])),
            *pixel_steps(fov_y_deg, aspect, width, height))


def _jittered(camera: tuple, jitter) -> tuple[tuple, tuple]:
    """``camera`` for the coverage pass and for the hits pass, each moved by a sub-pixel ``jitter`` ``(x, y)``.

    A jittered pixel's ray is ``forward + (x_c + j_x·step_x)·right + (y_c − j_y·step_y)·up`` (``x_c, y_c``
    its centre's image-plane point, rows growing down): the hits pass gets the forward axis tilted
    by ``j_x·step_x·right − j_y·step_y·up`` (still of unit forward component, so a ray's parameter
    stays its view depth); the coverage pass the right and up axes sheared by ``−j_x·step_x·forward``
    and ``+j_y·step_y·forward``, so that a centre covered in the sheared camera space is the
    jittered ray's. A zero jitter returns ``camera`` itself for both.
    """
    jx, jy = (float(v) for v in jitter)
    if jx == 0.0 and jy == 0.0:
        return camera, camera
    eye, right, up, forward, step_x, step_y = camera
    r, u, f = (np.array([float(v) for v in axis]) for axis in (right, up, forward))
    tilted = wp.vec3d(*(f + (jx * step_x) * r - (jy * step_y) * u))
    sheared = (eye, wp.vec3d(*(r - (jx * step_x) * f)), wp.vec3d(*(u + (jy * step_y) * f)), forward, step_x, step_y)
    return sheared, (eye, right, up, tilted, step_x, step_y)


def _pinhole_camera(bvh: MeshBVH, camera: tuple, *, far: float, frustum=None) -> PinholeCamera:
    """The :class:`PinholeCamera` of :func:`_pinhole`'s ``camera``, clipped at ``far`` (and :data:`NEAR_FRACTION` of it)
    with the raster's padded ``frustum`` (unset for the ray cast, which reads none)."""
    pinhole = PinholeCamera()
    pinhole.eye, pinhole.right, pinhole.up, pinhole.forward, pinhole.step_x, pinhole.step_y = camera
    pinhole.near = float(NEAR_FRACTION * far)
    pinhole.far = float(far)
    if frustum is not None:
        pinhole.frustum = frustum
    pinhole.anchor = wp.vec3d(*bvh.anchor)
    return pinhole


def _hits_record(bvh: MeshBVH, shape: tuple[int, int], pool: LaunchPool, kernel, inputs: tuple,
                 columns: int | None = None) -> CameraHits:
    """Allocate the output arrays, launch ``kernel`` over bands of rows (``inputs``, then the band's first row)
    and return them as host arrays; ``columns``: the threads a row is cut into (None: one per pixel)."""
    device = bvh.device
    outputs = (device_empty(shape, wp.vec3d, device), device_empty(shape, wp.vec3, device),
               device_empty(shape, wp.int32, device), device_empty(shape, wp.float32, device))
    pool.run([functools.partial(wp.launch, kernel, dim=(hi - lo, shape[1] if columns is None else columns),
                                inputs=(*inputs, lo), outputs=outputs, device=device)
              for lo, hi in split_range(shape[0], pool.threads)])
    position, normal, triangle, view_depth = (a.numpy() for a in outputs)
    return CameraHits(position=position, normal=normal, triangle=triangle, view_depth=view_depth)


def camera_hits_ray(bvh: MeshBVH, *, position, rotation, fov_y_deg: float, aspect: float, far: float, width: int,
                    height: int, threads: int = 1, jitter=(0.0, 0.0)) -> CameraHits:
    """:func:`camera_hits` by one BVH ray per pixel centre: the hit triangle found in float32.

    ``max_t = far·|d|``: hits beyond view depth ``far`` (to float32 rounding) are not found. This is
    the raster's independent oracle in the tests. With ``threads`` > 1 on the CPU, each thread casts
    the rays of one band of rows.

    Raises
    ------
    ValueError
        On a mesh with alpha masks: the nearest triangle a ray meets may be a hole there.
    """
    if bvh.masked:
        raise ValueError("method: the ray method finds only the nearest triangle and cannot see through alpha "
                         "masks; expected \"raster\" for a masked scene")
    _, rays = _jittered(_pinhole(bvh, position, rotation, fov_y_deg, aspect, far, width, height), jitter)
    pinhole = _pinhole_camera(bvh, rays, far=far)
    threads = checked_threads(threads, bvh.device)
    with LaunchPool(threads, kernels=(camera_hits_kernel,), device=bvh.device) as pool:
        return _hits_record(bvh, (height, width), pool, camera_hits_kernel,
                            (bvh.mesh.id, bvh.vertices, bvh.triangles, pinhole))


def camera_hits_raster(bvh: MeshBVH, *, position, rotation, fov_y_deg: float, aspect: float, far: float, width: int,
                       height: int, threads: int = 1, atomic: bool | None = None, jitter=(0.0, 0.0)) -> CameraHits:
    """:func:`camera_hits` by perspective rasterization of every triangle: coverage and depth in float64.

    Parameters
    ----------
    atomic : bool, optional
        How concurrent writes to a pixel are resolved: None picks by device — one compare-and-write
        pass on ``"cpu"`` (a Warp CPU launch runs its threads one after another), two atomic passes
        on CUDA. Both give the same pixels; ``True`` on the CPU tests the CUDA path.
    (the others as :func:`camera_hits`)

    Notes
    -----
    Three launches, or four with atomics, each split over ``threads`` concurrent CPU launches
    (:mod:`csmlab.kernels.threads`) that write disjoint outputs:

    1. every vertex to camera space, ``(x, y, z)`` along right, up and forward relative to the eye,
       with an out-code: which of the six half-spaces (``z ≥ near``, ``z ≤ far`` and the four
       through the eye and the image's sides, padded by a pixel) it lies outside, where
       ``near = NEAR_FRACTION·far`` — each thread a range of vertices;
    2. one thread per triangle of the chunks the host did not drop whole (:func:`chunks_in_view`):
       a triangle with all three vertices outside one half-space returns
       (behind the camera, beyond ``far`` or off-screen); the others walk the pixels of their
       image-plane bounding box — of the triangle clipped to ``z ≥ near``, so that triangles crossing
       the camera plane (underfoot, beside a walking camera) bound their pixels too — and test each
       centre with the exact ray test: the centre ``(x, y)`` is covered when ``g·(x, y, 1) ≥ 0``
       for the three inward normals ``g`` of the planes through the eye and an edge (the top-left
       rule on ties, so each centre on an edge shared by two triangles goes to one). Its depth is
       ``t = n·A / n·(x, y, 1)``, kept for ``near ≤ t ≤ far``. A pixel keeps the smallest
       ``(t, triangle)``: in place on one CPU thread; on CUDA an ``atomic_min`` of ``t`` in a first
       pass, then of the triangle index among those whose ``t`` equals the minimum in a second —
       either way the result does not depend on the order of the threads. Split over threads, launch
       ``k`` takes the chunks ``k, k + threads, …`` of those left (interleaved, so that near and far
       triangles, small and large, fall to every launch alike) into its own depth and triangle buffers;
    3. per pixel, the smallest ``(t, triangle)`` over those buffers, and the hit on that triangle as
       the ray method computes it — each thread a band of rows; on the CPU a kernel thread walks a
       whole row, taking a triangle's plane once for the run of pixels that hit it.

    The minimum of ``(t, triangle)`` pairs does not depend on how they are grouped, so every
    ``threads`` gives the same pixels, bit for bit.
    """
    unjittered = _pinhole(bvh, position, rotation, fov_y_deg, aspect, far, width, height)
    camera, rays = _jittered(unjittered, jitter)
    eye, right, up, forward, step_x, step_y = unjittered
    device = bvh.device
    threads = checked_threads(threads, device)
    atomic = device != "cpu" if atomic is None else bool(atomic)
    # The image's extent on the plane at unit depth, padded by a pixel against rounding.
    frustum = wp.vec4d(-(0.5 * width + 1.0) * step_x, (0.5 * width + 1.0) * step_x,
                       -(0.5 * height + 1.0) * step_y, (0.5 * height + 1.0) * step_y)
    pinhole = _pinhole_camera(bvh, camera, far=far, frustum=frustum)
    hits_pinhole = pinhole if rays is camera else _pinhole_camera(bvh, rays, far=far, frustum=frustum)
    vertex_count = bvh.vertices.shape[0]
    view = CameraSpaceVertices()
    view.camera = device_empty(vertex_count, wp.vec3d, device)
    view.outcode = device_empty(vertex_count, wp.int32, device)
    visible = chunks_in_view(bvh, eye=eye, right=right, up=up, forward=forward, frustum=frustum, near=pinhole.near,
                             far=far)
    parts = max(1, min(threads, len(visible)))
    depth = device_empty((parts, height, width), wp.float64, device)
    nearest = device_empty((parts, height, width), wp.int32, device)
    chunk_bits = CHUNK.bit_length() - 1
    run_bits = chunk_bits if wp.get_device(device).is_cpu else 0

    def rasterize(k: int) -> None:
        depth[k].fill_(np.inf)
        nearest[k].fill_(int(NO_TRIANGLE))
        # Launch k takes the chunks k, k + parts, …: near and far, small and large alike.
        work = ChunkRuns()
        work.chunks = wp.array(visible[k::parts], dtype=wp.int32, device=device)
        work.chunk_bits = chunk_bits
        work.run_bits = run_bits
        if work.chunks.shape[0] == 0:
            return
        for resolve in ((1, 2) if atomic else (0,)):
            wp.launch(raster_view_kernel, dim=work.chunks.shape[0] << (chunk_bits - run_bits),
                      inputs=(view, bvh.triangles, pinhole, resolve, work, bvh.masks.uv, bvh.masks.vertex_mask,
                              bvh.masks.textures), outputs=(depth[k], nearest[k]),
                      device=device)

    with LaunchPool(threads, kernels=(raster_view_kernel,), device=device) as pool:
        pool.run([functools.partial(wp.launch, camera_space_kernel, dim=hi - lo,
                                    inputs=(bvh.vertices[lo:hi], pinhole),
                                    outputs=(view.camera[lo:hi], view.outcode[lo:hi]), device=device)
                  for lo, hi in split_range(vertex_count, threads)])
        pool.run([functools.partial(rasterize, k) for k in range(parts)])
        # On the CPU a thread per row (raster_hits_kernel's run), on a GPU per pixel.
        run = width if wp.get_device(device).is_cpu else 1
        return _hits_record(bvh, (height, width), pool, raster_hits_kernel,
                            (bvh.vertices, bvh.triangles, nearest, depth, hits_pinhole, run), columns=width // run)


VISIBILITY_METHODS = {"raster": camera_hits_raster, "ray": camera_hits_ray}
"""How :func:`camera_hits` finds the first hit of each pixel's ray, by name."""


def camera_hits(bvh: MeshBVH, *, position, rotation, fov_y_deg: float, aspect: float, far: float, width: int,
                height: int, method: str = "raster", threads: int = 1, jitter=(0.0, 0.0)) -> CameraHits:
    """First hit of the ray through every pixel centre of a pinhole camera.

    Parameters
    ----------
    bvh : MeshBVH
        The scene, on the device the kernel runs on.
    position : array_like, shape (3,), float64
        Camera position, world metres.
    rotation : array_like, shape (3, 3), float64
        Camera-to-world rotation; columns are the camera's right, up and back (−forward) axes.
    fov_y_deg : float
        Vertical field of view, degrees.
    aspect : float
        Width / height of the image plane (the frustum's, which the cascades use too).
    far : float
        Far plane distance, metres of view depth; nothing beyond it is hit.
    width, height : int
        Image size in pixels.
    method : str
        A key of :data:`VISIBILITY_METHODS`: ``"raster"`` (exact coverage, the faster on the
        default scene) or ``"ray"`` (BVH rays, float32 coverage).
    threads : int
        Concurrent CPU launches (:mod:`csmlab.kernels.threads`), each writing its own part of the
        outputs; the result is the same, bit for bit, for every value. Ignored on CUDA.
    jitter : tuple of float
        Sub-pixel camera jitter ``(x, y)`` in pixels (x right, y down): pixel ``(row, col)`` takes
        the ray through ``(col + ½ + x, row + ½ + y)`` (temporal anti-aliasing, :mod:`csmlab.metrics.taa`).

    Returns
    -------
    CameraHits
        Arrays of shape ``(height, width, ...)``, pixel ``(row, col)`` through the image point
        ``(col + ½, row + ½)`` with row 0 at the top.

    Raises
    ------
    ValueError
        On an unknown method, a non-positive image size, field of view outside (0, 180),
        non-finite camera or ``threads`` not an integer ≥ 1.
    """
    return VISIBILITY_METHODS[check_name(method, VISIBILITY_METHODS, field="method")](
        bvh, position=position, rotation=rotation, fov_y_deg=fov_y_deg, aspect=aspect, far=far, width=width,
        height=height, threads=threads, jitter=jitter)
