"""Accuracy of a fit against a simulated session's truth (thesis §4.8).

- true meshes: the Anny vertices of ``truth/bodies/NNNNNN.npz`` mapped into our template's
  topology with :func:`studio.body.anny_correspondence` (the map the model was learned with);
- joint error (eq. 4.17): mean distance between corresponding joint centres, both obtained by
  applying OUR joint regressor (``model.joint_regressor``, (15, V)) to the posed meshes — the
  fitted mesh and the mapped true mesh — so both sides use the same joint definition;
- surface distance: symmetric mean point-to-surface distance, approximated with a k-d tree on
  dense area-uniform surface samples of each mesh;
- silhouette precision / recall of the fitted silhouettes against the true person labels.
"""

from __future__ import annotations

import numpy as np

from studio.fit.errors import FitError

__all__ = ["joint_error", "silhouette_agreement", "surface_distance", "surface_samples", "true_mesh",
           "true_person_masks"]


def true_mesh(session_path, frame: int) -> np.ndarray:
    """True body (V, 3) of ``frame`` in our model's topology (world metres)."""
    from studio.body import anny_correspondence
    from studio.workspace import Layout

    p = Layout(session_path).truth_body(frame)
    if not p.is_file():
        raise FitError(f"{p}: no true body (not a simulated session?)")
    with np.load(p) as z:
        anny = z["vertices"].astype(np.float64)
    A = anny_correspondence()
    if anny.shape[0] != A.shape[1]:
        raise FitError(f"{p}: {anny.shape[0]} vertices, the Anny correspondence expects {A.shape[1]}")
    return np.asarray(A @ anny)


def true_person_masks(session_path, frame: int, cameras) -> list[np.ndarray]:
    """The simulator's true person pixels (label 1 of ``truth/labels``) of ``frame``, (H, W) bool
    per camera of ``cameras`` (objects with a ``name``), in that order."""
    from rigs.imageio import read_image
    from studio.workspace import Layout

    lay = Layout(session_path)
    return [read_image(lay.truth_labels(c.name, frame)) == 1 for c in cameras]


def surface_samples(vertices: np.ndarray, faces: np.ndarray, n: int, rng) -> np.ndarray:
    """(n, 3) points uniformly distributed over the mesh surface."""
    rng = np.random.default_rng(rng)
    a, b, c = (vertices[faces[:, i]] for i in range(3))
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    tri = rng.choice(len(faces), size=n, p=area / area.sum())
    r1 = np.sqrt(rng.random(n))[:, None]
    r2 = rng.random(n)[:, None]
    return (1 - r1) * a[tri] + r1 * (1 - r2) * b[tri] + r1 * r2 * c[tri]


def surface_distance(va, fa, vb, fb, *, n: int = 60000, seed=0) -> float:
    """Symmetric mean surface distance (metres) between two meshes (dense-sample k-d trees)."""
    from scipy.spatial import cKDTree

    rng = np.random.default_rng(seed)
    sa = surface_samples(np.asarray(va, float), np.asarray(fa), n, rng)
    sb = surface_samples(np.asarray(vb, float), np.asarray(fb), n, rng)
    dab = cKDTree(sb).query(sa[: n // 4])[0]
    dba = cKDTree(sa).query(sb[: n // 4])[0]
    return float(0.5 * (dab.mean() + dba.mean()))


def joint_error(model, fitted_vertices: np.ndarray, true_vertices: np.ndarray) -> tuple[float, np.ndarray]:
    """Mean joint position error (eq. 4.17, metres) and per-joint errors (15,)."""
    R = model.joint_regressor
    d = np.linalg.norm(R @ fitted_vertices - R @ true_vertices, axis=1)
    return float(d.mean()), d


def silhouette_agreement(model_masks, true_masks) -> tuple[float, float]:
    """Pixel precision and recall of model silhouettes against true silhouettes (all views pooled)."""
    inter = sum(int(np.count_nonzero(m & t)) for m, t in zip(model_masks, true_masks, strict=True))
    nm = sum(int(np.count_nonzero(m)) for m in model_masks)
    nt = sum(int(np.count_nonzero(t)) for t in true_masks)
    return inter / max(nm, 1), inter / max(nt, 1)
