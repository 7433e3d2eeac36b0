"""glTF 2.0 levels: triangles placed by the node hierarchy, and the sun.

The file (JSON, or the GLB container of §4.4) is parsed here and read through
:class:`csmlab.documents.Value`, the typed accessor every reader uses: each key is read as what
the specification says it holds, and anything else — a list where an object belongs, a string for
an index, a null — stops with the file, the key and what was expected.

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
read (they come from the winding), nor vertex colours. A primitive's material gives its triangles'
albedo: ``pbrMetallicRoughness.baseColorFactor`` (linear RGB, white without one) times its
``baseColorTexture`` (sRGB-decoded, sampled at the texture's ``TEXCOORD_n`` under
``KHR_texture_transform``, :class:`~csmlab.scene.core.ColourTextures`); a primitive without a
material keeps :func:`~csmlab.scene.mesh.load_mesh`'s ``albedo`` (grey). The alpha test (§3.9.4
"Alpha Coverage") is read too: a primitive whose material has ``alphaMode = "MASK"`` becomes alpha-tested triangles
(:class:`~csmlab.scene.core.AlphaMask`) — coverage is ``pbrMetallicRoughness.baseColorFactor[3]``
times the ``baseColorTexture``'s alpha channel (read by :func:`csmlab.scene.alpha_files.alpha_mask_of_image`
from a file beside the glTF, a ``data:`` URI or a buffer view), opaque where coverage ≥
``alphaCutoff`` (0.5 by default), sampled at the primitive's ``TEXCOORD_n`` (``n`` the texture's
``texCoord``; glTF's v already runs down the image, as :class:`~csmlab.scene.core.AlphaMask` does).
Every primitive has vertices of its own in every placement, so an instanced or mirrored copy keeps
its texture coordinates and its mask.

The sun is a ``KHR_lights_punctual`` light of type ``directional`` attached to a node of the scene:
it shines along that node's world −Z axis (the extension's "lights point along −Z"), in its
``color`` (linear RGB; the shaded views tint the direct light with it).

Every broken file stops with an :class:`~csmlab.errors.InputError` naming the file and the glTF
key (``accessors[3]``, ``nodes[2].rotation``, ``KHR_lights_punctual``, …) and what was expected;
so does a file asking for more than a machine holds: JSON nested deeper than
:data:`~csmlab.documents.MAX_JSON_DEPTH`, an accessor of more than ``9 ×``
:data:`~csmlab.documents.MAX_TRIANGLES` components, a scene of more than
:data:`~csmlab.documents.MAX_TRIANGLES` triangles once its instances are placed.
"""

from __future__ import annotations

import base64
import math
import struct
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import unquote

import numpy as np

from csmlab.documents import MAX_TRIANGLES, Value, is_file, json_value, within_limit
from csmlab.errors import InputError
from csmlab.geometry import quat_to_matrix
from csmlab.scene.alpha_files import alpha_mask_of_image, colour_texture_of_image
from csmlab.scene.core import AlphaMask, ColourTexture, ColourTextures
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
SECTIONS = ("accessors", "animations", "bufferViews", "buffers", "cameras", "images", "materials", "meshes", "nodes",
            "samplers", "scenes", "skins", "textures")
"""The top-level lists of a glTF document (§5.17 "glTF"), each read as a list when present."""
_GLB_MAGIC = b"glTF"
_GLB_JSON, _GLB_BIN = 0x4E4F534A, 0x004E4942
"""GLB chunk types (§4.4.3): the JSON chunk and the binary buffer."""


