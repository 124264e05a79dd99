"""The symmetric template mesh of the model build: Anny's neutral adult segmented into the 15
parts, decimated half-body, mirrored and welded, and its barycentric map to Anny (build time)."""

from __future__ import annotations

import logging

import numpy as np
import scipy.sparse as sp

from studio.body.anny_adapter import _Anny, bone_part
from studio.body.skeleton import PART_NAMES

log = logging.getLogger(__name__)


def _segment(anny: _Anny) -> np.ndarray:
    """Part index of every Anny vertex: argmax of skinning weights summed per part."""
    bp = np.array([PART_NAMES.index(bone_part(b)) for b in anny.labels])
    P = sp.csr_matrix((np.ones(len(bp)), (np.arange(len(bp)), bp)), shape=(len(bp), 15))
    return np.asarray((anny.weights @ P).argmax(axis=1)).ravel()


def _weld(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Merge vertices closer than 0.1 µm (the decimated pieces share their kept borders)."""
    q = np.round(vertices / 1e-7).astype(np.int64)
    _, first, inverse = np.unique(q, axis=0, return_index=True, return_inverse=True)
    return vertices[first], inverse.ravel()[faces]


def _decimate_template(
    V0: np.ndarray, F0: np.ndarray, vpart: np.ndarray, keep: dict[str, float]
) -> tuple[np.ndarray, np.ndarray]:
    """Symmetric decimation: decimate the +x half region by region (borders kept), mirror."""
    import fast_simplification

    V0 = V0.copy()
    mid = np.abs(V0[:, 0]) < 1e-6
    V0[mid, 0] = 0.0
    cx = V0[F0].mean(axis=1)[:, 0]
    half = F0[cx > 0]
    fpart = vpart[half]
    fpart = np.array([np.bincount(r, minlength=15).argmax() for r in fpart])
    region = np.full(len(half), "body", dtype=object)
    region[fpart == PART_NAMES.index("head")] = "head"
    region[(fpart == PART_NAMES.index("hand_l")) | (fpart == PART_NAMES.index("hand_r"))] = "hand"
    region[(fpart == PART_NAMES.index("foot_l")) | (fpart == PART_NAMES.index("foot_r"))] = "foot"
    pieces_v, pieces_f = [], []
    offset = 0
    for name in ("body", "head", "hand", "foot"):
        f = half[region == name]
        used, inv = np.unique(f, return_inverse=True)
        v, fl = V0[used], inv.reshape(-1, 3)
        target = int(len(fl) * keep[name])
        v2, f2 = fast_simplification.simplify(
            v, fl.astype(np.int32), target_count=target, agg=7.0, preserve_border=True
        )
        pieces_v.append(v2)
        pieces_f.append(f2 + offset)
        offset += len(v2)
    v = np.concatenate(pieces_v)
    f = np.concatenate(pieces_f)
    v, f = _weld(v, f)
    # snap the seam on the symmetry plane, then mirror
    on_plane = np.abs(v[:, 0]) < 1e-6
    v[on_plane, 0] = 0.0
    n = len(v)
    vm = v * [-1.0, 1.0, 1.0]
    allv = np.concatenate([v, vm])
    allf = np.concatenate([f, f[:, ::-1] + n])
    allv, allf = _weld(allv, allf)
    # drop degenerate faces
    good = (allf[:, 0] != allf[:, 1]) & (allf[:, 1] != allf[:, 2]) & (allf[:, 0] != allf[:, 2])
    allf = allf[good]
    used, inv = np.unique(allf, return_inverse=True)
    return allv[used], inv.reshape(-1, 3)


def _closest_on_triangles(p: np.ndarray, tri: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closest points of p (N, 3) on triangles (N, K, 3, 3): distances (N, K), bary (N, K, 3)."""
    a, b, c = tri[..., 0, :], tri[..., 1, :], tri[..., 2, :]
    q = p[:, None, :]
    e0, e1 = b - a, c - a
    n = np.cross(e0, e1)
    nn = np.maximum(np.einsum("...i,...i", n, n), 1e-30)
    # projection barycentrics
    w = q - a
    d00, d01, d11 = (np.einsum("...i,...i", x, y) for x, y in ((e0, e0), (e0, e1), (e1, e1)))
    d20, d21 = np.einsum("...i,...i", w, e0), np.einsum("...i,...i", w, e1)
    den = np.maximum(d00 * d11 - d01 * d01, 1e-30)
    v = (d11 * d20 - d01 * d21) / den
    u = (d00 * d21 - d01 * d20) / den
    bary = np.stack([1 - v - u, v, u], axis=-1)
    inside = np.all(bary >= 0, axis=-1)
    best_b = bary.copy()
    best_d = np.abs(np.einsum("...i,...i", w, n)) / np.sqrt(nn)
    best_d = np.where(inside, best_d, np.inf)
    verts = (a, b, c)
    for i, j in ((0, 1), (1, 2), (2, 0)):
        s0, s1 = verts[i], verts[j]
        seg = s1 - s0
        t = np.clip(np.einsum("...i,...i", q - s0, seg) / np.maximum(np.einsum("...i,...i", seg, seg), 1e-30), 0, 1)
        d = np.linalg.norm(q - (s0 + t[..., None] * seg), axis=-1)
        bb = np.zeros_like(bary)
        bb[..., i] = 1 - t
        bb[..., j] = t
        better = d < best_d
        best_d = np.where(better, d, best_d)
        best_b = np.where(better[..., None], bb, best_b)
    return best_d, best_b


def _barycentric_map(V0: np.ndarray, F0: np.ndarray, points: np.ndarray, k: int = 12) -> sp.csr_matrix:
    """Sparse (P, V0) map: each point as barycentric combination of its closest triangle."""
    from scipy.spatial import cKDTree

    vf = sp.csr_matrix(
        (np.ones(F0.size), (F0.ravel(), np.repeat(np.arange(len(F0)), 3))), shape=(len(V0), len(F0))
    )
    _, nn = cKDTree(V0).query(points, k=k)
    rows, cols, vals = [], [], []
    for i, pt in enumerate(points):
        cand = np.unique(vf[nn[i]].indices)
        d, b = _closest_on_triangles(pt[None], V0[F0[cand]][None])
        j = int(np.argmin(d[0]))
        rows += [i] * 3
        cols += list(F0[cand[j]])
        vals += list(b[0, j])
    M = sp.csr_matrix((vals, (rows, cols)), shape=(len(points), len(V0)))
    M.sum_duplicates()
    return M


def _check_watertight(faces: np.ndarray) -> int:
    e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    _, counts = np.unique(e, axis=0, return_counts=True)
    return int(np.sum(counts != 2))
