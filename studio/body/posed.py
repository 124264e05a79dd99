"""Compiled kernel of the model's per-triangle deformation ``R·D·Q·v`` (eq. 3.11).

Each triangle's pose deformation Q depends on the rotations of the two joints next to it
(eq. 3.16: six rotation-vector components and a 1), so its edges ``Q·v`` are a (7, 3, 2)
map of those seven numbers — not of all 45 components of the pose. The NumPy path multiplied
a dense (46, 6F) map (12.7 MB, 85 % zeros) read whole for every body; here each triangle reads
only its own 42 coefficients, then applies its shape deformation D (eq. 3.22) and its part's
rotation R in the same pass. Measured on the 5,746-vertex female model (process time, one
body as Nelder–Mead asks, same run): 1.28 ms with NumPy → 0.59 ms; a whole mesh 3.36 → 2.02
ms. The fit's costs came out identical on walk frame 12 (40 poses, sum 908.33682565).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["compact_q", "planar_q", "posed_edges", "posed_edges_planar"]


def compact_q(Q_coef: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Per-triangle edge map ``C`` (F, 7, 3, 2) float32: ``Q_f·v_f = Σ_r x_r C[f, r]`` with
    ``x`` the two adjacent joints' rotation vectors and a 1 (eq. 3.16).

    ``Q_coef`` (F, 7, 9) regression coefficients (rows of Q, eq. 3.17), ``edges`` (F, 3, 2)
    the template's triangle edges.
    """
    F = len(edges)
    C = np.einsum("fkij,fjl->fkil", np.asarray(Q_coef, np.float64).reshape(F, 7, 3, 3),
                  np.asarray(edges, np.float64))
    return np.ascontiguousarray(C, dtype=np.float32)


@njit(cache=True, nogil=True)
def posed_edges(rotvecs, C, joint_pairs, D, G, face_parts):  # pragma: no cover - compiled
    """Target edges ``R_p(f) · D_f · Q_f · v_f`` (eq. 3.11), planar (B, 3, 2, F) float32.

    ``rotvecs`` (B, 15, 3) joint rotation vectors (eq. 3.15), ``C`` (F, 7, 3, 2) from
    :func:`compact_q`, ``joint_pairs`` (F, 2) int, ``D`` (B or 1, 3, 3, F) shape
    deformations, ``G`` (B, 15, 3, 3) part rotations, ``face_parts`` (F,) int.
    """
    B = G.shape[0]
    F = C.shape[0]
    out = np.empty((B, 3, 2, F), np.float32)
    x = np.empty(7, np.float32)
    w = np.empty((3, 2), np.float32)
    u = np.empty((3, 2), np.float32)
    for b in range(B):
        bd = b if D.shape[0] > 1 else 0
        for f in range(F):
            j0 = joint_pairs[f, 0]
            j1 = joint_pairs[f, 1]
            for c in range(3):
                x[c] = rotvecs[b, j0, c]
                x[3 + c] = rotvecs[b, j1, c]
            x[6] = 1.0
            for i in range(3):
                for k in range(2):
                    s = np.float32(0.0)
                    for r in range(7):
                        s += x[r] * C[f, r, i, k]
                    w[i, k] = s
            for i in range(3):
                for k in range(2):
                    u[i, k] = D[bd, i, 0, f] * w[0, k] + D[bd, i, 1, f] * w[1, k] + D[bd, i, 2, f] * w[2, k]
            p = face_parts[f]
            for i in range(3):
                for k in range(2):
                    out[b, i, k, f] = G[b, p, i, 0] * u[0, k] + G[b, p, i, 1] * u[1, k] + G[b, p, i, 2] * u[2, k]
    return out


def planar_q(C: np.ndarray) -> np.ndarray:
    """:func:`compact_q`'s map (F, 7, 3, 2) laid out faces last, (7, 3, 2, F) float32, for
    :func:`posed_edges_planar`."""
    return np.ascontiguousarray(np.transpose(np.asarray(C, np.float32), (1, 2, 3, 0)))


