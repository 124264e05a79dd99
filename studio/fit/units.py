"""The unit of work of a session fit: one frame, run by any worker (:mod:`studio.execution`).

A unit reads what it needs from the session folder (calibration, the frame's segmentation and
images), fits the frame with :func:`studio.fit.frame.fit_frame` / ``fit_frame_gender`` and
writes ``fit/NNNNNN.ply``, the overlays and ``fit/NNNNNN.json`` (last, atomically) through the
workspace's layout. It returns a small **chain state** the next frame of its chain starts from:

``{"frame", "record" (the JSON written), "gender", "pose", "pose_frame", "shape", "ref_cost"}``

where ``pose`` / ``pose_frame`` are the last fitted pose of the chain and its frame (kept across
a refused frame), ``shape`` the chain's starting shape (its first fitted frame's) and
``ref_cost`` that frame's total cost. A chain's first frame (no previous pose) is fitted from its
silhouettes with the shape free — the **key frame** of the session is the first fitted frame of
the first chain — and each next frame within ``MAX_TRACK_GAP`` frames is tracked from the
previous pose, searched again from the silhouettes when tracking ends above
``RECOVERY_FACTOR`` × the chain's reference cost. Frames further apart get a broad search with
the previous pose as a hint.

A unit whose ``fit/NNNNNN.json`` exists with the same ``run`` settings returns the stored result
without fitting: a rerun (or Dask running a lost worker's unit again) continues where the work
stopped, with the same results as an uninterrupted run (the state is rebuilt from the JSON,
whose floats round-trip exactly).
"""

from __future__ import annotations

import hashlib
import json
import logging

import numpy as np

from studio.fit.errors import FitError, UnusableFrame
from studio.fit.frame import fit_frame, fit_frame_gender

__all__ = ["FIT_CODE", "FRAME_FIT_EXCLUDES", "MAX_TRACK_GAP", "RECOVERY_FACTOR", "chain_state", "fit_code_digest",
           "fit_unit", "frame_fit_code_digest", "segmentation_identity", "stored_fit"]

log = logging.getLogger(__name__)

#: Frames further apart than this are not tracked (broad search, previous pose as a hint).
MAX_TRACK_GAP = 2
#: A tracked frame costing more than this × its chain's reference cost is searched again.
RECOVERY_FACTOR = 3.0

# per worker process: the opened workspace and body models of the spec last seen
_CACHE: dict = {}


#: Packages whose code decides a fit (with the body model file): part of a run's settings, so a
#: frame fitted by other code is fitted again rather than kept.
FIT_CODE = ("studio.fit", "studio.cost", "studio.body", "studio.optimize", "studio.render")


#: Modules of :data:`FIT_CODE` a single-frame fit never runs (the batch of chapter 6, its skin
#: adaptation and clothing cost): left out of :func:`frame_fit_code_digest`, so a change to the
#: batch keeps the session's single-frame fits (the batch starts from them).
FRAME_FIT_EXCLUDES = ("studio.fit.batch", "studio.fit.batch_frames", "studio.fit.batch_gender",
                      "studio.fit.batch_session", "studio.fit.batch_terms", "studio.fit.skin_adapt",
                      "studio.cost.clothing")


def fit_code_digest() -> str:
    """Digest of the fitting code and the body model file (:func:`studio.provenance.code_digest`)."""
    from studio.body.model import DATA_FILE
    from studio.provenance import code_digest

    return code_digest(*FIT_CODE, files=(DATA_FILE,))


def frame_fit_code_digest() -> str:
    """Digest of the code a single-frame fit runs: :func:`fit_code_digest` without
    :data:`FRAME_FIT_EXCLUDES` (the ``code`` of a stored fit's run settings)."""
    from studio.body.model import DATA_FILE
    from studio.provenance import code_digest

    return code_digest(*FIT_CODE, files=(DATA_FILE,), exclude=FRAME_FIT_EXCLUDES)


def segmentation_identity(layout) -> str | None:
    """16-hex digest of the settings (with the code) the session's labels were written with
    (``segmentation/segmentation.json``), or None without one: part of a run's settings, so a frame
    fitted on masks since relabelled is fitted again."""
    try:
        settings = json.loads(layout.segmentation_summary.read_text()).get("settings")
    except (OSError, ValueError, AttributeError):
        return None
    return None if settings is None else hashlib.sha256(json.dumps(settings, sort_keys=True).encode()).hexdigest()[:16]


def stored_fit(layout, frame: int, run: dict) -> dict | None:
    """``fit/NNNNNN.json`` of ``frame`` when written by a run with the same settings (and the same
    fitting code, ``run["code"]``), else None."""
    try:
        obj = json.loads(layout.fit_json(frame).read_text())
    except (OSError, ValueError):
        return None
    return obj if obj.get("run") == run else None


def chain_state(record: dict, previous: dict | None) -> dict:
    """The state a chain carries past frame ``record`` (fitted or refused), given the one before."""
    prev = previous or {}
    if not record.get("fitted", True):
        return {**prev, "frame": record["frame"], "record": record}
    first = prev.get("pose") is None
    return {
        "frame": record["frame"],
        "record": record,
        "gender": record["gender"],
        "pose": record["pose"],
        "pose_frame": record["frame"],
        "shape": record["shape"] if first else prev["shape"],
        "ref_cost": record["costs"]["total"] if first else prev["ref_cost"],
    }


