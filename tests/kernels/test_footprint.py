"""The texel-footprint kernel against NumPy's SVD and hand-computed Jacobians."""

import numpy as np
import pytest
import warp as wp

from csmlab.kernels.footprint import surface_differentials, texel_footprint

CUDA = pytest.mark.skipif(not wp.is_cuda_available(), reason="no CUDA device")


def _random_case(seed, *, height=24, width=32, cascades=3):
    rng = np.random.default_rng(seed)
    dpdx = rng.normal(size=(height, width, 3)).astype(np.float32)
    dpdy = rng.normal(size=(height, width, 3)).astype(np.float32)
    cascade = rng.integers(-1, cascades, size=(height, width)).astype(np.int8)
    axes = rng.normal(size=(cascades, 2, 3)) * rng.uniform(0.5, 4.0, size=(cascades, 1, 1))
    return dpdx, dpdy, cascade, axes


def _numpy_singular_values(dpdx, dpdy, cascade, axes):
    """Brute-force reference: build every J in float64 and take NumPy's SVD."""
    a = axes[np.maximum(cascade, 0)]
    jac = np.einsum("hwkc,hwcj->hwkj", a, np.stack([dpdx, dpdy], axis=-1).astype(np.float64))
    return np.linalg.svd(jac, compute_uv=False)


def test_texel_footprint_matches_numpy_svd_on_random_jacobians(device):
    dpdx, dpdy, cascade, axes = _random_case(7)
    rho, sigma_min = texel_footprint(dpdx, dpdy, cascade, texel_axes=axes, device=device)
    s = _numpy_singular_values(dpdx, dpdy, cascade, axes)
    selected = cascade >= 0
    atol = 1e-5 * s[..., 0][selected].max()
    np.testing.assert_allclose(rho[selected], np.sqrt(s[..., 0] * s[..., 1])[selected], rtol=1e-4, atol=atol)
    np.testing.assert_allclose(sigma_min[selected], s[..., 1][selected], rtol=1e-4, atol=atol)
    assert np.all(np.isnan(rho[~selected])) and np.all(np.isnan(sigma_min[~selected]))


def test_texel_footprint_of_an_axis_aligned_pixel_is_pixel_size_over_texel_size(device):
    # A pixel 0.1 m × 0.3 m seen through texels of 0.05 m: J = diag(2, 6), ρ = sqrt(12), σ_min = 2.
    dpdx = np.broadcast_to(np.float32([0.1, 0.0, 0.0]), (2, 3, 3))
    dpdy = np.broadcast_to(np.float32([0.0, 0.0, 0.3]), (2, 3, 3))
    axes = np.array([[[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]]) / 0.05
    rho, sigma_min = texel_footprint(dpdx, dpdy, np.zeros((2, 3), np.int8), texel_axes=axes, device=device)
    np.testing.assert_allclose(rho, np.sqrt(12.0), rtol=1e-6)
    np.testing.assert_allclose(sigma_min, 2.0, rtol=1e-6)


def test_texel_footprint_doubles_exactly_when_texels_halve(device):
    dpdx, dpdy, cascade, axes = _random_case(11)
    rho, sigma_min = texel_footprint(dpdx, dpdy, cascade, texel_axes=axes, device=device)
    rho2, sigma_min2 = texel_footprint(dpdx, dpdy, cascade, texel_axes=axes * 2.0, device=device)
    np.testing.assert_array_equal(rho2, 2.0 * rho)
    np.testing.assert_array_equal(sigma_min2, 2.0 * sigma_min)


def test_texel_footprint_rejects_a_cascade_index_beyond_the_axes(device):
    dpdx, dpdy, cascade, axes = _random_case(3, cascades=2)
    with pytest.raises(ValueError, match="cascade: expected indices below 1"):
        texel_footprint(dpdx, dpdy, cascade, texel_axes=axes[:1], device=device)
    with pytest.raises(ValueError, match=r"texel_axes: expected a finite \(C, 2, 3\)"):
        texel_footprint(dpdx, dpdy, cascade, texel_axes=axes[:, :1], device=device)


@pytest.mark.cuda
@CUDA
def test_texel_footprint_cuda_matches_cpu():
    dpdx, dpdy, cascade, axes = _random_case(5, height=90, width=160)
    cpu = texel_footprint(dpdx, dpdy, cascade, texel_axes=axes)
    gpu = texel_footprint(dpdx, dpdy, cascade, texel_axes=axes, device="cuda")
    for a, b in zip(cpu, gpu):
        np.testing.assert_allclose(b, a, rtol=1e-5, atol=1e-6)


@pytest.mark.cuda
@CUDA
def test_surface_differentials_cuda_matches_cpu():
    rng = np.random.default_rng(9)
    position = rng.normal(size=(45, 80, 3)) + [0.0, 0.0, -20.0]
    normal = rng.normal(size=(45, 80, 3))
    normal = (normal / np.linalg.norm(normal, axis=-1, keepdims=True)).astype(np.float32)
    camera = dict(eye=np.zeros(3), rotation=np.eye(3), fov_y_deg=50.0, aspect=80 / 45)
    cpu = surface_differentials(position, normal, **camera)
    gpu = surface_differentials(position, normal, **camera, device="cuda")
    for a, b in zip(cpu, gpu):
        np.testing.assert_allclose(b, a, rtol=1e-6, atol=1e-9)


def test_surface_differentials_are_the_transferred_ray_steps_and_zero_where_the_ray_missed(device):
    # The tangent-plane transfer dX = t·(∂D − D (n·∂D)/(n·D)) in float64 NumPy, against the kernel, which takes the
    # hit relative to the eye itself and must read a missed pixel's NaN position as no hit at all.
    rng = np.random.default_rng(4)
    height, width = 12, 20
    eye = np.array([1.0, 2.0, 3.0])
    position = eye + rng.normal(size=(height, width, 3)) + [0.0, 0.0, -15.0]
    normal = rng.normal(size=(height, width, 3))
    normal = (normal / np.linalg.norm(normal, axis=-1, keepdims=True)).astype(np.float32)
    missed = rng.random((height, width)) < 0.2
    position[missed] = np.nan
    normal[missed] = 0.0
    partly = tuple(np.argwhere(~missed)[0])  # a hit with one coordinate made non-finite, its normal kept
    position[partly][1] = np.inf
    camera = dict(rotation=np.eye(3), fov_y_deg=50.0, aspect=width / height)
    dpdu, dpdv = surface_differentials(position, normal, eye=eye, **camera, device=device)
    tan_y = np.tan(np.radians(50.0) / 2.0)
    steps = (np.array([2.0 * tan_y * width / height / width, 0.0, 0.0]), np.array([0.0, -2.0 * tan_y / height, 0.0]))
    v = np.where(np.isfinite(position), position - eye, 0.0)  # a non-finite coordinate is no offset
    t = -v[..., 2]
    n = normal.astype(np.float64)
    for got, step in zip((dpdu, dpdv), steps):
        with np.errstate(invalid="ignore"):  # 0/0 at the missed pixels, left out below
            d = v / t[..., None]
            want = t[..., None] * (step - d * (n @ step)[..., None] / np.sum(n * d, axis=-1)[..., None])
        np.testing.assert_allclose(got[~missed], want[~missed], rtol=1e-5, atol=1e-7)
        assert np.all(got[missed] == 0.0) and np.any(got[partly] != 0.0)
