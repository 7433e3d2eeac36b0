"""Unity's split-sphere cascade selection (``selection = "sphere"``), against Unity's shader code written out."""

from __future__ import annotations

import numpy as np
import pytest

from csmlab.camera import CameraPose
from csmlab.geometry import rotation_looking_at, slice_bounding_sphere
from csmlab.kernels.shadow import split_sphere_cascades
from csmlab.light import direction_from_angles
from csmlab.render import prepare_scene, render_shadow, render_view
from csmlab.scene import Scene
from csmlab.settings import ShadowSettings


def unity_cascade_index(points, centres, radii):
    """URP ``ComputeCascadeIndex`` (Shadows.hlsl) for four spheres, and whether its weights are one-hot.

    ``weights = distances2 < radii²``; ``weights.yzw = saturate(weights.yzw - weights.xyz)``;
    ``index = 4 - dot(weights, (4, 3, 2, 1))`` (4: no sphere). Built-in's
    ``getCascadeWeights_splitSpheres`` makes the same weights.
    """
    d2 = np.sum((points[:, None, :] - centres[None, :, :]) ** 2, axis=2)
    w = (d2 < radii[None, :] ** 2).astype(float)
    w[:, 1:] = np.clip(w[:, 1:] - w[:, :-1], 0.0, 1.0)
    return 4.0 - w @ np.array([4.0, 3.0, 2.0, 1.0]), w.sum(axis=1) <= 1.0


def test_split_sphere_cascades_equal_urps_compute_cascade_index(device):
    rng = np.random.default_rng(7)
    centres = np.array([[0.0, 0.0, -3.0], [0.5, 0.2, -9.0], [1.0, -0.5, -22.0], [2.0, 1.0, -50.0]])
    radii = np.array([4.0, 8.0, 16.0, 35.0])
    points = rng.uniform([-40, -40, -90], [40, 40, 5], (20000, 3))
    ours = split_sphere_cascades(points, centres=centres, radii=radii, device=device)
    index, one_hot = unity_cascade_index(points, centres, radii)
    assert one_hot.mean() > 0.99 and np.all(np.isin(ours, [-1, 0, 1, 2, 3]))
    expected = np.where(index == 4.0, -1, index).astype(np.int32)
    np.testing.assert_array_equal(ours[one_hot], expected[one_hot])
    assert len(np.unique(ours)) == 5


def test_a_point_on_a_sphere_lies_outside_it_as_the_strict_compare_says(device):
    centres, radii = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]), np.array([2.0, 4.0])
    points = np.array([[2.0, 0.0, 0.0], [0.0, 4.0, 0.0], [0.0, 0.0, 1.999], [np.nan, 0.0, 0.0]])
    np.testing.assert_array_equal(split_sphere_cascades(points, centres=centres, radii=radii, device=device),
                                  [1, -1, 0, -1])


def test_each_receiver_reads_the_first_bounding_sphere_of_its_slice_that_holds_it(device):
    """render: with selection = "sphere", every shaded receiver lies in its cascade's slice bounding sphere
    and in no earlier one, the spheres being each fitted slice's smallest bounding sphere."""
    vertices = np.array([[-60, 0, -60], [60, 0, -60], [60, 0, 60], [-60, 0, 60],
                         [-1, 2, -1], [1, 2, -1], [1, 2, 1], [-1, 2, 1]], float)
    dscene = prepare_scene(Scene.from_triangles(vertices, np.array([[0, 2, 1], [0, 3, 2], [4, 6, 5], [4, 7, 6]])),
                           device=device)
    light = direction_from_angles(elevation_deg=50.0, azimuth_deg=20.0)
    eye = np.array([4.0, 3.0, 8.0])
    pose = CameraPose(position=eye, orientation=rotation_looking_at(-eye), aspect=1.6, near=0.1, far=60.0)
    view = render_view(dscene, pose, light, width=48, height=30)
    settings = ShadowSettings(cascades=3, resolution=128, shadow_distance=40.0, selection="sphere")
    frame = render_shadow(dscene, view, settings)
    cascades = frame.maps.cascades
    g = view.gbuffer
    points, chosen = g.position[g.valid], frame.shadow.cascade[g.valid]
    spheres = []
    for c in cascades.cascades:
        s = slice_bounding_sphere(fov_y_deg=pose.fov_y_deg, aspect=pose.aspect, z_near=c.slice_near, z_far=c.slice_far)
        np.testing.assert_allclose(c.sphere_centre, pose.position + pose.forward * s.centre_depth, atol=1e-12)
        assert s.radius <= c.sphere_radius <= s.radius * (1 + 2.0**-11)
        spheres.append((c.sphere_centre, c.sphere_radius))
    inside = np.stack([np.sum((points - centre) ** 2, axis=1) < r * r for centre, r in spheres], axis=1)
    first = np.where(inside.any(axis=1), inside.argmax(axis=1), -1)
    selected = chosen >= 0
    assert selected.sum() > 500 and len(np.unique(chosen[selected])) == 3
    np.testing.assert_array_equal(chosen[selected], first[selected])
    # A receiver in no sphere is shaded by none (csmlab's "no cascade"); one in a sphere is refused only
    # where its filter taps would leave the box.
    assert np.all(chosen[first < 0] == -1) and np.mean(chosen[first >= 0] >= 0) > 0.99


def test_sphere_selection_needs_each_receivers_sphere():
    from csmlab.kernels.shadow import shadow_lookup

    with pytest.raises(ValueError, match="sphere_cascade"):
        shadow_lookup(np.zeros((1, 16, 16), np.float32), np.zeros((1, 2, 2), np.int64), np.zeros((1, 2), np.float32),
                      np.ones(2), splits=np.array([0.1, 10.0]), texel_area=np.ones(1), selection="sphere",
                      filter="pcf", radius=1, margin=2, blend_band=0.0, bits=8)
