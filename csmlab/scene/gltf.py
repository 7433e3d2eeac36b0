"""glTF 2.0 levels read through pygltflib: triangles placed by the node hierarchy, and the sun.

VTK's glTF reader is not used for levels: a level's geometry is mostly placed by its nodes —
nested transforms, meshes shared by several nodes, ``EXT_mesh_gpu_instancing`` — and every
triangle here is put where the glTF 2.0 specification puts it (§3.5.3 "Transformations"):

- a node's local matrix is its ``matrix``, else ``T · R · S`` of ``translation``, ``rotation``
  (unit quaternion ``x, y, z, w``) and ``scale``; its world matrix is its parent's world matrix
  times its local matrix, from the scene's root nodes down;
- an instanced node (``EXT_mesh_gpu_instancing``) draws its mesh once per instance at
  ``world · T_i · R_i · S_i`` (the extension's "the node's global transform is applied after the
  instance transform");
- a transform with a negative determinant mirrors the mesh, and then its triangles are wound
  clockwise seen from the front (§3.7.2.1): their index order is reversed, so that csmlab's
  counter-clockwise rule and per-triangle normals stay outward.

Only triangle primitives (modes 4, 5, 6) are read; points and lines are left out. Normals are not
read (they come from the winding) and neither are colours (the albedo is one colour, as for the
other mesh formats). The one material property read is the alpha test (§3.9.4 "Alpha Coverage"):
a primitive whose material has ``alphaMode = "MASK"`` becomes alpha-tested triangles
(:class:`~csmlab.scene.core.AlphaMask`) — coverage is ``pbrMetallicRoughness.baseColorFactor[3]``
times the ``baseColorTexture``'s alpha channel (read by :func:`csmlab.scene.alpha_files.alpha_mask_of_image`
from a file beside the glTF, a ``data:`` URI or a buffer view), opaque where coverage ≥
``alphaCutoff`` (0.5 by default), sampled at the primitive's ``TEXCOORD_n`` (``n`` the texture's
``texCoord``; glTF's v already runs down the image, as :class:`~csmlab.scene.core.AlphaMask` does).
Every primitive has vertices of its own in every placement, so an instanced or mirrored copy keeps
its texture coordinates and its mask.

The sun is a ``KHR_lights_punctual`` light of type ``directional`` attached to a node of the scene:
it shines along that node's world −Z axis (the extension's "lights point along −Z").

Every broken file stops with an :class:`~csmlab.errors.InputError` naming the file and the glTF
key (``accessors[3]``, ``nodes[2].rotation``, ``KHR_lights_punctual``, …) and what was expected.
"""

from __future__ import annotations

import base64
import math
import warnings
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import unquote

import numpy as np

from csmlab.errors import InputError
from csmlab.geometry import quat_to_matrix
from csmlab.scene.alpha_files import alpha_mask_of_image
from csmlab.scene.core import AlphaMask
from csmlab.scene.gltf_compression import decompressed
from csmlab.scene.gltf_materials import texture_coordinate_set, transformed_uv

__all__ = ["GltfFile", "Sun", "gltf_scene_triangles", "material_mask", "read_gltf", "sun_of", "trs_matrices"]

_COMPONENTS: dict[int, np.dtype] = {
    5120: np.dtype("<i1"), 5121: np.dtype("<u1"), 5122: np.dtype("<i2"), 5123: np.dtype("<u2"),
    5125: np.dtype("<u4"), 5126: np.dtype("<f4"),
}
"""glTF ``componentType`` → little-endian NumPy type."""
_WIDTHS: dict[str, int] = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
"""glTF accessor ``type`` → components per element."""
_NORMALIZED_DIVISORS: dict[int, float] = {5120: 127.0, 5121: 255.0, 5122: 32767.0, 5123: 65535.0}
"""Integer ``componentType`` → the divisor of a normalized accessor (§3.11, signed values clamped at −1)."""
INSTANCING = "EXT_mesh_gpu_instancing"
LIGHTS = "KHR_lights_punctual"
UNIT_TOLERANCE = 1e-3
"""A node or key quaternion with ``| |q| − 1 |`` beyond this is broken, not rounding."""
DEFAULT_ALPHA_CUTOFF = 0.5
"""A ``MASK`` material's ``alphaCutoff`` when the file gives none (§5.19 "material")."""


