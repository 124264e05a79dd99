"""Shadow meshes: a body projected through a light onto the ground plane (thesis §5.4).

A point light L and the ground plane form a *shadow camera*: the shadow of a point P is
``S = L + λ (P − L)`` with ``λ = (d − n·L) / (n·(P − L))`` (eqs. 5.1–5.2, plane ``n·X = d``);
a directional light shining along ω gives ``S = P − ω (n·P − d) / (n·ω)`` (distant-light
case of §5.4). The projected vertices with the body's faces are the shadow mesh (eq. 5.3),
rasterised into each camera like any mesh.

:func:`shadow_silhouettes` is the fast path the light estimator and the shadow term of the fit
call thousands of times: the shadow of a closed mesh is bounded by the projection of its
occluding contour *as seen from the light* (edges between a face turned towards the light and
one turned away), so only those few hundred edges are projected onto the plane (eq. 5.2) and
into each camera (eq. 5.3), and filled by winding number — the same masks as
:func:`shadow_mask`, for one or several lights at once (their union, §5.4.2).
"""

from __future__ import annotations

import numpy as np

from studio.render.lights import DirectionalLight, PointLight
from studio.render.raster import front_facing, silhouette

__all__ = ["fill_outlines", "join_outlines", "light_facing", "shadow_mask", "shadow_outline", "shadow_silhouettes", "shadow_vertices"]


def _plane(ground) -> tuple[np.ndarray, float]:
    if ground is None:
        return np.array([0.0, 0.0, 1.0]), 0.0
    n = np.asarray(ground.normal, dtype=np.float64)
    return n / np.linalg.norm(n), float(ground.offset)


