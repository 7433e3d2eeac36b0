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

import copy
from typing import Callable

import numpy as np

from csmlab.errors import InputError

__all__ = ["DRACO", "MESHOPT", "decompressed"]

DRACO = "KHR_draco_mesh_compression"
MESHOPT = "EXT_meshopt_compression"

_COMPONENT_DTYPES = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32,
                     5126: np.float32}
"""glTF ``componentType`` → NumPy dtype (§3.6.2.2)."""
_UNSIGNED_INT = 5125


def _extension(entry, name: str):
    return (getattr(entry, "extensions", None) or {}).get(name)


def _fallback(buffer) -> bool:
    return bool((_extension(buffer, MESHOPT) or {}).get("fallback"))


def decompressed(document, path, buffer_bytes: Callable[[int], bytes]) -> tuple[object, tuple[bytes, ...]]:
    """``document`` with its Draco primitives and meshopt buffer views decoded, and its buffers' bytes.

    Parameters
    ----------
    document : pygltflib.GLTF2
        The parsed file; changed in place (new buffers, views and accessors are appended).
    path : Path
        The file, for messages.
    buffer_bytes : callable
        ``buffer_bytes(i)``: the bytes of ``buffers[i]`` (called for every buffer but meshopt fallbacks).

    Returns
    -------
    document, buffers
        The decoded document and every buffer's bytes (empty for a fallback buffer), decoded data last.

    Raises
    ------
    InputError
        A decoder that is not installed (naming the extension and the package), or a stream it
        cannot decode (naming the primitive or buffer view).
    """
    buffers = [b"" if _fallback(b) else buffer_bytes(i) for i, b in enumerate(document.buffers)]
    if any(_extension(view, MESHOPT) for view in document.bufferViews or []):
        _decode_meshopt(document, buffers, path)
    primitives = [(m, p) for m, mesh in enumerate(document.meshes or []) for p, primitive in enumerate(mesh.primitives)
                  if _extension(primitive, DRACO)]
    if primitives:
        _decode_draco(document, buffers, path, primitives)
    return document, tuple(buffers)


def _required(module: str, package: str, extension: str, path):
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError:
        raise InputError(f"expected the {package} package to decode {extension} (pip install {package}); it is not "
                         "installed", file=path, field=f"extensionsUsed.{extension}") from None


def _view_bytes(document, buffers, view_index: int, path) -> bytes:
    views = document.bufferViews or []
    if not isinstance(view_index, int) or not 0 <= view_index < len(views):
        raise InputError(f"expected a bufferView index in [0, {len(views)}), got {view_index!r}", file=path,
                         field="bufferViews")
    view = views[view_index]
    start = view.byteOffset or 0
    data = buffers[view.buffer]
    if start + view.byteLength > len(data):
        raise InputError(f"expected {view.byteLength} bytes at {start} of buffers[{view.buffer}], which holds "
                         f"{len(data)}", file=path, field=f"bufferViews[{view_index}]")
    return data[start:start + view.byteLength]


def _append(document, buffers, data: bytes, *, stride: int | None = None) -> int:
    """A new buffer holding ``data`` and a buffer view over all of it; returns the view's index."""
    import pygltflib

    buffers.append(bytes(data))
    document.buffers.append(pygltflib.Buffer(byteLength=len(data)))
    document.bufferViews.append(pygltflib.BufferView(buffer=len(buffers) - 1, byteOffset=0, byteLength=len(data),
                                                     byteStride=stride))
    return len(document.bufferViews) - 1


# --- KHR_draco_mesh_compression ---------------------------------------------------------------------


def _decode_draco(document, buffers, path, primitives) -> None:
    draco = _required("DracoPy", "DracoPy", DRACO, path)
    for m, p in primitives:
        primitive = document.meshes[m].primitives[p]
        key = f"meshes[{m}].primitives[{p}].extensions.{DRACO}"
        extension = _extension(primitive, DRACO)
        try:
            mesh = draco.decode(_view_bytes(document, buffers, extension.get("bufferView"), path))
        except InputError:
            raise
        except Exception as exc:  # DracoPy raises its own and ValueError/RuntimeError on a bad stream.
            raise InputError(f"expected a Draco mesh stream that DracoPy decodes; it failed: {exc}", file=path,
                             field=f"{key}.bufferView") from None
        for name, unique_id in (extension.get("attributes") or {}).items():
            attribute = mesh.get_attribute_by_unique_id(unique_id)
            original = getattr(primitive.attributes, name, None)
            if attribute is None or original is None:
                raise InputError(f"expected attribute {name} (Draco unique id {unique_id}) in the stream and in the "
                                 "primitive's attributes", file=path, field=f"{key}.attributes.{name}")
            setattr(primitive.attributes, name, _draco_accessor(document, buffers, original, attribute["data"]))
        faces = np.asarray(mesh.faces, dtype=np.uint32)
        primitive.indices = _new_accessor(document, buffers, primitive.indices, faces.reshape(-1, 1),
                                          component=_UNSIGNED_INT, kind="SCALAR")
        del primitive.extensions[DRACO]


