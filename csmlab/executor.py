"""Where units of work run: in this process, a local process pool, or a Dask cluster.

An executor calls ``fn(shared, task)`` for every task and yields ``(task, result)`` as results come
in, in whatever order they finish; callers that need an order sort the results themselves. ``shared``
(the scene and everything else common to all tasks) reaches each worker once, not once per task:
the pool hands it to each process's initializer, Dask scatters it to every worker.

Warp's CPU backend runs one kernel launch on one thread, so parallelism comes from processes: the
pool's processes are forked from a process server (:func:`process_context`) that has imported
csmlab's modules but never started Warp (a forked Warp or CUDA context is not safe), and Dask
workers have one thread each. ``fn`` must be importable (a module-level function) and ``shared``,
tasks and results picklable.
"""

from __future__ import annotations

import atexit
import contextlib
import gc
import logging
import multiprocessing
import os
import pickle
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from pathlib import Path

from csmlab.errors import InputError
from csmlab.registry import dispatch

__all__ = ["EXECUTORS", "WORKER_MODULES", "execute", "executor_for", "freeze_objects_at_exit", "kept_processes",
           "process_context", "run_dask", "run_inprocess", "run_pool", "start_process_server", "start_worker",
           "task_runs"]

_SHARED = None
_KEPT: dict | None = None
"""The pool's processes by (start method, count) while a :func:`kept_processes` block runs; None outside one."""


def freeze_objects_at_exit() -> None:
    """Have this process's exit skip the garbage collector's last pass over the objects still alive.

    A process that has imported csmlab's stack (Warp, colour, SciPy, Matplotlib: about 280,000
    objects the collector tracks) spent 0.5–0.6 s of its exit in that pass, freeing memory the
    operating system takes back anyway. :func:`gc.freeze` at exit takes them out of it (the exit
    then takes 0.04 s); reference counting still releases them, and the exit handlers registered
    after this call run before it. The command line and every process csmlab starts call this
    first, so that no one waits on a process's exit.
    """
    atexit.register(gc.freeze)


def process_context() -> multiprocessing.context.BaseContext:
    """The start method of the processes csmlab starts itself: ``forkserver`` where the platform has it, else ``spawn``.

    A spawned process is a fresh interpreter that imports csmlab, Warp, SciPy and colour-science
    (with Matplotlib) itself: 1.5–2 s of CPU in every process, before its first task. A process
    forked from the process server starts with whatever the server imported
    (:func:`start_process_server`); the server never starts Warp, so each process starts its own
    Warp and CUDA context, as a spawned one does. Without a server started beforehand, the first
    process started starts a bare one, and its processes import what they need themselves.
    """
    if "forkserver" in multiprocessing.get_all_start_methods():
        return multiprocessing.get_context("forkserver")
    return multiprocessing.get_context("spawn")


WORKER_MODULES = ("csmlab.worker_imports",)
"""The modules the process server imports for csmlab's workers (:mod:`csmlab.worker_imports`)."""


def start_process_server(modules: Sequence[str] = WORKER_MODULES) -> None:
    """Start the process server of :func:`process_context` now, importing ``modules``, unless it runs already.

    The server is a process of its own: its imports overlap whatever this process does until it
    starts its first worker, which then waits only for the imports still unfinished. A server
    already running keeps the modules it was started with. An import error in the server leaves
    that module to the processes; nothing is started where the start method is ``spawn``.
    """
    context = process_context()
    if context.get_start_method() != "forkserver":
        return
    from multiprocessing import forkserver

    import csmlab

    context.set_forkserver_preload(list(modules))
    # Python 3.11's server does not take this process's sys.path: it imports from its working
    # folder first, then the installed packages. Started in the folder this process's csmlab
    # lies in, it imports the same csmlab — a checkout's, or the installed one — whatever folder
    # the command runs in. Forked processes still work in this process's folder.
    here = os.getcwd()
    os.chdir(Path(csmlab.__file__).resolve().parent.parent)
    try:
        forkserver.ensure_running()
    finally:
        os.chdir(here)


def start_worker() -> None:
    """Prepare a process for csmlab's work: its exit skips the collector, Warp starts quietly.

    Warp's start-up (:func:`csmlab.kernels.start_warp`) drops the CUDA-driver warning Warp's native
    library prints once per process on a machine without a GPU.
    """
    from csmlab.kernels import start_warp

    freeze_objects_at_exit()
    start_warp()


def run_inprocess(fn: Callable, tasks: list, *, shared, jobs: int = 1, address: str | None = None) -> Iterator:
    """Run the tasks one after another in this process."""
    if tasks:
        from csmlab.kernels import start_warp

        start_warp()
    for task in tasks:
        yield task, fn(shared, task)


def _install_shared(packed: bytes) -> None:
    global _SHARED
    # Let go of the previous call's data first: its memory, and no task of a failed install reads it.
    _SHARED = None
    _SHARED = pickle.loads(packed)


