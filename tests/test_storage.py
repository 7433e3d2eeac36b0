"""Stored depth precision (steps by hand, error against the reference rising with depth range) and allocated memory."""

import numpy as np
import pytest

from csmlab.camera import CameraPose
from csmlab.geometry import rotation_looking_at
from csmlab.metrics.cost import shadow_memory_bytes
from csmlab.render import lookup_shadow, prepare_scene, render_shadow, render_view
from csmlab.frame import ShadowMaps
from csmlab.scene import make_scene
from csmlab.settings import ShadowSettings
from csmlab.storage import depth_step, memory_bytes, stored_depth, texel_bytes


def test_depth_step_is_the_power_of_two_at_or_above_span_over_the_levels():
    # 100 m over 65,535 steps is 1.526 mm: the next power of two is 2^-9 m = 1.953 mm.
    assert depth_step(100.0, depth_format="unorm16") == 2.0**-9
    # 100 m over 2^24 − 1 steps is 5.96 µm: 2^-17 m = 7.63 µm.
    assert depth_step(100.0, depth_format="unorm24") == 2.0**-17
    assert depth_step(100.0, depth_format="float32") == 0.0
    with pytest.raises(ValueError, match="unorm16"):
        depth_step(100.0, depth_format="d16")


def test_stored_depth_rounds_to_the_nearest_level_and_keeps_empty_texels():
    rng = np.random.default_rng(3)
    depth = rng.uniform(0.0, 100.0, (2, 8, 8)).astype(np.float32)
    depth[0, 0, 0] = np.inf
    stored = stored_depth(depth, span=100.0, depth_format="unorm16")
    step = 2.0**-9
    finite = np.isfinite(depth)
    assert np.all(np.abs(stored[finite].astype(np.float64) - depth[finite]) <= step / 2)
    assert np.all(np.mod(stored[finite].astype(np.float64), step) == 0.0)
    assert stored[0, 0, 0] == np.inf
    np.testing.assert_array_equal(stored_depth(depth, span=100.0, depth_format="float32"), depth)


def test_quantization_is_unchanged_by_a_shift_of_the_whole_map():
    # Levels sit at multiples of a step from zref, not from the box: a moved box stores the same values.
    depth = np.random.default_rng(1).uniform(0, 50, (1, 16, 16)).astype(np.float32)
    a = stored_depth(depth, span=60.0, depth_format="unorm16")
    b = stored_depth(np.roll(depth, (3, -5), axis=(1, 2)), span=60.0, depth_format="unorm16")
    np.testing.assert_array_equal(np.roll(a, (3, -5), axis=(1, 2)), b)


def test_unorm16_reference_error_rises_over_float32_monotonically_with_depth_range():
    dscene = prepare_scene(make_scene("plane_box", plane_size=40.0, box_size=2.0))
    position = np.array([6.0, 5.0, 9.0])
    pose = CameraPose(position=position, orientation=rotation_looking_at(-position), fov_y_deg=60.0,
                      aspect=4 / 3, near=0.1, far=100.0)
    view = render_view(dscene, pose, [0.4, -0.8, 0.3], width=96, height=72)
    settings = ShadowSettings(cascades=2, resolution=512, filter="none", shadow_distance=40.0)
    frame = render_shadow(dscene, view, settings)
    g, valid = view.gbuffer, view.gbuffer.valid

    def error(depth):
        maps = ShadowMaps(cascades=frame.maps.cascades, depth=depth, texels_rasterized=0)
        lit = lookup_shadow(maps, points=g.position, normals=g.normal, view_depth=g.view_depth,
                            settings=settings).lit
        return float(np.mean((lit[valid] > 0.5) != (view.reference[valid] > 0.5)))

    float_error = error(frame.maps.depth)
    spans = [1e2, 1e3, 1e4, 1e5]
    errors = [error(stored_depth(frame.maps.depth, span=s, depth_format="unorm16")) for s in spans]
    assert all(b >= a for a, b in zip(errors, errors[1:])), errors
    assert errors[-1] > float_error + 0.05, (float_error, errors)


