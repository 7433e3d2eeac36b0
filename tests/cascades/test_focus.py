"""Scene focus (csmlab.cascades.focus): the slice clipped to the scene's light-space box, against dense sampling."""

import numpy as np

from csmlab.camera import CameraPose
from csmlab.cascades import build_cascades
from csmlab.cascades.focus import frustum_box_intersection
from csmlab.geometry import frustum_slice_corners, light_basis, rotation_looking_at
from csmlab.light import direction_from_angles
from csmlab.settings import ShadowSettings

LIGHT = direction_from_angles(elevation_deg=40.0, azimuth_deg=30.0)


def _slice(z_near=0.5, z_far=80.0):
    pose = CameraPose(position=np.array([3.0, 2.0, 1.0]), orientation=rotation_looking_at(np.array([0.4, -0.3, -1.0])),
                      aspect=16 / 9, near=0.1, far=400.0)
    basis = light_basis(LIGHT)
    corners = frustum_slice_corners(position=pose.position, orientation=pose.orientation, fov_y_deg=pose.fov_y_deg,
                                    aspect=pose.aspect, z_near=z_near, z_far=z_far)
    return pose, basis, corners @ basis.T


def _sampled_slice(corners, count=40):
    """Points filling the slice: trilinear in its corners (near quad 0–3, far quad 4–7)."""
    s, t, u = np.meshgrid(*(np.linspace(0.0, 1.0, count),) * 3, indexing="ij")
    s, t, u = s.ravel()[:, None], t.ravel()[:, None], u.ravel()[:, None]

    def quad(q):
        return (1 - s) * (1 - t) * q[0] + s * (1 - t) * q[1] + s * t * q[2] + (1 - s) * t * q[3]

    return (1 - u) * quad(corners[:4]) + u * quad(corners[4:])


def test_a_box_holding_the_whole_slice_leaves_its_eight_corners():
    _, _, corners = _slice()
    hull = frustum_box_intersection(corners, corners.min(axis=0) - 1.0, corners.max(axis=0) + 1.0)
    assert hull.shape == (8, 3)
    np.testing.assert_allclose(np.sort(hull, axis=0), np.sort(corners, axis=0))


def test_the_clipped_hull_has_the_bounds_of_the_slice_points_inside_the_box():
    _, _, corners = _slice()
    centre = corners.mean(axis=0)
    lo, hi = centre - [25.0, 8.0, 30.0], centre + [10.0, 30.0, 5.0]
    hull = frustum_box_intersection(corners, lo, hi)
    assert np.all(hull >= lo - 1e-3) and np.all(hull <= hi + 1e-3)
    dense = _sampled_slice(corners)
    inside = dense[np.all((dense >= lo) & (dense <= hi), axis=1)]
    # The sampled bounds lie within the hull's, short of it by at most a sample spacing.
    spacing = np.ptp(corners, axis=0) / 39.0
    assert np.all(hull.min(axis=0) <= inside.min(axis=0) + 1e-9)
    assert np.all(hull.max(axis=0) >= inside.max(axis=0) - 1e-9)
    assert np.all(inside.min(axis=0) - hull.min(axis=0) <= spacing)
    assert np.all(hull.max(axis=0) - inside.max(axis=0) <= spacing)


def test_scene_focus_shrinks_a_tight_box_to_the_scene_and_leaves_a_slice_inside_it_alone():
    pose, _, _ = _slice()
    small = np.array([[x, y, z] for x in (-20, 20) for y in (-1, 5) for z in (-40, 10)], dtype=float)
    large = small * 100.0
    built = {}
    for name, scene in (("small", small), ("large", large)):
        for focus in ("slice", "scene"):
            built[name, focus] = build_cascades(pose=pose, light_direction=LIGHT, scene_corners=scene,
                                                settings=ShadowSettings(stabilization="none", focus=focus,
                                                                        shadow_distance=150.0))
    for c in range(4):
        assert np.all(built["small", "scene"].cascades[c].extent <= built["small", "slice"].cascades[c].extent + 1e-9)
        np.testing.assert_array_equal(built["large", "scene"].cascades[c].extent,
                                      built["large", "slice"].cascades[c].extent)
    assert np.any(built["small", "scene"].cascades[3].extent < 0.8 * built["small", "slice"].cascades[3].extent)
