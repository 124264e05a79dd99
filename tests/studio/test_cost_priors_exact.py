"""Eq. 6.7–6.9 on hand-computed values, at the documented boundaries.

Boundaries: equal joint limits (``lower <= upper``) fix a parameter; a weight of exactly 0 is
allowed (">= 0"); a covariance is symmetric to ``rtol = 1e-10, atol = 1e-12``. Batches keep
their leading shape, one vector gives a Python float. Full-covariance values use
``Σ = [[4, 2], [2, 3]]``: ``Σ⁻¹ = [[3, −2], [−2, 4]] / 8``, so ``d = (1, 1)`` has ``r² = 3/8``.
"""

from __future__ import annotations

import math

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

COV = np.array([[4.0, 2.0], [2.0, 3.0]])
R2 = 3.0 / 8.0  # (1, 1) Σ⁻¹ (1, 1)ᵀ


def test_deviation_is_measured_from_a_nonzero_reference():
    # |0.5 − 2.0| / 0.25 = 6 σ → (6 − 3)²; |1 − (−1)| / 1 = 2 σ → 0
    assert pose_deviation_penalty([0.5, 1.0], [2.0, -1.0], [0.25, 1.0]) == 9.0
    prior = PosePrior(lower=[-10, -10], upper=[10, 10], sigma=[0.25, 1.0], mean=[2.0, -1.0], threshold=1.0)
    assert prior([0.5, 1.0]) == (6 - 1) ** 2 + (2 - 1) ** 2  # the prior's own threshold


def test_equal_limits_fix_a_parameter():
    # limit 0 is the single value 1.0: θ = 1.5 is 0.5 / 0.25 = 2 σ past it
    assert pose_limit_penalty([1.5, 0.0], [1.0, -1.0], [1.0, 1.0], [0.25, 1.0]) == 4.0
    prior = PosePrior(lower=[1.0, -np.inf], upper=[1.0, np.inf], sigma=[0.25, 1.0])
    assert prior([0.5, 1e6]) == 4.0
    with pytest.raises(ValueError, match=r"^lower/upper: limit 1 has lower 2\.0 > upper 1\.0$"):
        pose_limit_penalty([0.0, 0.0], [1.0, 2.0], [1.0, 1.0], [1.0, 1.0])
    with pytest.raises(ValueError, match=r"^lower/upper: limit 1 has lower 2\.0 > upper 1\.0$"):
        PosePrior(lower=[1.0, 2.0], upper=[1.0, 1.0], sigma=[1.0, 1.0])


def test_full_covariance_hinge_hand_computed():
    x, mean = np.array([2.0, 0.0]), np.array([1.0, -1.0])
    assert gaussian_penalty(x, mean, COV) == pytest.approx(R2, rel=1e-12)
    r = math.sqrt(R2)
    assert gaussian_penalty(x, mean, COV, threshold=0.25) == pytest.approx((r - 0.25) ** 2, rel=1e-12)
    assert gaussian_penalty(x, mean, COV, threshold=1.0) == 0.0
    # a float32 covariance is factored in float64 (these entries are exact in float32)
    assert gaussian_penalty(x, mean, COV.astype(np.float32)) == pytest.approx(R2, rel=1e-12)
    prior = PosePrior(lower=[-9, -9], upper=[9, 9], sigma=[1, 1], mean=mean, cov=COV.astype(np.float32),
                      weight=2.0, threshold=0.25)
    assert prior(x) == pytest.approx(2.0 * (r - 0.25) ** 2, rel=1e-12)


def test_batches_keep_their_shape_and_single_vectors_give_floats():
    mean = np.array([1.0, -1.0])
    batch = np.broadcast_to(np.array([2.0, 0.0]), (2, 3, 2))
    np.testing.assert_allclose(gaussian_penalty(batch, mean, COV), np.full((2, 3), R2), rtol=1e-12)
    assert type(gaussian_penalty([2.0, 0.0], mean, COV)) is float
    np.testing.assert_array_equal(mahalanobis_squared(np.array([[1.0, 0.0], [0.0, 2.0], [3.0, 0.0]]),
                                                      [0.0, 0.0], [1.0, 2.0]), [1.0, 1.0, 9.0])
    with_cov = PosePrior(lower=[-9, -9], upper=[9, 9], sigma=[1, 1], mean=mean, cov=COV, threshold=0.0)
    np.testing.assert_allclose(with_cov(batch), np.full((2, 3), R2), rtol=1e-12)
    assert type(with_cov([2.0, 0.0])) is float
    no_mean = PosePrior(lower=[-1, -1], upper=[1, 1], sigma=[0.5, 0.5])
    for shape in [(4, 2), (2, 3, 2)]:
        terms = no_mean.terms(np.zeros(shape))
        assert terms.deviation.shape == shape[:-1] and not terms.deviation.any()
    assert type(no_mean.terms([0.0, 2.0]).deviation) is float
    assert no_mean.terms([0.0, 2.0]).total == 4.0


def test_integer_input_is_converted_before_arithmetic():
    # |−128| as int8 overflows to −128; converted to float64 first it is 128 σ → (128 − 0)²
    assert shape_prior(np.array([-128], np.int8), [1.0], threshold=0.0) == 16384.0


def test_zero_weights_are_allowed():
    assert combine_costs(1.5, shape=3.0, shape_weight=0.0).total == 1.5
    assert combine_costs(1.5, pose=3.0, pose_weight=0.0).total == 1.5
    prior = PosePrior(lower=[-1.0], upper=[1.0], sigma=[0.5], mean=[0.0], weight=0)
    assert prior([2.0]) == 4.0  # (1 / 0.5)², no deviation term
    assert combine_costs(2.5).as_dict() == {"silhouette": 2.5, "shape_prior": 0.0, "pose_prior": 0.0,
                                            "shape_weight": 1.0, "pose_weight": 1.0, "total": 2.5}