def _workspace(spec: dict):
    from studio.fit.session import open_workspace

    key = (spec["path"], spec["out"])
    if _CACHE.get("key") != key:
        _CACHE.clear()
        _CACHE.update(key=key, ws=open_workspace(spec["path"], spec["out"]), models={})
    return _CACHE["ws"]


def _model(gender: str):
    from studio.body import BodyModel

    models = _CACHE.setdefault("models", {})
    if gender not in models:
        models[gender] = BodyModel.load(gender)
    return models[gender]


def _images(ws, frame: int):
    try:
        return ws.images(frame)
    except Exception as exc:  # noqa: BLE001 - overlays fall back to a grey background
        log.warning("frame %d: no camera images for the overlays (%s)", frame, exc)
        return None


def _shadow_inputs(ws, frame: int, shadows: dict | None) -> dict:
    """fit_frame's shadow arguments (eq. 5.7) when the spec asks for the shadow term: the lights of
    ``light/light.json``, the frame's segmented shadows (label 2), the calibrated ground (or the
    floor refined from the shadows, when ``light.json`` holds one)."""
    if not shadows:
        return {}
    from studio.light import LightError, light_uncertainty, load_light

    try:
        lights, light = load_light(ws.layout.light_json)
    except LightError as exc:
        raise FitError(str(exc)) from None
    ground = getattr(ws.calibration, "ground", None)
    if "floor" in light:  # refined from the shadows (`studio light --refine-floor`)
        from calibration import GroundPlane

        n = np.asarray(light["floor"]["normal"], float)
        ground = GroundPlane(n / np.linalg.norm(n), float(light["floor"]["offset"]))
    return {"lights": lights, "shadow_masks": [ws.labels(c, frame) == 2 for c in ws.camera_names],
            "shadow_weight": float(shadows.get("weight", 1.0)), "ground": ground,
            "light_uncertainty": light_uncertainty(light)}


def fit_unit(spec: dict, frame: int, previous: dict | None) -> dict:
    """Fit ``frame`` of the session ``spec`` names (or take its stored result); the chain state.

    ``spec``: ``path``, ``out`` (session and output folders), ``gender`` (a model, or "auto" for
    a chain's first frame only), ``options`` (:meth:`FitOptions.to_dict`), ``seed``, ``run``
    (the settings recorded in every result), optionally ``shadows`` ({"weight": w}: the shadow
    term of eq. 5.7 with the light of ``light/light.json``). ``previous``: the chain state of the frame before.
    """
    from studio.fit.frame import FitOptions
    from studio.fit.output import write_frame_fit, write_unfitted
    from studio.fit.quality import screen_masks
    from studio.workspace import WorkspaceError

    ws = _workspace(spec)
    stored = stored_fit(ws.layout, frame, spec["run"])
    if stored is not None:
        return chain_state(stored, previous)
    cameras = ws.cameras
    try:
        masks = ws.person_masks(frame)
    except WorkspaceError as exc:
        raise FitError(str(exc)) from None
    options = FitOptions(**{k: tuple(v) if isinstance(v, list) else v for k, v in spec["options"].items()})
    seed = int(spec["seed"]) + frame
    prev = previous or {}
    pose = None if prev.get("pose") is None else np.asarray(prev["pose"], float)
    gender = prev.get("gender") or spec["gender"]
    extra = _shadow_inputs(ws, frame, spec.get("shadows"))
    screen = screen_masks(cameras, masks, shadow=bool(extra.get("lights")), light=extra.get("light_uncertainty"))
    try:
        if pose is None:  # the chain's first fitted frame: from the silhouettes, shape free
            fit = fit_frame_gender(cameras, masks, gender, frame=frame, options=options, seed=seed, screen=screen,
                                   **extra)
        else:
            model = _model(gender)
            shape = np.asarray(prev["shape"], float)
            track = abs(frame - prev["pose_frame"]) <= MAX_TRACK_GAP
            fit = fit_frame(model, cameras, masks, frame=frame, shape=shape,
                            previous_pose=pose if track else None, hint_pose=None if track else pose,
                            options=options, seed=seed, screen=screen, **extra)
            if track and fit.costs["total"] > RECOVERY_FACTOR * prev["ref_cost"]:
                # tracking lost the body: search again from the silhouettes, keep the better fit
                log.info("frame %d: tracking cost %.2f, re-initialising from the silhouettes", frame,
                         fit.costs["total"])
                again = fit_frame(model, cameras, masks, frame=frame, shape=shape, hint_pose=pose,
                                  options=options, seed=seed + 1, screen=screen, **extra)
                if again.costs["total"] < fit.costs["total"]:
                    fit = again
    except UnusableFrame as err:
        log.warning("%s", err)
        write_unfitted(ws.layout, err, run=spec["run"])
    else:
        write_frame_fit(ws.layout, fit, _model(fit.gender), cameras, masks, _images(ws, frame), run=spec["run"])
    # the state from the file just written: a fresh and a resumed chain carry the very same numbers
    return chain_state(json.loads(ws.layout.fit_json(frame).read_text()), previous)