@dataclass(frozen=True)
class GltfFile:
    """A parsed glTF file with its buffers loaded.

    Attributes
    ----------
    path : Path
        The ``.gltf`` or ``.glb`` file (for error messages and relative buffer URIs).
    document : pygltflib.GLTF2
        The parsed JSON.
    buffers : tuple of bytes
        Each ``buffers[i]``'s bytes (the GLB binary chunk, a data URI or a file beside ``path``).
    """

    path: Path
    document: object
    buffers: tuple

    def error(self, key: str, expected: str) -> InputError:
        """An :class:`InputError` naming this file and the glTF ``key``."""
        return InputError(expected, file=self.path, field=key)

    def accessor(self, index: int, *, key: str) -> np.ndarray:
        """Accessor ``index`` as float64 ``(count, width)`` (normalized integers scaled to [−1, 1]).

        ``key`` names who refers to it, for error messages. Sparse accessors are applied.
        """
        document = self.document
        if not isinstance(index, int) or not 0 <= index < len(document.accessors):
            raise self.error(key, f"expected an accessor index in [0, {len(document.accessors)}), got {index!r}")
        accessor = document.accessors[index]
        where = f"accessors[{index}]"
        dtype = _COMPONENTS.get(accessor.componentType)
        width = _WIDTHS.get(accessor.type)
        if dtype is None or width is None or not isinstance(accessor.count, int) or accessor.count < 0:
            raise self.error(where, f"expected a componentType in {sorted(_COMPONENTS)}, a type in "
                                    f"{list(_WIDTHS)} and a count >= 0, got {accessor.componentType!r}, "
                                    f"{accessor.type!r}, {accessor.count!r}")
        if accessor.bufferView is None:
            values = np.zeros((accessor.count, width), dtype=dtype)
        else:
            values = self._view(accessor.bufferView, accessor.byteOffset or 0, dtype, width, accessor.count,
                                where=where)
        values = values.astype(np.float64)
        if accessor.sparse is not None:
            sparse = accessor.sparse
            index_type = _COMPONENTS.get(sparse.indices.componentType)
            if index_type is None or index_type.kind != "u":
                raise self.error(f"{where}.sparse.indices", "expected an unsigned componentType, got "
                                                            f"{sparse.indices.componentType!r}")
            at = self._view(sparse.indices.bufferView, sparse.indices.byteOffset or 0, index_type, 1, sparse.count,
                            where=f"{where}.sparse.indices")[:, 0].astype(np.int64)
            if at.size and (at.min() < 0 or at.max() >= accessor.count):
                raise self.error(f"{where}.sparse.indices", f"expected indices in [0, {accessor.count})")
            values[at] = self._view(sparse.values.bufferView, sparse.values.byteOffset or 0, dtype, width,
                                    sparse.count, where=f"{where}.sparse.values")
        if accessor.normalized and accessor.componentType in _NORMALIZED_DIVISORS:
            values = np.maximum(values / _NORMALIZED_DIVISORS[accessor.componentType], -1.0)
        if not np.all(np.isfinite(values)):
            row = int(np.argmax(~np.all(np.isfinite(values), axis=1)))
            raise self.error(where, f"expected finite numbers, found NaN or infinity (element {row})")
        return values

    def _view(self, view_index, offset: int, dtype: np.dtype, width: int, count: int, *, where: str) -> np.ndarray:
        """``count`` elements of ``width`` components from buffer view ``view_index``, honouring its stride."""
        views = self.document.bufferViews
        if not isinstance(view_index, int) or not 0 <= view_index < len(views):
            raise self.error(where, f"expected a bufferView index in [0, {len(views)}), got {view_index!r}")
        view = views[view_index]
        if not isinstance(view.buffer, int) or not 0 <= view.buffer < len(self.buffers):
            raise self.error(f"bufferViews[{view_index}]", f"expected a buffer index in [0, {len(self.buffers)}), "
                                                           f"got {view.buffer!r}")
        element = dtype.itemsize * width
        stride = view.byteStride or element
        start = (view.byteOffset or 0) + offset
        need = start + (stride * (count - 1) + element if count else 0)
        data = self.buffers[view.buffer]
        if count and (need > (view.byteOffset or 0) + view.byteLength or need > len(data)):
            raise self.error(where, f"expected {count} elements of {element} bytes inside bufferViews[{view_index}] "
                                    f"and its buffer, but they end at byte {need} of {len(data)}")
        if stride == element:
            return np.frombuffer(data, dtype=dtype, count=count * width, offset=start).reshape(count, width)
        rows = np.lib.stride_tricks.as_strided(np.frombuffer(data, dtype=np.uint8, offset=start),
                                               shape=(count, element), strides=(stride, 1))
        return np.ascontiguousarray(rows).view(dtype).reshape(count, width)


