"""The ray-traced hard shadow, ground truth of every shadow map (docs/design.md, CSM model step 7).

From each visible point, moved a small epsilon along its normal (relative to the scene's size, far
above the float32 error of the BVH's anchored vertices), a ray toward the light (``−d``) of length
``4·diagonal`` asks whether anything lies in the way. A point whose normal faces away from the light
(``n·(−d) ≤ 0``) receives no direct light and is shadowed without a ray. Two methods answer the same
question, registered in :data:`REFERENCE_METHODS`:

- ``irregular`` — an irregular z-buffer (the default): every ray is parallel to the light, so in
  light space (orthographic along ``d``, :func:`csmlab.geometry.light_basis`) a ray from ``S`` is
  blocked exactly when a triangle's projection contains ``S.xy`` and the triangle's depth there is
  nearer the light than ``S`` by more than 0 and less than the ray's length. The ray starts are
  binned into a uniform light-space grid (a counting sort), then one thread per chunk of triangles
  walks, triangle by triangle, the cells a bounding box covers and tests the starts in them —
  closed point-in-triangle and depth, both in float64 from float64 vertices
  (:func:`hard_shadow_irregular`);
- ``ray`` — one any-hit ray per point through the BVH in float32, ``wp.mesh_query_ray_anyhit``
  (:func:`hard_shadow_ray`), the independent oracle of the tests.

They agree everywhere but within float32 rounding of a triangle's edge or of the ray's start plane,
where the float32 ray cast may decide either way.

Alpha-tested triangles (:mod:`csmlab.kernels.alpha`) block only where their mask is opaque: the
irregular z-buffer interpolates the texture coordinates with the start's light-space barycentric
weights; the ray cast (a masked mesh only) walks the ray's hits nearest first
(``wp.mesh_query_ray``), stepping past each hole at the hit's barycentric coordinates, up to
:data:`MASKED_HITS` of them.

Both take ``threads``: on the CPU, that many concurrent Warp launches share the work, each writing
its own part of the outputs (:mod:`csmlab.kernels.threads`) — but for the flags of the rays that the
irregular z-buffer finds blocked, which every writer sets to 0 — with the same shadow for every value.

References
----------
- Aila and Laine, "Alias-Free Shadow Maps", EGSR 2004 — shadow rays from the eye's samples,
  organised by occluding triangle in light space.
- Johnson, Hux, Lin, Chen and Mark, "The irregular Z-buffer: Hardware acceleration for irregular
  data structures", ACM TOG 24(4), 2005 — the light-space grid of samples, each triangle testing
  the samples of the cells it covers.
"""


from __future__ import annotations

import numpy as np

from csmlab.kernels.reference.irregular import CHUNK, hard_shadow_irregular
from csmlab.kernels.reference.ray_cast import MASKED_HITS, hard_shadow_ray
from csmlab.kernels.reference.ray_grid import COARSE_RAYS_PER_CELL, RAYS_PER_CELL, RECEIVER_BLOCK
from csmlab.kernels.reference.shadow_rays import RAY_OFFSET
from csmlab.kernels.visibility import MeshBVH
from csmlab.registry import check_name

__all__ = ["CHUNK", "COARSE_RAYS_PER_CELL", "MASKED_HITS", "RAYS_PER_CELL", "RAY_OFFSET", "RECEIVER_BLOCK",
           "REFERENCE_METHODS", "hard_shadow", "hard_shadow_irregular", "hard_shadow_ray"]

# Products and sums rounded one by one on both devices (clang and NVRTC may otherwise contract them): a
# CUDA build may not contract them into fused multiply-adds, or its bits differ from the CPU's.

REFERENCE_METHODS = {"irregular": hard_shadow_irregular, "ray": hard_shadow_ray}
"""Methods of the hard shadow by name: the irregular z-buffer (float64, the default) and the BVH ray cast (float32)."""


def hard_shadow(bvh: MeshBVH, *, points, normals, light_direction, method: str = "irregular",
                threads: int = 1) -> np.ndarray:
    """Ray-traced hard shadow R at receiver points: 1 lit, 0 shadowed, NaN where no point.

    Parameters
    ----------
    bvh : MeshBVH
        The scene, on the device the kernels run on.
    points : array_like, shape (..., 3), float64
        World positions in metres; rows with a NaN are not receivers.
    normals : array_like, shape (..., 3), float32
        Unit normals of the receivers (facing the camera).
    light_direction : array_like, shape (3,)
        From the light toward the scene; normalised here.
    method : str
        A key of :data:`REFERENCE_METHODS`: ``"irregular"`` (float64, the faster) or ``"ray"``
        (BVH rays in float32).
    threads : int
        Concurrent CPU launches (:mod:`csmlab.kernels.threads`), each writing its own part of the
        outputs; the result is the same, bit for bit, for every value. Ignored on CUDA.

    Returns
    -------
    ndarray, shape (...), float32

    Raises
    ------
    ValueError
        On an unknown method, mis-shaped points or normals, a zero or non-finite light direction, or
        ``threads`` not an integer ≥ 1.
    """
    return REFERENCE_METHODS[check_name(method, REFERENCE_METHODS, field="method")](
        bvh, points=points, normals=normals, light_direction=light_direction, threads=threads)
