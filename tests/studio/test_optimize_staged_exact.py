"""Staged Nelder–Mead (thesis §4.7.4) against SciPy run by hand, and at its documented limits.

One stage with the defaults is SciPy's bounded Nelder–Mead (xatol = fatol = 1e-4, fixed
coefficients) from the documented simplex, keeping the best point seen; the default step is
"10 % of a finite range, else 5 % of |x0| (at least 0.1)"; the simplex stays inside the box
(``z0 + step`` when ``<= hi``, else ``z0 − step`` when ``>= lo``, else the farther bound).
"""

from __future__ import annotations

import logging

import numpy as np
import pytest
from scipy.optimize import minimize

from studio.optimize import Stage, StageResult, staged_nelder_mead, thesis_stages
from studio.optimize.staged import _default_step, _initial_simplex


def rosenbrock(x):
    x = np.asarray(x)
    return float(np.sum(100.0 * (x[1:] - x[:-1] ** 2) ** 2 + (1 - x[:-1]) ** 2))


def test_default_step():
    lo = np.array([0.0, -np.inf, 0.0, -np.inf])
    hi = np.array([2.0, np.inf, np.inf, 5.0])
    x0 = np.array([1.0, 4.0, -10.0, 0.5])
    np.testing.assert_allclose(_default_step(x0, lo, hi), [0.2, 0.2, 0.5, 0.1], rtol=1e-15)


def test_initial_simplex_inside_the_box():
    z0 = np.array([0.0, 0.0, 0.2, 0.8, 0.5, 1.2])
    step = np.array([1.0, 1.0, 5.0, 5.0, 5.0, 5.0])
    lo = np.array([-5.0, -1.0, 0.0, 0.0, 0.0, 1.0])
    hi = np.array([1.0, 0.5, 1.0, 1.0, 1.0, 2.0])
    s = _initial_simplex(z0, step, lo, hi)
    want = np.repeat(z0[None], 7, axis=0)
    # up = hi exactly; up past hi, down = lo exactly; narrower than the step: farther bound (ties: hi)
    for i, value in enumerate([1.0, -1.0, 1.0, 0.0, 1.0, 2.0]):
        want[i + 1, i] = value
    np.testing.assert_array_equal(s, want)


def steep_bowl(x):
    """Converges in x long before in f: the default fatol decides when it stops."""
    return float(1e6 * np.sum((np.asarray(x) - 0.3) ** 2))


@pytest.mark.parametrize("cost, budget", [(rosenbrock, 150), (steep_bowl, 3000)])
def test_one_stage_is_scipys_bounded_nelder_mead(cost, budget):
    x0 = np.array([-1.2, 1.0, 0.5])
    lo, hi = np.array([-2.0, -2.0, -2.0]), np.array([2.0, 2.0, 2.0])
    res = staged_nelder_mead(cost, x0, [Stage((0, 1, 2), budget)], bounds=(lo, hi))

    seen = []

    def f(z):
        seen.append((cost(z), np.array(z)))
        return seen[-1][0]

    step = 0.1 * (hi - lo)
    simplex = np.repeat(x0[None], 4, axis=0) + np.vstack([np.zeros(3), np.diag(step)])
    minimize(f, x0, method="Nelder-Mead", bounds=list(zip(lo, hi)),
             options={"initial_simplex": simplex, "maxfev": budget, "maxiter": budget, "xatol": 1e-4, "fatol": 1e-4,
                      "adaptive": False})
    costs = [c for c, _ in seen]
    best = int(np.argmin(costs))  # the first point of the lowest cost
    np.testing.assert_array_equal(res.x, seen[best][1])
    assert res.cost == costs[best]
    assert res.n_evaluations == 1 + len(seen)
    stage = res.stages[0]
    assert stage.indices == (0, 1, 2) and stage.n_evaluations == len(seen)
    assert not res.x.flags.writeable


def test_the_first_best_point_is_kept_on_ties():
    """A flat valley (cost 0 for |z| <= 1): the first point reaching it is the result."""
    seen = []

    def f(z):
        seen.append(np.array(z))
        return float(np.sum(np.maximum(np.abs(z) - 1.0, 0.0)))

    res = staged_nelder_mead(f, [3.0, -2.5], [Stage((0, 1), 80)], step=0.7)
    first = next(z for z in seen if f(z) == 0.0)
    np.testing.assert_array_equal(res.x, first)


def test_converged_stage_and_fixed_stage_results():
    res = staged_nelder_mead(lambda x: float(np.sum((x - 0.3) ** 2)), [0.0, 0.0, 5.0],
                             [Stage((0, 1), 400, "free"), Stage((2,), 10, "fixed")],
                             bounds=([-1.0, -1.0, 5.0], [1.0, 1.0, 5.0]))
    free, fixed = res.stages
    assert free.converged is True and free.indices == (0, 1)
    c = res.cost
    assert fixed == StageResult("fixed", (2,), c, c, 0, True, "all parameters fixed by bounds")
    assert res.stopped_early is False


def test_stopping_after_the_last_stage_is_not_early():
    stages = [Stage((0,), 20), Stage((1,), 20)]
    f = lambda x: float(np.sum(x**2))  # noqa: E731
    assert staged_nelder_mead(f, [1.0, 1.0], stages, callback=lambda r: True).stopped_early is True
    last = staged_nelder_mead(f, [1.0, 1.0], stages, callback=lambda r: r.name == "stage1")
    assert last.stopped_early is False and len(last.stages) == 2


def test_start_outside_the_bounds_is_clipped_with_a_warning(caplog):
    seen = []

    def f(x):
        seen.append(x.copy())
        return float(np.sum(x**2))

    with caplog.at_level(logging.WARNING, logger="studio.optimize.staged"):
        staged_nelder_mead(f, [-3.0, 0.5, 4.0], [Stage((1,), 5)], bounds=([-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]))
    np.testing.assert_array_equal(seen[0], [-1.0, 0.5, 1.0])
    assert [r.getMessage() for r in caplog.records] == ["x0 outside bounds at indices [0, 2]: clipped"]
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="studio.optimize.staged"):
        staged_nelder_mead(f, [0.0, 0.5, 0.0], [Stage((1,), 5)], bounds=([-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]))
    assert caplog.records == []


def test_stage_limits_and_defaults():
    stage = Stage(np.array([2, 0]), 1.0)  # one evaluation is allowed
    assert stage.indices == (2, 0) and stage.max_evaluations == 1 and type(stage.max_evaluations) is int
    with pytest.raises(ValueError, match=r"^Stage '': max_evaluations must be >= 1, got 0$"):
        Stage((0,), 0)
    assert [s.max_evaluations for s in thesis_stages([0], [[1], [2]])] == [300] * 5
    with pytest.raises(ValueError, match=r"^stages: at least one Stage is needed$"):
        staged_nelder_mead(lambda x: 0.0, [0.0], [])
    with pytest.raises(ValueError, match=r"^step: initial simplex steps must be finite and positive$"):
        staged_nelder_mead(lambda x: 0.0, [0.0], [Stage((0,))], step=0.0)
