"""Write data/gltf/level.glb: the small glTF level of experiments/gltf_level.toml.

A 160 m ground, 48 instanced boxes (EXT_mesh_gpu_instancing) as buildings of several heights, a row
of instanced fence posts, a KHR_lights_punctual sun and a camera on a rig: the rig node walks
(LINEAR translation) and the camera node under it looks about (CUBICSPLINE rotation with zero
tangents), 4 s at any frame rate. Everything is made here, so the file is reproducible::

    PYTHONPATH=. python data/gltf/make_level.py
"""

from pathlib import Path

import numpy as np

from csmlab.scene.gltf_writer import GltfBuilder, box, ground


def _about_y(deg: float) -> list[float]:
    """Quaternion (x, y, z, w) of a turn of ``deg`` degrees about +Y."""
    half = np.radians(deg) / 2
    return [0.0, float(np.sin(half)), 0.0, float(np.cos(half))]


def _pitch_yaw(pitch_deg: float, yaw_deg: float) -> np.ndarray:
    """Quaternion (x, y, z, w) of yaw about +Y after pitch about +X."""
    p, y = np.radians(pitch_deg) / 2, np.radians(yaw_deg) / 2
    qx = np.array([np.sin(p), 0.0, 0.0, np.cos(p)])
    qy = np.array([0.0, np.sin(y), 0.0, np.cos(y)])
    x1, y1, z1, w1 = qy
    x2, y2, z2, w2 = qx
    return np.array([w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2, w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
                     w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2, w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2])


def write_level(file) -> Path:
    """Write the level to ``file`` (``.glb`` or ``.gltf``); returns its path."""
    rng = np.random.default_rng(7)
    builder = GltfBuilder()
    floor = builder.add_node(name="ground", mesh=builder.add_mesh(*ground(half_size=80.0, cells=8), name="ground"))
    cells = np.array([(x, z) for x in range(-3, 3) for z in range(-4, 4)], dtype=float)
    centres = np.column_stack([cells[:, 0] * 20.0 + 10.0, np.zeros(len(cells)), cells[:, 1] * 20.0 + 10.0])
    keep = np.abs(centres[:, 0] - 0.0) > 12.0  # a clear street along x = 0 for the walk
    centres = centres[keep]
    heights = rng.uniform(4.0, 24.0, len(centres))
    houses = builder.add_node(name="buildings", mesh=builder.add_mesh(*box((8.0, 1.0, 8.0)), name="building"),
                              instances={"TRANSLATION": centres,
                                         "ROTATION": np.array([_about_y(a) for a in rng.uniform(0, 90, len(centres))]),
                                         "SCALE": np.column_stack([np.ones(len(centres)), heights,
                                                                   np.ones(len(centres))])})
    posts = np.column_stack([np.full(40, 4.0), np.zeros(40), np.linspace(-60.0, 60.0, 40)])
    fence = builder.add_node(name="fence", mesh=builder.add_mesh(*box((0.15, 1.2, 0.15)), name="post"),
                             instances={"TRANSLATION": posts})
    sun = builder.add_node(name="sun", light=builder.add_light(name="sun"),
                           rotation=_pitch_yaw(-35.0, 30.0))
    camera = builder.add_camera(name="eye", yfov_rad=float(np.radians(60.0)), znear=0.1, zfar=300.0,
                                aspect=16.0 / 9.0)
    eye = builder.add_node(name="eye", camera=camera, translation=(0.0, 1.7, 0.0))
    rig = builder.add_node(name="rig", children=[eye])
    times = np.array([0.0, 4.0])
    look_times = np.array([0.0, 2.0, 4.0])
    looks = np.array([_pitch_yaw(-5.0, 0.0), _pitch_yaw(-10.0, 25.0), _pitch_yaw(-5.0, -15.0)])
    tangents = np.zeros_like(looks)
    builder.add_animation([
        (rig, "translation", times, np.array([[0.0, 0.0, 40.0], [0.0, 0.0, 0.0]]), "LINEAR"),
        (eye, "rotation", look_times, np.stack([tangents, looks, tangents], axis=1).reshape(-1, 4), "CUBICSPLINE"),
    ], name="walk")
    return builder.save(file, roots=[floor, houses, fence, sun, rig])


if __name__ == "__main__":
    print(write_level(Path(__file__).with_name("level.glb")))
