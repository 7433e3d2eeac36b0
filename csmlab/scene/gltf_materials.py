"""glTF material rules of a level as engines export it: ``KHR_texture_transform`` on masks, ``BLEND`` casters.

* ``KHR_texture_transform`` on a ``MASK`` material's ``baseColorTexture`` (atlased leaf cards):
  :func:`transformed_uv` applies its ``offset``, ``rotation`` and ``scale`` to the coordinates the
  mask is sampled at, as the extension defines it — ``uv' = T R S uv`` with
  ``R = [[cos r, sin r], [−sin r, cos r]]`` (its GLSL ``mat3`` is column-major) — and its
  ``texCoord`` picks the coordinate set in place of the texture info's own.
* ``alphaMode = "BLEND"`` casters: csmlab's shadow maps and its ray-traced reference have no
  translucency, so a blended material is either solid or alpha-tested. ``[scene] blend_casters``
  (:data:`BLEND_CASTERS`) says which for the whole level: ``opaque`` (the default, every triangle
  solid, as before) or ``masked`` (alpha-tested at the material's ``alphaCutoff``, 0.5 without one,
  like a ``MASK`` material). docs/engines.md says what each engine does with them.
  :func:`blend_materials` names a file's blended materials so that a run warns about them.
"""

from __future__ import annotations

import numpy as np

__all__ = ["BLEND_CASTERS", "TEXTURE_TRANSFORM", "apply_blend_rule", "blend_line", "blend_materials", "blend_note",
           "texture_coordinate_set", "transformed_uv"]

TEXTURE_TRANSFORM = "KHR_texture_transform"
BLEND_CASTERS = ("opaque", "masked")
"""``[scene] blend_casters``: how ``alphaMode = "BLEND"`` triangles cast (and block the reference's rays)."""


def _transform(texture_info) -> dict:
    return ((getattr(texture_info, "extensions", None) or {}).get(TEXTURE_TRANSFORM)) or {}


def texture_coordinate_set(texture_info) -> int:
    """The ``TEXCOORD_n`` set a texture is sampled with: ``KHR_texture_transform``'s ``texCoord``, else its own."""
    override = _transform(texture_info).get("texCoord")
    return int(override) if isinstance(override, int) else int(getattr(texture_info, "texCoord", None) or 0)


def transformed_uv(uv, texture_info, *, key: str = "texture") -> np.ndarray:
    """``uv`` ``(V, 2)`` under the texture info's ``KHR_texture_transform`` (unchanged without one).

    Raises
    ------
    ValueError
        On a non-numeric or mis-sized ``offset``, ``rotation`` or ``scale``, naming it under ``key``.
    """
    transform = _transform(texture_info)
    uv = np.asarray(uv, dtype=np.float64)
    if not transform:
        return uv
    values = {}
    for name, default, size in (("offset", (0.0, 0.0), 2), ("scale", (1.0, 1.0), 2), ("rotation", 0.0, None)):
        value = np.asarray(transform.get(name, default), dtype=object)
        ok = value.shape == ((size,) if size else ()) and all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v) for v in value.reshape(-1))
        if not ok:
            raise ValueError(f"{key}.extensions.{TEXTURE_TRANSFORM}.{name}: expected "
                             f"{f'{size} finite numbers' if size else 'a finite number of radians'}, "
                             f"got {transform.get(name)!r}")
        values[name] = value.astype(np.float64)
    c, s = np.cos(values["rotation"]), np.sin(values["rotation"])
    scaled = uv * values["scale"]
    rotated = np.stack([c * scaled[:, 0] - s * scaled[:, 1], s * scaled[:, 0] + c * scaled[:, 1]], axis=1)
    return rotated + values["offset"]


def blend_materials(document) -> list[str]:
    """Names (``materials[i]`` where unnamed) of the ``BLEND`` materials the file's meshes use, in material order."""
    used = {primitive.material for mesh in (document.meshes or []) for primitive in mesh.primitives
            if isinstance(primitive.material, int)}
    materials = document.materials or []
    return [materials[i].name or f"materials[{i}]" for i in sorted(used)
            if 0 <= i < len(materials) and materials[i].alphaMode == "BLEND"]


def apply_blend_rule(document, rule: str) -> None:
    """Turn ``BLEND`` materials to ``MASK`` for ``rule = "masked"`` (in place); ``opaque`` leaves them (read as solid).

    Raises
    ------
    ValueError
        On a rule not in :data:`BLEND_CASTERS`.
    """
    if rule not in BLEND_CASTERS:
        raise ValueError(f"blend_casters: expected one of {list(BLEND_CASTERS)}, got {rule!r}")
    if rule != "masked":
        return
    for material in document.materials or []:
        if material.alphaMode == "BLEND":
            material.alphaMode = "MASK"


def blend_note(files, rule: str) -> dict | None:
    """``{"rule": rule, "materials": ["file: name", …]}`` for the ``BLEND`` materials of the glTF ``files``; None without any.

    What ``summary.json`` keeps under ``blend_materials`` and :func:`blend_line` words.
    """
    from pathlib import Path

    from csmlab.scene.gltf import read_gltf

    names = [f"{Path(file).name}: {name}" for file in dict.fromkeys(files)
             if Path(file).suffix.lower() in (".gltf", ".glb") for name in blend_materials(read_gltf(file).document)]
    return {"rule": rule, "materials": names} if names else None


def blend_line(note: dict | None) -> str | None:
    """The one-line warning of a :func:`blend_note` (from ``summary.json``); None without one."""
    if not note or not note.get("materials"):
        return None
    rule = note.get("rule", "opaque")
    how = "cast solid" if rule == "opaque" else "cast alpha-tested at their alphaCutoff"
    return (f"{len(note['materials'])} alphaMode BLEND material(s) {how} ([scene] blend_casters = \"{rule}\"; "
            f"docs/engines.md says what each engine does): {', '.join(note['materials'])}")
