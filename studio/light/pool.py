"""Scoring many light hypotheses on several processes (the search's grids, the sampler's walkers).

Each worker builds the :class:`~studio.light.objective.ShadowObjective` once from the frames
(sent once, in the pool's initializer) and scores a share of every batch. Workers are spawned by
:func:`studio.workers.worker_pool` and die with the command.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

import numpy as np

from studio.light.objective import ShadowObjective

__all__ = ["evaluators"]

_OBJECTIVES: dict = {}


def _init(sets: dict, cameras, ground) -> None:
    from studio.blas import limit_blas_threads

    limit_blas_threads()
    for name, frames in sets.items():
        _OBJECTIVES[name] = ShadowObjective(frames, cameras, ground)


def _score(name: str, hypotheses) -> np.ndarray:
    return _OBJECTIVES[name].many(hypotheses)


class _Batched:
    """``many(hypotheses)`` split over the pool's workers."""

    def __init__(self, pool, name: str, workers: int):
        self.pool, self.name, self.workers = pool, name, workers
        self.n_evaluations = 0

    def __call__(self, hypotheses) -> np.ndarray:
        hypotheses = list(hypotheses)
        self.n_evaluations += len(hypotheses)
        if len(hypotheses) < 2 * self.workers:
            return self.pool.submit(_score, self.name, hypotheses).result()
        chunks = [c for c in np.array_split(np.arange(len(hypotheses)), self.workers) if len(c)]
        futures = [self.pool.submit(_score, self.name, [hypotheses[i] for i in c]) for c in chunks]
        return np.concatenate([f.result() for f in futures])


@contextlib.contextmanager
def evaluators(sets: dict, cameras, ground=None, workers: int = 1) -> Iterator[dict]:
    """{name: evaluate(hypotheses) -> (N,) costs} for each list of :class:`ShadowFrame` in
    ``sets``, in this process (``workers`` 1) or split over ``workers`` processes."""
    if workers <= 1:
        objectives = {name: ShadowObjective(frames, cameras, ground) for name, frames in sets.items()}
        yield {name: obj.many for name, obj in objectives.items()}
        return
    from studio.workers import worker_pool

    with worker_pool(workers, _init, (sets, list(cameras), ground)) as pool:
        yield {name: _Batched(pool, name, workers) for name in sets}
