"""OpenBLAS threads: one per process for the toolkit's small matrix products.

The fit's and the segmentation's products are small; OpenBLAS's own threads (one per core
by default) only spin on them. Measured on 2 cores: a tracked walk frame took 19.9 s wall /
37.1 s CPU with the default threads and 18.9 s / 20.9 s with one; ``studio segment`` of 24
walk frames with 2 workers 7.0 s → 4.9 s. With one thread each, worker processes no longer
fight over the cores.
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
