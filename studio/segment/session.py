"""Segment every frame of a capture session (the driver behind ``studio segment``).

Output, inside the session folder::

    segmentation/
      segmentation.json             settings, per-camera statistics, timings
      background/<cam>/             background model (mean.exr, std.exr, model.json) — fitted
                                    once from background/<cam>/ and reused
      skin_models/<cam>.npz         per-camera skin model (self-trained unless given)
      <cam>/NNNNNN.png              labels: 0 background, 1 person, 2 shadow (uint8)
      skin/<cam>/NNNNNN.png         skin mask (0 / 255) inside the person
      overlay/<cam>/NNNNNN.png      quick-look overlay (person blue, shadow red, skin orange)
      floor_votes/NNNNNN.png        shadow votes on the floor, top-down (fig. 5.4), 255 = all views

Per frame: single-view classification + morphology in each camera (§5.5.1), multi-view shadow
voting (with the photometric-consistency check of :mod:`studio.segment.voting`) when the session
has a calibration and ≥ 2 cameras (§5.5.2), then skin inside the person (§6.3.4). Frames are independent and processed in parallel worker processes.
"""

from __future__ import annotations

import json
import logging
import multiprocessing
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from studio.blas import limit_blas_threads
from studio.segment.background import BackgroundModel
from studio.segment.classify import PERSON, SHADOW, Thresholds
from studio.segment.errors import SegmentationError
from studio.segment.morphology import Morphology
from studio.segment.skin import SkinClassifier
from studio.segment.voting import FloorVotes, ShadowVoter

__all__ = ["SegmentOptions", "SegmentationSummary", "segment_session", "SEGMENTATION_DIR", "label_path"]

log = logging.getLogger(__name__)

SEGMENTATION_DIR = "segmentation"
SUMMARY_FORMAT = "studio.segmentation"
SUMMARY_VERSION = 1
RESERVED = {"background", "skin", "skin_models", "overlay", "floor_votes"}
OVERLAY_COLORS = {PERSON: (40, 90, 255), SHADOW: (230, 30, 30)}
SKIN_COLOR = (255, 150, 0)


def label_path(session_path: Path, camera: str, index: int) -> Path:
    """Path of the label image of ``camera`` / frame ``index``."""
    return Path(session_path) / SEGMENTATION_DIR / camera / f"{index:06d}.png"


@dataclass(frozen=True)
class SegmentOptions:
    """Settings of :func:`segment_session` (None: keep the stored/default value)."""

    thresholds: Thresholds | None = None
    morphology: Morphology | None = None
    refit_background: bool = False
    voting: bool = True
    skin: bool = True
    skin_model: Path | None = None  # one trained model for every camera
    skin_frames: int = 8  # frames per camera for self-training
    overlay_every: int = 1  # 0: no overlays
    floor_resolution: float = 0.02  # metres per cell of the floor vote image


@dataclass(frozen=True)
class SegmentationSummary:
    """What :func:`segment_session` did."""

    path: Path
    cameras: list[str]
    frames: list[int]
    voting: bool
    skin_cameras: list[str]
    seconds: float
    fractions: dict[str, dict[str, float]] = field(default_factory=dict)
    relabelled: dict[str, int] = field(default_factory=dict)


# ---------------------------------------------------------------------- worker state
_STATE: dict = {}


def _init_worker(state: dict) -> None:
    cv2.setNumThreads(1)
    limit_blas_threads()  # one process per core: BLAS threads would only compete (studio.blas)
    _setup_state(state)


def _setup_state(state: dict) -> None:
    from rigs.session import Session

    _STATE.clear()
    _STATE.update(state)
    _STATE["session"] = Session.open(state["path"])
    calib = state.get("calibration")
    _STATE["voter"] = ShadowVoter(calib, state["cameras"]) if calib is not None else None
    grid = state.get("grid")
    _STATE["floor_votes"] = (
        FloorVotes(calib, grid, state["cameras"]) if grid is not None and state["overlay_every"] > 0 else None
    )


def _overlay(image: np.ndarray, labels: np.ndarray, skin: np.ndarray | None) -> np.ndarray:
    rgb = image if image.dtype == np.uint8 else (image >> 8).astype(np.uint8)
    out = rgb.copy()
    for value, color in OVERLAY_COLORS.items():
        m = labels == value
        out[m] = (0.5 * out[m] + 0.5 * np.asarray(color)).astype(np.uint8)
    if skin is not None:
        out[skin] = (0.4 * out[skin] + 0.6 * np.asarray(SKIN_COLOR)).astype(np.uint8)
    return out


