"""Ray-traced hard shadow against the analytic shadow of a box on a plane."""

import numpy as np
import pytest

from csmlab.kernels.reference import hard_shadow
from csmlab.kernels.visibility import mesh_bvh
from csmlab.light import direction_from_angles
from csmlab.scene import Scene
from csmlab.scene.plane_box import plane_box

BOX_LO = np.array([-1.0, 0.0, -1.0])
BOX_HI = np.array([1.0, 2.0, 1.0])


def ray_meets_box(points, toward, lo, hi):
    """Whether ``p + s·toward`` (s > 0) passes through the box [lo, hi] (slab test)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (lo - points) / toward
        t2 = (hi - points) / toward
    near = np.nanmax(np.minimum(t1, t2), axis=-1)
    far = np.nanmin(np.maximum(t1, t2), axis=-1)
    return (near <= far) & (far > 0)


@pytest.mark.parametrize("offset", [(0.0, 0.0, 0.0), (-3e5, 12.0, 1e5)], ids=["origin", "far"])
@pytest.mark.parametrize("elevation", [35.0, 70.0])
def test_ground_points_are_shadowed_exactly_where_the_box_blocks_the_light(offset, elevation):
    rng = np.random.default_rng(7)
    d = direction_from_angles(elevation_deg=elevation, azimuth_deg=40.0)
    s = plane_box(plane_size=40.0, box_size=2.0, box_height=2.0)
    scene = Scene(s.vertices + np.asarray(offset), s.triangles, s.normals, s.albedo)
    ground = np.column_stack([rng.uniform(-4, 4, 4000), np.zeros(4000), rng.uniform(-4, 4, 4000)])
    outside_box = ~np.all((ground > BOX_LO - 1e-3) & (ground < BOX_HI + 1e-3), axis=1)
    ground = ground[outside_box]
    shadowed = ray_meets_box(ground, -d, BOX_LO, BOX_HI)
    # Points within a millimetre of the shadow's edge are not compared.
    robust = shadowed == ray_meets_box(ground, -d, BOX_LO - 1e-3, BOX_HI + 1e-3)
    robust &= shadowed == ray_meets_box(ground, -d, BOX_LO + 1e-3, BOX_HI - 1e-3)
    normals = np.tile(np.float32([0.0, 1.0, 0.0]), (ground.shape[0], 1))
    lit = hard_shadow(mesh_bvh(scene.vertices, scene.triangles), points=ground + offset, normals=normals,
                      light_direction=d)
    assert lit.dtype == np.float32
    assert 0.02 < shadowed[robust].mean() < 0.5
    np.testing.assert_array_equal(lit[robust], np.where(shadowed[robust], 0.0, 1.0))


def test_faces_turned_from_the_light_are_shadowed_and_the_top_is_lit():
    d = direction_from_angles(elevation_deg=50.0, azimuth_deg=0.0)
    s = plane_box(plane_size=40.0, box_size=2.0, box_height=2.0)
    points = np.array([[0.2, 2.0, 0.3], [0.0, 1.0, -1.0], [0.0, 1.0, 1.0]])
    normals = np.float32([[0, 1, 0], [0, 0, -1], [0, 0, 1]])
    lit = hard_shadow(mesh_bvh(s.vertices, s.triangles), points=points, normals=normals, light_direction=d)
    # d = -(0, sin 50°, cos 50°): the light comes from +z, so the -z face is turned away.
    np.testing.assert_array_equal(lit, [1.0, 0.0, 1.0])


def test_points_that_are_not_receivers_give_nan_and_keep_their_shape():
    s = plane_box(plane_size=40.0)
    points = np.full((2, 3, 3), np.nan)
    points[0, 1] = [5.0, 0.0, 5.0]
    normals = np.zeros((2, 3, 3), dtype=np.float32)
    normals[0, 1] = [0, 1, 0]
    lit = hard_shadow(mesh_bvh(s.vertices, s.triangles), points=points, normals=normals, light_direction=[0, -1, 0])
    assert lit.shape == (2, 3)
    assert lit[0, 1] == 1.0 and np.isnan(lit).sum() == 5