def _uri_bytes(uri: str, path: Path, *, key: str) -> tuple[bytes, Path]:
    """The bytes a buffer's or image's ``uri`` names (a base64 data URI or a file beside ``path``) and their source.

    The source is the file read, or ``path`` itself for a data URI.
    """
    if uri.startswith("data:"):
        try:
            return base64.b64decode(uri.partition(",")[2], validate=True), path
        except ValueError:
            raise InputError("expected a base64 data URI", file=path, field=key) from None
    source = path.parent / unquote(uri)
    if not source.is_file():
        raise InputError(f"expected the file {source} beside the glTF file, found nothing", file=path, field=key)
    return source.read_bytes(), source


def _buffer_bytes(document, index: int, path: Path) -> bytes:
    """The bytes of ``buffers[index]``: the GLB chunk, a base64 data URI or a file beside ``path``."""
    uri = document.buffers[index].uri
    if uri is None:
        blob = document.binary_blob()
        if blob is None:
            raise InputError("expected the GLB binary chunk for a buffer without uri, found none", file=path,
                             field=f"buffers[{index}]")
        return bytes(blob)
    return _uri_bytes(uri, path, key=f"buffers[{index}].uri")[0]


def read_gltf(file) -> GltfFile:
    """Parse a ``.gltf`` or ``.glb`` file and load its buffers.

    Raises
    ------
    InputError
        Field ``file``: missing, or not glTF 2.0 that pygltflib can parse; ``buffers[i]``: a buffer
        that cannot be loaded.
    """
    import pygltflib

    path = Path(file)
    if not path.is_file():
        raise InputError("expected an existing glTF file, found " + ("a directory" if path.is_dir() else "nothing"),
                         file=path, field="file")
    try:
        with warnings.catch_warnings():
            # The specification tells readers to skip unknown GLB chunks; pygltflib warns as it does.
            warnings.simplefilter("ignore")
            document = (pygltflib.GLTF2().load_binary(str(path)) if path.read_bytes()[:4] == b"glTF"
                        else pygltflib.GLTF2().load_json(str(path)))
    except Exception as exc:  # pygltflib raises JSON, struct, key and type errors on a broken file.
        raise InputError(f"expected a glTF 2.0 file (JSON or binary GLB); parsing failed: {exc}", file=path,
                         field="file") from None
    if document is None or not str(getattr(document.asset, "version", "")).startswith("2."):
        raise InputError("expected a glTF 2.0 file with asset.version \"2.0\"", file=path, field="asset.version")
    # Draco and meshopt geometry decoded into plain views and accessors (csmlab.scene.gltf_compression).
    document, buffers = decompressed(document, path, lambda i: _buffer_bytes(document, i, path))
    return GltfFile(path=path, document=document, buffers=buffers)


def trs_matrices(translation, rotation, scale) -> np.ndarray:
    """``T · R · S`` matrices ``(N, 4, 4)``: translations ``(N, 3)``, quaternions ``(N, 4)`` (x, y, z, w), scales ``(N, 3)``."""
    translation, rotation, scale = (np.asarray(a, dtype=np.float64) for a in (translation, rotation, scale))
    out = np.zeros((translation.shape[0], 4, 4))
    out[:, :3, :3] = quat_to_matrix(rotation) * scale[:, None, :]
    out[:, :3, 3] = translation
    out[:, 3, 3] = 1.0
    return out


