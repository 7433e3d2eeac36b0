"""A level made of several mesh files, each placed by a transform (``[[scene.parts]]``).

Engines export a level as several files — a terrain, and the props, trees and houses placed in it
by the editor's transforms (a Godot scene instancing glTF files, a Unity prefab's children). Each
:class:`PartPlacement` names a file and its transform; :func:`load_parts` reads every file with
:func:`~csmlab.scene.mesh.load_mesh` (the scene's ``scale`` in metres per file unit and its ``up``
axis apply to every file), then places it: its own uniform ``scale``, then turns about the world
X, then Y, then Z axes through its origin (``rotation_deg``), then ``translation`` in metres —
``p' = t + Rz Ry Rx (s p)``. Normals are recomputed from the placed winding; alpha masks follow
their triangles.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from csmlab.scene.core import Scene

__all__ = ["PartPlacement", "load_parts", "rotation_from_degrees"]


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
    """

    file: str
    translation: tuple = (0.0, 0.0, 0.0)
    rotation_deg: tuple = (0.0, 0.0, 0.0)
    scale: float = 1.0


def rotation_from_degrees(rotation_deg) -> np.ndarray:
    """``Rz Ry Rx`` ``(3, 3)``: turns about world X, then Y, then Z by ``rotation_deg`` ``(3,)`` degrees (right-handed)."""
    x, y, z = np.radians(np.asarray(rotation_deg, dtype=np.float64))
    rx = np.array([[1.0, 0.0, 0.0], [0.0, np.cos(x), -np.sin(x)], [0.0, np.sin(x), np.cos(x)]])
    ry = np.array([[np.cos(y), 0.0, np.sin(y)], [0.0, 1.0, 0.0], [-np.sin(y), 0.0, np.cos(y)]])
    rz = np.array([[np.cos(z), -np.sin(z), 0.0], [np.sin(z), np.cos(z), 0.0], [0.0, 0.0, 1.0]])
    return rz @ ry @ rx


def _placed(scene: Scene, placement: PartPlacement) -> Scene:
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
                 vertex_mask=scene.vertex_mask, alpha=scene.alpha)


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
                  vertex_mask=level.vertex_mask, alpha=level.alpha)
    return level.merged(_ground_under(level)) if ground else level
