"""csmlab.kernels: the device checks and arrays every wrapper shares."""

import numpy as np
import pytest
import warp as wp

from csmlab.kernels import checked_device, device_empty, host_array


@wp.kernel
def _fill_with_index(out: wp.array(dtype=wp.vec3d)):
    i = wp.tid()
    out[i] = wp.vec3d(wp.float64(i), wp.float64(2 * i), wp.float64(3 * i))


@pytest.mark.parametrize("shape, dtype, host", [(7, wp.int32, (7,)), ((2, 3), wp.vec3d, (2, 3, 3)),
                                                ((4, 5), wp.vec3, (4, 5, 3)), ((3,), wp.float64, (3,))])
def test_device_empty_has_the_shape_and_type_asked_for(shape, dtype, host, device):
    array = device_empty(shape, dtype, device)
    assert array.dtype == dtype
    assert array.numpy().shape == host


def test_device_empty_holds_what_a_kernel_writes(device):
    array = device_empty(1000, wp.vec3d, device)
    wp.launch(_fill_with_index, dim=1000, outputs=(array,), device=device)
    index = np.arange(1000, dtype=np.float64)
    np.testing.assert_array_equal(array.numpy(), np.stack([index, 2 * index, 3 * index], axis=1))


def test_host_array_writes_into_the_numpy_arrays_own_memory_and_copies_only_what_it_must():
    out = np.zeros((1000, 3))
    wp.launch(_fill_with_index, dim=1000, outputs=(host_array(out, wp.vec3d),), device="cpu")
    index = np.arange(1000, dtype=np.float64)
    np.testing.assert_array_equal(out, np.stack([index, 2 * index, 3 * index], axis=1))
    image = np.zeros((4, 5, 3))
    assert host_array(image, wp.vec3d).shape == (4, 5) and host_array(image, wp.vec3d).ptr == image.ctypes.data
    strided = np.arange(12.0)[::2]
    copied = host_array(strided, wp.float32)
    assert copied.dtype == wp.float32 and copied.ptr != strided.ctypes.data
    np.testing.assert_array_equal(copied.numpy(), strided)


class _NotTheDeviceAskedFor:
    """Stands in for Warp's default device: any use of it is a failure."""

    def __getattr__(self, name):
        raise AssertionError(f"Warp's default device was used (its {name!r} read), not the device asked for")


def test_device_empty_is_on_the_device_asked_for_whatever_warps_default(device, monkeypatch):
    # Where a GPU is present Warp's default device is cuda:0: an array for a CPU kernel made there
    # held a GPU pointer, and the CPU launch writing through it segfaulted (the lent H200 machine).
    wp.init()
    monkeypatch.setattr(wp._src.context.runtime, "default_device", _NotTheDeviceAskedFor())
    array = device_empty((3, 4), wp.vec3d, device)
    assert array.device == wp.get_device(device)
    wp.launch(_fill_with_index, dim=12, outputs=(array.flatten(),), device=device)
    assert array.numpy()[2, 3, 2] == 33.0


def test_checked_device_refuses_names_warp_does_not_know():
    with pytest.raises(ValueError, match="device"):
        checked_device("tpu")
    assert checked_device("cpu") == "cpu"


KERNEL_MODULES = ["depth_storage", "engine", "flip", "flip_inputs", "footprint", "levels", "moments",
                  "pages", "pcf", "raster.kernels", "raster.tiled", "rays", "records", "reference.irregular",
                  "reference.ray_cast", "reference.ray_grid", "shading", "shadow", "ssim", "taa", "temporal",
                  "texture", "usage", "visibility"]
"""csmlab's Warp modules: each module under csmlab.kernels (packages included) that defines kernels."""


def test_the_list_of_kernel_modules_is_every_module_that_defines_kernels():
    import importlib
    import pkgutil

    import csmlab.kernels

    prefix = "csmlab.kernels."
    modules = {m.name.removeprefix(prefix): importlib.import_module(m.name)
               for m in pkgutil.walk_packages(csmlab.kernels.__path__, prefix)}
    found = [name for name, module in modules.items()
             if any(isinstance(v, wp.Kernel) and v.func.__module__ == module.__name__ for v in vars(module).values())]
    assert sorted(found) == KERNEL_MODULES


