"""Compressed glTF geometry, decoded by the libraries made for it before the reader sees the file.

Engines' exporters and ``gltfpack``/``gltf-transform`` ship levels compressed by one of two
extensions; a reader that ignores them finds accessors with no data (every triangle degenerate).
:func:`decompressed` decodes both into plain buffer views and accessors and removes the extension,
so :mod:`csmlab.scene.gltf` reads the result as any other file:

* ``KHR_draco_mesh_compression`` (a primitive's attributes and indices in one Draco stream) through
  `DracoPy <https://pypi.org/project/DracoPy/>`_, Google Draco's Python binding: each attribute is
  taken by the unique id the extension names and written in its accessor's component type;
* ``EXT_meshopt_compression`` (a buffer view's bytes as meshoptimizer's vertex or index codec, with
  the octahedral, quaternion or exponential filter) through
  `meshoptimizer <https://pypi.org/project/meshoptimizer/>`_, the Python binding of
  meshoptimizer's own decoder; a buffer marked ``fallback`` holds no data and is not loaded.

A file that needs a decoder that is not installed stops with an
:class:`~csmlab.errors.InputError` naming the extension and the package; a stream the decoder
refuses names the primitive or buffer view.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable

import numpy as np

from csmlab.documents import Value
from csmlab.errors import InputError

__all__ = ["DRACO", "MESHOPT", "decompressed"]

DRACO = "KHR_draco_mesh_compression"
MESHOPT = "EXT_meshopt_compression"

_COMPONENT_DTYPES = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32,
                     5126: np.float32}
"""glTF ``componentType`` → NumPy dtype (§3.6.2.2)."""
_UNSIGNED_INT = 5125
_WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}


def _extension(entry: Value, name: str) -> Value | None:
    extensions = entry.get("extensions")
    return None if extensions is None else extensions.mapping().get(name)


def _fallback(buffer: Value) -> bool:
    extension = _extension(buffer.mapping(), MESHOPT)
    flag = None if extension is None else extension.mapping().get("fallback")
    return flag is not None and flag.boolean()


def decompressed(document: Value, buffer_bytes: Callable[[int], bytes]) -> tuple[bytes, ...]:
    """Every buffer's bytes, after decoding ``document``'s Draco primitives and meshopt buffer views into plain ones.

    Parameters
    ----------
    document : csmlab.documents.Value
        The parsed file (a JSON object); its raw JSON is changed in place: decoded data go to new
        buffers, views and accessors appended to it, and the extensions are removed.
    buffer_bytes : callable
        ``buffer_bytes(i)``: the bytes of ``buffers[i]`` (called for every buffer but meshopt fallbacks).

    Returns
    -------
    tuple of bytes
        Every buffer's bytes (empty for a fallback buffer), the decoded ones last.

    Raises
    ------
    InputError
        A decoder that is not installed (naming the extension and the package), a stream it cannot
        decode (naming the primitive or buffer view), or a malformed extension object (naming its key).
    """
    buffers = [b"" if _fallback(b) else buffer_bytes(i) for i, b in enumerate(document.list_at("buffers"))]
    views = document.list_at("bufferViews")
    if any(_extension(view.mapping(), MESHOPT) is not None for view in views):
        _decode_meshopt(document, buffers)
    primitives = [primitive.mapping() for mesh in document.list_at("meshes")
                  for primitive in mesh.mapping().list_at("primitives")
                  if _extension(primitive.mapping(), DRACO) is not None]
    if primitives:
        _decode_draco(document, buffers, primitives)
    return tuple(buffers)


def _required(module: str, extension: str, document: Value):
    try:
        return importlib.import_module(module)
    except ImportError:
        raise InputError(f"expected the {module} package to decode {extension} (pip install {module}); it is not "
                         "installed", file=document.file, field=f"extensionsUsed.{extension}") from None


def _view_bytes(document: Value, buffers: list, reference: Value) -> bytes:
    views = document.list_at("bufferViews")
    view = views[reference.index(len(views), "bufferViews")].mapping()
    source = view.at("buffer", "a buffer index").index(len(buffers), "buffers")
    start = 0 if view.get("byteOffset") is None else view.at("byteOffset").integer(minimum=0)
    length = view.at("byteLength", "a byte length").integer(minimum=1)
    if start + length > len(buffers[source]):
        raise view.error(f"{length} bytes at {start} of buffers[{source}], which holds {len(buffers[source])}",
                         got=False)
    return buffers[source][start:start + length]


def _append(document: Value, buffers: list, data: bytes, *, stride: int | None = None) -> int:
    """A new buffer holding ``data`` and a buffer view over all of it; returns the view's index."""
    raw = document.raw
    buffers.append(bytes(data))
    raw.setdefault("buffers", []).append({"byteLength": len(data)})
    view = {"buffer": len(buffers) - 1, "byteOffset": 0, "byteLength": len(data)}
    if stride is not None:
        view["byteStride"] = stride
    raw.setdefault("bufferViews", []).append(view)
    return len(raw["bufferViews"]) - 1


# --- KHR_draco_mesh_compression ---------------------------------------------------------------------


