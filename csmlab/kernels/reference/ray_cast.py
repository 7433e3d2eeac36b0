"""The reference's ``ray`` method: one float32 any-hit ray per receiver through the scene's BVH
(``wp.mesh_query_ray_anyhit``), through alpha masks by stepping past each hole — the independent
oracle of the tests (:mod:`csmlab.kernels.reference`)."""

from __future__ import annotations

import functools

import numpy as np
import warp as wp

from csmlab.kernels.alpha import AlphaTextures, alpha_passes
from csmlab.kernels.reference.shadow_rays import RAY_LENGTH, RAY_OFFSET, checked_receivers
from csmlab.kernels.threads import LaunchPool, checked_threads, split_range
from csmlab.kernels.visibility import MeshBVH

__all__ = ["MASKED_HITS", "hard_shadow_ray"]

# Products and sums rounded one by one on both devices (clang and NVRTC may otherwise contract them): a
# CUDA build may not contract them into fused multiply-adds, or its bits differ from the CPU's.
wp.set_module_options({"fuse_fp": False})

MASKED_HITS = 64
"""The most holes of alpha-tested triangles the masked ray cast steps through on one ray; a ray with
more is taken as blocked (a forest seen along the light holds far fewer cards per ray)."""


@wp.kernel
def hard_shadow_kernel(
    mesh: wp.uint64,
    position: wp.array(dtype=wp.vec3d),
    normal: wp.array(dtype=wp.vec3),
    toward_light: wp.vec3d,
    offset: wp.float64,
    max_t: wp.float32,
    lit: wp.array(dtype=wp.float32),
):
    k = wp.tid()
    n = wp.vec3d(normal[k])
    if wp.dot(n, toward_light) <= wp.float64(0.0):
        lit[k] = 0.0
        return
    start = wp.vec3(position[k] + n * offset)
    if wp.mesh_query_ray_anyhit(mesh, start, wp.vec3(toward_light), max_t):
        lit[k] = 0.0
    else:
        lit[k] = 1.0


@wp.kernel
def hard_shadow_masked_kernel(
    mesh: wp.uint64,
    position: wp.array(dtype=wp.vec3d),
    normal: wp.array(dtype=wp.vec3),
    toward_light: wp.vec3d,
    offset: wp.float64,
    max_t: wp.float32,
    triangles: wp.array2d(dtype=wp.int32),
    uv: wp.array(dtype=wp.vec2d),
    vertex_mask: wp.array(dtype=wp.int32),
    textures: AlphaTextures,
    lit: wp.array(dtype=wp.float32),
):
    """:func:`hard_shadow_kernel` through alpha masks: the hits nearest first, each hole stepped past."""
    k = wp.tid()
    n = wp.vec3d(normal[k])
    if wp.dot(n, toward_light) <= wp.float64(0.0):
        lit[k] = 0.0
        return
    start = wp.vec3(position[k] + n * offset)
    direction = wp.vec3(toward_light)
    left = max_t
    lit[k] = 1.0
    for _ in range(MASKED_HITS):
        query = wp.mesh_query_ray(mesh, start, direction, left)
        if not query.result:
            return
        face = query.face
        ia = triangles[face, 0]
        m = vertex_mask[ia]
        # Warp's barycentrics: the hit is u·A + v·B + (1 − u − v)·C.
        u = wp.float64(query.u)
        v = wp.float64(query.v)
        at = u * uv[ia] + v * uv[triangles[face, 1]] + (wp.float64(1.0) - u - v) * uv[triangles[face, 2]]
        if alpha_passes(textures, m, at[0], at[1]):
            lit[k] = 0.0
            return
        # Past the hole by a float32 step of the distance travelled, and on from there.
        step = query.t + wp.max(query.t, wp.float32(1.0)) * wp.float32(1e-6)
        start = start + direction * step
        left = left - step
        if left <= wp.float32(0.0):
            return
    lit[k] = 0.0


def hard_shadow_ray(bvh: MeshBVH, *, points, normals, light_direction, threads: int = 1) -> np.ndarray:
    """The hard shadow by one float32 any-hit ray per point through the BVH (arguments of
    :func:`~csmlab.kernels.reference.hard_shadow`).

    With ``threads`` > 1 on the CPU, each thread casts the rays of one range of points.
    """
    p, n, basis = checked_receivers(points, normals, light_direction)
    shape = np.shape(points)[:-1]
    device = bvh.device
    threads = checked_threads(threads, device)
    valid = np.all(np.isfinite(p), axis=1)
    out = np.full(p.shape[0], np.nan, dtype=np.float32)
    if np.any(valid):
        start = wp.array(np.ascontiguousarray(p[valid] - bvh.anchor), dtype=wp.vec3d, device=device, copy=False)
        normal = wp.array(np.ascontiguousarray(n[valid]), dtype=wp.vec3, device=device, copy=False)
        lit = wp.empty(start.shape[0], dtype=wp.float32, device=device)
        inputs = (wp.vec3d(*-basis[2]), RAY_OFFSET * max(bvh.diagonal, 1e-9),
                  float(RAY_LENGTH * max(bvh.diagonal, 1e-9)))
        kernel, masks = hard_shadow_kernel, ()
        if bvh.masked:
            kernel = hard_shadow_masked_kernel
            masks = (bvh.triangles, bvh.masks.uv, bvh.masks.vertex_mask, bvh.masks.textures)
        with LaunchPool(threads, kernels=(kernel,), device=device) as pool:
            pool.run([functools.partial(wp.launch, kernel, dim=hi - lo,
                                        inputs=(bvh.mesh.id, start[lo:hi], normal[lo:hi], *inputs, *masks),
                                        outputs=(lit[lo:hi],), device=device)
                      for lo, hi in split_range(start.shape[0], threads)])
        out[valid] = lit.numpy()
    return out.reshape(shape)