@dataclass(frozen=True)
class GltfFile:
    """A parsed glTF file with its buffers loaded.

    Attributes
    ----------
    path : Path
        The ``.gltf`` or ``.glb`` file (for error messages and relative buffer URIs).
    document : csmlab.documents.Value
        The parsed JSON, read through its typed accessor.
    buffers : tuple of bytes
        Each ``buffers[i]``'s bytes (the GLB binary chunk, a data URI or a file beside ``path``).
    sections : dict
        Each of :data:`SECTIONS` present, as its list of :class:`~csmlab.documents.Value`.
    """

    path: Path
    document: Value
    buffers: tuple
    sections: dict = field(default_factory=dict)

    def error(self, key: str, expected: str) -> InputError:
        """An :class:`InputError` naming this file and the glTF ``key``."""
        return InputError(expected, file=self.path, field=key)

    def section(self, name: str) -> list[Value]:
        """The entries of the top-level list ``name`` (``nodes``, ``accessors``, …); empty when absent."""
        return self.sections.get(name, [])

    def entry(self, reference: Value, name: str) -> tuple[int, Value]:
        """The index ``reference`` holds into section ``name``, and that entry (each checked to be an object)."""
        entries = self.section(name)
        index = reference.index(len(entries), name)
        return index, entries[index].mapping()

    def accessor(self, reference: Value) -> np.ndarray:
        """The accessor ``reference`` (an index) names, float64 ``(count, width)`` (normalized integers in [−1, 1]).

        Sparse accessors are applied.
        """
        index, accessor = self.entry(reference, "accessors")
        where = f"accessors[{index}]"
        component = accessor.at("componentType", "a componentType").integer(
            what=f"a componentType in {sorted(_COMPONENTS)}")
        dtype = _COMPONENTS.get(component)
        if dtype is None:
            raise accessor.at("componentType").error(f"a componentType in {sorted(_COMPONENTS)}")
        width = _WIDTHS[accessor.at("type", "an accessor type").text(_WIDTHS)]
        count = accessor.at("count", "an element count").integer(minimum=0)
        within_limit(count * width, MAX_TRIANGLES * 9, what="accessor components", file=self.path,
                     field=f"{where}.count")
        view = accessor.get("bufferView")
        offset = accessor.get("byteOffset")
        if view is None:
            values = np.zeros((count, width), dtype=dtype)
        else:
            values = self._view(view, 0 if offset is None else offset.integer(minimum=0), dtype, width, count,
                                where=where)
        with np.errstate(invalid="ignore"):  # a signalling NaN in the buffer: refused below, as every NaN
            values = values.astype(np.float64)
        sparse = accessor.get("sparse")
        if sparse is not None:
            values = self._sparse(sparse.mapping(), values, dtype, width, where=where)
        normalized = accessor.get("normalized")
        if normalized is not None and normalized.boolean() and component in _NORMALIZED_DIVISORS:
            values = np.maximum(values / _NORMALIZED_DIVISORS[component], -1.0)
        if not np.all(np.isfinite(values)):
            row = int(np.argmax(~np.all(np.isfinite(values), axis=1)))
            raise self.error(where, f"expected finite numbers, found NaN or infinity (element {row})")
        return values

    def _sparse(self, sparse: Value, values: np.ndarray, dtype: np.dtype, width: int, *, where: str) -> np.ndarray:
        """``values`` with the sparse accessor's substitutions (§3.6.2.3) applied."""
        count = sparse.at("count", "a substitution count").integer(minimum=1, below=values.shape[0] + 1)
        indices, substitutes = sparse.at("indices", "an object").mapping(), sparse.at("values", "an object").mapping()
        index_type = _COMPONENTS.get(indices.at("componentType", "a componentType").integer())
        if index_type is None or index_type.kind != "u":
            raise indices.at("componentType").error("an unsigned componentType (5121, 5123 or 5125)")
        at = self._view(indices.at("bufferView", "a bufferView index"), _offset(indices), index_type, 1, count,
                        where=f"{where}.sparse.indices")[:, 0].astype(np.int64)
        if at.size and (at.min() < 0 or at.max() >= values.shape[0]):
            raise self.error(f"{where}.sparse.indices", f"expected indices in [0, {values.shape[0]})")
        values[at] = self._view(substitutes.at("bufferView", "a bufferView index"), _offset(substitutes), dtype, width,
                                count, where=f"{where}.sparse.values")
        return values

    def _view(self, reference: Value, offset: int, dtype: np.dtype, width: int, count: int, *,
              where: str) -> np.ndarray:
        """``count`` elements of ``width`` components from the buffer view ``reference`` names, honouring its stride."""
        view_index, view = self.entry(reference, "bufferViews")
        buffer = view.at("buffer", "a buffer index").index(len(self.buffers), "buffers")
        element = dtype.itemsize * width
        stride_value = view.get("byteStride")
        stride = element if stride_value is None else stride_value.integer(minimum=4, below=253)
        view_offset = _offset(view)
        length = view.at("byteLength", "a byte length").integer(minimum=1)
        start = view_offset + offset
        need = start + (stride * (count - 1) + element if count else 0)
        data = self.buffers[buffer]
        if count and (need > view_offset + length or need > len(data) or stride < element):
            raise self.error(where, f"expected {count} elements of {element} bytes inside bufferViews[{view_index}] "
                                    f"and its buffer, but they end at byte {need} of {len(data)}")
        if not count:
            return np.zeros((0, width), dtype=dtype)
        if stride == element:
            return np.frombuffer(data, dtype=dtype, count=count * width, offset=start).reshape(count, width)
        rows = np.lib.stride_tricks.as_strided(np.frombuffer(data, dtype=np.uint8, offset=start),
                                               shape=(count, element), strides=(stride, 1))
        return np.ascontiguousarray(rows).view(dtype).reshape(count, width)


