"""The Warp LDR-ꟻLIP against NVIDIA's ``flip_evaluator`` (the C++ it follows) on random, flat, edged,
rendered and tiny images, and with a few changed pixels (the passes skip what lies out of their
reach); identical images give exactly 0; bad input is refused; its exp and pow are the C library's
on the CPU and correctly rounded on CUDA."""

import ctypes
import ctypes.util

import flip_evaluator
import numpy as np
import pytest
import warp as wp

from csmlab.camera import CameraPose
from csmlab.kernels import flip
from csmlab.geometry import rotation_looking_at
from csmlab.kernels.flip import (FLIP_DEFAULT_PPD, flip_error_map, flip_filter_radii, flip_reach, libm_exp, libm_pow,
                                pixels_differ)
from csmlab.metrics.shading import shaded_rgb
from csmlab.render import render_frame
from csmlab.scene import make_scene
from csmlab.settings import ShadowSettings
from csmlab.srgb import srgb_encoded

wp.set_module_options({"fuse_fp": False})

# The brief's bounds: per pixel, and of the mean error relative to the oracle's mean. Measured: the
# two differ in at most a few pixels by one float32 ulp (different libm powf/expf).
MAX_ABS = 1e-5
MEAN_REL = 1e-6


def _oracle(reference, test, **parameters):
    error, _, _ = flip_evaluator.evaluate(np.ascontiguousarray(reference, np.float32),
                                          np.ascontiguousarray(test, np.float32), "LDR", applyMagma=False,
                                          computeMeanError=False, parameters=parameters)
    return np.asarray(error)[..., 0]


def _assert_matches_oracle(reference, test, expected=None, **kw):
    expected = _oracle(reference, test) if expected is None else expected
    error = flip_error_map(reference, test, **kw)
    assert error.shape == reference.shape[:2] and error.dtype == np.float32
    difference = np.abs(error.astype(np.float64) - expected)
    assert difference.max() <= MAX_ABS
    assert abs(error.mean(dtype=np.float64) - expected.mean(dtype=np.float64)) <= MEAN_REL * expected.mean()
    return error, expected


def _noisy_pair(seed, shape, *, sigma=0.05):
    rng = np.random.default_rng(seed)
    reference = rng.random(shape + (3,)).astype(np.float32)
    test = np.clip(reference + rng.normal(0.0, sigma, reference.shape), 0.0, 1.0).astype(np.float32)
    return reference, test


@pytest.mark.parametrize("seed, shape", [(0, (24, 40)), (1, (40, 24)), (2, (33, 57))])
def test_random_images_match_flip_evaluator(seed, shape, device):
    _assert_matches_oracle(*_noisy_pair(seed, shape), device=device)


def test_unrelated_random_images_match_flip_evaluator(device):
    rng = np.random.default_rng(5)
    reference, test = rng.random((2, 30, 30, 3)).astype(np.float32)
    _assert_matches_oracle(reference, test, device=device)


def test_flat_regions_and_hard_edges_match_flip_evaluator(device):
    # Flat blocks of saturated and grey colours, a one-pixel line and a checkerboard corner; the
    # test image moves the block edges by a pixel and recolours one block: large colour and
    # feature differences, and exact zeros where both images stay flat far from any change.
    reference = np.zeros((48, 64, 3), np.float32)
    reference[:, 32:] = (0.0, 1.0, 0.0)
    reference[10:30, 5:20] = (0.0, 0.0, 1.0)
    reference[40, :] = 1.0
    reference[36:, 48:] = (np.indices((12, 16)).sum(axis=0) % 2)[..., None]
    test = reference.copy()
    test[10:30, 6:21] = (0.0, 0.0, 1.0)
    test[10:30, 5] = 0.0
    test[:, 31] = (0.0, 1.0, 0.0)
    test[0:8, 0:8] = 0.5
    error, expected = _assert_matches_oracle(reference, test, device=device)
    assert expected.max() > 0.9 and np.any(expected == 0.0)
    np.testing.assert_array_equal(error == 0.0, expected == 0.0)


