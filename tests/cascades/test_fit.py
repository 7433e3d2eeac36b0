"""Slice intervals: what view depths each cascade's box must hold, by fit and blend band (hand-worked cases)."""

import numpy as np
import pytest

from csmlab.cascades.fit import slice_intervals

SPLITS = np.array([0.5, 10.0, 30.0, 100.0])


def test_cascade_fit_takes_each_split_interval():
    np.testing.assert_array_equal(slice_intervals(SPLITS, method="cascade"),
                                  [[0.5, 10.0], [10.0, 30.0], [30.0, 100.0]])


def test_scene_fit_starts_every_cascade_at_the_near_plane():
    np.testing.assert_array_equal(slice_intervals(SPLITS, method="scene"),
                                  [[0.5, 10.0], [0.5, 30.0], [0.5, 100.0]])


def test_blend_band_starts_later_cascades_earlier_by_a_fraction_of_the_previous_one():
    # b = 0.1: cascade 1 starts 0.1 · (10 − 0.5) = 0.95 m early, cascade 2 0.1 · (30 − 10) = 2 m early.
    np.testing.assert_allclose(slice_intervals(SPLITS, method="cascade", blend_band=0.1),
                               [[0.5, 10.0], [9.05, 30.0], [28.0, 100.0]], rtol=0, atol=1e-12)
    # A scene fit already starts at the near plane: the band changes nothing.
    np.testing.assert_array_equal(slice_intervals(SPLITS, method="scene", blend_band=0.1),
                                  slice_intervals(SPLITS, method="scene"))


def test_unknown_fit_lists_the_known_ones():
    with pytest.raises(ValueError, match=r"fit: expected one of \['cascade', 'cascade_lerp', 'scene'\]"):
        slice_intervals(SPLITS, method="tight")


def test_transitions_place_each_band_where_its_engine_does():
    from csmlab.cascades.fit import transition_bands

    inf = np.inf
    # backward (csmlab, DirectX, Stride): the last b of cascade i's width, ending at its split.
    select, start = transition_bands(SPLITS, blend_band=0.1, transition="backward")
    np.testing.assert_array_equal(select, SPLITS)
    np.testing.assert_allclose(start, [9.05, 28.0, inf])
    # far_bound (Bevy): from (1 - b) · z_i+1 to z_i+1.
    select, start = transition_bands(SPLITS, blend_band=0.2, transition="far_bound")
    np.testing.assert_array_equal(select, SPLITS)
    np.testing.assert_allclose(start, [8.0, 24.0, inf])
    np.testing.assert_allclose(slice_intervals(SPLITS, method="cascade", blend_band=0.2, transition="far_bound"),
                               [[0.5, 10.0], [8.0, 30.0], [24.0, 100.0]])
    # forward (Unreal): cascade i reaches b · (z_i+1 - z_i) past its split, and is read there.
    select, start = transition_bands(SPLITS, blend_band=0.1, transition="forward")
    np.testing.assert_allclose(select, [0.5, 10.95, 32.0, 100.0])
    np.testing.assert_allclose(start, [10.0, 30.0, inf])
    np.testing.assert_allclose(slice_intervals(SPLITS, method="cascade", blend_band=0.1, transition="forward"),
                               [[0.5, 10.95], [10.0, 32.0], [30.0, 100.0]])
    # No band: the splits, and no cascade starts one.
    select, start = transition_bands(SPLITS, blend_band=0.0, transition="forward")
    np.testing.assert_array_equal(select, SPLITS)
    assert np.all(np.isinf(start))
    with pytest.raises(ValueError, match="transition: expected one of"):
        transition_bands(SPLITS, blend_band=0.1, transition="sideways")


def _footprint(centre, radius):
    from csmlab.cascades.stabilize import SliceFootprint

    return SliceFootprint(lo=np.asarray(centre) - radius, hi=np.asarray(centre) + radius, centre=np.asarray(centre),
                          radius=radius, frustum_extent=np.array([1.0, 1.0]))