def _offset(entry: Value) -> int:
    """``entry.byteOffset`` (0 when absent), checked to be a non-negative integer."""
    offset = entry.get("byteOffset")
    return 0 if offset is None else offset.integer(minimum=0)


def _uri_bytes(uri: Value, path: Path) -> tuple[bytes, Path]:
    """The bytes a buffer's or image's ``uri`` names (a base64 data URI or a file beside ``path``) and their source.

    The source is the file read, or ``path`` itself for a data URI.
    """
    text = uri.text(what="a URI string")
    if text.startswith("data:"):
        try:
            return base64.b64decode(text.partition(",")[2], validate=True), path
        except ValueError:
            raise uri.error("a base64 data URI", got=False) from None
    source = path.parent / unquote(text)
    if not is_file(source):
        raise InputError(f"expected the file {source} beside the glTF file, found nothing", file=path, field=uri.key)
    try:
        return source.read_bytes(), source
    except OSError as exc:
        raise InputError(f"expected a readable file beside the glTF file, got {exc.strerror or exc}", file=path,
                         field=uri.key) from None


def _buffer_bytes(buffer: Value, blob: bytes | None, path: Path) -> bytes:
    """The bytes of one ``buffers[i]``: the GLB chunk, a base64 data URI or a file beside ``path``."""
    uri = buffer.mapping().get("uri")
    if uri is None:
        if blob is None:
            raise buffer.error("the GLB binary chunk for a buffer without uri, found none", got=False)
        return blob
    return _uri_bytes(uri, path)[0]


def _glb_chunks(data: bytes, path: Path) -> tuple[str, bytes | None]:
    """The JSON text and the binary chunk (None when absent) of a GLB file's bytes (§4.4)."""
    if len(data) < 20:
        raise InputError("expected a GLB header and a JSON chunk, got a file of only "
                         f"{len(data)} bytes", file=path, field="file")
    _, version, length = struct.unpack_from("<4sII", data)
    if version != 2:
        raise InputError(f"expected a GLB file of version 2, got version {version}", file=path, field="file")
    end, at, chunks = min(length, len(data)), 12, []
    while at + 8 <= end:
        size, kind = struct.unpack_from("<II", data, at)
        if at + 8 + size > end:
            raise InputError(f"expected a GLB chunk of {size} bytes at byte {at}, the file ends at {end}", file=path,
                             field="file")
        chunks.append((kind, data[at + 8:at + 8 + size]))
        at += 8 + size
    if not chunks or chunks[0][0] != _GLB_JSON:
        raise InputError("expected a GLB file whose first chunk is JSON", file=path, field="file")
    try:
        text = chunks[0][1].decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InputError(f"expected a UTF-8 JSON chunk, got {exc.reason}", file=path, field="file") from None
    # Unknown chunk types are skipped, as the specification tells readers to.
    blob = next((chunk for kind, chunk in chunks[1:] if kind == _GLB_BIN), None)
    return text, blob


