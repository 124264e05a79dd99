"""``calibration_report.html``: how good a calibration is, in one self-contained page.

Sections (each only when its data is given): per-camera intrinsics (fx fy cx cy, RMS, views
used / rejected and why, per-view error bars, coverage map with advice where to show the
board next), the bundle adjustment (solver, RMS before/after, per-camera RMS, the view-graph
tree), the floor check per camera, and the rig drawn from above with the floor and the camera
frusta. Figures are matplotlib PNGs embedded as base64 (no pyplot global state).
"""

from __future__ import annotations

import base64
import html
import io
import logging
from pathlib import Path

import numpy as np

from calibration.intrinsics import coverage_advice

__all__ = ["render_report", "write_report", "rig_top_view"]

log = logging.getLogger(__name__)

_CSS = """
body{font-family:system-ui,sans-serif;margin:2em;max-width:1200px;color:#222}
table{border-collapse:collapse;margin:0.5em 0 1.5em}td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}
th{background:#f0f0f0}td.l,th.l{text-align:left}.bad{color:#b00}.ok{color:#070}
img{max-width:100%}.fig{display:inline-block;margin:4px;vertical-align:top}
"""


def _figure(width=5.0, height=3.5):
    from matplotlib.figure import Figure

    return Figure(figsize=(width, height), dpi=90)


def _png(fig) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", bbox_inches="tight")
    return '<img src="data:image/png;base64,' + base64.b64encode(buf.getvalue()).decode("ascii") + '">'


def _e(x) -> str:
    return html.escape(str(x))


def _view_error_figure(name: str, view_errors: dict, rejected: dict):
    fig = _figure(max(4.0, 0.25 * (len(view_errors) + len(rejected)) + 2), 2.8)
    ax = fig.add_subplot(111)
    names = list(view_errors)
    ax.bar(range(len(names)), [view_errors[n] for n in names], color="#4477aa", label="kept")
    outl = [v for v, r in rejected.items() if r.startswith("outlier")]
    ax.set_xticks(range(len(names)))
    ax.set_xticklabels(names, rotation=90, fontsize=6)
    ax.set_ylabel("RMS (px)")
    ax.set_title(f"{name}: per-view reprojection error" + (f" ({len(outl)} outliers dropped)" if outl else ""))
    return fig


def _coverage_figure(name: str, coverage: np.ndarray, image_size):
    fig = _figure(3.6, 3.6 * image_size[1] / image_size[0] + 0.4)
    ax = fig.add_subplot(111)
    im = ax.imshow(coverage, cmap="viridis", extent=(0, image_size[0], image_size[1], 0), interpolation="nearest")
    ax.set_title(f"{name}: corners per cell")
    fig.colorbar(im, ax=ax, fraction=0.046)
    return fig


def rig_top_view(cameras: dict, *, floor_extent=None, board_poses: dict | None = None, frustum_depth: float = 0.5):
    """Figure: the rig from above (world x-y), camera centres and frusta, the floor origin and axes."""
    fig = _figure(6.0, 6.0)
    ax = fig.add_subplot(111)
    if floor_extent is not None:
        (x0, y0), (x1, y1) = floor_extent
        from matplotlib.patches import Rectangle

        ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, facecolor="#eeeecc", edgecolor="#999966", label="floor"))
    if board_poses:
        pts = np.array([t for R, t in board_poses.values()])
        ax.scatter(pts[:, 0], pts[:, 1], s=6, color="#aaaaaa", label="board views")
    for name, cam in cameras.items():
        c = cam.center
        w, h = cam.size
        corners = np.array([[0, 0], [w - 1, 0], [w - 1, h - 1], [0, h - 1]], float)
        rays = np.c_[(corners - cam.K[:2, 2]) / np.diag(cam.K)[:2], np.ones(4)] * frustum_depth
        far = rays @ cam.R + c  # R^T ray + c
        for p in far:
            ax.plot([c[0], p[0]], [c[1], p[1]], color="#cc6677", lw=0.8)
        loop = np.vstack([far, far[:1]])
        ax.plot(loop[:, 0], loop[:, 1], color="#cc6677", lw=0.8)
        ax.plot(c[0], c[1], "o", color="#882255")
        ax.annotate(name, c[:2], textcoords="offset points", xytext=(4, 4), fontsize=8)
    ax.arrow(0, 0, 0.3, 0, color="r", width=0.01)
    ax.arrow(0, 0, 0, 0.3, color="g", width=0.01)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title("rig from above (z up, floor z = 0)")
    ax.grid(alpha=0.3)
    return fig


