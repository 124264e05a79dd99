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
    """
    from studio.body import measure

    per = {f: measure(model, fit.shape) for f, fit in sorted(fits.items())}
    same = (truth or {}).get("studio") or {}
    if not isinstance(same, dict):
        raise ValueError(f"truth measurements: 'studio' must be a mapping name → value, got {type(same).__name__}")
    out = {}
    for name in REPORTED:
        scale, unit = (1.0, "kg") if name == "mass" else (1000.0, "mm")
        vals = np.array([per[f][name] for f in per]) * scale
        row = {
            "unit": unit,
            "per_frame": {str(f): float(per[f][name] * scale) for f in per},
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

    CSV columns: name, unit, mean, std, truth, error, truth_anny, error_anny, then one
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
        w.writerow(["name", "unit", "mean", "std", "truth", "error", "truth_anny", "error_anny"]
                   + [f"frame_{f}" for f in frames])
        for name, row in table.items():
            fmt = (lambda v: "" if v is None else f"{v:.2f}")
            w.writerow([name, row["unit"], fmt(row["mean"]), fmt(row["std"]), fmt(row["truth"]), fmt(row["error"]),
                        fmt(row.get("truth_anny")), fmt(row.get("error_anny"))]
                       + [fmt(row["per_frame"].get(f)) for f in frames])
    return jp, layout.report_measurements_csv


def load_truth(layout) -> dict | None:
    """The simulator's true measurements of a session (:class:`~studio.workspace.Layout` or folder), or None."""
    from studio.workspace import Layout

    p = (layout if isinstance(layout, Layout) else Layout(layout)).truth_measurements
    return json.loads(p.read_text()) if p.is_file() else None