def read_gltf(file) -> GltfFile:
    """Parse a ``.gltf`` or ``.glb`` file and load its buffers.

    Raises
    ------
    InputError
        Field ``file``: missing, not JSON or not a GLB container, nested too deep; ``asset.version``:
        not glTF 2.0; a top-level key that is not a list; ``buffers[i]``: a buffer that cannot be loaded.
    """
    path = Path(file)
    if not path.is_file():
        raise InputError("expected an existing glTF file, found " + ("a directory" if path.is_dir() else "nothing"),
                         file=path, field="file")
    data = path.read_bytes()
    if data[:4] == _GLB_MAGIC:
        text, blob = _glb_chunks(data, path)
    else:
        try:
            text, blob = data.decode("utf-8-sig"), None
        except UnicodeDecodeError as exc:
            raise InputError(f"expected a glTF 2.0 file (JSON or binary GLB), got undecodable bytes ({exc.reason})",
                             file=path, field="file") from None
    document = json_value(text, file=path).mapping("a glTF 2.0 document (a JSON object)")
    version = document.at("asset", "an object with the glTF version").mapping().at("version", "\"2.0\"")
    if not version.text(what="\"2.0\" (glTF 2.0)").startswith("2."):
        raise version.error("\"2.0\" (glTF 2.0)")
    # Draco and meshopt geometry decoded into plain views and accessors (csmlab.scene.gltf_compression).
    buffers = decompressed(document, lambda i: _buffer_bytes(document.list_at("buffers")[i], blob, path))
    sections = {name: document.list_at(name) for name in SECTIONS if document.has(name)}
    return GltfFile(path=path, document=document, buffers=buffers, sections=sections)


def trs_matrices(translation, rotation, scale) -> np.ndarray:
    """``T · R · S`` matrices ``(N, 4, 4)``: translations ``(N, 3)``, quaternions ``(N, 4)`` (x, y, z, w), scales
    ``(N, 3)``."""
    translation, rotation, scale = (np.asarray(a, dtype=np.float64) for a in (translation, rotation, scale))
    out = np.zeros((translation.shape[0], 4, 4))
    out[:, :3, :3] = quat_to_matrix(rotation) * scale[:, None, :]
    out[:, :3, 3] = translation
    out[:, 3, 3] = 1.0
    return out


def node_quaternion(gltf: GltfFile, index: int) -> np.ndarray:
    """``nodes[index].rotation`` ``(4,)``, checked to be a unit quaternion and normalised."""
    rotation = gltf.section("nodes")[index].get("rotation")
    if rotation is None:
        return np.array([0.0, 0.0, 0.0, 1.0])
    q = rotation.numbers(4, what="a unit quaternion (x, y, z, w)")
    if abs(np.linalg.norm(q) - 1.0) > UNIT_TOLERANCE:
        raise rotation.error("a unit quaternion (x, y, z, w)")
    return q / np.linalg.norm(q)


def local_matrix(gltf: GltfFile, index: int) -> np.ndarray:
    """``nodes[index]``'s local matrix ``(4, 4)``: its ``matrix`` (column-major) or ``T · R · S``."""
    node = gltf.section("nodes")[index]
    if node.has("matrix"):
        return node.at("matrix").numbers(16, what="16 finite numbers").reshape(4, 4).T
    translation, scale = node.get("translation"), node.get("scale")
    translation = np.zeros(3) if translation is None else translation.numbers(3, what="3 finite numbers")
    scale = np.ones(3) if scale is None else scale.numbers(3, what="3 finite numbers")
    return trs_matrices(translation[None], node_quaternion(gltf, index)[None], scale[None])[0]


def scene_roots(gltf: GltfFile) -> list[int]:
    """Root node indices of the file's default scene (``scene``, else ``scenes[0]``, else every parentless node)."""
    nodes = gltf.section("nodes")
    count = len(nodes)
    scenes = gltf.section("scenes")
    if scenes:
        chosen = gltf.document.get("scene")
        scene = scenes[0] if chosen is None else scenes[chosen.index(len(scenes), "scenes")]
        roots = scene.mapping().list_at("nodes")
    else:
        children = {c for node in nodes for c in _children(node.mapping(), count)}
        return [i for i in range(count) if i not in children]
    return [root.index(count, "nodes") for root in roots]


