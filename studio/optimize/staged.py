"""Staged Nelder–Mead refinement over groups of parameters (thesis §4.7.4).

The thesis refines pose and shape with the (gradient-free) Nelder–Mead simplex
method, partitioning the search space: first the torso's global position with
the first shape coefficients (e.g. 6), then part rotations from the torso
outward (upper arms and legs, then lower arms and legs), then all part rotations
with more shape coefficients (e.g. 12), and finally every parameter.
:func:`staged_nelder_mead` runs such a list of :class:`Stage` s; each stage
optimises its parameter indices with the others held fixed, starting from the
previous stage's result. :func:`thesis_stages` builds the thesis's schedule from
index groups, so this module knows nothing about any body model.

Bounds (joint limits) are hard: the start is clipped into ``[lo, hi]``, the
initial simplex is built inside the box, and SciPy's bounded Nelder–Mead
(``scipy.optimize.minimize(method="Nelder-Mead", bounds=...)``) clips every
trial point onto it, so the cost is never evaluated outside the limits.
The method is deterministic: no seed is involved.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize

from ._common import CostError, check_bounds, check_vector

__all__ = ["Stage", "StageResult", "StagedResult", "staged_nelder_mead", "thesis_stages"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Stage:
    """One stage: the parameter ``indices`` to optimise (others fixed) and a budget.

    Attributes
    ----------
    indices : tuple[int, ...]
        Indices into the full parameter vector.
    max_evaluations : int
        Cost evaluations allowed in this stage.
    name : str
        Label for logs and reports.
    """

    indices: tuple[int, ...]
    max_evaluations: int = 200
    name: str = ""

    def __post_init__(self):
        try:
            idx = tuple(int(i) for i in np.asarray(self.indices).ravel())
        except (TypeError, ValueError):
            raise ValueError(f"Stage {self.name!r}: indices must be integers, got {self.indices!r}") from None
        if not idx:
            raise ValueError(f"Stage {self.name!r}: no parameter indices to optimise")
        if len(set(idx)) != len(idx):
            raise ValueError(f"Stage {self.name!r}: repeated parameter indices {sorted(idx)}")
        if isinstance(self.max_evaluations, bool) or int(self.max_evaluations) < 1:
            raise ValueError(f"Stage {self.name!r}: max_evaluations must be >= 1, got {self.max_evaluations!r}")
        object.__setattr__(self, "indices", idx)
        object.__setattr__(self, "max_evaluations", int(self.max_evaluations))


@dataclass(frozen=True)
class StageResult:
    """Outcome of one stage: costs before/after, evaluations used, SciPy's message."""

    name: str
    indices: tuple[int, ...]
    cost_before: float
    cost_after: float
    n_evaluations: int
    converged: bool
    message: str


@dataclass(frozen=True, eq=False)
class StagedResult:
    """Outcome of :func:`staged_nelder_mead`.

    Attributes
    ----------
    x : (D,) float64
        Final parameters (within bounds).
    cost : float
        ``f(x)``.
    stages : tuple[StageResult, ...]
        Per-stage history.
    n_evaluations : int
        Total cost evaluations.
    stopped_early : bool
        The callback asked to stop before the last stage.
    """

    x: np.ndarray
    cost: float
    stages: tuple[StageResult, ...]
    n_evaluations: int
    stopped_early: bool


def thesis_stages(
    root: Sequence[int],
    part_groups: Sequence[Sequence[int]],
    shape: Sequence[int] = (),
    *,
    n_shape_first: int = 6,
    n_shape_second: int = 12,
    max_evaluations: int | Sequence[int] = 300,
) -> list[Stage]:
    """The thesis's §4.7.4 schedule from parameter index groups.

    Parameters
    ----------
    root : sequence of int
        Global position/orientation (torso) indices.
    part_groups : sequence of sequences of int
        Part-rotation indices, ordered from the torso outward (e.g. upper arms and
        upper legs, then lower arms and legs, then hands, feet, head).
    shape : sequence of int
        Shape-coefficient indices, by decreasing PCA eigenvalue.
    n_shape_first, n_shape_second : int
        Shape coefficients in the first stage and in the all-pose stage (thesis: 6, 12).
    max_evaluations : int or sequence of int
        Budget per stage (one value for all, or one per stage: ``len(part_groups) + 3``).

    Returns
    -------
    list[Stage]
        ``root + shape[:6]``, each part group, ``root + all parts + shape[:12]``, all.
    """
    root, shape = list(root), list(shape)
    groups = [list(g) for g in part_groups]
    pose = root + [i for g in groups for i in g]
    specs = [("torso+shape", root + shape[:n_shape_first])]
    specs += [(f"parts{k}", g) for k, g in enumerate(groups)]
    specs += [("pose+shape", pose + shape[:n_shape_second]), ("all", pose + shape)]
    budgets = [max_evaluations] * len(specs) if np.ndim(max_evaluations) == 0 else list(max_evaluations)
    if len(budgets) != len(specs):
        raise ValueError(f"max_evaluations: expected one value or {len(specs)} (one per stage), got {len(budgets)}")
    return [Stage(tuple(idx), int(b), name) for (name, idx), b in zip(specs, budgets, strict=True)]


