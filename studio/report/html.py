"""``report/index.html`` of a fitted session: self-contained (images as base64 PNG), printable."""

from __future__ import annotations

import html
import json
import logging
import time
from pathlib import Path

import numpy as np

__all__ = ["page_html", "write_report"]

log = logging.getLogger(__name__)

_STATUS_STYLE = {"ok": "#1a7f37", "suspect": "#b35900", "failed": "#c0000f", "unchecked": "#777"}

_CSS = """body{font-family:sans-serif;max-width:1200px;margin:auto;padding:1em;color:#222}
table{border-collapse:collapse;margin:.5em 0}td,th{border:1px solid #ccc;padding:3px 7px;text-align:right;font-size:13px}
th{background:#f3f3f3}td.l,th.l{text-align:left}img{margin:2px;max-width:100%}
.sw{display:inline-block;width:1em;height:1em;margin:0 4px 0 12px;vertical-align:middle;border:1px solid #888}
.row{display:flex;flex-wrap:wrap}.meta td{text-align:left}.no{color:#c0000f;font-weight:bold}.yes{color:#1a7f37}
header{border-bottom:2px solid #333;margin-bottom:1em}footer{color:#666;font-size:12px;border-top:1px solid #ccc;margin-top:2em}
@media print{body{max-width:none;padding:0;font-size:11px}h2{page-break-before:always}h2.first{page-break-before:avoid}
img{page-break-inside:avoid;max-width:100%}table{page-break-inside:auto}tr{page-break-inside:avoid}
.noprint{display:none}}
@page{size:A4;margin:12mm}"""


def _esc(value) -> str:
    """Text for HTML content or a quoted attribute: every name and number a report embeds goes through here."""
    return html.escape(str(value), quote=True)


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
    rows = ["<tr><th>frame</th><th>status</th><th>silhouette precision</th><th>silhouette recall</th>"
            "<th class=l>reasons</th></tr>"]
    for f in sorted(qualities):
        q = qualities[f]
        pr = "".join(f"<td>{q[k]:.3f}</td>" if isinstance(q.get(k), (int, float)) else "<td>–</td>"
                     for k in ("silhouette_precision", "silhouette_recall"))
        rows.append(f"<tr><td>{_esc(f)}</td><td>{_status_html(q.get('status', 'unchecked'))}</td>{pr}"
                    f"<td class=l>{_esc('; '.join(_reason_texts(q)) or '–')}</td></tr>")
    return "<table>" + "".join(rows) + "</table>"


def _fmt(v, digits=1, sign=""):
    return "–" if v is None else f"{v:{sign}.{digits}f}"


def _table_html(table: dict) -> str:
    """The measurement table: value ± σ, 95 % interval, ISO 20685-1, ANSUR II, quality, truth."""
    has_truth = any(r["truth"] is not None for r in table.values())
    head = ("<tr><th class=l>measurement</th><th class=l>definition</th><th>value</th><th>± σ</th><th>95 % interval</th>"
            "<th>σ frames / calibration / fit / model</th><th>ISO 20685-1 limit</th><th>meets it</th>"
            "<th>ANSUR II percentile (z)</th><th class=l>quality</th>")
    head += "<th>truth</th><th>error</th>" if has_truth else ""
    rows = [head + "</tr>"]
    for name, r in table.items():
        u = _esc(r["unit"])
        st = r.get("status", "ok")
        d = 2 if r["unit"] == "kg/m²" else 1
        value = f"{r['mean']:.{d}f} {u}"
        if st != "ok":  # a flagged figure never looks like a clean one
            value = f"<s>{value}</s> <b style='color:{_STATUS_STYLE[st]}'>({_esc(st)})</b>"
        ci = r.get("ci95") or [None, None]
        comps = " / ".join(_fmt(r.get(k)) for k in ("sigma_frames", "sigma_calibration", "sigma_posterior", "sigma_model"))
        ok = r.get("iso20685_ok")
        meets = "–" if ok is None else ("<span class=yes>yes</span>" if ok else "<span class=no>no</span>")
        pop = r.get("population")
        pop_txt = "–" if pop is None else f"{_esc(pop['text'])} ({pop['z']:+.1f}, {_esc(pop['sex'])})"
        row = (f"<tr><td class=l title='{_esc(r.get('clause', ''))}'><b>{_esc(r.get('title', name))}</b><br>"
               f"<small>{_esc(r.get('clause', ''))}</small></td><td class=l><small>{_esc(r.get('definition', ''))}"
               f"{'<br><i>' + _esc(r['method']) + '</i>' if r.get('method') else ''}</small></td>"
               f"<td>{value}</td><td>{_fmt(r.get('sigma'), d)}</td>"
               f"<td>{_fmt(ci[0], d)} – {_fmt(ci[1], d)}</td><td>{comps}</td>"
               f"<td>{_fmt(r.get('iso20685_max_error'), 0)}</td><td>{meets}</td><td>{pop_txt}</td>"
               f"<td class=l>{_status_html(st, r.get('flags', []))}</td>")
        if has_truth:
            row += "<td>–</td><td>–</td>" if r["truth"] is None else f"<td>{r['truth']:.{d}f}</td><td>{r['error']:+.{d}f}</td>"
        rows.append(row + "</tr>")
    return "<table>" + "".join(rows) + "</table>"