def _children(node: Value, count: int) -> list[int]:
    """``node.children``, each checked to be a node index in ``[0, count)``."""
    return [child.index(count, "nodes") for child in node.list_at("children")]


def scene_nodes(gltf: GltfFile) -> list[tuple[int, int | None]]:
    """``(node, parent)`` of every node of the default scene, parents before children (depth first).

    Raises
    ------
    InputError
        On a child index out of range or a node reached twice (a cycle or a shared child: the
        specification requires a strict tree).
    """
    nodes = gltf.section("nodes")
    order, seen = [], set()
    stack = [(root, None) for root in reversed(scene_roots(gltf))]
    while stack:
        index, parent = stack.pop()
        if index in seen:
            raise gltf.error(f"nodes[{index}]", "expected each node once in the scene's tree, found it twice "
                                                "(a cycle or a node with two parents)")
        seen.add(index)
        order.append((index, parent))
        stack.extend((child, index) for child in reversed(_children(nodes[index].mapping(), len(nodes))))
    return order


def world_matrices(gltf: GltfFile) -> dict[int, np.ndarray]:
    """World matrix ``(4, 4)`` of every node of the default scene, by node index (file units, file axes)."""
    world: dict[int, np.ndarray] = {}
    for index, parent in scene_nodes(gltf):
        local = local_matrix(gltf, index)
        world[index] = local if parent is None else world[parent] @ local
    return world


def _extension(entry: Value, name: str) -> Value | None:
    """``entry.extensions[name]`` (an object), or None when the entry does not use the extension."""
    extensions = entry.get("extensions")
    return None if extensions is None else extensions.mapping().get(name)


def _instance_matrices(gltf: GltfFile, index: int) -> np.ndarray:
    """``T · R · S`` ``(I, 4, 4)`` of ``nodes[index]``'s ``EXT_mesh_gpu_instancing`` instances; identity ``(1, 4, 4)``
    without."""
    extension = _extension(gltf.section("nodes")[index], INSTANCING)
    if extension is None:
        return np.eye(4)[None]
    attributes = extension.mapping().at("attributes", "TRANSLATION, ROTATION and/or SCALE accessors").mapping()
    key = attributes.key
    widths = {"TRANSLATION": 3, "ROTATION": 4, "SCALE": 3}
    arrays = {name: gltf.accessor(attributes.at(name)) for name in widths if attributes.has(name)}
    if not arrays:
        raise attributes.error("TRANSLATION, ROTATION and/or SCALE accessors")
    counts = {a.shape[0] for a in arrays.values()}
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
    colour_material : int
        The primitive's material, −1 without one (it keeps :func:`~csmlab.scene.mesh.load_mesh`'s ``albedo``).
    colour_uv : ndarray, shape (V, 2), float64, or None
        Where its ``baseColorTexture`` is sampled (None without a texture).
    """

    points: np.ndarray
    triangles: np.ndarray
    material: int
    uv: np.ndarray | None
    colour_material: int = -1
    colour_uv: np.ndarray | None = None


def _primitive(gltf: GltfFile, mesh: Value, p: int) -> _Primitive | None:
    """``mesh.primitives[p]`` with its ``MASK`` material's coordinates; None for points, lines."""
    primitive = mesh.at("primitives", "a list of primitives").items()[p].mapping()
    key = primitive.key
    mode_value = primitive.get("mode")
    mode = 4 if mode_value is None else mode_value.integer(minimum=0, below=7, what="a primitive mode in [0, 6]")
    if mode not in (4, 5, 6):
        return None
    attributes = primitive.at("attributes", "an object of vertex attributes").mapping()
    points = gltf.accessor(attributes.at("POSITION", "a POSITION attribute"))
    if points.shape[1] != 3:
        raise gltf.error(f"{key}.attributes.POSITION", f"expected VEC3 positions, got {points.shape[1]} components")
    if not primitive.has("indices"):
        indices = np.arange(points.shape[0], dtype=np.int64)
    else:
        indices = gltf.accessor(primitive.at("indices"))[:, 0].astype(np.int64)
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
    material = _masked_material(gltf, primitive.get("material"))
    colour_material = -1 if not primitive.has("material") else gltf.entry(primitive.at("material"), "materials")[0]
    colour_uv = None
    if colour_material >= 0 and _base_colour_texture(gltf, colour_material) is not None:
        colour_uv = _mask_coordinates(gltf, attributes, colour_material, points.shape[0])
    if material < 0:
        return _Primitive(points, triangles, -1, None, colour_material, colour_uv)
    return _Primitive(points, triangles, material, _mask_coordinates(gltf, attributes, material, points.shape[0]),
                      colour_material, colour_uv)


