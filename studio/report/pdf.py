"""``report/report.pdf``: the printable pages of a report, drawn with matplotlib (no browser).

Page 1: participant, session and the measurement table (flagged figures marked, never clean);
page 2: the body with its landmarks and measurement lines; page 3: uncertainty against the ISO
20685-1 allowance; page 4: quality over frames and the calibration / segmentation figures;
then one page of overlays per shown frame.
"""

from __future__ import annotations

import io
import textwrap
from pathlib import Path

import numpy as np

__all__ = ["write_pdf"]

A4 = (8.27, 11.69)


def _text_page(plt, title: str, lines: list[str]):
    fig = plt.figure(figsize=A4)
    fig.text(0.06, 0.96, title, fontsize=15, weight="bold", va="top")
    fig.text(0.06, 0.92, "\n".join(lines), fontsize=8.5, va="top", family="monospace")
    return fig


def _measurement_rows(table: dict) -> tuple[list[str], list[list[str]], list[str]]:
    cols = ["measurement", "value", "95 % interval", "ISO 20685-1", "ANSUR II", "quality"]
    rows, colours = [], []
    for r in table.values():
        d = 2 if r["unit"] == "kg/m²" else 1
        st = r.get("status", "ok")
        value = f"{r['mean']:.{d}f} {r['unit']}"
        if st != "ok":  # never printed clean: marked, and the row shaded
            value = f"⚠ {value}"
        ci = r.get("ci95") or [np.nan, np.nan]
        ok = r.get("iso20685_ok")
        iso = "–" if ok is None else f"{r['iso20685_max_error']:.0f} mm: {'yes' if ok else 'NO'}"
        pop = r.get("population")
        rows.append([r.get("title", ""), value, f"{ci[0]:.{d}f} – {ci[1]:.{d}f}", iso,
                     "–" if pop is None else f"{pop['text']} ({pop['z']:+.1f})",
                     st + ("" if st == "ok" else ": " + textwrap.shorten("; ".join(r.get("flags", [])), 28))])
        colours.append({"ok": "white", "suspect": "#fde6c8", "failed": "#f8c9cc"}.get(st, "white"))
    return cols, rows, colours


def write_pdf(data, path: str | Path) -> Path:
    """Write the pages (module doc) of a :class:`~studio.report.data.ReportData` to ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.backends.backend_pdf import PdfPages
    from matplotlib.patches import Patch

    from rigs.atomic import atomic_write_bytes
    from rigs.imageio import read_image
    from studio.fit import OVERLAY_COLORS
    from studio.fit.quality import summary_line
    from studio.report.figures import frames_figure, uncertainty_figure
    from studio.report.views import body_views

    p = data.participant
    buf = io.BytesIO()
    with PdfPages(buf) as pdf:
        fig = plt.figure(figsize=A4)
        fig.text(0.06, 0.965, f"Body measurement report — {p.id or data.session_name}", fontsize=14, weight="bold",
                 va="top")
        meta = [f"Participant: {p.id or '(not given)'}   Sex: {p.sex or 'not given'}   "
                f"Age: {'not given' if p.age is None else f'{p.age:g}'}",
                f"Session: {data.session_name}   Body model: {data.gender}   Frames used: {len(data.frames_used)} of "
                f"{len(data.fits)}   Software: Silhouette & Shadow Studio {data.version}",
                textwrap.shorten(f"Notes: {p.notes or '–'}", 140),
                *textwrap.wrap("Quality: " + summary_line({f: q for f, q in data.qualities.items()
                                                           if q.get("status") != "unchecked"}), 120)[:3]]
        fig.text(0.06, 0.93, "\n".join(meta), fontsize=8, va="top")
        cols, rows, colours = _measurement_rows(data.table)
        ax = fig.add_axes([0.04, 0.05, 0.92, 0.8])
        ax.axis("off")
        t = ax.table(cellText=rows, colLabels=cols, loc="upper center", cellLoc="left",
                     colWidths=[0.25, 0.14, 0.16, 0.1, 0.11, 0.24],
                     cellColours=[[c] * len(cols) for c in colours])
        t.auto_set_font_size(False)
        t.set_fontsize(6.5)
        t.scale(1, 1.5)
        fig.text(0.06, 0.03, "ISO 7250-1 definitions; σ = frames ⊕ calibration ⊕ fit posterior ⊕ model error. A struck figure in "
                 "the HTML is marked ⚠ and shaded here (orange: suspect, red: failed).", fontsize=7)
        pdf.savefig(fig)
        plt.close(fig)

        m = data.measured
        img = body_views(data.rest_vertices, data.faces, size=(480, 720), points=m.points, lines=m.lines)
        fig = plt.figure(figsize=A4)
        fig.text(0.06, 0.96, "Landmarks (red), girths (blue), lengths and heights (orange)", fontsize=11, va="top")
        ax = fig.add_axes([0.02, 0.35, 0.96, 0.58])
        ax.imshow(img)
        ax.axis("off")
        pdf.savefig(fig)
        plt.close(fig)

        fig = uncertainty_figure(data.table)
        pdf.savefig(fig)
        plt.close(fig)
        fig = frames_figure(data.fits, data.qualities)
        pdf.savefig(fig)
        plt.close(fig)
        info = data.uncertainty.get("info", {})
        lines = [f"Reprojection error source: {info.get('calibration_rms_source', 'unknown')}"]
        for cam, rms in sorted(info.get("calibration_rms_px", {}).items()):
            s = data.segmentation.get(cam, {})
            lines.append(f"{cam:>12s}: RMS {rms:.3f} px   coverage {100 * s.get('coverage', np.nan):.2f} %   "
                         f"hull {s.get('hull_explained', np.nan):.3f}   precision {s.get('precision', np.nan):.3f}   "
                         f"recall {s.get('recall', np.nan):.3f}")
        fig = _text_page(plt, "Calibration and segmentation", lines)
        pdf.savefig(fig)
        plt.close(fig)
        for f in sorted(data.overlays)[:2]:
            shots = data.overlays[f]
            if not shots:
                continue
            fig, axes = plt.subplots(int(np.ceil(len(shots) / 2)), 2, figsize=A4, squeeze=False)
            for ax, (cam, pth) in zip(axes.ravel(), shots):
                ax.imshow(read_image(pth))
                ax.set_title(f"frame {f}, {cam}", fontsize=8)
            for ax in axes.ravel():
                ax.axis("off")
            fig.suptitle(f"Overlays of frame {f} at full resolution", fontsize=10)
            fig.legend(handles=[Patch(facecolor=np.asarray(c) / 255.0, edgecolor="#888", label=n)
                                for n, c in OVERLAY_COLORS.items()], loc="lower center", ncol=3, fontsize=8)
            pdf.savefig(fig)
            plt.close(fig)
    return atomic_write_bytes(path, buf.getvalue(), mkdir=True)
