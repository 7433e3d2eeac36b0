"""A level made of several mesh files, each placed by a transform (``[[scene.parts]]``).

Engines export a level as several files — a terrain, and the props, trees and houses placed in it
by the editor's transforms (a Godot scene instancing glTF files, a Unity prefab's children). Each
:class:`PartPlacement` names a file and its transform; :func:`load_parts` reads every file with
:func:`~csmlab.scene.mesh.load_mesh` (the scene's ``scale`` in metres per file unit and its ``up``
axis apply to every file), then places it: its own uniform ``scale``, then turns about the world
X, then Y, then Z axes through its origin (``rotation_deg``), then ``translation`` in metres —
``p' = t + Rz Ry Rx (s p)`` — or, instead, by a 4×4 affine ``matrix`` (``p' = A p + t``; an engine's
node transform: shear and non-uniform scale allowed). Normals turn by the inverse transpose of ``A``
(renormalised); a mirroring ``A`` (``det A < 0``) would turn every triangle inside out, so its winding is
swapped to keep faces facing the way their normals say. Alpha masks follow their triangles.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from csmlab.scene.core import Scene

__all__ = ["PartPlacement", "load_parts", "matrix_fault", "rotation_from_degrees"]


@dataclass(frozen=True)
class PartPlacement:
    """One file of a level and where it goes.

    Attributes
    ----------
    file : str
        A mesh file :func:`~csmlab.scene.mesh.load_mesh` reads.
    translation : tuple of 3 float
        Metres, applied last.
    rotation_deg : tuple of 3 float
        Turns about world X, Y and Z in that order, degrees.
    scale : float
        Uniform factor (> 0), applied first.
    matrix : tuple of 4 rows of 4 float, or None
        Row-major ``(4, 4)`` affine transform acting on column vectors, metres (the last row ``0, 0, 0, 1``):
        instead of ``translation``, ``rotation_deg`` and ``scale``, which then stay at their defaults.
    """

    file: str
    translation: tuple = (0.0, 0.0, 0.0)
    rotation_deg: tuple = (0.0, 0.0, 0.0)
    scale: float = 1.0
    matrix: tuple | None = None


_SINGULAR = 1e-12
"""``|det A|`` at most this fraction of the product of ``A``'s column lengths (Hadamard's bound) is singular: a part
flattened to a plane or a line (a scale of 0), whose normals are undefined."""


def matrix_fault(matrix) -> str:
    """What is wrong with ``matrix`` as a part's transform, as the words after "expected"; empty when nothing is.

    A transform must be 4 rows of 4 finite numbers whose last row is ``0, 0, 0, 1`` (affine) and whose upper-left
    ``(3, 3)`` block is non-singular (:data:`_SINGULAR`).
    """
    try:
        m = np.asarray(matrix, dtype=np.float64)
    except (TypeError, ValueError):
        return f"4 rows of 4 numbers, got {matrix!r}"
    if m.shape != (4, 4):
        return f"4 rows of 4 numbers, got shape {m.shape}"
    if not np.all(np.isfinite(m)):
        return f"finite numbers, got {m.tolist()!r}"
    if not np.array_equal(m[3], [0.0, 0.0, 0.0, 1.0]):
        return f"an affine transform (last row [0, 0, 0, 1]), got last row {m[3].tolist()!r}"
    linear = m[:3, :3]
    if abs(np.linalg.det(linear)) <= _SINGULAR * np.prod(np.linalg.norm(linear, axis=0)):
        return f"a non-singular 3×3 part (no scale of 0), got {linear.tolist()!r}"
    return ""


def rotation_from_degrees(rotation_deg) -> np.ndarray:
    """``Rz Ry Rx`` ``(3, 3)``: turns about world X, then Y, then Z by ``rotation_deg`` ``(3,)`` degrees
    (right-handed)."""
    x, y, z = np.radians(np.asarray(rotation_deg, dtype=np.float64))
    rx = np.array([[1.0, 0.0, 0.0], [0.0, np.cos(x), -np.sin(x)], [0.0, np.sin(x), np.cos(x)]])
    ry = np.array([[np.cos(y), 0.0, np.sin(y)], [0.0, 1.0, 0.0], [-np.sin(y), 0.0, np.cos(y)]])
    rz = np.array([[np.cos(z), -np.sin(z), 0.0], [np.sin(z), np.cos(z), 0.0], [0.0, 0.0, 1.0]])
    return rz @ ry @ rx


def _placed(scene: Scene, placement: PartPlacement) -> Scene:
    if placement.matrix is not None:
        return _placed_by_matrix(scene, placement)
    t = np.asarray(placement.translation, dtype=np.float64)
    s = float(placement.scale)
    if t.shape != (3,) or not np.all(np.isfinite(t)):
        raise ValueError(f"translation: expected 3 finite metres, got {placement.translation!r}")
    if not (np.isfinite(s) and s > 0):
        raise ValueError(f"scale: expected a positive factor, got {placement.scale!r}")
    rotation = rotation_from_degrees(placement.rotation_deg)
    vertices = (s * scene.vertices) @ rotation.T + t
    # A rotation and a positive uniform scale keep the winding: the normals turn with the part.
    return Scene(vertices, scene.triangles, scene.normals @ rotation.T, scene.albedo, name=scene.name, uv=scene.uv,
                 vertex_mask=scene.vertex_mask, alpha=scene.alpha, colour=scene.colour,
                 vertex_blend=scene.vertex_blend)


def _placed_by_matrix(scene: Scene, placement: PartPlacement) -> Scene:
    fault = matrix_fault(placement.matrix)
    if fault:
        raise ValueError(f"matrix: expected {fault}")
    if (placement.translation, placement.rotation_deg, placement.scale) != ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 1.0):
        raise ValueError("matrix: expected either matrix or translation, rotation_deg and scale, got both")
    m = np.asarray(placement.matrix, dtype=np.float64)
    linear, t = m[:3, :3], m[:3, 3]
    vertices = scene.vertices @ linear.T + t
    # Normals are covectors: n' ∝ A⁻ᵀ n keeps them perpendicular to the sheared, unevenly scaled surface.
    normals = scene.normals @ np.linalg.inv(linear)
    normals = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    # A mirror reverses the orientation: swapping two corners keeps each face's winding agreeing with its normal.
    triangles = scene.triangles[:, [0, 2, 1]] if np.linalg.det(linear) < 0 else scene.triangles
    return Scene(vertices, triangles, normals, scene.albedo, name=scene.name, uv=scene.uv,
                 vertex_mask=scene.vertex_mask, alpha=scene.alpha, colour=scene.colour,
                 vertex_blend=scene.vertex_blend)


def load_parts(placements, *, file: str = "", scale: float = 1.0, up: str = "y", ground: bool = False,
               blend_casters: str = "opaque", name: str = "level") -> Scene:
    """The level of ``file`` (placed as it is, when given) and every placed part, as one scene.

    Parameters
    ----------
    placements : sequence of PartPlacement
    file : str
        A mesh file at the world origin, or empty.
    scale, up, blend_casters : float, str, str
        Metres per file unit, the files' up axis and the rule for glTF ``BLEND`` materials
        (:func:`~csmlab.scene.mesh.load_mesh`), for every file.
    ground : bool
        Add :func:`~csmlab.scene.mesh.load_mesh`'s ground plane under the whole level.
    name : str
        The scene's name.

    Returns
    -------
    Scene
        The files in order (``file`` first), then the ground.

    Raises
    ------
    InputError
        From a part's file (:func:`~csmlab.scene.mesh.load_mesh`), naming it.
    ValueError
        On no file at all, or a bad transform, naming the field.
    """
    from csmlab.scene.mesh import _ground_under, load_mesh

    scenes = [load_mesh(file, scale=scale, up=up, blend_casters=blend_casters)] if file else []
    for i, placement in enumerate(placements):
        part = load_mesh(placement.file, scale=scale, up=up, blend_casters=blend_casters)
        try:
            scenes.append(_placed(part, placement))
        except ValueError as exc:
            raise ValueError(f"parts[{i}].{exc}") from None
    if not scenes:
        raise ValueError("parts: expected a file or at least one part, got none")
    level = scenes[0]
    for part in scenes[1:]:
        level = level.merged(part)
    level = Scene(level.vertices, level.triangles, level.normals, level.albedo, name=name, uv=level.uv,
                  vertex_mask=level.vertex_mask, alpha=level.alpha, colour=level.colour,
                  vertex_blend=level.vertex_blend)
    return level.merged(_ground_under(level)) if ground else level