def _masked_material(gltf: GltfFile, reference: Value | None) -> int:
    """The index of the material ``reference`` names if its ``alphaMode`` is ``"MASK"``, else −1 (none, opaque,
    blend)."""
    if reference is None:
        return -1
    index, material = gltf.entry(reference, "materials")
    mode = material.get("alphaMode")
    return index if mode is not None and mode.text(("OPAQUE", "MASK", "BLEND")) == "MASK" else -1


def _base_colour_texture(gltf: GltfFile, material: int) -> Value | None:
    """``materials[material].pbrMetallicRoughness.baseColorTexture`` (a textureInfo object), or None."""
    pbr = gltf.section("materials")[material].get("pbrMetallicRoughness")
    texture = None if pbr is None else pbr.mapping().get("baseColorTexture")
    return None if texture is None else texture.mapping()


def _mask_coordinates(gltf: GltfFile, attributes: Value, material: int, count: int) -> np.ndarray:
    """The ``TEXCOORD_n`` ``(count, 2)`` a material's base colour texture is sampled at (zeros without one)."""
    texture = _base_colour_texture(gltf, material)
    if texture is None:
        return np.zeros((count, 2))
    name = f"TEXCOORD_{texture_coordinate_set(texture)}"
    if not attributes.has(name):
        raise attributes.error(f"{name}, the coordinates of materials[{material}]'s baseColorTexture, "
                               f"found none", got=False)
    uv = gltf.accessor(attributes.at(name))
    if uv.shape != (count, 2):
        raise gltf.error(f"{attributes.key}.{name}", f"expected {count} VEC2 coordinates (one per POSITION), "
                                                     f"got shape {uv.shape}")
    return transformed_uv(uv, texture)  # KHR_texture_transform (csmlab.scene.gltf_materials)


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
    entry = gltf.section("materials")[material]
    key = f"materials[{material}]"
    cutoff_value = entry.get("alphaCutoff")
    cutoff = DEFAULT_ALPHA_CUTOFF if cutoff_value is None else cutoff_value.number(
        above=0.0, maximum=1.0, what="a number in (0, 1] (csmlab cuts where coverage ≥ it)")
    pbr = entry.get("pbrMetallicRoughness")
    factor_value = None if pbr is None else pbr.mapping().get("baseColorFactor")
    factor = np.ones(4) if factor_value is None else factor_value.numbers(4, what="4 numbers in [0, 1]")
    if not np.all((factor >= 0.0) & (factor <= 1.0)):
        raise factor_value.error("4 numbers in [0, 1]")
    texture = _base_colour_texture(gltf, material)
    if texture is None:
        return AlphaMask(np.full((1, 1), factor[3], np.float32), float(cutoff), source=f"{gltf.path} {key}")
    data, source, image_key = _texture_image(gltf, texture.at("index", "a texture index"))
    mask = alpha_mask_of_image(data, cutoff=float(cutoff), source=source, field=image_key)
    return AlphaMask(mask.alpha * np.float32(factor[3]), float(cutoff), source=mask.source)