def test_rendered_frames_whose_shadow_moved_match_flip_evaluator(device):
    # Two csmlab frames of a box on a plane under a light that turned slightly: the shaded images
    # the perceptual metric compares.
    scene = make_scene("plane_box", plane_size=40.0, box_size=3.0)
    pose = CameraPose(position=[6.0, 7.0, 9.0], orientation=rotation_looking_at([-6.0, -7.0, -9.0]), aspect=80 / 56)
    settings = ShadowSettings(cascades=2, resolution=256, shadow_distance=40.0)
    images = []
    for light in ([0.3, -0.8, -0.5], [0.33, -0.8, -0.47]):
        frame = render_frame(scene, pose, light, settings, width=80, height=56)
        g = frame.view.gbuffer
        lit = np.where(g.valid, frame.shadow.lit, 0.0)
        images.append(srgb_encoded(shaded_rgb(g.albedo, g.normal, lit, light_direction=light, ambient=0.25))
                      .astype(np.float32))
    error, expected = _assert_matches_oracle(*images, device=device)
    assert np.count_nonzero(expected) > 100


@pytest.mark.parametrize("shape", [(1, 1), (1, 25), (25, 1), (3, 4), (9, 21)])
def test_images_smaller_than_the_filters_match_flip_evaluator(shape, device):
    # Every tap beyond the edge clamps to the edge pixel, many times over.
    assert min(shape) < 2 * max(flip_filter_radii()) + 1
    _assert_matches_oracle(*_noisy_pair(11, shape, sigma=0.2), device=device)


def test_another_viewing_distance_matches_flip_evaluator(device):
    reference, test = _noisy_pair(3, (30, 36))
    assert flip_filter_radii(pixels_per_degree=30.0) == (5, 4)
    _assert_matches_oracle(reference, test, expected=_oracle(reference, test, ppd=30.0), pixels_per_degree=30.0,
                           device=device)


def test_default_viewing_distance_is_flip_evaluators():
    _, _, parameters = flip_evaluator.evaluate(np.zeros((2, 2, 3), np.float32), np.zeros((2, 2, 3), np.float32),
                                               "LDR", applyMagma=False, computeMeanError=False)
    assert np.float32(parameters["ppd"]) == np.float32(FLIP_DEFAULT_PPD)
    assert flip_filter_radii() == (10, 9)


def test_filter_radii_bound_where_one_changed_pixel_reaches_in_flip_evaluator():
    # One changed pixel alters the oracle's error exactly out to the larger radius (the spatial
    # filter's), so windows grown by it give the whole image's values.
    reference = np.full((41, 41, 3), 0.5, np.float32)
    test = reference.copy()
    test[20, 20] = (0.9, 0.2, 0.1)
    rows, cols = np.nonzero(_oracle(reference, test))
    reach = max(flip_filter_radii())
    assert max(np.abs(rows - 20).max(), np.abs(cols - 20).max()) == reach


def test_identical_images_give_exactly_zero_everywhere(device):
    rng = np.random.default_rng(8)
    image = rng.random((37, 29, 3)).astype(np.float32)
    image[:10] = 0.0
    image[-5:] = 1.0
    assert np.all(flip_error_map(image, image, device=device) == 0.0)


def _brute_force_reach(differs, radius):
    """Each level of :func:`flip_reach` by its definition, pixel by pixel."""
    height, width = differs.shape

    def grown(mask, axis):
        out = np.zeros_like(mask)
        for i in range(height):
            for j in range(width):
                if axis == 1:
                    out[i, j] = mask[i, max(j - radius, 0):j + radius + 1].any()
                else:
                    out[i, j] = mask[max(i - radius, 0):i + radius + 1, j].any()
        return out

    levels = [differs]
    for axis in (1, 0, 0, 1):
        levels.append(grown(levels[-1], axis))
    return sum(level.astype(np.uint8) for level in levels)


@pytest.mark.parametrize("radius", [0, 1, 3])
def test_reach_levels_are_the_nested_growths_of_the_differing_pixels(radius):
    rng = np.random.default_rng(radius)
    differs = rng.random((17, 23)) < 0.03
    differs[0, 0] = differs[-1, 5] = True
    reach = flip_reach(differs, radius=radius)
    np.testing.assert_array_equal(reach, _brute_force_reach(differs, radius))
    assert reach.dtype == np.uint8 and np.all((reach == 5) == differs)


