"""Wall time and CPU time of a command and of every process it starts, those it leaves behind included.

``/usr/bin/time`` counts the CPU of the processes its command waits for. A pool's processes are
forked from multiprocessing's process server (:func:`csmlab.executor.process_context`), which the
server, not the command, waits for, and the command leaves the server to exit after it: their CPU
— most of a run's — is missing from ``/usr/bin/time``'s ``user``. This script makes itself a child
subreaper (Linux's ``PR_SET_CHILD_SUBREAPER``): a process whose parent exits is handed to it, and it
waits for every one, so ``RUSAGE_CHILDREN`` holds them all.

Usage::

    python benchmarks/run_cpu.py python -m csmlab.cli run --out /tmp/run

prints ``wall W s (all exited A s) user U s sys S s`` to stderr: W until the command exits, A until
the last process it started has exited. Linux only.
"""

from __future__ import annotations

import ctypes
import os
import resource
import subprocess
import sys
import time

_PR_SET_CHILD_SUBREAPER = 36


def main(command: list[str]) -> int:
    """Run ``command``, wait for it and for every process it leaves; print the times; return its exit status."""
    if not command:
        print(__doc__, file=sys.stderr)
        return 2
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.prctl(_PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0) != 0:
        raise OSError(ctypes.get_errno(), "prctl(PR_SET_CHILD_SUBREAPER) failed")
    began = time.perf_counter()
    status = subprocess.call(command)
    command_s = time.perf_counter() - began
    while True:
        try:
            os.wait()
        except ChildProcessError:
            break
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    print(f"wall {command_s:.2f} s (all exited {time.perf_counter() - began:.2f} s) user {usage.ru_utime:.2f} s "
          f"sys {usage.ru_stime:.2f} s", file=sys.stderr)
    return status


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