def _texture_image(gltf: GltfFile, reference: Value) -> tuple[bytes, Path, str]:
    """The encoded image of the texture ``reference`` names: its bytes, the file they came from, the image's key."""
    _, texture = gltf.entry(reference, "textures")
    image, entry = gltf.entry(texture.at("source", "an image index"), "images")
    image_key = f"images[{image}]"
    if entry.has("uri"):
        data, source = _uri_bytes(entry.at("uri"), gltf.path)
        return data, source, image_key
    view = entry.at("bufferView", "a uri or a bufferView index")
    _, view_entry = gltf.entry(view, "bufferViews")
    length = view_entry.at("byteLength", "a byte length").integer(minimum=1)
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
        material drawn, by material index), with ``mask_materials`` (the material of each mask).

    Raises
    ------
    InputError
        On a broken reference, accessor or mask image (naming its glTF key), a scene with no
        triangle, or more than :data:`~csmlab.documents.MAX_TRIANGLES` triangles placed.
    """
    world = world_matrices(gltf)
    cache: dict[int, list[_Primitive]] = {}
    placed_nodes, total = [], 0
    for index, matrix in world.items():
        node = gltf.section("nodes")[index]
        if not node.has("mesh"):
            continue
        mesh, entry = gltf.entry(node.at("mesh"), "meshes")
        if mesh not in cache:
            primitives = entry.at("primitives", "a list of primitives").items()
            cache[mesh] = [part for p in range(len(primitives)) if (part := _primitive(gltf, entry, p)) is not None]
        placements = matrix @ _instance_matrices(gltf, index)
        total += placements.shape[0] * sum(part.triangles.shape[0] for part in cache[mesh])
        within_limit(total, MAX_TRIANGLES, what="triangles in the scene (instances counted)", file=gltf.path,
                     field=f"nodes[{index}]")
        placed_nodes.append((cache[mesh], placements))
    if total == 0:
        raise gltf.error("meshes", "expected at least one triangle primitive on a node of the scene, found none")
    points_out, triangles_out, parts, offset = [], [], [], 0
    for primitives, placements in placed_nodes:
        mirrored = np.linalg.det(placements[:, :3, :3]) < 0
        for part in primitives:
            # (I, V, 3): every instance's copy of the points; a batched matmul, several times einsum's speed.
            placed = np.matmul(part.points, placements[:, :3, :3].transpose(0, 2, 1)) + placements[:, None, :3, 3]
            wound = np.where(mirrored[:, None, None], part.triangles[None, :, ::-1], part.triangles[None])
            shift = offset + part.points.shape[0] * np.arange(placements.shape[0])
            points_out.append(placed.reshape(-1, 3))
            triangles_out.append((wound + shift[:, None, None]).reshape(-1, 3))
            parts.append((part, placements.shape[0]))
            offset += placed.shape[0] * placed.shape[1]
    return np.concatenate(points_out), np.concatenate(triangles_out), {**_scene_masks(gltf, parts),
                                                                       **_scene_colour(gltf, parts)}


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
                alpha=tuple(material_mask(gltf, material) for material in used), mask_materials=used)


def _scene_colour(gltf: GltfFile, parts: list[tuple[_Primitive, int]]) -> dict:
    """``base_colour`` ``(T, 3)`` (NaN where a primitive has no material) and ``colour``
    (:class:`~csmlab.scene.core.ColourTextures`) of the placed primitives, in output order; empty
    when no primitive has a material."""
    if all(part.colour_material < 0 for part, _ in parts):
        return {}
    textured = sorted({part.colour_material for part, _ in parts if part.colour_uv is not None})
    factors, uv, index = [], [], []
    for part, instances in parts:
        count = part.points.shape[0] * instances
        factor = (np.full(3, np.nan) if part.colour_material < 0
                  else _base_colour_factor(gltf, part.colour_material)[:3])
        factors.append(np.tile(factor, (part.triangles.shape[0] * instances, 1)))
        if part.colour_uv is None:
            uv.append(np.zeros((count, 2)))
            index.append(np.full(count, -1, np.int32))
        else:
            uv.append(np.tile(part.colour_uv, (instances, 1)))
            index.append(np.full(count, textured.index(part.colour_material), np.int32))
    textures = tuple(_colour_texture(gltf, material) for material in textured)
    colour = ColourTextures(np.concatenate(uv), np.concatenate(index), textures) if textures else None
    return dict(base_colour=np.concatenate(factors), colour=colour)


def _base_colour_factor(gltf: GltfFile, material: int) -> np.ndarray:
    """``materials[material].pbrMetallicRoughness.baseColorFactor`` ``(4,)``: linear RGBA in [0, 1], ones without
    one."""
    pbr = gltf.section("materials")[material].get("pbrMetallicRoughness")
    factor_value = None if pbr is None else pbr.mapping().get("baseColorFactor")
    factor = np.ones(4) if factor_value is None else factor_value.numbers(4, what="4 numbers in [0, 1]")
    if not np.all((factor >= 0.0) & (factor <= 1.0)):
        raise factor_value.error("4 numbers in [0, 1]")
    return factor


def _colour_texture(gltf: GltfFile, material: int) -> ColourTexture:
    """The :class:`~csmlab.scene.core.ColourTexture` of ``materials[material]``'s ``baseColorTexture``."""
    texture = _base_colour_texture(gltf, material)
    data, source, image_key = _texture_image(gltf, texture.at("index", "a texture index"))
    return colour_texture_of_image(data, source=source, field=image_key)


