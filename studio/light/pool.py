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


def _score(name: str, ground, hypotheses) -> np.ndarray:
    return _OBJECTIVES[name].many(hypotheses, ground)


def _score_planes(name: str, lights, grounds) -> np.ndarray:
    return _OBJECTIVES[name].planes(lights, grounds)


class _Local:
    """One :class:`ShadowObjective` in this process: ``(hypotheses, ground=None)`` → costs, and
    ``planes(lights, grounds)``."""

    def __init__(self, objective: ShadowObjective):
        self.objective = objective
        self.planes = objective.planes

    def __call__(self, hypotheses, ground=None) -> np.ndarray:
        return self.objective.many(hypotheses, ground)


class _Batched:
    """:class:`_Local`'s calls split over the pool's workers."""

    def __init__(self, pool, name: str, workers: int):
        self.pool, self.name, self.workers = pool, name, workers
        self.n_evaluations = 0

    def _split(self, fn, items: list, *args) -> np.ndarray:
        self.n_evaluations += len(items)
        if len(items) < 2 * self.workers:
            return self.pool.submit(fn, self.name, *args, items).result()
        chunks = [c for c in np.array_split(np.arange(len(items)), self.workers) if len(c)]
        futures = [self.pool.submit(fn, self.name, *args, [items[i] for i in c]) for c in chunks]
        return np.concatenate([f.result() for f in futures])

    def __call__(self, hypotheses, ground=None) -> np.ndarray:
        return self._split(_score, list(hypotheses), ground)

    def planes(self, lights, grounds) -> np.ndarray:
        return self._split(_score_planes, list(grounds), lights)


@contextlib.contextmanager
def evaluators(sets: dict, cameras, ground=None, workers: int = 1) -> Iterator[dict]:
    """{name: evaluate} for each list of :class:`ShadowFrame` in ``sets``: ``evaluate(hypotheses,
    ground=None)`` → (N,) costs, ``evaluate.planes(lights, grounds)`` → (N,) costs; in this
    process (``workers`` 1) or split over ``workers`` processes."""
    if workers <= 1:
        yield {name: _Local(ShadowObjective(frames, cameras, ground)) for name, frames in sets.items()}
        return
    from studio.workers import worker_pool

    with worker_pool(workers, _init, (sets, list(cameras), ground)) as pool:
        yield {name: _Batched(pool, name, workers) for name in sets}
