"""The ray-traced hard shadow, ground truth of every shadow map (DESIGN.md, CSM model step 7).

From each visible point, moved a small epsilon along its normal (relative to the scene's size, far
above the float32 error of the BVH's anchored vertices), a ray toward the light (``−d``) asks the
BVH whether anything lies in the way. A point whose normal faces away from the light
(``n·(−d) ≤ 0``) receives no direct light and is shadowed without a ray.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from csmlab.kernels.visibility import MeshBVH

__all__ = ["RAY_OFFSET", "hard_shadow"]

RAY_OFFSET = 1e-5
"""Ray start offset along the normal, as a fraction of the scene's bounding-box diagonal."""


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


def hard_shadow(bvh: MeshBVH, *, points, normals, light_direction) -> np.ndarray:
    """Ray-traced hard shadow R at receiver points: 1 lit, 0 shadowed, NaN where no point.

    Parameters
    ----------
    bvh : MeshBVH
        The scene, on the device the kernel runs on.
    points : array_like, shape (...,  3), float64
        World positions in metres; rows with a NaN are not receivers.
    normals : array_like, shape (..., 3), float32
        Unit normals of the receivers (facing the camera).
    light_direction : array_like, shape (3,)
        From the light toward the scene; normalised here.

    Returns
    -------
    ndarray, shape (...), float32
    """
    p = np.asarray(points, dtype=np.float64)
    n = np.asarray(normals, dtype=np.float32)
    if p.shape[-1:] != (3,) or n.shape != p.shape:
        raise ValueError(f"points, normals: expected two arrays of shape (..., 3), got {p.shape} and {n.shape}")
    d = np.asarray(light_direction, dtype=np.float64)
    if d.shape != (3,) or not np.all(np.isfinite(d)) or np.linalg.norm(d) == 0.0:
        raise ValueError(f"light_direction: expected a finite non-zero vector (3,), got {light_direction!r}")
    toward = -d / np.linalg.norm(d)
    flat = p.reshape(-1, 3)
    valid = np.all(np.isfinite(flat), axis=1)
    out = np.full(flat.shape[0], np.nan, dtype=np.float32)
    if np.any(valid):
        device = bvh.device
        start = np.ascontiguousarray(flat[valid] - bvh.anchor)
        normal = np.ascontiguousarray(n.reshape(-1, 3)[valid])
        lit = wp.empty(start.shape[0], dtype=wp.float32, device=device)
        wp.launch(
            hard_shadow_kernel,
            dim=start.shape[0],
            inputs=(
                bvh.mesh.id,
                wp.array(start, dtype=wp.vec3d, device=device, copy=False),
                wp.array(normal, dtype=wp.vec3, device=device, copy=False),
                wp.vec3d(*toward),
                RAY_OFFSET * max(bvh.diagonal, 1e-9),
                float(4.0 * max(bvh.diagonal, 1e-9)),
            ),
            outputs=(lit,),
            device=device,
        )
        out[valid] = lit.numpy()
    return out.reshape(p.shape[:-1])