def _calibration_html(unc: dict, segmentation: dict) -> str:
    info = unc.get("info", {})
    rms = info.get("calibration_rms_px", {})
    cams = sorted(set(rms) | set(segmentation))
    if not cams:
        return "<p>No calibration or segmentation figures recorded.</p>"
    rows = ["<tr><th class=l>camera</th><th>reprojection RMS (px)</th><th>mean silhouette coverage (% of image)</th>"
            "<th>share explained by the visual hull</th><th>precision</th><th>recall</th></tr>"]
    for c in cams:
        s = segmentation.get(c, {})
        cov = s.get("coverage")
        rows.append(f"<tr><td class=l>{_esc(c)}</td><td>{_fmt(rms.get(c), 3)}</td>"
                    f"<td>{_fmt(None if cov is None else 100 * cov, 2)}</td><td>{_fmt(s.get('hull_explained'), 3)}</td>"
                    f"<td>{_fmt(s.get('precision'), 3)}</td><td>{_fmt(s.get('recall'), 3)}</td></tr>")
    src = _esc(info.get("calibration_rms_source", "unknown"))
    return (f"<p>Reprojection error source: {src}; surface uncertainty from it: "
            f"{_fmt(info.get('surface_sigma_mm'), 2)} mm per point.</p><table>{''.join(rows)}</table>")


def _light_html(light: dict | None, camera_centres: dict | None, shadows=()) -> str:
    """The light section (thesis ch. 5): the light from above and its posterior, when estimated,
    and ``shadows`` (:class:`~studio.report.shadows.ShadowOverlay`): predicted against observed
    shadows per frame and camera."""
    if not light:
        return ""
    from studio.light.figures import posterior_figure, top_view_figure
    from studio.report.views import figure_base64

    rows = []
    for i, e in enumerate(light["lights"]):
        where = (f"at ({', '.join(f'{v:.2f}' for v in e['position'])}) m, {e['distance_m']:.2f} m from the subject "
                 f"(95 %: {e['distance_ci'][0]:+.1f} to {e['distance_ci'][1]:+.1f} %)" if e["kind"] == "point"
                 else f"towards ({', '.join(f'{v:.3f}' for v in e['direction'])})")
        rows.append(f"<li>light {i + 1}: {_esc(e['kind'])} {_esc(where)}, direction within "
                    f"{e['direction_ci_deg']:.2f}° (95 %)</li>")
    s = light["samples_summary"]
    return (f"<h2>Light</h2><p>Estimated from the shadows of frames {_esc(light['frames'])} (thesis eq. 5.9; posterior by "
            f"emcee, {s['n_samples']} samples, effective sample size {s['effective_sample_size']:.0f}).</p>"
            f"<ul>{''.join(rows)}</ul><div class='row'>"
            f"<img src=\"{figure_base64(top_view_figure(light, camera_centres))}\" alt=\"light from above\">"
            f"<img src=\"{figure_base64(posterior_figure(light))}\" alt=\"posterior of the light\"></div>"
            f"{_shadow_overlays_html(shadows)}")


