"""Where many localizer passes run: in series, on a local process pool, or on a cluster.

An :class:`Engine` maps a picklable, module-level function over a list of picklable items and
returns the results in the items' order. The evaluation of many logs (:mod:`tagloc.eval.fleet`)
and the held-out-tag passes of one log (:mod:`tagloc.eval.onsite`) are lists of independent
passes, so each takes an engine and is the same code in series or in parallel:

- :class:`SerialEngine`: in this process, one after the other (the reference);
- :class:`ProcessEngine`: a local pool of ``jobs`` processes (``spawn``: each worker imports
  tagloc afresh, so no thread or open file of the parent is copied into it);
- ``tagloc.adapters.ray.RayEngine``: the same on an existing Ray cluster (the ``fleet`` extra).

A failure in any item is raised by :meth:`Engine.map` once the running items have finished
(nothing is written by an engine: the caller writes its outputs after the map returns).
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing
import os
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from typing import Protocol, TypeVar

__all__ = ["Engine", "ProcessEngine", "Progress", "SerialEngine"]

logger = logging.getLogger(__name__)
T = TypeVar("T")
R = TypeVar("R")
#: ``progress(done, total)`` after each finished item.
Progress = Callable[[int, int], None]


class Engine(Protocol):
    """Runs ``fn`` over ``items``; results in the items' order (module docstring)."""

    #: How many items may run at once.
    jobs: int

    def map(
        self, fn: Callable[[T], R], items: Sequence[T], progress: Progress | None = None
    ) -> list[R]:
        """``[fn(item) for item in items]``, possibly in parallel."""
        ...

    def close(self) -> None:
        """Release what the engine holds (a cluster connection)."""
        ...


class SerialEngine:
    """In this process, in order."""

    jobs = 1

    def map(
        self, fn: Callable[[T], R], items: Sequence[T], progress: Progress | None = None
    ) -> list[R]:
        out = []
        for item in items:
            out.append(fn(item))
            if progress is not None:
                progress(len(out), len(items))
        return out

    def close(self) -> None:
        pass


class ProcessEngine:
    """A local pool of ``jobs`` worker processes (``jobs == 1`` runs in this process).

    Parameters
    ----------
    jobs : int
        At least 1.
    """

    def __init__(self, jobs: int) -> None:
        if jobs < 1:
            raise ValueError(f"jobs must be >= 1, got {jobs}")
        self.jobs = jobs

    def map(
        self, fn: Callable[[T], R], items: Sequence[T], progress: Progress | None = None
    ) -> list[R]:
        if self.jobs == 1 or len(items) <= 1:
            return SerialEngine().map(fn, items, progress)
        context = multiprocessing.get_context("spawn")
        workers = min(self.jobs, len(items))
        with _one_thread_per_worker(), ProcessPoolExecutor(
            max_workers=workers, mp_context=context
        ) as pool:
            futures = [pool.submit(fn, item) for item in items]
            pending = set(futures)
            while pending:
                done, pending = wait(pending, return_when=FIRST_COMPLETED)
                if progress is not None:
                    progress(len(futures) - len(pending), len(futures))
                failed = [f for f in done if f.exception() is not None]
                if failed:
                    for f in pending:
                        f.cancel()
                    wait(pending)
                    raise failed[0].exception()  # type: ignore[misc]
            logger.debug("%d items on %d processes", len(items), workers)
            return [f.result() for f in futures]

    def close(self) -> None:
        pass


#: Thread counts of the numerical libraries, pinned to 1 in the pool's workers.
_THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


@contextlib.contextmanager
def _one_thread_per_worker() -> Iterator[None]:
    """Workers started inside inherit one BLAS/OpenMP thread each: ``jobs`` processes on
    ``jobs`` cores, not each of them spreading over all cores (8 simulated drives on 2 cores:
    1.43x with --jobs 2 oversubscribed, 1.84x pinned). The parent's own settings come back."""
    saved = {k: os.environ.get(k) for k in _THREAD_VARS}
    os.environ.update({k: "1" for k in _THREAD_VARS})
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