def test_prior_holds_read_only_float_arrays():
    prior = PosePrior(lower=[-1, -2], upper=[1, 2], sigma=[1, 1], mean=[0, 0], weight=2, threshold=1)
    for name in ("lower", "upper", "sigma", "mean"):
        value = getattr(prior, name)
        assert isinstance(value, np.ndarray) and value.dtype == np.float64 and not value.flags.writeable, name
    assert type(prior.weight) is float and type(prior.threshold) is float


def test_covariance_symmetry_tolerance():
    """Symmetric to rtol 1e-10 and atol 1e-12: a relative asymmetry of 1e-7, or an absolute one
    of 1e-9 on entries of 1e-6, is refused."""
    with pytest.raises(ValueError, match=r"^cov: the covariance must be finite and symmetric$"):
        gaussian_penalty([0.0, 0.0], [0.0, 0.0], [[1.0, 0.5], [0.5 + 1e-7, 1.0]])
    with pytest.raises(ValueError, match=r"^cov: the covariance must be finite and symmetric$"):
        gaussian_penalty([0.0, 0.0], [0.0, 0.0], [[1e-6, 1e-9], [0.0, 1e-6]])
    assert gaussian_penalty([1.0, 0.0], [0.0, 0.0], [[1.0, 0.5], [0.5 + 1e-12, 1.0]]) == pytest.approx(4 / 3)
    with pytest.raises(ValueError, match=r"^cov: the covariance is not positive definite$"):
        gaussian_penalty([0.0, 0.0], [0.0, 0.0], [[1.0, 2.0], [2.0, 1.0]])
    with pytest.raises(ValueError, match=r"^cov: a covariance needs a mean \(reference pose\) to deviate from$"):
        PosePrior(lower=[0.0], upper=[1.0], sigma=[1.0], cov=[[1.0]])


def test_messages_name_the_argument():
    cases = [
        (lambda: gaussian_penalty([np.nan, 0.0], [0, 0], np.eye(2)), r"^x: parameters contain NaN"),
        (lambda: gaussian_penalty([0.0, 0.0], [0.0], np.eye(2)), r"^mean: expected 2 values, got 1$"),
        (lambda: mahalanobis_squared([np.inf], [0.0], [1.0]), r"^x: parameters contain NaN"),
        (lambda: mahalanobis_squared([0.0, 0.0], [0.0, 0.0], [1.0]), r"^sigma: expected 2 values, got 1$"),
        (lambda: mahalanobis_squared([0.0, 0.0], [0.0, 0.0], [0.5, -2.0]),
         r"^sigma: standard deviations must be positive, got -2\.0 at index 1$"),
        (lambda: pose_deviation_penalty([np.nan], [0.0], [1.0]), r"^theta: parameters contain NaN"),
        (lambda: pose_deviation_penalty([0.0, 0.0], [0.0], [1.0, 1.0]), r"^theta0: expected 2 values, got 1$"),
        (lambda: pose_deviation_penalty([0.0, 0.0], [0.0, 0.0], [1.0]), r"^sigma: expected 2 values, got 1$"),
        (lambda: pose_deviation_penalty([0.0], [0.0], [0.0]), r"^sigma: standard deviations must be positive"),
        (lambda: pose_limit_penalty([0.0, 0.0], [0.0], [1.0, 1.0], [1.0, 1.0]), r"^lower: expected 2 values, got 1$"),
        (lambda: pose_limit_penalty([0.0, 0.0], [0.0, 0.0], [1.0], [1.0, 1.0]), r"^upper: expected 2 values, got 1$"),
        (lambda: pose_limit_penalty([0.0], [0.0], [np.nan], [1.0]), r"^upper: NaN value at index 0$"),
        (lambda: pose_limit_penalty([0.0, 0.0], [0.0, 0.0], [1.0, 1.0], [1.0]), r"^sigma: expected 2 values, got 1$"),
        (lambda: pose_limit_penalty([0.0], [0.0], [1.0], [-1.0]), r"^sigma: standard deviations must be positive"),
        (lambda: PosePrior(lower=[0.0], upper=[1.0, 2.0], sigma=[1.0, 1.0]), r"^lower: expected 2 values, got 1$"),
        (lambda: PosePrior(lower=[np.nan, 0.0], upper=[1.0, 2.0], sigma=[1.0, 1.0]), r"^lower: NaN value at index 0$"),
        (lambda: PosePrior(lower=[0.0, 0.0], upper=[1.0], sigma=[1.0, 1.0]), r"^upper: expected 2 values, got 1$"),
        (lambda: PosePrior(lower=[0.0, 0.0], upper=[1.0, np.nan], sigma=[1.0, 1.0]), r"^upper: NaN value at index 1$"),
        (lambda: PosePrior(lower=[0.0], upper=[1.0], sigma=[1.0], mean=[0.0, 0.0]), r"^mean: expected 1 values, got 2$"),
        (lambda: PosePrior(lower=[0.0], upper=[1.0], sigma=[1.0], mean=[np.inf]),
         r"^mean: NaN or infinite value at index 0$"),
    ]
    for call, message in cases:
        with pytest.raises(ValueError, match=message):
            call()
    # infinite limits are allowed (an unlimited parameter)
    assert PosePrior(lower=[-np.inf], upper=[np.inf], sigma=[1.0])([1e9]) == 0.0
