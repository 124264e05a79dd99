"""Segment every frame of a capture session (the driver behind ``studio segment``).

Output, inside the session folder::

    segmentation/
      segmentation.json             settings (each camera's registration shift, the code's digest), per-camera
                                    statistics and mask quality (person fraction, components,
                                    clutter = share of person pixels outside the largest
                                    component, static / ignored pixels relabelled background;
                                    per frame under ``frame_quality``), timings
      background/<cam>/             background model (mean.exr, std.exr, model.json) — fitted
                                    once from background/<cam>/ and reused
      skin_models/<cam>.npz         per-camera skin model (self-trained unless given)
      <cam>/NNNNNN.png              labels: 0 background, 1 person, 2 shadow (uint8)
      skin/<cam>/NNNNNN.png         skin mask (0 / 255) inside the person
      overlay/<cam>/NNNNNN.png      quick-look overlay (person blue, shadow red, skin orange)
      floor_votes/NNNNNN.png        shadow votes on the floor, top-down (fig. 5.4), 255 = all views

Before the frames: each background model is registered to the session (a camera nudged by a pixel
since the empty-scene capture: :mod:`studio.segment.registration`). Per frame: single-view
classification + morphology in each camera (§5.5.1), multi-view shadow
voting (with the photometric-consistency check of :mod:`studio.segment.voting`) when the session
has a calibration and ≥ 2 cameras (§5.5.2), then skin inside the person (§6.3.4).

Frames are independent units of work (:mod:`studio.execution`): run in this process, in local
worker processes or on a Dask cluster. The parent fits and saves the background and skin models
first; every worker (the parent too) then loads them from the output folder (shared storage),
so each runner labels every frame the same.
"""

from __future__ import annotations

import json
import logging
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from studio.segment.background import BackgroundModel
from studio.segment.classify import PERSON, SHADOW, Thresholds
from studio.segment.errors import SegmentationError
from studio.segment.morphology import STUDIO_MORPHOLOGY, Morphology, person_components
from studio.segment.preparation import background_model, floor_grid, registered, registration_shifts
from studio.segment.skin import SkinClassifier
from studio.segment.static import StaticChanges, absolute_spec, ignore_masks
from studio.segment.voting import FloorVotes, ShadowVoter

__all__ = ["SEGMENT_CODE", "SegmentOptions", "SegmentationSummary", "segment_session", "segmentation_code_digest"]

#: The code that decides a session's labels: part of the recorded settings, so frames labelled by
#: other code are labelled again rather than kept (labels a development version had written under
#: the same settings were once kept: two benchmark sessions fitted on masks without the bridges).
SEGMENT_CODE = ("studio.segment", "studio.fit.init")


def segmentation_code_digest() -> str:
    """Digest of :data:`SEGMENT_CODE` (:func:`studio.provenance.code_digest`)."""
    from studio.provenance import code_digest

    return code_digest(*SEGMENT_CODE)

log = logging.getLogger(__name__)

SUMMARY_FORMAT = "studio.segmentation"
SUMMARY_VERSION = 1
OVERLAY_COLORS = {PERSON: (40, 90, 255), SHADOW: (230, 30, 30)}
SKIN_COLOR = (255, 150, 0)


@dataclass(frozen=True)
class SegmentOptions:
    """Settings of :func:`segment_session` (None: keep the stored/default value)."""

    thresholds: Thresholds | None = None
    morphology: Morphology | None = None  # None: STUDIO_MORPHOLOGY (a stored model's own is replaced)
    refit_background: bool = False
    voting: bool = True
    skin: bool = True
    skin_model: Path | None = None  # one trained model for every camera
    skin_frames: int = 8  # frames per camera for self-training
    overlay_every: int = 1  # 0: no overlays
    floor_resolution: float = 0.02  # metres per cell of the floor vote image
    register: bool = True  # move each background model onto the session's frames (a nudged camera)
    largest_component: bool = False  # keep only the largest person component per view
    hull: bool = False  # drop person components the visual hull of all views does not explain
    bridges: bool = True  # with voting: shadow that splits a person mask, a solid to the other views, is person
    static_frames: int = 0  # > 0: static changes (a box put down) after this many frames: background
    ignore: tuple[str, ...] = ()  # user regions labelled background: "CAM=MASK.png" or a polygons JSON


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
    skipped: list[int] = field(default_factory=list)  # frames already done with the same settings


