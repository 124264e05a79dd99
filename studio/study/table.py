"""``study.csv``: one row per participant, from each session's ``report/measurements.json`` and
``fit/sequence.json`` (the measurement means over clean frames, their spread over frames, the
quality gates' status and flags, the ANSUR II z-score).

Columns: ``participant, session, status, reason, gender, frames, quality, flagged, flags``, then
per measurement of :data:`studio.report.REPORTED`: ``<name>_<unit>`` (the mean),
``<name>_sd_<unit>`` (standard deviation over the frames used), ``<name>_status`` (ok / suspect /
failed) and ``<name>_z`` (z-score against ANSUR II, where it has the measurement).
"""

from __future__ import annotations

import json

from studio.report import REPORTED

__all__ = ["UNITS", "participant_row", "study_columns", "write_study_csv"]

#: Unit of each reported measurement in the table (that of ``report/measurements.json``).
UNITS = {name: "kg" if name == "mass" else "mm" for name in REPORTED}


def study_columns() -> list[str]:
    cols = ["participant", "session", "status", "reason", "gender", "frames", "quality", "flagged", "flags"]
    for name in REPORTED:
        u = UNITS[name]
        cols += [f"{name}_{u}", f"{name}_sd_{u}", f"{name}_status", f"{name}_z"]
    return cols


def participant_row(participant: str, session, entry: dict, folder) -> dict:
    """The row of one participant: ``entry`` its ``study.json`` record, ``folder`` its outputs."""
    row = {"participant": participant, "session": str(session), "status": entry.get("status", "not run"),
           "reason": entry.get("reason") or "", "flagged": True}
    if row["status"] != "done":
        row["flags"] = f"session {row['status']}: {row['reason']}" if row["reason"] else f"session {row['status']}"
        return row
    table = json.loads((folder / "report" / "measurements.json").read_text())["measurements"]
    seq = json.loads((folder / "fit" / "sequence.json").read_text())
    flags = []
    statuses = set(seq.get("quality", {}).values()) - {"ok"}
    if statuses:
        flags.append(f"frames: {seq.get('quality_summary')}")
    by_reason: dict[str, list[str]] = {}  # one line per reason, naming every measurement it affects
    for name in REPORTED:
        r = table[name]
        u = UNITS[name]
        row[f"{name}_{u}"] = round(r["mean"], 2)
        row[f"{name}_sd_{u}"] = round(r["std"], 2)
        row[f"{name}_status"] = r.get("status", "ok")
        row[f"{name}_z"] = r.get("population_z")
        if r.get("status", "ok") != "ok":
            by_reason.setdefault("; ".join(r.get("flags", [])) or r["status"], []).append(name)
    flags += [f"{', '.join(names)}: {reason}" for reason, names in by_reason.items()]
    row.update(gender=seq.get("gender"), frames=len(seq.get("costs", {})), quality=seq.get("quality_summary"),
               flagged=bool(flags), flags=" | ".join(flags))
    return row


def write_study_csv(layout, spec, state: dict) -> list[dict]:
    """Write ``study.csv`` (participants in the study's order); returns its rows."""
    import csv

    from rigs.atomic import atomic_open

    rows = [participant_row(s.participant, s.path, state.get(s.participant, {}), layout.session_dir(s.participant))
            for s in spec.sessions]
    cols = study_columns()
    with atomic_open(layout.csv, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=cols)
        w.writeheader()
        for r in rows:
            w.writerow({c: ("" if r.get(c) is None else ("yes" if r[c] is True else "no" if r[c] is False else r[c]))
                        for c in cols})
    return rows
