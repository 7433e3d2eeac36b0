"""NaN and infinity tests as comparisons: the same answers as NumPy's on every float class."""

import numpy as np
import pytest
import warp as wp

from csmlab.kernels.floats import is_finite, is_nan


@wp.kernel
def classes32_kernel(x: wp.array(dtype=wp.float32), finite: wp.array(dtype=wp.int32), nan: wp.array(dtype=wp.int32)):
    k = wp.tid()
    finite[k] = wp.where(is_finite(x[k]), 1, 0)
    nan[k] = wp.where(is_nan(x[k]), 1, 0)


@wp.kernel
def classes64_kernel(x: wp.array(dtype=wp.float64), finite: wp.array(dtype=wp.int32), nan: wp.array(dtype=wp.int32)):
    k = wp.tid()
    finite[k] = wp.where(is_finite(x[k]), 1, 0)
    nan[k] = wp.where(is_nan(x[k]), 1, 0)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_is_finite_and_is_nan_answer_as_numpy_on_every_class_of_float(dtype, device):
    info = np.finfo(dtype)
    special = np.array([0.0, -0.0, info.tiny, -info.tiny, info.smallest_subnormal, -info.smallest_subnormal,
                        info.max, -info.max, np.inf, -np.inf, np.nan, -np.nan, 1.0, -3.5], dtype=dtype)
    values = np.concatenate([special, np.random.default_rng(0).standard_normal(64).astype(dtype) * dtype(1e30)])
    finite = wp.empty(values.size, dtype=wp.int32, device=device)
    nan = wp.empty(values.size, dtype=wp.int32, device=device)
    kernel = classes32_kernel if dtype == np.float32 else classes64_kernel
    wp.launch(kernel, dim=values.size, inputs=(wp.array(values, device=device),), outputs=(finite, nan), device=device)
    np.testing.assert_array_equal(finite.numpy().astype(bool), np.isfinite(values))
    np.testing.assert_array_equal(nan.numpy().astype(bool), np.isnan(values))
