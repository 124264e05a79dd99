"""Direct search for the light(s) minimising eq. 5.9 (thesis §5.8.1).

A coarse grid of 288 hypotheses (:func:`studio.light.params.coarse_grid`), then a 7×7×7 grid
(7×7 for a directional light) centred on the best so far with a third of the previous spacing,
repeated down to a spacing of 5 mm (the thesis' last discretisation; for a directional light,
the angle a 5 mm step subtends at 5 m). Each stage scores what its spacing can tell apart: the
grid and the rounds down to 20 cm a subset of the frames (every other one) at a coarser image
level, the rounds down to 2 cm the same frames at the working level, and one last round at 5 mm
every frame (a round whose best lies on the grid's edge is repeated there once; points scored
already are not scored again). Two lights: the first is the best single light for the union of
both shadows; the second is searched on the coarse grid with the first held, then each is
refined in turn with the other held.
"""

from __future__ import annotations

import itertools
import logging
from dataclasses import dataclass, field

import numpy as np

from studio.light.params import Frame, above_bodies, coarse_grid, coarse_steps, param_bounds, to_light

__all__ = ["SearchResult", "polish_lights", "refine_grid", "search_lights", "step_size_m"]

log = logging.getLogger(__name__)

#: Stop the refinement when a step moves the light by less than this (m).
STOP_M = 0.005
#: The directional light's equivalent: a 5 mm step seen from 5 m.
STOP_RAD = STOP_M / 5.0
#: The rounds leave the coarse grid's scoring (coarser images) once a step moves the light less than this (m).
GRID_UNTIL_M = 0.2
#: ... and the subset of the frames once it moves it less than this many times the last spacing.
LOOSE_FACTOR = 4.0


@dataclass(frozen=True)
class SearchResult:
    """``thetas`` one parameter vector per light, ``cost`` E at the answer, ``coarse_cost`` the
    coarse grid's best, ``rounds`` the refinement's (step, cost) history."""

    kind: str
    thetas: list
    cost: float
    coarse_cost: float
    n_evaluations: int
    rounds: list = field(default_factory=list)


def step_size_m(kind: str, theta: np.ndarray, step: np.ndarray, frame: Frame) -> float:
    """Largest move of the light (m; radians for a directional light) for one ``step`` of any
    parameter at ``theta``."""
    if kind == "directional":
        return float(max(step[0] * np.cos(theta[1]), step[1]))
    base = to_light(kind, theta, frame).position
    moves = []
    for i in range(len(theta)):
        t = np.array(theta, dtype=float)
        t[i] += step[i]
        moves.append(np.linalg.norm(to_light(kind, t, frame).position - base))
    return float(max(moves))


def refine_grid(cost, x0: np.ndarray, c0: float, step: np.ndarray, lo: np.ndarray, hi: np.ndarray, *,
                n: int = 7, shrink: float = 3.0, done=None, max_rounds: int = 10) -> tuple[np.ndarray, float, list, int]:
    """Repeated n^D grids centred on the best point so far (the first with spacing ``step`` /
    ``shrink``). When the best lies inside the grid the spacing is divided by ``shrink``; when on
    its edge the grid moves there once with the same spacing (the points the moved grid shares
    with the last one are not scored again); stops once ``done(x, step)``, or after
    ``max_rounds``. ``cost`` maps (N, D) → (N,). Returns (x, cost, rounds, evaluations)."""
    x, c = np.asarray(x0, dtype=float).copy(), float(c0)
    step = np.asarray(step, dtype=float) / shrink
    half = n // 2
    offsets = np.array(list(itertools.product(range(-half, half + 1), repeat=len(x))), dtype=float)
    rounds, evals, moved = [], 0, False
    seen: dict = {}  # the last grid's costs by point, while the spacing stays the same
    for _ in range(max_rounds):
        X = np.clip(x + offsets * step, lo, hi)
        keys = [tuple(k) for k in np.round(X / step, 6)]
        new = {k: i for i, k in enumerate(keys) if k not in seen}  # also drops points clipped onto each other
        if new:
            idx = list(new.values())
            seen.update(zip(new, cost(X[idx]), strict=True))
            evals += len(idx)
        C = np.array([seen[k] for k in keys])
        k = int(np.argmin(C))
        edge = bool(np.any(np.abs(offsets[k]) == half)) and C[k] < c
        if C[k] < c:
            x, c = X[k].copy(), float(C[k])
        rounds.append({"step": step.tolist(), "cost": c, "edge": edge, "evaluations": len(new)})
        if edge and not moved:  # one move per spacing: the grid follows the best once
            moved = True
            continue
        moved = False
        if done is not None and done(x, step):
            break
        step = step / shrink
        seen = {}
    return x, c, rounds, evals


def _cost(evaluate, kind: str, frame: Frame, body_top: float, held: list):
    """(N, D) parameters of one light → (N,) costs with the ``held`` lights' parameters (inf
    where a point light is not above the bodies)."""
    def cost(X):
        ok = np.array([above_bodies(kind, x, body_top) for x in X], bool)
        out = np.full(len(X), np.inf)
        if ok.any():
            out[ok] = evaluate([[to_light(kind, x, frame), *[to_light(kind, h, frame) for h in held]] for x in X[ok]])
        return out
    return cost


