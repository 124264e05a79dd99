"""Batched triangle meshes of the cylinder body model (thesis §4.8.1) for the pose search.

:meth:`studio.body.CylinderModel.mesh` builds one posed mesh with a Python loop over the
15 cones; :func:`cone_meshes` builds the same meshes (same vertex order, same faces) for a
batch of poses in one vectorised pass, so the particle filter can score hundreds of
cylinder hypotheses with the contour renderer (:func:`studio.render.spans.silhouettes_contour`).
"""

from __future__ import annotations

import numpy as np

__all__ = ["cone_faces", "cone_meshes"]


def cone_faces(sides: int = 12, n_parts: int = 15) -> np.ndarray:
    """(n_parts · 4 · sides, 3) faces of ``n_parts`` closed cones of ``2·sides + 2`` vertices
    each (ring at the proximal end, ring at the distal end, the two cap centres)."""
    i = np.arange(sides)
    j = (i + 1) % sides
    f = np.concatenate([
        np.stack([i, j, sides + j], 1), np.stack([i, sides + j, sides + i], 1),
        np.stack([np.full(sides, 2 * sides), j, i], 1),
        np.stack([np.full(sides, 2 * sides + 1), sides + i, sides + j], 1),
    ])
    n = 2 * sides + 2
    return np.concatenate([f + p * n for p in range(n_parts)])


def cone_meshes(ends: np.ndarray, radii: np.ndarray, sides: int = 12) -> np.ndarray:
    """Vertices (B, 15 · (2·sides + 2), 3) of posed cones ``ends`` (B, P, 2, 3) with
    ``radii`` (P, 2); faces from :func:`cone_faces`."""
    ends = np.asarray(ends, dtype=np.float64)
    a, b = ends[:, :, 0], ends[:, :, 1]  # (B, P, 3)
    u = b - a
    u /= np.linalg.norm(u, axis=-1, keepdims=True)
    ref = np.where((np.abs(u[..., 0]) < 0.9)[..., None], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    t = np.cross(u, ref)
    t /= np.linalg.norm(t, axis=-1, keepdims=True)
    w = np.cross(u, t)
    ang = np.linspace(0, 2 * np.pi, sides, endpoint=False)
    ring = np.cos(ang)[None, None, :, None] * t[:, :, None] + np.sin(ang)[None, None, :, None] * w[:, :, None]
    r = np.asarray(radii, dtype=np.float64)
    v0 = a[:, :, None] + r[None, :, 0, None, None] * ring
    v1 = b[:, :, None] + r[None, :, 1, None, None] * ring
    V = np.concatenate([v0, v1, a[:, :, None], b[:, :, None]], axis=2)  # (B, P, 2S+2, 3)
    return V.reshape(len(V), -1, 3)
