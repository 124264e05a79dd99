"""Global registration of frames to a background model: a camera nudged by a pixel between the
empty-scene capture and the session.

A shift of one pixel turns every edge of the room (ceiling lights, tripods, door frames) into
"foreground" for a per-pixel model. The shift is a translation for a bump of the tripod; it is
measured by phase correlation of the value channel (``cv2.phaseCorrelate``, Hann window,
sub-pixel) and the background statistics are moved onto the frame (``cv2.warpAffine``; hue as a
unit vector so it interpolates around the circle).
"""

from __future__ import annotations

import cv2
import numpy as np

__all__ = ["estimate_shift", "shift_image", "shift_hsv"]


def estimate_shift(reference: np.ndarray, image: np.ndarray) -> tuple[float, float, float]:
    """``(dx, dy, response)``: ``image`` is ``reference`` moved by (dx, dy) pixels.

    Parameters
    ----------
    reference, image : (H, W) float32 single-channel images (e.g. HSV value).
    response : phase-correlation peak (≈1 for a clean translation, ≲0.1 for none found).
    """
    ref = np.ascontiguousarray(reference, np.float32)
    img = np.ascontiguousarray(image, np.float32)
    window = cv2.createHanningWindow(ref.shape[::-1], cv2.CV_32F)
    (dx, dy), response = cv2.phaseCorrelate(ref, img, window)
    return float(dx), float(dy), float(response)


def shift_image(image: np.ndarray, dx: float, dy: float) -> np.ndarray:
    """``image`` moved by (dx, dy) pixels, bilinear, borders replicated."""
    m = np.float32([[1, 0, dx], [0, 1, dy]])
    h, w = image.shape[:2]
    return cv2.warpAffine(image, m, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


def shift_hsv(hsv: np.ndarray, dx: float, dy: float) -> np.ndarray:
    """An (H, W, 3) float32 HSV image (hue in [0, 1), circular) moved by (dx, dy) pixels."""
    theta = hsv[..., 0] * np.float32(2 * np.pi)
    unit = shift_image(np.dstack([np.cos(theta), np.sin(theta)]).astype(np.float32), dx, dy)
    out = shift_image(hsv, dx, dy)
    out[..., 0] = np.mod(np.arctan2(unit[..., 1], unit[..., 0]) / np.float32(2 * np.pi), np.float32(1.0))
    return out
