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

__all__ = ["compact_q", "low_rank_q", "pair_slots", "planar_q", "posed_edges", "posed_edges_planar",
           "slot_regressors"]


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


def pair_slots(joint_pairs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The distinct joint pairs ``slots`` (S, 2) and each face's slot (F,): the faces of a slot
    share their regressors."""
    slots, slot = np.unique(np.asarray(joint_pairs), axis=0, return_inverse=True)
    return slots.astype(np.int64), slot.ravel().astype(np.int64)


def slot_regressors(feats: np.ndarray, slots: np.ndarray, A: np.ndarray | None = None) -> np.ndarray:
    """Regressors per slot (B, S, R) float32 for :func:`posed_edges_planar`: a slot's two joints'
    features side by side (R = 2K, in :func:`posed_edges`' order), or projected on the slot's
    reduced basis ``A`` (S, 2K, r) of :func:`low_rank_q` (R = r)."""
    x = np.concatenate([feats[:, slots[:, 0]], feats[:, slots[:, 1]]], axis=-1)
    if A is not None:
        x = np.einsum("bsr,srk->bsk", x, A)
    return np.ascontiguousarray(x, dtype=np.float32)


def low_rank_q(C: np.ndarray, slots: np.ndarray, slot: np.ndarray, feats: np.ndarray,
               rank: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`compact_q`'s map reduced to ``rank`` regressors per joint pair: ``(Cp, A)`` with
    ``Cp`` (rank + 1, 3, 2, F) for :func:`posed_edges_planar` (the constant row, Q·v at rest,
    exact) and ``A`` (S, 2K, rank) for :func:`slot_regressors`.

    The faces of a pair deform as ``x·M`` (eq. 3.16; ``x`` the pair's 2K features, ``M`` (2K,
    6 n) their edge maps); over the pair's features at sample poses ``feats`` (N, 15, K) the
    deformations' leading ``rank`` principal directions ``P`` (6 n, rank) keep the most of it:
    ``x·M ≈ (x·M·P)·Pᵀ``. With K = 9 (18 regressors) the relative error of the deformation over
    the build's near-rest and wide poses is 13 % at rank 6, 7 % at 8, 3.5 % at 10; the model's
    error at the lab postures 6.48 mm (full) → 6.61 at rank 8, 7.29 at rank 6.
    """
    F, R1 = C.shape[:2]
    R = R1 - 1
    Cp = np.zeros((rank + 1, 3, 2, F), np.float32)
    Cp[rank] = np.moveaxis(C[:, R], 0, -1)
    A = np.zeros((len(slots), R, rank), np.float64)
    for s, (a, b) in enumerate(slots):
        idx = np.nonzero(slot == s)[0]
        M = np.asarray(C[idx, :R], np.float64).transpose(1, 0, 2, 3).reshape(R, -1)  # (2K, 6 n)
        x = np.concatenate([feats[:, a], feats[:, b]], axis=1)
        lam, E = np.linalg.eigh(x.T @ x)  # (x·M)ᵀ(x·M) = (S·M)ᵀ(S·M), S = (xᵀx)^½: a (2K, 6 n) SVD
        P = np.linalg.svd((E * np.sqrt(np.clip(lam, 0, None))) @ E.T @ M, full_matrices=False)[2][:rank].T
        A[s, :, : P.shape[1]] = M @ P
        Cp[: P.shape[1], :, :, idx] = P.T.reshape(-1, len(idx), 3, 2).transpose(0, 2, 3, 1)
    return Cp, A


@njit(cache=True, nogil=True)
def posed_edges_planar(x, Cp, slot, D, G, part_start):  # pragma: no cover - compiled
    """:func:`posed_edges` with the regressors per slot (``x`` (B, S, R) from
    :func:`slot_regressors`, ``slot`` (F,) each face's), the edge map faces last (``Cp`` (R + 1,
    3, 2, F) from :func:`planar_q` or :func:`low_rank_q`), the faces innermost (contiguous loads,
    vectorised) and the part rotations applied part by part (``part_start`` (P + 1,): faces of
    part p are ``part_start[p]:part_start[p + 1]``; faces grouped by part). With the full map,
    each face's arithmetic in :func:`posed_edges`' order: the same float32 edges bit for bit.
    Measured on the female model (process time per body, one body / 16): the previous kernel,
    unrolled for 7 regressors, 0.23–0.25 ms; this one with 19 regressors 0.37 / 0.43 ms (face
    by face it took 1.9 / 1.3 ms); at rank 8 (9 rows) see :data:`studio.body.model.Q_RANK`."""
    B = G.shape[0]
    F = Cp.shape[3]
    R = x.shape[2]
    out = np.empty((B, 3, 2, F), np.float32)
    X = np.empty((R, F), np.float32)  # one body's regressors, faces last
    W = np.empty((6, F), np.float32)  # its Q_f·v_f, row i of edge k at 2i + k
    one = np.float32(1.0)
    for b in range(B):
        bd = b if D.shape[0] > 1 else 0
        for c in range(R):
            Xc = X[c]
            for f in range(F):
                Xc[f] = x[b, slot[f], c]
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