def test_depth_format_sets_the_bytes_unless_depth_bytes_is_given():
    assert texel_bytes(ShadowSettings(depth_format="unorm16")) == 2
    assert texel_bytes(ShadowSettings(depth_format="unorm24")) == 4
    assert texel_bytes(ShadowSettings(depth_format="unorm16", depth_bytes=4)) == 4


def test_memory_counts_what_the_engine_allocates_padding_included():
    # Three 2048² float32 cascades: an array 3 slices, a 2×2 atlas 4 tiles (one empty), a 1×4 row too.
    base = ShadowSettings(cascades=3, resolution=2048, depth_format="float32")
    assert memory_bytes(base) == 3 * 2048 * 2048 * 4
    assert memory_bytes(base.replace(storage="atlas", atlas_layout="2x2")) == 4096 * 4096 * 4
    assert memory_bytes(base.replace(storage="atlas", atlas_layout="1x4")) == 8192 * 2048 * 4
    assert memory_bytes(base.replace(storage="atlas", atlas_layout="unigine")) == 4096 * 4096 * 4
    # Unequal cascades: every slice or tile takes the largest one's size.
    mixed = ShadowSettings(cascades=4, cascade_resolutions=(2048, 1024, 1024, 512), depth_format="unorm16")
    assert memory_bytes(mixed) == 4 * 2048 * 2048 * 2
    assert shadow_memory_bytes(mixed) == memory_bytes(mixed)


@pytest.mark.parametrize("field, value, expected", [
    ("depth_format", "d16", "float32, unorm24 or unorm16"),
    ("storage", "cube", "array or atlas"),
    ("atlas_layout", "3x3", "unigine"),
    ("cascade_resolutions", (1024, 512), "4 integers"),
])
def test_settings_reject_bad_storage_fields_naming_them(field, value, expected):
    with pytest.raises(ValueError, match=f"{field}: expected .*{expected}"):
        ShadowSettings(**{field: value}).validated()


def test_an_atlas_holds_at_most_four_cascades():
    with pytest.raises(ValueError, match="storage"):
        ShadowSettings(cascades=5, storage="atlas").validated()


def test_unequal_cascades_render_each_at_its_own_size_and_shade_as_the_uniform_ones_do():
    dscene = prepare_scene(make_scene("plane_box", plane_size=40.0, box_size=2.0))
    position = np.array([6.0, 5.0, 9.0])
    pose = CameraPose(position=position, orientation=rotation_looking_at(-position), fov_y_deg=60.0, aspect=4 / 3,
                      near=0.1, far=100.0)
    view = render_view(dscene, pose, [0.4, -0.8, 0.3], width=64, height=48)
    base = ShadowSettings(cascades=2, shadow_distance=24.0, split="uniform", filter="pcf_tent", filter_size=3)
    mixed = render_shadow(dscene, view, base.replace(cascade_resolutions=(512, 128)))
    large = render_shadow(dscene, view, base.replace(resolution=512))
    small = render_shadow(dscene, view, base.replace(resolution=128))
    assert mixed.maps.depth.shape == (2, 512, 512)
    assert [c.resolution for c in mixed.maps.cascades.cascades] == [512, 128]
    np.testing.assert_array_equal(mixed.maps.depth[0], large.maps.depth[0])
    np.testing.assert_array_equal(mixed.maps.depth[1, :128, :128], small.maps.depth[1])
    assert np.all(np.isinf(mixed.maps.depth[1, 128:])) and np.all(np.isinf(mixed.maps.depth[1, :, 128:]))
    assert mixed.maps.texels_rasterized < large.maps.texels_rasterized
    for c, uniform in ((0, large), (1, small)):
        same = (mixed.shadow.cascade == c) & (uniform.shadow.cascade == c)
        assert same.sum() > 100
        np.testing.assert_array_equal(mixed.shadow.lit[same], uniform.shadow.lit[same])
