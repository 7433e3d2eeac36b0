"""The scene's BVH on a device, and what the camera sees through it (DESIGN.md, CSM model step 5).

:func:`mesh_bvh` uploads a triangle mesh once: a float32 ``wp.Mesh`` for the BVH traversal, with
vertices taken relative to a float64 anchor (the bounds centre) so that a scene far from the world
origin keeps float32 precision, and the same vertices in float64 for refinement.

:func:`camera_hits` casts one ray per pixel centre (row 0 at the top). The BVH finds the hit
triangle in float32; the hit point is then recomputed in float64 as the ray's intersection with
that triangle's plane, so positions and view depths are as exact as the float64 geometry. (The
footprint of a pixel on that plane is :mod:`csmlab.kernels.footprint`'s.)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from csmlab.kernels import checked_device

__all__ = ["CameraHits", "MeshBVH", "camera_hits", "mesh_bvh"]


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
    """

    mesh: wp.Mesh
    vertices: wp.array
    triangles: wp.array
    anchor: np.ndarray
    diagonal: float
    device: str


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


def mesh_bvh(vertices, triangles, *, device: str = "cpu") -> MeshBVH:
    """Upload a triangle mesh and build its BVH.

    Parameters
    ----------
    vertices : array_like, shape (V, 3), float64
        World positions in metres.
    triangles : array_like, shape (T, 3), integer
        Vertex indices.
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
    return MeshBVH(
        mesh=wp.Mesh(points=points, indices=indices),
        vertices=wp.array(local, dtype=wp.vec3d, device=device),
        triangles=wp.array(t, dtype=wp.int32, device=device),
        anchor=anchor,
        diagonal=float(np.linalg.norm(hi - lo)),
        device=device,
    )


@wp.func
def plane_distance(n: wp.vec3d, point: wp.vec3d, origin: wp.vec3d, direction: wp.vec3d, t_max: wp.float64):
    """Ray parameter where ``origin + t·direction`` meets the plane through ``point`` with normal ``n``.

    A ray that meets the plane behind the camera, beyond ``t_max`` or not at all is taken at
    ``t_max`` (the far plane), so grazing differentials stay finite.
    """
    denom = wp.dot(n, direction)
    t = t_max
    if denom != wp.float64(0.0):
        s = wp.dot(n, point - origin) / denom
        if s > wp.float64(0.0) and s < t_max:
            t = s
    return t


@wp.kernel
def camera_hits_kernel(
    mesh: wp.uint64,
    vertices: wp.array(dtype=wp.vec3d),
    triangles: wp.array2d(dtype=wp.int32),
    origin: wp.vec3d,
    right: wp.vec3d,
    up: wp.vec3d,
    forward: wp.vec3d,
    step_x: wp.float64,
    step_y: wp.float64,
    far: wp.float64,
    position: wp.array2d(dtype=wp.vec3d),
    normal: wp.array2d(dtype=wp.vec3),
    triangle: wp.array2d(dtype=wp.int32),
    view_depth: wp.array2d(dtype=wp.float32),
):
    row, col = wp.tid()
    height = position.shape[0]
    width = position.shape[1]
    half = wp.float64(0.5)
    # Camera-space ray through the pixel centre with unit forward component, so that its ray
    # parameter is the view depth: x = (col + ½ − W/2)·step_x, y = (H/2 − row − ½)·step_y.
    sx = (wp.float64(col) + half - half * wp.float64(width)) * step_x
    sy = (half * wp.float64(height) - wp.float64(row) - half) * step_y
    direction = forward + right * sx + up * sy
    length = wp.length(direction)
    query = wp.mesh_query_ray(mesh, wp.vec3(origin), wp.vec3(direction / length), wp.float32(far * length))
    if not query.result:
        position[row, col] = wp.vec3d(wp.float64(wp.nan), wp.float64(wp.nan), wp.float64(wp.nan))
        normal[row, col] = wp.vec3(0.0)
        triangle[row, col] = -1
        view_depth[row, col] = wp.inf
        return
    face = query.face
    a = vertices[triangles[face, 0]]
    b = vertices[triangles[face, 1]]
    c = vertices[triangles[face, 2]]
    n = wp.cross(b - a, c - a)
    t = plane_distance(n, a, origin, direction, far)
    if t == far:
        # Edge-on hit: the plane is parallel to the ray; keep the BVH's float32 distance.
        t = wp.float64(query.t) / length
    hit = origin + direction * t
    n = wp.normalize(n)
    if wp.dot(n, direction) > wp.float64(0.0):
        n = -n
    position[row, col] = hit
    normal[row, col] = wp.vec3(n)
    triangle[row, col] = face
    view_depth[row, col] = wp.float32(wp.dot(hit - origin, forward))


def camera_hits(bvh: MeshBVH, *, position, rotation, fov_y_deg: float, aspect: float, far: float, width: int,
                height: int) -> CameraHits:
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

    Returns
    -------
    CameraHits
        Arrays of shape ``(height, width, ...)``, pixel ``(row, col)`` through the image point
        ``(col + ½, row + ½)`` with row 0 at the top.

    Raises
    ------
    ValueError
        On a non-positive image size, field of view outside (0, 180) or non-finite camera.
    """
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
    tan_y = np.tan(np.radians(fov_y_deg) / 2.0)
    device = bvh.device
    shape = (height, width)
    out_position = wp.empty(shape, dtype=wp.vec3d, device=device)
    out_normal = wp.empty(shape, dtype=wp.vec3, device=device)
    out_triangle = wp.empty(shape, dtype=wp.int32, device=device)
    out_depth = wp.empty(shape, dtype=wp.float32, device=device)
    wp.launch(
        camera_hits_kernel,
        dim=shape,
        inputs=(
            bvh.mesh.id, bvh.vertices, bvh.triangles, wp.vec3d(*eye), wp.vec3d(*r[:, 0]), wp.vec3d(*r[:, 1]),
            wp.vec3d(*(-r[:, 2])), float(2.0 * tan_y * aspect / width), float(2.0 * tan_y / height), float(far),
        ),
        outputs=(out_position, out_normal, out_triangle, out_depth),
        device=device,
    )
    return CameraHits(
        position=out_position.numpy() + bvh.anchor,
        normal=out_normal.numpy(),
        triangle=out_triangle.numpy(),
        view_depth=out_depth.numpy(),
    )