def node_quaternion(gltf: GltfFile, index: int) -> np.ndarray:
    """``nodes[index].rotation`` ``(4,)``, checked to be a unit quaternion and normalised."""
    node = gltf.document.nodes[index]
    q = np.asarray(node.rotation if node.rotation is not None else (0.0, 0.0, 0.0, 1.0), dtype=np.float64)
    if q.shape != (4,) or not np.all(np.isfinite(q)) or abs(np.linalg.norm(q) - 1.0) > UNIT_TOLERANCE:
        raise gltf.error(f"nodes[{index}].rotation", f"expected a unit quaternion (x, y, z, w), got {node.rotation!r}")
    return q / np.linalg.norm(q)


def local_matrix(gltf: GltfFile, index: int) -> np.ndarray:
    """``nodes[index]``'s local matrix ``(4, 4)``: its ``matrix`` (column-major) or ``T · R · S``."""
    node = gltf.document.nodes[index]
    if node.matrix is not None:
        m = np.asarray(node.matrix, dtype=np.float64)
        if m.shape != (16,) or not np.all(np.isfinite(m)):
            raise gltf.error(f"nodes[{index}].matrix", f"expected 16 finite numbers, got {node.matrix!r}")
        return m.reshape(4, 4).T
    translation = np.asarray(node.translation if node.translation is not None else (0.0, 0.0, 0.0), dtype=np.float64)
    scale = np.asarray(node.scale if node.scale is not None else (1.0, 1.0, 1.0), dtype=np.float64)
    for name, value in (("translation", translation), ("scale", scale)):
        if value.shape != (3,) or not np.all(np.isfinite(value)):
            raise gltf.error(f"nodes[{index}].{name}", f"expected 3 finite numbers, got {getattr(node, name)!r}")
    return trs_matrices(translation[None], node_quaternion(gltf, index)[None], scale[None])[0]


def scene_roots(gltf: GltfFile) -> list[int]:
    """Root node indices of the file's default scene (``scene``, else ``scenes[0]``, else every parentless node)."""
    document = gltf.document
    count = len(document.nodes)
    if document.scenes:
        chosen = document.scene if document.scene is not None else 0
        if not isinstance(chosen, int) or not 0 <= chosen < len(document.scenes):
            raise gltf.error("scene", f"expected a scene index in [0, {len(document.scenes)}), got {chosen!r}")
        roots = list(document.scenes[chosen].nodes or [])
    else:
        children = {c for node in document.nodes for c in (node.children or [])}
        roots = [i for i in range(count) if i not in children]
    bad = [r for r in roots if not isinstance(r, int) or not 0 <= r < count]
    if bad:
        raise gltf.error("scenes", f"expected node indices in [0, {count}), got {bad[0]!r}")
    return roots


def scene_nodes(gltf: GltfFile) -> list[tuple[int, int | None]]:
    """``(node, parent)`` of every node of the default scene, parents before children (depth first).

    Raises
    ------
    InputError
        On a child index out of range or a node reached twice (a cycle or a shared child: the
        specification requires a strict tree).
    """
    count = len(gltf.document.nodes)
    order, seen = [], set()
    stack = [(root, None) for root in reversed(scene_roots(gltf))]
    while stack:
        index, parent = stack.pop()
        if index in seen:
            raise gltf.error(f"nodes[{index}]", "expected each node once in the scene's tree, found it twice "
                                                "(a cycle or a node with two parents)")
        seen.add(index)
        order.append((index, parent))
        children = gltf.document.nodes[index].children or []
        bad = [c for c in children if not isinstance(c, int) or not 0 <= c < count]
        if bad:
            raise gltf.error(f"nodes[{index}].children", f"expected node indices in [0, {count}), got {bad[0]!r}")
        stack.extend((child, index) for child in reversed(children))
    return order


def world_matrices(gltf: GltfFile) -> dict[int, np.ndarray]:
    """World matrix ``(4, 4)`` of every node of the default scene, by node index (file units, file axes)."""
    world: dict[int, np.ndarray] = {}
    for index, parent in scene_nodes(gltf):
        local = local_matrix(gltf, index)
        world[index] = local if parent is None else world[parent] @ local
    return world