@dataclass(frozen=True)
class Sun:
    """A ``KHR_lights_punctual`` directional light of a glTF scene.

    Attributes
    ----------
    direction : ndarray, shape (3,), float64
        Unit vector from the light toward the scene, in the file's axes (its node's world −Z).
    name : str
        The light's name (its node's when the light has none).
    colour : ndarray, shape (3,), float64
        The light's ``color``, linear RGB in [0, 1] (white without one). Its ``intensity`` (lux) is
        not read: csmlab's shading is in units of the sun's irradiance.
    """

    direction: np.ndarray
    name: str
    colour: np.ndarray = field(default_factory=lambda: np.ones(3))


def sun_of(gltf: GltfFile) -> Sun:
    """The one directional ``KHR_lights_punctual`` light placed on a node of the default scene.

    Raises
    ------
    InputError
        Field ``KHR_lights_punctual``: no directional light on a node of the scene, or more than one
        (their names listed); ``nodes[i].extensions.KHR_lights_punctual.light``: a bad light index;
        ``extensions.KHR_lights_punctual.lights[j]``: a light that is not an object with a type.
    """
    document_lights = _extension(gltf.document, LIGHTS)
    lights = [] if document_lights is None else document_lights.mapping().list_at("lights")
    found = []
    for index, matrix in world_matrices(gltf).items():
        node = gltf.section("nodes")[index]
        extension = _extension(node, LIGHTS)
        if extension is None:
            continue
        light = lights[extension.mapping().at("light", "a light index").index(len(lights), "lights")].mapping()
        if light.at("type", "a light type").text(what="a light type (a string)") != "directional":
            continue
        axis = -matrix[:3, 2]
        length = float(np.linalg.norm(axis))
        if not math.isfinite(length) or length < 1e-12:
            raise gltf.error(f"nodes[{index}]", "expected a directional light's node to have a non-degenerate "
                                                "world transform, its −Z axis has zero length")
        colour_value = light.get("color")
        colour = np.ones(3) if colour_value is None else colour_value.numbers(3, what="3 linear RGB numbers in [0, 1]")
        if not np.all((colour >= 0.0) & (colour <= 1.0)):
            raise colour_value.error("3 linear RGB numbers in [0, 1]")
        found.append(Sun(direction=axis / length, name=_name(light) or _name(node) or f"nodes[{index}]", colour=colour))
    if len(found) != 1:
        names = ", ".join(s.name for s in found)
        raise gltf.error(LIGHTS, "expected one directional light on a node of the scene, found "
                                 + (f"{len(found)}: {names}" if found else "none"))
    return found[0]


def _name(entry: Value) -> str:
    """``entry.name`` (a string), or ``""`` when it has none."""
    name = entry.get("name")
    return "" if name is None else name.text()
