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
  like a ``MASK`` material) for what the camera and the reference see; a shadow method's own
  ``[shadow] blend_casters`` may cast them otherwise (:meth:`csmlab.scene.core.Scene.casters`), so
  their masks are read whichever rule the level takes. docs/engines.md says what each engine does.
  :func:`blend_materials` names a file's blended materials so that a run warns about them.
"""

from __future__ import annotations

import numpy as np

from csmlab.documents import Value

__all__ = ["BLEND_CASTERS", "TEXTURE_TRANSFORM", "blend_line", "blend_materials", "blend_rule_masks",
           "read_blended_masked",
           "texture_coordinate_set", "transformed_uv"]

TEXTURE_TRANSFORM = "KHR_texture_transform"
BLEND_CASTERS = ("opaque", "masked")
"""``[scene] blend_casters``: how ``alphaMode = "BLEND"`` triangles cast (and block the reference's rays)."""


def _transform(texture: Value) -> Value | None:
    extensions = texture.get("extensions")
    transform = None if extensions is None else extensions.mapping().get(TEXTURE_TRANSFORM)
    return None if transform is None else transform.mapping()


def texture_coordinate_set(texture: Value) -> int:
    """The ``TEXCOORD_n`` set a textureInfo is sampled with: ``KHR_texture_transform``'s ``texCoord``, else its own."""
    transform = _transform(texture)
    override = None if transform is None else transform.get("texCoord")
    own = texture.get("texCoord") if override is None else override
    return 0 if own is None else own.integer(minimum=0)


def transformed_uv(uv, texture: Value) -> np.ndarray:
    """``uv`` ``(V, 2)`` under the textureInfo's ``KHR_texture_transform`` (unchanged without one).

    Raises
    ------
    InputError
        On a non-numeric or mis-sized ``offset``, ``rotation`` or ``scale``, naming its key.
    """
    uv = np.asarray(uv, dtype=np.float64)
    transform = _transform(texture)
    if transform is None:
        return uv
    offset, rotation, scale = (transform.get(name) for name in ("offset", "rotation", "scale"))
    offset = np.zeros(2) if offset is None else offset.numbers(2)
    scale = np.ones(2) if scale is None else scale.numbers(2)
    angle = 0.0 if rotation is None else rotation.number()
    c, s = np.cos(angle), np.sin(angle)
    scaled = uv * scale
    rotated = np.stack([c * scaled[:, 0] - s * scaled[:, 1], s * scaled[:, 0] + c * scaled[:, 1]], axis=1)
    return rotated + offset


def _blended(document: Value) -> list[int]:
    """Indices of the ``BLEND`` materials the file's meshes use, ascending."""
    used = {primitive.raw.get("material") for mesh in document.list_at("meshes") if mesh.is_object()
            for primitive in mesh.list_at("primitives") if primitive.is_object()}
    materials = document.list_at("materials")
    return [i for i in sorted(u for u in used if isinstance(u, int) and not isinstance(u, bool))
            if 0 <= i < len(materials) and materials[i].is_object() and materials[i].raw.get("alphaMode") == "BLEND"]


def blend_materials(document: Value) -> list[str]:
    """Names (``materials[i]`` where unnamed) of the ``BLEND`` materials the file's meshes use, in material order."""
    materials = document.list_at("materials")
    return [str(materials[i].raw.get("name") or f"materials[{i}]") for i in _blended(document)]


def read_blended_masked(document: Value) -> list[int]:
    """Turn the used ``BLEND`` materials to ``MASK`` (in the raw JSON) so that their masks are read; their indices.

    :func:`blend_rule_masks` then keeps each one's mask as its ``vertex_blend`` and, by the level's
    rule, as its ``vertex_mask`` too (``masked``) or not (``opaque``).
    """
    blended = _blended(document)
    materials = document.list_at("materials")
    for i in blended:
        materials[i].raw["alphaMode"] = "MASK"
    return blended


def blend_rule_masks(masks: dict, mask_materials: list[int], blended: list[int], rule: str) -> dict:
    """The :class:`~csmlab.scene.core.Scene` mask fields of a file read after :func:`read_blended_masked`.

    Parameters
    ----------
    masks : dict
        ``uv``, ``vertex_mask``, ``alpha`` as :func:`~csmlab.scene.gltf.gltf_scene_triangles` read them
        (empty: no mask).
    mask_materials : list of int
        The material of each mask in ``alpha``.
    blended : list of int
        The materials that were ``BLEND``.
    rule : {"opaque", "masked"}
        ``[scene] blend_casters``: ``opaque`` takes their masks out of ``vertex_mask``.

    Raises
    ------
    ValueError
        On a rule not in :data:`BLEND_CASTERS`.
    """
    if rule not in BLEND_CASTERS:
        raise ValueError(f"blend_casters: expected one of {list(BLEND_CASTERS)}, got {rule!r}")
    slots = [k for k, material in enumerate(mask_materials) if material in blended]
    if not masks or not slots:
        return masks
    vertex_blend = np.where(np.isin(masks["vertex_mask"], slots), masks["vertex_mask"], -1).astype(np.int32)
    vertex_mask = masks["vertex_mask"] if rule == "masked" else np.where(vertex_blend >= 0, -1, masks["vertex_mask"])
    return {**masks, "vertex_mask": vertex_mask, "vertex_blend": vertex_blend}


def blend_line(note: dict | None) -> str | None:
    """The one-line warning of ``summary.json``'s ``blend_materials`` (:func:`csmlab.experiment.build_workload`); None
    without one."""
    if not note or not note.get("materials"):
        return None
    rule = note.get("rule", "opaque")
    how = "cast solid" if rule == "opaque" else "cast alpha-tested at their alphaCutoff"
    own = "".join(f"; {name}'s shadow {rule}" for name, rule in note.get("methods", {}).items())
    return (f"{len(note['materials'])} alphaMode BLEND material(s) {how} ([scene] blend_casters = \"{rule}\"{own}; "
            f"docs/engines.md says what each engine does): {', '.join(note['materials'])}")
