"""What a point no cascade holds is given (``[shadow] outside``): nothing, lit (Bevy), or the last cascade (Stride,
MJP)."""

from __future__ import annotations

import numpy as np
import pytest

from csmlab.camera import CameraPose
from csmlab.geometry import rotation_looking_at
from csmlab.light import direction_from_angles
from csmlab.lookup_choices import OUTSIDE_METHODS
from csmlab.render import prepare_scene, render_shadow, render_view
from csmlab.scene import Scene
from csmlab.settings import ShadowSettings


@pytest.fixture(scope="module")
def frames():
    """One view of a 400 m ground with boxes near and far, shaded with cascades ending at 30 m, each way."""
    vertices = [np.array([[-200, 0, -200], [200, 0, -200], [200, 0, 200], [-200, 0, 200]], float)]
    triangles = [np.array([[0, 2, 1], [0, 3, 2]])]
    faces = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1], [2, 3, 7], [2, 7, 6],
                      [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    for k, (x, z, h) in enumerate([(2.0, -8.0, 3.0), (-6.0, -20.0, 4.0), (5.0, -45.0, 8.0), (-12.0, -70.0, 10.0)]):
        lo, hi = (x, 0.0, z), (x + 4.0, h, z + 4.0)
        vertices.append(np.array([[a, b, c] for a in (lo[0], hi[0]) for b in (lo[1], hi[1]) for c in (lo[2], hi[2])]))
        triangles.append(faces + 4 + 8 * k)
    dscene = prepare_scene(Scene.from_triangles(np.concatenate(vertices), np.concatenate(triangles)))
    light = direction_from_angles(elevation_deg=35.0, azimuth_deg=200.0)
    eye = np.array([0.0, 6.0, 10.0])
    pose = CameraPose(position=eye, orientation=rotation_looking_at(np.array([0.0, -0.12, -1.0])), aspect=1.6,
                      near=0.1, far=150.0)
    view = render_view(dscene, pose, light, width=64, height=40)
    base = ShadowSettings(cascades=3, resolution=256, shadow_distance=30.0)
    return view, {name: render_shadow(dscene, view, base.replace(outside=name)) for name in OUTSIDE_METHODS}


def test_none_leaves_a_point_beyond_the_last_split_without_a_cascade(frames):
    view, shadows = frames
    g = view.gbuffer
    beyond = g.valid & (g.view_depth >= 30.0)
    assert beyond.sum() > 200
    assert np.all(shadows["none"].shadow.cascade[beyond] == -1) and np.all(np.isnan(shadows["none"].shadow.lit[beyond]))


def test_lit_shades_every_point_without_a_cascade_as_lit_and_changes_nothing_else(frames):
    view, shadows = frames
    none, lit = shadows["none"].shadow, shadows["lit"].shadow
    valid = view.gbuffer.valid
    without = valid & (none.cascade < 0)
    assert without.sum() > 200
    assert np.all(lit.lit[without] == 1.0) and np.all(lit.cascade[without] == -1)
    np.testing.assert_array_equal(lit.lit[valid & ~without], none.lit[valid & ~without])


def test_last_keeps_the_last_cascade_past_the_last_split_where_its_box_holds_the_point(frames):
    """Stride: cascadeIndex stops at TCascadeCount − 1; MJP: cascadeIdx starts at NumCascades − 1 and moves down
    only for depthVS <= CascadeSplits[i]."""
    view, shadows = frames
    g = view.gbuffer
    none, last = shadows["none"].shadow, shadows["last"].shadow
    within = g.valid & (g.view_depth < 30.0)
    np.testing.assert_array_equal(last.lit[within], none.lit[within])
    np.testing.assert_array_equal(last.cascade[within], none.cascade[within])
    beyond = g.valid & (g.view_depth >= 30.0)
    assert np.all(np.isin(last.cascade[beyond], [-1, 2]))
    # The last box holds the points just past the last split, and shades some of them in shadow.
    held = beyond & (last.cascade == 2)
    assert held.sum() > 20 and np.any(last.lit[held] < 1.0)
