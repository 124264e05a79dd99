"""Sensor effects: exposure and flicker, shot and read noise, gamma, Bayer mosaic/demosaic."""

from __future__ import annotations

import cv2
import numpy as np

__all__ = ["apply_sensor", "bayer_mosaic", "demosaic", "gaussian_noise"]


def bayer_mosaic(rgb: np.ndarray) -> np.ndarray:
    """RGGB mosaic (H, W) of an RGB image (H, W, 3): R at (0,0), G at (0,1)/(1,0), B at (1,1)."""
    h, w, _ = rgb.shape
    m = np.empty((h, w), dtype=rgb.dtype)
    m[0::2, 0::2] = rgb[0::2, 0::2, 0]
    m[0::2, 1::2] = rgb[0::2, 1::2, 1]
    m[1::2, 0::2] = rgb[1::2, 0::2, 1]
    m[1::2, 1::2] = rgb[1::2, 1::2, 2]
    return m


def demosaic(mosaic: np.ndarray) -> np.ndarray:
    """RGB (H, W, 3) from an RGGB mosaic (OpenCV bilinear; its ``BayerBG`` code is RGGB→RGB)."""
    return cv2.cvtColor(mosaic, cv2.COLOR_BayerBG2RGB)


_LEVELS = 4096
_GAUSS: np.ndarray | None = None


def gaussian_noise(rng: np.random.Generator, shape) -> np.ndarray:
    """Standard normal noise (float32) by table lookup: 65536 exact quantiles indexed by
    uniform 16-bit integers (4-5× faster than ``rng.standard_normal`` for frame-size arrays)."""
    global _GAUSS
    if _GAUSS is None:
        from scipy.special import ndtri

        _GAUSS = ndtri((np.arange(65536) + 0.5) / 65536).astype(np.float32)
    return _GAUSS[rng.integers(0, 65536, size=shape, dtype=np.uint16)]


def _tone_tables(sensor: dict) -> tuple[np.ndarray, np.ndarray]:
    """Lookup tables over linear levels: encoded value (0-255) and its noise std (levels)."""
    x = np.arange(_LEVELS, dtype=np.float64) / (_LEVELS - 1)
    g = 1.0 / float(sensor["gamma"])
    value = 255.0 * x**g
    # shot noise (std shot·√x in linear units) carried through the encoding: dv/dx · std
    slope = 255.0 * g * np.maximum(x, 0.5 / (_LEVELS - 1)) ** (g - 1.0)
    shot = float(sensor["shot_noise"]) * np.sqrt(x) * slope
    sd = np.sqrt(shot**2 + float(sensor["noise"]) ** 2)
    return value.astype(np.float32), sd.astype(np.float32)


def apply_sensor(radiance: np.ndarray, sensor: dict, rng: np.random.Generator) -> np.ndarray:
    """Linear radiance (H, W, 3) → 8-bit RGB frame (H, W, 3) uint8.

    ``sensor``: ``exposure`` gain, ``flicker`` (relative std of a per-frame gain), ``shot_noise``
    (std of the signal-dependent noise at full scale, √signal law), ``noise`` (read noise std
    in 8-bit levels), ``gamma`` (display encoding ``v^(1/γ)``), ``bayer`` (mosaic + demosaic).
    The encoding goes through a 4096-level table; shot and read noise are combined into one
    Gaussian per pixel with the signal-dependent std.
    """
    gain = float(sensor["exposure"]) * (1.0 + float(sensor["flicker"]) * rng.standard_normal())
    x = radiance.astype(np.float32) * np.float32(gain * (_LEVELS - 1))
    idx = np.clip(np.rint(x), 0, _LEVELS - 1).astype(np.int32)
    value, sd = _tone_tables(sensor)
    v = value[idx]
    if sensor["noise"] > 0 or sensor["shot_noise"] > 0:
        v += sd[idx] * gaussian_noise(rng, v.shape)
    out = np.clip(np.rint(v), 0, 255).astype(np.uint8)
    if sensor["bayer"]:
        out = demosaic(bayer_mosaic(out))
    return out
