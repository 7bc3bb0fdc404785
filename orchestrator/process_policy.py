"""How a run sets up the process it steps in: its BLAS threads and Python's garbage collector.

A field of the run's options (orchestrator/plan.py ``RunOptions.process``), so that the process
that makes the runs says what holds for them: a study's run process, which keeps its objects
frozen (orchestrator/study/runner.py), or a benchmark comparing without the collector's switch
(benchmarks/bench_deadline.py).
"""
from __future__ import annotations

import contextlib
import gc
import os
from dataclasses import dataclass

from threadpoolctl import threadpool_limits

from orchestrator.errors import UserError

#: the BLAS libraries' own variables for their number of threads, read when a library loads
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS")


@dataclass(frozen=True)
class ProcessPolicy:
    #: BLAS threads while the run makes and steps its components: the cores' matrices are small
    #: (≤ 60 states), and a second thread only spins and takes the other core from the process
    #: (measured 1.8× slower model generation)
    blas_threads: int = 1
    #: Python's garbage collector frozen and off while the master steps (False: as it is, which
    #: benchmarks/bench_deadline.py --gc-frozen-off compares with)
    collector_off: bool = True
    #: the process froze what it holds for good and makes run after run (a study's run process):
    #: its runs turn the collector off while stepping and freeze nothing — what a run froze would
    #: stay frozen after it, its cyclic garbage never collected — nor count what is frozen
    #: (gc.get_freeze_count walks every frozen object: 5–20 ms in a study's worker)
    host_keeps_frozen: bool = False

    def __post_init__(self):
        if isinstance(self.blas_threads, bool) or not isinstance(self.blas_threads, int) or self.blas_threads < 1:
            raise UserError(f"blas_threads {self.blas_threads!r}: must be a whole number of threads, at least 1")

    @contextlib.contextmanager
    def blas_limited(self):
        """At most ``blas_threads`` BLAS threads: threadpoolctl limits the libraries loaded
        already, and the libraries' own environment variables, set for the block's duration,
        hold for those loaded during it. An FMU's module loads scipy.linalg (and with it scipy's
        own OpenBLAS) when the component is made, after the limit was entered: threadpoolctl
        does not see it, and two threads summing in another order change results in their last
        digit."""
        saved = {name: os.environ.get(name) for name in BLAS_THREAD_VARIABLES}
        os.environ.update({name: str(self.blas_threads) for name in BLAS_THREAD_VARIABLES})
        try:
            with threadpool_limits(limits=self.blas_threads, user_api="blas"):
                yield
        finally:
            for name, value in saved.items():
                if value is None:
                    os.environ.pop(name, None)
                else:
                    os.environ[name] = value

    @contextlib.contextmanager
    def stepping(self):
        """Python's cyclic garbage collector frozen and off for the stepping, as it was after.

        A collection stops the step it falls in: up to a millisecond for the oldest generation
        over everything initialisation made (measured at one sample per frame,
        docs/performance.md#one-sample-per-frame-as-a-deadline), four deadlines of a 4 kHz
        sample. Frozen, what exists before the first step is left out of every collection; off,
        none runs while stepping. Stepping makes no cyclic garbage (tests/test_run_gc.py), so
        nothing accumulates meanwhile; reference counting frees everything else as before. In a
        process that keeps its own objects frozen (``host_keeps_frozen``) the collector is only
        turned off."""
        if not self.collector_off:
            yield
            return
        was_enabled = gc.isenabled()
        freeze = not self.host_keeps_frozen and gc.get_freeze_count() == 0
        if freeze:
            gc.freeze()
        gc.disable()
        try:
            yield
        finally:
            if was_enabled:
                gc.enable()
            if freeze:                  # what a caller froze stays frozen
                gc.unfreeze()
