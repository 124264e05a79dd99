"""Anthropometric measurements of a body of the model (thesis §6.4.4).

All in metres / kilograms, on the body in its canonical standing pose (the default pose,
standing on z = 0). Every measurement that ISO 7250-1 defines comes from
:mod:`studio.body.iso7250` (the one definition of each, with its clause and landmarks):
``stature``, ``arm_span``, ``chest_circumference``, ``waist_circumference``,
``hip_circumference``, ``mass`` and ``inseam`` (= ISO crotch height) under these names, and
all of :data:`~studio.body.iso7250.ISO_NAMES` besides. Kept here, for the shape prior's
stored samples (:mod:`studio.body.inverse`), are the model's own:

- ``shoulder_breadth``: widest horizontal extent of torso + upper arms at shoulder level
  (bideltoid-like);
- ``arm_length``: shoulder joint → elbow → wrist joint (mean of both arms);
- ``volume`` (closed mesh, divergence theorem); ``mass`` = volume × density
  (980 kg/m³ by default, the value Anny's anthropometry uses).

Circumferences are perimeters of the convex hull of a plane section (a tape measure bridges
concavities, thesis §6.4.4).

:func:`measure_mesh` holds the definitions (on given meshes and joints); :func:`measure`
applies them to a body of the model, :func:`measure_anny_body` to a true (simulated) Anny
body mapped into the model's topology, so that fit and truth share every definition.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull

from studio.body.skeleton import PART_NAMES

__all__ = [
    "measure",
    "measure_mesh",
    "measure_anny_body",
    "place_canonical",
    "mesh_volume",
    "slice_points",
    "convex_perimeter",
    "slice_circumference",
    "t_pose",
    "MEASUREMENT_NAMES",
]

MEASUREMENT_NAMES = (
    "stature",
    "arm_span",
    "shoulder_breadth",
    "chest_circumference",
    "waist_circumference",
    "hip_circumference",
    "inseam",
    "arm_length",
    "volume",
    "mass",
)

_P = {n: i for i, n in enumerate(PART_NAMES)}


def mesh_volume(vertices: np.ndarray, faces: np.ndarray) -> float | np.ndarray:
    """Enclosed volume of a closed triangle mesh: |Σ (a × b)·c| / 6. (..., V, 3) → (...)."""
    a = vertices[..., faces[:, 0], :]
    b = vertices[..., faces[:, 1], :]
    c = vertices[..., faces[:, 2], :]
    return np.abs(np.einsum("...i,...i->...", np.cross(a, b), c).sum(axis=-1)) / 6.0


def _edges(faces: np.ndarray) -> np.ndarray:
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    return np.unique(np.sort(e, axis=1), axis=0)


def slice_points(vertices: np.ndarray, faces: np.ndarray, z: float, edges: np.ndarray | None = None) -> np.ndarray:
    """Points (N, 2) where the mesh edges cross the horizontal plane at height ``z``.

    ``edges`` (E, 2) may be given to skip recomputing the unique edges of ``faces``.
    """
    e = _edges(faces) if edges is None else edges
    za, zb = vertices[e[:, 0], 2] - z, vertices[e[:, 1], 2] - z
    cross = (za * zb) < 0
    t = za[cross] / (za[cross] - zb[cross])
    p = vertices[e[cross, 0]] + t[:, None] * (vertices[e[cross, 1]] - vertices[e[cross, 0]])
    return p[:, :2]


def convex_perimeter(points: np.ndarray) -> float:
    """Perimeter of the 2-D convex hull of ``points`` (N, 2); 0 for fewer than 3 points."""
    if len(points) < 3:
        return 0.0
    hull = ConvexHull(points)
    ring = points[hull.vertices]
    return float(np.linalg.norm(ring - np.roll(ring, 1, axis=0), axis=1).sum())


def slice_circumference(vertices: np.ndarray, faces: np.ndarray, z: float) -> float:
    """Convex-hull perimeter of the horizontal slice at ``z`` (thesis §6.4.4)."""
    return convex_perimeter(slice_points(vertices, faces, z))


def t_pose(model, shape) -> np.ndarray:
    """Pose with the upper arms horizontal (±x) and the elbows straight."""
    
    pose = model.default_pose()
    J = model.joints(shape, pose)
    from studio.body.skeleton import pose_slices

    sl = pose_slices()
    for side, sign in (("l", 1.0), ("r", -1.0)):
        s, e = J[_P[f"upperarm_{side}"]], J[_P[f"lowerarm_{side}"]]
        d = (e - s) / np.linalg.norm(e - s)
        target = np.array([sign, 0.0, 0.0])
        axis = np.cross(d, target)
        ang = np.arctan2(np.linalg.norm(axis), d @ target)
        pose[sl[_P[f"upperarm_{side}"]]] = axis / max(np.linalg.norm(axis), 1e-12) * ang
        w = J[_P[f"hand_{side}"]]
        d2 = (w - e) / np.linalg.norm(w - e)
        bend = np.arccos(np.clip(d @ d2, -1, 1))
        pose[sl[_P[f"lowerarm_{side}"]]] = -bend
    return model.clip_pose(pose)


def _check_mesh(name: str, array, shape: tuple, dtype=np.float64) -> np.ndarray:
    """``array`` as ``dtype`` with ``shape`` (None = any length), or a ValueError naming it."""
    a = np.asarray(array, dtype=dtype)
    if a.ndim != len(shape) or any(w is not None and w != n for w, n in zip(shape, a.shape)):
        want = "(" + ", ".join("N" if w is None else str(w) for w in shape) + ")"
        raise ValueError(f"{name} must have shape {want}, got {a.shape}")
    if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
        raise ValueError(f"{name} contains NaN or infinite values")
    return a


def measure_mesh(
    vertices: np.ndarray,
    tpose_vertices: np.ndarray,
    joints: np.ndarray,
    faces: np.ndarray,
    parts: np.ndarray,
    face_parts: np.ndarray,
    density: float = 980.0,
) -> dict[str, float]:
    """Measurements (metres, kilograms; see module doc) of one body given as meshes.

    ``vertices`` (V, 3) float64: the body in its canonical standing pose (the model's
    default pose), Z up, facing -y, its sagittal plane at x = 0 (``inseam`` looks for the
    crotch within 15 mm of it); ``tpose_vertices`` (V, 3): the same body in the T-pose of
    :func:`t_pose` (only its x-extent is used: ``arm_span``); ``joints`` (15, 3): joint
    centres of the canonical pose in :data:`~studio.body.skeleton.PART_NAMES` order;
    ``faces`` (F, 3) int; ``parts`` (V,) and ``face_parts`` (F,): part index per vertex /
    triangle (the model's topology: ``model.faces``, ``model.parts``, ``model.face_parts``).
    """
    v = _check_mesh("vertices", vertices, (None, 3))
    vt = _check_mesh("tpose_vertices", tpose_vertices, (len(v), 3))
    J = _check_mesh("joints", joints, (len(PART_NAMES), 3))
    f = _check_mesh("faces", faces, (None, 3), np.int64)
    parts = _check_mesh("parts", parts, (len(v),), np.int64)
    fp = _check_mesh("face_parts", face_parts, (len(f),), np.int64)
    if len(f) and (f.min() < 0 or f.max() >= len(v)):
        raise ValueError(f"faces index vertices {f.min()}..{f.max()}, the mesh has {len(v)}")
    if not np.isfinite(density) or density <= 0:
        raise ValueError(f"density must be a positive number of kg/m³, got {density}")
    from studio.body.iso7250 import measure_iso

    iso = measure_iso(v, vt, J, f, parts, fp, density=density).values
    out: dict[str, float] = {}
    out["stature"] = iso["stature"]
    out["arm_span"] = iso["arm_span"]
    sh_z = 0.5 * (J[_P["upperarm_l"], 2] + J[_P["upperarm_r"], 2])
    sel = np.isin(parts, [_P["torso"], _P["upperarm_l"], _P["upperarm_r"]]) & (v[:, 2] > sh_z - 0.03)
    out["shoulder_breadth"] = float(v[sel, 0].max() - v[sel, 0].min()) if np.any(sel) else 0.0
    for name in ("chest_circumference", "waist_circumference", "hip_circumference"):
        out[name] = iso[name]
    out["inseam"] = iso["crotch_height"]
    lengths = []
    for side in ("l", "r"):
        s, e, w = J[_P[f"upperarm_{side}"]], J[_P[f"lowerarm_{side}"]], J[_P[f"hand_{side}"]]
        lengths.append(np.linalg.norm(e - s) + np.linalg.norm(w - e))
    out["arm_length"] = float(np.mean(lengths))
    out["volume"] = float(mesh_volume(v, f))
    out["mass"] = iso["mass"]
    out.update({k: val for k, val in iso.items() if k not in out})
    return out


def measure(model, shape, density: float = 980.0) -> dict[str, float]:
    """Measurements of the body ``shape`` of ``model`` (metres, kilograms); see module doc.

    The default-pose mesh, its T-pose (:func:`t_pose`) and joints, measured by
    :func:`measure_mesh`.
    """
    shape = model.check_shape(shape)
    if not np.isfinite(density) or density <= 0:
        raise ValueError(f"density must be a positive number of kg/m³, got {density}")
    v = model.vertices(shape)
    vt = model.vertices(shape, t_pose(model, shape))
    return measure_mesh(v, vt, model.joints(shape), model.faces, model.parts, model.face_parts, density)


def place_canonical(vertices: np.ndarray, parts: np.ndarray) -> np.ndarray:
    """Shift (V, 3) like the model's default pose: pelvis centroid over the origin, floor z = 0.

    ``parts`` (V,) gives the pelvis vertices (part index of ``"pelvis"``).
    """
    v = np.asarray(vertices, dtype=np.float64)
    c = v[np.asarray(parts) == _P["pelvis"]].mean(axis=0)
    return v - [c[0], c[1], v[:, 2].min()]


def measure_anny_body(model, rest_vertices, tpose_vertices, density: float = 980.0) -> dict[str, float]:
    """Measurements by this module's definitions of a body given as Anny meshes.

    ``rest_vertices`` and ``tpose_vertices`` (13348, 3): an Anny body (topology
    ``anny-noeyes-notongue``, Anny's frame: Z up, facing -y, left +x) in Anny's rest pose —
    the posture the model's template and default pose were built from — and in the T-pose of
    :func:`t_pose` (upper arms horizontal, elbows straight), e.g. ``rest_q`` / ``tpose_q`` of
    a simulation ``body.npz``. Both are mapped into the model's topology with
    :func:`~studio.body.model.anny_correspondence` (the map the model was learned with),
    placed like the default pose (:func:`place_canonical`), and measured with
    :func:`measure_mesh`; the joints are the model's ``joint_regressor`` applied to the
    mapped rest mesh. The truth of a simulated person by the same definitions as a fit.
    """
    from studio.body.model import anny_correspondence

    A = anny_correspondence()
    n = A.shape[1]
    rest = _check_mesh("rest_vertices", rest_vertices, (n, 3))
    tpose = _check_mesh("tpose_vertices", tpose_vertices, (n, 3))
    if A.shape[0] != model.n_vertices:
        raise ValueError(f"the Anny correspondence maps to {A.shape[0]} vertices, the "
                         f"{model.gender} model has {model.n_vertices}")
    v = place_canonical(A @ rest, model.parts)
    vt = place_canonical(A @ tpose, model.parts)
    J = np.asarray(model.joint_regressor, dtype=np.float64) @ v
    return measure_mesh(v, vt, J, model.faces, model.parts, model.face_parts, density)
