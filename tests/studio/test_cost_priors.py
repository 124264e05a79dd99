"""Shape prior (eq. 6.8), pose prior (eq. 6.9) and the combined cost report."""

import numpy as np
import pytest

from studio.cost import (
    PosePrior,
    combine_costs,
    gaussian_penalty,
    mahalanobis_squared,
    pose_deviation_penalty,
    pose_limit_penalty,
    shape_prior,
)


def test_shape_prior_values():
    sigma = np.array([2.0, 1.0, 0.5])
    # within 3 sigma on every axis: flat (no pull toward the mean)
    assert shape_prior([5.9, -2.9, 1.4], sigma) == 0.0
    # 4 sigma on axis 0, 5 sigma on axis 2 -> (4-3)^2 + (5-3)^2
    assert shape_prior([8.0, 0.0, -2.5], sigma) == pytest.approx(1.0 + 4.0)
    # threshold 0 is the squared Mahalanobis distance to the mean shape
    beta = np.array([1.0, -2.0, 0.25])
    assert shape_prior(beta, sigma, threshold=0.0) == pytest.approx(0.25 + 4.0 + 0.25)
    assert mahalanobis_squared(beta, np.zeros(3), sigma) == pytest.approx(4.5)


def test_shape_prior_batches():
    sigma = np.ones(2)
    batch = np.array([[0.0, 0.0], [4.0, 0.0], [0.0, -5.0]])
    np.testing.assert_allclose(shape_prior(batch, sigma), [0.0, 1.0, 4.0])
    assert shape_prior(batch, sigma).shape == (3,)


def test_pose_limit_and_deviation_terms():
    lower = np.array([-1.0, 0.0, -np.inf])
    upper = np.array([1.0, 2.5, np.inf])
    sigma = np.array([0.1, 0.5, 1.0])
    # inside the limits: uniform prior
    assert pose_limit_penalty([0.5, 2.0, 100.0], lower, upper, sigma) == 0.0
    # 0.2 below the lower limit of joint 0 (2 sigma) and 1.0 above joint 1 (2 sigma)
    assert pose_limit_penalty([-1.2, 3.5, 0.0], lower, upper, sigma) == pytest.approx(4.0 + 4.0)
    theta0 = np.zeros(3)
    # deviation of 5 sigma on joint 2 beyond the 3-sigma threshold -> (5 - 3)^2
    assert pose_deviation_penalty([0.0, 0.0, 5.0], theta0, sigma) == pytest.approx(4.0)
    assert pose_deviation_penalty([0.25, 1.0, -2.0], theta0, sigma) == 0.0


def test_pose_prior_combines_terms_with_weight():
    prior = PosePrior(lower=[-1.0, -1.0], upper=[1.0, 1.0], sigma=[0.5, 0.5], mean=[0.0, 0.0], weight=0.5)
    terms = prior.terms([1.5, 0.0])  # 0.5 over the limit = 1 sigma; deviation 3 sigma -> 0
    assert terms.limits == pytest.approx(1.0)
    assert terms.deviation == 0.0
    theta = np.array([2.5, 0.0])  # 3 sigma over the limit, 5 sigma from the mean
    assert prior(theta) == pytest.approx(9.0 + 0.5 * 4.0)
    np.testing.assert_allclose(prior(np.array([[2.5, 0.0], [0.0, 0.0]])), [11.0, 0.0])
    no_mean = PosePrior(lower=[-1.0, -1.0], upper=[1.0, 1.0], sigma=[0.5, 0.5])
    assert no_mean(theta) == pytest.approx(9.0)
    np.testing.assert_allclose(no_mean(np.zeros((4, 2))), np.zeros(4))


def test_gaussian_penalty_is_mahalanobis_with_full_covariance():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(4, 4))
    cov = a @ a.T + 4 * np.eye(4)
    mean = rng.normal(size=4)
    x = rng.normal(size=(5, 4))
    expected = np.einsum("ni,ij,nj->n", x - mean, np.linalg.inv(cov), x - mean)
    np.testing.assert_allclose(gaussian_penalty(x, mean, cov), expected, rtol=1e-10)
    r = np.sqrt(expected[0])
    assert gaussian_penalty(x[0], mean, cov, threshold=0.5 * r) == pytest.approx((0.5 * r) ** 2)
    # diagonal covariance: same as the per-parameter Mahalanobis distance
    sig = np.array([0.5, 1.0, 2.0, 4.0])
    assert gaussian_penalty(x[1], mean, np.diag(sig**2)) == pytest.approx(mahalanobis_squared(x[1], mean, sig))
    prior = PosePrior(lower=np.full(4, -10.0), upper=np.full(4, 10.0), sigma=np.ones(4), mean=mean, cov=cov,
                      threshold=0.0)
    np.testing.assert_allclose(prior(x), expected, rtol=1e-10)


