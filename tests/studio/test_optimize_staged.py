"""Staged Nelder-Mead (thesis §4.7.4): groups, bounds, budgets."""

import numpy as np
import pytest

from studio.optimize import CostError, Stage, staged_nelder_mead, thesis_stages

TARGET = np.array([0.5, -1.0, 2.0, 0.25, -0.75, 1.5])


def coupled_quadratic(x):
    """Minimum at TARGET; parameters coupled in pairs so staged updates matter."""
    d = np.asarray(x) - TARGET
    return float(np.sum(d**2) + 0.5 * d[0] * d[1] + 0.5 * d[2] * d[3] + 0.5 * d[4] * d[5])


def test_stages_improve_and_converge():
    stages = [Stage((0, 1), 200, "root"), Stage((2, 3), 200, "inner"), Stage((4, 5), 200, "outer"),
              Stage(tuple(range(6)), 2000, "all")]
    res = staged_nelder_mead(coupled_quadratic, np.zeros(6), stages, step=0.5, xatol=1e-8, fatol=1e-12)
    np.testing.assert_allclose(res.x, TARGET, atol=1e-4)
    assert res.cost < 1e-8
    costs = [coupled_quadratic(np.zeros(6))] + [s.cost_after for s in res.stages]
    assert all(b <= a for a, b in zip(costs, costs[1:]))  # never worse than the previous stage
    assert [s.name for s in res.stages] == ["root", "inner", "outer", "all"]
    assert res.stages[0].cost_before == pytest.approx(coupled_quadratic(np.zeros(6)))
    assert res.n_evaluations == 1 + sum(s.n_evaluations for s in res.stages)


def test_only_stage_parameters_move():
    seen = []

    def f(x):
        seen.append(x.copy())
        return coupled_quadratic(x)

    x0 = np.zeros(6)
    res = staged_nelder_mead(f, x0, [Stage((1, 4), 300)])
    pts = np.array(seen)
    np.testing.assert_array_equal(pts[:, [0, 2, 3, 5]], 0.0)
    np.testing.assert_array_equal(res.x[[0, 2, 3, 5]], 0.0)
    # conditional optimum with the others held at 0: d1 = -0.25 d0 = 0.125, d4 = -0.25 d5 = 0.375
    assert res.x[1] == pytest.approx(TARGET[1] + 0.125, abs=1e-3)
    assert res.x[4] == pytest.approx(TARGET[4] + 0.375, abs=1e-3)


def test_bounds_are_never_violated_and_active_bound_is_reached():
    lo = np.array([0.0, -0.5, 0.0, 0.0, -1.0, 0.0])
    hi = np.array([0.4, 0.5, 3.0, 1.0, 1.0, 1.0])  # TARGET[0], [1], [5] lie outside
    seen = []

    def f(x):
        seen.append(x.copy())
        return coupled_quadratic(x)

    x0 = np.array([2.0, 0.0, 0.0, 0.0, 0.0, 0.0])  # starts outside: clipped
    res = staged_nelder_mead(f, x0, [Stage((0, 1, 2)), Stage((3, 4, 5)), Stage(tuple(range(6)), 1500)],
                             bounds=(lo, hi), xatol=1e-7, fatol=1e-10)
    pts = np.array(seen)
    assert (pts >= lo).all() and (pts <= hi).all()
    # constrained optimum by hand: x1 and x5 on their bounds (d1 = 0.5, d5 = -0.5), then the coupled
    # partners d0 = -0.25 d1 = -0.125 (inside its bound 0.4) and d4 = -0.25 d5 = 0.125; x2, x3 free.
    expected = TARGET + np.array([-0.125, 0.5, 0.0, 0.0, 0.125, -0.5])
    np.testing.assert_allclose(res.x, expected, atol=1e-3)


def test_budget_per_stage_is_exact():
    res = staged_nelder_mead(coupled_quadratic, np.zeros(6), [Stage(tuple(range(6)), 25), Stage((0,), 7)],
                             xatol=1e-12, fatol=1e-14)
    assert [s.n_evaluations for s in res.stages] == [25, 7]
    assert not res.stages[0].converged
    assert "Maximum number of function evaluations" in res.stages[0].message
    assert res.n_evaluations == 1 + 25 + 7


