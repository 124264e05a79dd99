"""Compact storage of the shipped model file (``studio/body/data/scape_models.npz``).

The shape bases (30 × 103,392 per gender) are most of the file. They are stored as int8
in blocks of :data:`BLOCK` values with one float16 scale per block (``<gender>/D_basis_q``,
``<gender>/D_basis_scale``), the pose coefficients Q as float16, and the archive is written
with LZMA (which :func:`numpy.load` reads like any ``.npz``). Measured against the float16
bases: 0.04 mm mean and 0.47 mm worst vertex difference over bodies 1.5 σ along every
component; the file went from 18.7 MB to about 9 MB.
"""

from __future__ import annotations

import io
import zipfile
from pathlib import Path

import numpy as np

from rigs.atomic import atomic_open

__all__ = ["BLOCK", "quantize_blocks", "dequantize_blocks", "save_model_file"]

#: values sharing one scale in the quantised bases
BLOCK = 96


def quantize_blocks(a: np.ndarray, block: int = BLOCK) -> tuple[np.ndarray, np.ndarray]:
    """(K, N) float → int8 (K, N) and float16 scales (K, ceil(N / block)): each block of
    ``block`` consecutive values of a row is ``q * scale`` with |q| ≤ 127."""
    a = np.asarray(a, dtype=np.float32)
    k, n = a.shape
    pad = -n % block
    blocks = np.pad(a, ((0, 0), (0, pad))).reshape(k, -1, block)
    exact = np.abs(blocks).max(axis=2) / 127.0
    scale = exact.astype(np.float16)
    low = scale.astype(np.float32) < exact  # round the scale up so the largest value fits in ±127
    scale[low] = np.nextafter(scale[low], np.float16(np.inf))
    s = scale.astype(np.float32)[:, :, None]
    q = np.round(np.divide(blocks, s, out=np.zeros_like(blocks), where=s > 0))
    return np.clip(q, -127, 127).astype(np.int8).reshape(k, -1)[:, :n], scale


def dequantize_blocks(q: np.ndarray, scale: np.ndarray, block: int = BLOCK) -> np.ndarray:
    """Inverse of :func:`quantize_blocks`: (K, N) float32."""
    k, n = q.shape
    pad = scale.shape[1] * block - n
    blocks = np.pad(q.astype(np.float32), ((0, 0), (0, pad))).reshape(k, -1, block)
    return (blocks * scale.astype(np.float32)[:, :, None]).reshape(k, -1)[:, :n]


def save_model_file(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """Write the model archive atomically: float ``*/D_basis`` quantised, ``Q_coef`` and
    ``Q_coef_search`` as float16, LZMA-compressed members with a fixed timestamp (same arrays → same bytes)."""
    out = {}
    for name, a in arrays.items():
        if name.endswith("/D_basis") and np.issubdtype(np.asarray(a).dtype, np.floating):
            out[name + "_q"], out[name + "_scale"] = quantize_blocks(a)
        elif name in ("Q_coef", "Q_coef_search"):
            out[name] = np.asarray(a).astype(np.float16)
        else:
            out[name] = np.asarray(a)
    path = Path(path)
    with atomic_open(path, "wb") as fh:
        with zipfile.ZipFile(fh, "w", compression=zipfile.ZIP_LZMA) as zf:
            for name, a in out.items():
                buf = io.BytesIO()
                np.lib.format.write_array(buf, a, allow_pickle=False)
                info = zipfile.ZipInfo(name + ".npy", date_time=(1980, 1, 1, 0, 0, 0))
                info.compress_type = zipfile.ZIP_LZMA
                zf.writestr(info, buf.getvalue())
