"""Draco and meshopt-compressed glTF read through DracoPy and meshoptimizer, and a missing decoder named.

Oracles: a closed box written uncompressed and compressed by each library's own encoder — the
meshopt codec is lossless (the same vertices bit for bit), Draco quantizes positions (within the
quantization step of the box's size) — and the same triangles, normals and bounds from the reader.
"""

from __future__ import annotations

import base64
import json
import sys

import numpy as np
import pytest

from csmlab.errors import InputError
from csmlab.scene.gltf_compression import DRACO, MESHOPT
from csmlab.scene.gltf_writer import box
from csmlab.scene.mesh import load_mesh

DracoPy = pytest.importorskip("DracoPy")
meshoptimizer = pytest.importorskip("meshoptimizer")

CORNERS, TRIANGLES = box((2.0, 3.0, 4.0))


def _uri(data: bytes) -> str:
    return "data:application/octet-stream;base64," + base64.b64encode(data).decode()


def _document(buffers, views, primitive, extension: str) -> dict:
    return {"asset": {"version": "2.0"}, "extensionsUsed": [extension], "extensionsRequired": [extension],
            "buffers": buffers, "bufferViews": views,
            "accessors": [{"componentType": 5126, "count": len(CORNERS), "type": "VEC3",
                           "min": CORNERS.min(axis=0).tolist(), "max": CORNERS.max(axis=0).tolist()},
                          {"componentType": 5125, "count": TRIANGLES.size, "type": "SCALAR"}],
            "meshes": [{"primitives": [primitive]}], "nodes": [{"mesh": 0}], "scenes": [{"nodes": [0]}], "scene": 0}


def _draco_file(tmp_path):
    stream = DracoPy.encode(CORNERS.astype(np.float32), TRIANGLES.astype(np.uint32), quantization_bits=16,
                            preserve_order=True)
    position = next(a["unique_id"] for a in DracoPy.decode(stream).attributes if a["attribute_type"] == 0)
    primitive = {"attributes": {"POSITION": 0}, "indices": 1,
                 "extensions": {DRACO: {"bufferView": 0, "attributes": {"POSITION": position}}}}
    document = _document([{"byteLength": len(stream), "uri": _uri(stream)}],
                         [{"buffer": 0, "byteOffset": 0, "byteLength": len(stream)}], primitive, DRACO)
    path = tmp_path / "box_draco.gltf"
    path.write_text(json.dumps(document))
    return path


def _meshopt_file(tmp_path):
    vertices = meshoptimizer.encode_vertex_buffer(CORNERS.astype(np.float32), len(CORNERS), 12)
    indices = meshoptimizer.encode_index_buffer(TRIANGLES.reshape(-1).astype(np.uint32), TRIANGLES.size, len(CORNERS))
    pad = -len(vertices) % 4
    data = vertices + bytes(pad) + indices
    raw_vertices, raw_indices = len(CORNERS) * 12, TRIANGLES.size * 4
    views = [{"buffer": 1, "byteOffset": 0, "byteLength": raw_vertices, "byteStride": 12,
              "extensions": {MESHOPT: {"buffer": 0, "byteOffset": 0, "byteLength": len(vertices), "byteStride": 12,
                                       "count": len(CORNERS), "mode": "ATTRIBUTES"}}},
             {"buffer": 1, "byteOffset": raw_vertices, "byteLength": raw_indices,
              "extensions": {MESHOPT: {"buffer": 0, "byteOffset": len(vertices) + pad, "byteLength": len(indices),
                                       "byteStride": 4, "count": TRIANGLES.size, "mode": "TRIANGLES"}}}]
    buffers = [{"byteLength": len(data), "uri": _uri(data)},
               {"byteLength": raw_vertices + raw_indices, "extensions": {MESHOPT: {"fallback": True}}}]
    document = _document(buffers, views, {"attributes": {"POSITION": 0}, "indices": 1}, MESHOPT)
    document["accessors"][0]["bufferView"] = 0
    document["accessors"][1]["bufferView"] = 1
    path = tmp_path / "box_meshopt.gltf"
    path.write_text(json.dumps(document))
    return path


def _plain():
    from csmlab.scene.core import Scene

    return Scene.from_triangles(CORNERS, TRIANGLES)


def test_a_draco_compressed_box_reads_as_the_box_within_the_quantization_step(tmp_path):
    scene = load_mesh(_draco_file(tmp_path))
    plain = _plain()
    assert scene.triangle_count == plain.triangle_count
    step = 4.0 / (2**16 - 1)
    np.testing.assert_allclose(scene.vertices[scene.triangles], plain.vertices[plain.triangles], atol=step)
    np.testing.assert_allclose(scene.normals, plain.normals, atol=1e-3)


def _rotated_to_smallest(triangles: np.ndarray) -> np.ndarray:
    """Each triangle's indices rotated (winding kept) to start at its smallest: the codec may rotate them."""
    first = np.argmin(triangles, axis=1)
    return np.stack([np.roll(t, -k) for t, k in zip(triangles, first)])


def test_a_meshopt_compressed_box_reads_as_the_same_box_bit_for_bit(tmp_path):
    scene = load_mesh(_meshopt_file(tmp_path))
    np.testing.assert_array_equal(scene.vertices, CORNERS)
    np.testing.assert_array_equal(_rotated_to_smallest(scene.triangles), _rotated_to_smallest(TRIANGLES))


@pytest.mark.parametrize("module, extension, make", [("DracoPy", DRACO, _draco_file),
                                                     ("meshoptimizer", MESHOPT, _meshopt_file)])
def test_a_missing_decoder_is_named_with_the_extension_not_degenerate_triangles(tmp_path, monkeypatch, module,
                                                                                 extension, make):
    path = make(tmp_path)
    monkeypatch.setitem(sys.modules, module, None)
    with pytest.raises(InputError, match=rf"{extension}.*pip install {module}"):
        load_mesh(path)


def test_a_broken_draco_stream_names_the_primitive(tmp_path):
    path = _draco_file(tmp_path)
    document = json.loads(path.read_text())
    broken = b"DRACO" + bytes(40)
    document["buffers"][0] = {"byteLength": len(broken), "uri": _uri(broken)}
    document["bufferViews"][0]["byteLength"] = len(broken)
    path.write_text(json.dumps(document))
    with pytest.raises(InputError, match=rf"meshes\[0\]\.primitives\[0\]\.extensions\.{DRACO}\.bufferView"):
        load_mesh(path)
