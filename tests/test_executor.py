"""Executors: a process pool and a Dask LocalCluster give the in-process run's metrics.csv byte for byte."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from csmlab.config import load_experiment
from csmlab.errors import InputError
from csmlab.executor import EXECUTORS, execute, executor_for, kept_processes, task_runs
from csmlab.experiment import run_experiment

TINY = """
name = "tiny"
extends = ["methods/exact", "methods/quantized", "methods/none"]
chunk_frames = 2

[scene]
kind = "terrain"
resolution = 24
trees = 60
ring_trees = 60

[camera]
path = "walk"
frames = 6
width = 64
height = 36

[shadow]
cascades = 2
resolution = 128
shadow_distance = 40.0
"""


# With TAA a unit is every frame of one variant: the executors run the variants side by side.
TINY_TAA = TINY.replace("frames = 6", "frames = 3") + "\n[taa]\nenabled = true\nphases = 4\n"


def run(tmp_path, name: str, text: str = TINY, **options):
    path = tmp_path / "tiny.toml"
    path.write_text(text)
    return run_experiment(load_experiment(path), out_dir=tmp_path / name, **options)


@pytest.fixture(scope="module")
def inprocess(tmp_path_factory):
    out = tmp_path_factory.mktemp("inprocess")
    run(out, "out")
    return out / "out" / "metrics.csv"


@pytest.mark.slow
def test_process_pool_gives_the_inprocess_csv(inprocess, tmp_path):
    result = run(tmp_path, "pool", executor="pool", jobs=2)
    assert result.chunks_run == 3
    assert (tmp_path / "pool" / "metrics.csv").read_bytes() == inprocess.read_bytes()


@pytest.fixture(scope="module")
def inprocess_taa(tmp_path_factory):
    out = tmp_path_factory.mktemp("inprocess_taa")
    run(out, "out", TINY_TAA)
    return out / "out"


@pytest.mark.slow
@pytest.mark.parametrize("options", [dict(executor="pool"), dict(executor="dask", address="local")],
                         ids=["pool", "dask"])
def test_taa_variants_on_two_workers_give_the_inprocess_files(inprocess_taa, tmp_path, options):
    result = run(tmp_path, "taa", TINY_TAA, jobs=2, **options)
    assert result.chunks_run == 3
    for name in ("metrics.csv", "summary.json", "pixels/exact__base.npz", "pixels/none__base.npz"):
        assert (tmp_path / "taa" / name).read_bytes() == (inprocess_taa / name).read_bytes()


@pytest.mark.slow
def test_dask_local_workers_keep_glibcs_adaptive_mmap_threshold():
    # Dask's default MALLOC_TRIM_THRESHOLD_ would map and fault in every large array afresh; the
    # thread limits stay. os.getenv(key, default) runs in the worker, which is given the key as the
    # shared value and the default as the task.
    from csmlab.executor import run_dask

    for key, expected in (("MALLOC_TRIM_THRESHOLD_", "unset"), ("OMP_NUM_THREADS", "1")):
        ((_, value),) = run_dask(os.getenv, ["unset"], shared=key, jobs=1, address="local")
        assert value == expected


@pytest.mark.slow
def test_dask_local_cluster_gives_the_inprocess_csv(inprocess, tmp_path):
    run(tmp_path, "dask", executor="dask", jobs=2, address="local")
    assert (tmp_path / "dask" / "metrics.csv").read_bytes() == inprocess.read_bytes()


def _add(shared, task):
    return shared + task


def test_task_runs_cut_the_tasks_into_consecutive_runs_of_near_equal_length():
    for tasks in range(0, 14):
        for processes in range(1, 5):
            runs = task_runs(tasks, processes)
            assert len(runs) == processes and sum(runs, []) == list(range(tasks))
            assert max(map(len, runs)) - min(map(len, runs)) <= 1


def _pid_of(shared, task):
    return task, os.getpid()


def test_the_pool_starts_each_process_on_a_run_of_its_own_and_runs_every_task_once():
    order = [result for _, result in execute(_pid_of, range(8), shared=None, executor="pool", jobs=2)]
    assert sorted(task for task, _ in order) == list(range(8))
    first = {}
    for task, pid in order:
        first.setdefault(pid, task)
    assert sorted(first.values()) == [0, 4]


def test_inprocess_executor_hands_shared_data_to_every_task():
    assert sorted(execute(_add, [1, 2, 3], shared=10)) == [(1, 11), (2, 12), (3, 13)]


def test_unknown_executor_lists_the_valid_ones():
    with pytest.raises(ValueError, match=str(sorted(EXECUTORS))):
        list(execute(_add, [1], shared=0, executor="threads"))


def test_command_line_options_pick_the_executor():
    cores = os.cpu_count() or 1
    assert executor_for(jobs=None, scheduler=None) == (("pool", cores, None) if cores > 1 else ("inprocess", 1, None))
    assert executor_for(jobs=1, scheduler=None) == ("inprocess", 1, None)
    assert executor_for(jobs=3, scheduler=None) == ("pool", 3, None)
    assert executor_for(jobs=2, scheduler="local") == ("dask", 2, "local")
    assert executor_for(jobs=None, scheduler="tcp://10.0.0.1:8786")[::2] == ("dask", "tcp://10.0.0.1:8786")
    with pytest.raises(InputError, match="--scheduler"):
        executor_for(jobs=None, scheduler="10.0.0.1")
    with pytest.raises(InputError, match="--jobs"):
        executor_for(jobs=0, scheduler=None)


def test_a_process_that_freezes_its_objects_at_exit_still_runs_every_other_exit_handler():
    # Handlers run last registered first: the one registered before sees the freeze done, the one
    # registered after runs before it, and the process exits cleanly.
    script = """
