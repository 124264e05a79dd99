"""Optimisers for fitting (thesis §4.7): annealed particle filter and staged Nelder–Mead.

Both take a generic cost ``f(x) -> float`` (the APF also a batched
``f(X (N, D)) -> (N,)``), per-parameter bounds and return frozen result
dataclasses with the best parameters, the best cost and a per-layer/per-stage
history. They know nothing about body models.
"""

from ._common import CostError
from .annealed import AnnealedResult, LayerStats, annealed_particle_filter, survival_rate
from .staged import Stage, StagedResult, StageResult, staged_nelder_mead, thesis_stages

__all__ = [
    "AnnealedResult",
    "CostError",
    "LayerStats",
    "Stage",
    "StageResult",
    "StagedResult",
    "annealed_particle_filter",
    "staged_nelder_mead",
    "survival_rate",
    "thesis_stages",
]
