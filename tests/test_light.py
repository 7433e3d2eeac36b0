"""The light: angles to a direction, and a sun that moves linearly in elevation and azimuth."""

import numpy as np
import pytest

from csmlab.light import LightPath, direction_from_angles


def test_angles_give_the_direction_from_the_light_toward_the_scene():
    np.testing.assert_allclose(direction_from_angles(elevation_deg=90.0, azimuth_deg=123.0), [0, -1, 0], atol=1e-15)
    # A sun 30° up in the +X direction (azimuth 90°) shines down and toward −X.
    np.testing.assert_allclose(direction_from_angles(elevation_deg=30.0, azimuth_deg=90.0),
                               [-np.sqrt(3) / 2, -0.5, 0.0], atol=1e-15)


def test_sun_moves_linearly_in_angles_from_the_first_frame_to_the_last():
    path = LightPath.sun(elevation_deg=60.0, azimuth_deg=0.0, elevation_end_deg=0.0, azimuth_end_deg=90.0, frames=4)
    assert len(path) == 4 and not path.is_static
    # Frames at s = 0, 1/3, 2/3, 1: elevation 60, 40, 20, 0 and azimuth 0, 30, 60, 90, written out.
    for frame, (el, az) in enumerate([(60, 0), (40, 30), (20, 60), (0, 90)]):
        e, a = np.radians(el), np.radians(az)
        expected = -np.array([np.cos(e) * np.sin(a), np.sin(e), np.cos(e) * np.cos(a)])
        np.testing.assert_allclose(path.direction(frame), expected, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(path.directions, axis=1), 1.0, atol=1e-15)


def test_a_sun_that_does_not_move_is_static_and_one_frame_is_its_start():
    still = LightPath.sun(elevation_deg=40.0, azimuth_deg=30.0, elevation_end_deg=40.0, azimuth_end_deg=30.0, frames=5)
    assert still.is_static
    one = LightPath.sun(elevation_deg=40.0, azimuth_deg=30.0, elevation_end_deg=10.0, azimuth_end_deg=0.0, frames=1)
    np.testing.assert_array_equal(one.directions, [direction_from_angles(elevation_deg=40.0, azimuth_deg=30.0)])


def test_elevation_outside_the_sky_is_refused():
    with pytest.raises(ValueError, match="elevation_deg"):
        LightPath.sun(elevation_deg=40.0, azimuth_deg=0.0, elevation_end_deg=120.0, azimuth_end_deg=0.0, frames=3)
