"""Pixel processing shared by the playback backends: ROI, pixel format, exposure/gain scaling.

Pure functions on arrays. A camera that plays back stored frames mimics what a sensor
would deliver under the configured features: ``ExposureTime`` and ``Gain`` scale the signal
linearly (``exposure / reference_exposure · 10^(gain_dB / 20)``) with clipping at the
format's white level, ``Width``/``Height``/``OffsetX``/``OffsetY`` crop a region of interest,
``PixelFormat`` sets channels and bit depth. A scale of exactly 1 and an unchanged format
return the input unchanged (bit for bit).
"""

from __future__ import annotations

import numpy as np

from rigs.device import PIXEL_FORMATS

__all__ = ["convert_pixels", "gain_scale"]

_LUMA = np.array([0.299, 0.587, 0.114], dtype=np.float32)


def gain_scale(exposure_us: float, gain_db: float, reference_exposure_us: float) -> float:
    """Linear signal scale of ``exposure_us`` and ``gain_db`` relative to the reference exposure
    at 0 dB.

    >>> gain_scale(10000.0, 0.0, 10000.0)
    1.0
    >>> round(gain_scale(5000.0, 6.0206, 10000.0), 4)
    1.0
    """
    return float(exposure_us) / float(reference_exposure_us) * 10.0 ** (float(gain_db) / 20.0)


def convert_pixels(
    image: np.ndarray,
    pixel_format: str,
    scale: float = 1.0,
    roi: tuple[int, int, int, int] | None = None,
) -> np.ndarray:
    """Deliver ``image`` ((H, W) or (H, W, 3), uint8/uint16) as ``pixel_format``.

    ``roi`` is ``(offset_x, offset_y, width, height)``. Returns the input object itself when
    nothing changes, else a new array.
    """
    out = image
    if roi is not None:
        x, y, w, h = roi
        if (x, y, w, h) != (0, 0, image.shape[1], image.shape[0]):
            out = out[y : y + h, x : x + w]
    channels, dtype = PIXEL_FORMATS[pixel_format]
    if out.ndim == 3 and channels == 1:
        out = (out.astype(np.float32) @ _LUMA).round()
        out = out.astype(image.dtype)
    elif out.ndim == 2 and channels == 3:
        out = np.repeat(out[:, :, None], 3, axis=2)
    if out.dtype != dtype:
        if dtype == np.uint16:  # 8 -> 16 bit: full-scale stretch
            out = out.astype(np.uint16) * np.uint16(257)
        else:  # 16 -> 8 bit
            out = ((out.astype(np.uint32) + 128) // 257).astype(np.uint8)
    if scale != 1.0:
        white = float(np.iinfo(dtype).max)
        out = np.clip(np.rint(out.astype(np.float32) * np.float32(scale)), 0.0, white).astype(dtype)
    elif out is not image:
        out = np.ascontiguousarray(out)
    return out
