"""Scenes: the :class:`Scene` record, procedural generators by name, and mesh import.

Every procedural scene is in world metres with Y up, deterministic from its ``seed``, and keeps
the camera's area clear (see :mod:`csmlab.scene.layout`; ``plane_box`` excepted, whose box stands
at the origin by design). :data:`SCENE_KINDS` maps each kind to its function; :func:`make_scene`
dispatches on the name.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable

from csmlab.registry import check_name, dispatch
from csmlab.scene.city import city
from csmlab.scene.core import Scene
from csmlab.scene.fence import fence
from csmlab.scene.foliage import foliage
from csmlab.scene.mesh import load_mesh
from csmlab.scene.plane_box import plane_box
from csmlab.scene.terrain import terrain

__all__ = ["SCENE_KINDS", "Scene", "load_mesh", "make_scene"]

SCENE_KINDS: dict[str, Callable[..., Scene]] = {
    "plane_box": plane_box,
    "terrain": terrain,
    "city": city,
    "fence": fence,
    "foliage": foliage,
    "mesh": load_mesh,
}
"""Scene generators by name; add an entry to register a new one. Each takes keyword arguments
(``mesh`` takes the file as ``file``) and returns a :class:`Scene`."""


def make_scene(kind: str, *, seed: int = 1, **params) -> Scene:
    """Build the scene ``kind`` with its generator's keyword arguments.

    Parameters
    ----------
    kind : str
        A key of :data:`SCENE_KINDS`.
    seed : int
        Passed to generators that take a seed; ``plane_box`` and ``mesh`` have no randomness and
        ignore it.
    **params
        The generator's keywords (see each function); ``mesh`` requires ``file``.

    Returns
    -------
    Scene

    Raises
    ------
    ValueError
        On an unknown kind or keyword, or a missing required one, listing the valid names; or a
        bad value, naming the keyword.
    InputError
        ``mesh`` only: a missing or broken mesh file (see :func:`load_mesh`).
    """
    signature = inspect.signature(SCENE_KINDS[check_name(kind, SCENE_KINDS, field="scene")])
    missing = [name for name, p in signature.parameters.items()
               if p.default is inspect.Parameter.empty and name not in params and name != "seed"]
    if missing:
        raise ValueError(f"scene {kind!r}: expected parameter(s) {', '.join(missing)}")
    return dispatch(SCENE_KINDS, kind, field="scene", offered={"seed": seed}, **params)
