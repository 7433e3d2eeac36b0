"""Unity HDRP's dithered cascade borders against its shader's formulas, written out per point."""

from __future__ import annotations

import math

import numpy as np
import pytest

from csmlab.cascades.borders import border_weights, dithered_sphere_cascades
from csmlab.config import load_experiment
from csmlab.errors import InputError
from csmlab.settings import ShadowSettings

CENTRES = np.array([[0.0, 0.0, -5.0], [0.0, 0.0, -15.0], [0.0, 0.0, -40.0], [0.0, 0.0, -100.0]])
RADII = np.array([6.0, 14.0, 32.0, 80.0])
BORDERS = (0.133, 0.067, 0.0, 0.0)  # DefaultSettingsVolumeProfile.asset cascadeShadowBorder0..3
EYE = np.zeros(3)


def _hdrp_alpha(point, eye, centres, radii, borders) -> tuple[int, float]:
    """HDShadowAlgorithms.hlsl EvalShadow_GetSplitIndex, one point at a time."""
    for i, (centre, radius) in enumerate(zip(centres, radii)):
        w = point - centre
        dist_sq = float(w @ w)
        rel = dist_sq / radius**2
        if 0.0 < rel <= 1.0:
            border = borders[i]
            break
    else:
        return -1, 0.0
    alpha = 0.0 if border <= 0.0 else min(max((rel - (1.0 - border)) / border, 0.0), 1.0)
    view = (eye - point) / np.linalg.norm(eye - point)
    casc_dot = float(view @ (w / math.sqrt(dist_sq)))
    t = min(max((border - 1.0) / (0.7 - 1.0), 0.0), 1.0)
    sharpness = 8.0 + 512.0 * t * t * (3.0 - 2.0 * t)
    return i, alpha + (0.0 - alpha) * min(max(casc_dot * sharpness, 0.0), 1.0)


def _first_spheres(points) -> np.ndarray:
    d = np.linalg.norm(points[:, None, :] - CENTRES[None], axis=2) ** 2 / RADII**2
    inside = (d > 0.0) & (d <= 1.0)
    return np.where(inside.any(axis=1), inside.argmax(axis=1), -1)


def test_border_weight_is_hdrps_alpha_with_its_view_side_attenuation():
    rng = np.random.default_rng(7)
    points = rng.uniform([-20.0, -5.0, -60.0], [20.0, 5.0, 0.0], (500, 3))
    cascade = _first_spheres(points)
    alpha = border_weights(cascade, points, centres=CENTRES, radii=RADII, borders=BORDERS, eye=EYE)
    expected = [_hdrp_alpha(p, EYE, CENTRES, RADII, BORDERS) for p in points]
    np.testing.assert_array_equal(cascade, [i for i, _ in expected])
    np.testing.assert_allclose(alpha, [a for _, a in expected], atol=1e-12)
    # The border dithers only on the sphere's far side from the camera: some points there have a weight.
    assert np.any(alpha > 0.0) and np.all(alpha[cascade >= 2] == 0.0)


def test_the_next_cascade_is_taken_where_the_noise_is_at_most_the_weight():
    point = np.array([[0.0, 0.0, -10.8]])          # cascade 0's far side: rel = 0.9, alpha = (0.9 − 0.867) / 0.133
    cascade = _first_spheres(point)
    alpha = border_weights(cascade, point, centres=CENTRES, radii=RADII, borders=BORDERS, eye=EYE)[0]
    assert cascade[0] == 0 and 0.0 < alpha < 1.0
    args = dict(centres=CENTRES, radii=RADII, borders=BORDERS, eye=EYE)
    assert dithered_sphere_cascades(cascade, point, noise=[alpha], **args)[0] == 1     # step(noise, alpha)
    assert dithered_sphere_cascades(cascade, point, noise=[np.nextafter(alpha, 1.0)], **args)[0] == 0
    # The same rel on the side toward a camera 3 m behind the sphere's near edge: attenuated to no dither.
    near_side = np.array([[0.0, 0.0, 0.9]])
    behind = {**args, "eye": np.array([0.0, 0.0, 3.0])}
    assert border_weights(_first_spheres(near_side), near_side, centres=CENTRES, radii=RADII, borders=BORDERS,
                          eye=behind["eye"])[0] == 0.0
    assert dithered_sphere_cascades(_first_spheres(near_side), near_side, noise=[0.0], **behind)[0] == 0
    outside = np.array([[0.0, 500.0, 0.0]])
    assert dithered_sphere_cascades(_first_spheres(outside), outside, noise=[0.0], **args)[0] == -1