def _default_step(x0: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """10 % of a finite range, else 5 % of |x0| (at least 0.1)."""
    finite = np.isfinite(lo) & np.isfinite(hi)
    return np.where(finite, 0.1 * (hi - lo), np.maximum(0.05 * np.abs(x0), 0.1))


def _initial_simplex(z0: np.ndarray, step: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """``(n + 1, n)`` simplex: ``z0`` and ``z0 ± step_i e_i``, every vertex inside the box."""
    n = z0.shape[0]
    simplex = np.repeat(z0[None, :], n + 1, axis=0)
    for i in range(n):
        up, down = z0[i] + step[i], z0[i] - step[i]
        if up <= hi[i]:
            simplex[i + 1, i] = up
        elif down >= lo[i]:
            simplex[i + 1, i] = down
        else:  # the box is narrower than the step: go to the farther bound
            simplex[i + 1, i] = hi[i] if hi[i] - z0[i] >= z0[i] - lo[i] else lo[i]
    return simplex


def staged_nelder_mead(
    f: Callable[[np.ndarray], float],
    x0,
    stages: Sequence[Stage],
    *,
    bounds=None,
    step=None,
    xatol: float = 1e-4,
    fatol: float = 1e-4,
    adaptive: bool = False,
    callback: Callable[[StageResult], bool | None] | None = None,
) -> StagedResult:
    """Minimise ``f`` with Nelder–Mead over successive parameter groups (thesis §4.7.4).

    Parameters
    ----------
    f : callable
        Cost ``(D,) -> float``; NaN raises :class:`CostError`, ``inf`` is allowed.
    x0 : (D,) float
        Start (clipped into ``bounds``).
    stages : sequence of Stage
        Parameter groups in order, each with its evaluation budget.
    bounds : (lo, hi), optional
        Per-parameter limits (``±inf`` allowed); never violated.
    step : float or (D,) float, optional
        Initial simplex edge per parameter (default: 10 % of a finite range, else
        ``max(0.05 |x0|, 0.1)``).
    xatol, fatol : float
        Per-stage convergence tolerances passed to SciPy.
    adaptive : bool
        Gao–Han dimension-adapted coefficients (helps above ~10 parameters).
    callback : callable, optional
        Called with each :class:`StageResult`; returning True stops.
    """
    x = check_vector(x0, "x0")
    d = x.shape[0]
    lo, hi = check_bounds(bounds, d)
    stages = list(stages)
    if not stages:
        raise ValueError("stages: at least one Stage is needed")
    for k, stage in enumerate(stages):
        if not isinstance(stage, Stage):
            raise ValueError(f"stages[{k}]: expected a Stage, got {type(stage).__name__}")
        bad = [i for i in stage.indices if not 0 <= i < d]
        if bad:
            raise ValueError(f"stages[{k}] ({stage.name!r}): indices {bad} out of range for {d} parameters")
    if step is None:
        step = _default_step(x, lo, hi)
    else:
        step = np.broadcast_to(np.asarray(step, dtype=np.float64), (d,)).copy() if np.ndim(step) == 0 \
            else check_vector(step, "step", d)
        if not np.isfinite(step).all() or (step <= 0).any():
            raise ValueError("step: initial simplex steps must be finite and positive")
    clipped = np.clip(x, lo, hi)
    if (clipped != x).any():
        log.warning("x0 outside bounds at indices %s: clipped", np.flatnonzero(clipped != x).tolist())
        x = clipped

    total_eval = 0

    def full_cost(z: np.ndarray) -> float:
        nonlocal total_eval
        total_eval += 1
        value = float(f(z))
        if np.isnan(value):
            raise CostError(f"cost function returned NaN at {z.tolist()}")
        return value

    cost = full_cost(x)
    history: list[StageResult] = []
    stopped = False
    for k, stage in enumerate(stages):
        idx = np.array([i for i in stage.indices if lo[i] < hi[i]], dtype=np.intp)  # fixed ones cannot move
        name = stage.name or f"stage{k}"
        if idx.size == 0:
            result = StageResult(name, stage.indices, cost, cost, 0, True, "all parameters fixed by bounds")
        else:
            before_eval = total_eval
            work = x.copy()
            best = {"cost": cost, "z": x[idx].copy()}

            def sub_cost(z: np.ndarray, work=work, idx=idx, best=best) -> float:
                work[idx] = z
                value = full_cost(work.copy())
                if value < best["cost"]:
                    best["cost"], best["z"] = value, np.array(z, dtype=np.float64)
                return value

            simplex = _initial_simplex(x[idx], step[idx], lo[idx], hi[idx])
            # SciPy stops exactly at maxfev (it may stop inside an iteration, before a better trial
            # point joins the simplex: hence the best-seen tracking above).
            res = minimize(
                sub_cost,
                x[idx],
                method="Nelder-Mead",
                bounds=list(zip(lo[idx], hi[idx], strict=True)),
                options={
                    "initial_simplex": simplex,
                    "maxfev": stage.max_evaluations,
                    "maxiter": stage.max_evaluations,
                    "xatol": xatol,
                    "fatol": fatol,
                    "adaptive": adaptive,
                },
            )
            converged, message = bool(res.success), str(res.message)
            before = cost
            if best["cost"] < cost:
                x = x.copy()
                x[idx] = np.clip(best["z"], lo[idx], hi[idx])
                cost = float(best["cost"])
            result = StageResult(name, stage.indices, before, cost, total_eval - before_eval, converged, message)
        history.append(result)
        log.info("NM stage %s: %d params, cost %.6g -> %.6g in %d evaluations", name, len(stage.indices),
                 result.cost_before, result.cost_after, result.n_evaluations)
        if callback is not None and callback(result):
            stopped = k < len(stages) - 1
            break
    x.flags.writeable = False
    return StagedResult(x=x, cost=cost, stages=tuple(history), n_evaluations=total_eval, stopped_early=stopped)
