"""The light's posterior by MCMC (emcee): credible intervals for direction and distance.

The cost of eq. 5.9 is turned into a likelihood ``p(ℓ) ∝ exp(−E(ℓ) / T)`` with a flat prior
over the searched parameter box (:func:`studio.light.params.param_bounds`, a point light above
the bodies). ``T`` is the residual cost per frame at the optimum, ``E_min / n_frames``: each
frame's shadow is one observation of the "shadow camera" (the K views of it are not independent,
thesis §5.6, which averages them), and the scatter of the chamfer terms about the best light is
the noise scale of the observations — a body fitted less well leaves a larger residual and so
widens the posterior. The affine-invariant ensemble sampler (emcee) starts in a small ball about
the search's answer; the effective sample size is the number of samples over the longest
integrated autocorrelation time.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from studio.light.params import Frame, above_bodies, direction_of, param_bounds, to_light

__all__ = ["Posterior", "sample_posterior", "summarise"]

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class Posterior:
    """``samples`` (S, D·n_lights) after burn-in, their ``costs`` (S,), ``temperature`` T,
    ``acceptance`` mean acceptance fraction, ``autocorr`` (D,) integrated autocorrelation
    times (steps; emcee advises chains of 50 of them, ours are shorter for speed: the ratio is
    reported), ``ess`` effective sample size, ``n_evaluations``."""

    samples: np.ndarray
    costs: np.ndarray
    temperature: float
    acceptance: float
    autocorr: np.ndarray
    ess: float
    n_walkers: int
    n_steps: int
    burn: int
    n_evaluations: int


def sample_posterior(evaluate, kind: str, thetas: list, cost: float, frame: Frame, body_top: float, *,
                     n_frames: int, step: np.ndarray, n_walkers: int | None = None, n_steps: int = 40,
                     burn: int = 15, seed=0) -> Posterior:
    """emcee over the parameters of every light (``thetas``: the search's answer, ``cost`` its
    E); ``evaluate`` maps a list of hypotheses (lists of lights) to costs; ``step`` (D,) the
    spread of the starting ball per parameter (a few of the search's last spacings). The first
    ``burn`` steps (at most a third of ``n_steps``) are discarded."""
    import emcee

    burn = min(int(burn), int(n_steps) // 3)
    x0 = np.concatenate([np.asarray(t, float) for t in thetas])
    d = len(thetas[0])
    lo, hi = param_bounds(kind, body_top)
    lo, hi = np.tile(lo, len(thetas)), np.tile(hi, len(thetas))
    T = max(float(cost), 1e-6) / max(int(n_frames), 1)
    n_walkers = n_walkers or max(4 * len(x0), 12)
    rng = np.random.default_rng(seed)
    spread = np.tile(np.asarray(step, float), len(thetas))
    start = np.clip(x0 + rng.standard_normal((n_walkers, len(x0))) * spread, lo, hi)
    counter = {"n": 0}

    def log_prob(X):
        X = np.atleast_2d(X)
        out = np.full(len(X), -np.inf)
        ok = np.all((X >= lo) & (X <= hi), axis=1)
        ok &= np.array([all(above_bodies(kind, x[i * d:(i + 1) * d], body_top) for i in range(len(thetas)))
                        for x in X], bool)
        if ok.any():
            hyps = [[to_light(kind, x[i * d:(i + 1) * d], frame) for i in range(len(thetas))] for x in X[ok]]
            out[ok] = -(np.asarray(evaluate(hyps), float) - cost) / T
            counter["n"] += int(ok.sum())
        return out

    sampler = emcee.EnsembleSampler(n_walkers, len(x0), log_prob, vectorize=True,
                                    moves=[(emcee.moves.DEMove(), 0.8), (emcee.moves.DESnookerMove(), 0.2)])
    sampler.random_state = np.random.RandomState(int(rng.integers(2**31))).get_state()
    sampler.run_mcmc(start, n_steps, progress=False)
    chain = sampler.get_chain(discard=burn)  # (steps, walkers, D)
    lp = sampler.get_log_prob(discard=burn)
    with np.errstate(invalid="ignore", divide="ignore"):  # a walker that never moved has no autocorrelation
        tau = (np.asarray(emcee.autocorr.integrated_time(chain, tol=0), float) if len(chain) > 1
               else np.ones(len(x0)))  # tol=0: short chains are reported, not refused (chain_over_autocorr)
    tau = np.where(np.isfinite(tau), tau, float(len(chain)))
    n = chain.shape[0] * chain.shape[1]
    ess = float(n / max(float(np.max(tau)), 1.0))
    return Posterior(chain.reshape(-1, len(x0)), cost - lp.reshape(-1) * T, T,
                     float(np.mean(sampler.acceptance_fraction)), tau, ess, n_walkers, n_steps, burn, counter["n"])


def summarise(kind: str, theta: np.ndarray, samples: np.ndarray, frame: Frame, level: float = 0.95) -> dict:
    """Credible intervals of one light from its posterior ``samples`` (S, D): ``direction_ci_deg``
    the angle (deg) from the estimate's direction (seen from the subject's centre) within which
    ``level`` of the samples lie; for a point light ``distance_ci`` [lo, hi] the central ``level``
    interval of the distance relative to the estimate's (percent), and ``distance_ci_m`` in metres."""
    est = to_light(kind, theta, frame)
    u = direction_of(est, frame)
    dirs = np.stack([direction_of(to_light(kind, s, frame), frame) for s in samples])
    ang = np.degrees(np.arccos(np.clip(dirs @ u, -1.0, 1.0)))
    out = {"direction_ci_deg": float(np.quantile(ang, level)),
           "direction_sd_deg": float(np.sqrt(np.mean(ang ** 2))),
           "parameter_mean": np.mean(samples, axis=0).tolist(),
           "parameter_sd": np.std(samples, axis=0).tolist()}
    if kind == "point":
        r0 = float(theta[2])
        q = np.quantile(samples[:, 2], [(1 - level) / 2, (1 + level) / 2])
        out["distance_ci"] = [float((q[0] / r0 - 1) * 100), float((q[1] / r0 - 1) * 100)]
        out["distance_ci_m"] = [float(q[0]), float(q[1])]
    return out
