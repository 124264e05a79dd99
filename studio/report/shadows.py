"""Shadow overlays for the report's light section (thesis §5.4–5.6).

For a few of the frames the light was estimated from, each camera's image with the shadow the
fitted body casts under the estimated light(s) (eq. 5.2 projected by eq. 5.3, the body's own
silhouette taken out: the *visible* shadow of §5.6) against the shadow the segmentation
observed (label 2), coloured as the fit's overlays (agreement / model only / image only), and
the shadow precision and recall per camera: how much of the predicted shadow is observed and
how much of the observed shadow the light explains.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["ShadowOverlay", "shadow_agreement", "shadow_overlays"]


@dataclass(frozen=True)
class ShadowOverlay:
    """One camera of one frame: the overlay image (H, W, 3) uint8 and the shadow agreement."""

    frame: int
    camera: str
    image: np.ndarray
    precision: float | None
    recall: float | None


def shadow_agreement(predicted: np.ndarray, observed: np.ndarray) -> tuple[float | None, float | None]:
    """(precision, recall) of a predicted shadow mask against the observed one: the share of
    predicted pixels observed, the share of observed pixels predicted (None when the
    denominator is empty).

    >>> p = np.array([[1, 1, 0, 0]], bool); o = np.array([[0, 1, 1, 1]], bool)
    >>> shadow_agreement(p, o)
    (0.5, 0.3333333333333333)
    """
    p = np.asarray(predicted, bool)
    o = np.asarray(observed, bool)
    both = float(np.count_nonzero(p & o))
    n_p, n_o = int(np.count_nonzero(p)), int(np.count_nonzero(o))
    return (both / n_p if n_p else None), (both / n_o if n_o else None)


def shadow_overlays(ws, lights, light: dict, *, max_frames: int = 2) -> list[ShadowOverlay]:
    """Overlays of up to ``max_frames`` of the frames in ``light["frames"]`` (spread over them),
    every camera of ``ws`` (a :class:`~studio.workspace.Workspace`); the bodies from the source
    the light was estimated from (``light["sources"]["bodies"]``: the fits or the truth),
    ``lights`` as :func:`studio.light.load_light` returns them, the calibration's ground."""
    from studio.fit import overlay_image
    from studio.light.session import spread_frames, session_bodies
    from studio.render import silhouette
    from studio.render.shadow import shadow_silhouettes

    frames = spread_frames([int(f) for f in light.get("frames", [])], max_frames)
    if not frames:
        return []
    source = (light.get("sources") or {}).get("bodies", "fit")
    frames, bodies = session_bodies(ws, frames, source)
    cameras = ws.cameras
    ground = getattr(ws.calibration, "ground", None)
    out = []
    for f, (V, F) in zip(frames, bodies, strict=True):
        body = [silhouette(c, V, F) for c in cameras]
        predicted = shadow_silhouettes(cameras, V, F, lights, ground, occluders=body)
        images = ws.images(f)
        for cam, img, pred in zip(cameras, images, predicted, strict=True):
            observed = ws.labels(cam.name, f) == 2
            p, r = shadow_agreement(pred, observed)
            out.append(ShadowOverlay(f, cam.name, overlay_image(img, pred, observed), p, r))
    return out
