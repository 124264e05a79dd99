"""Circular hue statistics (eq. 5.4) and the HSV conversion."""

import numpy as np
import pytest

from studio.segment import SegmentationError, circular_mean, circular_std, hue_distance, rgb_to_hsv


def test_hue_distance_wraps_at_one():
    d = hue_distance(np.array([0.98, 0.1, 0.5]), np.array([0.01, 0.9, 0.0]))
    np.testing.assert_allclose(d, [0.03, 0.2, 0.5], atol=1e-6)


def test_circular_mean_and_std_across_the_wrap():
    hues = np.array([0.98, 0.99, 0.01, 0.02], dtype=np.float32)
    mean = float(circular_mean(hues))
    assert min(mean, 1 - mean) < 1e-6  # 0 (== 1), where the naive mean would give 0.5
    assert abs(hues.mean() - 0.5) < 1e-6
    std = float(circular_std(hues, np.float32(mean)))
    assert std == pytest.approx(np.sqrt(np.mean([0.02**2, 0.01**2, 0.01**2, 0.02**2])), rel=1e-4)


def test_circular_statistics_per_pixel_with_weights():
    hues = np.array([[0.95, 0.3], [0.05, 0.3], [0.5, 0.32]], dtype=np.float32)  # (N=3, 2 pixels)
    w = np.array([[1, 1], [1, 1], [0, 1]], dtype=np.float32)  # drop the outlier 0.5 at pixel 0
    mean = circular_mean(hues, axis=0, weights=w)
    assert min(mean[0], 1 - mean[0]) < 1e-6
    assert mean[1] == pytest.approx(0.30667, abs=1e-4)
    std = circular_std(hues, mean, axis=0, weights=w)
    assert std[0] == pytest.approx(0.05, abs=1e-5)


def test_rgb_to_hsv_reference_values_uint8_and_uint16():
    rgb = np.array([[[255, 0, 0], [0, 255, 0], [0, 0, 255], [128, 128, 128]]], dtype=np.uint8)
    hsv = rgb_to_hsv(rgb)
    np.testing.assert_allclose(hsv[0, :, 0], [0.0, 1 / 3, 2 / 3, 0.0], atol=1e-6)
    np.testing.assert_allclose(hsv[0, :, 1], [1, 1, 1, 0], atol=1e-6)
    np.testing.assert_allclose(hsv[0, :, 2], [1, 1, 1, 128 / 255], atol=1e-6)
    np.testing.assert_allclose(rgb_to_hsv(rgb.astype(np.uint16) * 257), hsv, atol=1e-5)


def test_rgb_to_hsv_rejects_bad_input():
    with pytest.raises(SegmentationError, match=r"expected an \(H, W, 3\) RGB array"):
        rgb_to_hsv(np.zeros((4, 4), np.uint8))
    with pytest.raises(SegmentationError, match="expected uint8 or uint16 RGB, got dtype float64"):
        rgb_to_hsv(np.zeros((4, 4, 3)))
