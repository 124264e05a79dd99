"""The light of a session: bodies and shadows read through the workspace, ``light/light.json`` written.

Bodies come from ``fit/NNNNNN.json`` (``bodies="fit"``, the thesis' procedure: bodies fitted
from the silhouettes alone, eq. 5.8) or, for simulated sessions, from ``truth/bodies``
(``"truth"``); shadows from the segmentation's label 2 (``shadows="segmentation"``) or the
simulator's true labels (``"truth"``). The ground plane is the calibration's, refined from the
shadows on request (``refine_floor``; ``light.json`` then holds it under ``floor``).
"""

from __future__ import annotations

import json
import logging

import numpy as np

from studio.light.estimate import LightError, estimate_light
from studio.render.lights import light_from_dict

__all__ = ["BODY_SOURCES", "MAX_FRAMES", "estimate_session_light", "load_light", "session_bodies",
           "session_shadows", "spread_frames"]

log = logging.getLogger(__name__)

BODY_SOURCES = ("fit", "truth")
#: Frames used by default (evenly spread over those available): the thesis used 10 poses.
MAX_FRAMES = 10


def spread_frames(frames: list[int], n: int) -> list[int]:
    """At most ``n`` of ``frames``, evenly spread over them (first and last kept)."""
    if len(frames) <= n:
        return list(frames)
    return [frames[int(i)] for i in np.round(np.linspace(0, len(frames) - 1, n)).astype(int)]


def session_bodies(ws, frames: list[int] | None, source: str = "fit") -> tuple[list[int], list]:
    """(frames, [(vertices (V, 3), faces (F, 3)), ...]) of the session's bodies."""
    if source == "fit":
        from studio.body import BodyModel
        from studio.fit import FitError, load_fits

        try:
            fits = load_fits(ws, frames)
        except FitError as exc:
            raise LightError(str(exc)) from None
        models: dict = {}
        chosen = sorted(fits) if frames is None else [f for f in frames if f in fits]
        if frames is not None and len(chosen) < len(frames):
            missing = sorted(set(frames) - set(fits))
            raise LightError(f"{ws.layout.fit_dir}: frame(s) {missing} have no fitted body — run "
                             f"`studio fit {ws.path} --frames ...` on them first")
        out = []
        for f in chosen:
            fit = fits[f]
            model = models.setdefault(fit.gender, BodyModel.load(fit.gender))
            out.append((model.vertices(fit.shape, fit.pose), model.faces))
        return chosen, out
    if source == "truth":
        lay = ws.layout
        faces_path = lay.truth_dir / "faces.npy"
        if not faces_path.is_file():
            raise LightError(f"{faces_path}: no true bodies — --bodies truth needs a simulated session")
        faces = np.load(faces_path)
        chosen = ws.frame_indices if frames is None else frames
        out = []
        for f in chosen:
            with np.load(lay.truth_body(f)) as z:
                out.append((z["vertices"].astype(np.float64), faces))
        return list(chosen), out
    raise LightError(f"bodies: expected one of {BODY_SOURCES}, got {source!r}")


def session_shadows(ws, frames: list[int], source: str = "segmentation") -> list[list[np.ndarray]]:
    """Observed shadow masks (label 2) per frame, per camera in session order."""
    from rigs.imageio import read_image
    from studio.workspace import WorkspaceError

    if source == "segmentation":
        try:
            ws.check_segmented(frames)
        except WorkspaceError as exc:
            raise LightError(str(exc)) from None
        return [[ws.labels(c, f) == 2 for c in ws.camera_names] for f in frames]
    if source == "truth":
        out = []
        for f in frames:
            paths = [ws.layout.truth_labels(c, f) for c in ws.camera_names]
            missing = [p for p in paths if not p.is_file()]
            if missing:
                raise LightError(f"{missing[0]}: no true labels — --shadows truth needs a simulated session")
            labels = [np.asarray(read_image(p)) for p in paths]
            out.append([(lab[..., 0] if lab.ndim == 3 else lab) == 2 for lab in labels])
        return out
    raise LightError(f"shadows: expected 'segmentation' or 'truth', got {source!r}")


