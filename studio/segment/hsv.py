"""HSV conversion and circular hue statistics (thesis §5.5.1, eq. 5.4).

All channels are in [0, 1); hue wraps around at 1 (``0.99`` and ``0.01`` are 0.02 apart).
"""

from __future__ import annotations

import cv2
import numpy as np

from studio.segment.errors import SegmentationError

__all__ = ["rgb_to_hsv", "hue_distance", "fold_hue", "circular_mean", "circular_std"]

TWO_PI = np.float32(2.0 * np.pi)


def check_rgb(image: np.ndarray, name: str = "image") -> np.ndarray:
    """Return ``image`` if it is an (H, W, 3) uint8/uint16 RGB array, else raise naming ``name``."""
    image = np.asarray(image)
    if image.ndim != 3 or image.shape[2] != 3:
        raise SegmentationError(f"{name}: expected an (H, W, 3) RGB array, got shape {image.shape}")
    if image.dtype not in (np.uint8, np.uint16):
        raise SegmentationError(f"{name}: expected uint8 or uint16 RGB, got dtype {image.dtype}")
    return image


def rgb_to_hsv(image: np.ndarray) -> np.ndarray:
    """RGB image → HSV with every channel in [0, 1].

    Parameters
    ----------
    image : (H, W, 3) uint8 or uint16 RGB.

    Returns
    -------
    (H, W, 3) float32 HSV; hue in [0, 1) (fraction of a turn), saturation and value in [0, 1].
    """
    image = check_rgb(image)
    scale = 1.0 / (255.0 if image.dtype == np.uint8 else 65535.0)
    rgb = image.astype(np.float32) * np.float32(scale)
    hsv = cv2.cvtColor(rgb, cv2.COLOR_RGB2HSV)  # float input: H in degrees [0, 360)
    hsv[..., 0] *= np.float32(1.0 / 360.0)  # OpenCV returns H < 360, so hue < 1 (up to rounding)
    return hsv


def hue_distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Shortest distance on the hue circle, ``min(|a − b|, 1 − |a − b|)`` (eq. 5.4, 5.6).

    >>> round(float(hue_distance(np.float32(0.98), np.float32(0.01))), 6)
    0.03
    """
    return fold_hue(np.abs(np.asarray(a, dtype=np.float32) - np.asarray(b, dtype=np.float32)))


def fold_hue(d: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """An absolute hue difference ``d = |a − b|`` in [0, 1] folded onto the circle, ``min(d, 1 − d)``.

    The one implementation of the wrap-around (:func:`hue_distance` and the classifier's
    ``N^H`` use it); ``out`` writes in place (float32 arrays).

    >>> float(fold_hue(np.float32(0.75)))
    0.25
    """
    return np.minimum(d, np.float32(1.0) - d, out=out)


def circular_mean(hue: np.ndarray, axis: int = 0, weights: np.ndarray | None = None) -> np.ndarray:
    """Circular mean of hues in [0, 1): ``atan2(E[sin 2πH], E[cos 2πH]) / 2π`` mod 1 (eq. 5.4).

    ``weights`` (same shape as ``hue``) give a weighted expectation (used to drop outlier frames).

    >>> round(float(circular_mean(np.array([0.95, 0.05]))), 6) in (0.0, 1.0)
    True
    """
    theta = np.asarray(hue, dtype=np.float32) * TWO_PI
    s, c = np.sin(theta), np.cos(theta)
    if weights is not None:
        s, c = s * weights, c * weights
    mean = np.arctan2(s.sum(axis=axis), c.sum(axis=axis)) / TWO_PI
    return np.mod(mean, np.float32(1.0)).astype(np.float32)


def circular_std(
    hue: np.ndarray, mean: np.ndarray, axis: int = 0, weights: np.ndarray | None = None
) -> np.ndarray:
    """Root mean squared wrapped distance to ``mean``: ``sqrt(E[min(|H−μ|, 1−|H−μ|)²])`` (eq. 5.4)."""
    d2 = hue_distance(hue, np.expand_dims(mean, axis)) ** 2
    if weights is None:
        return np.sqrt(d2.mean(axis=axis)).astype(np.float32)
    total = np.maximum(weights.sum(axis=axis), np.float32(1e-12))
    return np.sqrt((d2 * weights).sum(axis=axis) / total).astype(np.float32)
