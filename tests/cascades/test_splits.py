"""Split schemes against the whitepaper's formulas (seed 000), written out independently here."""

import math

import numpy as np
import pytest

from csmlab.cascades.splits import SPLIT_METHODS, split_distances


@pytest.mark.parametrize("n, f, count, lam", [(0.1, 200.0, 4, 0.75), (0.5, 1000.0, 3, 0.5), (1.0, 50.0, 8, 0.9),
                                              (0.05, 120.0, 1, 0.3)])
def test_log_and_practical_match_the_whitepaper(n, f, count, lam):
    log = [n * math.pow(f / n, i / count) for i in range(count + 1)]
    uni = [n + (f - n) * i / count for i in range(count + 1)]
    practical = [lam * a + (1 - lam) * b for a, b in zip(log, uni)]
    np.testing.assert_allclose(split_distances(near=n, far=f, count=count, method="log"), log, rtol=1e-12)
    np.testing.assert_allclose(split_distances(near=n, far=f, count=count, method="uniform"), uni, rtol=1e-12)
    np.testing.assert_allclose(split_distances(near=n, far=f, count=count, method="practical", lambda_=lam),
                               practical, rtol=1e-12)


def test_every_scheme_is_increasing_from_near_to_far():
    for method in ("uniform", "log", "practical"):
        z = split_distances(near=0.1, far=300.0, count=5, method=method)
        assert z[0] == 0.1 and z[-1] == 300.0 and np.all(np.diff(z) > 0)


def test_manual_accepts_distances_and_fractions():
    metres = split_distances(near=0.1, far=100.0, count=3, method="manual", splits=[10.0, 40.0, 100.0])
    fractions = split_distances(near=0.1, far=100.0, count=3, method="manual", splits=[0.1, 0.4, 1.0])
    np.testing.assert_allclose(metres, [0.1, 10.0, 40.0, 100.0])
    np.testing.assert_allclose(fractions, metres)


@pytest.mark.parametrize("splits, match", [([10.0, 5.0, 100.0], "increasing"), ([10.0, 100.0], "3 far ends"),
                                           ([10.0, 20.0, 30.0], "shadow distance")])
def test_manual_rejects_bad_lists(splits, match):
    with pytest.raises(ValueError, match=match):
        split_distances(near=0.1, far=100.0, count=3, method="manual", splits=splits)


def test_unknown_scheme_lists_the_valid_ones():
    with pytest.raises(ValueError, match="practical"):
        split_distances(near=0.1, far=100.0, count=3, method="pssm")
    assert set(SPLIT_METHODS) == {"uniform", "log", "practical", "manual", "manual_range", "exponent", "geometric"}


@pytest.mark.parametrize("near, far", [(0.0, 100.0), (-1.0, 100.0), (5.0, 5.0), (5.0, 1.0)])
def test_bad_planes_name_the_field(near, far):
    with pytest.raises(ValueError, match="near|shadow_distance"):
        split_distances(near=near, far=far, count=4)


def test_exponent_is_unreals_geometric_series():
    """FDirectionalLightSceneProxy::GetSplitDistance: each cascade CascadeDistributionExponent times deeper.

    Hand-worked: n = 1, f = 15, C = 3, e = 2 → (2^i − 1)/(2^3 − 1) = 0, 1/7, 3/7, 1 → 1, 3, 7, 15 m.
    """
    np.testing.assert_allclose(split_distances(near=1.0, far=15.0, count=3, method="exponent",
                                               distribution_exponent=2.0), [1.0, 3.0, 7.0, 15.0], rtol=1e-12)
    # Unreal's defaults (DirectionalLightComponent.h): DynamicShadowCascades = 3,
    # CascadeDistributionExponent = 3.0, DynamicShadowDistanceMovableLight = 20000 cm; near 0.1 m.
    z = split_distances(near=0.1, far=200.0, count=3, method="exponent", distribution_exponent=3.0)
    np.testing.assert_allclose(z, [0.1, 0.1 + 199.9 / 13, 0.1 + 199.9 * 4 / 13, 200.0], rtol=1e-12)
    np.testing.assert_allclose(split_distances(near=0.1, far=50.0, count=4, method="exponent",
                                               distribution_exponent=1.0),
                               split_distances(near=0.1, far=50.0, count=4, method="uniform"), rtol=1e-12)


def test_geometric_is_bevys_first_bound_then_geometric_spacing():
    """bevy_light cascade.rs calculate_cascade_bounds: bound_i = b · ((max / b)^(1/(C−1)))^i.

    CascadeShadowConfigBuilder::default(): num_cascades 4, minimum_distance 0.1, maximum_distance 150,
    first_cascade_far_bound 10, overlap_proportion 0.2. Base = 15^(1/3).
    """
    base = 15.0 ** (1.0 / 3.0)
    z = split_distances(near=0.1, far=150.0, count=4, method="geometric", first_cascade_far=10.0)
    np.testing.assert_allclose(z, [0.1, 10.0, 10.0 * base, 10.0 * base * base, 150.0], rtol=1e-12)
    np.testing.assert_allclose(split_distances(near=0.1, far=150.0, count=1, method="geometric"), [0.1, 150.0])
    with pytest.raises(ValueError, match="first_cascade_far"):
        split_distances(near=0.1, far=8.0, count=4, method="geometric", first_cascade_far=10.0)


def test_ten_cascades_are_accepted():
    z = split_distances(near=0.1, far=500.0, count=10, method="exponent", distribution_exponent=1.5)
    assert z.shape == (11,) and np.all(np.diff(z) > 0)


@pytest.mark.parametrize("near, far, fractions", [(0.1, 100.0, (0.1, 0.2, 0.5, 1.0)),
                                                  (0.25, 250.0, (0.05, 0.15, 0.5, 1.0))])
def test_manual_range_places_fractions_over_the_range_from_near(near, far, fractions):
    # Godot renderer_scene_cull.cpp: distances[i + 1] = min_distance + split * (max_distance - min_distance);
    # MJP MeshRenderer.cpp: camera.NearClip() + splitDist * (FarClip - NearClip).
    expected = [near] + [near + s * (far - near) for s in fractions]
    got = split_distances(near=near, far=far, count=len(fractions), method="manual_range", splits=fractions)
    np.testing.assert_allclose(got, expected, rtol=1e-12)
    # Not manual's fractions of far alone.
    manual = split_distances(near=near, far=far, count=len(fractions), method="manual", splits=fractions)
    assert not np.allclose(got[1:-1], manual[1:-1])


def test_manual_range_refuses_fractions_that_do_not_end_at_one():
    with pytest.raises(ValueError, match="splits: expected increasing fractions"):
        split_distances(near=0.1, far=100.0, count=3, method="manual_range", splits=(0.1, 0.5, 0.9))
    with pytest.raises(ValueError, match="splits: expected 3 fractions"):
        split_distances(near=0.1, far=100.0, count=3, method="manual_range", splits=(0.5, 1.0))