def _instance_matrices(gltf: GltfFile, index: int) -> np.ndarray:
    """``T · R · S`` ``(I, 4, 4)`` of ``nodes[index]``'s ``EXT_mesh_gpu_instancing`` instances; identity ``(1, 4, 4)`` without."""
    extension = (gltf.document.nodes[index].extensions or {}).get(INSTANCING)
    if extension is None:
        return np.eye(4)[None]
    key = f"nodes[{index}].extensions.{INSTANCING}.attributes"
    attributes = extension.get("attributes") if isinstance(extension, dict) else None
    if not isinstance(attributes, dict) or not attributes:
        raise gltf.error(key, "expected TRANSLATION, ROTATION and/or SCALE accessors, got none")
    arrays = {name: gltf.accessor(attributes[name], key=f"{key}.{name}")
              for name in ("TRANSLATION", "ROTATION", "SCALE") if name in attributes}
    counts = {a.shape[0] for a in arrays.values()}
    widths = {"TRANSLATION": 3, "ROTATION": 4, "SCALE": 3}
    for name, array in arrays.items():
        if array.shape[1] != widths[name]:
            raise gltf.error(f"{key}.{name}", f"expected {widths[name]} components per instance, got {array.shape[1]}")
    if len(counts) != 1:
        raise gltf.error(key, f"expected one instance count for every attribute, got {sorted(counts)}")
    count = counts.pop()
    rotation = arrays.get("ROTATION", np.tile([0.0, 0.0, 0.0, 1.0], (count, 1)))
    length = np.linalg.norm(rotation, axis=1)
    if np.any(np.abs(length - 1.0) > UNIT_TOLERANCE):
        bad = int(np.argmax(np.abs(length - 1.0) > UNIT_TOLERANCE))
        raise gltf.error(f"{key}.ROTATION", f"expected unit quaternions, instance {bad} has |q| = {length[bad]:.6g}")
    return trs_matrices(arrays.get("TRANSLATION", np.zeros((count, 3))), rotation / length[:, None],
                        arrays.get("SCALE", np.ones((count, 3))))


@dataclass(frozen=True)
class _Primitive:
    """One triangle primitive of a mesh in its mesh's coordinates.

    Attributes
    ----------
    points : ndarray, shape (V, 3), float64
    triangles : ndarray, shape (T, 3), int64
        Indices into ``points``, as the file winds them.
    material : int
        The ``MASK`` material's index, −1 for an opaque primitive.
    uv : ndarray, shape (V, 2), float64, or None
        The mask's texture coordinates (None for an opaque primitive).
    """

    points: np.ndarray
    triangles: np.ndarray
    material: int
    uv: np.ndarray | None


def _primitive(gltf: GltfFile, mesh_index: int, p: int) -> _Primitive | None:
    """``meshes[mesh_index].primitives[p]`` with its ``MASK`` material's coordinates; None for points, lines."""
    primitive = gltf.document.meshes[mesh_index].primitives[p]
    key = f"meshes[{mesh_index}].primitives[{p}]"
    mode = 4 if primitive.mode is None else primitive.mode
    if mode not in (4, 5, 6):
        return None
    position = getattr(primitive.attributes, "POSITION", None)
    if position is None:
        raise gltf.error(f"{key}.attributes", "expected a POSITION attribute, found none")
    points = gltf.accessor(position, key=f"{key}.attributes.POSITION")
    if points.shape[1] != 3:
        raise gltf.error(f"{key}.attributes.POSITION", f"expected VEC3 positions, got {points.shape[1]} components")
    if primitive.indices is None:
        indices = np.arange(points.shape[0], dtype=np.int64)
    else:
        indices = gltf.accessor(primitive.indices, key=f"{key}.indices")[:, 0].astype(np.int64)
    if indices.size and (indices.min() < 0 or indices.max() >= points.shape[0]):
        raise gltf.error(f"{key}.indices", f"expected vertex indices in [0, {points.shape[0]}), got "
                                           f"[{indices.min()}, {indices.max()}]")
    if mode == 4:
        triangles = indices[: indices.size - indices.size % 3].reshape(-1, 3)
    elif mode == 5:
        k = np.arange(max(indices.size - 2, 0))
        # §3.7.2.1: strip triangle k is (k, k+1, k+2) for even k and (k+1, k, k+2) for odd k.
        first = np.where(k % 2 == 0, k, k + 1)
        second = np.where(k % 2 == 0, k + 1, k)
        triangles = np.stack([indices[first], indices[second], indices[k + 2]], axis=1)
    else:
        k = np.arange(max(indices.size - 2, 0))
        hub = np.full(k.shape, indices[0] if indices.size else 0)
        triangles = np.stack([hub, indices[k + 1], indices[k + 2]], axis=1)
    material = _masked_material(gltf, primitive.material, key=f"{key}.material")
    if material < 0:
        return _Primitive(points, triangles, -1, None)
    return _Primitive(points, triangles, material, _mask_coordinates(gltf, primitive, material, points.shape[0],
                                                                     key=key))


