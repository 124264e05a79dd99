"""Direct search for the light(s) minimising eq. 5.9 (thesis §5.8.1).

A coarse grid of 288 hypotheses (:func:`studio.light.params.coarse_grid`), then a 7×7×7 grid
(7×7 for a directional light) centred on the best so far with a third of the previous spacing,
repeated until one step moves the light by less than 5 mm (the thesis' last discretisation; for a
directional light, the angle a 5 mm step subtends at 5 m). The grid and the refinement down to
2 cm score a subset of the frames (``coarse``: every other frame), the last rounds every frame. Two lights: the
first is the best single light for the union of both shadows; the second is searched on the
coarse grid with the first held, then each is refined in turn with the other held.
"""

from __future__ import annotations

import itertools
import logging
from dataclasses import dataclass, field

import numpy as np

from studio.light.params import Frame, above_bodies, coarse_grid, coarse_steps, param_bounds, to_light

__all__ = ["SearchResult", "refine_grid", "search_lights", "step_size_m"]

log = logging.getLogger(__name__)

#: Stop the refinement when a step moves the light by less than this (m).
STOP_M = 0.005
#: The directional light's equivalent: a 5 mm step seen from 5 m.
STOP_RAD = STOP_M / 5.0


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
    its edge the grid moves there once with the same spacing; stops once ``done(x, step)``, or
    after ``max_rounds``. ``cost`` maps (N, D) → (N,). Returns (x, cost,
    rounds, evaluations)."""
    x, c = np.asarray(x0, dtype=float).copy(), float(c0)
    step = np.asarray(step, dtype=float) / shrink
    half = n // 2
    offsets = np.array(list(itertools.product(range(-half, half + 1), repeat=len(x))), dtype=float)
    rounds, evals, moved = [], 0, False
    for _ in range(max_rounds):
        X = np.clip(x + offsets * step, lo, hi)
        C = cost(X)
        evals += len(X)
        k = int(np.argmin(C))
        edge = bool(np.any(np.abs(offsets[k]) == half)) and C[k] < c
        if C[k] < c:
            x, c = X[k].copy(), float(C[k])
        rounds.append({"step": step.tolist(), "cost": c, "edge": edge})
        if edge and not moved:  # one move per spacing: the grid follows the best once
            moved = True
            continue
        moved = False
        if done is not None and done(x, step):
            break
        step = step / shrink
    return x, c, rounds, evals


def search_lights(evaluate, kind: str, frame: Frame, body_top: float, n_lights: int = 1, *,
                  coarse=None, stop_m: float = STOP_M, hopeless=None) -> SearchResult:
    """The light(s) of ``kind`` minimising eq. 5.9; ``evaluate`` maps a list of hypotheses
    (each a list of lights) to their costs (N,) (:class:`studio.light.ShadowObjective`'s
    ``many``, or a pool of them); ``coarse`` (default ``evaluate``) scores the coarse grid
    (e.g. on every other frame: the grid only has to find the basin); ``stop_m`` the last
    spacing (m; 5 mm in the thesis). ``hopeless(coarse_cost)`` true stops after the coarse grid
    (nothing there explains the shadows: refining would only polish a wrong answer)."""
    coarse = evaluate if coarse is None else coarse
    lo, hi = param_bounds(kind, body_top)
    grid = coarse_grid(kind, body_top)
    step0 = coarse_steps(kind, body_top)
    stop = stop_m if kind == "point" else stop_m * STOP_RAD / STOP_M

    def cost_with(held, evaluate=evaluate):
        def cost(X):
            ok = np.array([above_bodies(kind, x, body_top) for x in X], bool)
            out = np.full(len(X), np.inf)
            if ok.any():
                out[ok] = evaluate([[to_light(kind, x, frame), *[to_light(kind, h, frame) for h in held]]
                                    for x in X[ok]])
            return out
        return cost

    def done(x, step):
        return step_size_m(kind, x, step, frame) < stop

    if n_lights not in (1, 2):
        raise ValueError(f"n_lights: expected 1 or 2, got {n_lights}")
    C = cost_with([], coarse)(grid)
    evals = len(grid)
    k = int(np.argmin(C))
    thetas = [grid[k].copy()]
    coarse_best = float(C[k])
    if n_lights == 2:
        C2 = cost_with(thetas, coarse)(grid)
        evals += len(grid)
        # the second light must be somewhere else: skip the hypothesis of the first one
        k2 = int(np.argmin(np.where(np.all(np.isclose(grid, thetas[0]), axis=1), np.inf, C2)))
        thetas.append(grid[k2].copy())
        coarse_best = float(C2[k2])
    if hopeless is not None and hopeless(coarse_best):
        return SearchResult(kind, [np.asarray(t) for t in thetas], float("inf"), coarse_best, evals, [])
    c = float(cost_with(thetas[1:], coarse)(thetas[0][None])[0])
    evals += 1
    rounds_all = []

    def loose(x, step):
        return step_size_m(kind, x, step, frame) < stop * 4

    for sweep in range(1 if n_lights == 1 else 2):
        for i in range(n_lights):
            held = [t for j, t in enumerate(thetas) if j != i]
            # down to 2 cm on the coarse frames, then to 5 mm on every frame
            x, c, rounds, e = refine_grid(cost_with(held, coarse), thetas[i], c, step0 / 9.0 ** sweep, lo, hi,
                                          done=loose)
            evals += e
            last = np.asarray(rounds[-1]["step"])
            c = float(cost_with(held)(x[None])[0])
            thetas[i], c, more, e = refine_grid(cost_with(held), x, c, last, lo, hi, done=done, shrink=3.0)
            evals += e + 1
            rounds_all.append({"light": i, "rounds": rounds + [dict(r, frames="all") for r in more]})
    for t in thetas:
        t[0] = float(np.mod(t[0], 2 * np.pi))
    log.info("light search (%s, %d): cost %.3f (coarse %.3f) in %d evaluations", kind, n_lights, c, coarse_best,
             evals)
    return SearchResult(kind, [np.asarray(t) for t in thetas], float(c), coarse_best, evals, rounds_all)