def test_fixed_parameters_and_narrow_bounds():
    lo = np.array([0.0, 1.0])
    hi = np.array([0.05, 1.0])  # second fixed, first narrower than the default step
    res = staged_nelder_mead(lambda x: (x[0] - 1.0) ** 2, [0.0, 1.0], [Stage((1,)), Stage((0, 1))],
                             bounds=(lo, hi), step=0.5)
    assert res.stages[0].n_evaluations == 0 and res.stages[0].message.startswith("all parameters fixed")
    assert res.x[0] == pytest.approx(0.05) and res.x[1] == 1.0


def test_thesis_stages_schedule():
    stages = thesis_stages(root=[0, 1, 2], part_groups=[[3, 4], [5, 6]], shape=list(range(7, 21)),
                           max_evaluations=[10, 20, 30, 40, 50])
    assert [s.name for s in stages] == ["torso+shape", "parts0", "parts1", "pose+shape", "all"]
    assert stages[0].indices == (0, 1, 2, 7, 8, 9, 10, 11, 12)
    assert stages[1].indices == (3, 4)
    assert stages[3].indices == tuple(range(7)) + tuple(range(7, 19))
    assert stages[4].indices == tuple(range(21))
    assert [s.max_evaluations for s in stages] == [10, 20, 30, 40, 50]
    assert all(s.max_evaluations == 99 for s in thesis_stages([0], [[1]], max_evaluations=99))


def test_callback_can_stop():
    seen = []
    res = staged_nelder_mead(coupled_quadratic, np.zeros(6), [Stage((0,)), Stage((1,)), Stage((2,))],
                             callback=lambda s: seen.append(s.name) or len(seen) == 2)
    assert seen == ["stage0", "stage1"] and res.stopped_early and len(res.stages) == 2


def test_bad_inputs():
    f = coupled_quadratic
    with pytest.raises(ValueError, match="x0: non-finite value nan at index 2"):
        staged_nelder_mead(f, [0, 0, np.nan, 0, 0, 0], [Stage((0,))])
    with pytest.raises(ValueError, match=r"stages\[0\] \('s'\): indices \[6\] out of range for 6"):
        staged_nelder_mead(f, np.zeros(6), [Stage((0, 6), name="s")])
    with pytest.raises(ValueError, match=r"x0: expected a non-empty 1-D parameter vector, got shape \(2, 3\)"):
        staged_nelder_mead(f, np.zeros((2, 3)), [Stage((0,))])
    with pytest.raises(ValueError, match="stages: at least one Stage"):
        staged_nelder_mead(f, np.zeros(6), [])
    with pytest.raises(ValueError, match=r"stages\[0\]: expected a Stage, got tuple"):
        staged_nelder_mead(f, np.zeros(6), [(0, 1)])
    with pytest.raises(ValueError, match="step: initial simplex steps must be finite and positive"):
        staged_nelder_mead(f, np.zeros(6), [Stage((0,))], step=0.0)
    with pytest.raises(ValueError, match="step: expected 6 values"):
        staged_nelder_mead(f, np.zeros(6), [Stage((0,))], step=[1.0, 1.0])
    with pytest.raises(ValueError, match="bounds: parameter 1 has lo"):
        staged_nelder_mead(f, np.zeros(2), [Stage((0,))], bounds=([0, 1], [1, 0]))
    with pytest.raises(ValueError, match="Stage 'a': no parameter indices"):
        Stage((), name="a")
    with pytest.raises(ValueError, match=r"Stage '': repeated parameter indices \[1, 1\]"):
        Stage((1, 1))
    with pytest.raises(ValueError, match="Stage '': indices must be integers"):
        Stage(("a",))
    with pytest.raises(ValueError, match="Stage '': max_evaluations must be >= 1"):
        Stage((0,), 0)
    with pytest.raises(ValueError, match="max_evaluations: expected one value or 4"):
        thesis_stages([0], [[1]], max_evaluations=[1, 2])
    with pytest.raises(CostError, match="cost function returned NaN at"):
        staged_nelder_mead(lambda x: float("nan"), np.zeros(2), [Stage((0,))])