def polish_lights(evaluate, kind: str, frame: Frame, body_top: float, thetas: list, *,
                  stop_m: float = STOP_M) -> tuple[list, float, int]:
    """:func:`search_lights`' last stage again from ``thetas`` (e.g. once the floor changed): per
    light, the others held, a 7×7×7 round at 3 × ``stop_m`` then one at ``stop_m``. Returns
    (thetas, cost, evaluations)."""
    lo, hi = param_bounds(kind, body_top)
    stop = stop_m if kind == "point" else stop_m * STOP_RAD / STOP_M
    step0 = coarse_steps(kind, body_top)
    thetas = [np.asarray(t, float).copy() for t in thetas]
    c, evals = np.inf, 0
    for i in range(len(thetas)):
        cost = _cost(evaluate, kind, frame, body_top, [t for j, t in enumerate(thetas) if j != i])
        c = float(cost(thetas[i][None])[0])
        step = step0 * 3.0 * stop / step_size_m(kind, thetas[i], step0, frame)  # first round: 3 × stop
        thetas[i], c, _, e = refine_grid(cost, thetas[i], c, step * 3.0, lo, hi,
                                         done=lambda x, s: step_size_m(kind, x, s, frame) < stop * (1 + 1e-9))
        evals += e + 1
    return thetas, c, evals


def search_lights(evaluate, kind: str, frame: Frame, body_top: float, n_lights: int = 1, *,
                  coarse=None, grid=None, stop_m: float = STOP_M, hopeless=None) -> SearchResult:
    """The light(s) of ``kind`` minimising eq. 5.9; ``evaluate`` maps a list of hypotheses
    (each a list of lights) to their costs (N,) (:class:`studio.light.ShadowObjective`'s
    ``many``, or a pool of them).

    Coarse to fine, each stage scoring what its spacing can tell apart: ``grid`` (default
    ``coarse``; e.g. every other frame at a coarser image level) scores the coarse grid and the
    7×7×7 rounds down to ``GRID_UNTIL_M``; ``coarse`` (default ``evaluate``; e.g. every other
    frame) the rounds down to ``LOOSE_FACTOR`` × ``stop_m``; ``evaluate`` the last round, whose
    spacing is ``stop_m`` (m; 5 mm in the thesis) — one round unless its best lies on the grid's
    edge. ``hopeless(coarse_cost)`` true stops after the coarse grid (nothing there explains the
    shadows: refining would only polish a wrong answer)."""
    coarse = evaluate if coarse is None else coarse
    grid_eval = coarse if grid is None else grid
    lo, hi = param_bounds(kind, body_top)
    hyps = coarse_grid(kind, body_top)
    step0 = coarse_steps(kind, body_top)
    stop = stop_m if kind == "point" else stop_m * STOP_RAD / STOP_M
    unit = 1.0 if kind == "point" else STOP_RAD / STOP_M  # metres → this kind's step measure

    def below(limit):
        return lambda x, step: step_size_m(kind, x, step, frame) < limit

    if n_lights not in (1, 2):
        raise ValueError(f"n_lights: expected 1 or 2, got {n_lights}")
    C = _cost(grid_eval, kind, frame, body_top, [])(hyps)
    evals = len(hyps)
    k = int(np.argmin(C))
    thetas = [hyps[k].copy()]
    coarse_best = float(C[k])
    if n_lights == 2:
        C2 = _cost(grid_eval, kind, frame, body_top, thetas)(hyps)
        evals += len(hyps)
        # the second light must be somewhere else: skip the hypothesis of the first one
        k2 = int(np.argmin(np.where(np.all(np.isclose(hyps, thetas[0]), axis=1), np.inf, C2)))
        thetas.append(hyps[k2].copy())
        coarse_best = float(C2[k2])
    if hopeless is not None and hopeless(coarse_best):
        return SearchResult(kind, [np.asarray(t) for t in thetas], float("inf"), coarse_best, evals, [])
    stages = [(grid_eval, below(GRID_UNTIL_M * unit), "grid"), (coarse, below(stop * LOOSE_FACTOR), "coarse"),
              (evaluate, below(stop * (1 + 1e-9)), "all")]
    rounds_all = []
    c = np.inf
    for sweep in range(1 if n_lights == 1 else 2):
        for i in range(n_lights):
            held = [t for j, t in enumerate(thetas) if j != i]
            x, step, rounds = thetas[i], step0 / 9.0 ** sweep, []
            for s, (ev, done, name) in enumerate(stages):
                cost = _cost(ev, kind, frame, body_top, held)
                c = float(cost(x[None])[0])  # the stages' costs differ (frames, image level)
                evals += 1
                if s == len(stages) - 1:  # the last round at the thesis' spacing (stop_m), not below
                    step = step * min(1.0, stop / max(step_size_m(kind, x, step / 3.0, frame), 1e-12))
                x, c, more, e = refine_grid(cost, x, c, step, lo, hi, done=done)
                evals += e
                rounds += [dict(r, frames=name) for r in more]
                step = np.asarray(more[-1]["step"])
            thetas[i] = x
            rounds_all.append({"light": i, "rounds": rounds})
    for t in thetas:
        t[0] = float(np.mod(t[0], 2 * np.pi))
    log.info("light search (%s, %d): cost %.3f (coarse %.3f) in %d evaluations", kind, n_lights, c, coarse_best,
             evals)
    return SearchResult(kind, [np.asarray(t) for t in thetas], float(c), coarse_best, evals, rounds_all)
