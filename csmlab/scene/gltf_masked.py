"""glTF 2.0 with alpha-masked materials, read by csmlab itself: VTK's reader keeps no material.

A glTF file any of whose materials has ``alphaMode = "MASK"`` is read here instead of through VTK
(:func:`csmlab.scene.mesh.load_mesh` asks :func:`has_masked_materials`; :mod:`csmlab.scene.gltf` reads every other glTF level): the default scene's nodes,
their transforms (``matrix``, or ``translation``/``rotation``/``scale``) applied down the hierarchy,
every triangle primitive (``mode`` 4) of their meshes. A ``MASK`` material's coverage is its base
colour's alpha — ``baseColorFactor[3]`` times the ``baseColorTexture``'s alpha channel, read with
Pillow — tested against its ``alphaCutoff`` (0.5 by default), at the primitive's ``TEXCOORD_n``
(glTF's v already runs down the image, as :class:`~csmlab.scene.core.AlphaMask` does). Primitives
do not share vertices, so each masked triangle's vertices carry its mask alone. Buffers and images
come from files beside the ``.gltf``, ``data:`` URIs or a ``.glb``'s binary chunk.

Anything else a mesh may hold (sparse accessors, strips, fans, lines, points, skins, morph targets)
is bad input here, with an :class:`~csmlab.errors.InputError` naming the file and the field.
"""

from __future__ import annotations

import base64
import json
import struct
from pathlib import Path

import numpy as np

from csmlab.errors import InputError
from csmlab.scene.alpha_files import alpha_mask_of_image
from csmlab.scene.core import AlphaMask

__all__ = ["has_masked_materials", "read_masked_gltf"]

_COMPONENTS = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}


def _document(path: Path) -> tuple[dict, bytes | None]:
    """The glTF JSON and, for a ``.glb``, its binary chunk."""
    raw = path.read_bytes()
    if raw[:4] == b"glTF":
        if len(raw) < 20:
            raise InputError("expected a binary glTF with a JSON chunk", file=path, field="file")
        length, kind = struct.unpack_from("<II", raw, 12)
        if kind != 0x4E4F534A:
            raise InputError("expected the binary glTF's first chunk to be JSON", file=path, field="file")
        text = raw[20:20 + length]
        binary = None
        at = 20 + length
        if at + 8 <= len(raw):
            size, kind = struct.unpack_from("<II", raw, at)
            if kind == 0x004E4942:
                binary = raw[at + 8:at + 8 + size]
    else:
        text, binary = raw, None
    try:
        return json.loads(text), binary
    except (ValueError, UnicodeDecodeError) as exc:
        raise InputError(f"expected glTF JSON, parsing failed: {exc}", file=path, field="file") from None


def has_masked_materials(file) -> bool:
    """Whether a ``.gltf``/``.glb`` file has a material with ``alphaMode = "MASK"`` (False if it cannot be parsed:
    VTK's reader then reports the file)."""
    try:
        gltf, _ = _document(Path(file))
    except (InputError, OSError):
        return False
    return any(m.get("alphaMode") == "MASK" for m in gltf.get("materials", []))


def _uri_bytes(uri: str, path: Path, field: str) -> bytes:
    if uri.startswith("data:"):
        try:
            return base64.b64decode(uri.split(",", 1)[1])
        except (IndexError, ValueError) as exc:
            raise InputError(f"expected a base64 data URI, decoding failed: {exc}", file=path, field=field) from None
    target = path.parent / uri
    try:
        return target.read_bytes()
    except OSError as exc:
        raise InputError(f"expected a readable file, got {exc.strerror or exc}", file=target, field=field) from None


class _Reader:
    """Accessors, buffers and images of one glTF document."""

    def __init__(self, path: Path):
        self.path = path
        self.gltf, self.binary = _document(path)
        self.buffers: dict[int, bytes] = {}

    def buffer(self, index: int) -> bytes:
        if index not in self.buffers:
            entry = self.gltf["buffers"][index]
            if "uri" in entry:
                self.buffers[index] = _uri_bytes(entry["uri"], self.path, "buffers")
            elif self.binary is not None:
                self.buffers[index] = self.binary
            else:
                raise InputError(f"expected buffer {index} to have a uri or a binary chunk", file=self.path,
                                 field="buffers")
        return self.buffers[index]

    def view_bytes(self, index: int) -> tuple[bytes, int, int | None]:
        view = self.gltf["bufferViews"][index]
        return self.buffer(view["buffer"]), view.get("byteOffset", 0), view.get("byteStride")

    def accessor(self, index: int) -> np.ndarray:
        """Accessor ``index`` as ``(count, width)`` float64 (normalized integers scaled to [0, 1])."""
        acc = self.gltf["accessors"][index]
        if "sparse" in acc or "bufferView" not in acc:
            raise InputError(f"expected accessor {index} in a buffer view (sparse accessors are not read)",
                             file=self.path, field="accessors")
        dtype = np.dtype(_COMPONENTS[acc["componentType"]]).newbyteorder("<")
        width = _WIDTH[acc["type"]]
        data, offset, stride = self.view_bytes(acc["bufferView"])
        offset += acc.get("byteOffset", 0)
        count = acc["count"]
        item = dtype.itemsize * width
        stride = stride or item
        rows = np.ndarray((count, width), dtype=dtype, buffer=data, offset=offset, strides=(stride, dtype.itemsize))
        out = rows.astype(np.float64)
        if acc.get("normalized") and dtype.kind in "iu":
            out /= float(np.iinfo(dtype).max)
        return out

    def base_colour_alpha(self, material: dict, index: int) -> AlphaMask:
        """The :class:`AlphaMask` of a ``MASK`` material: its base colour's alpha and ``alphaCutoff``."""
        pbr = material.get("pbrMetallicRoughness", {})
        factor = float(pbr.get("baseColorFactor", [1.0, 1.0, 1.0, 1.0])[3])
        cutoff = float(material.get("alphaCutoff", 0.5))
        texture = pbr.get("baseColorTexture")
        if texture is None:
            return AlphaMask(np.full((1, 1), factor, np.float32), cutoff, source=f"{self.path} material {index}")
        image = self.gltf["images"][self.gltf["textures"][texture["index"]]["source"]]
        if "uri" in image and not image["uri"].startswith("data:"):
            source = self.path.parent / image["uri"]
            data = _uri_bytes(image["uri"], self.path, "images")
        elif "uri" in image:
            source, data = self.path, _uri_bytes(image["uri"], self.path, "images")
        else:
            raw, offset, _ = self.view_bytes(image["bufferView"])
            length = self.gltf["bufferViews"][image["bufferView"]]["byteLength"]
            source, data = self.path, raw[offset:offset + length]
        mask = alpha_mask_of_image(data, cutoff=cutoff, source=source, field="images")
        return AlphaMask(mask.alpha * np.float32(factor), cutoff, source=mask.source)