def test_combine_costs_reports_each_term():
    terms = combine_costs(12.5, shape=2.0, pose=4.0, shape_weight=0.5, pose_weight=0.25)
    assert terms.total == pytest.approx(12.5 + 1.0 + 1.0)
    assert terms.as_dict() == {"silhouette": 12.5, "shape_prior": 2.0, "pose_prior": 4.0,
                               "shape_weight": 0.5, "pose_weight": 0.25, "total": 14.5}


def test_bad_inputs():
    with pytest.raises(ValueError, match="beta: parameters contain NaN"):
        shape_prior([np.nan, 0.0], [1.0, 1.0])
    with pytest.raises(ValueError, match="sigma: expected 2 values, got 3"):
        shape_prior([0.0, 0.0], [1.0, 1.0, 1.0])
    with pytest.raises(ValueError, match="sigma: standard deviations must be positive"):
        shape_prior([0.0, 0.0], [1.0, 0.0])
    with pytest.raises(ValueError, match="threshold: "):
        shape_prior([0.0], [1.0], threshold=-1)
    with pytest.raises(ValueError, match="beta: expected a parameter vector"):
        shape_prior(1.0, [1.0])
    with pytest.raises(ValueError, match="theta: parameters contain NaN"):
        pose_limit_penalty([0.0, np.nan], [-1, -1], [1, 1], [1, 1])
    with pytest.raises(ValueError, match="lower/upper: limit 1 has lower 2.0 > upper 1.0"):
        pose_limit_penalty([0.0, 0.0], [-1, 2], [1, 1], [1, 1])
    with pytest.raises(ValueError, match="lower: NaN value at index 0"):
        pose_limit_penalty([0.0], [np.nan], [1.0], [1.0])
    with pytest.raises(ValueError, match="theta0: NaN or infinite value at index 0"):
        pose_deviation_penalty([0.0], [np.inf], [1.0])
    with pytest.raises(ValueError, match=r"theta: expected 2 parameters in the last axis"):
        PosePrior(lower=[-1, -1], upper=[1, 1], sigma=[1, 1])([0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="lower/upper: limit 0"):
        PosePrior(lower=[2.0], upper=[1.0], sigma=[1.0])
    with pytest.raises(ValueError, match="sigma: expected a 1-D vector"):
        PosePrior(lower=[0.0], upper=[1.0], sigma=1.0)
    with pytest.raises(ValueError, match="cov: a covariance needs a mean"):
        PosePrior(lower=[0.0], upper=[1.0], sigma=[1.0], cov=[[1.0]])
    with pytest.raises(ValueError, match="weight: expected a finite weight"):
        PosePrior(lower=[0.0], upper=[1.0], sigma=[1.0], weight=-1)
    with pytest.raises(ValueError, match=r"cov: expected a \(2, 2\) covariance"):
        gaussian_penalty([0.0, 0.0], [0.0, 0.0], np.eye(3))
    with pytest.raises(ValueError, match="cov: the covariance must be finite and symmetric"):
        gaussian_penalty([0.0, 0.0], [0.0, 0.0], [[1.0, 0.5], [0.0, 1.0]])
    with pytest.raises(ValueError, match="cov: the covariance is not positive definite"):
        gaussian_penalty([0.0, 0.0], [0.0, 0.0], [[1.0, 2.0], [2.0, 1.0]])
    with pytest.raises(ValueError, match="mean: expected 2 values"):
        mahalanobis_squared([0.0, 0.0], [0.0], [1.0, 1.0])
    with pytest.raises(ValueError, match="silhouette: cost term is NaN"):
        combine_costs(float("nan"))
    with pytest.raises(ValueError, match="pose_weight: expected a finite weight"):
        combine_costs(1.0, pose_weight=-2.0)


def test_doctests():
    import doctest

    import studio.cost.priors as priors_module

    assert doctest.testmod(priors_module).failed == 0