def estimate_session_light(ws, *, frames: list[int] | None = None, kind: str = "auto", n_lights: int = 1,
                           bodies: str = "fit", shadows: str = "segmentation", workers: int = 1, seed: int = 0,
                           n_steps: int = 40, refine_floor: bool = False) -> dict:
    """Estimate the session's light(s) and write ``light/light.json``; returns what was written."""
    from rigs.atomic import atomic_write_json

    calib = ws.require_calibration("the light (the cameras and the ground plane)")
    if frames is None and bodies == "fit":
        chosen, _ = session_bodies(ws, None, "fit") if ws.layout.fit_dir.is_dir() else (None, None)
        if chosen is None:
            raise LightError(f"{ws.path}: no fit/ folder — run `studio fit {ws.path}` first (or --bodies truth)")
        frames = spread_frames(chosen, MAX_FRAMES)
    elif frames is None:
        frames = spread_frames(ws.frame_indices, MAX_FRAMES)
    frames = ws.check_frames(frames)
    ws.check_writable(ws.layout.light_dir)
    frames, body_list = session_bodies(ws, frames, bodies)
    masks = session_shadows(ws, frames, shadows)
    est = estimate_light(body_list, ws.cameras, masks, frames=frames, kind=kind, n_lights=n_lights,
                         ground=getattr(calib, "ground", None), workers=workers, seed=seed, n_steps=n_steps,
                         refine_floor=refine_floor)
    out = est.to_json()
    out["sources"] = {"bodies": bodies, "shadows": shadows}
    atomic_write_json(ws.layout.light_json, out)
    return out


def load_light(source) -> tuple[list, dict]:
    """(lights, light.json contents) of a session (a Workspace, a Layout or a ``light.json`` path)."""
    from pathlib import Path

    from studio.workspace import Layout, Workspace

    if isinstance(source, Workspace):
        path = source.layout.light_json
    elif isinstance(source, Layout):
        path = source.light_json
    else:
        path = Path(source)
    try:
        obj = json.loads(path.read_text())
    except FileNotFoundError:
        raise LightError(f"{path}: no light estimated — run `studio light` first") from None
    except ValueError as exc:
        raise LightError(f"{path}: not JSON ({exc})") from None
    if obj.get("format") != "studio.light" or int(obj.get("version", 0)) != 1:
        raise LightError(f"{path}: not a studio.light version 1 file (format={obj.get('format')!r}, "
                         f"version={obj.get('version')!r})")
    lights = []
    for i, entry in enumerate(obj.get("lights", [])):
        if entry.get("kind") == "point":
            lights.append(light_from_dict({"type": "point", "position": entry["position"]}, f"{path}: lights[{i}]"))
        elif entry.get("kind") == "directional":
            d = -np.asarray(entry["direction"], float)
            lights.append(light_from_dict({"type": "directional", "direction": d.tolist()}, f"{path}: lights[{i}]"))
        else:
            raise LightError(f"{path}: field 'lights[{i}].kind': expected 'point' or 'directional', "
                             f"got {entry.get('kind')!r}")
    if not lights:
        raise LightError(f"{path}: field 'lights': expected at least one light")
    return lights, obj


def light_uncertainty(obj: dict) -> dict:
    """The widest 95 % intervals over the lights of a ``light.json`` (or
    :meth:`~studio.light.LightEstimate.to_json`) object: ``{"direction_ci_deg", "distance_ci":
    [lo, hi] % or None}`` (None for directional lights) — what
    :func:`studio.fit.quality.screen_masks` asks of a light that gives one view its depth."""
    entries = obj.get("lights") or [obj]
    direction = max(float(e.get("direction_ci_deg") or 0.0) for e in entries)
    spans = [e["distance_ci"] for e in entries if e.get("distance_ci") is not None]
    distance = [min(float(s[0]) for s in spans), max(float(s[1]) for s in spans)] if spans else None
    return {"direction_ci_deg": direction, "distance_ci": distance}
