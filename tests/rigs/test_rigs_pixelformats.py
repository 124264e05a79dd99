"""rigs.pixelformats: unpacking of PFNC buffers and Bayer demosaicing against known images."""

from __future__ import annotations

import numpy as np
import pytest

from rigs.pixelformats import SENSOR_FORMATS, bayer_pattern, mosaic, to_image, unpack
from fake_gentl import pack

PATTERNS = ("RG", "GB", "GR", "BG")


def ramp_rgb(h=24, w=32, top=255) -> np.ndarray:
    """A smooth image (linear ramps per channel): bilinear demosaicing recovers it exactly
    away from the border."""
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    rgb = np.stack([x / (w - 1), y / (h - 1), 1 - 0.5 * (x / (w - 1) + y / (h - 1))], axis=2)
    return np.round(rgb * top * 0.9 + top * 0.05).astype(np.uint8 if top == 255 else np.uint16)


@pytest.mark.parametrize("pattern", PATTERNS)
def test_bayer8_debayers_back_to_the_image(pattern):
    rgb = ramp_rgb()
    out = to_image(mosaic(rgb, pattern).tobytes(), 32, 24, f"Bayer{pattern}8")
    assert out.shape == (24, 32, 3) and out.dtype == np.uint8
    inner = np.abs(out[2:-2, 2:-2].astype(int) - rgb[2:-2, 2:-2])
    assert inner.max() <= 2, f"{pattern}: interior error {inner.max()} (a wrong pattern is off by ~100)"
    raw = to_image(mosaic(rgb, pattern).tobytes(), 32, 24, f"Bayer{pattern}8", debayer=False)
    np.testing.assert_array_equal(raw, mosaic(rgb, pattern))
    assert bayer_pattern(f"Bayer{pattern}8") == pattern


@pytest.mark.parametrize("suffix", ["12", "12p", "12Packed"])
@pytest.mark.parametrize("pattern", PATTERNS)
def test_bayer12_packed_and_unpacked_debayer_to_16_bit(pattern, suffix):
    rgb12 = ramp_rgb(top=4095)
    fmt = f"Bayer{pattern}{suffix}"
    out = to_image(pack(mosaic(rgb12, pattern), fmt), 32, 24, fmt)
    assert out.dtype == np.uint16 and out.shape == (24, 32, 3)
    err = np.abs(out[2:-2, 2:-2].astype(int) - (rgb12[2:-2, 2:-2].astype(int) << 4))
    assert err.max() <= 32, f"{fmt}: interior error {err.max()} (16-bit units; 1 12-bit step = 16)"


@pytest.mark.parametrize("fmt", ["Mono12", "Mono12p", "Mono12Packed"])
def test_mono12_formats_unpack_to_the_values(fmt):
    values = np.random.default_rng(3).integers(0, 4096, size=(6, 10), dtype=np.uint16)
    np.testing.assert_array_equal(unpack(pack(values, fmt), 10, 6, fmt), values)
    np.testing.assert_array_equal(to_image(pack(values, fmt), 10, 6, fmt), values << 4)


def test_mono10p_is_a_little_endian_bit_stream():
    values = np.random.default_rng(4).integers(0, 1024, size=(3, 8), dtype=np.uint16)
    bits = ((values.reshape(-1, 1) >> np.arange(10)) & 1).astype(np.uint8).reshape(-1)
    data = np.packbits(bits, bitorder="little").tobytes()
    assert len(data) == 30  # 24 pixels x 10 bits
    np.testing.assert_array_equal(unpack(data, 8, 3, "Mono10p"), values)


def test_colour_orders_alpha_and_16_bit():
    px = np.array([[[10, 20, 30], [40, 50, 60]]], np.uint8)
    np.testing.assert_array_equal(to_image(px[:, :, ::-1].tobytes(), 2, 1, "BGR8"), px)
    rgba = np.concatenate([px, np.full((1, 2, 1), 255, np.uint8)], axis=2)
    np.testing.assert_array_equal(to_image(rgba.tobytes(), 2, 1, "RGBa8"), px)
    m16 = np.array([[1, 65535]], "<u2")
    out = to_image(m16.tobytes() + b"\0\0chunk", 2, 1, "Mono16")  # trailing chunk bytes ignored
    assert out.dtype == np.uint16 and out.tolist() == [[1, 65535]]
    assert out.flags.writeable and out.flags.c_contiguous


def test_bad_formats_and_short_buffers_are_named():
    with pytest.raises(ValueError, match="pixel format 'YUV422_8' is not supported; expected one of Mono8"):
        to_image(b"\0" * 8, 2, 2, "YUV422_8")
    with pytest.raises(ValueError, match=r"Mono12p 4x2: buffer holds 3 bytes, expected 12"):
        unpack(b"\0" * 3, 4, 2, "Mono12p")
    with pytest.raises(ValueError, match=r"RGB8 2x2: buffer holds 4 bytes, expected 12"):
        unpack(b"\0" * 4, 2, 2, "RGB8")
    with pytest.raises(ValueError, match="Bayer pattern 'XY'"):
        mosaic(np.zeros((2, 2, 3), np.uint8), "XY")
    assert {"Mono8", "Mono12", "Mono16", "RGB8", "BGR8", "BayerRG12p", "BayerBG12Packed"} <= set(SENSOR_FORMATS)
