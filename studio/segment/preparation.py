"""What a session's segmentation starts from (:func:`studio.segment.session.segment_session`): each
camera's empty-scene model, its registration onto the session's frames (a camera nudged since the
empty scene), and the floor grid of the vote images."""

from __future__ import annotations

import logging

import numpy as np

from studio.segment.background import BackgroundModel
from studio.segment.errors import SegmentationError

__all__ = ["background_model", "floor_grid", "registered", "registration_shifts"]

log = logging.getLogger("studio.segment.session")


def background_model(ws, cam: str, options) -> BackgroundModel:
    """Camera ``cam``'s empty-scene model: loaded from the session's output, or fitted on its
    background frames and saved (``options``: :class:`~studio.segment.session.SegmentOptions`)."""
    session = ws.session
    folder = ws.layout.background_model_dir(cam)
    model = None
    if (folder / "model.json").is_file() and not options.refit_background:
        model = BackgroundModel.load(folder)
        log.info("camera %s: background model loaded from %s", cam, folder)
    else:
        indices = session.background_indices(cam)
        if not indices:
            raise SegmentationError(
                f"session {session.path}: camera {cam!r} has no empty-scene frames in "
                f"background/{cam}/ (capture a few frames of the empty scene first)"
            )
        model = BackgroundModel.fit(session.backgrounds(cam))
        model = model.with_settings(options.thresholds, options.morphology)
        model.save(folder)
        log.info("camera %s: background model fitted on %d frames", cam, len(indices))
    model = model.with_settings(options.thresholds, options.morphology)
    w, h = session.image_size(cam)
    if model.shape != (h, w):
        raise SegmentationError(
            f"{folder}: the background model is {model.shape[1]}x{model.shape[0]}, camera {cam!r}'s "
            f"frames are {w}x{h} (refit it with --refit-background)"
        )
    return model


def registered(model: BackgroundModel, shift) -> BackgroundModel:
    """``model`` moved by ``shift`` ([dx, dy] px; none or zero: ``model`` itself)."""
    return model if not shift or (shift[0] == 0 and shift[1] == 0) else model.shifted(*shift)


def registration_shifts(ws, models: dict, frames: list[int], options, count: int = 5) -> dict:
    """Per camera ``[dx, dy]`` by which the session's frames are moved against the empty scene
    (median over ``count`` frames spread over the session, to 0.1 px; shifts under 0.25 px are
    noise: 0)."""
    if not options.register:
        return {}
    sample = sorted({frames[int(i)] for i in np.linspace(0, len(frames) - 1, min(count, len(frames))).round()})
    images = [ws.session.frame(i) for i in sample]
    out = {}
    for cam, model in models.items():
        dx, dy = model.estimate_shift([im[cam] for im in images])
        # to 0.1 px: a rerun on another selection of frames keeps the same settings (and its frames)
        out[cam] = [round(dx, 1), round(dy, 1)] if np.hypot(dx, dy) >= 0.25 else [0.0, 0.0]
        if out[cam] != [0.0, 0.0]:
            log.info("camera %s: frames moved by (%.2f, %.2f) px against the empty scene: model registered",
                     cam, *out[cam])
    return out


def floor_grid(calib, resolution: float):
    """The floor grid of the vote images: the cameras' footprint on the floor, padded."""
    from calibration import FloorGrid

    centres = np.array([calib[c].center for c in calib.camera_names])
    xy = calib.ground.to_plane_coords(centres)
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    pad = 0.1 * float(np.max(hi - lo)) + 0.5
    return FloorGrid((lo[0] - pad, hi[0] + pad), (lo[1] - pad, hi[1] + pad), resolution)
