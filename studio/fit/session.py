"""Fitting a capture session: frames in parallel processes, shape shared (thesis §4.7, §4.8.6).

Plan of :func:`fit_session`:

1. The **key frame** (the first requested frame) is fitted from the silhouettes alone with the
   shape free (and the gender chosen by fitting both models when ``gender="auto"``, §4.7.2).
2. Its shape **starts** every other frame's fit (one person per session); each frame refines
   it, and the session's shape is the mean of the per-frame estimates (their spread is the
   measurement spread of §4.8.6). The remaining frames are cut into ``workers`` contiguous chunks fitted in parallel processes. The first
   frame of a chunk is initialised from its silhouettes like the key frame (a broad
   particle-filter search, with the key frame's pose as one more start); each next frame of
   the chunk starts from the previous frame's pose with a smaller spread (tracking) when at
   most ``MAX_TRACK_GAP`` frames apart — otherwise a broad search with the previous pose as a
   hint — and is searched again from the silhouettes when tracking ends with a cost above
   ``RECOVERY_FACTOR`` × the key frame's cost.
3. Each frame writes ``fit/NNNNNN.json`` (shape, pose, per-term costs, joints, timings,
   settings), ``fit/NNNNNN.ply`` and ``fit/overlay/<cam>/NNNNNN.png``; the session summary is
   ``fit/sequence.json``.
"""

from __future__ import annotations

import json
import logging
import multiprocessing
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from studio.fit.errors import FitError
from studio.fit.frame import FitOptions, FrameFit, fit_frame, fit_frame_gender
from studio.fit.output import FIT_DIR, write_frame_fit

__all__ = ["SessionInputs", "fit_session", "load_fits", "load_inputs", "observed_masks"]

log = logging.getLogger(__name__)

PERSON_LABEL = 1
#: Frames further apart than this are not tracked (broad search, previous pose as a hint).
MAX_TRACK_GAP = 2
#: A tracked frame costing more than this × the key frame's cost is searched again.
RECOVERY_FACTOR = 3.0


class SessionInputs:
    """A session opened for fitting: cameras (calibration order = session order) and label paths."""

    def __init__(self, path: str | Path):
        from calibration import RigCalibration
        from rigs.session import Session

        path = Path(path)
        if not path.is_dir():
            raise FitError(f"{path}: no such session folder")
        self.session = Session.open(path)
        self.path = self.session.path
        calib_path = self.path / "calibration.json"
        if not calib_path.is_file():
            raise FitError(f"{self.path}: no calibration.json — calibrate the rig first (`studio calibrate ...`) "
                           "and copy its calibration.json into the session")
        calib = RigCalibration.load(calib_path)
        names = {c.name: c for c in calib}
        missing = [c for c in self.session.cameras if c not in names]
        if missing:
            raise FitError(f"{calib_path}: no calibration for cameras {missing}")
        self.cameras = [names[c] for c in self.session.cameras]
        seg = self.path / "segmentation"
        if not seg.is_dir():
            raise FitError(f"{self.path}: no segmentation/ folder — run `studio segment {self.path}` first")

    @property
    def frame_indices(self) -> list[int]:
        return list(self.session.frame_indices)

    def label_path(self, camera: str, frame: int) -> Path:
        return self.path / "segmentation" / camera / f"{frame:06d}.png"

    def check_frames(self, frames: list[int]) -> None:
        for f in frames:
            if f not in self.session.frame_indices:
                raise FitError(f"{self.path}: frame {f} is not a complete frame of the session")
            for cam in self.cameras:
                if not self.label_path(cam.name, f).is_file():
                    raise FitError(f"{self.label_path(cam.name, f)}: missing segmentation of frame {f} — "
                                   f"run `studio segment {self.path}` first")


def observed_masks(inputs: SessionInputs, frame: int) -> list[np.ndarray]:
    """Person silhouettes (H, W) bool of ``frame`` in camera order (label 1 of the segmentation)."""
    from rigs.imageio import read_image

    out = []
    for cam in inputs.cameras:
        lab = read_image(inputs.label_path(cam.name, frame))
        if lab.ndim == 3:
            lab = lab[..., 0]
        out.append(lab == PERSON_LABEL)
    return out


def load_inputs(path) -> SessionInputs:
    return SessionInputs(path)


def _fit_chunk(job: dict) -> list[dict]:
    """Worker: fit consecutive frames (the first from a broad search), write results."""
    from studio.body import BodyModel

    inputs = SessionInputs(job["path"])
    model = BodyModel.load(job["gender"])
    options = FitOptions(**{k: tuple(v) if isinstance(v, list) else v for k, v in job["options"].items()})
    shape = np.asarray(job["shape"], float)
    prev, prev_frame = None, None
    out = []
    for frame in job["frames"]:
        masks = observed_masks(inputs, frame)
        track = prev is not None and abs(frame - prev_frame) <= MAX_TRACK_GAP
        hint = prev if prev is not None else job.get("hint_pose")
        fit = fit_frame(model, inputs.cameras, masks, frame=frame, shape=shape,
                        previous_pose=prev if track else None, hint_pose=None if track else hint,
                        options=options, seed=job["seed"] + frame)
        if track and fit.costs["total"] > RECOVERY_FACTOR * job["key_cost"]:
            # tracking lost the body: search again from the silhouettes, keep the better fit
            log.info("frame %d: tracking cost %.2f, re-initialising from the silhouettes", frame, fit.costs["total"])
            again = fit_frame(model, inputs.cameras, masks, frame=frame, shape=shape, hint_pose=prev,
                              options=options, seed=job["seed"] + frame + 1)
            if again.costs["total"] < fit.costs["total"]:
                fit = again
        images = _images(inputs, frame)
        write_frame_fit(inputs.path, fit, model, inputs.cameras, masks, images)
        prev, prev_frame = fit.pose, frame
        out.append(fit.to_json())
    return out


