"""Compiled kernels of the contour renderer (:func:`studio.render.spans.silhouettes_contour`).

The fitter renders a body in four views some ten thousand times per frame; in NumPy the
per-view work (front faces, contour edges, the scanline fill) was dominated by the overhead
of some thirty array calls on a few thousand elements each. These loops do the same
arithmetic, in the same order, compiled by numba (``cache=True``: compiled once per machine;
``nogil=True``: views and particles can run on several threads).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["contour_edges", "contour_silhouette", "front_faces", "project_pinhole", "scan_segment", "winding_fill"]


@njit(cache=True, nogil=True)
def front_faces(V, F, centres):  # pragma: no cover - compiled
    """(F, C) bool: face ``f`` faces camera ``k`` (centre ``centres[:, k]``) — the normal
    ``n = (b − a) × (c − a)`` points at the camera, with the sign of the enclosed volume
    (the winding of a closed mesh) taken into account."""
    nf = F.shape[0]
    nc = centres.shape[1]
    n = np.empty((nf, 3))
    na = np.empty(nf)
    total = 0.0
    for f in range(nf):
        a0, a1, a2 = V[F[f, 0], 0], V[F[f, 0], 1], V[F[f, 0], 2]
        u0, u1, u2 = V[F[f, 1], 0] - a0, V[F[f, 1], 1] - a1, V[F[f, 1], 2] - a2
        v0, v1, v2 = V[F[f, 2], 0] - a0, V[F[f, 2], 1] - a1, V[F[f, 2], 2] - a2
        n0 = u1 * v2 - u2 * v1
        n1 = u2 * v0 - u0 * v2
        n2 = u0 * v1 - u1 * v0
        n[f, 0], n[f, 1], n[f, 2] = n0, n1, n2
        na[f] = n0 * a0 + n1 * a1 + n2 * a2
        total += na[f]
    sign = 1.0 if total >= 0 else -1.0
    out = np.empty((nf, nc), dtype=np.bool_)
    for f in range(nf):
        for k in range(nc):
            d = n[f, 0] * centres[0, k] + n[f, 1] * centres[1, k] + n[f, 2] * centres[2, k] - na[f]
            out[f, k] = d * sign > 0
    return out


@njit(cache=True, nogil=True)
def contour_edges(facing, u, v, f_uv, f_vu, n_vertices):  # pragma: no cover - compiled
    """The occluding contour of one view: edges between a front and a back face, each
    directed as it runs in its front face → (start, end) vertex indices (E,), and the
    sorted vertices they use."""
    ne = u.shape[0]
    start = np.empty(ne, dtype=np.int64)
    end = np.empty(ne, dtype=np.int64)
    used = np.zeros(n_vertices, dtype=np.bool_)
    m = 0
    for e in range(ne):
        a = facing[f_uv[e]]
        if a != facing[f_vu[e]]:
            if a:
                start[m], end[m] = u[e], v[e]
            else:
                start[m], end[m] = v[e], u[e]
            used[start[m]] = True
            used[end[m]] = True
            m += 1
    return start[:m], end[:m], np.flatnonzero(used)


@njit(cache=True, nogil=True)
def scan_segment(px, py, qx, qy, diff, box):  # pragma: no cover - compiled
    """Add the directed segment (px, py) → (qx, qy) to the row differences ``diff`` (h, w + 1)
    int32: ±1 at the first pixel centre right of its crossing of each row ``y`` (pixel centres
    at integer coordinates, rows ``lo ≤ y < hi``); ``box`` (4,) int64 [y_min, y_max, x_min,
    x_max] of the cells touched, grown in place. A running sum of ``diff`` along a row is the
    winding number of the segments added."""
    h = diff.shape[0]
    w = diff.shape[1] - 1
    ylo = max(np.ceil(min(py, qy)), 0.0)
    yhi = min(np.ceil(max(py, qy)) - 1.0, h - 1.0)
    if not np.isfinite(ylo + yhi) or yhi < ylo:
        return
    s = 1 if qy > py else -1
    slope = (qx - px) / (qy - py)
    y = ylo
    while y <= yhi:
        x = px + (y - py) * slope
        xi = int(min(max(np.ceil(x), 0.0), w))
        yi = int(y)
        diff[yi, xi] += s
        box[0], box[1] = min(box[0], yi), max(box[1], yi)
        box[2], box[3] = min(box[2], xi), max(box[3], xi)
        y += 1.0


@njit(cache=True, nogil=True)
def winding_fill(p, q, w, h):  # pragma: no cover - compiled
    """(h, w) bool pixels with a non-zero winding number of the directed segments p → q
    ((E, 2) pixel coordinates each, added by :func:`scan_segment`)."""
    out = np.zeros((h, w), dtype=np.bool_)
    diff = np.zeros((h, w + 1), dtype=np.int32)
    box = np.array([h, -1, w, -1])
    for e in range(p.shape[0]):
        scan_segment(p[e, 0], p[e, 1], q[e, 0], q[e, 1], diff, box)
    ya, yb, xa, xb = box[0], box[1], box[2], box[3]
    if yb < 0 or xa >= w:
        return out
    for yi in range(ya, yb + 1):
        acc = 0
        for xi in range(xa, min(xb, w)):
            acc += diff[yi, xi]
            out[yi, xi] = acc != 0
    return out


@njit(cache=True, nogil=True)
def _pinhole_pixel(X0, X1, X2, R, t, K, d):  # pragma: no cover - compiled
    """Pixel (u, v) and depth of one world point (see :func:`project_pinhole`); NaN pixel
    behind the camera."""
    k1, k2, p1, p2, k3, k4, k5, k6 = d[0], d[1], d[2], d[3], d[4], d[5], d[6], d[7]
    s1, s2, s3, s4 = d[8], d[9], d[10], d[11]
    xc = X0 * R[0, 0] + X1 * R[0, 1] + X2 * R[0, 2] + t[0]
    yc = X0 * R[1, 0] + X1 * R[1, 1] + X2 * R[1, 2] + t[1]
    z = X0 * R[2, 0] + X1 * R[2, 1] + X2 * R[2, 2] + t[2]
    if z <= 0:
        return np.nan, np.nan, z
    x = xc / z
    y = yc / z
    r2 = x * x + y * y
    radial = (1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1.0 + r2 * (k4 + r2 * (k5 + r2 * k6)))
    xy2 = 2.0 * x * y
    xd = x * radial + p1 * xy2 + p2 * (r2 + 2.0 * x * x) + r2 * (s1 + s2 * r2)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + p2 * xy2 + r2 * (s3 + s4 * r2)
    return K[0, 0] * xd + K[0, 1] * yd + K[0, 2], K[1, 1] * yd + K[1, 2], z


@njit(cache=True, nogil=True)
def project_pinhole(V, idx, R, t, K, d):  # pragma: no cover - compiled
    """Pixels (n, 2) and depths (n,) of the vertices ``V[idx]`` in a pinhole camera (``R``,
    ``t``, ``K``) with OpenCV's radial / tangential / thin-prism distortion ``d`` = (k1, k2,
    p1, p2, k3, k4, k5, k6, s1, s2, s3, s4) (no sensor tilt): the arithmetic of
    :meth:`calibration.Camera.project_points` (:func:`calibration.distortion.distort_normalized`)
    for the few hundred contour vertices of a view, without its thirty array calls."""
    n = idx.shape[0]
    uv = np.empty((n, 2))
    depth = np.empty(n)
    for i in range(n):
        uv[i, 0], uv[i, 1], depth[i] = _pinhole_pixel(V[idx[i], 0], V[idx[i], 1], V[idx[i], 2], R, t, K, d)
    return uv, depth


@njit(cache=True, nogil=True)
def contour_silhouette(facing, u, v, f_uv, f_vu, V, R, t, K, d, w, h, near, diff):  # pragma: no cover - compiled
    """One view's silhouette in one pass: :func:`contour_edges` of the view's ``facing``
    column, its vertices by :func:`project_pinhole`, then :func:`winding_fill` — the same
    arithmetic, without the arrays passed between them. ``diff`` (h, w + 1) int32 is the
    difference image, all zeros on entry and left so (only the cells written are cleared:
    a fresh full-size one per view cost more than the fill). → ((h, w) bool, ok); ``ok``
    False (an empty mask) when a contour vertex is within ``near`` of the camera plane (the
    caller falls back)."""
    start, end, used = contour_edges(facing, u, v, f_uv, f_vu, V.shape[0])
    out = np.zeros((h, w), dtype=np.bool_)
    uv = np.empty((V.shape[0], 2))
    zmin = np.inf
    for i in used:
        px, py, z = _pinhole_pixel(V[i, 0], V[i, 1], V[i, 2], R, t, K, d)
        uv[i, 0], uv[i, 1] = px, py
        zmin = min(zmin, z)
    if used.shape[0] and zmin <= near:
        return out, False
    box = np.array([h, -1, w, -1])
    for e in range(start.shape[0]):
        a, b = start[e], end[e]
        scan_segment(uv[a, 0], uv[a, 1], uv[b, 0], uv[b, 1], diff, box)
    ya, yb, xa, xb = box[0], box[1], box[2], box[3]
    if yb < 0:
        return out, True
    for yi in range(ya, yb + 1):
        acc = 0
        for xi in range(xa, min(xb, w)):
            acc += diff[yi, xi]
            out[yi, xi] = acc != 0
        diff[yi, xa:xb + 1] = 0
    return out, True