def _local(node: dict) -> np.ndarray:
    if "matrix" in node:
        return np.asarray(node["matrix"], dtype=np.float64).reshape(4, 4).T
    x, y, z, w = node.get("rotation", [0.0, 0.0, 0.0, 1.0])
    rotation = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                         [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                         [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    out = np.eye(4)
    out[:3, :3] = rotation * np.asarray(node.get("scale", [1.0, 1.0, 1.0]), dtype=np.float64)[None, :]
    out[:3, 3] = node.get("translation", [0.0, 0.0, 0.0])
    return out


def read_masked_gltf(file) -> tuple[np.ndarray, np.ndarray, dict]:
    """Vertices ``(V, 3)``, triangles ``(T, 3)`` and ``dict(uv, vertex_mask, alpha)`` of a glTF with masked materials.

    Raises
    ------
    InputError
        Naming the file (or the image or buffer file) and the glTF field it could not read.
    """
    path = Path(file)
    reader = _Reader(path)
    gltf = reader.gltf
    try:
        materials = gltf.get("materials", [])
        masked = [k for k, m in enumerate(materials) if m.get("alphaMode") == "MASK"]
        masks = tuple(reader.base_colour_alpha(materials[k], k) for k in masked)
        scenes = gltf.get("scenes", [{"nodes": list(range(len(gltf.get("nodes", []))))}])
        roots = scenes[gltf.get("scene", 0)].get("nodes", [])
        vertices, triangles, uv, vertex_mask = [], [], [], []
        count = 0
        stack = [(node, np.eye(4)) for node in roots]
        while stack:
            node_index, parent = stack.pop(0)
            node = gltf["nodes"][node_index]
            world = parent @ _local(node)
            stack.extend((child, world) for child in node.get("children", []))
            if "mesh" not in node:
                continue
            for primitive in gltf["meshes"][node["mesh"]]["primitives"]:
                if primitive.get("mode", 4) != 4:
                    raise InputError(f"expected triangle primitives (mode 4) in a file with alpha-masked materials, "
                                     f"got mode {primitive['mode']}", file=path, field="meshes")
                points = reader.accessor(primitive["attributes"]["POSITION"])
                points = points @ world[:3, :3].T + world[:3, 3]
                indices = (reader.accessor(primitive["indices"])[:, 0].astype(np.int64) if "indices" in primitive
                           else np.arange(points.shape[0]))
                material = primitive.get("material", -1)
                mask = masked.index(material) if material in masked else -1
                coordinates = np.zeros((points.shape[0], 2))
                if mask >= 0:
                    texture = materials[material].get("pbrMetallicRoughness", {}).get("baseColorTexture", {})
                    name = f"TEXCOORD_{texture.get('texCoord', 0)}"
                    if name in primitive["attributes"]:
                        coordinates = reader.accessor(primitive["attributes"][name])
                    elif texture:
                        raise InputError(f"expected {name} on the primitives of alpha-masked material {material}",
                                         file=path, field="meshes")
                vertices.append(points)
                triangles.append(indices.reshape(-1, 3) + count)
                uv.append(coordinates)
                vertex_mask.append(np.full(points.shape[0], mask, dtype=np.int32))
                count += points.shape[0]
    except (KeyError, IndexError, TypeError, ValueError) as exc:
        if isinstance(exc, InputError):
            raise
        raise InputError(f"expected a glTF 2.0 document csmlab can follow, failed at {exc!r}", file=path,
                         field="file") from None
    if not vertices:
        raise InputError("expected at least one mesh primitive in the default scene", file=path, field="meshes")
    return (np.concatenate(vertices), np.concatenate(triangles),
            dict(uv=np.concatenate(uv), vertex_mask=np.concatenate(vertex_mask), alpha=masks))
