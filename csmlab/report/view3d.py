"""The 3D view (PyVista, off-screen): the visible scene, the camera's frustum slices and the cascade boxes.

One picture of one snapshot frame, a column per method, two views each: the near cascades from
behind the camera, and every cascade seen from the light. Drawn in both: the surface points the
camera sees (every :data:`~csmlab.report.capture.POINT_STRIDE`-th pixel) coloured by the cascade
they select, each cascade's slice of the view frustum (thin lines) and its light-space box
(thick lines) in the same colour, the camera (a black ball) and the light direction (a grey
arrow). Seen from the light, each box is its square of R×R texels around the slice it must
cover: how much of it the slice leaves empty is what `exact`'s bounding sphere wastes.

Rendering needs no display: VTK draws through EGL (Debian: ``libegl1``, ``libegl-mesa0``,
``libgl1-mesa-dri`` for the software rasterizer). When no ``DISPLAY`` is set, the EGL render
window is asked for by name — before PyVista is imported, hence the import inside the function —
so that VTK does not first try, and complain about, an X server.
"""

from __future__ import annotations

import os

import numpy as np

from csmlab.geometry import light_basis
from csmlab.report.images import CATEGORY_COLOURS

__all__ = ["BOX_EDGES", "FRUSTUM_EDGES", "view3d_figure"]

FRUSTUM_EDGES = np.array([[0, 1], [1, 2], [2, 3], [3, 0], [4, 5], [5, 6], [6, 7], [7, 4],
                          [0, 4], [1, 5], [2, 6], [3, 7]])
"""Edges ``(12, 2)`` between the corners of :func:`csmlab.geometry.frustum_slice_corners`."""
BOX_EDGES = np.array([[i, i | bit] for i in range(8) for bit in (1, 2, 4) if not i & bit])
"""Edges ``(12, 2)`` between box corners numbered by their (x, y, depth) high bits, x fastest."""
_PANEL = (720, 560)
_UNSELECTED = np.array([0.6, 0.6, 0.6])


def view3d_figure(snapshots: list[dict], labels: list[str], path, *, title: str) -> None:
    """Render the 3D view of one frame to a PNG: a column per method, two views each.

    Top row: the nearer half of the cascades from behind, above and beside the camera. Bottom
    row: every cascade seen from the light (parallel projection along the light direction).
    Cameras are linked along each row, so the methods are seen alike.

    Parameters
    ----------
    snapshots : list of dict
        Snapshot arrays as :mod:`csmlab.report.capture` stores them (``points``,
        ``point_cascade``, ``frustum_corners``, ``box_corners``, ``camera_position``,
        ``light_direction``), world metres.
    labels : list of str
        Panel titles (method names).
    path : str or Path
        The PNG to write.
    title : str
        Shown in the first panel.
    """
    if not os.environ.get("DISPLAY"):
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    import pyvista as pv

    count = len(snapshots)
    plotter = pv.Plotter(off_screen=True, shape=(2, count), window_size=(_PANEL[0] * count, 2 * _PANEL[1]),
                         border=False)
    plotter.set_background("white")
    for k, (snap, label) in enumerate(zip(snapshots, labels)):
        views = ((_overview_camera(snap), _near_corners(snap), "near cascades, from behind the camera"),
                 (_light_camera(snap), snap["frustum_corners"], "all cascades, seen from the light"))
        for row, (camera, framed, caption) in enumerate(views):
            plotter.subplot(row, k)
            _add_scene(plotter, pv, snap)
            plotter.add_text(f"{label}: {caption}", position="upper_edge", font_size=10, color="black")
            if k == 0 and row == 0:
                plotter.add_text(title, position="lower_left", font_size=9, color="black")
            plotter.camera_position = camera
            if row == 1:
                plotter.enable_parallel_projection()
            plotter.reset_camera(bounds=_bounds(framed))
            plotter.camera.zoom(0.9)
    plotter.link_views(list(range(count)))
    plotter.link_views(list(range(count, 2 * count)))
    plotter.screenshot(str(path))
    plotter.close()


def _add_scene(plotter, pv, snap: dict) -> None:
    if len(snap["points"]):
        cascade = snap["point_cascade"].astype(np.int64)
        colours = np.where((cascade >= 0)[:, None], CATEGORY_COLOURS[np.mod(cascade, len(CATEGORY_COLOURS))],
                           _UNSELECTED)
        cloud = pv.PolyData(np.asarray(snap["points"], dtype=np.float64))
        cloud["rgb"] = np.rint(colours * 255).astype(np.uint8)
        plotter.add_mesh(cloud, scalars="rgb", rgb=True, point_size=4.0, render_points_as_spheres=False)
    for c, (frustum, box) in enumerate(zip(snap["frustum_corners"], snap["box_corners"])):
        colour = CATEGORY_COLOURS[c % len(CATEGORY_COLOURS)]
        plotter.add_mesh(_wireframe(pv, frustum, FRUSTUM_EDGES), color=colour, line_width=1.5)
        plotter.add_mesh(_wireframe(pv, box, BOX_EDGES), color=colour, line_width=3.5)
    near = _near_corners(snap)
    span = float(np.ptp(near, axis=0).max())
    camera = np.asarray(snap["camera_position"], dtype=np.float64)
    plotter.add_mesh(pv.Sphere(radius=0.015 * span, center=camera), color="black", smooth_shading=True)
    d = np.asarray(snap["light_direction"], dtype=np.float64)
    plotter.add_mesh(pv.Arrow(start=near.mean(axis=0) - 0.6 * span * d, direction=d, scale=0.3 * span),
                     color="#737373")


def _near_corners(snap: dict) -> np.ndarray:
    """Corners ``(K, 3)`` of the nearer half of the frustum slices (at least the first)."""
    corners = snap["frustum_corners"]
    return corners[: max(1, len(corners) // 2)].reshape(-1, 3)


def _wireframe(pv, corners: np.ndarray, edges: np.ndarray):
    lines = np.column_stack([np.full(len(edges), 2), edges]).ravel()
    return pv.PolyData(np.asarray(corners, dtype=np.float64), lines=lines)


def _bounds(corners: np.ndarray) -> tuple:
    lo = corners.reshape(-1, 3).min(axis=0)
    hi = corners.reshape(-1, 3).max(axis=0)
    return (lo[0], hi[0], lo[1], hi[1], lo[2], hi[2])


def _light_camera(snap: dict) -> list[tuple]:
    """Look along the light direction at the middle of the frustum slices, light-space y up (boxes axis-aligned)."""
    corners = snap["frustum_corners"].reshape(-1, 3)
    centre = corners.mean(axis=0)
    _, up, d = light_basis(snap["light_direction"])
    return [tuple(centre - 10.0 * float(np.ptp(corners, axis=0).max()) * d), tuple(centre), tuple(up)]


def _overview_camera(snap: dict) -> list[tuple]:
    """Look at the near frustum slices from behind, above and to the side of the camera."""
    corners = _near_corners(snap)
    camera = np.asarray(snap["camera_position"], dtype=np.float64)
    centre = corners.mean(axis=0)
    forward = centre - camera
    forward /= np.linalg.norm(forward)
    up = np.array([0.0, 1.0, 0.0])
    side = np.cross(forward, up)
    side = side / np.linalg.norm(side) if np.linalg.norm(side) > 1e-6 else np.array([1.0, 0.0, 0.0])
    eye = centre + (-1.0 * forward + 0.45 * up + 0.35 * side) * float(np.ptp(corners, axis=0).max())
    return [tuple(eye), tuple(centre), tuple(up)]
