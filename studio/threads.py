"""Threads inside one process: a fit's batch of bodies evaluated side by side.

The fitter's kernels (the SCAPE solve, the contour renderer, the silhouette cost, the library's
scores) are compiled with ``nogil=True``, so a batch of bodies cut into chunks runs on several
threads of one process. Each chunk's arithmetic is its own, so the results are the same to the
last bit whether the chunks run one after the other or side by side, and the cut does not depend
on the thread count where it could change a result
(:meth:`studio.fit.objective.FrameObjective.chunks`; tested). Measured on 2 cores: a particle
filter's batch of 80 SCAPE bodies 120 → 65 ms wall; walk frame 12 fitted from its silhouettes
12.9 → 10.4 s wall (``benchmarks/fit_speed.py``).

How many: :func:`set_threads`; else one in a worker process (a ``multiprocessing`` child: the
workers already share out the cores; :func:`studio.execution.worker_setup` sets one too), every
core this process may run on otherwise.
"""

from __future__ import annotations

import multiprocessing
import os
import threading
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor

__all__ = ["chunk_ranges", "map_chunks", "set_threads", "threads"]

_count: int | None = None
_pool: tuple[int, ThreadPoolExecutor] | None = None  # (threads, pool)
_inside = threading.local()  # set in the pool's threads: a chunk that maps again runs in its thread


def threads() -> int:
    """Threads a batch may use in this process (see the module docstring)."""
    if _count is not None:
        return _count
    if multiprocessing.parent_process() is not None:
        return 1
    affinity = getattr(os, "sched_getaffinity", None)  # Linux: the cores this process may use
    return max(1, len(affinity(0)) if affinity else os.cpu_count() or 1)


def set_threads(n: int | None) -> None:
    """Use ``n`` threads per batch from now on (None: the default of :func:`threads`)."""
    global _count
    if n is not None and (isinstance(n, bool) or not isinstance(n, int) or n < 1):
        raise ValueError(f"threads: expected an integer >= 1 or None, got {n!r}")
    _count = n


def _mark() -> None:
    _inside.active = True


def _executor(n: int) -> ThreadPoolExecutor:
    global _pool
    if _pool is None or _pool[0] != n:
        if _pool is not None:
            _pool[1].shutdown(wait=False)
        _pool = (n, ThreadPoolExecutor(n, thread_name_prefix="studio-batch", initializer=_mark))
    return _pool[1]


def _forget_pool() -> None:  # a forked child has none of the parent's threads
    global _pool
    _pool = None


os.register_at_fork(after_in_child=_forget_pool)


def chunk_ranges(n: int, size: int, *, balance: bool = True) -> list[tuple[int, int]]:
    """``range(n)`` cut into ``(start, stop)`` ranges of at most ``size`` items: with ``balance``
    near-equal ones, as many as fill every thread evenly while each keeps two items or more (a
    particle filter's 80 bodies in chunks of 16 leave one of two threads idle a third of the
    time; in 6 chunks of 13–14 none); without, ``size`` items each but the last. ``n`` = 0: none."""
    if not balance:
        return [(i, min(i + size, n)) for i in range(0, n, size)]
    t = 1 if getattr(_inside, "active", False) else threads()  # a chunk cut again runs in its thread
    k = -(-n // size)
    balanced = -(-k // t) * t
    if balanced <= n // 2:
        k = balanced
    return [(i * n // k, (i + 1) * n // k) for i in range(k)]  # integers: on every evaluation's path


def map_chunks(fn: Callable, chunks: Sequence) -> list:
    """``[fn(c) for c in chunks]``, the chunks on up to :func:`threads` threads, in order."""
    n = threads()
    if n <= 1 or len(chunks) <= 1 or getattr(_inside, "active", False):
        return [fn(c) for c in chunks]
    return list(_executor(n).map(fn, chunks))
