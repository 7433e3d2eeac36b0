"""An animated glTF camera as a camera path: its node's world pose sampled at the frame times.

The camera is a node of the file's default scene that holds a perspective ``camera``; with several,
``camera`` names one (its node's name or its camera's name). Its world matrix is the product of the
local matrices of its ancestors and itself (:mod:`csmlab.scene.gltf`), each node's ``translation``,
``rotation`` and ``scale`` replaced by its animation channels' values at the frame time, as the
glTF 2.0 specification (§3.11 "Animations", Appendix C "Interpolation") defines them:

- ``STEP``: the value of the last key at or before ``t``;
- ``LINEAR``: linear between the two keys around ``t``; rotations by spherical linear
  interpolation (slerp, the short way round);
- ``CUBICSPLINE``: the cubic Hermite spline through the keys with the file's in- and out-tangents
  ``a_k``, ``b_k`` scaled by the key interval ``t_d``:
  ``p(s) = (2s³ − 3s² + 1) v_k + t_d (s³ − 2s² + s) b_k + (−2s³ + 3s²) v_{k+1}
  + t_d (s³ − s²) a_{k+1}``,
  rotations normalised afterwards;
- before the first key a channel holds its first value, after the last its last.

Frames are taken at ``t = t_0 + i / fps`` on the file's animation clock, from the first key ``t_0``
of the channels that move the camera to their last key (a run's clock then starts at its first
frame, ``[camera] time_offset``). A glTF camera looks along its node's −Z with +Y up and the world is
+Y up in metres (§3.4, §3.10): csmlab's own ``opengl`` convention. The node's scale is removed from
the orientation (its rotation is the polar factor of the world matrix's 3×3 part). The camera's
``yfov`` (radians) becomes the path's vertical field of view; ``znear``, ``zfar`` (when given) and
``aspectRatio`` (when given) its clip distances and aspect.

Broken files stop with an :class:`~csmlab.errors.InputError` naming the file and the glTF key:
no perspective camera (``cameras``), an unknown ``camera`` name (``camera``), no
animation moving the camera (``animations``), keys that go back, non-unit quaternions, NaN, a key
of a type the specification does not give it (read through :class:`csmlab.documents.Value`), or an
animation longer than :data:`~csmlab.documents.MAX_FRAMES` frames at the path's rate.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from csmlab.documents import MAX_FRAMES, Value, within_limit
from csmlab.geometry import quat_from_matrix, quat_slerp
from csmlab.paths.recorded import RecordedPoses
from csmlab.scene.gltf import UNIT_TOLERANCE, GltfFile, local_matrix, node_quaternion, read_gltf, scene_nodes, \
    trs_matrices

__all__ = ["INTERPOLATIONS", "Channel", "GltfCamera", "animation_channels", "camera_nodes", "read_gltf_camera",
           "sample_channel", "write_gltf_camera"]

INTERPOLATIONS = ("LINEAR", "STEP", "CUBICSPLINE")
"""glTF animation sampler interpolations (``LINEAR`` is the default)."""
_WIDTH = {"translation": 3, "rotation": 4, "scale": 3}


@dataclass(frozen=True)
class Channel:
    """One animation channel, read and checked.

    Attributes
    ----------
    times : ndarray, shape (K,)
        Key times in seconds, strictly increasing.
    values : ndarray, shape (K, k), or (K, 3, k) for CUBICSPLINE (in-tangent, value, out-tangent)
    interpolation : str
        One of :data:`INTERPOLATIONS`.
    key : str
        Where it is in the file (``animations[a].channels[c]``).
    """

    times: np.ndarray
    values: np.ndarray
    interpolation: str
    key: str


@dataclass(frozen=True)
class GltfCamera:
    """A glTF camera's projection and where it sits in the scene.

    Attributes
    ----------
    node : int
        Index of the node holding the camera.
    chain : tuple of int
        The node's ancestors from the root, then the node.
    name : str
        The node's name (the camera's when the node has none).
    fov_y_deg : float
        ``yfov`` in degrees.
    near : float
        ``znear`` in file units.
    far : float or None
        ``zfar`` in file units; None for an infinite projection.
    aspect : float or None
        ``aspectRatio`` (width / height); None when the file leaves it to the viewport.
    camera_name : str
        The camera's own name (``""`` when it has none).
    """

    node: int
    chain: tuple
    name: str
    fov_y_deg: float
    near: float
    far: float | None
    aspect: float | None
    camera_name: str = ""


def camera_nodes(gltf: GltfFile) -> list[GltfCamera]:
    """Every node of the default scene holding a perspective camera, in the scene's depth-first order.

    Orthographic cameras are left out: csmlab's views and cascades are perspective.

    Raises
    ------
    InputError
        On a bad camera index (``nodes[i].camera``), a camera neither perspective nor orthographic,
        or a bad ``yfov``/``znear``/``zfar``/``aspectRatio`` (``cameras[j]…``).
    """
    parents = {}
    found = []
    for index, parent in scene_nodes(gltf):
        parents[index] = parent
        node = gltf.section("nodes")[index]
        if not node.has("camera"):
            continue
        _, spec = gltf.entry(node.at("camera"), "cameras")
        kind = spec.at("type", "a camera type").text(("perspective", "orthographic"))
        if kind == "orthographic":
            continue
        p = spec.at("perspective", "the perspective projection's object").mapping()
        yfov = p.at("yfov", "an angle in (0, π) radians").number(above=0.0, below=np.pi,
                                                                what="an angle in (0, π) radians")
        znear = p.at("znear", "a positive distance").number(above=0.0, what="a positive distance")
        zfar = None if not p.has("zfar") else p.at("zfar").number(above=znear, what="a distance beyond znear, or none")
        aspect = None if not p.has("aspectRatio") else p.at("aspectRatio").number(
            above=0.0, what="a positive width / height")
        chain = [index]
        while parents[chain[0]] is not None:
            chain.insert(0, parents[chain[0]])
        found.append(GltfCamera(node=index, chain=tuple(chain), name=_name(node) or _name(spec) or f"nodes[{index}]",
                                fov_y_deg=float(np.degrees(yfov)), near=znear, far=zfar, aspect=aspect,
                                camera_name=_name(spec)))
    return found


def _name(entry: Value) -> str:
    """``entry.name`` (a string), or ``""`` when it has none."""
    name = entry.get("name")
    return "" if name is None else name.text()


def _chosen_camera(gltf: GltfFile, name: str) -> GltfCamera:
    cameras = camera_nodes(gltf)
    if not cameras:
        raise gltf.error("cameras", "expected a node of the scene holding a perspective camera, found none "
                                    "(orthographic cameras are not read)")
    if not name:
        if len(cameras) > 1:
            raise gltf.error("camera", f"expected camera = one of {[c.name for c in cameras]} (the file has "
                                       f"{len(cameras)} cameras), got none")
        return cameras[0]
    chosen = [c for c in cameras if name in (c.name, c.camera_name)]
    if len(chosen) != 1:
        what = "no camera" if not chosen else f"{len(chosen)} cameras"
        raise gltf.error("camera", f"expected the name of one camera node {[c.name for c in cameras]}, got {name!r} "
                                   f"({what} by that name)")
    return chosen[0]


def animation_channels(gltf: GltfFile, nodes) -> dict[tuple[int, str], Channel]:
    """The translation, rotation and scale channels moving ``nodes`` (node indices), by ``(node, path)``.

    Raises
    ------
    InputError
        On two channels animating the same property, a bad sampler, an unknown interpolation, key
        times that do not increase, a wrong number of values, or non-unit rotation keys.
    """
    out: dict[tuple[int, str], Channel] = {}
    node_count = len(gltf.section("nodes"))
    for animation in gltf.section("animations"):
        samplers = animation.mapping().list_at("samplers")
        for channel in animation.list_at("channels"):
            target = channel.mapping().at("target", "an object naming the node and the property")
            target_node = target.mapping().get("node")
            node = None if target_node is None else target_node.index(node_count, "nodes")
            path = target.at("path", "a property (translation, rotation, scale, weights)").text()
            if node not in nodes or path not in _WIDTH:
                continue
            key = channel.key
            if (node, path) in out:
                raise gltf.error(key, f"expected one channel animating nodes[{node}].{path}, found a "
                                      f"second ({out[node, path].key} is the first)")
            sampler = samplers[channel.at("sampler", "a sampler index").index(len(samplers), "samplers")].mapping()
            where = sampler.key
            interpolation = sampler.get("interpolation")
            interpolation = "LINEAR" if interpolation is None else interpolation.text(INTERPOLATIONS)
            times = gltf.accessor(sampler.at("input", "an accessor index"))[:, 0]
            values = gltf.accessor(sampler.at("output", "an accessor index"))
            width = _WIDTH[path]
            per_key = 3 if interpolation == "CUBICSPLINE" else 1
            if times.size == 0 or np.any(np.diff(times) <= 0):
                raise gltf.error(f"{where}.input", "expected at least one key time, strictly increasing")
            if values.shape != (times.size * per_key, width):
                raise gltf.error(f"{where}.output", f"expected {times.size * per_key} values of {width} components "
                                                    f"for {times.size} keys ({interpolation} {path}), got "
                                                    f"{values.shape[0]} of {values.shape[1]}")
            values = values.reshape(times.size, per_key, width)
            if path == "rotation":
                length = np.linalg.norm(values[:, per_key // 2], axis=1)
                bad = np.abs(length - 1.0) > UNIT_TOLERANCE
                if np.any(bad):
                    k = int(np.argmax(bad))
                    raise gltf.error(f"{where}.output", f"expected unit quaternions (x, y, z, w), key {k} at "
                                                        f"t = {times[k]:.6g} s has |q| = {length[k]:.6g}")
            out[node, path] = Channel(times, values if per_key == 3 else values[:, 0], interpolation, key)
    return out


def sample_channel(times, values, interpolation: str, t, *, rotation: bool = False) -> np.ndarray:
    """A channel's value ``(N, k)`` at times ``t`` ``(N,)`` (seconds) by the glTF interpolation rule.

    Parameters
    ----------
    times : ndarray, shape (K,)
        Key times, strictly increasing, seconds.
    values : ndarray, shape (K, k), or (K, 3, k) for CUBICSPLINE (in-tangent, value, out-tangent)
    interpolation : {"LINEAR", "STEP", "CUBICSPLINE"}
    t : array_like, shape (N,)
    rotation : bool
        Values are unit quaternions ``(x, y, z, w)``: LINEAR slerps, CUBICSPLINE normalises.
    """
    times = np.asarray(times, dtype=np.float64)
    t = np.clip(np.asarray(t, dtype=np.float64), times[0], times[-1])
    keys = values[:, 1] if interpolation == "CUBICSPLINE" else values
    if times.size == 1:
        return np.repeat(keys[:1], t.size, axis=0)
    k = np.clip(np.searchsorted(times, t, side="right") - 1, 0, times.size - 2)
    span = times[k + 1] - times[k]
    s = ((t - times[k]) / span)[:, None]
    if interpolation == "STEP":
        return np.where(t[:, None] >= times[k + 1][:, None], keys[k + 1], keys[k])
    if interpolation == "LINEAR":
        if rotation:
            return quat_slerp(keys[k], keys[k + 1], s[:, 0])
        return keys[k] + s * (keys[k + 1] - keys[k])
    s2, s3 = s * s, s * s * s
    out = ((2 * s3 - 3 * s2 + 1) * keys[k] + span[:, None] * (s3 - 2 * s2 + s) * values[k, 2]
           + (-2 * s3 + 3 * s2) * keys[k + 1] + span[:, None] * (s3 - s2) * values[k + 1, 0])
    return out / np.linalg.norm(out, axis=1, keepdims=True) if rotation else out


def _node_matrices(gltf: GltfFile, index: int, channels: dict, t: np.ndarray) -> np.ndarray:
    """Local matrices ``(N, 4, 4)`` of ``nodes[index]`` at times ``t``, its channels applied."""
    node = gltf.section("nodes")[index]
    moved = {path: channels[index, path] for path in _WIDTH if (index, path) in channels}
    local = local_matrix(gltf, index)  # checks the node's own matrix, or translation, rotation and scale
    if not moved:
        return np.broadcast_to(local, (t.size, 4, 4))
    if node.has("matrix"):
        raise gltf.error(f"nodes[{index}].matrix", "expected translation/rotation/scale on an animated node (the "
                                                   "specification forbids matrix there), got matrix")
    translation, scale = node.get("translation"), node.get("scale")
    base = {"translation": np.zeros(3) if translation is None else translation.numbers(3),
            "rotation": node_quaternion(gltf, index), "scale": np.ones(3) if scale is None else scale.numbers(3)}
    trs = {path: (sample_channel(c.times, c.values, c.interpolation, t, rotation=path == "rotation")
                  if (c := moved.get(path)) is not None else np.tile(base[path], (t.size, 1)))
           for path in _WIDTH}
    return trs_matrices(trs["translation"], trs["rotation"], trs["scale"])


def read_gltf_camera(file, *, camera: str = "", fps: float = 30.0) -> RecordedPoses:
    """The animated camera of a glTF file sampled at ``t_0 + i / fps``, in the file's axes (glTF = csmlab's).

    Parameters
    ----------
    file : str or Path
        A ``.gltf`` or ``.glb`` file.
    camera : str
        The camera node's name (or its camera's name); may be empty when the scene has one camera.
    fps : float
        Frames per second on the file's animation clock.

    Returns
    -------
    RecordedPoses
        ``times`` ``t_0 + i / fps`` from the first to the last key moving the camera, positions ``(N, 3)`` in file
        units, orientations ``(N, 4)`` camera-to-world, ``fov_y_deg`` from ``yfov``, ``near``,
        ``far`` and ``aspect`` from the camera (None where the file leaves them out); ``lines`` the
        1-based frame numbers.

    Raises
    ------
    InputError
        Naming the file and the glTF key (see the module docstring).
    """
    if not np.isfinite(fps) or fps <= 0:
        raise ValueError(f"fps: expected a positive frame rate in Hz, got {fps}")
    gltf = read_gltf(file)
    chosen = _chosen_camera(gltf, camera)
    channels = animation_channels(gltf, set(chosen.chain))
    if not channels:
        raise gltf.error("animations", f"expected an animation moving camera {chosen.name!r} (a translation, "
                                       f"rotation or scale channel on its node or an ancestor), found none")
    start = min(float(c.times[0]) for c in channels.values())
    end = max(float(c.times[-1]) for c in channels.values())
    frames = (end - start) * fps + 1e-9
    within_limit(int(min(frames, 1e30)) + 1, MAX_FRAMES, what=f"frames at {fps:g} fps", file=gltf.path,
                 field="animations")
    t = start + np.arange(int(np.floor(frames)) + 1) / fps
    world = np.broadcast_to(np.eye(4), (t.size, 4, 4))
    for index in chosen.chain:
        world = world @ _node_matrices(gltf, index, channels, t)
    u, _, vt = np.linalg.svd(world[:, :3, :3])
    rotation = u @ vt
    if np.any(np.linalg.det(rotation) < 0):
        frame = int(np.argmax(np.linalg.det(rotation) < 0))
        raise gltf.error(f"nodes[{chosen.node}]", f"expected a camera transform without mirroring, frame {frame} "
                                                  f"(t = {t[frame]:.6g} s) has a negative determinant")
    return RecordedPoses(file=str(file), lines=np.arange(1, t.size + 1), times=t, positions=world[:, :3, 3].copy(),
                         orientations=quat_from_matrix(rotation), fov_y_deg=np.full(t.size, chosen.fov_y_deg),
                         time_field="time", aspect=chosen.aspect, near=chosen.near, far=chosen.far)


def write_gltf_camera(poses: RecordedPoses, file) -> None:
    """Write ``poses`` as a glTF file holding one camera node animated LINEAR through them.

    The camera is named ``camera``; its ``yfov`` is the first pose's field of view (60° when the
    poses carry none), ``znear``/``zfar``/``aspectRatio`` the poses' own when known (0.1 and none
    otherwise). Read back at the poses' own rate, evenly spaced poses from time 0 come back exactly
    (to float32 rounding of the file's accessors).
    """
    from csmlab.scene.gltf_writer import GltfBuilder

    builder = GltfBuilder()
    fov = 60.0 if poses.fov_y_deg is None else float(poses.fov_y_deg[0])
    camera = builder.add_camera(name="camera", yfov_rad=float(np.radians(fov)),
                                znear=0.1 if poses.near is None else poses.near, zfar=poses.far, aspect=poses.aspect)
    node = builder.add_node(name="camera", camera=camera)
    builder.add_animation([(node, "translation", poses.times, poses.positions, "LINEAR"),
                           (node, "rotation", poses.times, poses.orientations, "LINEAR")], name="camera path")
    builder.save(file, roots=[node])
