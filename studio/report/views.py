"""Pictures for the report: the fitted body from several directions, figures as PNG."""

from __future__ import annotations

import base64
import io

import numpy as np

from calibration import Camera

__all__ = ["LINE_COLOUR", "POINT_COLOUR", "RING_COLOUR", "body_views", "png_base64", "figure_base64"]


#: colours (RGB) of the drawn measurements: girths, lengths / breadths, landmarks
RING_COLOUR, LINE_COLOUR, POINT_COLOUR = (0, 110, 220), (220, 120, 0), (200, 0, 30)


def body_views(vertices: np.ndarray, faces: np.ndarray, azimuths=(0, 90, 180, 270), *, size=(240, 360),
               points: dict | None = None, lines: dict | None = None) -> np.ndarray:
    """(H, n·W, 3) uint8: the mesh rendered (grey, normal shading) from ``azimuths`` (degrees
    around the vertical through its centre; 0 = from the -y side, the model's front), each
    view ``size`` (W, H) pixels. ``points`` {name: (3,)} (landmarks) are drawn as dots and
    ``lines`` {name: (N, 3)} as polylines (closed when the name holds "circumference")."""
    from studio.render import rasterize

    V = np.asarray(vertices, dtype=np.float64)
    c = 0.5 * (V.min(0) + V.max(0))
    height = float(V[:, 2].max() - V[:, 2].min())
    dist = max(height, 0.5) * 1.6
    a, b, cc = (V[faces[:, i]] for i in range(3))
    n = np.cross(b - a, cc - a)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    tiles = []
    for az in azimuths:
        t = np.deg2rad(az)
        eye = c + dist * np.array([np.sin(t), -np.cos(t), 0.15])
        cam = Camera.look_at("view", eye, c, 420.0 * size[1] / 360.0, tuple(size))
        r = rasterize(cam, V, faces)
        img = np.full(r.face.shape + (3,), 250, dtype=np.uint8)
        sel = r.face >= 0
        view = (eye - c) / np.linalg.norm(eye - c)
        shade = np.abs(n[r.face[sel]] @ view)
        g = (35 + 190 * shade**1.5).astype(np.uint8)
        img[sel] = np.stack([g, g, (g * 0.95 + 10).astype(np.uint8)], axis=1)
        _draw(img, cam, points or {}, lines or {}, max(1, size[1] // 240))
        tiles.append(img)
    return np.concatenate(tiles, axis=1)


def _draw(img: np.ndarray, cam, points: dict, lines: dict, width: int) -> None:
    """Draw ``lines`` and ``points`` (world coordinates) seen by ``cam`` onto ``img`` in place."""
    import cv2

    for name, poly in lines.items():
        poly = np.asarray(poly, dtype=np.float64)
        if len(poly) < 2:
            continue
        uv, _, front = cam.project_points(poly)
        if not np.all(front):
            continue
        closed = "circumference" in name
        colour = RING_COLOUR if closed else LINE_COLOUR
        cv2.polylines(img, [np.rint(uv).astype(np.int32)], closed, colour, width, cv2.LINE_AA)
    for p in points.values():
        uv, _, front = cam.project_points(np.asarray(p, dtype=np.float64)[None])
        if front[0]:
            cv2.circle(img, tuple(int(round(x)) for x in uv[0]), 2 * width + 1, POINT_COLOUR, -1, cv2.LINE_AA)


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
