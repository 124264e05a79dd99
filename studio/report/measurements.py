"""Measurement table of a fitted session (thesis §4.8.6): per-frame values, mean ± std, truth."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

__all__ = ["REPORTED", "measurement_table", "write_measurements"]

#: Measurements reported, in order (names of :func:`studio.body.measure`).
REPORTED = ("stature", "arm_span", "shoulder_breadth", "chest_circumference", "waist_circumference",
            "hip_circumference", "inseam", "arm_length", "mass")


def measurement_table(model, fits: dict, truth: dict | None = None) -> dict:
    """{name: {"per_frame": {frame: value}, "mean", "std", "unit", "truth", "error", ...}}.

    Lengths in millimetres, mass in kilograms. ``fits`` {frame: FrameFit}; ``truth`` the
    session's ``truth/measurements.json`` (metres, kg) or None. ``truth`` is the true
    person measured by the same definitions as the fit (the file's ``"studio"`` entry,
    :func:`studio.simulate.session.studio_truth`) when the session has it, else the
    file's top-level value (the simulator's Anny definitions: waist from Anny's
    anthropometry, chest/hips from slices of Anny's T-pose); ``truth_source`` says which
    ("studio", "anny" or None). ``truth_anny`` is always the top-level value (or None);
    ``error`` = mean − truth and ``error_anny`` = mean − truth_anny.

    Quality (:mod:`studio.fit.quality`): the mean is taken over the frames whose status is
    ``ok`` (or unchecked); with none, over the ``suspect`` ones, with none, over the ``failed``
    ones. ``status`` is then the worst status of the frames used, raised by the mean's own
    ANSUR II z-score (stature, mass, girths); ``flags`` says why, ``frames_used`` which frames
    count, ``per_frame_status`` every frame's status. A figure is never clean when its frames
    or its value are not.
    """
    from studio.body import measure
    from studio.fit.quality import POPULATION_Z, population_z, status_of

    per = {f: measure(model, fit.shape) for f, fit in sorted(fits.items())}
    status = {f: getattr(fit, "status", "ok").replace("unchecked", "ok") for f, fit in fits.items()}
    for level in ("ok", "suspect", "failed"):
        used = [f for f in per if status[f] == level]
        if used:
            break
    base_flags = []
    if level != "ok":
        base_flags.append(f"no clean frame: mean over {len(used)} {level} frame(s)")
    elif len(used) < len(per):
        base_flags.append(f"{len(per) - len(used)} flagged frame(s) left out of the mean")
    same = (truth or {}).get("studio") or {}
    if not isinstance(same, dict):
        raise ValueError(f"truth measurements: 'studio' must be a mapping name → value, got {type(same).__name__}")
    out = {}
    for name in REPORTED:
        scale, unit = (1.0, "kg") if name == "mass" else (1000.0, "mm")
        vals = np.array([per[f][name] for f in used]) * scale
        flags = list(base_flags)
        severities = [] if level == "ok" else [level]
        z = population_z({name: float(vals.mean()) / scale}, model.gender).get(name)
        if z is not None and abs(z) > POPULATION_Z[0]:
            severities.append("failed" if abs(z) > POPULATION_Z[1] else "suspect")
            flags.append(f"{severities[-1]}: {z:+.1f} σ from ANSUR II ({model.gender})")
        row_status = status_of([{"severity": sev} for sev in severities])
        row = {
            "unit": unit,
            "per_frame": {str(f): float(per[f][name] * scale) for f in per},
            "per_frame_status": {str(f): status[f] for f in per},
            "frames_used": [int(f) for f in used],
            "status": row_status,
            "flags": flags,
            "population_z": None if z is None else round(z, 2),
            "mean": float(vals.mean()),
            "std": float(vals.std(ddof=1)) if len(vals) > 1 else 0.0,
            "truth": None,
            "error": None,
            "truth_source": None,
            "truth_anny": None,
            "error_anny": None,
        }
        if truth is not None and truth.get(name) is not None:
            row["truth_anny"] = float(truth[name]) * scale
            row["error_anny"] = row["mean"] - row["truth_anny"]
        if same.get(name) is not None:
            row["truth"], row["truth_source"] = float(same[name]) * scale, "studio"
        elif row["truth_anny"] is not None:
            row["truth"], row["truth_source"] = row["truth_anny"], "anny"
        if row["truth"] is not None:
            row["error"] = row["mean"] - row["truth"]
        out[name] = row
    return out


def write_measurements(layout, table: dict) -> tuple[Path, Path]:
    """``report/measurements.json`` and ``report/measurements.csv`` of a session
    (a :class:`~studio.workspace.Layout` or a session folder).

    CSV columns: name, unit, mean, std, status, flags, truth, error, truth_anny, error_anny, then one
    column per frame (rows of tables without the ``truth_anny`` keys leave them empty).
    """
    import csv

    from rigs.atomic import atomic_open, atomic_write_json
    from studio.workspace import Layout

    layout = layout if isinstance(layout, Layout) else Layout(layout)
    layout.report_dir.mkdir(parents=True, exist_ok=True)
    jp = atomic_write_json(layout.report_measurements_json,
                           {"format": "studio.measurements", "version": 1, "measurements": table})
    frames = sorted({f for row in table.values() for f in row["per_frame"]}, key=int)
    with atomic_open(layout.report_measurements_csv, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["name", "unit", "mean", "std", "status", "flags", "truth", "error", "truth_anny", "error_anny"]
                   + [f"frame_{f}" for f in frames])
        for name, row in table.items():
            fmt = (lambda v: "" if v is None else f"{v:.2f}")
            w.writerow([name, row["unit"], fmt(row["mean"]), fmt(row["std"]), row.get("status", "ok"),
                        "; ".join(row.get("flags", [])), fmt(row["truth"]), fmt(row["error"]),
                        fmt(row.get("truth_anny")), fmt(row.get("error_anny"))]
                       + [fmt(row["per_frame"].get(f)) for f in frames])
    return jp, layout.report_measurements_csv


def load_truth(layout) -> dict | None:
    """The simulator's true measurements of a session (:class:`~studio.workspace.Layout` or folder), or None."""
    from studio.workspace import Layout

    p = (layout if isinstance(layout, Layout) else Layout(layout)).truth_measurements
    return json.loads(p.read_text()) if p.is_file() else None
