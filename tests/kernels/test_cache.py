"""``./setup.sh`` fills Warp's kernel cache: every csmlab kernel module is found and compiled ahead of a run."""

from __future__ import annotations

import re
from pathlib import Path

import warp as wp

from csmlab.kernels.cache import build_kernel_cache, kernel_modules
from tests.locations import ROOT

KERNELS = ROOT / "csmlab" / "kernels"


def _modules_defining_a_kernel() -> list[str]:
    """The oracle: module names of the files under csmlab/kernels whose source defines a ``@wp.kernel``."""
    names = []
    for path in KERNELS.rglob("*.py"):
        if re.search(r"^\s*@wp\.kernel\b", path.read_text(), flags=re.MULTILINE):
            parts = path.relative_to(KERNELS.parent.parent).with_suffix("").parts
            names.append(".".join(parts))
    return sorted(names)


def test_kernel_modules_are_the_files_that_define_kernels():
    assert kernel_modules() == _modules_defining_a_kernel()


def test_setup_runs_the_cache_build():
    setup = (KERNELS.parent.parent / "setup.sh").read_text()
    assert "build_kernel_cache()" in setup


def test_build_kernel_cache_leaves_every_module_in_the_cache():
    names = build_kernel_cache("cpu")
    cached = {entry.name for entry in Path(wp.config.kernel_cache_dir).iterdir()}
    assert names == kernel_modules()
    for name in names:
        # Warp's cache entry of a module is named by its content hash at the block size of the launch
        # (one thread per block on the CPU): the entry a run's first launch loads.
        assert wp.get_module(name).get_module_identifier(block_dim=1) in cached, name