def test_pixels_differ_in_any_channel():
    reference = np.zeros((3, 4, 3), np.float32)
    test = reference.copy()
    test[0, 1, 2] = 1e-7
    test[2, 3, 0] = 0.5
    np.testing.assert_array_equal(np.argwhere(pixels_differ(reference, test)), [[0, 1], [2, 3]])


@pytest.mark.parametrize("spots", [[(20, 30)], [(0, 0), (39, 63)], [(5, 60), (6, 61), (30, 2)]])
def test_a_few_changed_pixels_match_flip_evaluator_and_are_zero_out_of_reach(spots, device):
    # The passes skip what lies out of a change's reach, at the edges too (the taps clamp there).
    rng = np.random.default_rng(len(spots))
    reference = rng.random((40, 64, 3)).astype(np.float32)
    test = reference.copy()
    for i, j in spots:
        test[i, j] = rng.random(3)
    error, expected = _assert_matches_oracle(reference, test, device=device)
    may_differ = flip_reach(pixels_differ(reference, test), radius=max(flip_filter_radii())) >= 3
    assert np.all(error[~may_differ] == 0.0) and np.all(expected[~may_differ] == 0.0)
    assert np.count_nonzero(error) > 100


@pytest.mark.parametrize("extra", [0.0, 0.01, 0.3])
def test_a_reach_grown_from_more_pixels_than_differ_gives_the_same_map_bit_for_bit(extra, device):
    # The caller's reach (from the linear images, a superset of the encoded ones' differences)
    # only makes the passes compute more: where inputs agree they give the values they skip.
    rng = np.random.default_rng(31)
    reference = rng.random((40, 64, 3)).astype(np.float32)
    test = reference.copy()
    for i, j in [(5, 7), (20, 30), (39, 63)]:
        test[i, j] = rng.random(3)
    differs = pixels_differ(reference, test)
    marked = differs | (rng.random(differs.shape) < extra)
    reach = flip_reach(marked, radius=max(flip_filter_radii()))
    expected, _ = _assert_matches_oracle(reference, test, device=device)
    np.testing.assert_array_equal(flip_error_map(reference, test, reach=reach, device=device), expected)
    with pytest.raises(ValueError, match="reach: expected the images' shape"):
        flip_error_map(reference, test, reach=reach[:-1], device=device)


@pytest.mark.parametrize("changed", [0.002, 0.02, 0.3])
def test_the_cpus_runs_of_pixels_give_the_bits_of_a_pixel_at_a_time(changed, monkeypatch):
    # On the CPU the row passes take four or eight pixels at once where the taps allow; a pixel at a
    # time (a GPU's threads) is the oracle, checked against flip_evaluator above. Scattered changes
    # leave runs of every length, at the image's edges too.
    rng = np.random.default_rng(int(changed * 1000))
    reference = rng.random((48, 160, 3)).astype(np.float32)
    test = reference.copy()
    spots = rng.random(reference.shape[:2]) < changed
    test[spots] = rng.random((np.count_nonzero(spots), 3)).astype(np.float32)
    blocks = flip_error_map(reference, test, device="cpu")
    monkeypatch.setattr(flip, "_pixels_per_thread", lambda device, width: 1)
    pixels = flip_error_map(reference, test, device="cpu")
    np.testing.assert_array_equal(blocks.view(np.uint32), pixels.view(np.uint32))
    assert np.count_nonzero(blocks) > 0.5 * np.count_nonzero(flip_reach(pixels_differ(reference, test),
                                                                         radius=max(flip_filter_radii())) >= 3)


def test_the_passes_kept_arrays_hold_nothing_a_later_call_reads(device):
    # The intermediate arrays are kept from call to call (flip._scratch): filled with NaN between two
    # calls of one shape, the second map is still the one a first call gives (no pixel read unwritten).
    first = _noisy_pair(5, (40, 72))
    reference, test = _noisy_pair(6, (40, 72))
    test[:, :30] = reference[:, :30]
    expected = flip_error_map(reference, test, device=device)
    flip_error_map(*first, device=device)
    for array in flip._SCRATCH.arrays:
        array.fill_(float("nan"))
    np.testing.assert_array_equal(flip_error_map(reference, test, device=device), expected)


