"""Shape coefficients from measurements (Braga §4.3).

A joint Gaussian of (shape coefficients, measurements) is estimated from bodies sampled
from the shape prior and measured with :func:`studio.body.measure`; the stored samples
ship with the model (``<gender>/meas_shapes``, ``<gender>/meas_values``). Given any subset
of the measurements, the conditional Gaussian gives the expected shape (missing
measurements are marginalised out — the linear map with conditional Gaussian of Braga);
an optional fine-tuning then corrects the residual non-linearity by a few damped
Gauss–Newton steps on the real measurements, using the regression Jacobian.
"""

from __future__ import annotations

import numpy as np

from studio.body.measure import MEASUREMENT_NAMES, measure

__all__ = ["shape_from_measurements", "measurement_samples", "fit_joint_gaussian"]


def measurement_samples(model, n: int, rng: np.random.Generator | int | None = 0) -> tuple[np.ndarray, np.ndarray]:
    """Shapes (n, K) from the prior and their measurements (n, M) in ``MEASUREMENT_NAMES`` order."""
    shapes = model.sample_shapes(n, rng)
    values = np.array([[measure(model, s)[k] for k in MEASUREMENT_NAMES] for s in shapes])
    return shapes, values


def fit_joint_gaussian(shapes: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean (K+M,) and covariance (K+M, K+M) of stacked [shape, measurements]."""
    Z = np.concatenate([shapes, values], axis=1)
    return Z.mean(axis=0), np.cov(Z, rowvar=False)


def shape_from_measurements(
    model,
    measurements: dict[str, float],
    refine: int = 3,
    samples: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """Shape coefficients (n_shape,) of ``model`` matching ``measurements`` (metres, kg).

    ``measurements`` maps any subset of ``MEASUREMENT_NAMES`` to values; ``refine`` is the
    number of fine-tuning iterations (0: conditional mean only).
    """
    if not measurements:
        raise ValueError("measurements is empty: give at least one of " + ", ".join(MEASUREMENT_NAMES))
    unknown = sorted(set(measurements) - set(MEASUREMENT_NAMES))
    if unknown:
        raise ValueError(f"unknown measurement(s) {unknown}: expected some of {', '.join(MEASUREMENT_NAMES)}")
    obs = np.array([float(measurements[k]) for k in MEASUREMENT_NAMES if k in measurements])
    if not np.all(np.isfinite(obs)) or np.any(obs <= 0):
        raise ValueError("measurements must be finite positive numbers (metres, kilograms)")
    idx = np.array([i for i, k in enumerate(MEASUREMENT_NAMES) if k in measurements])
    if samples is None:
        samples = getattr(model, "measurement_samples", None)
    if samples is None:
        raise ValueError(f"the {model.gender} model has no measurement samples (rebuild it)")
    shapes, values = samples
    mu, cov = fit_joint_gaussian(shapes, values)
    K = shapes.shape[1]
    if K != model.n_shape:
        raise ValueError(f"measurement samples: each has {K} shape coefficients, the model has {model.n_shape}")
    mb, mm = mu[:K], mu[K:][idx]
    Sbm = cov[:K, K:][:, idx]
    Smm = cov[K:, K:][np.ix_(idx, idx)]
    Smm_inv = np.linalg.pinv(Smm + 1e-10 * np.eye(len(idx)))
    beta = mb + Sbm @ Smm_inv @ (obs - mm)
    # fine-tuning: m(β) ≈ m(β0) + Jm (β - β0) with the regression Jacobian Jm = Σmb Σbb⁻¹
    Sbb = cov[:K, :K]
    Jm = Sbm.T @ np.linalg.pinv(Sbb)
    prior = 1.0 / np.maximum(model.eigenvalues, 1e-12)
    for _ in range(int(refine)):
        m = measure(model, beta)
        r = obs - np.array([m[k] for k in MEASUREMENT_NAMES if k in measurements])
        scale = 1.0 / np.maximum(np.abs(obs), 1e-3)  # relative residuals
        A = (Jm * scale[:, None]).T @ (Jm * scale[:, None]) + 1e-4 * np.diag(prior)
        beta = beta + np.linalg.solve(A, (Jm * scale[:, None]).T @ (r * scale) - 1e-4 * prior * beta)
    return beta