def _masked_material(gltf: GltfFile, material, *, key: str) -> int:
    """``material`` if it is an ``alphaMode = "MASK"`` material, else −1 (no material, ``OPAQUE``, ``BLEND``)."""
    if material is None:
        return -1
    materials = gltf.document.materials
    if not isinstance(material, int) or not 0 <= material < len(materials):
        raise gltf.error(key, f"expected a material index in [0, {len(materials)}), got {material!r}")
    return material if materials[material].alphaMode == "MASK" else -1


def _base_colour_texture(gltf: GltfFile, material: int):
    """``materials[material].pbrMetallicRoughness.baseColorTexture`` (a TextureInfo), or None."""
    pbr = gltf.document.materials[material].pbrMetallicRoughness
    return None if pbr is None else pbr.baseColorTexture


def _mask_coordinates(gltf: GltfFile, primitive, material: int, count: int, *, key: str) -> np.ndarray:
    """The ``TEXCOORD_n`` ``(count, 2)`` a ``MASK`` material's base colour texture is sampled at (zeros without one)."""
    texture = _base_colour_texture(gltf, material)
    if texture is None:
        return np.zeros((count, 2))
    name = f"TEXCOORD_{texture_coordinate_set(texture)}"
    accessor = getattr(primitive.attributes, name, None)
    if accessor is None:
        raise gltf.error(f"{key}.attributes", f"expected {name}, the coordinates of alpha-masked "
                                              f"materials[{material}]'s baseColorTexture, found none")
    uv = gltf.accessor(accessor, key=f"{key}.attributes.{name}")
    if uv.shape != (count, 2):
        raise gltf.error(f"{key}.attributes.{name}", f"expected {count} VEC2 coordinates (one per POSITION), "
                                                     f"got shape {uv.shape}")
    texture_key = f"materials[{material}].pbrMetallicRoughness.baseColorTexture"
    try:
        return transformed_uv(uv, texture, key=texture_key)  # KHR_texture_transform (csmlab.scene.gltf_materials)
    except ValueError as exc:
        field, _, message = str(exc).partition(": ")
        raise gltf.error(field, message) from None


