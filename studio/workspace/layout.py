"""Where everything lives in a session folder: the one description of the derived outputs.

The capture itself (``session.json``, ``calibration.json``, ``frames/``, ``background/``,
``frames.csv``) is the session format of :mod:`rigs.session`; this module places what the
toolkit derives from it and the simulator's truth::

    truth/          labels/<cam>/NNNNNN.png, skin/<cam>/NNNNNN.png, bodies/NNNNNN.npz,
                    scene.json, calibration.json, measurements.json
    segmentation/   segmentation.json, background/<cam>/, skin_models/<cam>.npz,
                    <cam>/NNNNNN.png, skin/<cam>/NNNNNN.png, overlay/<cam>/NNNNNN.png,
                    floor_votes/NNNNNN.png
    fit/            NNNNNN.json, NNNNNN.ply, overlay/<cam>/NNNNNN.png, sequence.json, batch.json,
                    batch_neutral.ply
    light/          light.json
    report/         index.html, report.pdf, measurements.json, measurements.csv
    export/         body_neutral.obj/.glb, frames/NNNNNN.obj/.glb, joints.trc, measurements.csv, model_parameters.json

Frame numbers are formatted by :func:`rigs.session.index_name` only; no other module builds
one of these paths.

>>> lay = Layout(Path("s"))
>>> lay.labels("cam0", 7).as_posix(), lay.fit_json(7).as_posix()
('s/segmentation/cam0/000007.png', 's/fit/000007.json')
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from rigs.session import index_name

__all__ = ["Layout", "SEGMENTATION_RESERVED"]

#: Names inside ``segmentation/`` that are not cameras.
SEGMENTATION_RESERVED = frozenset({"background", "skin", "skin_models", "overlay", "floor_votes"})


@dataclass(frozen=True)
class Layout:
    """Paths of one session folder (pure: nothing is read or created).

    Derived outputs live under ``root``; the capture and its truth under ``source`` (the
    session folder; by default ``root`` itself, a different folder when outputs go elsewhere,
    e.g. ``--out`` for a read-only session).
    """

    root: Path
    source: Path | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "root", Path(self.root))
        object.__setattr__(self, "source", Path(self.root if self.source is None else self.source))

    # ------------------------------------------------------------------ truth (simulated)
    @property
    def truth_dir(self) -> Path:
        return self.source / "truth"

    def truth_labels(self, camera: str, index: int) -> Path:
        """True labels (0 background, 1 person, 2 shadow) of ``camera`` / frame ``index``."""
        return self.truth_dir / "labels" / camera / f"{index_name(index)}.png"

    def truth_skin(self, camera: str, index: int) -> Path:
        return self.truth_dir / "skin" / camera / f"{index_name(index)}.png"

    def truth_body(self, index: int) -> Path:
        return self.truth_dir / "bodies" / f"{index_name(index)}.npz"

    @property
    def truth_scene(self) -> Path:
        return self.truth_dir / "scene.json"

    @property
    def truth_calibration(self) -> Path:
        return self.truth_dir / "calibration.json"

    @property
    def truth_measurements(self) -> Path:
        return self.truth_dir / "measurements.json"

    # ------------------------------------------------------------------ segmentation
    @property
    def segmentation_dir(self) -> Path:
        return self.root / "segmentation"

    @property
    def segmentation_summary(self) -> Path:
        return self.segmentation_dir / "segmentation.json"

    def background_model_dir(self, camera: str) -> Path:
        return self.segmentation_dir / "background" / camera

    def skin_model(self, camera: str) -> Path:
        return self.segmentation_dir / "skin_models" / f"{camera}.npz"

    def labels(self, camera: str, index: int) -> Path:
        """Segmentation labels (0 background, 1 person, 2 shadow) of ``camera`` / frame ``index``."""
        return self.segmentation_dir / camera / f"{index_name(index)}.png"

    def skin(self, camera: str, index: int) -> Path:
        return self.segmentation_dir / "skin" / camera / f"{index_name(index)}.png"

    def segmentation_overlay(self, camera: str, index: int) -> Path:
        return self.segmentation_dir / "overlay" / camera / f"{index_name(index)}.png"

    def floor_votes(self, index: int) -> Path:
        return self.segmentation_dir / "floor_votes" / f"{index_name(index)}.png"

    # ------------------------------------------------------------------ fit
    @property
    def fit_dir(self) -> Path:
        return self.root / "fit"

    def fit_json(self, index: int) -> Path:
        return self.fit_dir / f"{index_name(index)}.json"

    def fit_ply(self, index: int) -> Path:
        return self.fit_dir / f"{index_name(index)}.ply"

    def fit_overlay(self, camera: str, index: int) -> Path:
        return self.fit_dir / "overlay" / camera / f"{index_name(index)}.png"

    @property
    def fit_sequence(self) -> Path:
        return self.fit_dir / "sequence.json"

    @property
    def fit_batch(self) -> Path:
        return self.fit_dir / "batch.json"

    @property
    def fit_batch_mesh(self) -> Path:
        """The batch body (shared shape) in the model's default pose."""
        return self.fit_dir / "batch_neutral.ply"

    # ------------------------------------------------------------------ light, report, export
    @property
    def light_dir(self) -> Path:
        return self.root / "light"

    @property
    def light_json(self) -> Path:
        return self.light_dir / "light.json"

    @property
    def report_dir(self) -> Path:
        return self.root / "report"

    @property
    def report_html(self) -> Path:
        return self.report_dir / "index.html"

    @property
    def report_measurements_json(self) -> Path:
        return self.report_dir / "measurements.json"

    @property
    def report_measurements_csv(self) -> Path:
        return self.report_dir / "measurements.csv"

    @property
    def report_pdf(self) -> Path:
        return self.report_dir / "report.pdf"

    @property
    def export_dir(self) -> Path:
        return self.root / "export"

    def export_mesh(self, kind: str, ext: str, frame: int | None = None) -> Path:
        """``export/body_<kind>.<ext>`` (``kind`` "neutral": the rest pose) or, with ``frame``,
        ``export/frames/NNNNNN.<ext>``."""
        if frame is None:
            return self.export_dir / f"body_{kind}.{ext}"
        return self.export_dir / "frames" / f"{index_name(frame)}.{ext}"

    @property
    def export_trc(self) -> Path:
        return self.export_dir / "joints.trc"

    @property
    def export_csv(self) -> Path:
        return self.export_dir / "measurements.csv"

    @property
    def export_parameters(self) -> Path:
        return self.export_dir / "model_parameters.json"