def test_sphere_dither_takes_one_border_per_cascade_ending_at_zero(tmp_path):
    ShadowSettings(selection="sphere_dither", cascade_borders=BORDERS).validated()
    for bad in ((0.1, 0.1), (0.1, 0.1, 0.1, 0.1), (1.5, 0.0, 0.0, 0.0)):
        with pytest.raises(ValueError, match="cascade_borders"):
            ShadowSettings(selection="sphere_dither", cascade_borders=bad).validated()
    path = tmp_path / "exp.toml"
    path.write_text('[camera]\npath = "walk"\n[shadow]\ncascade_borders = [0.1, 0.0, 0.0, 0.0]\n')
    with pytest.raises(InputError) as caught:
        load_experiment(path)
    assert caught.value.field == "shadow.cascade_borders" and "sphere_dither" in caught.value.detail


def test_render_shades_each_receiver_from_its_dithered_sphere(device):
    """render with selection = "sphere_dither": every shaded receiver reads the cascade HDRP's dither picks from its
    first sphere, its border weight and its pixel's interleaved gradient noise (written out above)."""
    from csmlab.camera import CameraPose
    from csmlab.geometry import rotation_looking_at
    from csmlab.light import direction_from_angles
    from csmlab.render import prepare_scene, render_shadow, render_view
    from csmlab.scene import Scene

    vertices = np.array([[-60, 0, -60], [60, 0, -60], [60, 0, 60], [-60, 0, 60]], float)
    dscene = prepare_scene(Scene.from_triangles(vertices, np.array([[0, 2, 1], [0, 3, 2]])), device=device)
    eye = np.array([4.0, 3.0, 8.0])
    pose = CameraPose(position=eye, orientation=rotation_looking_at(-eye), aspect=1.6, near=0.1, far=60.0)
    view = render_view(dscene, pose, direction_from_angles(elevation_deg=50.0, azimuth_deg=20.0), width=48, height=30)
    borders = (0.3, 0.2, 0.0)
    settings = ShadowSettings(cascades=3, resolution=128, shadow_distance=40.0, selection="sphere_dither",
                              cascade_borders=borders)
    frame = render_shadow(dscene, view, settings)
    cs = frame.maps.cascades
    centres, radii = np.stack([c.sphere_centre for c in cs.cascades]), np.array([c.sphere_radius for c in cs.cascades])
    g = view.gbuffer
    rows, cols = np.nonzero(g.valid)
    points, chosen = g.position[g.valid], frame.shadow.cascade[g.valid]
    d2 = np.sum((points[:, None, :] - centres[None]) ** 2, axis=2) / radii**2
    inside = (d2 > 0.0) & (d2 <= 1.0)
    first = np.where(inside.any(axis=1), inside.argmax(axis=1), -1)
    weights = np.array([_hdrp_alpha(p, eye, centres, radii, borders)[1] for p in points])
    inner = 0.06711056 * cols + 0.00583715 * rows                    # Unity's InterleavedGradientNoise, frame 0
    noise = (52.9829189 * (inner - np.floor(inner))) % 1.0
    expected = np.where((first >= 0) & (first < 2) & (weights > 0) & (noise <= weights), first + 1, first)
    selected = chosen >= 0
    assert np.any(expected[selected] != first[selected])             # some receivers are dithered over
    np.testing.assert_array_equal(chosen[selected], expected[selected])


@pytest.mark.parametrize("seed", range(6))
def test_the_dither_equals_hdrps_rule_applied_to_every_point(seed):
    """dithered_sphere_cascades weighs only the points in a border band; the cascades equal HDRP's rule with the
    weight of every point (``next = min(i + 1, count − 1)``, taken where ``next ≠ i``, ``alpha > 0``, noise ≤ alpha),
    with points outside every sphere, at a centre, at the eye, zero borders and zero radii."""
    rng = np.random.default_rng(seed)
    count = 4
    points = rng.uniform(-30.0, 30.0, (5000, 3))
    centres = rng.uniform(-5.0, 5.0, (count, 3))
    radii = rng.choice([0.0, 10.0, 20.0, 40.0], count)
    borders = tuple(rng.choice([0.0, 0.05, 0.3, 1.0], count - 1)) + (0.0,)
    eye = rng.uniform(-3.0, 3.0, 3)
    points[:5], points[5:10], points[10:15] = centres[0], centres[1], eye
    offset = points[:, None, :] - centres[None]
    inside = np.sum(offset * offset, axis=2) <= radii ** 2
    cascade = np.where(inside.any(axis=1), inside.argmax(axis=1), -1)
    noise = rng.uniform(0.0, 1.0, len(points))
    with np.errstate(divide="ignore", invalid="ignore"):
        alpha = border_weights(cascade, points, centres=centres, radii=radii, borders=borders, eye=eye)
    following = np.minimum(cascade + 1, count - 1)
    want = np.where((cascade >= 0) & (following != cascade) & (alpha > 0.0) & (noise <= alpha), following, cascade)
    got = dithered_sphere_cascades(cascade, points, centres=centres, radii=radii, borders=borders, eye=eye,
                                   noise=noise)
    assert got.dtype == np.int32 and np.array_equal(got, want)