def _numpy_constants(module) -> list[str]:
    """Globals of ``module`` that its kernels and functions read and that hold a NumPy scalar (or a Warp scalar made
    of one)."""
    import inspect
    import re

    sources = "\n".join(inspect.getsource(v.func) for v in vars(module).values()
                        if isinstance(v, (wp.Kernel, wp.Function)) and v.func.__module__ == module.__name__)
    return [name for name, value in vars(module).items()
            if isinstance(getattr(value, "value", value), np.generic) and re.search(rf"\b{name}\b", sources)]


@pytest.mark.parametrize("name", KERNEL_MODULES)
def test_no_kernel_reads_a_constant_made_of_a_numpy_scalar(name):
    """Warp writes a NumPy scalar into its C++ as NumPy prints it, and importing colour-science sets NumPy's
    legacy printing: ``np.finfo(np.float64).max`` became 1.79769313486e+308, below itself, in a module first
    compiled by a process that had imported colour. Constants are Python floats (printed exactly) or arguments."""
    import importlib

    assert _numpy_constants(importlib.import_module(f"csmlab.kernels.{name}")) == []


def test_the_numpy_constant_check_finds_one(tmp_path):
    import importlib.util

    path = tmp_path / "numpy_constant_probe.py"
    path.write_text("import numpy as np\nimport warp as wp\n\n"
                    "LARGEST = wp.constant(wp.float64(np.finfo(np.float64).max))\n"
                    "EXACT = wp.constant(wp.float64(float(np.finfo(np.float64).max)))\n\n\n"
                    "@wp.func\ndef probe(x: wp.float64) -> wp.float64:\n    return wp.min(wp.min(x, LARGEST), EXACT)\n")
    spec = importlib.util.spec_from_file_location("numpy_constant_probe", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert _numpy_constants(module) == ["LARGEST"]


FMA_FROM_LIBRARIES = {
    "engine": "libdevice's hypot (a warped cascade's receivers; the CPU calls the C library's)",
    "flip": "libdevice's float64 exp and pow",
    "moments": "libdevice's exp and log",
    "pcf": "libdevice's exp",
    "rays": "Warp's BVH ray query (wp.mesh_query_ray)",
    "reference.ray_cast": "Warp's BVH ray queries (wp.mesh_query_ray_anyhit, wp.mesh_query_ray)",
    "visibility": "Warp's BVH ray query (wp.mesh_query_ray)",
}
"""Kernel modules whose CUDA build keeps a few ``fma`` that no compiler option removes: the library
code they call (``fma`` written out by hand, for accuracy) — and which the CPU computes its own way."""


def _fma_count(name: str, module_dir, *, fuse_fp=None) -> int:
    """``fma`` instructions in the PTX of kernel module ``name`` (sm_90, NVRTC), as built, or with ``fuse_fp``."""
    import importlib
    import re

    module = wp.get_module(importlib.import_module(f"csmlab.kernels.{name}").__name__)
    held = module.options["fuse_fp"]
    try:
        if fuse_fp is not None:
            module.options["fuse_fp"] = fuse_fp
        paths = wp.compile_aot_module(module, arch=90, module_dir=module_dir, use_ptx=True)
    finally:
        module.options["fuse_fp"] = held
    return len(re.findall(r"\bfma\.", paths[0].read_text()))


@pytest.mark.slow
@pytest.mark.compile
@pytest.mark.skipif(wp.get_cuda_toolkit_version() is None, reason="this Warp has no CUDA compiler (NVRTC)")
@pytest.mark.parametrize("name", KERNEL_MODULES)
def test_every_kernel_module_compiles_for_a_gpu_and_rounds_there_as_on_the_cpu(name, tmp_path):
    """Each module's CUDA source compiles (sm_90, NVRTC, to PTX) on a machine with no GPU, and fuses no
    multiply and add (``fuse_fp``): its PTX holds no ``fma`` but what the libraries it calls write out
    (:data:`FMA_FROM_LIBRARIES`).

    The compilation catches what only the CUDA build sees — the native snippets' ``__CUDA_ARCH__``
    branches, device-only builtins — where no GPU is lent. With ``fuse_fp`` off Warp's CPU build
    (clang, ``-march=native``) rounds every product and every sum; NVRTC contracts ``a * b + c``
    into one ``fma`` (one rounding) unless told not to, and then depths, edge functions and lookups
    differ in their last bits between the devices (on an H200 the CPU and CUDA depth maps, hits and
    shadows were bit for bit the same).
    """
    fused = _fma_count(name, tmp_path / "built")
    if name in FMA_FROM_LIBRARIES:
        assert fused == _fma_count(name, tmp_path / "unfused", fuse_fp=False), FMA_FROM_LIBRARIES[name]
    else:
        assert fused == 0
