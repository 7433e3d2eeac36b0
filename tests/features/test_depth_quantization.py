"""Per-cascade unorm depth (``depth_quantization = "cascade"``): each box's own near/far divided into 2^b − 1 steps."""

from __future__ import annotations

import numpy as np
import pytest

from csmlab.camera import CameraPose
from csmlab.geometry import rotation_looking_at
from csmlab.light import direction_from_angles
from csmlab.render import prepare_scene, render_shadow, render_view
from csmlab.scene import Scene
from csmlab.settings import ShadowSettings
from csmlab.storage import DEPTH_QUANTIZATION_METHODS, cascade_stored_depth, depth_step, stored_depth


@pytest.mark.parametrize(("depth_format", "bits"), [("unorm16", 16), ("unorm24", 24)])
def test_each_cascade_stores_the_nearest_of_its_own_2_to_the_b_levels(depth_format, bits):
    """A unorm depth buffer stores round(z_ndc · (2^b − 1)) with z_ndc = (z − near) / (far − near)."""
    rng = np.random.default_rng(5)
    near = np.array([3.0, 10.0, -20.0])
    far = np.array([3.0 + 65.535, 210.0, 380.0])
    z = near[:, None, None] + rng.uniform(0.0, 1.0, (3, 8, 8)) * (far - near)[:, None, None]
    z = z.astype(np.float32)
    stored = cascade_stored_depth(z, near=near, far=far, depth_format=depth_format)
    for c in range(3):
        levels = 2.0**bits - 1.0
        ndc = (z[c].astype(np.float64) - near[c]) / (far[c] - near[c])
        expected = near[c] + np.round(ndc * levels) / levels * (far[c] - near[c])
        np.testing.assert_allclose(stored[c], expected.astype(np.float32), rtol=0, atol=1e-6 * abs(far[c]))
        step = (far[c] - near[c]) / levels
        assert np.max(np.abs(stored[c].astype(np.float64) - z[c])) <= 0.5 * step + 4e-7 * abs(far[c])
    # The first box: 65.535 m over 65535 steps of unorm16, a millimetre.
    if bits == 16:
        assert (far[0] - near[0]) / (2**16 - 1) == pytest.approx(1e-3)
        assert stored[0, 0, 0] == pytest.approx(round(float(z[0, 0, 0]) - 3.0, 3) + 3.0, abs=2e-6)


def test_a_caster_beyond_the_far_side_stores_the_far_side_and_empty_texels_stay_empty():
    z = np.array([[[np.inf, 5.0], [12.0, -1.0]]], dtype=np.float32)
    stored = cascade_stored_depth(z, near=[0.0], far=[10.0], depth_format="unorm16")
    assert np.isinf(stored[0, 0, 0]) and stored[0, 1, 0] == 10.0 and stored[0, 1, 1] == 0.0
    assert stored[0, 0, 1] == pytest.approx(5.0, abs=10.0 / 65535)


def test_float32_is_stored_as_rasterized():
    z = np.random.default_rng(1).uniform(0, 9, (2, 4, 4)).astype(np.float32)
    np.testing.assert_array_equal(cascade_stored_depth(z, near=[0.0, 1.0], far=[9.0, 9.0], depth_format="float32"), z)


def test_a_near_cascade_is_far_finer_than_the_scene_span():
    """A 40 m deep near box in a 600 m scene: 15× finer levels than the scene's power-of-two step."""
    span, near, far = 600.0, 100.0, 140.0
    scene = depth_step(span, depth_format="unorm16")
    cascade = (far - near) / (2**16 - 1)
    assert scene / cascade > 15.0
    z = np.full((1, 2, 2), 120.00037, dtype=np.float32)
    assert abs(cascade_stored_depth(z, near=[near], far=[far], depth_format="unorm16")[0, 0, 0] - z[0, 0, 0]) \
        <= cascade / 2 + 1e-5
    assert abs(stored_depth(z, span=span, depth_format="unorm16")[0, 0, 0] - z[0, 0, 0]) <= scene / 2


def test_a_box_with_no_depth_is_refused():
    with pytest.raises(ValueError, match="far > near"):
        cascade_stored_depth(np.zeros((1, 2, 2), np.float32), near=[1.0], far=[1.0], depth_format="unorm16")


def test_the_choices_are_registered_and_scene_is_the_default():
    assert sorted(DEPTH_QUANTIZATION_METHODS) == ["cascade", "scene"]
    assert ShadowSettings().depth_quantization == "scene"