def _call_with_shared(fn: Callable, task):
    return fn(_SHARED, task)


@contextlib.contextmanager
def kept_processes() -> Iterator[None]:
    """Keep :func:`run_pool`'s processes from one call to the next until the block ends.

    A run's processes otherwise start with the run and end with it; a block of many short runs
    (a tune's candidates: ``tune_default`` makes 16 runs of 12 frames) then pays each process's
    start, its Warp kernels loaded, its scene prepared (:func:`csmlab.experiment.run_chunk` keeps
    it per workload) and its first frame's allocations once a run. Kept, each call hands them its
    ``shared`` data as their first task. A block inside a block keeps the outer one's processes;
    an error in a call ends its processes, and the next call starts new ones.
    """
    global _KEPT
    if _KEPT is not None:
        yield
        return
    _KEPT = {}
    try:
        yield
    finally:
        kept, _KEPT = _KEPT, None
        for lanes in kept.values():
            _shut_down(lanes)


def _lanes(context, count: int) -> list[ProcessPoolExecutor]:
    """``count`` single-process pools: new ones, or those a :func:`kept_processes` block keeps."""
    key = (context.get_start_method(), count)
    if _KEPT is not None and key in _KEPT:
        return _KEPT[key]
    # One single-process pool per process, so that the next task of a run goes to its process.
    lanes = [ProcessPoolExecutor(max_workers=1, mp_context=context, initializer=start_worker) for _ in range(count)]
    if _KEPT is not None:
        _KEPT[key] = lanes
    return lanes


def _shut_down(lanes: list[ProcessPoolExecutor]) -> None:
    for lane in lanes:
        lane.shutdown(wait=True, cancel_futures=True)


def run_pool(fn: Callable, tasks: list, *, shared, jobs: int, address: str | None = None) -> Iterator:
    """Run the tasks on ``jobs`` local processes (:func:`process_context`), ``shared`` installed once per process.

    Each process takes a run of consecutive tasks in list order (the tasks cut into ``jobs`` runs),
    one at a time; a process whose run is done takes over the second half of the longest run left.
    A task then mostly follows its own predecessor in the same process, which a task may use: a
    chunk of frames starts from the previous chunk's last frame, kept in the process, instead of
    rendering it again (:func:`csmlab.experiment.run_chunk`). Stopping the iteration early (an
    exception in the caller, Ctrl-C) cancels the tasks not yet started and waits for the running ones.
    The processes end with the call, unless a :func:`kept_processes` block keeps them for the next.
    """
    if len(tasks) <= 1 or jobs <= 1:
        # One task gains nothing from a process of its own, and starting one costs seconds.
        yield from run_inprocess(fn, tasks, shared=shared)
        return
    context = process_context()
    # Pickled here, unpickled by each process's first task: unpickling the shared objects in the
    # stream a process reads its task from would import their modules (seconds, where the process
    # server has not) with this process blocked on the pipe — one process after another.
    packed = pickle.dumps(shared, protocol=pickle.HIGHEST_PROTOCOL)
    count = max(1, min(jobs, len(tasks)))
    runs = task_runs(len(tasks), count)
    lanes = _lanes(context, count)
    # A lane runs its tasks in order: its install is done when its first task is. Its error is raised
    # before any result of the lane is taken.
    installs = [lane.submit(_install_shared, packed) for lane in lanes]
    running = {}

    def feed(lane: int) -> None:
        if not runs[lane]:
            longest = max(range(count), key=lambda other: len(runs[other]))
            half = len(runs[longest]) // 2 or len(runs[longest])
            runs[lane] = runs[longest][-half:]
            del runs[longest][-half:]
        if runs[lane]:
            index = runs[lane].pop(0)
            running[lanes[lane].submit(_call_with_shared, fn, tasks[index])] = (lane, index)

    finished = False
    try:
        for lane in range(count):
            feed(lane)
        while running:
            done, _ = wait(running, return_when=FIRST_COMPLETED)
            for future in done:
                lane, index = running.pop(future)
                installs[lane].result()
                result = future.result()
                feed(lane)
                yield tasks[index], result
        finished = True
    finally:
        for future in running:
            future.cancel()
        if not finished and _KEPT is not None:
            # Processes an error or a stopped iteration left busy, or broken, are not kept for the next call.
            _KEPT.pop((context.get_start_method(), count), None)
        if not finished or _KEPT is None:
            _shut_down(lanes)


def task_runs(tasks: int, processes: int) -> list[list[int]]:
    """Task indices ``0 … tasks − 1`` cut into ``processes`` runs of consecutive indices, as even as can be."""
    bounds = [round(k * tasks / processes) for k in range(processes + 1)]
    return [list(range(bounds[k], bounds[k + 1])) for k in range(processes)]


