"""Test kit for the renderer and simulator tests: small closed meshes and a brute-force
point-in-triangle rasteriser that shares no code with :mod:`studio.render`."""

import numpy as np


def uv_sphere(center, radius, n=16):
    """Closed UV sphere, outward-facing triangles: ``(V (N, 3), F (M, 3))``."""
    th = np.linspace(0, np.pi, n + 1)[1:-1]
    ph = np.linspace(0, 2 * np.pi, 2 * n, endpoint=False)
    T, P = np.meshgrid(th, ph, indexing="ij")
    pts = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1).reshape(-1, 3)
    V = np.vstack([pts, [[0, 0, 1]], [[0, 0, -1]]]) * radius + np.asarray(center, dtype=float)
    m = 2 * n
    F = []
    for i in range(n - 2):
        for j in range(m):
            a, b = i * m + j, i * m + (j + 1) % m
            F += [[a, a + m, b], [b, a + m, b + m]]
    top, bot = len(V) - 2, len(V) - 1
    for j in range(m):
        F += [[top, j, (j + 1) % m], [bot, (n - 2) * m + (j + 1) % m, (n - 2) * m + j]]
    return V, np.array(F)


def brute_force_silhouette(camera, V, F):
    """(H, W) bool: pixel centres inside any projected triangle (barycentric sign test, loops)."""
    uv, _, _ = camera.project_points(V)
    w, h = camera.size
    ys, xs = np.mgrid[0:h, 0:w]
    P = np.stack([xs.ravel(), ys.ravel()], axis=1).astype(float)
    out = np.zeros(w * h, bool)
    for a, b, c in F:
        A, B, C = uv[a], uv[b], uv[c]
        d = (B[0] - A[0]) * (C[1] - A[1]) - (B[1] - A[1]) * (C[0] - A[0])
        if abs(d) < 1e-12:
            continue
        l1 = ((B[0] - P[:, 0]) * (C[1] - P[:, 1]) - (B[1] - P[:, 1]) * (C[0] - P[:, 0])) / d
        l2 = ((C[0] - P[:, 0]) * (A[1] - P[:, 1]) - (C[1] - P[:, 1]) * (A[0] - P[:, 0])) / d
        out |= (l1 >= 0) & (l2 >= 0) & (1 - l1 - l2 >= 0)
    return out.reshape(h, w)