def _images(inputs: SessionInputs, frame: int):
    try:
        imgs = inputs.session.frame(frame)
        return [imgs[c.name] for c in inputs.cameras]
    except Exception as exc:  # noqa: BLE001 - overlays fall back to a grey background
        log.warning("frame %d: no camera images for the overlays (%s)", frame, exc)
        return None


def fit_session(
    path,
    *,
    frames: list[int] | None = None,
    gender: str = "auto",
    workers: int = 1,
    options: FitOptions = FitOptions(),
    seed: int = 0,
    progress: Callable[[int, int], None] | None = None,
) -> dict:
    """Fit ``frames`` (default all) of the session at ``path``; returns the summary dict
    (also written to ``fit/sequence.json``)."""
    from rigs.imageio import atomic_write_json
    from studio.body import GENDERS, BodyModel

    if gender != "auto" and gender not in GENDERS:
        raise FitError(f"gender: expected 'auto' or one of {', '.join(GENDERS)}, got {gender!r}")
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise FitError(f"workers: expected an integer >= 1, got {workers!r}")
    inputs = SessionInputs(path)
    frames = inputs.frame_indices if frames is None else [int(f) for f in frames]
    if not frames:
        raise FitError(f"{inputs.path}: no frames to fit")
    inputs.check_frames(frames)
    t0 = time.perf_counter()
    total = len(frames)
    # 1. key frame: shape free, gender chosen
    key = frames[0]
    masks = observed_masks(inputs, key)
    key_fit = fit_frame_gender(inputs.cameras, masks, gender, frame=key, options=options, seed=seed + key)
    model = BodyModel.load(key_fit.gender)
    write_frame_fit(inputs.path, key_fit, model, inputs.cameras, masks, _images(inputs, key))
    results = {key: key_fit.to_json()}
    if progress:
        progress(1, total)
    # 2. other frames, shape held, in contiguous chunks
    rest = frames[1:]
    n_chunks = max(1, min(workers, len(rest)))
    chunks = [list(c) for c in np.array_split(np.asarray(rest, dtype=int), n_chunks) if len(c)]
    held = options
    jobs = [{"path": str(inputs.path), "gender": key_fit.gender, "shape": key_fit.shape.tolist(),
             "frames": [int(f) for f in c], "options": held.to_dict(), "seed": int(seed),
             "hint_pose": key_fit.pose.tolist(), "key_cost": float(key_fit.costs["total"])} for c in chunks]
    done = 1
    if jobs:
        if workers <= 1 or len(jobs) == 1:
            for job in jobs:
                for r in _fit_chunk(job):
                    results[r["frame"]] = r
                    done += 1
                    if progress:
                        progress(done, total)
        else:
            ctx = multiprocessing.get_context("spawn")
            with ProcessPoolExecutor(len(jobs), mp_context=ctx) as pool:
                futures = [pool.submit(_fit_chunk, job) for job in jobs]
                for fut in futures:
                    for r in fut.result():
                        results[r["frame"]] = r
                        done += 1
                        if progress:
                            progress(done, total)
    summary = {
        "format": "studio.fit-sequence",
        "version": 1,
        "gender": key_fit.gender,
        "gender_costs": key_fit.costs.get("gender_costs"),
        "key_shape": key_fit.shape.tolist(),
        "shape": np.mean([results[f]["shape"] for f in results], axis=0).tolist(),
        "key_frame": key,
        "frames": sorted(results),
        "costs": {str(f): results[f]["costs"]["total"] for f in sorted(results)},
        "workers": workers,
        "wall_time": round(time.perf_counter() - t0, 3),
        "settings": options.to_dict(),
        "shape_strategy": "key frame fitted first; every other frame refines the key shape; session shape = mean over frames",
    }
    atomic_write_json(inputs.path / FIT_DIR / "sequence.json", summary)
    return summary


def load_fits(path, frames: list[int] | None = None) -> dict[int, FrameFit]:
    """The ``fit/NNNNNN.json`` results of a session, by frame: ``frames``, or those of the last
    :func:`fit_session` run (``fit/sequence.json``), or else every result in the folder."""
    root = Path(path) / FIT_DIR
    if not root.is_dir():
        raise FitError(f"{path}: no fit/ folder — run `studio fit {path}` first")
    if frames is None and (root / "sequence.json").is_file():
        frames = json.loads((root / "sequence.json").read_text()).get("frames")
    out = {}
    for p in sorted(root.glob("[0-9]*.json")):
        if frames is None or int(p.stem) in frames:
            out[int(p.stem)] = FrameFit.from_json(json.loads(p.read_text()))
    if not out:
        raise FitError(f"{root}: no fitted frames — run `studio fit {path}` first")
    return out
