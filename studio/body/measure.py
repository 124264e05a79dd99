"""Anthropometric measurements of a body of the model (thesis §6.4.4).

All in metres / kilograms, on the body in its canonical standing pose (the default pose,
standing on z = 0). Circumferences are horizontal slices of the trunk and the perimeter of
the slice's convex hull (a tape measure bridges concavities, thesis §6.4.4):

- ``stature``: top of the head above the floor;
- ``arm_span``: fingertip to fingertip in a T-pose (arms rotated horizontal, elbows straight);
- ``shoulder_breadth``: widest horizontal extent of torso + upper arms at shoulder level
  (bideltoid-like);
- ``chest_circumference``: maximum torso slice between 6 and 22 cm below the shoulder joints;
- ``waist_circumference``: minimum trunk slice between the hips and the chest;
- ``hip_circumference``: maximum slice of pelvis + thighs around the hip joints (buttocks);
- ``inseam``: crotch height above the floor;
- ``arm_length``: shoulder joint → elbow → wrist joint (mean of both arms);
- ``volume`` (closed mesh, divergence theorem) and ``mass`` = volume × density
  (980 kg/m³ by default, the value Anny's anthropometry uses).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull

from studio.body.skeleton import PART_NAMES

__all__ = [
    "measure",
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


def _scan(vertices, faces, z0, z1, step=0.005):
    zs = np.arange(z0, z1 + 1e-9, step)
    e = _edges(faces)
    # only edges spanning the scanned band matter
    lo = np.minimum(vertices[e[:, 0], 2], vertices[e[:, 1], 2])
    hi = np.maximum(vertices[e[:, 0], 2], vertices[e[:, 1], 2])
    e = e[(hi >= z0) & (lo <= z1)]
    return zs, np.array([convex_perimeter(slice_points(vertices, faces, z, e)) for z in zs])


def t_pose(model, shape) -> np.ndarray:
    """Pose with the upper arms horizontal (±x) and the elbows straight."""
    from studio.body.scape import rotvec_to_matrix  # noqa: F401  (doc link)

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


def measure(model, shape, density: float = 980.0) -> dict[str, float]:
    """Measurements of the body ``shape`` of ``model`` (metres, kilograms); see module doc."""
    shape = model.check_shape(shape)
    if not np.isfinite(density) or density <= 0:
        raise ValueError(f"density must be a positive number of kg/m³, got {density}")
    v = model.vertices(shape)
    J = model.joints(shape)
    f = model.faces
    fp = model.face_parts
    out: dict[str, float] = {}
    out["stature"] = float(v[:, 2].max() - v[:, 2].min())
    vt = model.vertices(shape, t_pose(model, shape))
    out["arm_span"] = float(vt[:, 0].max() - vt[:, 0].min())

    sh_z = 0.5 * (J[_P["upperarm_l"], 2] + J[_P["upperarm_r"], 2])
    hip_z = 0.5 * (J[_P["upperleg_l"], 2] + J[_P["upperleg_r"], 2])
    sel = np.isin(model.parts, [_P["torso"], _P["upperarm_l"], _P["upperarm_r"]]) & (v[:, 2] > sh_z - 0.03)
    out["shoulder_breadth"] = float(v[sel, 0].max() - v[sel, 0].min()) if np.any(sel) else 0.0

    torso_f = f[fp == _P["torso"]]
    trunk_f = f[np.isin(fp, [_P["torso"], _P["pelvis"]])]
    hips_f = f[np.isin(fp, [_P["pelvis"], _P["upperleg_l"], _P["upperleg_r"]])]
    zs, c = _scan(v, torso_f, sh_z - 0.22, sh_z - 0.06)
    out["chest_circumference"] = float(c.max())
    chest_z = float(zs[np.argmax(c)])
    zs, c = _scan(v, trunk_f, hip_z + 0.06, chest_z - 0.05)
    c = np.where(c > 0, c, np.inf)
    out["waist_circumference"] = float(c.min())
    zs, c = _scan(v, hips_f, hip_z - 0.15, hip_z + 0.05)
    out["hip_circumference"] = float(c.max())

    knee_z = 0.5 * (J[_P["lowerleg_l"], 2] + J[_P["lowerleg_r"], 2])
    mid = (np.abs(v[:, 0]) < 0.015) & (v[:, 2] > knee_z) & (v[:, 2] < sh_z)
    mid &= np.isin(model.parts, [_P["pelvis"], _P["upperleg_l"], _P["upperleg_r"]])
    out["inseam"] = float(v[mid, 2].min() - v[:, 2].min()) if np.any(mid) else float("nan")

    lengths = []
    for side in ("l", "r"):
        s, e, w = J[_P[f"upperarm_{side}"]], J[_P[f"lowerarm_{side}"]], J[_P[f"hand_{side}"]]
        lengths.append(np.linalg.norm(e - s) + np.linalg.norm(w - e))
    out["arm_length"] = float(np.mean(lengths))
    out["volume"] = float(mesh_volume(v, f))
    out["mass"] = out["volume"] * density
    return out
