"""A second process for the report's pictures, so that a report uses both cores of a small machine.

Most of a report's time goes to pictures that need nothing from each other: the snapshot strips
(matplotlib), the 3D view (VTK) and the interactive folder's frame files (WebP). A
:class:`PicturePool` hands pictures to one worker process while this process makes the rest, then
draws here every picture the worker has not started, so that neither process waits while the other
has work queued. The worker is forked from csmlab's process server
(:func:`csmlab.executor.process_context`): after a run, whose server has imported csmlab and
matplotlib, it imports only PyVista for the 3D view; a bare server's worker imports csmlab and
matplotlib afresh too (about a second), which pays only for pictures that take longer than that:
the caller decides with ``worker=``.

A picture drawn in the worker is the same, byte for byte, as one drawn here: same code, same
libraries, no shared state.
"""

from __future__ import annotations

from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from typing import Any
from collections.abc import Callable

from csmlab.executor import freeze_objects_at_exit, process_context

__all__ = ["Picture", "PicturePool"]


class Picture:
    """One submitted picture: :meth:`result` is what its function returned, wherever it ran."""

    def __init__(self, function: Callable, args: tuple, kwargs: dict, future: Future | None):
        self._call = (function, args, kwargs)
        self._future = future
        self._done = False
        self._value: Any = None

    def _run_here(self) -> None:
        function, args, kwargs = self._call
        self._value = function(*args, **kwargs)
        self._done = True

    def take_back(self) -> None:
        """Draw the picture in this process unless the worker has started it."""
        if not self._done and (self._future is None or self._future.cancel()):
            self._run_here()

    def result(self) -> Any:
        """The function's return value; its exception if it raised one.

        A worker that died (a crash in a native library) costs its pictures a second try here.
        """
        if not self._done:
            try:
                self._value = self._future.result()
                self._done = True
            except BrokenProcessPool:
                self._run_here()
        return self._value


class PicturePool:
    """Draw pictures in one worker process and in this one; a context manager.

    :meth:`submit` each picture (a module-level function and picklable arguments), do this
    process's own work, then :meth:`finish`: it draws here, latest first, every picture the worker
    has not started, and waits for the others. Leaving the ``with`` block lets the worker go.

    Parameters
    ----------
    worker : bool, keyword-only
        Start the worker process. Without one (or when it cannot be started) every picture is
        drawn here, in :meth:`finish`.
    """

    def __init__(self, *, worker: bool):
        self._pictures: list[Picture] = []
        self._executor = None
        if worker:
            self._executor = ProcessPoolExecutor(max_workers=1, mp_context=process_context(),
                                                 initializer=freeze_objects_at_exit)

    def __enter__(self) -> PicturePool:
        return self

    def __exit__(self, *exc) -> None:
        if self._executor is not None:
            # Not waiting: a worker takes a third of a second to exit (VTK lets go of its EGL display), and by
            # now every picture is drawn, or the caller is on its way out with an error. The interpreter joins
            # the worker when it exits.
            self._executor.shutdown(wait=False, cancel_futures=True)
            self._executor = None

    def submit(self, function: Callable, /, *args, **kwargs) -> Picture:
        """Queue ``function(*args, **kwargs)`` for the worker; return its :class:`Picture`."""
        future = None
        if self._executor is not None:
            try:
                future = self._executor.submit(function, *args, **kwargs)
            except (OSError, BrokenProcessPool):
                # No second process on this machine (or it died): the pictures are drawn here.
                self._executor.shutdown(wait=False, cancel_futures=True)
                self._executor = None
        picture = Picture(function, args, kwargs, future)
        self._pictures.append(picture)
        return picture

    def finish(self) -> None:
        """Draw here each picture the worker has not started (the worker takes the earliest first), then wait."""
        for picture in reversed(self._pictures):
            picture.take_back()
        for picture in self._pictures:
            picture.result()
