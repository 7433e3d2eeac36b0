"""Warp CPU launches split over Python threads, each launch writing outputs no other launch writes.

A Warp CPU launch runs every thread of its grid one after another on the calling thread, but it is
a ctypes call that releases the GIL: launches made from several Python threads run on several
cores at once. Warp's CPU atomics are atomic only within one launch, so the wrappers that split
their work here give every concurrent launch its own part of the outputs — a band of rows, a
range of receivers, or a private buffer merged afterwards — and the result does not depend on how
many threads ran it. On CUDA one launch already fills the device: ``threads`` is ignored there.

Warp's debug mode (``wp.config.mode = "debug"``, bounds-checked indexing) is the exception: each
CPU launch parks its stack-allocated tile storage in one static pointer per module (Warp's
``native/tile.h``, ``tile_shared_storage_t``, x86-64 with ``enable_tiles_in_stack_memory``) and
restores the previous value on return, and only debug builds read through it on return (the
``check()`` assertion) — concurrent launches of one module then read a pointer another launch
has reset to null or left dangling, and crash. :class:`LaunchPool` runs such launches one after
another instead, with the same results.
"""

from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor
from collections.abc import Callable, Sequence

import warp as wp

__all__ = ["LaunchPool", "checked_threads", "split_range"]


def checked_threads(threads, device: str) -> int:
    """The number of concurrent CPU launches to use: ``threads`` on the CPU, 1 on CUDA.

    Raises
    ------
    ValueError
        If ``threads`` is not an integer ≥ 1.
    """
    if isinstance(threads, bool) or not isinstance(threads, int) or threads < 1:
        raise ValueError(f"threads: expected an integer >= 1 (concurrent CPU launches), got {threads!r}")
    return int(threads) if wp.get_device(device).is_cpu else 1


def split_range(count: int, parts: int) -> list[tuple[int, int]]:
    """``[0, count)`` cut into ``min(parts, count)`` consecutive ranges ``(lo, hi)`` of sizes differing by at most 1.

    An empty range gives one empty part, so that a split always has a first part.
    """
    parts = max(1, min(parts, count))
    return [(count * k // parts, count * (k + 1) // parts) for k in range(parts)]


class LaunchPool:
    """Runs groups of tasks (each making Warp launches), one group at a time, on up to ``threads`` threads.

    The first task of a group runs on the calling thread, the others on a pool of ``threads − 1``
    that lives as long as the ``with`` block (a pool kept across calls would not survive the fork
    of a process-pool worker).

    Parameters
    ----------
    threads : int
        Checked by :func:`checked_threads`.
    kernels : sequence of wp.Kernel
        Kernels the tasks launch: their modules are loaded on ``device`` before any task runs, as
        Warp's loading on first launch is not meant to run from two threads at once. If Warp is in
        debug mode, or any of their modules is, every group runs on the calling thread (the
        module's docstring).
    device : str
    """

    def __init__(self, threads: int, *, kernels: Sequence = (), device: str = "cpu"):
        self.threads = threads
        self._concurrent = threads > 1 and not _debug_build(kernels)
        if self._concurrent:
            for module in {id(k.module): k.module for k in kernels}.values():
                # The variant a launch on ``device`` loads (one thread per block on the CPU).
                wp.load_module(module, device=device)
        self._pool = None

    def __enter__(self) -> LaunchPool:
        if self._concurrent:
            self._pool = ThreadPoolExecutor(self.threads - 1, thread_name_prefix="csmlab-launch")
        return self

    def __exit__(self, *exc) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None

    def run(self, tasks: Sequence[Callable[[], object]]) -> None:
        """Run every task of ``tasks`` and return when all have finished; the first error is raised."""
        if not tasks:
            return
        if self._pool is None or len(tasks) == 1:
            for task in tasks:
                task()
            return
        futures = [self._pool.submit(task) for task in tasks[1:]]
        try:
            tasks[0]()
        finally:
            errors = [f.exception() for f in futures]
        for error in errors:
            if error is not None:
                raise error

    def take_in_turn(self, items: Sequence, job: Callable[[object], object]) -> None:
        """Run ``job(item)`` for every item of ``items``: each thread takes the next item left, in order, until none is.

        A work queue: with the items listed costliest first, the threads finish together however
        unequal the items are. The jobs of two items run at once, so they must write disjoint outputs.
        """
        queue = iter(items)
        lock = threading.Lock()

        def work() -> None:
            while True:
                with lock:
                    item = next(queue, _NONE_LEFT)
                if item is _NONE_LEFT:
                    return
                job(item)

        self.run([work] * min(self.threads, len(items)))


def _debug_build(kernels: Sequence) -> bool:
    """Whether Warp builds any of ``kernels``' modules (or, with none given, every module) in debug mode."""
    modes = {k.module.options.get("mode") or wp.config.mode for k in kernels} or {wp.config.mode}
    return "debug" in modes


_NONE_LEFT = object()
"""What :meth:`LaunchPool.take_in_turn`'s queue gives when it is empty (``None`` may be an item)."""
