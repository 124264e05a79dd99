"""Lambertian shading of rasterised meshes (the colour path of the renderer)."""

from __future__ import annotations

import numpy as np

from studio.render.raster import Raster

__all__ = ["vertex_normals", "lambert", "shade_raster"]


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals (V, 3) of a mesh (V, 3) / (F, 3)."""
    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(faces)
    fn = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    idx = F.T.ravel()  # vertex of each (corner, face)
    n = np.stack([np.bincount(idx, weights=np.tile(fn[:, j], 3), minlength=len(V))
                  for j in range(3)], axis=1)
    # orientation: outward for a closed mesh whatever its winding
    if np.einsum("ij,ij->", fn, V[F[:, 0]]) < 0:
        n = -n
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)


def lambert(points: np.ndarray, normals: np.ndarray, lights, ambient: float,
            visibility: list[np.ndarray] | None = None) -> np.ndarray:
    """Irradiance factor (N,) = ambient + Σ_l I_l · max(0, n·l̂) [· visibility_l].

    ``points``/``normals`` (N, 3); ``visibility`` optional list of (N,) factors in [0, 1].
    """
    E = np.full(len(points), float(ambient))
    for k, light in enumerate(lights):
        ldir, scale = light.directions_to(points)
        term = np.maximum(np.einsum("ij,ij->i", normals, ldir), 0.0) * scale
        if visibility is not None:
            term = term * visibility[k]
        E += term
    return E


def shade_raster(raster: Raster, vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray,
                 albedo: np.ndarray, lights, ambient: float) -> tuple[np.ndarray, np.ndarray]:
    """Linear radiance of the covered pixels of a :class:`Raster`.

    ``albedo`` (V, 3) linear RGB per vertex; normals (V, 3). Returns (pixel linear indices (n,),
    radiance (n, 3) float32), interpolating position, normal and albedo with the barycentric
    weights of each pixel.
    """
    face = raster.face.ravel()
    pix = np.flatnonzero(face >= 0)
    f = face[pix]
    b = raster.bary.reshape(-1, 3)[pix].astype(np.float64)
    tri = np.asarray(faces)[f]  # (n, 3)
    P = np.einsum("nk,nkj->nj", b, vertices[tri])
    N = np.einsum("nk,nkj->nj", b, normals[tri])
    N /= np.maximum(np.linalg.norm(N, axis=1, keepdims=True), 1e-12)
    A = np.einsum("nk,nkj->nj", b, albedo[tri])
    E = lambert(P, N, lights, ambient)
    return pix, (A * E[:, None]).astype(np.float32)