def render_report(
    *,
    title: str = "Calibration report",
    intrinsics: dict | None = None,
    extrinsics=None,
    floor=None,
    cameras: dict | None = None,
    detection_summary: dict | None = None,
    notes: list[str] | None = None,
) -> str:
    """The report as an HTML string (see the module docstring for the sections)."""
    out = [f"<!doctype html><html><head><meta charset='utf-8'><title>{_e(title)}</title><style>{_CSS}</style></head><body>"]
    out.append(f"<h1>{_e(title)}</h1>")
    for n in notes or []:
        out.append(f"<p>{_e(n)}</p>")
    if detection_summary:
        out.append("<h2>Board detection</h2><table><tr><th class=l>camera</th><th>views</th><th>ok</th><th>partial</th><th>rejected</th><th class=l>rejected views (reason)</th></tr>")
        for cam, dets in detection_summary.items():
            st = [d.status for d in dets]
            rej = "; ".join(f"{d.view}: {d.reason}" for d in dets if d.status == "rejected")
            out.append(f"<tr><td class=l>{_e(cam)}</td><td>{len(dets)}</td><td>{st.count('ok')}</td><td>{st.count('partial')}</td><td>{st.count('rejected')}</td><td class=l>{_e(rej)}</td></tr>")
        out.append("</table>")
    if intrinsics:
        out.append("<h2>Intrinsics</h2><table><tr><th class=l>camera</th><th>model</th><th>fx</th><th>fy</th><th>cx</th><th>cy</th><th>RMS px</th><th>views</th><th>corners</th><th>coverage</th><th class=l>rejected views</th></tr>")
        for cam, r in intrinsics.items():
            rej = "; ".join(f"{v}: {why}" for v, why in r.rejected.items())
            cls = "ok" if r.rms < 0.5 else "bad"
            out.append(
                f"<tr><td class=l>{_e(cam)}</td><td>{r.model}</td><td>{r.fx:.2f}</td><td>{r.fy:.2f}</td><td>{r.cx:.2f}</td><td>{r.cy:.2f}</td>"
                f"<td class={cls}>{r.rms:.3f}</td><td>{len(r.view_errors)}</td><td>{r.n_corners}</td><td>{100 * (r.coverage > 0).mean():.0f}%</td><td class=l>{_e(rej)}</td></tr>"
            )
        out.append("</table>")
        for cam, r in intrinsics.items():
            out.append(f"<h3>{_e(cam)}</h3>")
            advice = coverage_advice(r.coverage)
            if advice:
                out.append(f"<p class=bad>{_e(advice)}.</p>")
            out.append(f"<div class=fig>{_png(_view_error_figure(cam, r.view_errors, r.rejected))}</div>")
            out.append(f"<div class=fig>{_png(_coverage_figure(cam, r.coverage, r.image_size))}</div>")
    if extrinsics is not None:
        ba = extrinsics.bundle
        out.append("<h2>Extrinsics (bundle adjustment)</h2>")
        out.append(f"<p>{_e(ba.method)}; {ba.nfev} evaluations. RMS {ba.rms_before:.3f} px before, <b>{ba.rms_after:.3f} px</b> after; reference camera <b>{_e(extrinsics.info.get('reference'))}</b>.</p>")
        out.append("<table><tr><th class=l>camera</th><th>RMS px</th><th class=l>chained from</th><th>shared views</th><th>relative-pose spread (deg)</th></tr>")
        parents = {c: (p, n, s) for p, c, n, s in extrinsics.info.get("tree", [])}
        for cam, rms in ba.camera_rms.items():
            p, n, s = parents.get(cam, ("(reference)", "", ""))
            s = f"{s:.2f}" if s != "" else ""
            out.append(f"<tr><td class=l>{_e(cam)}</td><td>{rms:.3f}</td><td class=l>{_e(p)}</td><td>{n}</td><td>{s}</td></tr>")
        out.append("</table>")
        for k, v in extrinsics.info.items():
            if k not in ("tree", "pnp_rms", "reference", "shared_views"):
                out.append(f"<p>{_e(k)}: {_e(v)}</p>")
    if floor is not None:
        out.append("<h2>Floor and world frame</h2><p>World frame from the floor board: origin at its first corner, z up, floor z = 0. Each camera on its own (PnP) places the floor corners; the table gives their largest distance from z = 0 and the reprojection error of the calibrated floor board.</p>")
        out.append("<table><tr><th class=l>camera / placement</th><th>max |z| mm</th><th>mean z mm</th><th>reprojection px</th><th>corners</th></tr>")
        for cam, v in floor.check.items():
            cls = "ok" if v["plane_mm"] < 10 else "bad"
            out.append(f"<tr><td class=l>{_e(cam)}</td><td class={cls}>{v['plane_mm']:.2f}</td><td>{v['mean_height_mm']:.2f}</td><td>{v['reproj_px']:.3f}</td><td>{v['corners']}</td></tr>")
        out.append("</table>")
    if cameras:
        centres = np.array([c.center for c in cameras.values()])
        r = max(1.0, float(np.abs(centres[:, :2]).max()) * 0.6)
        out.append("<h2>The rig from above</h2>")
        out.append(_png(rig_top_view(cameras, floor_extent=((-r, -r), (r, r)),
                                     frustum_depth=0.25 * max(1.0, float(np.ptp(centres[:, :2], axis=0).max())))))
        out.append("<table><tr><th class=l>camera</th><th>x m</th><th>y m</th><th>z m</th><th>fx</th><th>size</th></tr>")
        for n, c in cameras.items():
            x, y, z = c.center
            out.append(f"<tr><td class=l>{_e(n)}</td><td>{x:.3f}</td><td>{y:.3f}</td><td>{z:.3f}</td><td>{c.K[0, 0]:.1f}</td><td>{c.size[0]}x{c.size[1]}</td></tr>")
        out.append("</table>")
    out.append("</body></html>")
    return "\n".join(out)


def write_report(path: str | Path, **sections) -> Path:
    """Render and write the report atomically; returns the path."""
    from rigs.atomic import atomic_write_text

    return atomic_write_text(Path(path), render_report(**sections))
