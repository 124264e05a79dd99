"""Everything a report shows, gathered once from a fitted session (HTML and PDF both draw on it)."""

from __future__ import annotations

import json
import logging
import math
from dataclasses import dataclass, field

import numpy as np

from studio.fit.errors import FitError

__all__ = ["Participant", "ReportData", "gather"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Participant:
    """Who was measured: ``id`` (any text, escaped wherever shown), ``sex`` (``female``/``male``
    or None: the fitted model's gender then sets the population), ``age`` (years) and ``notes``."""

    id: str = ""
    sex: str | None = None
    age: float | None = None
    notes: str = ""

    def __post_init__(self):
        if not isinstance(self.id, str) or len(self.id) > 200:
            raise ValueError(f"participant id: expected text of at most 200 characters, got {self.id!r:.60}")
        if self.sex not in (None, "female", "male"):
            raise ValueError(f"participant sex: expected 'female' or 'male', got {self.sex!r}")
        if self.age is not None and (isinstance(self.age, bool) or not isinstance(self.age, (int, float))
                                     or not math.isfinite(self.age) or not 0 < self.age < 130):
            raise ValueError(f"participant age: expected years between 0 and 130, got {self.age!r}")
        if not isinstance(self.notes, str) or len(self.notes) > 5000:
            raise ValueError("participant notes: expected text of at most 5000 characters")

    def to_json(self) -> dict:
        return {"id": self.id, "sex": self.sex, "age": self.age, "notes": self.notes}


@dataclass
class ReportData:
    """The gathered report (see :func:`gather`)."""

    session_name: str
    participant: Participant
    gender: str
    sex: str
    fits: dict
    qualities: dict
    table: dict
    uncertainty: dict
    frames_used: list
    shape: np.ndarray
    measured: object  # studio.body.iso7250.IsoMeasurement of the mean shape
    rest_vertices: np.ndarray
    faces: np.ndarray
    posed_vertices: np.ndarray
    overlays: dict  # {frame: [(camera, path)]}
    segmentation: dict  # {camera: {figure: mean over frames}}
    settings: dict
    sequence: dict = field(default_factory=dict)
    version: str = ""
    batch: dict | None = None


def _segmentation_summary(qualities: dict) -> dict:
    """{camera: {coverage, hull_explained, precision, recall}} averaged over the frames that have them."""
    acc: dict = {}
    for q in qualities.values():
        for cam, fig in (q.get("views") or {}).items():
            for k in ("coverage", "hull_explained", "precision", "recall"):
                if isinstance(fig.get(k), (int, float)):
                    acc.setdefault(cam, {}).setdefault(k, []).append(float(fig[k]))
    return {cam: {k: float(np.mean(v)) for k, v in figs.items()} for cam, figs in sorted(acc.items())}


def gather(source, participant: Participant | None = None, *, posterior: bool = True) -> ReportData:
    """Read the fits of ``source`` (a :class:`~studio.workspace.Workspace`, a
    :class:`~studio.workspace.Layout` or a session folder), measure them, and compute the
    uncertainty (the fit posterior needs the segmentation and calibration: without them,
    or with ``posterior=False``, it is left out and the page says so)."""
    import studio
    from studio.body import BodyModel
    from studio.body.iso7250 import measure_iso
    from studio.body.measure import t_pose
    from studio.fit import load_fits, load_quality
    from studio.fit.batch_session import gender_warning, load_batch
    from studio.report.measurements import frames_used, load_truth, measurement_table, use_batch_shape
    from studio.report.uncertainty import load_model_error, session_uncertainty
    from studio.workspace import Layout, Workspace

    participant = participant or Participant()
    ws = source if isinstance(source, Workspace) else None
    lay = ws.layout if ws else source if isinstance(source, Layout) else Layout(source)
    if not lay.source.is_dir():
        raise FitError(f"{lay.source}: no such session folder")
    fits = load_fits(lay)
    qualities = load_quality(lay)
    gender = sorted({f.gender for f in fits.values()})[0]
    model = BodyModel.load(gender)
    sex = participant.sex or (gender if gender in ("female", "male") else "neutral")
    used, _ = frames_used(fits)
    if ws is None:
        try:
            ws = Workspace.open(lay.source, out=lay.root)
        except Exception as exc:  # noqa: BLE001 - a report without the capture still reports the fits
            log.warning("no workspace for the uncertainty (%s)", exc)
    if ws is not None and ws.calibration is not None:
        masks_of = ws.person_masks if posterior else None
        unc = session_uncertainty(model, ws.cameras, ws.calibration, fits, used, masks_of)
    else:  # the model's own error needs no capture (uncertainty module doc, 4.)
        model_error = load_model_error()
        unc = {"model": model_error["model_sigma"], "info": {"model_error_source": model_error["source"]}}
    table = measurement_table(model, fits, load_truth(lay), unc, sex=sex)
    shape = np.mean([fits[f].shape for f in used], axis=0)
    first = fits[used[0]]
    posed = model.vertices(first.shape, first.pose)
    batch = load_batch(lay)
    if batch is not None:  # one shape shared by the batch frames (thesis ch. 6) is the body measured
        model, gender, shape = BodyModel.load(batch["gender"]), batch["gender"], np.asarray(batch["shape"], float)
        sex = participant.sex or (gender if gender in ("female", "male") else "neutral")
        table = use_batch_shape(table, model, shape, load_truth(lay), sex=sex, frames=batch["frames"],
                                clothing=batch.get("clothing"),
                                poses=[batch["poses"][str(f)] for f in batch["frames"]],
                                warning=gender_warning(batch.get("gender_test")))
    rest = model.vertices(shape)
    measured = measure_iso(rest, model.vertices(shape, t_pose(model, shape)), model.joint_regressor @ rest,
                           model.faces, model.parts, model.face_parts)
    overlays = {}
    fdir = lay.fit_dir / "overlay"
    cameras = sorted(p.name for p in fdir.iterdir() if p.is_dir()) if fdir.is_dir() else []
    for f in sorted(fits):
        overlays[f] = [(c, lay.fit_overlay(c, f)) for c in cameras if lay.fit_overlay(c, f).is_file()]
    seq = json.loads(lay.fit_sequence.read_text()) if lay.fit_sequence.is_file() else {}
    return ReportData(
        session_name=lay.source.name, participant=participant, gender=gender, sex=sex, fits=fits,
        qualities=qualities, table=table, uncertainty=unc, frames_used=used, shape=shape, measured=measured,
        rest_vertices=rest, faces=model.faces, posed_vertices=posed,
        overlays=overlays, segmentation=_segmentation_summary(qualities), settings=dict(first.settings),
        sequence=seq, version=studio.__version__, batch=batch)