def _decode_draco(document: Value, buffers: list, primitives: list[Value]) -> None:
    draco = _required("DracoPy", DRACO, document)
    for primitive in primitives:
        extension = _extension(primitive, DRACO).mapping()
        try:
            mesh = draco.decode(_view_bytes(document, buffers, extension.at("bufferView", "a bufferView index")))
        except InputError:
            raise
        except Exception as exc:  # DracoPy raises its own and ValueError/RuntimeError on a bad stream.
            raise InputError(f"expected a Draco mesh stream that DracoPy decodes; it failed: {exc}",
                             file=document.file, field=f"{extension.key}.bufferView") from None
        attributes = primitive.at("attributes", "an object of accessor indices").mapping()
        for name, unique_id in extension.at("attributes", "an object of Draco attribute ids").mapping().fields():
            decoded = mesh.get_attribute_by_unique_id(unique_id.integer(minimum=0))
            if decoded is None or not attributes.has(name):
                raise unique_id.error(f"attribute {name} in the Draco stream and in the primitive's attributes")
            attributes.raw[name] = _new_accessor(document, buffers, attributes.at(name), decoded["data"])
        faces = np.asarray(mesh.faces, dtype=np.uint32).reshape(-1, 1)
        primitive.raw["indices"] = _new_accessor(document, buffers, None, faces, component=_UNSIGNED_INT,
                                                 kind="SCALAR")
        del primitive.raw["extensions"][DRACO]


def _new_accessor(document: Value, buffers: list, original: Value | None, values, *, component: int | None = None,
                  kind: str | None = None) -> int:
    """A new accessor over ``values`` ``(N, k)``, typed as the ``original`` accessor it replaces (or as given)."""
    accessors = document.list_at("accessors")
    old = {} if original is None else accessors[original.index(len(accessors), "accessors")].mapping().raw
    component = old.get("componentType") if component is None else component
    kind = old.get("type") if kind is None else kind
    if component not in _COMPONENT_DTYPES or kind not in _WIDTHS:
        raise (original or document).error("an accessor of a componentType and a SCALAR or VECn type to decode into")
    values = np.asarray(values)
    packed = np.ascontiguousarray(values.reshape(values.shape[0], -1).astype(_COMPONENT_DTYPES[component]))
    element = packed.dtype.itemsize * packed.shape[1]
    # Vertex attributes' elements are aligned to 4 bytes (§3.6.2.4): pad each row.
    row = element if kind == "SCALAR" else -(-element // 4) * 4
    raw = np.zeros((packed.shape[0], row), dtype=np.uint8)
    raw[:, :element] = packed.view(np.uint8).reshape(packed.shape[0], element)
    view = _append(document, buffers, raw.tobytes(), stride=row if row != element else None)
    accessor = {"bufferView": view, "componentType": component, "type": kind, "count": int(packed.shape[0])}
    accessor.update({key: old[key] for key in ("normalized", "min", "max") if key in old and kind != "SCALAR"})
    document.raw.setdefault("accessors", []).append(accessor)
    return len(document.raw["accessors"]) - 1


# --- EXT_meshopt_compression ------------------------------------------------------------------------


def _decode_meshopt(document: Value, buffers: list) -> None:
    codec = _required("meshoptimizer", MESHOPT, document)
    for view in document.list_at("bufferViews"):
        extension = _extension(view.mapping(), MESHOPT)
        if extension is None:
            continue
        extension = extension.mapping()
        source = extension.at("buffer", "a buffer index").index(len(buffers), "buffers")
        if _fallback(document.list_at("buffers")[source]):
            raise extension.at("buffer").error("a buffer holding the compressed data, not a fallback")
        start = 0 if extension.get("byteOffset") is None else extension.at("byteOffset").integer(minimum=0)
        length = extension.at("byteLength", "a byte length").integer(minimum=1)
        count = extension.at("count", "an element count").integer(minimum=0)
        stride = extension.at("byteStride", "a byte stride").integer(minimum=1, below=257)
        mode = extension.at("mode", "ATTRIBUTES, TRIANGLES or INDICES").text(("ATTRIBUTES", "TRIANGLES", "INDICES"))
        filter_ = "NONE" if extension.get("filter") is None else extension.at("filter").text(("NONE", *_FILTERS))
        try:
            decoded = _meshopt_bytes(codec, buffers[source][start:start + length], count=count, stride=stride,
                                     mode=mode, filter_=filter_)
        except (RuntimeError, ValueError, TypeError) as exc:
            raise InputError(f"expected a meshopt {mode} stream of {count} × {stride} bytes that meshoptimizer "
                             f"decodes; it failed: {exc}", file=document.file, field=extension.key) from None
        buffers.append(decoded)
        document.raw.setdefault("buffers", []).append({"byteLength": len(decoded)})
        view.raw.update({"buffer": len(buffers) - 1, "byteOffset": 0, "byteLength": len(decoded)})
        del view.raw["extensions"][MESHOPT]


_FILTERS = {"OCTAHEDRAL": "decode_filter_oct", "QUATERNION": "decode_filter_quat", "EXPONENTIAL": "decode_filter_exp"}
"""meshopt filters (the extension's ``filter``) → meshoptimizer's decoding function."""


def _meshopt_bytes(codec, stream: bytes, *, count: int, stride: int, mode: str, filter_: str) -> bytes:
    """The ``count × stride`` bytes a meshopt stream decodes to (ATTRIBUTES, TRIANGLES or INDICES, then its filter)."""
    if mode == "ATTRIBUTES":
        raw = codec.decode_vertex_buffer(count, stride, stream).view(np.uint8).reshape(-1)
    else:
        decode = codec.decode_index_buffer if mode == "TRIANGLES" else codec.decode_index_sequence
        raw = decode(count, stride, stream).view(np.uint8).reshape(-1)[:count * stride]
    if filter_ != "NONE":
        if mode != "ATTRIBUTES":
            raise ValueError(f"filter: expected NONE on {mode}, got {filter_!r}")
        raw = getattr(codec, _FILTERS[filter_])(np.ascontiguousarray(raw), count, stride)
    return np.ascontiguousarray(raw).tobytes()
