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

from studio.cost.view_terms import numerators_in_box
from studio.render.winding import scan_segment

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
def _clip_and_project(seg, m, Mk, plane, uv):  # pragma: no cover - compiled
    """Project the ``m`` floor segments of ``seg`` into the camera ``Mk`` (3, 4) as ``uv`` rows
    (u0, v0, u1, v1); returns the row count. Floor points closer to the camera's plane than
    ``NEAR`` (behind it included) are first moved along the floor onto the line at depth ``NEAR``:
    a segment crossing it is split there and its far part replaced by its projection onto the
    line. The outline stays closed and, the moved points never crossing a point in front, the
    winding number of every floor point in front is unchanged (the fill is that of the exact
    renderer, which drops what is behind the camera)."""
    near = 1e-2
    r0, r1, r2, r3 = Mk[2, 0], Mk[2, 1], Mk[2, 2], Mk[2, 3]
    nx, ny, nz = plane[0], plane[1], plane[2]
    rn = r0 * nx + r1 * ny + r2 * nz
    gx, gy, gz = r0 - rn * nx, r1 - rn * ny, r2 - rn * nz  # depth's steepest ascent along the floor
    gg = gx * gx + gy * gy + gz * gz
    out = 0
    pts = np.empty((3, 3))
    for s in range(m):
        px, py, pz, qx, qy, qz = seg[s, 0], seg[s, 1], seg[s, 2], seg[s, 3], seg[s, 4], seg[s, 5]
        zp = r0 * px + r1 * py + r2 * pz + r3
        zq = r0 * qx + r1 * qy + r2 * qz + r3
        if zp >= near and zq >= near:
            npts = 2
            pts[0, 0], pts[0, 1], pts[0, 2] = px, py, pz
            pts[1, 0], pts[1, 1], pts[1, 2] = qx, qy, qz
        elif gg < 1e-18:  # the camera looks along the floor's normal and the floor is behind it
            continue
        else:
            a = (near - zp) / gg if zp < near else 0.0
            b = (near - zq) / gg if zq < near else 0.0
            pts[0, 0], pts[0, 1], pts[0, 2] = px + a * gx, py + a * gy, pz + a * gz
            if (zp < near) == (zq < near):  # both behind: the segment along the line
                npts = 2
                pts[1, 0], pts[1, 1], pts[1, 2] = qx + b * gx, qy + b * gy, qz + b * gz
            else:  # split where it crosses the line
                npts = 3
                t = (near - zp) / (zq - zp)
                pts[1, 0], pts[1, 1], pts[1, 2] = px + t * (qx - px), py + t * (qy - py), pz + t * (qz - pz)
                pts[2, 0], pts[2, 1], pts[2, 2] = qx + b * gx, qy + b * gy, qz + b * gz
        for j in range(npts):
            x, y, z = pts[j, 0], pts[j, 1], pts[j, 2]
            zc = max(r0 * x + r1 * y + r2 * z + r3, near)
            u = (Mk[0, 0] * x + Mk[0, 1] * y + Mk[0, 2] * z + Mk[0, 3]) / zc
            v = (Mk[1, 0] * x + Mk[1, 1] * y + Mk[1, 2] * z + Mk[1, 3]) / zc
            if j > 0:
                uv[out, 2], uv[out, 3] = u, v
                out += 1
            if j < npts - 1:
                uv[out, 0], uv[out, 1] = u, v
    return out


@njit(cache=True, nogil=True)
def shadow_chamfer(V, n, na, sign, eu, ev, f_uv, f_vu, lights, plane, M, occ, occ_index, dmaps, observed,
                   n_observed, tau):  # pragma: no cover - compiled
    """Chamfer numerators of eq. 4.4 between the visible predicted shadow and the observed one.

    ``V`` (V, 3) the body, ``n, na, sign`` its :func:`studio.render.spans.face_normals`,
    ``eu, ev, f_uv, f_vu`` its edge topology; ``lights`` (N, J, 4) per hypothesis J lights as
    ``[x, y, z, 1]`` (point, position) or ``[dx, dy, dz, 0]`` (directional, the direction it
    shines along); ``plane`` ``[nx, ny, nz, d]`` (n·X = d); ``M`` (C, 3, 4) the ideal level
    cameras ``K [R | t]``; ``occ`` (C, S) bool the body's silhouettes, flat, in images of S pixels
    that ``occ_index`` (C, H, W) maps the level image's pixels to (flat index, −1: none; the
    identity when the body was rendered in the ideal image, the nearest source pixel of the lens
    when it was rendered through it — the body taken out at the shadow's pixels only);
    ``dmaps`` (C, H, W)
    the observed ``C^τ(S^o)``, ``observed`` (C, H, W) bool the observed shadows and ``n_observed``
    (C,) their pixel counts; ``tau`` in level pixels. The observed-to-predicted direction is
    :func:`studio.cost.view_terms.numerators_in_box` on the filled box (the silhouette cost's own
    exact distances).

    Returns (N, C, 3) ``[Σ_{S^e} C^τ(S^o), Σ_{S^o} C^τ(S^e), |S^e|]`` and (N, C) bool ``ok``
    (False: the outline fast path does not apply to the hypothesis — a light below a contour
    vertex, or shining upwards; those terms are left at 0 for the caller to compute). Shadow
    points behind a camera are clipped (:func:`_clip_and_project`).
    """
    N, J = lights.shape[0], lights.shape[1]
    C, h, w = occ_index.shape
    out = np.zeros((N, C, 3))
    ok = np.ones((N, C), dtype=np.bool_)
    facing = np.empty(n.shape[0], dtype=np.bool_)
    seg = np.empty((J * eu.shape[0], 6))
    uv = np.empty((2 * J * eu.shape[0], 4))
    diff = np.zeros((h, w + 1), dtype=np.int32)
    model = np.zeros((h, w), dtype=np.bool_)
    box = np.empty(4, dtype=np.int64)
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
            ms = _clip_and_project(seg, m, M[k], plane, uv)
            # winding fill (as studio.render.winding.winding_fill)
            box[0], box[1], box[2], box[3] = h, -1, w, -1
            for s in range(ms):
                scan_segment(uv[s, 0], uv[s, 1], uv[s, 2], uv[s, 3], diff, box)
            ya, yb, xa, xb = box[0], box[1], box[2], box[3]
            fwd, count = 0.0, 0
            if yb >= 0 and xa < w:
                for yi in range(ya, yb + 1):
                    acc = 0
                    for xi in range(xa, min(xb, w)):
                        acc += diff[yi, xi]
                        if acc != 0 and not (occ_index[k, yi, xi] >= 0 and occ[k, occ_index[k, yi, xi]]):
                            model[yi, xi] = True
                            fwd += dmaps[k, yi, xi]
                            count += 1
            # observed → predicted: distance to the nearest predicted pixel, at most τ
            bwd = tau * n_observed[k]
            if count > 0:
                _, near, _, n_inside = numerators_in_box(model, observed[k], dmaps[k], tau, r, ya, yb + 1, xa,
                                                         min(xb, w))
                bwd = tau * (n_observed[k] - n_inside) + near
            out[i, k, 0], out[i, k, 1], out[i, k, 2] = fwd, bwd, count
            if yb >= 0:
                for yi in range(ya, yb + 1):
                    for xi in range(xa, min(xb, w) + 1):
                        diff[yi, xi] = 0
                        if xi < w:
                            model[yi, xi] = False
    return out, ok