def _segment_frame(index: int, state: dict) -> tuple[dict, dict, dict]:
    """(images, voted labels, pixels relabelled by voting) of one multi-frame."""
    session = state["session"]
    frame = session.frame(index)
    labels, ratios = {}, {}
    for cam in state["cameras"]:
        labels[cam], ratios[cam] = state["models"][cam].analyse(frame[cam], name=f"camera {cam!r} frame {index}")
    voter = state.get("voter")
    relabelled = {}
    if voter is not None:
        result = voter.vote(labels, ratios)
        labels, relabelled = result.labels, result.relabelled
    return frame, labels, relabelled


def _process_frame(index: int) -> dict:
    from rigs.imageio import write_image

    state = _STATE
    root = Path(state["path"]) / SEGMENTATION_DIR
    frame, labels, relabelled = _segment_frame(index, state)
    overlay = state["overlay_every"] > 0 and index % state["overlay_every"] == 0
    fractions = {}
    for cam in state["cameras"]:
        lab = labels[cam]
        write_image(root / cam / f"{index:06d}.png", lab, compression=1)
        skin = None
        model = state["skin"].get(cam)
        if model is not None:
            skin = model.predict(frame[cam], lab == PERSON)
            write_image(root / "skin" / cam / f"{index:06d}.png", skin, compression=1)
        if overlay:
            write_image(root / "overlay" / cam / f"{index:06d}.png", _overlay(frame[cam], lab, skin))
        counts = np.bincount(lab.ravel(), minlength=3)[:3] / lab.size
        fractions[cam] = counts.tolist()
    if overlay and state.get("floor_votes") is not None:
        votes = state["floor_votes"](labels)
        scaled = (votes.astype(np.uint16) * 255 // max(len(state["cameras"]), 1)).astype(np.uint8)
        write_image(root / "floor_votes" / f"{index:06d}.png", scaled)
    return {"index": index, "fractions": fractions, "relabelled": relabelled}


# ---------------------------------------------------------------------- preparation
def _load_calibration(session, cameras: list[str]):
    from calibration import RigCalibration

    if session.calibration_path is None:
        raise SegmentationError(
            f"session {session.path}: no calibration.json, needed for multi-view shadow voting "
            "(calibrate the rig, or segment with --no-voting)"
        )
    calib = RigCalibration.load(session.calibration_path)
    for cam in cameras:
        if cam not in calib:
            raise SegmentationError(
                f"{session.calibration_path}: camera {cam!r} of the session is not calibrated"
            )
        size = tuple(session.image_size(cam))
        if tuple(calib[cam].size) != size:
            raise SegmentationError(
                f"{session.calibration_path}: camera {cam!r} is calibrated for "
                f"{calib[cam].size[0]}x{calib[cam].size[1]} images, the session's are {size[0]}x{size[1]}"
            )
    return calib


def _background_model(session, cam: str, options: SegmentOptions) -> BackgroundModel:
    folder = session.path / SEGMENTATION_DIR / "background" / cam
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


def _floor_grid(calib, resolution: float):
    from calibration import FloorGrid

    centres = np.array([calib[c].center for c in calib.camera_names])
    xy = calib.ground.to_plane_coords(centres)
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    pad = 0.1 * float(np.max(hi - lo)) + 0.5
    return FloorGrid((lo[0] - pad, hi[0] + pad), (lo[1] - pad, hi[1] + pad), resolution)


def _skin_models(session, state: dict, frames: list[int], options: SegmentOptions) -> dict:
    cameras = state["cameras"]
    if not options.skin:
        return {}
    if options.skin_model is not None:
        model = SkinClassifier.load(options.skin_model)
        return {cam: model for cam in cameras}
    folder = session.path / SEGMENTATION_DIR / "skin_models"
    models = {}
    missing = []
    for cam in cameras:
        path = folder / f"{cam}.npz"
        if path.is_file() and not options.refit_background:
            models[cam] = SkinClassifier.load(path)
        else:
            missing.append(cam)
    if not missing:
        return models
    count = max(1, min(options.skin_frames, len(frames)))
    sample = [frames[int(i)] for i in np.linspace(0, len(frames) - 1, count).round()]
    images = {cam: [] for cam in missing}
    persons = {cam: [] for cam in missing}
    for index in sample:
        frame, labels, _ = _segment_frame(index, state)
        for cam in missing:
            images[cam].append(frame[cam])
            persons[cam].append(labels[cam] == PERSON)
    for cam in missing:
        try:
            models[cam] = SkinClassifier().self_train(images[cam], persons[cam])
        except SegmentationError as exc:
            log.warning("camera %s: no skin model (%s)", cam, exc)
            continue
        models[cam].save(folder / f"{cam}.npz")
    return models


def segment_session(
    path: str | Path,
    options: SegmentOptions = SegmentOptions(),
    *,
    frames: list[int] | None = None,
    workers: int = 1,
    progress: Callable[[int, int], None] | None = None,
) -> SegmentationSummary:
    """Segment ``frames`` (default: all complete frames) of the session at ``path``.

    ``progress(done, total)`` is called after each frame. Raises :class:`SegmentationError`
    for a camera without background frames, image sizes that disagree with the background
    model or the calibration, and a missing calibration when voting is requested.
    """
    from rigs.imageio import atomic_write_json
    from rigs.session import Session

    t0 = time.perf_counter()
    session = Session.open(path)
    cameras = list(session.cameras)
    bad = sorted(RESERVED & set(cameras))
    if bad:
        raise SegmentationError(f"session {session.path}: camera names {bad} clash with output folders")
    frames = list(session.frame_indices if frames is None else frames)
    if not frames:
        raise SegmentationError(f"session {session.path}: no complete frames to segment")
    for index in frames:
        if index not in session.frame_indices:
            raise SegmentationError(f"session {session.path}: frame {index} is not a complete frame")
    models = {cam: _background_model(session, cam, options) for cam in cameras}
    voting = options.voting and len(cameras) >= 2
    calib = _load_calibration(session, cameras) if voting else None
    state = {
        "path": str(session.path),
        "cameras": cameras,
        "models": models,
        "calibration": calib,
        "overlay_every": int(options.overlay_every),
        "grid": _floor_grid(calib, options.floor_resolution) if calib is not None else None,
        "skin": {},
    }
    _setup_state(state)
    state["skin"] = _skin_models(session, _STATE, frames, options)
    _STATE["skin"] = state["skin"]

    root = session.path / SEGMENTATION_DIR
    for cam in cameras:
        (root / cam).mkdir(parents=True, exist_ok=True)
        if cam in state["skin"]:
            (root / "skin" / cam).mkdir(parents=True, exist_ok=True)
        if options.overlay_every > 0:
            (root / "overlay" / cam).mkdir(parents=True, exist_ok=True)
    if options.overlay_every > 0 and state["grid"] is not None:
        (root / "floor_votes").mkdir(parents=True, exist_ok=True)

    results = []
    total = len(frames)
    if workers <= 1:
        for i, index in enumerate(frames):
            results.append(_process_frame(index))
            if progress:
                progress(i + 1, total)
    else:
        # "spawn": a forked child inherits OpenCV's thread pool in an unusable state and hangs
        context = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(
            workers, mp_context=context, initializer=_init_worker, initargs=(state,)
        ) as pool:
            for i, result in enumerate(pool.map(_process_frame, frames, chunksize=2)):
                results.append(result)
                if progress:
                    progress(i + 1, total)
    seconds = time.perf_counter() - t0
    fractions = {
        cam: dict(zip(("background", "person", "shadow"), np.mean([r["fractions"][cam] for r in results], axis=0).tolist()))
        for cam in cameras
    }
    relabelled = {cam: int(sum(r["relabelled"].get(cam, 0) for r in results)) for cam in cameras}
    first = next(iter(models.values()))
    atomic_write_json(
        session.path / SEGMENTATION_DIR / "segmentation.json",
        {
            "format": SUMMARY_FORMAT,
            "version": SUMMARY_VERSION,
            "cameras": cameras,
            "frames": frames,
            "labels": {"0": "background", "1": "person", "2": "shadow"},
            "thresholds": first.thresholds.to_dict(),
            "voting": voting,
            "skin_cameras": sorted(state["skin"]),
            "mean_fractions": fractions,
            "relabelled_by_voting": relabelled,
            "seconds": round(seconds, 3),
        },
        fsync=False,
    )
    return SegmentationSummary(
        path=session.path,
        cameras=cameras,
        frames=frames,
        voting=voting,
        skin_cameras=sorted(state["skin"]),
        seconds=seconds,
        fractions=fractions,
        relabelled=relabelled,
    )