@pytest.mark.parametrize("reference, test, match", [
    (np.zeros((4, 4)), np.zeros((4, 4)), "reference: expected an \\(H, W, 3\\)"),
    (np.zeros((4, 4, 3)), np.zeros((4, 4, 4)), "test: expected an \\(H, W, 3\\)"),
    (np.zeros((4, 4, 3)), np.zeros((4, 5, 3)), "test: expected the reference's shape"),
    (np.full((4, 4, 3), np.nan), np.zeros((4, 4, 3)), "reference: expected finite"),
    (np.zeros((4, 4, 3)), np.full((4, 4, 3), 1.5), "test: expected sRGB values in \\[0, 1\\]"),
    (np.zeros((0, 4, 3)), np.zeros((0, 4, 3)), "reference: expected an \\(H, W, 3\\)"),
])
def test_bad_images_are_refused_naming_the_argument(reference, test, match):
    with pytest.raises(ValueError, match=match):
        flip_error_map(reference, test)


def test_bad_viewing_distance_and_device_are_refused():
    image = np.zeros((4, 4, 3), np.float32)
    with pytest.raises(ValueError, match="pixels_per_degree: expected a finite value > 0"):
        flip_error_map(image, image, pixels_per_degree=0.0)
    with pytest.raises(ValueError, match="device"):
        flip_error_map(image, image, device="tpu")



@wp.kernel
def _libm_kernel(x: wp.array(dtype=float), y: wp.array(dtype=float), exp_out: wp.array(dtype=float),
                 pow_out: wp.array(dtype=float)):
    k = wp.tid()
    exp_out[k] = libm_exp(x[k])
    pow_out[k] = libm_pow(wp.abs(x[k]), y[k])


def _c_library():
    libm = ctypes.CDLL(ctypes.util.find_library("m"))
    for name, arity in (("expf", 1), ("powf", 2)):
        getattr(libm, name).restype = ctypes.c_float
        getattr(libm, name).argtypes = [ctypes.c_float] * arity
    return libm


def test_exp_and_pow_are_the_c_librarys_on_the_cpu_and_correctly_rounded_on_cuda(device):
    # The inputs span what the kernels pass: the Gaussians' exponents (≤ 0), and bases in [0, 2) —
    # sRGB, CIELAB's f(t), HyAB and feature differences — raised to 2.4, 1/3, qc = 0.7, qf = 0.5
    # and 1 − feature in [0, 1]. Oracles: the C library's expf and powf (flip_evaluator's own) on
    # the CPU; NumPy's float64 exp and pow rounded to float32 on CUDA; within one ulp of that on both.
    rng = np.random.default_rng(12)
    x = np.concatenate([-rng.uniform(0.0, 60.0, 3000), rng.uniform(0.0, 2.0, 3000), np.geomspace(1e-30, 1.0, 2000),
                        [0.0, 1.0, 0.5, 2.0]]).astype(np.float32)
    exponents = np.array([2.4, 1.0 / 3.0, 0.7, 0.5, 1.0, 0.0], np.float32)
    y = np.where(np.arange(x.size) % 2 == 0, exponents[np.arange(x.size) % exponents.size],
                 rng.uniform(0.0, 1.0, x.size)).astype(np.float32)
    exp_out, pow_out = (wp.empty(x.size, dtype=float, device=device) for _ in range(2))
    wp.launch(_libm_kernel, dim=x.size, inputs=(wp.array(x, device=device), wp.array(y, device=device)),
              outputs=(exp_out, pow_out), device=device)
    rounded_exp = np.exp(x.astype(np.float64)).astype(np.float32)
    rounded_pow = np.power(np.abs(x.astype(np.float64)), y.astype(np.float64)).astype(np.float32)
    for got, rounded in ((exp_out.numpy(), rounded_exp), (pow_out.numpy(), rounded_pow)):
        np.testing.assert_array_max_ulp(got, rounded, maxulp=1)
    if wp.get_device(device).is_cpu:
        libm = _c_library()
        np.testing.assert_array_equal(exp_out.numpy(), np.array([libm.expf(v) for v in x.tolist()], np.float32))
        np.testing.assert_array_equal(pow_out.numpy(),
                                      np.array([libm.powf(abs(a), b) for a, b in zip(x.tolist(), y.tolist())],
                                               np.float32))
    else:
        np.testing.assert_array_equal(exp_out.numpy(), rounded_exp)
        np.testing.assert_array_equal(pow_out.numpy(), rounded_pow)
