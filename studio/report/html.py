"""``report/index.html`` of a fitted session: self-contained (images as base64 PNG)."""

from __future__ import annotations

import html
import json
import logging
import time
from pathlib import Path

import numpy as np

from studio.fit.errors import FitError

__all__ = ["write_report"]

log = logging.getLogger(__name__)



def _esc(value) -> str:
    """Text for HTML content or a quoted attribute: every name and number a report embeds goes through here."""
    return html.escape(str(value), quote=True)


def _cost_figure(fits: dict) -> str:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from studio.report.views import figure_base64

    frames = sorted(fits)
    fig, ax = plt.subplots(figsize=(6.5, 3))
    tot = [fits[f].costs["total"] for f in frames]
    ax.plot(frames, tot, "o-", color="k", label="total")
    views = sorted(fits[frames[0]].costs.get("silhouette_per_view", {}))
    for v in views:
        ax.plot(frames, [fits[f].costs["silhouette_per_view"][v] for f in frames], ".--", label=v)
    ax.set_xlabel("frame")
    ax.set_ylabel("cost (eq. 4.6, full-res px)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=3)
    return figure_base64(fig)


def _measurement_figure(table: dict) -> str:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from studio.report.views import figure_base64

    names = [n for n in table if table[n]["unit"] == "mm"]
    fig, ax = plt.subplots(figsize=(6.5, 3))
    for i, n in enumerate(names):
        vals = np.array(list(table[n]["per_frame"].values()))
        ax.plot(np.full(len(vals), i), vals - table[n]["mean"], "o", color="C0", alpha=0.6)
        if table[n]["truth"] is not None:
            ax.plot(i, table[n]["truth"] - table[n]["mean"], "x", color="C3", ms=9)
    ax.axhline(0, color="k", lw=0.6)
    ax.set_xticks(range(len(names)), [n.replace("_", " ") for n in names], rotation=35, ha="right", fontsize=8)
    ax.set_ylabel("per-frame value − mean (mm)\n× = truth")
    ax.grid(alpha=0.3)
    return figure_base64(fig)


_STATUS_STYLE = {"ok": "#1a7f37", "suspect": "#b35900", "failed": "#c0000f", "unchecked": "#777"}


def _status_html(status: str, reasons=()) -> str:
    """A coloured status word, its reasons as the hover text (and spelled out when not ok)."""
    text = "; ".join(reasons)
    tail = f" <small>{_esc(text)}</small>" if text and status != "ok" else ""
    return (f"<b style='color:{_STATUS_STYLE.get(status, '#777')}' title='{_esc(text)}'>"
            f"{'⚠ ' if status not in ('ok', 'unchecked') else ''}{_esc(status)}</b>{tail}")


def _reason_texts(quality: dict) -> list[str]:
    return [(f"{r['view']}: " if r.get("view") else "") + r["message"] for r in quality.get("reasons", [])]


def _quality_html(qualities: dict) -> str:
    """One row per frame (fitted or refused): status, precision / recall, reasons."""
    rows = ["<tr><th>frame</th><th>status</th><th>precision</th><th>recall</th><th>reasons</th></tr>"]
    for f in sorted(qualities):
        q = qualities[f]
        pr = "".join(f"<td>{q[k]:.3f}</td>" if isinstance(q.get(k), (int, float)) else "<td>–</td>"
                     for k in ("silhouette_precision", "silhouette_recall"))
        rows.append(f"<tr><td>{_esc(f)}</td><td>{_status_html(q.get('status', 'unchecked'))}</td>{pr}"
                    f"<td style='text-align:left'>{_esc('; '.join(_reason_texts(q)) or '–')}</td></tr>")
    return "<table>" + "".join(rows) + "</table>"


def _table_html(table: dict) -> str:
    has_truth = any(r["truth"] is not None for r in table.values())
    has_anny = any(r.get("truth_anny") is not None and r.get("truth_source") == "studio" for r in table.values())
    head = "<tr><th>measurement</th><th>mean ± std over frames</th><th>quality</th>"
    head += "<th>truth</th><th>error</th>" if has_truth else ""
    head += "<th>truth (Anny's definition)</th><th>error</th>" if has_anny else ""
    rows = [head + "</tr>"]

    def pair(value, error, u):
        return "<td>–</td><td>–</td>" if value is None else f"<td>{value:.1f} {u}</td><td>{error:+.1f} {u}</td>"

    for name, r in table.items():
        u = _esc(r["unit"])
        st = r.get("status", "ok")
        value = f"{r['mean']:.1f} ± {r['std']:.1f} {u}"
        if st != "ok":  # a flagged figure never looks like a clean one
            value = f"<s>{value}</s> <b style='color:{_STATUS_STYLE[st]}'>({_esc(st)})</b>"
        row = (f"<tr><td>{_esc(name.replace('_', ' '))}</td><td>{value}</td>"
               f"<td style='text-align:left'>{_status_html(st, r.get('flags', []))}</td>")
        if has_truth:
            row += pair(r["truth"], r["error"], u)
        if has_anny:
            row += pair(r.get("truth_anny"), r.get("error_anny"), u)
        rows.append(row + "</tr>")
    return "<table>" + "".join(rows) + "</table>"


def write_report(source, *, max_overlay_frames: int = 6, extra: dict | None = None) -> Path:
    """Write ``report/index.html``, ``report/measurements.json`` and ``.csv`` for a fitted session
    (a :class:`~studio.workspace.Workspace`, a :class:`~studio.workspace.Layout` or a folder).

    ``extra`` {title: text} adds plain-text notes (e.g. what the demo did not do). Every name
    the page embeds is HTML-escaped. Raises :class:`~studio.fit.FitError` when the session has
    no fit results.
    """
    from rigs.atomic import atomic_write_text
    from rigs.imageio import read_image
    from studio.body import BodyModel
    from studio.fit import OVERLAY_COLORS, load_fits, load_quality
    from studio.fit.quality import summary_line
    from studio.report.measurements import load_truth, measurement_table, write_measurements
    from studio.report.views import body_views, png_base64
    from studio.workspace import Layout, Workspace

    t0 = time.perf_counter()
    lay = source.layout if isinstance(source, Workspace) else source if isinstance(source, Layout) else Layout(source)
    session_path = lay.source
    if not session_path.is_dir():
        raise FitError(f"{session_path}: no such session folder")
    fits = load_fits(lay)
    qualities = load_quality(lay)
    genders = {f.gender for f in fits.values()}
    gender = sorted(genders)[0]
    model = BodyModel.load(gender)
    truth = load_truth(lay)
    table = measurement_table(model, fits, truth)
    write_measurements(lay, table)
    frames = sorted(fits)
    shape = np.mean([fits[f].shape for f in frames], axis=0)
    rest = body_views(model.vertices(shape), model.faces)
    posed = body_views(model.vertices(fits[frames[0]].shape, fits[frames[0]].pose), model.faces, azimuths=(0, 45, 90))
    seq = {}
    if lay.fit_sequence.is_file():
        seq = json.loads(lay.fit_sequence.read_text())
    step = max(1, int(np.ceil(len(frames) / max_overlay_frames)))
    overlay_rows = []
    fdir = lay.fit_dir / "overlay"
    cameras = sorted(p.name for p in fdir.iterdir() if p.is_dir()) if fdir.is_dir() else []
    for f in frames[::step]:
        imgs = []
        for cam in cameras:
            p = lay.fit_overlay(cam, f)
            if p.is_file():
                im = read_image(p)
                imgs.append(f'<img src="{png_base64(im[::2, ::2])}" title="{_esc(cam)}" alt="{_esc(cam)}">')
        c = fits[f].costs
        q = fits[f].quality
        overlay_rows.append(f"<h3>frame {_esc(f)} — cost {c['total']:.2f} — "
                            f"{_status_html(fits[f].status, _reason_texts(q))}</h3><div class='row'>{''.join(imgs)}</div>")
    legend = " ".join(
        f"<span class='sw' style='background:rgb{tuple(int(v) for v in col)}'></span>{_esc(name)}"
        for name, col in OVERLAY_COLORS.items()
    )
    timing = np.mean([fits[f].timings.get("total", np.nan) for f in frames])
    notes = "".join(f"<h3>{_esc(k)}</h3><pre>{_esc(v)}</pre>" for k, v in (extra or {}).items())
    page = f"""<!doctype html><html><head><meta charset="utf-8"><title>Body fit report — {_esc(session_path.name)}</title>
<style>body{{font-family:sans-serif;max-width:1100px;margin:auto;padding:1em}} table{{border-collapse:collapse}}
td,th{{border:1px solid #ccc;padding:3px 8px;text-align:right}} img{{margin:2px;max-width:100%}}
.sw{{display:inline-block;width:1em;height:1em;margin:0 4px 0 12px;vertical-align:middle;border:1px solid #888}}
.row{{display:flex;flex-wrap:wrap}}</style></head><body>
<h1>Body shape and pose from silhouettes</h1>
<p>Session <code>{_esc(str(session_path))}</code>: {len(frames)} fitted frame(s) ({_esc(str(frames[0]))}…{_esc(str(frames[-1]))}),
model <b>{_esc(gender)}</b>{' (chosen by lower cost: ' + _esc(json.dumps(seq.get('gender_costs'))) + ')' if seq.get('gender_costs') else ''};
mean fit time {timing:.1f} s per frame. Thesis ch. 4: annealed particle filter on the pose, staged Nelder–Mead on pose and shape,
silhouette cost eq. 4.6 with coarse-to-fine pyramid levels.</p>
<h2>Quality</h2>
<p>{_esc(summary_line({f: q for f, q in qualities.items() if q.get('status') != 'unchecked'}) or 'no quality gates recorded (fitted before they existed)')}.
A <b>suspect</b> or <b>failed</b> frame is left out of the measurements while clean frames exist; a figure resting on flagged frames,
or implausible against ANSUR II, is struck through and marked.</p>
{_quality_html(qualities)}
<h2>Measurements</h2>
<p>From the fitted shape of every frame (lengths in mm, rest pose; arm span in a T-pose).
Spread = standard deviation over frames (thesis §4.8.6).{' Truth: the simulated person measured with the same definitions as the fit (and, where it differs, with the simulator’s Anny anthropometry).' if truth else ''}</p>
{_table_html(table)}
<img src="{_measurement_figure(table)}">
<h2>Cost per frame</h2><img src="{_cost_figure(fits)}">
<h2>Fitted body</h2><p>Mean shape over frames, rest pose, front / left / back / right:</p><img src="{png_base64(rest)}">
<p>Frame {_esc(frames[0])}, fitted pose:</p><img src="{png_base64(posed)}">
<h2>Overlays</h2><p>Legend: {legend}. One image per camera (half resolution).</p>
{''.join(overlay_rows)}
{notes}
<p style="color:#777">Generated {time.strftime('%Y-%m-%d %H:%M:%S')} by <code>studio report</code>.</p>
</body></html>"""
    p = atomic_write_text(lay.report_html, page)
    log.info("report written to %s in %.1f s", p, time.perf_counter() - t0)
    return p
