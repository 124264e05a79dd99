"""Compiled kernel of the light's objective: eq. 5.9's terms of one frame for many lights at once.

For each hypothesis (one or several lights) and each view, :func:`shadow_chamfer` does in one
pass what :func:`studio.light.objective.predicted_shadows` followed by
:func:`studio.cost.silhouette_cost` do in some thirty array calls: the light-facing faces and
their occluding contour, its shadow on the ground (eq. 5.2), its projection into the view
(eq. 5.3), the winding fill (the same arithmetic as :func:`studio.render.winding.winding_fill`),
the body's own silhouette taken out (§5.6), and both directions of the truncated chamfer
distance (eq. 4.4): the observed distance map summed over the predicted pixels, and for every
observed pixel the distance to the nearest predicted one, found in its ``ceil(τ)`` neighbourhood
(exact Euclidean, as OpenCV's precise distance transform; farther is τ).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["shadow_chamfer"]


@njit(cache=True, nogil=True)
def _contour_shadows(V, n, na, sign, eu, ev, f_uv, f_vu, light, plane, facing, seg, m):  # pragma: no cover
    """Append the shadow segments (start xyz, end xyz) of ``light``'s occluding contour to
    ``seg`` from row ``m``; returns the new row count, or -1 when the outline does not apply
    (a contour vertex at or above a point light, a light shining upwards)."""
    nx, ny, nz, d = plane[0], plane[1], plane[2], plane[3]
    lx, ly, lz, point = light[0], light[1], light[2], light[3] > 0.5
    for f in range(n.shape[0]):
        if point:
            s = n[f, 0] * lx + n[f, 1] * ly + n[f, 2] * lz - na[f]
        else:
            s = -(n[f, 0] * lx + n[f, 1] * ly + n[f, 2] * lz)
        facing[f] = s * sign > 0
    if point:
        hl = nx * lx + ny * ly + nz * lz - d
        if hl <= 0:
            return -1
    else:
        den = nx * lx + ny * ly + nz * lz
        if den >= -1e-12:
            return -1
    for e in range(eu.shape[0]):
        a = facing[f_uv[e]]
        if a == facing[f_vu[e]]:
            continue
        i0, i1 = (eu[e], ev[e]) if a else (ev[e], eu[e])
        for j in range(2):
            i = i0 if j == 0 else i1
            px, py, pz = V[i, 0], V[i, 1], V[i, 2]
            if point:
                rx, ry, rz = px - lx, py - ly, pz - lz
                den = rx * nx + ry * ny + rz * nz
                if not (den < -1e-12 and px * nx + py * ny + pz * nz - d < hl):
                    return -1
                lam = (d - (nx * lx + ny * ly + nz * lz)) / den
                seg[m, 3 * j] = lx + lam * rx
                seg[m, 3 * j + 1] = ly + lam * ry
                seg[m, 3 * j + 2] = lz + lam * rz
            else:
                t = (px * nx + py * ny + pz * nz - d) / den
                seg[m, 3 * j] = px - t * lx
                seg[m, 3 * j + 1] = py - t * ly
                seg[m, 3 * j + 2] = pz - t * lz
        m += 1
    return m


@njit(cache=True, nogil=True)
def shadow_chamfer(V, n, na, sign, eu, ev, f_uv, f_vu, lights, plane, M, occ, dmaps, obs_y, obs_x, obs_start,
                   tau):  # pragma: no cover - compiled
    """Chamfer numerators of eq. 4.4 between the visible predicted shadow and the observed one.

    ``V`` (V, 3) the body, ``n, na, sign`` its :func:`studio.render.spans.face_normals`,
    ``eu, ev, f_uv, f_vu`` its edge topology; ``lights`` (N, J, 4) per hypothesis J lights as
    ``[x, y, z, 1]`` (point, position) or ``[dx, dy, dz, 0]`` (directional, the direction it
    shines along); ``plane`` ``[nx, ny, nz, d]`` (n·X = d); ``M`` (C, 3, 4) the ideal level
    cameras ``K [R | t]``; ``occ`` (C, H, W) bool the body's silhouettes; ``dmaps`` (C, H, W)
    the observed ``C^τ(S^o)``; the observed pixels of view k are ``(obs_y, obs_x)[obs_start[k]:
    obs_start[k + 1]]``; ``tau`` in level pixels.

    Returns (N, C, 3) ``[Σ_{S^e} C^τ(S^o), Σ_{S^o} C^τ(S^e), |S^e|]`` and (N, C) bool ``ok``
    (False: the outline fast path does not apply to the hypothesis, or a shadow point is behind
    that camera; those terms are left at 0 for the caller to compute).
    """
    N, J = lights.shape[0], lights.shape[1]
    C, h, w = occ.shape
    out = np.zeros((N, C, 3))
    ok = np.ones((N, C), dtype=np.bool_)
    facing = np.empty(n.shape[0], dtype=np.bool_)
    seg = np.empty((J * eu.shape[0], 6))
    uv = np.empty((J * eu.shape[0], 4))
    diff = np.zeros((h, w + 1), dtype=np.int32)
    model = np.zeros((h, w), dtype=np.bool_)
    r = int(np.ceil(tau))
    for i in range(N):
        m = 0
        for j in range(J):
            m = _contour_shadows(V, n, na, sign, eu, ev, f_uv, f_vu, lights[i, j], plane, facing, seg, m)
            if m < 0:
                break
        if m < 0:
            ok[i, :] = False
            continue
        for k in range(C):
            behind = False
            for s in range(m):
                for j in range(2):
                    x, y, z = seg[s, 3 * j], seg[s, 3 * j + 1], seg[s, 3 * j + 2]
                    zc = M[k, 2, 0] * x + M[k, 2, 1] * y + M[k, 2, 2] * z + M[k, 2, 3]
                    if zc <= 1e-3:
                        behind = True
                    uv[s, 2 * j] = (M[k, 0, 0] * x + M[k, 0, 1] * y + M[k, 0, 2] * z + M[k, 0, 3]) / zc
                    uv[s, 2 * j + 1] = (M[k, 1, 0] * x + M[k, 1, 1] * y + M[k, 1, 2] * z + M[k, 1, 3]) / zc
            if behind:
                ok[i, k] = False
                continue
            # winding fill (as studio.render.winding.winding_fill)
            ya, yb, xa, xb = h, -1, w, -1
            for s in range(m):
                px, py, qx, qy = uv[s, 0], uv[s, 1], uv[s, 2], uv[s, 3]
                ylo = max(np.ceil(min(py, qy)), 0.0)
                yhi = min(np.ceil(max(py, qy)) - 1.0, h - 1.0)
                if not np.isfinite(ylo + yhi) or yhi < ylo:
                    continue
                sg = 1 if qy > py else -1
                slope = (qx - px) / (qy - py)
                y = ylo
                while y <= yhi:
                    x = px + (y - py) * slope
                    xi = int(min(max(np.ceil(x), 0.0), w))
                    yi = int(y)
                    diff[yi, xi] += sg
                    ya, yb = min(ya, yi), max(yb, yi)
                    xa, xb = min(xa, xi), max(xb, xi)
                    y += 1.0
            fwd, count = 0.0, 0
            if yb >= 0 and xa < w:
                for yi in range(ya, yb + 1):
                    acc = 0
                    for xi in range(xa, min(xb, w)):
                        acc += diff[yi, xi]
                        if acc != 0 and not occ[k, yi, xi]:
                            model[yi, xi] = True
                            fwd += dmaps[k, yi, xi]
                            count += 1
            # observed → predicted: distance to the nearest predicted pixel, at most τ
            bwd = 0.0
            for p in range(obs_start[k], obs_start[k + 1]):
                y0, x0 = obs_y[p], obs_x[p]
                if count == 0 or y0 < ya - r or y0 > yb + r or x0 < xa - r or x0 > xb + r:
                    bwd += tau
                    continue
                if model[y0, x0]:
                    continue
                best = tau * tau
                for yy in range(max(y0 - r, ya), min(y0 + r, yb) + 1):
                    dy2 = (yy - y0) * (yy - y0)
                    if dy2 >= best:
                        continue
                    for xx in range(max(x0 - r, xa), min(x0 + r, xb - 1) + 1):
                        if model[yy, xx]:
                            d2 = dy2 + (xx - x0) * (xx - x0)
                            if d2 < best:
                                best = d2
                bwd += min(np.sqrt(best), tau)
            out[i, k, 0], out[i, k, 1], out[i, k, 2] = fwd, bwd, count
            if yb >= 0:
                for yi in range(ya, yb + 1):
                    for xi in range(xa, min(xb, w) + 1):
                        diff[yi, xi] = 0
                        if xi < w:
                            model[yi, xi] = False
    return out, ok
