"""Compiled kinematic chain of the mesh evaluation: part rotations and joint rotation vectors.

Every SCAPE mesh needs the global rotation ``R_p`` of each part (the chain of local joint
rotations down the tree, thesis §3.5.4) and the rotation vector of each joint relative to its
parent (the regressors of the pose deformations Q, eq. 3.15–3.16). Through
:func:`studio.body.skeleton.part_rotations` and :func:`~studio.body.skeleton.joint_rotvecs`
that is two SciPy ``Rotation`` round trips per call (with their input checks: 0.3 ms of a
1.5 ms mesh); here one compiled pass does the same arithmetic as SciPy — Rodrigues through
the quaternion, the matrix logarithm by Markley's method with SciPy's small-angle series —
for 15 parts. Equal to the SciPy path to 1e-13 (tests/studio/test_body_kinematics.py).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from studio.body.skeleton import JOINT_KIND, PART_PARENTS, pose_slices

__all__ = ["chain_rotations"]

_KIND = np.array([{"root": 0, "ball": 1, "hinge": 2}[k] for k in JOINT_KIND], dtype=np.int64)
_OFFSET = np.array([s.start for s in pose_slices()], dtype=np.int64)
_PARENTS = np.array(PART_PARENTS, dtype=np.int64)


@njit(cache=True, nogil=True)
def _rotvec_matrix(r0, r1, r2, M):  # pragma: no cover - compiled
    """``M`` (3, 3) ← the rotation of axis-angle (r0, r1, r2) (SciPy: via the quaternion)."""
    angle = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
    if angle <= 1e-3:
        a2 = angle * angle
        scale = 0.5 - a2 / 48 + a2 * a2 / 3840
    else:
        scale = math.sin(angle / 2) / angle
    x, y, z, w = r0 * scale, r1 * scale, r2 * scale, math.cos(angle / 2)
    x2, y2, z2, w2 = x * x, y * y, z * z, w * w
    xy, zw, xz, yw, yz, xw = x * y, z * w, x * z, y * w, y * z, x * w
    M[0, 0], M[0, 1], M[0, 2] = x2 - y2 - z2 + w2, 2 * (xy - zw), 2 * (xz + yw)
    M[1, 0], M[1, 1], M[1, 2] = 2 * (xy + zw), -x2 + y2 - z2 + w2, 2 * (yz - xw)
    M[2, 0], M[2, 1], M[2, 2] = 2 * (xz - yw), 2 * (yz + xw), -x2 - y2 + z2 + w2


@njit(cache=True, nogil=True)
def _matrix_rotvec(M):  # pragma: no cover - compiled
    """Axis-angle (angle in [0, π]) of the rotation ``M`` (3, 3): Markley's quaternion, made
    canonical (w ≥ 0), then SciPy's ``as_rotvec``."""
    tr = M[0, 0] + M[1, 1] + M[2, 2]
    choice, best = 3, tr
    for i in range(3):
        if M[i, i] > best:
            choice, best = i, M[i, i]
    q = np.empty(4)
    if choice == 3:
        q[0], q[1], q[2], q[3] = M[2, 1] - M[1, 2], M[0, 2] - M[2, 0], M[1, 0] - M[0, 1], 1 + tr
    else:
        i = choice
        j = (i + 1) % 3
        k = (j + 1) % 3
        q[i] = 1 - tr + 2 * M[i, i]
        q[j] = M[j, i] + M[i, j]
        q[k] = M[k, i] + M[i, k]
        q[3] = M[k, j] - M[j, k]
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    x, y, z, w = q[0] / n, q[1] / n, q[2] / n, q[3] / n
    if w < 0 or (w == 0 and (x < 0 or (x == 0 and (y < 0 or (y == 0 and z < 0))))):
        x, y, z, w = -x, -y, -z, -w
    angle = 2 * math.atan2(math.sqrt(x * x + y * y + z * z), w)
    if angle <= 1e-3:
        a2 = angle * angle
        scale = 2 + a2 / 12 + 7 * a2 * a2 / 2880
    else:
        scale = angle / math.sin(angle / 2.0)
    return scale * x, scale * y, scale * z


@njit(cache=True, nogil=True)
def _chain(poses, hinge_axes, kind, offset, parents):  # pragma: no cover - compiled
    B = poses.shape[0]
    P = kind.shape[0]
    G = np.empty((B, P, 3, 3))
    rv = np.zeros((B, P, 3))
    L = np.empty((3, 3))
    R = np.empty((3, 3))
    for b in range(B):
        for p in range(P):
            o = offset[p]
            if kind[p] == 2:
                a = poses[b, o]
                r0, r1, r2 = a * hinge_axes[p, 0], a * hinge_axes[p, 1], a * hinge_axes[p, 2]
            else:
                r0, r1, r2 = poses[b, o], poses[b, o + 1], poses[b, o + 2]
            _rotvec_matrix(r0, r1, r2, L)
            q = parents[p]
            if q < 0:
                G[b, p] = L
                continue
            for i in range(3):
                for j in range(3):
                    G[b, p, i, j] = G[b, q, i, 0] * L[0, j] + G[b, q, i, 1] * L[1, j] + G[b, q, i, 2] * L[2, j]
            # the joint's rotation relative to its parent, in the parent's frame: G_qᵀ G_p
            for i in range(3):
                for j in range(3):
                    R[i, j] = G[b, q, 0, i] * G[b, p, 0, j] + G[b, q, 1, i] * G[b, p, 1, j] \
                        + G[b, q, 2, i] * G[b, p, 2, j]
            rv[b, p, 0], rv[b, p, 1], rv[b, p, 2] = _matrix_rotvec(R)
    return G, rv


def chain_rotations(poses: np.ndarray, hinge_axes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Global part rotations (B, 15, 3, 3) and joint rotation vectors (B, 15, 3) of poses
    (B, POSE_SIZE) — :func:`studio.body.skeleton.part_rotations` followed by
    :func:`studio.body.skeleton.joint_rotvecs` (root row zeros), in one compiled pass."""
    poses = np.ascontiguousarray(poses, dtype=np.float64)
    axes = np.ascontiguousarray(hinge_axes, dtype=np.float64)
    return _chain(poses, axes, _KIND, _OFFSET, _PARENTS)
