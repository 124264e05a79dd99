"""Figures of an estimated light (``light/light.json``): the scene from above and the posterior.

:func:`top_view_figure` draws the cameras, the subject's centre, each light (a point light at
its position, a directional one as an arrow towards it) with its posterior samples;
:func:`posterior_figure` the pairwise scatter of the posterior samples (a corner plot: azimuth,
elevation in degrees, distance in metres), the estimate marked.
"""

from __future__ import annotations

import numpy as np

from studio.report.figures import _plt

__all__ = ["posterior_figure", "top_view_figure"]


def _names(light: dict) -> list[str]:
    return list(light["samples_summary"]["parameters"])


def _samples(light: dict) -> np.ndarray:
    s = np.asarray(light.get("samples", []), dtype=float)
    return s.reshape(len(s), -1) if s.size else np.zeros((0, len(_names(light))))


def _positions(light: dict, samples: np.ndarray, index: int) -> np.ndarray:
    """(S, 2) floor (x, y) of light ``index`` for each sample (a directional light: 3 m along
    its direction from the centre)."""
    d = 3 if light["kind"] == "point" else 2
    th = samples[:, index * d:(index + 1) * d]
    r = th[:, 2] if d == 3 else np.full(len(th), 3.0)
    c = np.asarray(light["centre"], float)
    return np.stack([c[0] + r * np.cos(th[:, 1]) * np.cos(th[:, 0]), c[1] + r * np.cos(th[:, 1]) * np.sin(th[:, 0])], 1)


def top_view_figure(light: dict, camera_centres: dict | None = None):
    """The scene from above (metres): cameras, the subject's centre, the light(s) and samples."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(5.5, 5.0))
    c = np.asarray(light["centre"], float)
    for name, pos in (camera_centres or {}).items():
        ax.plot(pos[0], pos[1], "s", color="#555")
        ax.annotate(name, (pos[0], pos[1]), fontsize=7, xytext=(3, 3), textcoords="offset points")
    ax.plot(c[0], c[1], "o", color="#1f4e9c", ms=9, label="subject (mean floor position)")
    samples = _samples(light)
    for i, entry in enumerate(light["lights"]):
        if len(samples):
            xy = _positions(light, samples, i)
            ax.plot(xy[:, 0], xy[:, 1], ".", color="#e0a000", ms=2, alpha=0.5)
        if entry["kind"] == "point":
            p = entry["position"]
            ax.plot(p[0], p[1], "*", color="#c0000f", ms=16, label=f"light {i + 1}: {p[2]:.2f} m high, "
                    f"±{entry['direction_ci_deg']:.2f}°")
        else:
            u = np.asarray(entry["direction"], float)
            ax.annotate("", xy=(c[0] + 3 * u[0], c[1] + 3 * u[1]), xytext=(c[0], c[1]),
                        arrowprops={"arrowstyle": "->", "color": "#c0000f", "lw": 2})
            ax.plot([], [], color="#c0000f", label=f"light {i + 1}: towards the sun, ±{entry['direction_ci_deg']:.2f}°")
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="best")
    ax.set_title("light from above · dots: posterior samples", fontsize=9)
    fig.tight_layout()
    return fig


def posterior_figure(light: dict):
    """Corner plot of the posterior samples (angles in degrees, distances in metres)."""
    plt = _plt()
    names = _names(light)
    s = _samples(light).copy()
    est = []
    for entry in light["lights"]:
        est += [np.radians(entry["azimuth_deg"]), np.radians(entry["elevation_deg"])]
        if entry["kind"] == "point":
            est.append(entry["distance_m"])
    est = np.asarray(est)
    ang = np.array(["rad" in n for n in names])
    if len(s):
        s = np.where(ang[None, :], np.degrees(s), s)
    est = np.where(ang, np.degrees(est), est)
    labels = [n.replace("_rad", " (°)").replace("_m", " (m)") for n in names]
    d = len(names)
    fig, axes = plt.subplots(d, d, figsize=(1.9 * d + 0.6, 1.9 * d + 0.4), squeeze=False)
    for i in range(d):
        for j in range(d):
            ax = axes[i, j]
            if j > i:
                ax.axis("off")
                continue
            if len(s) and i == j:
                ax.hist(s[:, i], bins=20, color="#1f4e9c", alpha=0.7)
                ax.axvline(est[i], color="#c0000f")
            elif len(s):
                ax.plot(s[:, j], s[:, i], ".", ms=2, color="#1f4e9c", alpha=0.5)
                ax.plot(est[j], est[i], "x", color="#c0000f", ms=8, mew=2)
            if i == d - 1:
                ax.set_xlabel(labels[j], fontsize=7)
            if j == 0 and i > 0:
                ax.set_ylabel(labels[i], fontsize=7)
            ax.tick_params(labelsize=6)
    fig.suptitle(f"posterior of the light ({len(s)} samples, ESS "
                 f"{light['samples_summary']['effective_sample_size']:.0f}) · ×: estimate", fontsize=9)
    fig.tight_layout()
    return fig
