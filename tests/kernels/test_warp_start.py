"""Warp starts quietly in every csmlab process: no CUDA-driver warning for work asked of the CPU.

Warp's native library writes "Warp CUDA warning: Could not find or load the NVIDIA CUDA driver" to
file descriptor 2 when a process starts Warp on a machine without a GPU; a run printed it once per
worker process. Each check runs in a fresh interpreter, since Warp starts once per process.
"""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from csmlab.kernels import CUDA_DRIVER_WARNING


WORK = """
import warp as wp


def zeros_shape(shared, task):
    return wp.zeros(task, dtype=float, device="cpu").shape
"""


def _python(code: str, folder=None) -> subprocess.CompletedProcess:
    environment = dict(os.environ)
    if folder is not None:
        # A module of the test's own for the workers to import (a spawned process needs fn by name).
        (folder / "warp_work.py").write_text(WORK)
        environment["PYTHONPATH"] = os.pathsep.join(filter(None, [str(folder), environment.get("PYTHONPATH")]))
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, env=environment)


def test_plain_warp_start_is_what_is_dropped():
    # The control: on a machine without a CUDA driver this is the line a bare start prints (with a
    # driver it prints nothing, and the checks below hold trivially).
    done = _python("import warp as wp; wp.config.log_level = wp.LOG_WARNING; wp.init()")
    assert done.returncode == 0, done.stderr
    assert done.stderr in ("", CUDA_DRIVER_WARNING + ". GPU execution will not be available.\n")


def test_start_warp_drops_the_cuda_driver_warning_and_keeps_stderr_working():
    done = _python("import sys, warp as wp\n"
                   "from csmlab.kernels import start_warp\n"
                   "start_warp(); start_warp()\n"
                   "wp.zeros(3, dtype=float, device='cpu')\n"
                   "print('after', file=sys.stderr)\n")
    assert done.returncode == 0, done.stderr
    assert done.stderr == "after\n"


@pytest.mark.parametrize("executor", ["inprocess", "pool"])
def test_the_executors_start_warp_quietly(tmp_path, executor):
    done = _python("from csmlab.executor import execute\n"
                   "from warp_work import zeros_shape\n"
                   f"results = execute(zeros_shape, [2, 3, 4], shared=None, executor={executor!r}, jobs=2)\n"
                   "print(sorted(shape for _, shape in results))\n", tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stdout == "[(2,), (3,), (4,)]\n" and "CUDA" not in done.stderr