def _draco_accessor(document, buffers, original: int, data) -> int:
    accessor = document.accessors[original]
    values = np.asarray(data)
    values = values.reshape(values.shape[0], -1)
    return _new_accessor(document, buffers, original, values, component=accessor.componentType, kind=accessor.type)


def _new_accessor(document, buffers, original, values: np.ndarray, *, component: int, kind: str) -> int:
    """An accessor (a copy of ``original``'s fields where it has one) over ``values`` in ``component``'s dtype."""
    import pygltflib

    dtype = _COMPONENT_DTYPES[component]
    packed = np.ascontiguousarray(values.astype(dtype, copy=False))
    element = packed.dtype.itemsize * packed.shape[1]
    # Vertex attributes' elements are aligned to 4 bytes (§3.6.2.4): pad each row.
    row = element if kind == "SCALAR" else -(-element // 4) * 4
    raw = np.zeros((packed.shape[0], row), dtype=np.uint8)
    raw[:, :element] = packed.view(np.uint8).reshape(packed.shape[0], element)
    view = _append(document, buffers, raw.tobytes(), stride=row if row != element else None)
    base = copy.copy(document.accessors[original]) if isinstance(original, int) else pygltflib.Accessor()
    base.bufferView, base.byteOffset, base.sparse = view, 0, None
    base.componentType, base.type, base.count = component, kind, int(packed.shape[0])
    if kind == "SCALAR":
        base.min = base.max = None
    document.accessors.append(base)
    return len(document.accessors) - 1


# --- EXT_meshopt_compression ------------------------------------------------------------------------


def _decode_meshopt(document, buffers, path) -> None:
    codec = _required("meshoptimizer", "meshoptimizer", MESHOPT, path)
    for v, view in enumerate(document.bufferViews):
        extension = _extension(view, MESHOPT)
        if not extension:
            continue
        key = f"bufferViews[{v}].extensions.{MESHOPT}"
        source = extension.get("buffer")
        if not isinstance(source, int) or not 0 <= source < len(buffers) or _fallback(document.buffers[source]):
            raise InputError(f"expected the index of a buffer holding the compressed data, got {source!r}",
                             file=path, field=f"{key}.buffer")
        start, length = extension.get("byteOffset", 0), extension.get("byteLength", 0)
        stream = buffers[source][start:start + length]
        count, stride = extension.get("count"), extension.get("byteStride")
        mode, filter_ = extension.get("mode"), extension.get("filter", "NONE")
        try:
            decoded = _meshopt_bytes(codec, stream, count=count, stride=stride, mode=mode, filter_=filter_)
        except (RuntimeError, ValueError, TypeError) as exc:
            raise InputError(f"expected a meshopt {mode} stream of {count} × {stride} bytes that meshoptimizer "
                             f"decodes; it failed: {exc}", file=path, field=key) from None
        buffers.append(decoded)
        import pygltflib

        document.buffers.append(pygltflib.Buffer(byteLength=len(decoded)))
        view.buffer, view.byteOffset, view.byteLength = len(buffers) - 1, 0, len(decoded)
        del view.extensions[MESHOPT]


_FILTERS = {"OCTAHEDRAL": "decode_filter_oct", "QUATERNION": "decode_filter_quat", "EXPONENTIAL": "decode_filter_exp"}
"""meshopt filters (the extension's ``filter``) → meshoptimizer's decoding function."""


def _meshopt_bytes(codec, stream: bytes, *, count, stride, mode: str, filter_: str) -> bytes:
    """The ``count × stride`` bytes a meshopt stream decodes to (ATTRIBUTES, TRIANGLES or INDICES, then its filter)."""
    if not isinstance(count, int) or not isinstance(stride, int) or count < 0 or stride <= 0:
        raise ValueError(f"count and byteStride: expected whole numbers, got {count!r} and {stride!r}")
    if mode == "ATTRIBUTES":
        raw = codec.decode_vertex_buffer(count, stride, stream).view(np.uint8).reshape(-1)
    elif mode in ("TRIANGLES", "INDICES"):
        decode = codec.decode_index_buffer if mode == "TRIANGLES" else codec.decode_index_sequence
        raw = decode(count, stride, stream).view(np.uint8).reshape(-1)[:count * stride]
    else:
        raise ValueError(f"mode: expected ATTRIBUTES, TRIANGLES or INDICES, got {mode!r}")
    if filter_ != "NONE":
        if filter_ not in _FILTERS or mode != "ATTRIBUTES":
            raise ValueError(f"filter: expected NONE, or one of {sorted(_FILTERS)} on ATTRIBUTES, got {filter_!r}")
        raw = getattr(codec, _FILTERS[filter_])(np.ascontiguousarray(raw), count, stride)
    return np.ascontiguousarray(raw).tobytes()