def test_centroid_extent_is_the_corners_average_and_farthest_corner():
    from csmlab.camera import CameraPose
    from csmlab.cascades.extent import extent_centroid, extent_sphere
    from csmlab.geometry import light_basis

    pose = CameraPose(position=[1.0, 2.0, 3.0], orientation=[0.0, 0.0, 0.0, 1.0], fov_y_deg=60.0, aspect=16 / 9)
    ty = np.tan(np.radians(30.0))
    tx = ty * 16 / 9
    corners = np.array([[sx * z * tx, sy * z * ty, -z] for z in (0.1, 10.0) for sx in (-1, 1) for sy in (-1, 1)])
    corners += pose.position
    centre = corners.mean(axis=0)
    radius = np.linalg.norm(corners - centre, axis=1).max()
    basis = light_basis([-0.383, -0.643, -0.663])
    got_centre, got_radius = extent_centroid(pose=pose, basis=basis, z_near=0.1, z_far=10.0, corners=corners @ basis.T)
    np.testing.assert_allclose(got_centre, (basis @ centre)[:2], rtol=1e-12)
    assert radius <= got_radius <= radius * (1 + 2.0 ** -11)
    # Larger than the smallest sphere: +8.5 % for a 0.1–10 m slice at 60°, 16:9.
    _, smallest = extent_sphere(pose=pose, basis=basis, z_near=0.1, z_far=10.0, corners=corners @ basis.T)
    assert got_radius / smallest == pytest.approx(1.085, abs=0.001)


@pytest.mark.parametrize("margin", [0, 1, 2, 3])
def test_nearest2_snap_rounds_godots_edges_to_two_texels_and_holds_the_sphere(margin):
    from csmlab.cascades.stabilize import snap_nearest2

    resolution, radius = 64, 10.0
    size = resolution - 2 * margin                     # Godot's map, the margins laid outside it
    for c in np.linspace(-7.3, 7.3, 41) + 0.0123:  # off the ties, where float noise picks the side
        texel, origin = snap_nearest2(_footprint([c, 2 * c], radius), resolution=resolution, margin=margin)
        wide = radius * size / (size - 2.0)            # radius *= size / (size - 2)
        t = 2.0 * wide / size
        unit = 4.0 * wide / size
        edge = np.floor((np.array([c, 2 * c]) - wide) / unit + 0.5) * unit   # Math::snapped(c - r', unit)
        np.testing.assert_allclose(texel, [t, t], rtol=1e-12)
        np.testing.assert_allclose((origin + margin) * texel, edge, rtol=1e-9, atol=1e-9)
        assert np.all((origin + margin) % 2 == 0)
        lo, hi = origin * texel, (origin + resolution) * texel
        assert np.all(lo + margin * texel <= np.array([c, 2 * c]) - radius + 1e-9)
        assert np.all(hi - margin * texel >= np.array([c, 2 * c]) + radius - 1e-9)


def test_centre_nearest_snap_rounds_the_centre_to_the_nearest_texel():
    from csmlab.cascades.stabilize import snap_centre, snap_centre_nearest

    resolution, margin, radius = 64, 2, 10.0
    for c in np.linspace(-7.3, 7.3, 37) + 0.0123:
        texel, origin = snap_centre_nearest(_footprint([c, -c], radius), resolution=resolution, margin=margin)
        floor_texel, _ = snap_centre(_footprint([c, -c], radius), resolution=resolution, margin=margin)
        np.testing.assert_array_equal(texel, floor_texel)
        # Stride: the projection's translation in pixels rounded (Round), so the box centre is the nearest texel.
        centre = (origin + resolution // 2) * texel
        assert np.all(np.abs(centre - [c, -c]) <= 0.5 * texel + 1e-12)
        np.testing.assert_array_equal(origin + resolution // 2, np.floor(np.array([c, -c]) / texel + 0.5))
        lo, hi = origin * texel, (origin + resolution) * texel
        assert (np.all(lo + margin * texel <= np.array([c, -c]) - radius)
                and np.all(hi - margin * texel >= np.array([c, -c]) + radius))


def test_transition_bands_hand_back_a_copy_of_the_splits():
    """The lookup opens the last interval (outside = "last") on what it gets: the cascades' splits must not change."""
    from csmlab.cascades.fit import transition_bands

    splits = np.array([0.1, 10.0, 40.0, 200.0])
    for transition in ("backward", "far_bound", "forward"):
        select, _ = transition_bands(splits, blend_band=0.2, transition=transition)
        select[-1] = np.inf
        np.testing.assert_array_equal(splits, [0.1, 10.0, 40.0, 200.0])
