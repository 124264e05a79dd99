"""Pictures for the report: the fitted body from several directions, figures as PNG."""

from __future__ import annotations

import base64
import io

import numpy as np

from calibration import Camera

__all__ = ["body_views", "png_base64", "figure_base64"]


def body_views(vertices: np.ndarray, faces: np.ndarray, azimuths=(0, 90, 180, 270)) -> np.ndarray:
    """(H, n·W, 3) uint8: the mesh rendered (grey, normal shading) from ``azimuths`` (degrees
    around the vertical through its centre; 0 = from the -y side, the model's front)."""
    from studio.render import rasterize

    V = np.asarray(vertices, dtype=np.float64)
    c = 0.5 * (V.min(0) + V.max(0))
    height = float(V[:, 2].max() - V[:, 2].min())
    dist = max(height, 0.5) * 2.1
    a, b, cc = (V[faces[:, i]] for i in range(3))
    n = np.cross(b - a, cc - a)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    tiles = []
    for az in azimuths:
        t = np.deg2rad(az)
        eye = c + dist * np.array([np.sin(t), -np.cos(t), 0.15])
        cam = Camera.look_at("view", eye, c, 420.0, (240, 360))
        r = rasterize(cam, V, faces)
        img = np.full(r.face.shape + (3,), 250, dtype=np.uint8)
        sel = r.face >= 0
        view = (eye - c) / np.linalg.norm(eye - c)
        shade = np.abs(n[r.face[sel]] @ view)
        g = (35 + 190 * shade**1.5).astype(np.uint8)
        img[sel] = np.stack([g, g, (g * 0.95 + 10).astype(np.uint8)], axis=1)
        tiles.append(img)
    return np.concatenate(tiles, axis=1)


def png_base64(image: np.ndarray) -> str:
    """A data URI of an RGB uint8 image as PNG."""
    import cv2

    ok, buf = cv2.imencode(".png", np.ascontiguousarray(image[..., ::-1]))
    if not ok:
        raise RuntimeError("PNG encoding failed")
    return "data:image/png;base64," + base64.b64encode(buf.tobytes()).decode()


def figure_base64(fig) -> str:
    """A data URI of a matplotlib figure as PNG (the figure is closed)."""
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90, bbox_inches="tight")
    plt.close(fig)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode()
