"""The study report, ``report/index.html`` of a study folder (self-contained): the participants'
measurements against the ANSUR II distributions, the flagged participants with their reasons,
the sessions that failed with theirs, and a link to every session's own report."""

from __future__ import annotations

import os

import numpy as np

from studio.report.html import _esc, _status_html
from studio.study.table import UNITS

__all__ = ["write_study_report"]

_OK, _FLAGGED = "#0072b2", "#c0000f"


def _distribution_figure(rows: list[dict]) -> str | None:
    """Per ANSUR II measurement and sex: the population's normal density (p1–p99 shaded) and
    every participant's value (red: flagged). None when no participant has a measurement."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from studio.fit.quality import population
    from studio.report.views import figure_base64

    sexes = population()["sexes"]
    done = [r for r in rows if r["status"] == "done" and r.get("gender") in sexes]
    present = [g for g in sexes if any(r["gender"] == g for r in done)]
    if not present:
        return None
    names = [n for n in sexes[present[0]] if n in UNITS]
    fig, axes = plt.subplots(len(names), len(present), figsize=(4.2 * len(present), 1.9 * len(names)), squeeze=False)
    for j, sex in enumerate(present):
        for i, name in enumerate(names):
            ax = axes[i, j]
            p = sexes[sex][name]
            scale = 1.0 if UNITS[name] == "kg" else 1000.0
            mu, sd = p["mean"] * scale, p["std"] * scale
            x = np.linspace(mu - 4.5 * sd, mu + 4.5 * sd, 300)
            ax.plot(x, np.exp(-0.5 * ((x - mu) / sd) ** 2), color="k", lw=1)
            ax.axvspan(p["p01"] * scale, p["p99"] * scale, color="0.85", zorder=0)
            for r in (r for r in done if r["gender"] == sex):
                v = r.get(f"{name}_{UNITS[name]}")
                if v is None:
                    continue
                color = _FLAGGED if r.get(f"{name}_status", "ok") != "ok" else _OK
                ax.plot([v], [0.08], "v", color=color, ms=8)
                ax.annotate(r["participant"], (v, 0.12), fontsize=6, rotation=60, color=color)
            ax.set_yticks([])
            ax.set_ylim(0, 1.25)
            ax.set_title(f"{name.replace('_', ' ')} ({UNITS[name]}), ANSUR II {sex} (n={p['n']})", fontsize=8)
            ax.tick_params(labelsize=7)
    fig.tight_layout()
    return figure_base64(fig)


def _value(row: dict, name: str) -> str:
    u = UNITS[name]
    v = row.get(f"{name}_{u}")
    if v is None:
        return "–"
    text = f"{v:.1f} ± {row.get(f'{name}_sd_{u}', 0.0):.1f}"
    st = row.get(f"{name}_status", "ok")
    return text if st == "ok" else f"<s>{text}</s> ({_esc(st)})"


def write_study_report(layout, spec, rows: list[dict]):
    """Write the study report of ``rows`` (:func:`studio.study.table.write_study_csv`); its path."""
    from rigs.atomic import atomic_write_text

    out = layout.report_html
    out.parent.mkdir(parents=True, exist_ok=True)
    done = [r for r in rows if r["status"] == "done"]
    failed = [r for r in rows if r["status"] == "failed"]
    flagged = [r for r in done if r["flagged"]]
    shown = ("stature", "arm_span", "chest_circumference", "waist_circumference", "hip_circumference", "mass")
    head = "".join(f"<th>{_esc(n.replace('_', ' '))} ({UNITS[n]})</th>" for n in shown)
    table = [f"<tr><th>participant</th><th>status</th><th>gender</th><th>frames</th><th>quality</th>{head}"
             "<th>report</th></tr>"]
    for r in rows:
        report = layout.session_dir(r["participant"]) / "report" / "index.html"
        link = (f"<a href='{_esc(os.path.relpath(report, out.parent))}'>report</a>" if report.is_file() else "–")
        status = _status_html("failed" if r["status"] == "failed" else "suspect" if r["flagged"] else "ok",
                              [r.get("flags", "")] if r["flagged"] else ())
        cells = "".join(f"<td>{_value(r, n)}</td>" for n in shown)
        table.append(f"<tr><td>{_esc(r['participant'])}</td><td style='text-align:left'>{status}</td>"
                     f"<td>{_esc(r.get('gender') or '–')}</td><td>{_esc(r.get('frames', '–'))}</td>"
                     f"<td>{_esc(r.get('quality') or '–')}</td>{cells}<td>{link}</td></tr>")
    fig = _distribution_figure(rows)
    parts = [
        "<!doctype html><html><head><meta charset='utf-8'><title>Study report</title><style>"
        "body{font-family:sans-serif;margin:2em;max-width:1300px} table{border-collapse:collapse;font-size:13px}"
        "td,th{border:1px solid #ccc;padding:3px 7px;text-align:right} th{background:#eee} li{margin:.3em 0}"
        "</style></head><body>",
        f"<h1>Study: {len(rows)} participant(s)</h1>",
        f"<p>{len(done)} measured ({len(flagged)} flagged), {len(failed)} failed. Source: "
        f"{_esc(spec.source or 'session folders given on the command line')}; table: "
        f"<code>{_esc(layout.csv.name)}</code>.</p>",
        "<h2>Participants</h2><p>Measurements: mean ± standard deviation over the frames used; struck "
        "through when the quality gates or ANSUR II flag them.</p><table>" + "".join(table) + "</table>",
        "<h2>Against ANSUR II</h2>" + (
            f"<p>Black: the ANSUR II population (normal density from its mean and SD; grey: 1st–99th "
            f"percentile). Marks: participants (red: that measurement is flagged).</p>"
            f"<img src='{fig}'>" if fig else "<p>No participant was measured.</p>"),
        "<h2>Flagged participants</h2>" + ("<ul>" + "".join(
            f"<li><b>{_esc(r['participant'])}</b>: {_esc(r['flags'])}</li>" for r in flagged) + "</ul>"
            if flagged else "<p>None.</p>"),
        "<h2>Failed sessions</h2>" + ("<ul>" + "".join(
            f"<li><b>{_esc(r['participant'])}</b> ({_esc(r['session'])}): {_esc(r['reason'])}</li>" for r in failed)
            + "</ul>" if failed else "<p>None.</p>"),
        "</body></html>",
    ]
    return atomic_write_text(out, "\n".join(parts))
