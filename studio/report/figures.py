"""Matplotlib figures of a report (returned open; the HTML embeds them, the PDF prints them)."""

from __future__ import annotations

import numpy as np

__all__ = ["STATUS_COLOURS", "frames_figure", "uncertainty_figure"]

STATUS_COLOURS = {"ok": "#1a7f37", "suspect": "#b35900", "failed": "#c0000f", "unchecked": "#777777"}


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def uncertainty_figure(table: dict):
    """Per length measurement (mm): the 95 % interval around the reported value, the ISO
    20685-1 allowance, the per-frame values and (simulated sessions) the truth."""
    plt = _plt()
    names = [n for n, r in table.items() if r["unit"] == "mm"]
    fig, ax = plt.subplots(figsize=(7.5, 0.32 * len(names) + 1.2))
    for i, n in enumerate(names):
        r = table[n]
        y = len(names) - 1 - i
        mae = r.get("iso20685_max_error")
        if mae is not None:
            ax.fill_betweenx([y - 0.35, y + 0.35], -mae, mae, color="#d9ead3", lw=0)
        half = 1.96 * r.get("sigma", 0.0)
        ax.plot([-half, half], [y, y], color="#1f4e9c", lw=3, solid_capstyle="butt")
        vals = np.array(list(r["per_frame"].values())) - r["mean"]
        ax.plot(vals, np.full(len(vals), y + 0.18), "|", color="#555", ms=6)
        if r.get("truth") is not None:
            ax.plot(r["truth"] - r["mean"], y, "x", color="#c0000f", ms=8, mew=2)
    ax.axvline(0, color="k", lw=0.6)
    ax.set_yticks(range(len(names)), [table[n].get("title", n) for n in reversed(names)], fontsize=8)
    ax.set_xlabel("difference from the reported value (mm)")
    ax.set_title("blue: 95 % interval · green: ISO 20685-1 allowance · ticks: single frames · ×: truth", fontsize=8)
    ax.grid(axis="x", alpha=0.3)
    fig.tight_layout()
    return fig


def frames_figure(fits: dict, qualities: dict):
    """Over frames: the silhouette cost (eq. 4.6) and the silhouette precision / recall, each
    frame coloured by its quality status."""
    plt = _plt()
    frames = sorted(fits)
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(9, 3))
    cost = [fits[f].costs.get("silhouette", fits[f].costs["total"]) for f in frames]
    colours = [STATUS_COLOURS.get(fits[f].status, "#777777") for f in frames]
    a1.plot(frames, cost, "-", color="#999", lw=1)
    a1.scatter(frames, cost, c=colours, zorder=3)
    a1.set_xlabel("frame")
    a1.set_ylabel("silhouette disagreement\n(mean contour distance, pixels)")
    a1.grid(alpha=0.3)
    qf = [f for f in sorted(qualities) if isinstance(qualities[f].get("silhouette_precision"), (int, float))]
    low = 0.7  # the y range reaches down to the lowest precision or recall shown
    if qf:
        precision = [qualities[f]["silhouette_precision"] for f in qf]
        recall = [qualities[f]["silhouette_recall"] for f in qf]
        a2.plot(qf, precision, "o-", label="precision")
        a2.plot(qf, recall, "s-", label="recall")
        a2.legend(fontsize=8)
        low = min(low, *precision, *recall)
    a2.set_xlabel("frame")
    a2.set_ylabel("share of silhouette pixels")
    a2.set_ylim(low, 1.0)
    a2.grid(alpha=0.3)
    from matplotlib.ticker import MaxNLocator

    for ax in (a1, a2):
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    fig.tight_layout()
    return fig
