"""Writing glTF 2.0 levels with pygltflib: meshes, node trees, instancing, masked materials, a sun and animated cameras.

The writer of csmlab's own glTF files — the test fixtures, the shipped ``data/gltf/level.glb``
(``data/gltf/make_level.py``) and the benchmark's 3M-triangle level (``benchmarks/bench_gltf_level.py``)
— so that every one is made by code in the repository. :class:`GltfBuilder` collects the parts and
:meth:`GltfBuilder.save` writes a ``.glb`` (one binary chunk) or a ``.gltf`` (its buffer as a base64
data URI). :func:`box` and :func:`ground` are the meshes the levels are made of.
"""

from __future__ import annotations

import base64
from pathlib import Path

import numpy as np

from csmlab.scene.gltf import INSTANCING, LIGHTS

__all__ = ["GltfBuilder", "box", "ground"]

_FLOAT, _UINT32 = 5126, 5125
_TYPES = {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4"}


def _listed(values) -> list[float] | None:
    """``values`` as a flat list of Python floats (what the JSON holds); None stays None."""
    return None if values is None else [float(x) for x in np.asarray(values).reshape(-1)]


class GltfBuilder:
    """Collects a glTF level's parts; indices returned by the ``add_*`` methods refer to them.

    Every array goes into one buffer as float32 (indices as uint32), each view 4-byte aligned.
    """

    def __init__(self) -> None:
        import pygltflib

        self._g = pygltflib
        self.document = pygltflib.GLTF2(asset=pygltflib.Asset(version="2.0", generator="csmlab gltf_writer"))
        self._blob = bytearray()
        self._extensions: set[str] = set()
        self._lights: list[dict] = []

    def _accessor(self, values, *, component: int, minmax: bool = False) -> int:
        """Append ``values`` ``(N,)`` or ``(N, k)`` as a new buffer view and accessor; its index."""
        array = np.asarray(values, dtype=np.float32 if component == _FLOAT else np.uint32)
        array = array.reshape(array.shape[0], -1)
        data = np.ascontiguousarray(array).tobytes()
        self._blob.extend(b"\0" * (-len(self._blob) % 4))
        self.document.bufferViews.append(self._g.BufferView(buffer=0, byteOffset=len(self._blob),
                                                            byteLength=len(data)))
        self._blob.extend(data)
        accessor = self._g.Accessor(bufferView=len(self.document.bufferViews) - 1, componentType=component,
                                    count=array.shape[0], type=_TYPES[array.shape[1]])
        if minmax and np.all(np.isfinite(array)):  # the specification's bounds; a test's broken file has none
            accessor.min, accessor.max = array.min(axis=0).tolist(), array.max(axis=0).tolist()
        self.document.accessors.append(accessor)
        return len(self.document.accessors) - 1

    def add_mesh(self, positions, triangles, *, name: str = "", uv=None, material: int | None = None) -> int:
        """A mesh of one triangle primitive: ``positions`` ``(V, 3)``, ``triangles`` ``(T, 3)`` counter-clockwise.

        ``uv`` ``(V, 2)`` becomes ``TEXCOORD_0`` (v down the image); ``material`` is an index from
        :meth:`add_masked_material`.
        """
        primitive = self._g.Primitive(attributes=self._g.Attributes(
            POSITION=self._accessor(positions, component=_FLOAT, minmax=True),
            TEXCOORD_0=None if uv is None else self._accessor(uv, component=_FLOAT)),
            indices=self._accessor(np.asarray(triangles).reshape(-1), component=_UINT32), mode=4, material=material)
        self.document.meshes.append(self._g.Mesh(name=name or None, primitives=[primitive]))
        return len(self.document.meshes) - 1

    def add_masked_material(self, png: bytes, *, cutoff: float = 0.5, alpha_factor: float = 1.0) -> int:
        """An ``alphaMode = "MASK"`` material: ``png`` (encoded bytes, kept in the buffer) as its base colour texture.

        ``cutoff`` is its ``alphaCutoff``, ``alpha_factor`` its ``baseColorFactor``'s alpha.
        """
        self._blob.extend(b"\0" * (-len(self._blob) % 4))
        self.document.bufferViews.append(self._g.BufferView(buffer=0, byteOffset=len(self._blob), byteLength=len(png)))
        self._blob.extend(png)
        self.document.images.append(self._g.Image(bufferView=len(self.document.bufferViews) - 1, mimeType="image/png"))
        self.document.textures.append(self._g.Texture(source=len(self.document.images) - 1))
        self.document.materials.append(self._g.Material(
            alphaMode="MASK", alphaCutoff=cutoff, doubleSided=True, pbrMetallicRoughness=self._g.PbrMetallicRoughness(
                baseColorFactor=[1.0, 1.0, 1.0, alpha_factor],
                baseColorTexture=self._g.TextureInfo(index=len(self.document.textures) - 1))))
        return len(self.document.materials) - 1

    def add_camera(self, *, name: str, yfov_rad: float, znear: float, zfar: float | None = None,
                   aspect: float | None = None) -> int:
        """A perspective camera (radians, metres, width/height)."""
        self.document.cameras.append(self._g.Camera(name=name, type="perspective", perspective=self._g.Perspective(
            yfov=yfov_rad, znear=znear, zfar=zfar, aspectRatio=aspect)))
        return len(self.document.cameras) - 1

    def add_light(self, *, name: str, kind: str = "directional") -> int:
        """A ``KHR_lights_punctual`` light (white, intensity 1); attach it with ``add_node(light=…)``."""
        self._extensions.add(LIGHTS)
        self._lights.append({"name": name, "type": kind, "color": [1.0, 1.0, 1.0], "intensity": 1.0})
        return len(self._lights) - 1

    def add_node(self, *, name: str = "", mesh: int | None = None, camera: int | None = None,
                 light: int | None = None, translation=None, rotation=None, scale=None, matrix=None,
                 children=(), instances: dict | None = None) -> int:
        """A node; ``rotation`` is ``(x, y, z, w)``, ``matrix`` column-major 16 numbers.

        ``instances`` maps ``TRANSLATION`` ``(I, 3)``, ``ROTATION`` ``(I, 4)``, ``SCALE`` ``(I, 3)``
        (any subset) to arrays: the node's mesh is drawn once per instance (``EXT_mesh_gpu_instancing``).
        """
        extensions = {}
        if light is not None:
            extensions[LIGHTS] = {"light": light}
        if instances:
            self._extensions.add(INSTANCING)
            extensions[INSTANCING] = {"attributes": {k: self._accessor(v, component=_FLOAT)
                                                     for k, v in instances.items()}}
        self.document.nodes.append(self._g.Node(
            name=name or None, mesh=mesh, camera=camera, translation=_listed(translation), rotation=_listed(rotation),
            scale=_listed(scale), matrix=_listed(matrix), children=list(children), extensions=extensions))
        return len(self.document.nodes) - 1

    def add_animation(self, channels, *, name: str = "") -> int:
        """An animation of ``(node, path, times (K,), values (K, k) or (3K, k), interpolation)`` channels.

        ``path`` is ``translation``, ``rotation`` or ``scale``; CUBICSPLINE values hold
        in-tangent, value, out-tangent for each key, in that order.
        """
        samplers, targets = [], []
        for k, (node, path, times, values, interpolation) in enumerate(channels):
            samplers.append(self._g.AnimationSampler(input=self._accessor(times, component=_FLOAT, minmax=True),
                                                     output=self._accessor(values, component=_FLOAT),
                                                     interpolation=interpolation))
            targets.append(self._g.AnimationChannel(sampler=k, target=self._g.AnimationChannelTarget(node=node,
                                                                                                     path=path)))
        self.document.animations.append(self._g.Animation(name=name or None, samplers=samplers, channels=targets))
        return len(self.document.animations) - 1

    def save(self, file, *, roots) -> Path:
        """Write the level with scene ``roots`` (node indices): ``.glb`` binary, ``.gltf`` with a data URI."""
        path = Path(file)
        document = self.document
        document.scenes = [self._g.Scene(nodes=list(roots))]
        document.scene = 0
        document.extensionsUsed = sorted(self._extensions)
        if self._lights:
            document.extensions = {LIGHTS: {"lights": self._lights}}
        blob = bytes(self._blob) + b"\0" * (-len(self._blob) % 4)
        if path.suffix.lower() == ".glb":
            document.buffers = [self._g.Buffer(byteLength=len(blob))]
            document.set_binary_blob(blob)
            document.save_binary(str(path))
        else:
            document.buffers = [self._g.Buffer(byteLength=len(blob), uri="data:application/octet-stream;base64,"
                                                                          + base64.b64encode(blob).decode())]
            document.save_json(str(path))
        return path


def box(size=(1.0, 1.0, 1.0)) -> tuple[np.ndarray, np.ndarray]:
    """A closed box standing on y = 0: corners ``(8, 3)`` from ``(−sx/2, 0, −sz/2)`` to ``(sx/2, sy, sz/2)``, 12 outward
    triangles."""
    sx, sy, sz = size
    corners = np.array([[x, y, z] for x in (-sx / 2, sx / 2) for y in (0.0, sy) for z in (-sz / 2, sz / 2)])
    # Corner k = 4·[x high] + 2·[y high] + [z high]; each face's quad counter-clockwise from outside.
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    triangles = np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))])
    return corners, triangles


def ground(*, half_size: float, cells: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """A flat square on y = 0 of side ``2 · half_size`` in ``cells × cells`` quads, facing +Y."""
    axis = np.linspace(-half_size, half_size, cells + 1)
    x, z = np.meshgrid(axis, axis, indexing="ij")
    points = np.stack([x.ravel(), np.zeros(x.size), z.ravel()], axis=1)
    i, j = np.meshgrid(np.arange(cells), np.arange(cells), indexing="ij")
    a = (i * (cells + 1) + j).ravel()
    b, c, d = a + 1, a + cells + 2, a + cells + 1
    # (x, z) grid seen from +Y: a=(i, j), b=(i, j+1), c=(i+1, j+1), d=(i+1, j); a → b → c winds counter-clockwise.
    triangles = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return points, triangles