def _shadow_overlays_html(shadows) -> str:
    """Per frame, every camera's shadow overlay with its shadow precision / recall."""
    from studio.fit import OVERLAY_COLORS
    from studio.report.views import png_base64

    if not shadows:
        return ""
    legend = " ".join(f"<span class='sw' style='background:rgb{tuple(int(v) for v in col)}'></span>{_esc(name)}"
                      for name, col in OVERLAY_COLORS.items())
    rows = []
    for f in sorted({s.frame for s in shadows}):
        figs = [f'<figure style="margin:2px"><img src="{png_base64(s.image)}" alt="shadow {_esc(s.camera)}">'
                f'<figcaption>{_esc(s.camera)}: shadow precision {_fmt(s.precision, 3)}, recall {_fmt(s.recall, 3)}'
                f'</figcaption></figure>' for s in shadows if s.frame == f]
        rows.append(f"<h3>Shadows of frame {_esc(f)}</h3><div class='row'>{''.join(figs)}</div>")
    return (f"<p>The shadow the body casts under the estimated light, less the body itself (model), against the "
            f"shadow the segmentation found (image); precision: share of the predicted shadow observed, recall: "
            f"share of the observed shadow predicted. Legend: {legend}.</p>{''.join(rows)}")


def page_html(data, *, max_overlay_frames: int = 4, light: dict | None = None,
              camera_centres: dict | None = None, shadows=()) -> str:
    """The whole page of a :class:`~studio.report.data.ReportData` (with ``light``, the
    contents of ``light/light.json``, a light section; ``shadows`` its shadow overlays)."""
    from rigs.imageio import read_image
    from studio.fit import OVERLAY_COLORS
    from studio.fit.quality import summary_line
    from studio.report.figures import frames_figure, uncertainty_figure
    from studio.report.views import LINE_COLOUR, POINT_COLOUR, RING_COLOUR, body_views, figure_base64, png_base64

    p = data.participant
    frames = sorted(data.fits)
    qual = summary_line({f: q for f, q in data.qualities.items() if q.get("status") != "unchecked"})
    unc = data.uncertainty.get("info", {})
    post = (f"Laplace approximation over the {unc.get('n_leading')} leading shape coefficients on frame(s) "
            f"{_esc(unc.get('posterior_frames'))}, temperature {unc.get('temperature')}"
            if unc.get("posterior_frames") else _esc(unc.get("posterior_note", "not computed")))
    model_source = unc.get("model_error_source", "not recorded")
    m = data.measured
    rest = body_views(data.rest_vertices, data.faces, size=(480, 720), points=m.points, lines=m.lines)
    posed = body_views(data.posed_vertices, data.faces, azimuths=(0, 45, 90), size=(480, 720))
    step = max(1, int(np.ceil(len(frames) / max_overlay_frames)))
    overlay_rows = []
    for f in frames[::step]:
        imgs = [f'<figure style="margin:2px"><img src="{png_base64(read_image(path))}" alt="{_esc(cam)}">'
                f'<figcaption>{_esc(cam)}</figcaption></figure>' for cam, path in data.overlays.get(f, [])]
        q = data.fits[f].quality
        overlay_rows.append(f"<h3>Frame {_esc(f)} — {_status_html(data.fits[f].status, _reason_texts(q))}</h3>"
                            f"<div class='row'>{''.join(imgs)}</div>")
    legend = " ".join(f"<span class='sw' style='background:rgb{tuple(int(v) for v in col)}'></span>{_esc(name)}"
                      for name, col in OVERLAY_COLORS.items())
    draw_legend = " ".join(f"<span class='sw' style='background:rgb{c}'></span>{t}" for c, t in (
        (POINT_COLOUR, "landmark"), (RING_COLOUR, "girth"), (LINE_COLOUR, "length, breadth, height")))
    meta = [("Participant", p.id or "(not given)"), ("Sex", p.sex or f"not given (population: {data.sex})"),
            ("Age", "not given" if p.age is None else f"{p.age:g} years"), ("Notes", p.notes or "–"),
            ("Session", data.session_name), ("Body model", data.gender),
            ("Frames", f"{len(frames)} fitted, {len(data.frames_used)} used for the measurements"
             if data.batch is None else f"{len(frames)} fitted; measured on the batch shape of frames {data.batch['frames']}"),
            ("Software", f"Silhouette & Shadow Studio {data.version}"),
            ("Fit settings", json.dumps(data.settings, sort_keys=True)[:600] or "–")]
    meta_html = "".join(f"<tr><th class=l>{_esc(k)}</th><td>{_esc(v)}</td></tr>" for k, v in meta)
    title = f"Body measurement report — {p.id or data.session_name}"
    return f"""<!doctype html><html><head><meta charset="utf-8"><title>{_esc(title)}</title><style>{_CSS}</style></head><body>
<header><h1>{_esc(title)}</h1><table class=meta>{meta_html}</table></header>
<h2 class=first>Measurements</h2>
<p>ISO 7250-1 definitions measured on the fitted body (mean shape over the frames used, standing pose; arm span with the arms
horizontal). σ combines the spread over frames (standard error of the mean), the calibration's reprojection error carried to
the body's surface, the fit's own posterior ({post}), and the body model's error on people it never saw (learned on
generated people, {_esc(model_source)}). The ISO 20685-1:2018 column is the maximum allowable error of a
scan-derived measurement; “meets it” compares the 95 % half-width with it. Percentiles against ANSUR II (US Army, 2012) of the
participant's sex. A figure resting on flagged frames or implausible against the population is struck through and marked.</p>
{_batch_html(data.batch)}{_table_html(data.table)}
<img src="{figure_base64(uncertainty_figure(data.table))}" alt="measurement uncertainty">
<h2>Landmarks and measurement lines</h2><p>{draw_legend}. Front, left, back, right.</p><img src="{png_base64(rest)}" alt="body with landmarks">
<p>Frame {_esc(frames[0])}, fitted pose:</p><img src="{png_base64(posed)}" alt="fitted pose">
<h2>Quality</h2><p>{_esc(qual or 'no quality gates recorded (fitted before they existed)')}.</p>
{_quality_html(data.qualities)}
<img src="{figure_base64(frames_figure(data.fits, data.qualities))}" alt="quality over frames">
{_light_html(light, camera_centres, shadows)}
<h2>Calibration and segmentation</h2>{_calibration_html(data.uncertainty, data.segmentation)}
<h2>Overlays</h2><p>Full resolution, one image per camera. Legend: {legend}.</p>
{''.join(overlay_rows)}
<footer>Generated {time.strftime('%Y-%m-%d %H:%M:%S')} by <code>studio report</code> (Silhouette &amp; Shadow Studio {_esc(data.version)}).
Method: Bălan, Detailed Human Shape and Pose from Images (annealed particle filter and staged Nelder–Mead on the silhouette cost, eq. 4.6).</footer>
</body></html>"""


