"""OpenBLAS threads: one per process for the toolkit's small matrix products.

The fit's products are small; OpenBLAS's own threads (one per core by default) only spin
on them. Measured on 2 cores: a tracked walk frame took 19.9 s wall / 37.1 s CPU with the
default threads and 18.9 s / 20.9 s with one, so the fit always runs with one
(:func:`one_blas_thread`). Segmentation gains a little from the threads in one process
(31.7 vs 29.9 multi-frames/s) but not when a worker process runs on every core
(``studio segment`` of 24 walk frames with 2 workers: 7.0 s → 5.2 s with one thread per
worker), so only its workers limit them (:func:`limit_blas_threads`).
"""

from __future__ import annotations

import functools

__all__ = ["one_blas_thread", "limit_blas_threads"]


def limit_blas_threads() -> None:
    """Put BLAS on one thread for the rest of this process (for worker initialisers)."""
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=1, user_api="blas")


def one_blas_thread(fn):
    """Decorator: run ``fn`` with BLAS on one thread, restoring the previous setting after."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        from threadpoolctl import threadpool_limits

        with threadpool_limits(limits=1, user_api="blas"):
            return fn(*args, **kwargs)

    return wrapper
