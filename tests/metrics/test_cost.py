"""Cost: texture memory from its formula, rasterization work and stage times passed through."""

import math

import numpy as np

from csmlab.camera import CameraPose
from csmlab.cascades import build_cascades
from csmlab.frame import Frame, GBuffer, ShadowLookup, ShadowMaps, View
from csmlab.kernels.visibility import CameraHits
from csmlab.geometry import rotation_looking_at
from csmlab.metrics.cost import cost_summary, shadow_memory_bytes
from csmlab.settings import ShadowSettings


def test_shadow_memory_is_cascades_times_resolution_squared_times_depth_bytes():
    assert shadow_memory_bytes(ShadowSettings(cascades=4, resolution=1024, depth_bytes=4)) == 16 * 2**20
    assert shadow_memory_bytes(ShadowSettings(cascades=3, resolution=2048, depth_bytes=2)) == 3 * 2048 * 2048 * 2


def test_cost_summary_of_a_frame():
    pose = CameraPose(position=[0.0, 10.0, 0.0], orientation=rotation_looking_at([0.0, -1.0, 0.0]))
    settings = ShadowSettings(cascades=2, resolution=64)
    cascades = build_cascades(pose=pose, light_direction=[0.0, -1.0, 0.0], scene_corners=np.zeros((1, 3)),
                              settings=settings)
    zeros3 = np.zeros((2, 2, 3), np.float32)
    gbuffer = GBuffer(hits=CameraHits(position=np.zeros((2, 2, 3)), normal=zeros3, triangle=np.zeros((2, 2), np.int32),
                                      view_depth=np.ones((2, 2), np.float32)),
                      albedo=zeros3)
    view = View(index=0, pose=pose, light_direction=np.array([0.0, -1.0, 0.0]), gbuffer=gbuffer,
                reference=np.ones((2, 2), np.float32), timings={"visibility": 0.5, "reference": 0.25})
    frame = Frame(view=view, settings=settings,
                  maps=ShadowMaps(cascades=cascades, depth=np.zeros((2, 64, 64), np.float32), texels_rasterized=1234),
                  shadow=ShadowLookup(lit=np.ones((2, 2), np.float32), cascade=np.zeros((2, 2), np.int8),
                                      blend=np.zeros((2, 2), bool)),
                  timings={"cascades": 0.125, "raster": 2.0, "shadow": 1.0})
    cost = cost_summary(frame)
    # Cascades have no pages: a virtual clipmap's page columns are empty for them.
    assert all(math.isnan(cost.pop(key)) for key in ("pages_marked", "pages_rendered", "pool_bytes"))
    assert cost == {"memory_bytes": 2 * 64 * 64 * 4.0, "texels_rasterized": 1234.0}