# ---------------------------------------------------------------------- worker state
_STATE: dict = {}


def _setup_state(state: dict) -> None:
    from rigs.session import Session
    from studio.workspace import Layout

    _STATE.clear()
    _STATE.update(state)
    _STATE["session"] = Session.open(state["path"])
    _STATE["layout"] = Layout(state["out"], source=state["path"])
    calib = state.get("calibration")
    _STATE["voter"] = ShadowVoter(calib, state["cameras"]) if calib is not None and state.get("voting", True) else None
    _STATE["hull_cameras"] = {c: calib[c] for c in state["cameras"]} if calib is not None and state.get("hull") else None
    _STATE["bridge_cameras"] = ({c: calib[c] for c in state["cameras"]}
                                if calib is not None and state.get("voting", True) and state.get("bridges") else None)
    _STATE["floor"] = calib.ground if calib is not None else None
    _STATE["changes"] = StaticChanges(state.get("ignore") or {}, int(state.get("static_frames", 0)))
    grid = state.get("grid")
    _STATE["floor_votes"] = (
        FloorVotes(calib, grid, state["cameras"]) if grid is not None and state["overlay_every"] > 0 else None
    )


def _load_state(spec: dict) -> dict:
    """The worker state of ``spec`` (built once per process from the saved models, then kept)."""
    from studio.workspace import Workspace

    if _STATE.get("token") == spec["token"]:
        return _STATE
    ws = Workspace.open(spec["path"], out=spec["out"])
    options = spec["options"]
    models = {cam: registered(BackgroundModel.load(ws.layout.background_model_dir(cam)).with_settings(
        options.thresholds, options.morphology), spec["registration"].get(cam)) for cam in ws.camera_names}
    skin_file = options.skin_model
    skin = {cam: SkinClassifier.load(skin_file if skin_file is not None else ws.layout.skin_model(cam))
            for cam in spec["skin_cameras"]}
    calib = ws.calibration if spec["voting"] or spec["hull"] else None
    _setup_state({"path": spec["path"], "out": spec["out"], "cameras": ws.camera_names, "models": models,
                  "largest_component": bool(options.largest_component), "voting": spec["voting"],
                  "bridges": bool(options.bridges),
                  "hull": spec["hull"], "static_frames": int(options.static_frames),
                  "ignore": ignore_masks(options.ignore, {c: models[c].shape for c in models}),
                  "calibration": calib, "overlay_every": int(options.overlay_every), "skin": skin,
                  "grid": floor_grid(calib, options.floor_resolution) if calib is not None else None})
    _STATE["token"] = spec["token"]
    return _STATE


def _segment_unit(spec: dict, index: int, previous=None) -> dict:
    """One frame as a unit of :func:`studio.execution.run_chains` (``previous`` unused: frames
    are independent)."""
    _load_state(spec)
    return _process_frame(index)


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
    changes = state["changes"](index, frame, labels)
    voter = state.get("voter")
    relabelled = {}
    if voter is not None:
        result = voter.vote(labels, ratios)
        labels, relabelled = result.labels, result.relabelled
    bridged = {}
    if state.get("bridge_cameras"):
        from studio.segment.bridges import shadow_bridges

        labels, bridged = shadow_bridges(labels, state["bridge_cameras"], plane=state["floor"])
    dropped = {}
    if state.get("hull_cameras"):
        from studio.segment.hull import hull_filter

        labels, dropped = hull_filter(labels, state["hull_cameras"])
    quality = {}
    for cam in state["cameras"]:
        labels[cam], quality[cam] = person_components(labels[cam], state.get("largest_component", False))
        if state.get("hull_cameras"):
            quality[cam]["hull_dropped"] = dropped.get(cam, 0)
        if state.get("bridge_cameras"):
            quality[cam]["bridged"] = bridged.get(cam, 0)
        if voter is not None:
            quality[cam]["relabelled"] = int(relabelled.get(cam, 0))
        quality[cam].update(changes.get(cam, {}))
    state["last_quality"] = quality
    return frame, labels, relabelled


