"""Face culling in the depth pass (``[shadow] cull``): which triangles the shadow maps leave out.

A triangle ``(a, b, c)`` is wound counter-clockwise seen from its front (glTF, OpenGL's default
``glFrontFace(GL_CCW)``; csmlab's world is right-handed), so its front side is the side of
``n = (b − a) × (c − a)``. Seen by the light looking along ``d`` (light toward scene) through an
orthographic projection, it is **front-facing** when ``n · d < 0`` (its front turned toward the
light: counter-clockwise in the light camera's window) and **back-facing** otherwise — a triangle
seen edge-on or of zero area (``n · d = 0``) counts as back-facing, as OpenGL counts a window area
that is not positive. The culls are OpenGL's in the light's view:

* ``none`` — both windings rasterized (csmlab before culling; Stride ``CullMode.None``, MJP's
  ``NoCullDesc``, DirectX's ``D3D11_CULL_NONE``);
* ``back`` — ``glCullFace(GL_BACK)``: back faces dropped, the faces turned toward the light kept
  (a FrontSide material rendered as the camera renders it);
* ``front`` — ``glCullFace(GL_FRONT)``: front faces dropped, the faces turned away from the light
  kept (three.js: ``WebGLShadowMap``'s ``getDepthMaterial`` renders ``shadowSide[material.side]``,
  BackSide for a FrontSide material).

The set is chosen on the host once per light (:func:`culled_triangles`), from the world vertices
and ``d`` alone, before the mesh is put in light space for the depth raster
(:func:`csmlab.kernels.raster.light_space_mesh`); the camera pass and the ray-traced reference see
both sides. It does not depend on the camera or the boxes, so it keeps the exact-zero promise
(:mod:`csmlab.invariants`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from csmlab.registry import check_name

__all__ = ["BLEND_CASTER_RULES", "CULL_METHODS", "Cull", "culled_triangles", "front_facing"]


@dataclass(frozen=True)
class Cull:
    """One face cull of the depth pass (``[shadow] cull``).

    Attributes
    ----------
    keeps : callable or None
        ``keeps(front) -> mask``: the triangles kept, from :func:`front_facing`'s mask; None keeps
        every triangle (the mesh handed on unchanged).
    what : str
    """

    keeps: Callable[[np.ndarray], np.ndarray] | None
    what: str


CULL_METHODS: dict[str, Cull] = {
    "none": Cull(None, "both windings rasterized (Stride CullMode.None, MJP NoCullDesc, DirectX D3D11_CULL_NONE)"),
    "back": Cull(lambda front: front, "glCullFace(GL_BACK) in the light's view: only the faces turned toward the "
                                      "light (n·d < 0) are rasterized"),
    "front": Cull(lambda front: ~front, "glCullFace(GL_FRONT) in the light's view: only the faces turned away from "
                                        "the light (n·d ≥ 0) are rasterized (three.js WebGLShadowMap: shadowSide "
                                        "= BackSide for FrontSide materials)"),
}
"""Face culls of the depth pass, by name."""

BLEND_CASTER_RULES: dict[str, str] = {
    "scene": "as the level reads them ([scene] blend_casters)",
    "opaque": "cast solid",
    "masked": "alpha-tested at their material's alphaCutoff (Godot 4's alpha depth pre-pass)",
    "none": "no shadow (Unity URP: a Transparent surface has no ShadowCaster pass)",
}
"""How the depth pass casts blended (glTF ``alphaMode = BLEND``) triangles (``[shadow] blend_casters``,
:meth:`csmlab.scene.core.Scene.casters`); the camera and the reference see the level's rule."""


def front_facing(vertices, triangles, light_direction) -> np.ndarray:
    """``(T,)`` bool: whether each counter-clockwise triangle's front is turned toward the light, ``n · d < 0``.

    Parameters
    ----------
    vertices : array_like, shape (V, 3), float64
        World positions, metres.
    triangles : array_like, shape (T, 3), integer
    light_direction : array_like, shape (3,)
        ``d``, from the light toward the scene (any positive length).
    """
    v = np.asarray(vertices, dtype=np.float64)
    t = np.asarray(triangles)
    a = v[t[:, 0]]
    n = np.cross(v[t[:, 1]] - a, v[t[:, 2]] - a)
    return n @ np.asarray(light_direction, dtype=np.float64) < 0.0


def culled_triangles(vertices, triangles, light_direction, cull: str) -> np.ndarray:
    """The rows of ``triangles`` ``(T', 3)`` that the depth pass rasterizes under ``cull`` (:data:`CULL_METHODS`).

    ``cull = "none"`` returns ``triangles`` itself, so the depth maps are those of before culling,
    bit for bit; the others keep the rows in their order.
    """
    record = CULL_METHODS[check_name(cull, CULL_METHODS, field="cull")]
    if record.keeps is None:
        return triangles
    return triangles[record.keeps(front_facing(vertices, triangles, light_direction))]
