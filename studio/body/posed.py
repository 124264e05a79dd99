"""Compiled kernel of the model's per-triangle deformation ``R·D·Q·v`` (eq. 3.11).

Each triangle's pose deformation Q depends on the rotations of the two joints next to it
(eq. 3.16: K features per joint — the shipped model's rotation entries minus the identity,
K = 9, or the thesis' rotation vectors, K = 3 — and a 1), so its edges ``Q·v`` are a
(2K + 1, 3, 2) map of those numbers — not of all components of the pose. The NumPy path multiplied
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
    """Per-triangle edge map ``C`` (F, R, 3, 2) float32: ``Q_f·v_f = Σ_r x_r C[f, r]`` with
    ``x`` the two adjacent joints' features and a 1 (eq. 3.16; R = 2K + 1).

    ``Q_coef`` (F, R, 9) regression coefficients (rows of Q, eq. 3.17), ``edges`` (F, 3, 2)
    the template's triangle edges.
    """
    F = len(edges)
    C = np.einsum("fkij,fjl->fkil", np.asarray(Q_coef, np.float64).reshape(F, -1, 3, 3),
                  np.asarray(edges, np.float64))
    return np.ascontiguousarray(C, dtype=np.float32)


@njit(cache=True, nogil=True)
def posed_edges(feats, C, joint_pairs, D, G, face_parts):  # pragma: no cover - compiled
    """Target edges ``R_p(f) · D_f · Q_f · v_f`` (eq. 3.11), planar (B, 3, 2, F) float32.

    ``feats`` (B, 15, K) the joints' features (:func:`studio.body.scape.pose_features`), ``C``
    (F, 2K + 1, 3, 2) from :func:`compact_q`, ``joint_pairs`` (F, 2) int, ``D`` (B or 1, 3, 3, F)
    shape deformations, ``G`` (B, 15, 3, 3) part rotations, ``face_parts`` (F,) int.
    """
    B = G.shape[0]
    F = C.shape[0]
    K = feats.shape[2]
    R = 2 * K
    out = np.empty((B, 3, 2, F), np.float32)
    x = np.empty(R, np.float32)
    w = np.empty((3, 2), np.float32)
    u = np.empty((3, 2), np.float32)
    for b in range(B):
        bd = b if D.shape[0] > 1 else 0
        for f in range(F):
            j0 = joint_pairs[f, 0]
            j1 = joint_pairs[f, 1]
            for c in range(K):
                x[c] = feats[b, j0, c]
                x[K + c] = feats[b, j1, c]
            for i in range(3):
                for k in range(2):
                    s = np.float32(0.0)
                    for r in range(R):
                        s += x[r] * C[f, r, i, k]
                    s += np.float32(1.0) * C[f, R, i, k]
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
    """:func:`compact_q`'s map (F, R, 3, 2) laid out faces last, (R, 3, 2, F) float32, for
    :func:`posed_edges_planar`."""
    return np.ascontiguousarray(np.transpose(np.asarray(C, np.float32), (1, 2, 3, 0)))


@njit(cache=True, nogil=True)
def posed_edges_planar(feats, Cp, joint_pairs, D, G, part_start):  # pragma: no cover - compiled
    """:func:`posed_edges` with the edge map faces last (``Cp`` from :func:`planar_q`), the faces
    innermost (contiguous loads, vectorised) and the part rotations applied part by part
    (``part_start`` (P + 1,): faces of part p are ``part_start[p]:part_start[p + 1]``; faces
    grouped by part). Each face's arithmetic in :func:`posed_edges`' order, so the same float32
    edges bit for bit. Measured on the female model (process time per body, one body / 16):
    the previous kernel, unrolled for 7 regressors, 0.23–0.25 ms; this one with 19 regressors
    0.37 / 0.43 ms (face by face it took 1.9 / 1.3 ms)."""
    B = G.shape[0]
    F = Cp.shape[3]
    K = feats.shape[2]
    R = 2 * K
    out = np.empty((B, 3, 2, F), np.float32)
    X = np.empty((R, F), np.float32)  # one body's regressors, faces last
    W = np.empty((6, F), np.float32)  # its Q_f·v_f, row i of edge k at 2i + k
    one = np.float32(1.0)
    for b in range(B):
        bd = b if D.shape[0] > 1 else 0
        for f in range(F):
            j0 = joint_pairs[f, 0]
            j1 = joint_pairs[f, 1]
            for c in range(K):
                X[c, f] = feats[b, j0, c]
                X[K + c, f] = feats[b, j1, c]
        for ik in range(6):
            Wik = W[ik]
            for f in range(F):
                Wik[f] = np.float32(0.0)
            for r in range(R):
                Xr = X[r]
                Cr = Cp[r, ik // 2, ik % 2]
                for f in range(F):
                    Wik[f] += Xr[f] * Cr[f]
            Cr = Cp[R, ik // 2, ik % 2]
            for f in range(F):
                Wik[f] += one * Cr[f]
        for p in range(part_start.shape[0] - 1):
            g00, g01, g02 = G[b, p, 0, 0], G[b, p, 0, 1], G[b, p, 0, 2]
            g10, g11, g12 = G[b, p, 1, 0], G[b, p, 1, 1], G[b, p, 1, 2]
            g20, g21, g22 = G[b, p, 2, 0], G[b, p, 2, 1], G[b, p, 2, 2]
            for k in range(2):
                for f in range(part_start[p], part_start[p + 1]):
                    w0, w1, w2 = W[k, f], W[2 + k, f], W[4 + k, f]
                    u0 = D[bd, 0, 0, f] * w0 + D[bd, 0, 1, f] * w1 + D[bd, 0, 2, f] * w2
                    u1 = D[bd, 1, 0, f] * w0 + D[bd, 1, 1, f] * w1 + D[bd, 1, 2, f] * w2
                    u2 = D[bd, 2, 0, f] * w0 + D[bd, 2, 1, f] * w1 + D[bd, 2, 2, f] * w2
                    out[b, 0, k, f] = g00 * u0 + g01 * u1 + g02 * u2
                    out[b, 1, k, f] = g10 * u0 + g11 * u1 + g12 * u2
                    out[b, 2, k, f] = g20 * u0 + g21 * u1 + g22 * u2
    return out
