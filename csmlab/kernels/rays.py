"""First hits of arbitrary rays against a scene's BVH (:func:`ray_hits`): the level's probes.

The camera G-buffer (:mod:`csmlab.kernels.visibility`) casts one ray per pixel of one view; the
level's ground under a point and the check of a path's views (:mod:`csmlab.scene.level`,
:mod:`csmlab.paths.view_check`) cast a few rays from many places at once — vertical rays over a
grid, a sparse grid of view rays per frame. They go through the same float32 ``wp.Mesh`` built by
:func:`~csmlab.kernels.visibility.mesh_bvh`, whose vertices are relative to its anchor: origins
are taken relative to the anchor in float64 first, so a level far from the world origin keeps
float32 precision. Alpha masks are not applied: a ray stops at the first triangle it meets.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from csmlab.kernels import device_empty
from csmlab.kernels.visibility import MeshBVH

# Products and sums rounded one by one on every device, so CUDA finds the hits the CPU finds.
wp.set_module_options({"fuse_fp": False})

__all__ = ["RayHits", "ray_hits"]


@dataclass(frozen=True)
class RayHits:
    """The first triangle each ray meets.

    Attributes
    ----------
    distance : ndarray, shape (N,), float64
        Along the unit direction, metres (float32 precision); +inf on a miss.
    triangle : ndarray, shape (N,), int32
        Index of the hit triangle in the mesh given to :func:`~csmlab.kernels.visibility.mesh_bvh`; -1 on a miss.
    """

    distance: np.ndarray
    triangle: np.ndarray


@wp.kernel
def ray_hits_kernel(
    mesh: wp.uint64,
    origins: wp.array(dtype=wp.vec3),
    directions: wp.array(dtype=wp.vec3),
    max_distance: wp.float32,
    distance: wp.array(dtype=wp.float32),
    triangle: wp.array(dtype=wp.int32),
):
    """Ray ``i`` from ``origins[i]`` (relative to the mesh's anchor) along the unit ``directions[i]``."""
    i = wp.tid()
    query = wp.mesh_query_ray(mesh, origins[i], directions[i], max_distance)
    if query.result:
        distance[i] = query.t
        triangle[i] = query.face
    else:
        distance[i] = wp.inf
        triangle[i] = -1


def ray_hits(bvh: MeshBVH, origins, directions, *, max_distance: float) -> RayHits:
    """The first triangle each ray meets within ``max_distance``.

    Parameters
    ----------
    bvh : MeshBVH
        The mesh (:func:`~csmlab.kernels.visibility.mesh_bvh`).
    origins : array_like, shape (N, 3)
        World positions in metres.
    directions : array_like, shape (N, 3)
        Non-zero directions (normalised here).
    max_distance : float
        Metres, > 0; farther hits count as misses.

    Returns
    -------
    RayHits

    Raises
    ------
    ValueError
        On mis-shaped or non-finite input, a zero direction or a non-positive ``max_distance``.
    """
    o = np.asarray(origins, dtype=np.float64)
    d = np.asarray(directions, dtype=np.float64)
    if o.ndim != 2 or o.shape[1] != 3 or d.shape != o.shape:
        raise ValueError(f"origins, directions: expected two (N, 3) arrays, got shapes {o.shape} and {d.shape}")
    if not (np.all(np.isfinite(o)) and np.all(np.isfinite(d))):
        raise ValueError("origins, directions: expected finite numbers, found NaN or inf")
    length = np.linalg.norm(d, axis=1)
    if np.any(length == 0.0):
        raise ValueError("directions: expected non-zero vectors, found a zero one")
    if not (np.isfinite(max_distance) and max_distance > 0):
        raise ValueError(f"max_distance: expected a positive number of metres, got {max_distance}")
    n = o.shape[0]
    if n == 0:
        return RayHits(distance=np.zeros(0), triangle=np.zeros(0, np.int32))
    device = bvh.device
    distance = device_empty(n, wp.float32, device)
    triangle = device_empty(n, wp.int32, device)
    wp.launch(ray_hits_kernel, dim=n, device=device, inputs=[
        bvh.mesh.id,
        wp.array((o - bvh.anchor).astype(np.float32), dtype=wp.vec3, device=device),
        wp.array((d / length[:, None]).astype(np.float32), dtype=wp.vec3, device=device),
        wp.float32(max_distance),
        distance, triangle])
    return RayHits(distance=distance.numpy().astype(np.float64), triangle=triangle.numpy())
