"""Shadow meshes: a body projected through a light onto the ground plane (thesis §5.4).

A point light L and the ground plane form a *shadow camera*: the shadow of a point P is
``S = L + λ (P − L)`` with ``λ = (d − n·L) / (n·(P − L))`` (eqs. 5.1–5.2, plane ``n·X = d``);
a directional light shining along ω gives ``S = P − ω (n·P − d) / (n·ω)`` (distant-light
case of §5.4). The projected vertices with the body's faces are the shadow mesh (eq. 5.3),
rasterised into each camera like any mesh.
"""

from __future__ import annotations

import numpy as np

from studio.render.lights import DirectionalLight, PointLight
from studio.render.raster import front_facing, silhouette

__all__ = ["shadow_vertices", "shadow_mask"]


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