import atexit, gc
atexit.register(lambda: print("frozen", gc.get_freeze_count() > 0, flush=True))
from csmlab.executor import freeze_objects_at_exit
freeze_objects_at_exit()
atexit.register(lambda: print("before", gc.get_freeze_count() == 0, flush=True))
"""
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["before", "True", "frozen", "True"]


STATE = """
import sys
from pathlib import Path

import warp._src.context


def worker_state(queue):
    import csmlab

    queue.put((csmlab.__file__, "csmlab.render" in sys.modules, "colour" in sys.modules,
               warp._src.context.runtime is None))


def main():
    import csmlab
    from csmlab.executor import process_context, start_process_server

    start_process_server()
    context = process_context()
    queue = context.Queue()
    process = context.Process(target=worker_state, args=(queue,))
    process.start()
    print(repr((csmlab.__file__, *queue.get(timeout=120))))
    process.join()


if __name__ == "__main__":
    main()
"""


@pytest.mark.skipif(sys.platform == "win32", reason="no forkserver start method")
def test_a_process_forked_from_the_server_has_the_parents_csmlab_imported_and_warp_not_started(tmp_path):
    # Run from a folder holding another package named csmlab, as `csmlab run` in a second checkout
    # runs: Python 3.11's server puts its working folder first on its path, and would import that one.
    (tmp_path / "script").mkdir()
    (tmp_path / "script" / "state.py").write_text(STATE)
    (tmp_path / "csmlab").mkdir()
    (tmp_path / "csmlab" / "__init__.py").write_text("raise ImportError('the decoy csmlab')\n")
    here = str(Path(__file__).resolve().parent.parent)
    environment = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [here, os.environ.get("PYTHONPATH")])))
    done = subprocess.run([sys.executable, str(tmp_path / "script" / "state.py")], capture_output=True, text=True,
                          timeout=300, cwd=tmp_path, env=environment)
    assert done.returncode == 0, done.stderr
    parents, workers, render_imported, colour_imported, warp_not_started = eval(done.stdout)
    assert workers == parents == str(Path(here) / "csmlab" / "__init__.py")
    assert render_imported and colour_imported and warp_not_started


def _pid_with_shared(shared, task):
    return shared, os.getpid()


def test_kept_processes_serve_every_call_of_the_block_each_with_its_own_shared_data():
    with kept_processes():
        first = [result for _, result in execute(_pid_with_shared, range(4), shared="a", executor="pool", jobs=2)]
        second = [result for _, result in execute(_pid_with_shared, range(4), shared="b", executor="pool", jobs=2)]
    assert {shared for shared, _ in first} == {"a"} and {shared for shared, _ in second} == {"b"}
    assert {pid for _, pid in first} == {pid for _, pid in second} and len({pid for _, pid in first}) == 2
    after = [result for _, result in execute(_pid_with_shared, range(4), shared="c", executor="pool", jobs=2)]
    assert not {pid for _, pid in after} & {pid for _, pid in first}


def _fails_on_two(shared, task):
    if task == 2:
        raise RuntimeError("task 2")
    return os.getpid()


def test_a_call_that_fails_inside_the_block_ends_its_processes_and_the_next_call_starts_new_ones():
    before = set()
    with kept_processes():
        with pytest.raises(RuntimeError, match="task 2"):
            for _, pid in execute(_fails_on_two, range(6), shared=None, executor="pool", jobs=2):
                before.add(pid)
        pids = {pid for _, pid in execute(_fails_on_two, [0, 1, 3, 4], shared=None, executor="pool", jobs=2)}
    assert len(pids) == 2 and before and not pids & before


def _refuse_to_load(message):
    raise RuntimeError(message)


class _Unloadable:
    """Shared data that pickles in the caller and fails to load in a worker."""

    def __reduce__(self):
        return _refuse_to_load, ("shared data not loaded",)


def test_shared_data_a_process_cannot_load_fails_the_call_with_its_error_not_results_of_the_previous_data():
    with kept_processes():
        assert {shared for _, (shared, _) in execute(_pid_with_shared, range(4), shared="a", executor="pool",
                                                     jobs=2)} == {"a"}
        with pytest.raises(RuntimeError, match="shared data not loaded"):
            list(execute(_pid_with_shared, range(4), shared=_Unloadable(), executor="pool", jobs=2))