def material_mask(gltf: GltfFile, material: int) -> AlphaMask:
    """The :class:`~csmlab.scene.core.AlphaMask` of ``MASK`` material ``material``: its base colour's alpha and cutoff.

    Coverage ``(H, W)`` is ``baseColorFactor[3]`` times the ``baseColorTexture`` image's alpha
    (``(1, 1)`` of the factor alone without a texture), row 0 the image's top row (v = 0).

    Raises
    ------
    InputError
        Naming ``materials[i].alphaCutoff`` or ``.pbrMetallicRoughness.baseColorFactor`` out of
        range, a bad ``textures[j]`` or ``images[k]`` reference, or the image (its file, or the glTF
        file that embeds it) that Pillow cannot read.
    """
    entry = gltf.document.materials[material]
    key = f"materials[{material}]"
    cutoff = DEFAULT_ALPHA_CUTOFF if entry.alphaCutoff is None else entry.alphaCutoff
    if isinstance(cutoff, bool) or not isinstance(cutoff, (int, float)) or not 0.0 < cutoff <= 1.0:
        raise gltf.error(f"{key}.alphaCutoff", f"expected a number in (0, 1] (csmlab cuts where coverage ≥ it), "
                                               f"got {entry.alphaCutoff!r}")
    pbr = entry.pbrMetallicRoughness
    factor = np.asarray(pbr.baseColorFactor if pbr is not None and pbr.baseColorFactor is not None
                        else (1.0, 1.0, 1.0, 1.0), dtype=np.float64)
    if factor.shape != (4,) or not np.all((factor >= 0.0) & (factor <= 1.0)):
        raise gltf.error(f"{key}.pbrMetallicRoughness.baseColorFactor",
                         f"expected 4 numbers in [0, 1], got {pbr.baseColorFactor!r}")
    texture = _base_colour_texture(gltf, material)
    if texture is None:
        return AlphaMask(np.full((1, 1), factor[3], np.float32), float(cutoff), source=f"{gltf.path} {key}")
    data, source, image_key = _texture_image(gltf, texture.index, key=f"{key}.pbrMetallicRoughness.baseColorTexture")
    mask = alpha_mask_of_image(data, cutoff=float(cutoff), source=source, field=image_key)
    return AlphaMask(mask.alpha * np.float32(factor[3]), float(cutoff), source=mask.source)


def _texture_image(gltf: GltfFile, texture, *, key: str) -> tuple[bytes, Path, str]:
    """The encoded bytes of ``textures[texture]``'s image, the file they came from and the image's glTF key."""
    document = gltf.document
    if not isinstance(texture, int) or not 0 <= texture < len(document.textures):
        raise gltf.error(f"{key}.index", f"expected a texture index in [0, {len(document.textures)}), got {texture!r}")
    image = document.textures[texture].source
    if not isinstance(image, int) or not 0 <= image < len(document.images):
        raise gltf.error(f"textures[{texture}].source", f"expected an image index in [0, {len(document.images)}), "
                                                        f"got {image!r}")
    entry = document.images[image]
    image_key = f"images[{image}]"
    if entry.uri is not None:
        data, source = _uri_bytes(entry.uri, gltf.path, key=f"{image_key}.uri")
        return data, source, image_key
    view = entry.bufferView
    if not isinstance(view, int) or not 0 <= view < len(document.bufferViews):
        raise gltf.error(image_key, f"expected a uri or a bufferView index in [0, {len(document.bufferViews)}), "
                                    f"got {view!r}")
    length = document.bufferViews[view].byteLength or 0
    return gltf._view(view, 0, np.dtype(np.uint8), 1, length, where=image_key).tobytes(), gltf.path, image_key


def gltf_scene_triangles(gltf: GltfFile) -> tuple[np.ndarray, np.ndarray, dict]:
    """Every triangle of the default scene in world coordinates (file units, file axes), with its alpha masks.

    Returns
    -------
    points : ndarray, shape (V, 3), float64
    triangles : ndarray, shape (T, 3), int64
        Counter-clockwise seen from the front in world space (mirrored instances reversed).
    masks : dict
        Empty when no primitive of the scene has a ``MASK`` material; else the
        :class:`~csmlab.scene.core.Scene` fields ``uv`` ``(V, 2)`` float64, ``vertex_mask`` ``(V,)``
        int32 (−1 opaque) and ``alpha`` (one :class:`~csmlab.scene.core.AlphaMask` per ``MASK``
        material drawn, by material index).

    Raises
    ------
    InputError
        On a broken reference, accessor or mask image (naming its glTF key), or a scene with no triangle.
    """
    document = gltf.document
    world = world_matrices(gltf)
    cache: dict[int, list[_Primitive]] = {}
    points_out, triangles_out, parts, offset = [], [], [], 0
    for index, matrix in world.items():
        mesh = document.nodes[index].mesh
        if mesh is None:
            continue
        if not isinstance(mesh, int) or not 0 <= mesh < len(document.meshes):
            raise gltf.error(f"nodes[{index}].mesh", f"expected a mesh index in [0, {len(document.meshes)}), "
                                                     f"got {mesh!r}")
        if mesh not in cache:
            cache[mesh] = [part for p in range(len(document.meshes[mesh].primitives))
                           if (part := _primitive(gltf, mesh, p)) is not None]
        placements = matrix @ _instance_matrices(gltf, index)
        mirrored = np.linalg.det(placements[:, :3, :3]) < 0
        for part in cache[mesh]:
            # (I, V, 3): every instance's copy of the points; a batched matmul, several times einsum's speed.
            placed = np.matmul(part.points, placements[:, :3, :3].transpose(0, 2, 1)) + placements[:, None, :3, 3]
            wound = np.where(mirrored[:, None, None], part.triangles[None, :, ::-1], part.triangles[None])
            shift = offset + part.points.shape[0] * np.arange(placements.shape[0])
            points_out.append(placed.reshape(-1, 3))
            triangles_out.append((wound + shift[:, None, None]).reshape(-1, 3))
            parts.append((part, placements.shape[0]))
            offset += placed.shape[0] * placed.shape[1]
    if not triangles_out or sum(t.shape[0] for t in triangles_out) == 0:
        raise gltf.error("meshes", "expected at least one triangle primitive on a node of the scene, found none")
    return np.concatenate(points_out), np.concatenate(triangles_out), _scene_masks(gltf, parts)


