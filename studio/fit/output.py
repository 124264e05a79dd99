"""Writing fit results: ``fit/NNNNNN.json``, ``fit/NNNNNN.ply`` and overlay images.

Overlay colours (thesis figures, chosen for colour-blind safety): model silhouette only
**blue**, image silhouette only **orange**, agreement **white**-ish grey; background pixels keep a
dimmed copy of the camera frame.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["OVERLAY_COLORS", "overlay_image", "write_frame_fit", "write_unfitted"]

#: RGB colours of the overlay classes.
OVERLAY_COLORS = {
    "model only": (0, 114, 178),
    "image only": (230, 159, 0),
    "agreement": (235, 235, 235),
}

def overlay_image(image: np.ndarray | None, model_mask: np.ndarray, observed_mask: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8: the frame dimmed, with model-only / image-only / agreement pixels coloured."""
    model_mask = np.asarray(model_mask, dtype=bool)
    observed_mask = np.asarray(observed_mask, dtype=bool)
    if image is None:
        out = np.full(model_mask.shape + (3,), 40, dtype=np.uint8)
    else:
        img = np.asarray(image)
        if img.dtype != np.uint8:
            img = (img.astype(np.float64) / max(float(img.max()), 1.0) * 255).astype(np.uint8)
        if img.ndim == 2:
            img = np.repeat(img[..., None], 3, axis=2)
        out = (img[..., :3].astype(np.float32) * 0.45).astype(np.uint8)
    for name, sel in (("agreement", model_mask & observed_mask), ("model only", model_mask & ~observed_mask),
                      ("image only", observed_mask & ~model_mask)):
        out[sel] = OVERLAY_COLORS[name]
    return out


def write_frame_fit(layout, fit, model, cameras, masks, images=None, run: dict | None = None) -> Path:
    """Write the mesh, one overlay per camera, then the JSON of one frame fit (the JSON last: it
    marks the frame complete; ``run`` records the settings a rerun compares). Returns the JSON path."""
    from rigs.atomic import atomic_write_json
    from rigs.imageio import write_image
    from studio.body import write_mesh
    from studio.render import silhouette

    layout.fit_dir.mkdir(parents=True, exist_ok=True)
    V = model.vertices(fit.shape, fit.pose)
    ply = layout.fit_ply(fit.frame)
    write_mesh(ply, V, model.faces)
    obj = fit.to_json()
    overlays = {}
    agree = {}
    for k, (cam, obs) in enumerate(zip(cameras, masks, strict=True)):
        sil = silhouette(cam, V, model.faces)
        img = None if images is None else images[k]
        p = layout.fit_overlay(cam.name, fit.frame)
        p.parent.mkdir(parents=True, exist_ok=True)
        write_image(p, overlay_image(img, sil, obs))
        overlays[cam.name] = str(p.relative_to(layout.fit_dir))
        inter = int(np.count_nonzero(sil & obs))
        agree[cam.name] = {
            "precision": inter / max(int(np.count_nonzero(sil)), 1),
            "recall": inter / max(int(np.count_nonzero(obs)), 1),
        }
    obj["overlays"] = overlays
    obj["silhouette_agreement"] = agree
    obj["mesh"] = ply.name
    if run is not None:
        obj["run"] = run
    return atomic_write_json(layout.fit_json(fit.frame), obj)


def write_unfitted(layout, error, run: dict | None = None) -> dict:
    """Write ``fit/NNNNNN.json`` of a frame the quality gates refused to fit
    (:class:`~studio.fit.errors.UnusableFrame` ``error``): its ``quality`` object (status
    ``failed``, the reasons) and no body, so no figure is ever read off it. Returns what it wrote."""
    from rigs.atomic import atomic_write_json

    layout.fit_dir.mkdir(parents=True, exist_ok=True)
    obj = {"format": "studio.fit", "version": 1, "frame": error.frame, "fitted": False, "quality": error.quality}
    if run is not None:
        obj["run"] = run
    atomic_write_json(layout.fit_json(error.frame), obj)
    return obj