def _local_worker_config() -> dict:
    """Dask settings of a LocalCluster's workers: Dask's own, less ``MALLOC_TRIM_THRESHOLD_`` and the profiler.

    Dask's pre-spawn environment keeps its thread limits but also sets ``MALLOC_TRIM_THRESHOLD_``,
    which turns off glibc's adaptive mmap threshold: every array over 128 KiB is then mapped and
    unmapped afresh, its pages faulted in each time, and a frame's metrics took 1.8× as long as in
    a plain process (158 vs 87 ms). The sampling profiler, which no one reads here, takes the GIL
    every 10 ms.
    """
    import dask

    environment = dict(dask.config.get("distributed.nanny.pre-spawn-environ", default={}))
    environment.pop("MALLOC_TRIM_THRESHOLD_", None)
    return {"distributed.nanny.pre-spawn-environ": environment, "distributed.worker.profile.enabled": False}


def run_dask(fn: Callable, tasks: list, *, shared, jobs: int, address: str | None) -> Iterator:
    """Run the tasks on a Dask cluster: ``address="local"`` starts a LocalCluster of ``jobs``
    single-threaded worker processes, ``tcp://HOST:PORT`` connects to a running scheduler (its
    workers must be able to import csmlab)."""
    import dask
    from dask.distributed import Client, LocalCluster, as_completed

    if not tasks:
        return
    cluster = None
    if address == "local":
        with dask.config.set(_local_worker_config()):
            cluster = LocalCluster(n_workers=max(1, min(jobs, len(tasks))), threads_per_worker=1, processes=True,
                                   dashboard_address=None, silence_logs=logging.ERROR)
        client = Client(cluster)
    else:
        try:
            client = Client(address, timeout="10s")
        except (OSError, ValueError, TimeoutError) as exc:
            raise InputError(f"expected a reachable Dask scheduler, got {exc}", field="--scheduler") from None
    try:
        if cluster is not None:
            # The workers this run started: the run does not wait for their exits, nor reads Warp's warning.
            client.run(start_worker)
        shared_future = client.scatter(shared, broadcast=True)
        futures = {client.submit(fn, shared_future, task, pure=False): task for task in tasks}
        try:
            for future in as_completed(futures):
                result = future.result()
                # Released as soon as it is here: a worker keeps no finished chunk, so its memory
                # stays at one chunk's state however long the path.
                future.release()
                yield futures.pop(future), result
        finally:
            client.cancel(list(futures))
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


EXECUTORS: dict[str, Callable[..., Iterator]] = {
    "inprocess": run_inprocess,
    "pool": run_pool,
    "dask": run_dask,
}
"""Executors by name: ``inprocess``, ``pool`` (``--jobs N``), ``dask`` (``--scheduler``)."""


def execute(fn: Callable, tasks: Iterable, *, shared, executor: str = "inprocess", jobs: int = 1,
            address: str | None = None) -> Iterator:
    """``(task, fn(shared, task))`` for every task, as they finish, on the executor named ``executor``.

    Parameters
    ----------
    fn : callable
        A module-level function ``fn(shared, task) -> result``.
    tasks : iterable
        Picklable task descriptions.
    shared : object
        Picklable data every task needs, sent once per worker.
    executor : str
        A key of :data:`EXECUTORS`.
    jobs : int
        Worker processes (pool, local Dask cluster).
    address : str, optional
        Dask: ``"local"`` or a scheduler address ``tcp://HOST:PORT``.
    """
    return dispatch(EXECUTORS, executor, fn, list(tasks), field="executor", shared=shared,
                    offered={"jobs": jobs, "address": address})


def executor_for(*, jobs: int | None, scheduler: str | None) -> tuple[str, int, str | None]:
    """``(executor, jobs, address)`` for the command line's ``--jobs`` and ``--scheduler``.

    ``--scheduler`` picks Dask (a local cluster of ``--jobs`` workers, all cores when not given);
    otherwise the process pool with ``--jobs`` processes — all cores when not given, since Warp's
    CPU backend runs each launch on one thread — and ``--jobs 1`` runs in this process.

    Raises
    ------
    InputError
        On ``--jobs`` below 1 or a scheduler that is neither ``local`` nor ``tcp://HOST:PORT``.
    """
    if jobs is not None and jobs < 1:
        raise InputError(f"expected at least 1 process, got {jobs}", field="--jobs")
    if scheduler is not None:
        if scheduler != "local" and not scheduler.startswith(("tcp://", "tls://", "ucx://", "inproc://")):
            raise InputError(f"expected 'local' or a scheduler address like tcp://HOST:PORT, got {scheduler!r}",
                             field="--scheduler")
        return "dask", jobs or os.cpu_count() or 1, scheduler
    jobs = (os.cpu_count() or 1) if jobs is None else jobs
    if jobs > 1:
        return "pool", jobs, None
    return "inprocess", 1, None