def _scene_masks(gltf: GltfFile, parts: list[tuple[_Primitive, int]]) -> dict:
    """``uv``, ``vertex_mask`` and ``alpha`` of the placed primitives ``(primitive, instances)``, in output order.

    Each instance's copy of a masked primitive repeats its coordinates: placements move points, not
    texture coordinates. Empty when none is masked.
    """
    used = sorted({part.material for part, _ in parts if part.material >= 0})
    if not used:
        return {}
    uv, vertex_mask = [], []
    for part, instances in parts:
        count = part.points.shape[0] * instances
        if part.material < 0:
            uv.append(np.zeros((count, 2)))
            vertex_mask.append(np.full(count, -1, np.int32))
        else:
            uv.append(np.tile(part.uv, (instances, 1)))
            vertex_mask.append(np.full(count, used.index(part.material), np.int32))
    return dict(uv=np.concatenate(uv), vertex_mask=np.concatenate(vertex_mask),
                alpha=tuple(material_mask(gltf, material) for material in used))


@dataclass(frozen=True)
class Sun:
    """A ``KHR_lights_punctual`` directional light of a glTF scene.

    Attributes
    ----------
    direction : ndarray, shape (3,), float64
        Unit vector from the light toward the scene, in the file's axes (its node's world −Z).
    name : str
        The light's name (its node's when the light has none).
    """

    direction: np.ndarray
    name: str


def sun_of(gltf: GltfFile) -> Sun:
    """The one directional ``KHR_lights_punctual`` light placed on a node of the default scene.

    Raises
    ------
    InputError
        Field ``KHR_lights_punctual``: no directional light on a node of the scene, or more than one
        (their names listed); ``nodes[i].extensions.KHR_lights_punctual.light``: a bad light index.
    """
    lights = ((gltf.document.extensions or {}).get(LIGHTS) or {}).get("lights") or []
    found = []
    for index, matrix in world_matrices(gltf).items():
        extension = (gltf.document.nodes[index].extensions or {}).get(LIGHTS)
        if extension is None:
            continue
        light = extension.get("light") if isinstance(extension, dict) else None
        if not isinstance(light, int) or not 0 <= light < len(lights):
            raise gltf.error(f"nodes[{index}].extensions.{LIGHTS}.light",
                             f"expected a light index in [0, {len(lights)}), got {light!r}")
        if lights[light].get("type") != "directional":
            continue
        axis = -matrix[:3, 2]
        length = float(np.linalg.norm(axis))
        if not math.isfinite(length) or length < 1e-12:
            raise gltf.error(f"nodes[{index}]", "expected a directional light's node to have a non-degenerate "
                                                "world transform, its −Z axis has zero length")
        found.append(Sun(direction=axis / length,
                         name=lights[light].get("name") or gltf.document.nodes[index].name or f"nodes[{index}]"))
    if len(found) != 1:
        names = ", ".join(s.name for s in found)
        raise gltf.error(LIGHTS, "expected one directional light on a node of the scene, found "
                                 + (f"{len(found)}: {names}" if found else "none"))
    return found[0]
