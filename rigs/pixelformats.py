"""GenICam (PFNC) pixel formats a camera sends, and how a frame becomes an image in memory.

A GenICam camera delivers a flat buffer in its ``PixelFormat``. :func:`to_image` turns it
into the toolkit's in-memory image — ``(H, W)`` mono or ``(H, W, 3)`` **RGB**, uint8 or uint16:

==========================================  =========================================
sensor format                               in memory
==========================================  =========================================
``Mono8``                                   ``(H, W)`` uint8
``Mono10``, ``Mono12``, ``Mono16``          ``(H, W)`` uint16, MSB-aligned (``v << (16 - bits)``)
``Mono10p``, ``Mono12p``, ``Mono12Packed``  unpacked, then as ``Mono10`` / ``Mono12``
``RGB8``, ``BGR8``, ``RGBa8``, ``BGRa8``    ``(H, W, 3)`` uint8 RGB (channels reordered, alpha dropped)
``RGB16``                                   ``(H, W, 3)`` uint16
``Bayer{RG,GB,GR,BG}8``                     debayered ``(H, W, 3)`` uint8, or raw ``(H, W)``
``Bayer..12``, ``Bayer..12p``, ``..12Packed``  debayered ``(H, W, 3)`` uint16, or raw ``(H, W)``
==========================================  =========================================

Packing. PFNC ``…p`` formats are one little-endian bit stream (``Mono12p``: byte 0 = bits 0–7
of pixel 0, byte 1 = bits 8–11 of pixel 0 | bits 0–3 of pixel 1 << 4, byte 2 = bits 4–11 of
pixel 1); the GigE Vision legacy ``…Packed`` formats put the high bits first (``Mono12Packed``:
byte 0 = bits 4–11 of pixel 0, byte 1 = bits 0–3 of pixel 0 | bits 0–3 of pixel 1 << 4,
byte 2 = bits 4–11 of pixel 1). Debayering is OpenCV's bilinear demosaic; a raw Bayer frame
is stored as its mosaic with the pattern (``RG`` = red at the top-left pixel) recorded.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

__all__ = ["SENSOR_FORMATS", "SensorFormat", "bayer_pattern", "mosaic", "to_image", "unpack"]


@dataclass(frozen=True)
class SensorFormat:
    """``channels`` in the buffer (1, 3 or 4), ``bits`` per value, ``packing``
    (``None``, ``"lsb"`` for PFNC ``…p``, ``"gige"`` for ``…Packed``), ``order`` of colour
    channels (``"RGB"``, ``"BGR"``) and the Bayer ``pattern`` or None."""

    channels: int
    bits: int
    packing: str | None = None
    order: str = "RGB"
    pattern: str | None = None

    @property
    def container_bytes(self) -> int:
        return 1 if self.bits <= 8 else 2


def _table() -> dict[str, SensorFormat]:
    t = {
        "Mono8": SensorFormat(1, 8), "Mono10": SensorFormat(1, 10), "Mono12": SensorFormat(1, 12),
        "Mono16": SensorFormat(1, 16), "Mono10p": SensorFormat(1, 10, "lsb"),
        "Mono12p": SensorFormat(1, 12, "lsb"), "Mono12Packed": SensorFormat(1, 12, "gige"),
        "RGB8": SensorFormat(3, 8), "BGR8": SensorFormat(3, 8, order="BGR"),
        "RGBa8": SensorFormat(4, 8), "BGRa8": SensorFormat(4, 8, order="BGR"),
        "RGB16": SensorFormat(3, 16),
    }  # fmt: skip
    for p in ("RG", "GB", "GR", "BG"):
        t[f"Bayer{p}8"] = SensorFormat(1, 8, pattern=p)
        t[f"Bayer{p}12"] = SensorFormat(1, 12, pattern=p)
        t[f"Bayer{p}16"] = SensorFormat(1, 16, pattern=p)
        t[f"Bayer{p}12p"] = SensorFormat(1, 12, "lsb", pattern=p)
        t[f"Bayer{p}12Packed"] = SensorFormat(1, 12, "gige", pattern=p)
    return t


#: PFNC name -> :class:`SensorFormat`, every format :func:`to_image` reads
SENSOR_FORMATS: dict[str, SensorFormat] = _table()

# PFNC names the colour of the top-left 2x2 cell's first row; OpenCV names the second row's
# middle pair, so PFNC ``BayerRG`` is OpenCV's ``BayerBG`` (checked by the round-trip tests).
_CV_DEMOSAIC = {"RG": cv2.COLOR_BayerBG2RGB, "GB": cv2.COLOR_BayerGR2RGB,
                "GR": cv2.COLOR_BayerGB2RGB, "BG": cv2.COLOR_BayerRG2RGB}  # fmt: skip


def bayer_pattern(pixel_format: str) -> str | None:
    """The Bayer pattern (``"RG"``, ...) of a sensor format, or None for mono/colour formats.

    >>> bayer_pattern("BayerGR12p"), bayer_pattern("Mono8")
    ('GR', None)
    """
    return _format(pixel_format).pattern


def _format(pixel_format: str) -> SensorFormat:
    try:
        return SENSOR_FORMATS[pixel_format]
    except KeyError:
        raise ValueError(
            f"pixel format {pixel_format!r} is not supported; expected one of {', '.join(SENSOR_FORMATS)}"
        ) from None


def _unpack12(data: np.ndarray, packing: str) -> np.ndarray:
    """(3n,) uint8 -> (2n,) uint16 12-bit values."""
    b = data.reshape(-1, 3).astype(np.uint16)
    out = np.empty((b.shape[0], 2), np.uint16)
    if packing == "lsb":
        out[:, 0] = b[:, 0] | ((b[:, 1] & 0x0F) << 8)
        out[:, 1] = (b[:, 1] >> 4) | (b[:, 2] << 4)
    else:  # gige
        out[:, 0] = (b[:, 0] << 4) | (b[:, 1] & 0x0F)
        out[:, 1] = (b[:, 2] << 4) | (b[:, 1] >> 4)
    return out.reshape(-1)


def _unpack_lsb(data: np.ndarray, bits: int, n: int) -> np.ndarray:
    """A little-endian stream of ``bits``-bit values -> (n,) uint16."""
    stream = np.unpackbits(data, bitorder="little")[: n * bits].reshape(n, bits)
    return (stream.astype(np.uint16) << np.arange(bits, dtype=np.uint16)).sum(axis=1, dtype=np.uint16)


def unpack(data, width: int, height: int, pixel_format: str) -> np.ndarray:
    """The values of a buffer as ``(H, W)`` or ``(H, W, C)`` uint8/uint16, unscaled
    (a 12-bit value stays in 0..4095). ``data`` is bytes or a uint8 array; trailing bytes
    (chunk data, padding) are ignored.

    >>> unpack(bytes([0x12, 0x34, 0x56]), 2, 1, "Mono12p").tolist()
    [[1042, 1379]]
    >>> unpack(bytes([0x12, 0x34, 0x56]), 2, 1, "Mono12Packed").tolist()
    [[292, 1379]]
    """
    f = _format(pixel_format)
    raw = np.frombuffer(data, np.uint8) if not isinstance(data, np.ndarray) else data.reshape(-1).view(np.uint8)
    n = int(width) * int(height)
    shape = (int(height), int(width)) if f.channels == 1 else (int(height), int(width), f.channels)
    if f.packing is None:
        need = n * f.channels * f.container_bytes
        if raw.size < need:
            raise ValueError(f"{pixel_format} {width}x{height}: buffer holds {raw.size} bytes, expected {need}")
        dtype = np.uint8 if f.container_bytes == 1 else np.dtype("<u2")
        return raw[:need].view(dtype).reshape(shape).astype(np.uint8 if f.bits <= 8 else np.uint16)
    need = (n * f.bits + 7) // 8
    if raw.size < need:
        raise ValueError(f"{pixel_format} {width}x{height}: buffer holds {raw.size} bytes, expected {need}")
    if f.bits == 12 and n % 2 == 0:
        values = _unpack12(raw[:need], f.packing)
    elif f.packing == "lsb":
        values = _unpack_lsb(raw[:need], f.bits, n)
    else:
        raise ValueError(f"{pixel_format}: a GigE-packed 12-bit frame needs an even pixel count, got {n}")
    return values.reshape(shape)


def to_image(data, width: int, height: int, pixel_format: str, *, debayer: bool = True) -> np.ndarray:
    """A camera buffer as the toolkit's image (see the module table): RGB channel order,
    values MSB-aligned to 8 or 16 bits, Bayer mosaics demosaiced unless ``debayer=False``.
    Always a new array (never a view of ``data``)."""
    f = _format(pixel_format)
    values = unpack(data, width, height, pixel_format)
    if f.bits not in (8, 16):
        values = values << np.uint16(16 - f.bits)
    if f.channels == 4:
        values = values[:, :, :3]
    if f.order == "BGR":
        values = values[:, :, ::-1]
    if f.pattern is not None and debayer:
        return cv2.cvtColor(np.ascontiguousarray(values), _CV_DEMOSAIC[f.pattern])
    return np.ascontiguousarray(values)  # unpack() already copied out of ``data``


def mosaic(rgb: np.ndarray, pattern: str) -> np.ndarray:
    """The Bayer mosaic a sensor with ``pattern`` (``"RG"``: red top-left) records of an
    ``(H, W, 3)`` RGB image: ``(H, W)``, same dtype. The inverse of debayering on flat regions.

    >>> mosaic(np.array([[[1, 2, 3]] * 2] * 2, np.uint8), "GB").tolist()
    [[2, 3], [1, 2]]
    """
    if pattern not in _CV_DEMOSAIC:
        raise ValueError(f"Bayer pattern {pattern!r}: expected one of {', '.join(_CV_DEMOSAIC)}")
    channel = {"R": 0, "G": 1, "B": 2}
    out = np.empty(rgb.shape[:2], rgb.dtype)
    for dy in (0, 1):
        for dx in (0, 1):
            c = channel[pattern[dx] if dy == 0 else _other_row(pattern)[dx]]
            out[dy::2, dx::2] = rgb[dy::2, dx::2, c]
    return out


def _other_row(pattern: str) -> str:
    """Second row of a 2x2 Bayer cell: ``RG`` -> ``GB``, ``GR`` -> ``BG``, ..."""
    return {"RG": "GB", "BG": "GR", "GB": "RG", "GR": "BG"}[pattern]
