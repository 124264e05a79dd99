"""Cameras of image-pyramid levels for coarse-to-fine silhouette fitting (thesis §7.2.3).

A level-``l`` image is the full image reduced by ``s = 2**l`` (padded with background to a
multiple of ``s``, as :func:`studio.cost.downsample_mask` does). Pixel centres map as
``x_l = (x + 0.5)/s − 0.5``, so the level camera has
``K_l = [[1/s, 0, (1/s − 1)/2], [0, 1/s, (1/s − 1)/2], [0, 0, 1]] · K`` and size
``(ceil(W/s), ceil(H/s))``; distortion, R and t are unchanged.
"""

from __future__ import annotations

import numpy as np

__all__ = ["level_camera", "level_cameras"]


def level_camera(camera, level: int):
    """The camera that renders masks at pyramid ``level`` (0 returns ``camera`` itself)."""
    if isinstance(level, bool) or not isinstance(level, (int, np.integer)) or not 0 <= level <= 8:
        raise ValueError(f"level: expected a pyramid level in 0..8, got {level!r}")
    if level == 0:
        return camera
    s = float(1 << int(level))
    A = np.array([[1 / s, 0.0, (1 / s - 1) / 2], [0.0, 1 / s, (1 / s - 1) / 2], [0.0, 0.0, 1.0]])
    w, h = camera.size
    size = (-(-int(w) // int(s)), -(-int(h) // int(s)))
    return camera.replace(K=A @ np.asarray(camera.K, dtype=np.float64), size=size)


def level_cameras(cameras, level: int) -> list:
    """:func:`level_camera` of every camera in an iterable (or ``{name: camera}`` dict)."""
    cams = cameras.values() if isinstance(cameras, dict) else cameras
    return [level_camera(c, level) for c in cams]
