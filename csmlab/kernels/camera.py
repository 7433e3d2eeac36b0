"""The pinhole camera as the kernels read it: one ``wp.struct`` and the host arithmetic that fills it.

A pixel ``(col, row)`` (row 0 at the top) of a ``width × height`` image looks along
``forward + x·right + y·up``, its centre's image-plane point at unit view depth being
``x = (col + ½ − W/2)·step_x``, ``y = (H/2 − row − ½)·step_y``. The camera pass
(:mod:`csmlab.kernels.visibility`) casts those rays; the TAA resolve (:mod:`csmlab.kernels.taa`)
projects world points back through them.
"""

from __future__ import annotations

import numpy as np
import warp as wp

__all__ = ["PinholeCamera", "pinhole_frame", "pixel_ray", "pixel_steps", "pixel_x", "pixel_y"]

# Products and sums rounded one by one on both devices (clang and NVRTC may otherwise contract them).
wp.set_module_options({"fuse_fp": False})


@wp.struct
class PinholeCamera:
    """A pinhole camera as the kernels read it: its frame relative to the scene's anchor, its image plane at
    unit view depth and its clip distances."""

    eye: wp.vec3d
    """The eye relative to the scene's anchor, metres."""
    right: wp.vec3d
    up: wp.vec3d
    forward: wp.vec3d
    """The view direction: a pixel's ray is ``forward + x·right + y·up`` on the image plane at unit depth."""
    step_x: wp.float64
    """Pixel width on the image plane at unit view depth."""
    step_y: wp.float64
    """Pixel height on the image plane at unit view depth."""
    near: wp.float64
    """The raster's near clip (:data:`csmlab.kernels.visibility.NEAR_FRACTION` of ``far``), metres of view depth."""
    far: wp.float64
    """The far clip, metres of view depth."""
    frustum: wp.vec4d
    """The image's extent at unit depth ``(x lo, x hi, y lo, y hi)``, padded by a pixel against rounding."""
    anchor: wp.vec3d
    """The scene's anchor in world metres (:attr:`csmlab.kernels.visibility.MeshBVH.anchor`)."""


@wp.func
def pixel_x(col: int, width: int, step_x: wp.float64) -> wp.float64:
    """Image-plane x of the centre of column ``col``: ``(col + ½ − W/2)·step_x`` (unit view depth)."""
    half = wp.float64(0.5)
    return (wp.float64(col) + half - half * wp.float64(width)) * step_x


@wp.func
def pixel_y(row: int, height: int, step_y: wp.float64) -> wp.float64:
    """Image-plane y of the centre of row ``row`` (row 0 at the top): ``(H/2 − row − ½)·step_y``."""
    half = wp.float64(0.5)
    return (half * wp.float64(height) - wp.float64(row) - half) * step_y


@wp.func
def pixel_ray(pinhole: PinholeCamera, row: int, col: int, height: int, width: int) -> wp.vec3d:
    """The ray through the centre of pixel ``(row, col)`` of a ``height × width`` image, relative to the eye:
    ``forward + x·right + y·up``, of unit forward component so that its parameter is the view depth."""
    return (pinhole.forward + pinhole.right * pixel_x(col, width, pinhole.step_x)
            + pinhole.up * pixel_y(row, height, pinhole.step_y))


def pixel_steps(fov_y_deg: float, aspect: float, width: int, height: int) -> tuple[float, float]:
    """A pixel's width and height on the image plane at unit view depth, ``(step_x, step_y)``.

    ``fov_y_deg`` is the vertical field of view in degrees, ``aspect`` the image's width / height.
    """
    tan_y = np.tan(np.radians(fov_y_deg) / 2.0)
    return float(2.0 * tan_y * aspect / width), float(2.0 * tan_y / height)


def pinhole_frame(eye, rotation, fov_y_deg: float, aspect: float, width: int, height: int) -> PinholeCamera:
    """The :class:`PinholeCamera` frame of a camera at world ``eye`` (3,) with camera-to-world ``rotation`` (3, 3)
    (columns right, up, back), its anchor at the world origin; ``near``, ``far`` and ``frustum`` left unset
    for kernels that clip nothing."""
    r = np.asarray(rotation, dtype=np.float64)
    camera = PinholeCamera()
    camera.eye = wp.vec3d(*np.asarray(eye, dtype=np.float64))
    camera.right, camera.up, camera.forward = wp.vec3d(*r[:, 0]), wp.vec3d(*r[:, 1]), wp.vec3d(*(-r[:, 2]))
    camera.step_x, camera.step_y = pixel_steps(fov_y_deg, aspect, width, height)
    camera.anchor = wp.vec3d(0.0, 0.0, 0.0)
    return camera