#: faces per block of :func:`posed_edges_planar` (their maps stay in cache across a batch)
_BLOCK = 512


@njit(cache=True, nogil=True, inline="always")
def _qv(Cp, i, k, f, x0, x1, x2, x3, x4, x5):  # pragma: no cover - compiled
    """Row ``i`` of edge ``k`` of ``Q_f·v_f`` (eq. 3.16): the 7 regressors summed in
    :func:`posed_edges`' order (the constant's coefficient last)."""
    w = np.float32(0.0)
    w += x0 * Cp[0, i, k, f]
    w += x1 * Cp[1, i, k, f]
    w += x2 * Cp[2, i, k, f]
    w += x3 * Cp[3, i, k, f]
    w += x4 * Cp[4, i, k, f]
    w += x5 * Cp[5, i, k, f]
    w += np.float32(1.0) * Cp[6, i, k, f]
    return w


@njit(cache=True, nogil=True)
def posed_edges_planar(rotvecs, Cp, joint_pairs, D, G, part_start):  # pragma: no cover - compiled
    """:func:`posed_edges` with the edge map faces last (``Cp`` from :func:`planar_q`) and the
    faces taken part by part (``part_start`` (P + 1,): faces of part p are
    ``part_start[p]:part_start[p + 1]``; faces grouped by part), in blocks shared by the whole
    batch: each face's arithmetic in the same order, so the same float32 edges bit for bit,
    with contiguous loads (per body 0.33 → 0.23 ms)."""
    B = G.shape[0]
    F = Cp.shape[3]
    out = np.empty((B, 3, 2, F), np.float32)
    X = np.empty((B, 6, F), np.float32)
    for b in range(B):
        for f in range(F):
            j0 = joint_pairs[f, 0]
            j1 = joint_pairs[f, 1]
            for c in range(3):
                X[b, c, f] = rotvecs[b, j0, c]
                X[b, 3 + c, f] = rotvecs[b, j1, c]
    for p in range(part_start.shape[0] - 1):
        for f0 in range(part_start[p], part_start[p + 1], _BLOCK):
            f1 = min(f0 + _BLOCK, part_start[p + 1])
            for b in range(B):
                bd = b if D.shape[0] > 1 else 0
                g00, g01, g02 = G[b, p, 0, 0], G[b, p, 0, 1], G[b, p, 0, 2]
                g10, g11, g12 = G[b, p, 1, 0], G[b, p, 1, 1], G[b, p, 1, 2]
                g20, g21, g22 = G[b, p, 2, 0], G[b, p, 2, 1], G[b, p, 2, 2]
                for f in range(f0, f1):
                    x0, x1, x2 = X[b, 0, f], X[b, 1, f], X[b, 2, f]
                    x3, x4, x5 = X[b, 3, f], X[b, 4, f], X[b, 5, f]
                    for k in range(2):
                        w0 = _qv(Cp, 0, k, f, x0, x1, x2, x3, x4, x5)
                        w1 = _qv(Cp, 1, k, f, x0, x1, x2, x3, x4, x5)
                        w2 = _qv(Cp, 2, k, f, x0, x1, x2, x3, x4, x5)
                        u0 = D[bd, 0, 0, f] * w0 + D[bd, 0, 1, f] * w1 + D[bd, 0, 2, f] * w2
                        u1 = D[bd, 1, 0, f] * w0 + D[bd, 1, 1, f] * w1 + D[bd, 1, 2, f] * w2
                        u2 = D[bd, 2, 0, f] * w0 + D[bd, 2, 1, f] * w1 + D[bd, 2, 2, f] * w2
                        out[b, 0, k, f] = g00 * u0 + g01 * u1 + g02 * u2
                        out[b, 1, k, f] = g10 * u0 + g11 * u1 + g12 * u2
                        out[b, 2, k, f] = g20 * u0 + g21 * u1 + g22 * u2
    return out
