"""The coarse cylinder body model of thesis §4.8.1: 15 truncated cones on the SCAPE skeleton.

Each part is a truncated cone between two points fixed to the part (its joint and its
distal end) with one radius at each end, sized from a SCAPE body: the axis joins the part's
joint to its child joint (or to the farthest vertex for head, hands and feet) and the two
radii are a least-squares linear fit of the part vertices' distance to the axis. It moves
with the same pose vector as the SCAPE model (same kinematic tree, same part rotations).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from studio.body.skeleton import PART_NAMES

__all__ = ["CylinderModel", "cone_faces", "cone_meshes"]

_P = {n: i for i, n in enumerate(PART_NAMES)}
#: distal end of each part: a child joint, or None (farthest vertex along the part)
_DISTAL = {
    "pelvis": "torso",
    "torso": "head",
    "head": None,
    "upperarm_l": "lowerarm_l",
    "lowerarm_l": "hand_l",
    "hand_l": None,
    "upperarm_r": "lowerarm_r",
    "lowerarm_r": "hand_r",
    "hand_r": None,
    "upperleg_l": "lowerleg_l",
    "lowerleg_l": "foot_l",
    "foot_l": None,
    "upperleg_r": "lowerleg_r",
    "lowerleg_r": "foot_r",
    "foot_r": None,
}


@dataclass(frozen=True)
class CylinderModel:
    """Truncated cones sized from one body; ``ends`` are in the default pose.

    ``ends`` (15, 2, 3) proximal/distal axis points, ``radii`` (15, 2) metres,
    ``joints`` (15, 3) rest joint centres; ``model`` supplies the kinematics.
    """

    model: object
    shape: np.ndarray
    ends: np.ndarray
    radii: np.ndarray
    joints: np.ndarray

    @classmethod
    def from_shape(cls, model, shape) -> "CylinderModel":
        """Size the 15 cones from the SCAPE body ``shape`` of ``model`` (default pose)."""
        shape = model.check_shape(shape)
        v = model.vertices(shape)
        J = model.joints(shape)
        ends = np.zeros((15, 2, 3))
        radii = np.zeros((15, 2))
        for p, name in enumerate(PART_NAMES):
            pts = v[model.parts == p]
            if name == "pelvis":
                a = 0.5 * (J[_P["upperleg_l"]] + J[_P["upperleg_r"]])
                a = a.copy()
                a[2] = pts[:, 2].min()
            else:
                a = J[p]
            if _DISTAL[name] is not None:
                b = J[_P[_DISTAL[name]]]
            else:
                d = pts.mean(axis=0) - a
                d /= np.linalg.norm(d)
                b = a + d * np.max((pts - a) @ d)
            axis = b - a
            length = np.linalg.norm(axis)
            u = axis / length
            t = ((pts - a) @ u) / length
            r = np.linalg.norm((pts - a) - np.outer(t * length, u), axis=1)
            keep = (t >= 0) & (t <= 1)
            if keep.sum() < 10:
                keep = np.ones(len(t), bool)
            A = np.stack([1 - t[keep], t[keep]], axis=1)
            r0, r1 = np.linalg.lstsq(A, r[keep], rcond=None)[0]
            ends[p] = a, b
            radii[p] = max(r0, 0.01), max(r1, 0.01)
        return cls(model=model, shape=shape, ends=ends, radii=radii, joints=J)

    def segments(self, pose) -> tuple[np.ndarray, np.ndarray]:
        """Posed cone ends (15, 2, 3) and radii (15, 2) for one pose vector."""
        e, r = self.segments_batch(np.asarray(pose, dtype=float)[None])
        return e[0], r

    def segments_batch(self, poses) -> tuple[np.ndarray, np.ndarray]:
        """Posed cone ends (B, 15, 2, 3) for poses (B, POSE_SIZE); radii (15, 2)."""
        poses = self.model.check_pose(poses, batch=True)
        B = len(poses)
        G = self.model.part_rotations(poses)
        Jp = self.model.joints_batch(np.broadcast_to(self.shape, (B, len(self.shape))), poses)
        local = self.ends - self.joints[:, None, :]  # (15, 2, 3)
        out = Jp[:, :, None, :] + np.einsum("bpij,pkj->bpki", G, local)
        return out, self.radii

    def mesh(self, pose, sides: int = 12) -> tuple[np.ndarray, np.ndarray]:
        """Closed triangle mesh ``(V, F)`` of the posed cones (for display/rendering)."""
        ends, radii = self.segments(pose)
        return cone_meshes(ends[None], radii, sides)[0], cone_faces(sides)


def cone_faces(sides: int = 12, n_parts: int = 15) -> np.ndarray:
    """(n_parts · 4 · sides, 3) faces of ``n_parts`` closed cones of ``2·sides + 2`` vertices
    each (ring at the proximal end, ring at the distal end, the two cap centres)."""
    i = np.arange(sides)
    j = (i + 1) % sides
    f = np.concatenate([
        np.stack([i, j, sides + j], 1), np.stack([i, sides + j, sides + i], 1),
        np.stack([np.full(sides, 2 * sides), j, i], 1),
        np.stack([np.full(sides, 2 * sides + 1), sides + i, sides + j], 1),
    ])
    n = 2 * sides + 2
    return np.concatenate([f + p * n for p in range(n_parts)])


def cone_meshes(ends: np.ndarray, radii: np.ndarray, sides: int = 12) -> np.ndarray:
    """Vertices (B, 15 · (2·sides + 2), 3) of posed cones ``ends`` (B, P, 2, 3) with
    ``radii`` (P, 2); faces from :func:`cone_faces`."""
    ends = np.asarray(ends, dtype=np.float64)
    a, b = ends[:, :, 0], ends[:, :, 1]  # (B, P, 3)
    u = b - a
    u /= np.linalg.norm(u, axis=-1, keepdims=True)
    ref = np.where((np.abs(u[..., 0]) < 0.9)[..., None], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    t = np.cross(u, ref)
    t /= np.linalg.norm(t, axis=-1, keepdims=True)
    w = np.cross(u, t)
    ang = np.linspace(0, 2 * np.pi, sides, endpoint=False)
    ring = np.cos(ang)[None, None, :, None] * t[:, :, None] + np.sin(ang)[None, None, :, None] * w[:, :, None]
    r = np.asarray(radii, dtype=np.float64)
    v0 = a[:, :, None] + r[None, :, 0, None, None] * ring
    v1 = b[:, :, None] + r[None, :, 1, None, None] * ring
    V = np.concatenate([v0, v1, a[:, :, None], b[:, :, None]], axis=2)  # (B, P, 2S+2, 3)
    return V.reshape(len(V), -1, 3)
