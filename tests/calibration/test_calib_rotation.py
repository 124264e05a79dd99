"""One rotation module: axis-angle, matrices and quaternions through SciPy, exact near π."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from calibration.rotation import (is_rotation, matrix_to_quaternion, matrix_to_rotvec, quaternion_to_matrix,
                                  rotation_angle, rotvec_to_matrix)

AXIS = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])


@pytest.mark.parametrize("angle", [0.0, 1e-9, 0.7, np.pi - 1e-6, np.pi])
def test_axis_angle_round_trip_keeps_the_axis(angle):
    """At π − 1e-6 and at π the axis comes back (up to the sign that is the same rotation at π)."""
    R = rotvec_to_matrix(AXIS * angle)
    assert np.allclose(R, cv2.Rodrigues(AXIS * angle)[0], atol=1e-12)
    r = matrix_to_rotvec(R)
    assert abs(np.linalg.norm(r) - angle) < 1e-9
    if angle > 0.1:
        assert abs(abs(np.dot(r / np.linalg.norm(r), AXIS)) - 1.0) < 1e-9
    assert np.allclose(rotvec_to_matrix(r), R, atol=1e-12)
    assert rotation_angle(R) == pytest.approx(angle, abs=1e-9)


def test_batched_shapes():
    rng = np.random.default_rng(0)
    rv = rng.normal(size=(4, 15, 3))
    R = rotvec_to_matrix(rv)
    assert R.shape == (4, 15, 3, 3)
    assert np.allclose(R[2, 7], cv2.Rodrigues(rv[2, 7])[0], atol=1e-12)
    assert matrix_to_rotvec(R).shape == (4, 15, 3)
    with pytest.raises(ValueError, match=r"shape \(\.\.\., 3\)"):
        rotvec_to_matrix(np.zeros((2, 4)))


def test_quaternions_wxyz_and_zero_norm_refused():
    q = np.array([np.cos(0.35), 0.0, 0.0, np.sin(0.35)])  # 0.7 rad about z
    assert np.allclose(quaternion_to_matrix(q), rotvec_to_matrix([0, 0, 0.7]))
    assert np.allclose(matrix_to_quaternion(rotvec_to_matrix([0, 0, 0.7])), q)
    assert np.allclose(quaternion_to_matrix(3.0 * q), quaternion_to_matrix(q))  # normalised
    with pytest.raises(ValueError, match="zero or non-finite norm"):
        quaternion_to_matrix([0.0, 0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="zero or non-finite norm"):
        quaternion_to_matrix([np.nan, 0.0, 0.0, 1.0])


def test_is_rotation():
    R = rotvec_to_matrix([0.1, 0.2, 0.3])
    assert is_rotation(R)
    assert not is_rotation(np.diag([1.0, 1.0, -1.0]))
    assert not is_rotation(R * 1.001)
    assert not is_rotation(np.full((3, 3), np.nan))


def test_read_only_inputs_are_accepted():
    """Camera arrays are frozen (read-only); SciPy's Cython needs a writeable copy."""
    rv = np.array([0.1, 0.2, 0.3])
    rv.flags.writeable = False
    R = rotvec_to_matrix(rv)
    R.flags.writeable = False
    assert np.allclose(matrix_to_rotvec(R), rv)
    assert rotation_angle(R) == pytest.approx(np.linalg.norm(rv))
