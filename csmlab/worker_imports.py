"""What csmlab's worker processes import, imported once by the process server they are forked from.

:func:`csmlab.executor.start_process_server` names this module to the ``forkserver`` start method
(:func:`csmlab.executor.process_context`): the server imports it while the command line reads the
experiment and builds the workload, and every pool worker — and the report's picture process —
is forked from the server with these modules already imported, instead of importing Warp, SciPy,
colour-science and Matplotlib afresh (1.5–2 s of CPU a process). What it imports is what a
worker's first unit of work imports (:func:`csmlab.experiment.run_chunk`); Warp is imported, never
started, so that each forked process starts its own Warp and CUDA context.

Importing this module also freezes every object imported so far (:func:`gc.freeze`): the garbage
collector of a forked process, and of the server at its exit, then never walks the ~280,000
objects of these libraries, and a forked process does not copy the server's pages by touching
their headers.
"""

from __future__ import annotations

import gc

import threadpoolctl  # noqa: F401

import csmlab.experiment  # noqa: F401
import csmlab.metrics  # noqa: F401
import csmlab.metrics.taa  # noqa: F401
import csmlab.render  # noqa: F401
import csmlab.report.capture  # noqa: F401
import csmlab.report.pixels  # noqa: F401

__all__: list[str] = []

gc.freeze()