def _batch_html(batch: dict | None) -> str:
    """The paragraph saying the measurements rest on the batch shape (thesis ch. 6), or nothing."""
    from studio.fit.batch_session import gender_warning

    if batch is None:
        return ""
    margin = ("" if batch.get("gender_margin") is None else
              f", gender by batch with a score margin of {batch['gender_margin']:.3f} per frame")
    cons = batch.get("consistency") or {}
    warn = (f" <b>Flagged: the frames may not show one person ({_esc('; '.join(cons.get('reasons', [])))}).</b>"
            if cons.get("flagged") else "")
    if (why := gender_warning(batch.get("gender_test"))) is not None:
        warn += f" <b>Flagged: {_esc(why)}; every figure is of the {_esc(batch['gender'])} model's body.</b>"
    return (f"<p class=batch>Measured on the <b>batch shape</b>: one body shape shared by frames "
            f"{_esc(batch['frames'])} with one pose each (thesis ch. 6, eq. 6.5–6.9), {_esc(batch['gender'])} model"
            f"{_esc(margin)}, {_esc(batch.get('clothing', ''))} clothing cost. The per-frame values and the spread are "
            f"those of the single-frame fits.{warn}</p>")


def write_report(source, *, participant=None, pdf: bool = False, posterior: bool = True,
                 max_overlay_frames: int = 4) -> Path:
    """Write ``report/index.html``, ``report/measurements.json`` and ``.csv`` (and with ``pdf``
    ``report/report.pdf``) for a fitted session (a :class:`~studio.workspace.Workspace`, a
    :class:`~studio.workspace.Layout` or a folder); ``participant`` a
    :class:`~studio.report.data.Participant`. Every name the page embeds is HTML-escaped and no
    machine path appears in it. Raises :class:`~studio.fit.FitError` when the session has no
    fit results."""
    from rigs.atomic import atomic_write_text
    from studio.report.data import gather
    from studio.report.measurements import write_measurements

    t0 = time.perf_counter()
    lay = _layout(source)
    ws = _workspace(source, lay)  # opened once: the uncertainty and the light section both read the capture
    data = gather(source if ws is None else ws, participant, posterior=posterior)
    write_measurements(lay, data.table, data.participant.to_json())
    light, centres, shadows = _light_of(ws, lay)
    p = atomic_write_text(lay.report_html, page_html(data, max_overlay_frames=max_overlay_frames, light=light,
                                                     camera_centres=centres, shadows=shadows))
    if pdf:
        from studio.report.pdf import write_pdf

        write_pdf(data, lay.report_pdf)
    log.info("report written to %s in %.1f s", p, time.perf_counter() - t0)
    return p


