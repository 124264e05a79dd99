"""BLAS thread limits used by the fit and the segmentation (studio.blas)."""

import numpy as np
from threadpoolctl import threadpool_info

from studio.blas import one_blas_thread


def _blas_threads() -> list[int]:
    np.ones(2) @ np.ones(2)  # make sure NumPy's BLAS is loaded
    return [lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"]


def test_one_blas_thread_limits_and_restores():
    before = _blas_threads()
    assert before, "NumPy's BLAS not found by threadpoolctl"

    @one_blas_thread
    def inside(x, *, scale):
        """doc kept"""
        return _blas_threads(), x * scale

    threads, value = inside(2, scale=3)
    assert threads == [1] * len(before) and value == 6
    assert inside.__doc__ == "doc kept" and inside.__name__ == "inside"
    assert _blas_threads() == before