def _fractions(labels) -> list[float]:
    return (np.bincount(labels.ravel(), minlength=3)[:3] / labels.size).tolist()


def _process_frame(index: int) -> dict:
    """Segment one multi-frame and write its outputs; the label images go last, so a frame whose
    labels exist for every camera is complete (every file is written atomically)."""
    from rigs.imageio import write_image

    state = _STATE
    lay = state["layout"]
    frame, labels, relabelled = _segment_frame(index, state)
    overlay = state["overlay_every"] > 0 and index % state["overlay_every"] == 0
    for cam in state["cameras"]:
        skin = None
        model = state["skin"].get(cam)
        if model is not None:
            skin = model.predict(frame[cam], labels[cam] == PERSON)
            write_image(lay.skin(cam, index), skin, compression=1)
        if overlay:
            write_image(lay.segmentation_overlay(cam, index), _overlay(frame[cam], labels[cam], skin))
    if overlay and state.get("floor_votes") is not None:
        votes = state["floor_votes"](labels)
        scaled = (votes.astype(np.uint16) * 255 // max(len(state["cameras"]), 1)).astype(np.uint8)
        write_image(lay.floor_votes(index), scaled)
    for cam in state["cameras"]:
        write_image(lay.labels(cam, index), labels[cam], compression=1)
    fractions = {cam: _fractions(labels[cam]) for cam in state["cameras"]}
    return {"index": index, "fractions": fractions, "relabelled": relabelled, "quality": state["last_quality"]}


# ---------------------------------------------------------------------- preparation
def _skin_models(ws, state: dict, frames: list[int], options: SegmentOptions) -> dict:
    cameras = state["cameras"]
    if not options.skin:
        return {}
    if options.skin_model is not None:
        model = SkinClassifier.load(options.skin_model)
        return {cam: model for cam in cameras}
    models = {}
    missing = []
    for cam in cameras:
        path = ws.layout.skin_model(cam)
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
        ws.layout.skin_model(cam).parent.mkdir(parents=True, exist_ok=True)
        models[cam].save(ws.layout.skin_model(cam))
    return models


def _open(source, out=None):
    from studio.workspace import Workspace, WorkspaceError

    if isinstance(source, Workspace):
        return source
    try:
        return Workspace.open(source, out=out)
    except WorkspaceError as exc:
        raise SegmentationError(str(exc)) from None


def _settings(models: dict, options: SegmentOptions, voting: bool, skin_cameras, registration: dict) -> dict:
    """What decides a frame's outputs (the code too): a frame done with other settings is done again."""
    first = next(iter(models.values()))
    return {
        "thresholds": first.thresholds.to_dict(),
        "morphology": {k: getattr(first.morphology, k) for k in
                       ("median", "open_radius", "close_radius", "min_area", "max_person_hole", "max_hole")},
        "voting": voting,
        "skin_cameras": sorted(skin_cameras),
        "skin_model": None if options.skin_model is None else str(options.skin_model),
        "overlay_every": int(options.overlay_every),
        "floor_resolution": float(options.floor_resolution),
        "registration": registration,
        "largest_component": bool(options.largest_component),
        "hull": bool(options.hull),
        "bridges": bool(options.bridges) and voting,
        "static_frames": int(options.static_frames),
        "ignore": [str(v) for v in options.ignore],
        "code": segmentation_code_digest(),
    }


def _previous_summary(ws) -> dict:
    """The ``segmentation.json`` a previous run left (finished or not), or {} without a readable one."""
    try:
        return json.loads(ws.layout.segmentation_summary.read_text())
    except (OSError, ValueError):
        return {}


def _done_frames(ws, frames: list[int], settings: dict, previous: dict) -> list[int]:
    """Frames whose labels exist for every camera, written with the same ``settings`` (the
    ``previous`` run's, :func:`_previous_summary`)."""
    if previous.get("settings") != settings:
        return []
    return [i for i in frames if all(ws.layout.labels(c, i).is_file() for c in ws.camera_names)]


def _kept_frame_quality(previous: dict, frames: list[int], cameras: list[str]) -> dict:
    """The per-frame quality the ``previous`` run recorded for ``frames`` ({"i": {camera: figures}};
    frames it has not for every camera of ``cameras`` are left out)."""
    stored = previous.get("frame_quality") or {}
    return {str(i): stored[str(i)] for i in frames
            if isinstance(stored.get(str(i)), dict) and all(c in stored[str(i)] for c in cameras)}


def segment_session(
    source,
    options: SegmentOptions = SegmentOptions(),
    *,
    frames: list[int] | None = None,
    workers: int = 1,
    scheduler: str | None = None,
    progress: Callable[[int, int], None] | None = None,
    force: bool = False,
    out: str | Path | None = None,
) -> SegmentationSummary:
    """Segment ``frames`` (default: all complete frames) of a session.

    ``source`` is a :class:`studio.workspace.Workspace` or a session folder (outputs then go
    to ``out``, default the session). Frames already segmented with the same settings (and
    code, :func:`segmentation_code_digest`) are skipped unless ``force``: a rerun after an
    interruption continues where it stopped, keeping what the skipped frames' run measured
    (``frame_quality``: voting relabels, bridges, hull).
    ``progress(done, total)`` is called after each frame. The frames run in this process
    (``workers`` 1), in ``workers`` local processes, or on the Dask cluster ``scheduler``
    (:func:`studio.execution.open_runner`). Raises :class:`SegmentationError`
    for a camera without background frames, image sizes that disagree with the background
    model or the calibration, and a missing calibration when voting is requested.
    """
    from rigs.atomic import atomic_write_json
    from rigs.imageio import read_image
    from studio.execution import ExecutionError, open_runner, run_chains
    from studio.workspace import SEGMENTATION_RESERVED, WorkspaceError

    t0 = time.perf_counter()
    ws = _open(source, out)
    options = replace(options, morphology=options.morphology or STUDIO_MORPHOLOGY)
    cameras = ws.camera_names
    bad = sorted(SEGMENTATION_RESERVED & set(cameras))
    if bad:
        raise SegmentationError(f"session {ws.path}: camera names {bad} clash with output folders")
    frames = list(ws.frame_indices if frames is None else frames)
    if not frames:
        raise SegmentationError(f"session {ws.path}: no complete frames to segment")
    try:
        ws.check_frames(frames)
        ws.check_writable(ws.layout.segmentation_dir)
    except WorkspaceError as exc:
        raise SegmentationError(str(exc)) from None
    models = {cam: background_model(ws, cam, options) for cam in cameras}
    registration = registration_shifts(ws, models, frames, options)
    models = {cam: registered(m, registration.get(cam)) for cam, m in models.items()}
    voting = options.voting and len(cameras) >= 2
    hull = options.hull and len(cameras) >= 2
    try:
        calib = ws.require_calibration("multi-view shadow voting (or segment with --no-voting)") if voting else None
        if hull and calib is None:
            calib = ws.require_calibration("the visual-hull check of the masks (--hull)")
    except WorkspaceError as exc:
        raise SegmentationError(str(exc)) from None
    state = {"path": str(ws.path), "out": str(ws.layout.root), "cameras": cameras, "models": models,
             "calibration": calib, "voting": voting, "hull": hull, "bridges": bool(options.bridges),
             "overlay_every": int(options.overlay_every),
             "grid": floor_grid(calib, options.floor_resolution) if calib is not None else None, "skin": {},
             "largest_component": bool(options.largest_component), "static_frames": int(options.static_frames),
             "ignore": ignore_masks(options.ignore, {c: m.shape for c, m in models.items()})}  # fmt: skip
    _setup_state(state)
    state["skin"] = _skin_models(ws, _STATE, frames, options)
    # workers elsewhere read a given skin model by its absolute path
    unit_options = options if options.skin_model is None else replace(options, skin_model=Path(options.skin_model).resolve())
    unit_options = replace(unit_options, ignore=tuple(absolute_spec(v) for v in options.ignore))
    spec = {"token": uuid.uuid4().hex, "path": str(ws.path), "out": str(ws.layout.root), "options": unit_options,
            "voting": voting, "hull": hull, "skin_cameras": sorted(state["skin"]), "registration": registration}
    settings = _settings(models, options, voting, state["skin"], registration)
    # persistence needs every frame from the first: with static changes nothing is kept
    previous = {} if force or options.static_frames > 0 else _previous_summary(ws)
    skipped = _done_frames(ws, frames, settings, previous)
    todo = [i for i in frames if i not in set(skipped)]
    summary = {
        "format": SUMMARY_FORMAT,
        "version": SUMMARY_VERSION,
        "cameras": cameras,
        "frames": frames,
        "labels": {"0": "background", "1": "person", "2": "shadow"},
        "settings": settings,
        "thresholds": settings["thresholds"],
        "voting": voting,
        "skin_cameras": sorted(state["skin"]),
        "status": "running",
    }
    # what the skipped frames' run measured (voting, bridges, hull), kept in the summary from the start
    kept_quality = _kept_frame_quality(previous, skipped, cameras)
    summary["frame_quality"] = kept_quality
    # the settings go down first: a rerun after a kill knows which finished frames it may keep
    atomic_write_json(ws.layout.segmentation_summary, summary, fsync=False)
    folders = [ws.layout.labels(cam, 0).parent for cam in cameras]
    folders += [ws.layout.skin(cam, 0).parent for cam in cameras if cam in state["skin"]]
    if options.overlay_every > 0:
        folders += [ws.layout.segmentation_overlay(cam, 0).parent for cam in cameras]
        folders += [ws.layout.floor_votes(0).parent] if state["grid"] is not None else []
    for folder in folders:  # (check_writable cleared the temporary files a killed run's writers left)
        folder.mkdir(parents=True, exist_ok=True)

    results = []
    for i in skipped:
        stored = {c: read_image(ws.layout.labels(c, i)) for c in cameras}
        quality = kept_quality.get(str(i)) or {c: person_components(v)[1] for c, v in stored.items()}
        results.append({"index": i, "relabelled": {c: q.get("relabelled", 0) for c, q in quality.items()},
                        "fractions": {c: _fractions(v) for c, v in stored.items()}, "quality": quality})
    total = len(frames)
    if skipped:
        log.info("%d of %d frame(s) already segmented with the same settings: skipped (--force redoes them)",
                 len(skipped), total)
        if progress:
            progress(len(results), total)
    try:
        # static changes need the frames in order in one process: one chain
        chains = [todo] if options.static_frames > 0 else [[i] for i in todo]
        with open_runner(workers if len(chains) > 1 else 1, scheduler) as runner:
            for chain in run_chains(runner, _segment_unit, chains, spec=spec, progress=progress,
                                    done=len(results), total=total):
                results.extend(chain)
    except ExecutionError as exc:
        raise SegmentationError(str(exc)) from None
    seconds = time.perf_counter() - t0
    fractions = {
        cam: dict(zip(("background", "person", "shadow"), np.mean([r["fractions"][cam] for r in results], axis=0).tolist()))
        for cam in cameras
    }
    relabelled = {cam: int(sum(r["relabelled"].get(cam, 0) for r in results)) for cam in cameras}
    quality = {cam: {"person_fraction_mean": float(np.mean([r["quality"][cam]["person_fraction"] for r in results])),
                     "clutter_mean": float(np.mean([r["quality"][cam]["clutter"] for r in results])),
                     "clutter_max": float(np.max([r["quality"][cam]["clutter"] for r in results]))} for cam in cameras}
    for cam in cameras:
        for key in ("static", "ignored"):
            values = [r["quality"][cam][key] for r in results if key in r["quality"][cam]]
            if values:
                quality[cam][f"{key}_mean"] = float(np.mean(values))
    summary.update(status="complete", skipped=skipped, mean_fractions=fractions, relabelled_by_voting=relabelled,
                   seconds=round(seconds, 3), quality=quality,
                   frame_quality={str(r["index"]): r["quality"] for r in sorted(results, key=lambda r: r["index"])})
    atomic_write_json(ws.layout.segmentation_summary, summary, fsync=False)
    return SegmentationSummary(
        path=ws.layout.root,
        cameras=cameras,
        frames=frames,
        voting=voting,
        skin_cameras=sorted(state["skin"]),
        seconds=seconds,
        fractions=fractions,
        relabelled=relabelled,
        skipped=skipped,
    )
