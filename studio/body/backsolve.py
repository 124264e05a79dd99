"""Compiled back-substitution of the SCAPE mesh reconstruction (eq. 3.23).

The least-squares vertex positions solve ``GᵀG Y = Gᵀ E`` (vertex 0 pinned), with ``GᵀG``
factored once by SuperLU (:class:`studio.body.scape.PoissonSolver`). SuperLU's own ``solve``
costs ~1.2 ms per body (3 right-hand sides) and nearly the same per body for 48 of them: it
walks the factors once per column. Here the triangular factors are taken out of SuperLU once,
as plain CSC arrays, and one compiled pass assembles ``Gᵀ E`` straight from the planar edges
and runs both triangular solves over all the right-hand sides of a row at once. The result
equals SuperLU's to rounding (tests/studio/test_body_backsolve.py: 1e-12 m).

Scipy's convention: ``Pr · A · Pc = L · U`` with ``(Pr b)[perm_r[i]] = b[i]`` and
``(Pc y)[i] = y[perm_c[i]]``; so ``A x = b`` is ``z[perm_r] = b``, ``L U y = z``,
``x = y[perm_c]``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

__all__ = ["TriangularFactors", "solve_planar_edges"]


@dataclass(frozen=True, eq=False)
class TriangularFactors:
    """SuperLU's factors as CSC arrays: ``L`` strictly lower (its unit diagonal implied),
    ``U`` strictly upper with its diagonal ``u_diag`` apart, and the two permutations."""

    l_ptr: np.ndarray
    l_idx: np.ndarray
    l_val: np.ndarray
    u_ptr: np.ndarray
    u_idx: np.ndarray
    u_val: np.ndarray
    u_diag: np.ndarray
    perm_r: np.ndarray
    perm_c: np.ndarray

    @classmethod
    def from_superlu(cls, lu) -> "TriangularFactors":
        """The factors of a ``scipy.sparse.linalg.splu`` object (L must have a unit diagonal)."""
        import scipy.sparse as sp

        L, U = lu.L.tocsc(), lu.U.tocsc()
        if not np.allclose(L.diagonal(), 1.0):
            raise ValueError("TriangularFactors: SuperLU's L is expected to have a unit diagonal")
        l_strict = sp.tril(L, k=-1, format="csc")
        u_strict = sp.triu(U, k=1, format="csc")
        for m in (l_strict, u_strict):
            m.sort_indices()
        return cls(
            l_strict.indptr.astype(np.int64), l_strict.indices.astype(np.int64), l_strict.data.astype(np.float64),
            u_strict.indptr.astype(np.int64), u_strict.indices.astype(np.int64), u_strict.data.astype(np.float64),
            U.diagonal().astype(np.float64), np.asarray(lu.perm_r, np.int64), np.asarray(lu.perm_c, np.int64),
        )

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """``A⁻¹ rhs`` for (n, K) right-hand sides (float64); the same as ``lu.solve(rhs)``."""
        rhs = np.ascontiguousarray(rhs, dtype=np.float64)
        z = np.empty_like(rhs)
        z[self.perm_r] = rhs
        _lu_solve_rows(self.l_ptr, self.l_idx, self.l_val, self.u_ptr, self.u_idx, self.u_val, self.u_diag, z)
        return z[self.perm_c]


@njit(cache=True, nogil=True, inline="always")
def _eliminate3(ptr, idx, val, j, z, z0, z1, z2):  # pragma: no cover - compiled
    """``z[i] -= a · (z0, z1, z2)`` for every entry (i, a) of factor column ``j`` (K = 3)."""
    for p in range(ptr[j], ptr[j + 1]):
        i = idx[p]
        a = val[p]
        z[i, 0] -= a * z0
        z[i, 1] -= a * z1
        z[i, 2] -= a * z2


@njit(cache=True, nogil=True)
def _lu_solve_rows(l_ptr, l_idx, l_val, u_ptr, u_idx, u_val, u_diag, z):  # pragma: no cover - compiled
    """In place: ``z ← U⁻¹ L⁻¹ z`` for (n, K) ``z``, every right-hand side of a row at once
    (one body, K = 3, unrolled: 0.36 → 0.21 ms; many bodies share each factor entry read)."""
    n, k = z.shape
    if k != 3:
        for j in range(n):  # L: unit lower triangular, column-oriented
            for p in range(l_ptr[j], l_ptr[j + 1]):
                i = l_idx[p]
                a = l_val[p]
                for c in range(k):
                    z[i, c] -= a * z[j, c]
        for j in range(n - 1, -1, -1):  # U: upper triangular, column-oriented
            d = u_diag[j]
            for c in range(k):
                z[j, c] /= d
            for p in range(u_ptr[j], u_ptr[j + 1]):
                i = u_idx[p]
                a = u_val[p]
                for c in range(k):
                    z[i, c] -= a * z[j, c]
        return
    for j in range(n):
        _eliminate3(l_ptr, l_idx, l_val, j, z, z[j, 0], z[j, 1], z[j, 2])
    for j in range(n - 1, -1, -1):
        d = u_diag[j]
        z0, z1, z2 = z[j, 0] / d, z[j, 1] / d, z[j, 2] / d
        z[j, 0], z[j, 1], z[j, 2] = z0, z1, z2
        _eliminate3(u_ptr, u_idx, u_val, j, z, z0, z1, z2)


@njit(cache=True, nogil=True)
def _assemble(edges, faces, perm_r):  # pragma: no cover - compiled
    """``Gᵀ E`` of eq. 3.23 without vertex 0's row, rows permuted by ``perm_r``: (V-1, 3B).

    ``edges`` (B, 3, 2, F) planar target edges; edge k of face f is ``y[f[k+1]] − y[f[0]]``.
    Summed edge by edge, then face by face (the order of ``Gᵀ`` in CSR, so the sums are
    SciPy's to the last bit)."""
    B = edges.shape[0]
    F = edges.shape[3]
    n = perm_r.shape[0]
    full = np.zeros((3 * B, n + 1))
    for bb in range(B):
        for c in range(3):
            row = full[3 * bb + c]
            for k in range(2):
                for f in range(F):
                    v = np.float64(edges[bb, c, k, f])
                    row[faces[f, k + 1]] += v
                    row[faces[f, 0]] -= v
    z = np.empty((n, 3 * B))
    for i in range(n):
        r = perm_r[i]
        for col in range(3 * B):
            z[r, col] = full[col, i + 1]
    return z


@njit(cache=True, nogil=True)
def _scatter(y, perm_c, B):  # pragma: no cover - compiled
    """Vertices (B, V, 3) from the solution rows ``y`` (V-1, 3B) in pivot order; vertex 0 at 0."""
    n = y.shape[0]
    out = np.zeros((B, n + 1, 3))
    for i in range(n):
        r = perm_c[i]
        for bb in range(B):
            for c in range(3):
                out[bb, i + 1, c] = y[r, 3 * bb + c]
    return out


def solve_planar_edges(factors: TriangularFactors, faces: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Vertices (B, V, 3), vertex 0 at the origin, from planar target edges (B, 3, 2, F) —
    :meth:`studio.body.scape.PoissonSolver.solve_planar` in one compiled pass."""
    f = factors
    if edges.ndim != 4 or edges.shape[1:] != (3, 2, len(faces)):
        raise ValueError(f"edges: expected planar (B, 3, 2, {len(faces)}) target edges, got {edges.shape}")
    z = _assemble(np.ascontiguousarray(edges), faces, f.perm_r)
    _lu_solve_rows(f.l_ptr, f.l_idx, f.l_val, f.u_ptr, f.u_idx, f.u_val, f.u_diag, z)
    return _scatter(z, f.perm_c, edges.shape[0])
