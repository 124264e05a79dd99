"""The cost and the optimisers together: recover a toy body from two silhouettes.

A vertical elliptic cylinder (centre x, z; radii rx, rz in pixels) is seen by a front
camera (x, rx visible) and a side camera (z, rz visible), both orthographic. This is
the fitting pipeline of thesis §4.7 in miniature: APF search, then staged Nelder-Mead.
"""

import numpy as np
import pytest

from studio.cost import PosePrior, SilhouetteTarget, silhouette_cost
from studio.optimize import Stage, annealed_particle_filter, staged_nelder_mead

H, W = 48, 64
COLS = np.arange(W)[None, :]
ROWS = np.arange(H)[:, None]
TRUTH = np.array([38.3, 22.6, 7.4, 4.2])  # x, z, rx, rz (pixels)


def render(params):
    x, z, rx, rz = params
    body = (ROWS >= 8) & (ROWS < 42)
    front = body & (np.abs(COLS - x) < rx)
    side = body & (np.abs(COLS - z) < rz)
    return [front, side]


def test_apf_then_staged_nelder_mead_recover_the_body():
    target = SilhouetteTarget.build(render(TRUTH), tau=10.0, names=["front", "side"])
    limits = PosePrior(lower=[0, 0, 2, 2], upper=[W, W, 15, 15], sigma=[1.0, 1.0, 0.5, 0.5])

    def cost(p):
        return silhouette_cost(target, render(p)).total + limits(p)

    def batch(ps):
        return np.array([cost(p) for p in ps])

    start = np.array([30.0, 30.0, 5.0, 5.0])
    bounds = (np.array([0.0, 0.0, 2.0, 2.0]), np.array([W, W, 15.0, 15.0]))
    apf = annealed_particle_filter(batch, start, [8.0, 8.0, 2.0, 2.0], bounds=bounds, n_particles=60,
                                   n_layers=8, vectorized=True, seed=0)
    assert apf.cost < cost(start)
    np.testing.assert_allclose(apf.x[:2], TRUTH[:2], atol=2.0)
    refined = staged_nelder_mead(cost, apf.x, [Stage((0, 1), 60, "position"), Stage((2, 3), 60, "size"),
                                               Stage((0, 1, 2, 3), 200, "all")], bounds=bounds, step=1.0)
    assert refined.cost <= apf.cost
    # pixel masks quantise the parameters to about a pixel
    np.testing.assert_allclose(refined.x, TRUTH, atol=1.0)
    assert silhouette_cost(target, render(refined.x)).total == pytest.approx(refined.cost, abs=1e-9)