def _workspace(source, lay):
    """The :class:`~studio.workspace.Workspace` of ``source``, or None when the capture cannot be
    opened (the report then covers the fits alone; :func:`~studio.report.data.gather` says why)."""
    from studio.workspace import Workspace

    if isinstance(source, Workspace):
        return source
    try:
        return Workspace.open(lay.source, out=lay.root)
    except Exception:  # noqa: BLE001 - a report without the capture still reports the fits
        return None


def _light_of(ws, lay) -> tuple[dict | None, dict | None, list]:
    """``light/light.json`` (None when absent or unreadable: the report goes on without it), the
    calibrated camera centres {name: (x, y, z)} and the shadow overlays of two of its frames
    (empty when the capture ``ws`` (None: not readable), its segmentation or the bodies cannot be read)."""
    from studio.light import LightError, load_light
    from studio.report.shadows import shadow_overlays

    try:
        lights, light = load_light(lay.light_json)
    except LightError as exc:
        if lay.light_json.is_file():
            log.warning("report without the light: %s", exc)
        return None, None, []
    if ws is None:
        log.warning("report's light section without cameras or shadow overlays: the capture cannot be opened")
        return light, None, []
    try:
        centres = {c.name: c.center.tolist() for c in ws.cameras}
    except Exception as exc:  # noqa: BLE001 - the cameras and overlays are decoration of the light section
        log.warning("report's light section without cameras or shadow overlays: %s", exc)
        return light, None, []
    try:
        shadows = shadow_overlays(ws, lights, light)
    except Exception as exc:  # noqa: BLE001 - e.g. the segmentation was removed since the light was estimated
        log.warning("report's light section without shadow overlays: %s", exc)
        shadows = []
    return light, centres, shadows


def _layout(source):
    from studio.workspace import Layout, Workspace

    return source.layout if isinstance(source, Workspace) else source if isinstance(source, Layout) else Layout(source)