def shadow_vertices(vertices: np.ndarray, light, ground=None) -> tuple[np.ndarray, np.ndarray]:
    """Project vertices (V, 3) onto the ground through ``light`` (eq. 5.2).

    ``ground`` has ``normal`` (3,) and ``offset`` (n·X = offset; default the floor z = 0).
    Returns (V, 3) shadow points and (V,) bool ``valid``: the vertex lies between the light
    and the plane (a point light above the vertex, or a directional light pointing at the
    plane); invalid vertices are returned unchanged.
    """
    P = np.asarray(vertices, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 3:
        raise ValueError(f"vertices: expected shape (V, 3), got {P.shape}")
    n, d = _plane(ground)
    if isinstance(light, PointLight):
        L = light.position
        hL = float(n @ L) - d
        ray = P - L
        den = ray @ n
        valid = (hL > 0) & (den < -1e-12) & ((P @ n - d) < hL)
        lam = np.where(valid, (d - n @ L) / np.where(valid, den, 1.0), 1.0)
        S = L + lam[:, None] * ray
    elif isinstance(light, DirectionalLight):
        w = light.direction
        den = float(n @ w)
        if den >= -1e-12:
            return P.copy(), np.zeros(len(P), dtype=bool)
        h = P @ n - d
        S = P - np.outer(h / den, w)
        valid = h >= 0
    else:
        raise TypeError(f"light: expected PointLight or DirectionalLight, got {type(light).__name__}")
    S = np.where(valid[:, None], S, P)
    return S, valid


def shadow_mask(camera, vertices: np.ndarray, faces: np.ndarray, light, ground=None, *,
                closed: bool = True) -> np.ndarray:
    """(H, W) bool: pixels of the floor shadow of the mesh cast by ``light`` (eq. 5.3).

    For a ``closed`` mesh only the faces turned towards the light are projected (the shadow
    is the light's view of the body, so the front faces cover it). Faces with an invalid
    vertex (above a point light) are dropped. Where the person occludes the shadow is the
    caller's business (labels put the person first).
    """
    S, valid = shadow_vertices(vertices, light, ground)
    F = np.asarray(faces)
    if closed:
        if isinstance(light, PointLight):
            F = F[front_facing(None, vertices, F, point=light.position)]
        else:
            F = F[front_facing(None, vertices, F, direction=light.direction)]
    F = F[np.all(valid[F], axis=1)]
    return silhouette(camera, S, F, closed=False)


def light_facing(normals: np.ndarray, na: np.ndarray, sign: float, light) -> np.ndarray:
    """(F,) bool: faces turned towards ``light``, from :func:`studio.render.spans.face_normals`
    (unnormalised normals (F, 3), ``n · a`` (F,), the enclosed volume's sign)."""
    if isinstance(light, PointLight):
        return (normals @ light.position - na) * sign > 0
    if isinstance(light, DirectionalLight):
        return (normals @ -light.direction) * sign > 0
    raise TypeError(f"light: expected PointLight or DirectionalLight, got {type(light).__name__}")


def shadow_outline(vertices: np.ndarray, faces: np.ndarray, light, ground=None, *,
                   normals: tuple | None = None, topology=None) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The directed outline of the shadow of a closed mesh on the ground (eq. 5.2).

    Returns ``points`` (U, 3) on the plane (the shadows of the light's occluding-contour
    vertices) and ``start``, ``end`` (E,) indices into them: each contour edge directed as in its
    light-facing face, so that the winding number of the outline around a floor point counts the
    light-facing faces whose shadow covers it. ``normals`` may pass
    :func:`studio.render.spans.face_normals` of the mesh and ``topology`` its
    ``studio.render.spans._topology`` (computed once for many lights).
    None when the fast path does not apply (an open or inconsistently wound mesh, a contour
    vertex at or above a point light's height, a light shining upwards): use
    :func:`shadow_mask`.
    """
    from studio.render.spans import _topology, face_normals
    from studio.render.winding import contour_edges

    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(faces, dtype=np.int64)
    topo = _topology(F, len(V)) if topology is None else topology
    if topo is None:
        return None
    n, na, sign = face_normals(V, F) if normals is None else normals
    facing = light_facing(n, na, sign, light)
    u, v, used = contour_edges(facing, topo.u, topo.v, topo.f_uv, topo.f_vu, len(V))
    S, valid = shadow_vertices(V[used], light, ground)
    if isinstance(light, DirectionalLight):
        valid = np.ones(len(used), bool) if float(_plane(ground)[0] @ light.direction) < -1e-12 else valid
    if not valid.all():
        return None
    index = np.empty(len(V), dtype=np.int64)
    index[used] = np.arange(len(used))
    return S, index[u], index[v]


def shadow_silhouettes(cameras, vertices: np.ndarray, faces: np.ndarray, lights, ground=None, *,
                       normals: tuple | None = None, topology=None, occluders=None) -> list[np.ndarray]:
    """(H_k, W_k) bool shadow of a closed mesh in each camera: the union over ``lights`` (a
    light or a sequence) of the floor shadows (eqs. 5.2-5.3, several lights §5.4.2); same
    masks as :func:`shadow_mask` (with which it falls back when the outline fast path does
    not apply). ``occluders`` (per camera (H_k, W_k) bool, e.g. the body's own silhouette) are
    taken out: the visible shadow (thesis §5.6, shadows first, then the body)."""
    lights = [lights] if isinstance(lights, (PointLight, DirectionalLight)) else list(lights)
    outlines = [shadow_outline(vertices, faces, light, ground, normals=normals, topology=topology)
                for light in lights]
    out = []
    for k, cam in enumerate(cameras):
        m = fill_outlines(cam, outlines) if all(o is not None for o in outlines) else None
        if m is None:  # the exact path
            m = np.zeros((cam.size[1], cam.size[0]), bool)
            for light in lights:
                m |= shadow_mask(cam, vertices, faces, light, ground)
        out.append(m if occluders is None else m & ~occluders[k])
    return out


def join_outlines(outlines) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One outline (points, start, end) of several (:func:`shadow_outline`): their union."""
    points, starts, ends, k = [], [], [], 0
    for P, a, b in outlines:
        points.append(P)
        starts.append(a + k)
        ends.append(b + k)
        k += len(P)
    if not points:
        z = np.zeros(0, np.int64)
        return np.zeros((0, 3)), z, z
    return np.concatenate(points), np.concatenate(starts), np.concatenate(ends)


def fill_outlines(camera, outlines) -> np.ndarray | None:
    """(H, W) bool pixels of ``camera`` inside the union of ``outlines`` (each (points, start,
    end) of :func:`shadow_outline`), filled by winding number; None when a point lies behind
    the camera."""
    from studio.render.winding import winding_fill

    w, h = camera.size
    P, a, b = join_outlines(outlines)
    if len(a) == 0:
        return np.zeros((h, w), bool)
    uv, depth, _ = camera.project_points(P)
    if depth.min() <= 1e-3:
        return None
    return winding_fill(uv[a], uv[b], w, h)