def test_the_cascade_pass_stores_each_map_over_its_own_box(device):
    """render: the unorm16 maps of depth_quantization = "cascade" are the float32 maps quantized over each
    box's depth_near/depth_far (less zref); "scene" keeps the scene span's steps."""
    vertices = np.array([[-30, 0, -30], [30, 0, -30], [30, 0, 30], [-30, 0, 30],
                         [-1, 2, -1], [1, 2, -1], [1, 2, 1], [-1, 2, 1]], float)
    scene = Scene.from_triangles(vertices, np.array([[0, 2, 1], [0, 3, 2], [4, 6, 5], [4, 7, 6]]))
    dscene = prepare_scene(scene, device=device)
    light = direction_from_angles(elevation_deg=50.0, azimuth_deg=20.0)
    eye = np.array([4.0, 3.0, 8.0])
    pose = CameraPose(position=eye, orientation=rotation_looking_at(-eye), aspect=1.6, near=0.1, far=60.0)
    view = render_view(dscene, pose, light, width=32, height=20)
    base = ShadowSettings(cascades=3, resolution=64, shadow_distance=40.0, depth_range="slice", pancake=5.0)
    exact = render_shadow(dscene, view, base).maps
    cascade = render_shadow(dscene, view, base.replace(depth_format="unorm16", depth_quantization="cascade")).maps
    scene_wide = render_shadow(dscene, view, base.replace(depth_format="unorm16")).maps
    boxes = exact.cascades
    near = [c.depth_near - boxes.zref for c in boxes.cascades]
    far = [c.depth_far - boxes.zref for c in boxes.cascades]
    np.testing.assert_array_equal(cascade.depth, cascade_stored_depth(exact.depth, near=near, far=far,
                                                                      depth_format="unorm16"))
    np.testing.assert_array_equal(scene_wide.depth, stored_depth(exact.depth, span=exact.depth_span,
                                                                 depth_format="unorm16"))
    assert not np.array_equal(cascade.depth, scene_wide.depth)


def _numpy_levels(maps, *, lo, step, top):
    """The quantization in NumPy's float64 arithmetic, as csmlab.storage stated it before its kernel: the oracle."""
    levels = np.clip(np.rint((maps.astype(np.float64) - lo) / step), 0.0, top)
    return np.where(np.isfinite(maps), lo + levels * step, maps).astype(np.float32)


@pytest.mark.parametrize("depth_format", ["unorm16", "unorm24"])
def test_the_quantization_kernel_gives_numpys_bits_beyond_the_range_at_signed_zeros_and_on_empty_texels(depth_format):
    rng = np.random.default_rng(9)
    z = rng.uniform(-30.0, 400.0, (3, 40, 33)).astype(np.float32)
    z[:, 0] = np.inf
    z[:, 1, :4] = [-0.0, 0.0, np.nan, -np.inf]
    z[:, 2] = rng.uniform(-1e-4, 1e-4, 33)
    near = np.array([-5.0, 0.0, 12.3])
    far = np.array([80.0, 200.0, 99.9])
    top = float(2 ** {"unorm16": 16, "unorm24": 24}[depth_format] - 1)
    per_cascade = cascade_stored_depth(z, near=near, far=far, depth_format=depth_format)
    expected = _numpy_levels(z, lo=near[:, None, None], step=((far - near) / top)[:, None, None], top=top)
    assert np.array_equal(per_cascade.view(np.uint32), expected.view(np.uint32))
    step = depth_step(350.0, depth_format=depth_format)
    levels = np.clip(np.rint(z.astype(np.float64) / step), 0.0, top)
    scene = np.where(np.isfinite(z), levels * step, z).astype(np.float32)
    assert np.array_equal(stored_depth(z, span=350.0, depth_format=depth_format).view(np.uint32), scene.view(np.uint32))
    assert np.signbit(stored_depth(z, span=350.0, depth_format=depth_format)[0, 1, 0])
    assert np.array_equal(stored_depth(z[1, 2], span=350.0, depth_format=depth_format), scene[1, 2])


def unorm16_stored(maps, scheme: str, **how) -> np.ndarray:
    """``maps`` ``(3, R, R)`` stored as unorm16 by the ``scene`` scheme (a 350 m span) or the ``cascade`` one (each
    cascade's own near and far, across and beyond the test depths)."""
    if scheme == "scene":
        return stored_depth(maps, span=350.0, depth_format="unorm16", **how)
    return cascade_stored_depth(maps, near=np.array([-5.0, 0.0, 12.3]), far=np.array([80.0, 200.0, 99.9]),
                                depth_format="unorm16", **how)


@pytest.mark.parametrize("scheme", ["scene", "cascade"])
def test_quantizing_in_place_gives_the_same_bits_and_leaves_read_only_maps_as_they_were(scheme):
    rng = np.random.default_rng(10)
    z = rng.uniform(-30.0, 400.0, (3, 24, 24)).astype(np.float32)
    z[:, 0] = np.inf

    def stored(maps, **how):
        return unorm16_stored(maps, scheme, **how)

    fresh = stored(z)
    own = z.copy()
    in_place = stored(own, overwrite=True)
    assert np.shares_memory(in_place, own) and np.array_equal(in_place.view(np.uint32), fresh.view(np.uint32))
    kept = z.copy()
    kept.flags.writeable = False
    assert np.array_equal(stored(kept, overwrite=True).view(np.uint32), fresh.view(np.uint32))
    assert np.array_equal(kept.view(np.uint32), z.view(np.uint32))
