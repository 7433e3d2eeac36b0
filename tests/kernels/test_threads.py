"""Splitting Warp CPU launches over threads: ranges that partition, tasks that all run, errors that surface."""

import os
import subprocess
import sys
import threading

import pytest

from csmlab.kernels.threads import LaunchPool, checked_threads, split_range


@pytest.mark.parametrize("count", [0, 1, 2, 5, 360, 1001])
@pytest.mark.parametrize("parts", [1, 2, 3, 7])
def test_split_range_partitions_into_nearly_equal_consecutive_ranges(count, parts):
    ranges = split_range(count, parts)
    assert len(ranges) == max(1, min(parts, count))
    assert ranges[0][0] == 0 and ranges[-1][1] == count
    assert all(hi == lo for (_, hi), (lo, _) in zip(ranges, ranges[1:]))
    sizes = [hi - lo for lo, hi in ranges]
    assert max(sizes) - min(sizes) <= 1 and (count == 0 or min(sizes) >= 1)


@pytest.mark.parametrize("threads", [1, 2, 3])
def test_every_task_runs_once_the_first_on_the_calling_thread(threads):
    ran = []
    barrier = threading.Barrier(threads)

    def task(k):
        # With threads > 1 the tasks of a group must run at once: each waits for the others here.
        if threads > 1:
            barrier.wait(timeout=30)
        ran.append((k, threading.get_ident()))

    with LaunchPool(threads) as pool:
        pool.run([lambda k=k: task(k) for k in range(threads)])
    assert sorted(k for k, _ in ran) == list(range(threads))
    assert dict(ran)[0] == threading.get_ident()
    assert len({ident for _, ident in ran}) == threads


def test_an_error_in_a_task_is_raised_after_every_task_has_finished():
    finished = []

    def fail():
        raise RuntimeError("task 1 failed")

    def slow():
        threading.Event().wait(0.05)
        finished.append("slow")

    with LaunchPool(3) as pool, pytest.raises(RuntimeError, match="task 1 failed"):
        pool.run([slow, fail, slow])
    assert finished == ["slow", "slow"]


@pytest.mark.parametrize("threads", [0, -1, 1.5, True, "2", None])
def test_threads_must_be_a_positive_integer(threads):
    with pytest.raises(ValueError, match=r"threads: expected an integer >= 1"):
        checked_threads(threads, "cpu")


def test_the_cpu_takes_the_threads_asked_for_and_cuda_one_launch(device):
    assert checked_threads(4, device) == (4 if device == "cpu" else 1)


@pytest.mark.parametrize("threads", [1, 2, 3])
def test_taken_in_turn_every_item_runs_once_and_the_threads_take_them_in_order(threads):
    started = []
    lock = threading.Lock()

    def job(item):
        with lock:
            started.append(item)

    with LaunchPool(threads) as pool:
        pool.take_in_turn([5, None, 3, 0, 8, 1, 2], job)
        pool.take_in_turn([], job)
    # Each thread takes the next item left: with one thread exactly the list's order.
    assert sorted(started, key=str) == sorted([5, None, 3, 0, 8, 1, 2], key=str)
    if threads == 1:
        assert started == [5, None, 3, 0, 8, 1, 2]


_DEBUG_LAUNCHES = '''
import sys
import numpy as np
import warp as wp
wp.config.quiet = True
wp.config.mode = "debug"
wp.config.kernel_cache_dir = sys.argv[1]
from csmlab.kernels.threads import LaunchPool

@wp.kernel
def add_one(a: wp.array(dtype=wp.float32)):
    i = wp.tid()
    a[i] = a[i] + 1.0

arrays = [wp.zeros(100000, dtype=wp.float32, device="cpu") for _ in range(4)]
with LaunchPool(4, kernels=(add_one,), device="cpu") as pool:
    for _ in range(300):
        pool.run([lambda a=a: wp.launch(add_one, dim=a.shape[0], inputs=(a,), device="cpu") for a in arrays])
print(sorted({float(v) for a in arrays for v in np.unique(a.numpy())}))
'''


def test_launches_of_one_module_built_in_warp_debug_mode_survive_a_pool_of_threads(tmp_path):
    # Concurrent debug-mode launches of one module read Warp's shared tile-storage pointer after
    # another launch reset it (threads.py's docstring): the process died of a segfault within
    # 300 rounds of four overlapping launches. A subprocess, so that a crash is this test's failure.
    script = tmp_path / "debug_launches.py"
    script.write_text(_DEBUG_LAUNCHES)
    done = subprocess.run([sys.executable, str(script), str(tmp_path / "kernels")], capture_output=True, text=True,
                          timeout=300, env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip().splitlines()[-1] == "[300.0]"
