"""Standard exports of a fitted session into ``export/`` (paths from the workspace Layout).

- ``obj`` / ``glb``: the person's mesh in the neutral (default standing) pose,
  ``export/body_neutral.*``, and as fitted in every frame, ``export/frames/NNNNNN.*``
  (metres, world Z up);
- ``trc``: joint centres of every fitted frame, ``export/joints.trc`` — the OpenSim / Pose2Sim
  marker format, tab-separated, metres, **Y up** (OpenSim's convention: X_trc = x, Y_trc = z,
  Z_trc = −y), joints named as Pose2Sim names its markers (:data:`TRC_NAMES`);
- ``csv``: the measurement table (as ``report/measurements.csv``), ``export/measurements.csv``;
- ``json``: the model parameters (:mod:`studio.body.parameters`), ``export/model_parameters.json``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

__all__ = ["EXPORT_KINDS", "TRC_NAMES", "export_session", "read_trc", "trc_text"]

EXPORT_KINDS = ("obj", "glb", "trc", "csv", "json")

#: marker name of each joint (the joint of each part with its parent, PART_NAMES order)
TRC_NAMES = ("Hip", "Spine", "Neck", "LShoulder", "LElbow", "LWrist", "RShoulder", "RElbow", "RWrist",
             "LHip", "LKnee", "LAnkle", "RHip", "RKnee", "RAnkle")


def trc_text(joints: dict, fps: float, name: str = "joints.trc") -> str:
    """TRC file text of ``joints`` {frame: (15, 3) metres, Z up}; ``fps`` the capture rate."""
    frames = sorted(joints)
    n = len(frames)
    head = [f"PathFileType\t4\t(X/Y/Z)\t{name}",
            "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
            f"{fps:g}\t{fps:g}\t{n}\t{len(TRC_NAMES)}\tm\t{fps:g}\t{frames[0] + 1 if frames else 1}\t{n}",
            "Frame#\tTime\t" + "\t\t\t".join(TRC_NAMES) + "\t\t",
            "\t\t" + "\t".join(f"{a}{i + 1}" for i in range(len(TRC_NAMES)) for a in "XYZ"),
            ""]
    rows = []
    for k, f in enumerate(frames):
        J = np.asarray(joints[f], dtype=np.float64)
        yup = np.stack([J[:, 0], J[:, 2], -J[:, 1]], axis=1)
        rows.append(f"{k + 1}\t{f / fps:.6f}\t" + "\t".join(f"{x:.6f}" for x in yup.ravel()))
    return "\n".join(head + rows) + "\n"


def read_trc(path: str | Path) -> tuple[list[str], np.ndarray, np.ndarray]:
    """(marker names, times (N,), positions (N, M, 3) as written, Y up) of a TRC file."""
    lines = Path(path).read_text().splitlines()
    if len(lines) < 6 or not lines[0].startswith("PathFileType"):
        raise ValueError(f"{path}: not a TRC file (first line {lines[0][:40]!r})" if lines else f"{path}: empty")
    n_frames, n_markers = (int(v) for v in lines[2].split("\t")[2:4])
    names = [c for c in lines[3].split("\t")[2:] if c]
    data = np.array([[float(v) for v in row.split("\t")] for row in lines[6:] if row.strip()])
    if len(names) != n_markers or data.shape != (n_frames, 2 + 3 * n_markers):
        raise ValueError(f"{path}: header says {n_frames} frames of {n_markers} markers, the file holds "
                         f"{data.shape[0]} rows of {data.shape[1] if data.ndim == 2 else 0} columns")
    return names, data[:, 1], data[:, 2:].reshape(n_frames, n_markers, 3)


def export_session(source, kinds=EXPORT_KINDS, *, table: dict | None = None) -> list[Path]:
    """Write the exports ``kinds`` (module doc) of a fitted session (a
    :class:`~studio.workspace.Workspace` or a folder); returns the files written. ``table``: the
    measurement table to export as CSV (default: measured now, without the fit posterior)."""
    from rigs.atomic import atomic_write_text
    from studio.body import BodyModel, write_mesh
    from studio.body.parameters import BodyParameters
    from studio.fit import load_fits
    from studio.report.measurements import frames_used, write_measurements_csv
    from studio.workspace import Layout, Workspace

    unknown = sorted(set(kinds) - set(EXPORT_KINDS))
    if unknown:
        raise ValueError(f"export kind(s) {unknown}: expected some of {', '.join(EXPORT_KINDS)}")
    lay = source.layout if isinstance(source, Workspace) else source if isinstance(source, Layout) else Layout(source)
    fits = load_fits(lay)
    used, _ = frames_used(fits)
    gender = sorted({f.gender for f in fits.values()})[0]
    model = BodyModel.load(gender)
    shape = np.mean([fits[f].shape for f in used], axis=0)
    written = []
    lay.export_dir.mkdir(parents=True, exist_ok=True)
    for ext in ("obj", "glb"):
        if ext in kinds:
            written.append(write_mesh(lay.export_mesh("neutral", ext), model.vertices(shape), model.faces))
            lay.export_mesh("neutral", ext, 0).parent.mkdir(parents=True, exist_ok=True)
            for f, fit in sorted(fits.items()):
                written.append(write_mesh(lay.export_mesh("neutral", ext, f), model.vertices(fit.shape, fit.pose),
                                          model.faces))
    if "trc" in kinds:
        fps = None
        info = lay.source / "session.json"
        if info.is_file():
            fps = json.loads(info.read_text()).get("fps")
        text = trc_text({f: fit.joints for f, fit in fits.items()}, float(fps or 1.0), lay.export_trc.name)
        written.append(atomic_write_text(lay.export_trc, text))
    if "csv" in kinds:
        if table is None:
            from studio.report.measurements import measurement_table

            table = measurement_table(model, fits)
        written.append(write_measurements_csv(lay.export_csv, table))
    if "json" in kinds:
        params = BodyParameters(gender, shape, {f: (fit.shape, fit.pose) for f, fit in fits.items()})
        written.append(params.save(lay.export_parameters))
    return written
