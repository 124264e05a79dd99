"""The 15-part kinematic tree and its joint-angle pose vector (thesis §3.5.4).

Pose vector (``POSE_SIZE`` = 30): root translation (3, metres), root rotation (axis-angle,
3, in world axes), then the joint angles of the 14 non-root parts in ``PART_NAMES`` order:
ball joints (3, a rotation vector in the template's world axes) for the torso (spine),
shoulders and hips; hinges (1 angle about a fixed axis) for head (neck nod), elbows,
wrists, knees and ankles — the 27-D joint-angle pose of the thesis plus translation.

The template stands upright, Z up, facing **-y**; the subject's left is **+x**.
"""

from __future__ import annotations

import numpy as np

from calibration.rotation import rotvec_to_matrix

__all__ = [
    "PART_NAMES",
    "PART_PARENTS",
    "JOINT_KIND",
    "POSE_SIZE",
    "pose_slices",
    "part_rotations",
    "joint_features",
    "joint_rotvecs",
    "default_limits",
    "sample_poses",
    "sample_wide_poses",
]

PART_NAMES: tuple[str, ...] = (
    "pelvis",
    "torso",
    "head",
    "upperarm_l",
    "lowerarm_l",
    "hand_l",
    "upperarm_r",
    "lowerarm_r",
    "hand_r",
    "upperleg_l",
    "lowerleg_l",
    "foot_l",
    "upperleg_r",
    "lowerleg_r",
    "foot_r",
)
PART_PARENTS: tuple[int, ...] = (-1, 0, 1, 1, 3, 4, 1, 6, 7, 0, 9, 10, 0, 12, 13)
#: 'root', 'ball' (3 DOF) or 'hinge' (1 DOF) for the joint of each part with its parent
JOINT_KIND: tuple[str, ...] = (
    "root",
    "ball",
    "hinge",
    "ball",
    "hinge",
    "hinge",
    "ball",
    "hinge",
    "hinge",
    "ball",
    "hinge",
    "hinge",
    "ball",
    "hinge",
    "hinge",
)
_DOF = {"root": 0, "ball": 3, "hinge": 1}
POSE_SIZE = 6 + sum(_DOF[k] for k in JOINT_KIND)


def pose_slices() -> list[slice]:
    """Slice of the pose vector holding each part's joint angles (root: its rotation)."""
    out = [slice(3, 6)]
    i = 6
    for kind in JOINT_KIND[1:]:
        out.append(slice(i, i + _DOF[kind]))
        i += _DOF[kind]
    return out


_SLICES = pose_slices()


def local_rotations(pose: np.ndarray, hinge_axes: np.ndarray) -> np.ndarray:
    """Rotation of every part relative to its parent (root: world), (..., 15, 3, 3).

    ``pose`` (..., POSE_SIZE); ``hinge_axes`` (15, 3) unit axes (rows of ball/root unused).
    """
    pose = np.asarray(pose, dtype=float)
    rv = np.zeros(pose.shape[:-1] + (15, 3))
    for p, kind in enumerate(JOINT_KIND):
        s = _SLICES[p]
        if kind == "hinge":
            rv[..., p, :] = pose[..., s] * hinge_axes[p]
        else:
            rv[..., p, :] = pose[..., s]
    return rotvec_to_matrix(rv)


def part_rotations(pose: np.ndarray, hinge_axes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Global part rotations R_p (..., 15, 3, 3) and local joint rotations (..., 15, 3, 3)."""
    L = local_rotations(pose, hinge_axes)
    G = np.empty_like(L)
    for p, parent in enumerate(PART_PARENTS):
        G[..., p, :, :] = L[..., p, :, :] if parent < 0 else G[..., parent, :, :] @ L[..., p, :, :]
    return G, L


def joint_rotvecs(G: np.ndarray) -> np.ndarray:
    """Relative rotations between adjacent parts as rotation vectors (eq. 3.15).

    ``G`` (..., 15, 3, 3) global part rotations → (..., 15, 3); entry p is the rotation of
    part p relative to its parent, expressed in the parent's frame (root row: zeros).
    """
    from calibration.rotation import matrix_to_rotvec

    parents = np.array(PART_PARENTS[1:])
    rel = np.swapaxes(G[..., parents, :, :], -1, -2) @ G[..., 1:, :, :]
    out = np.zeros(G.shape[:-2] + (3,))
    out[..., 1:, :] = matrix_to_rotvec(rel)
    return out


def joint_features(G: np.ndarray) -> np.ndarray:
    """Relative rotations between adjacent parts as their matrices' entries minus the identity
    (..., 15, 9) (root row: zeros): the pose deformation's regressors (eq. 3.16 with these in
    place of the rotation vectors, as SMPL's pose blend shapes take them).

    Rotation vectors enter Q linearly, which holds near rest only: over a lab's postures
    (measured on 4 + 4 held-out Anny adults in the pose library's 14 families at the true pose,
    the regression trained on the same poses) they leave 8.6 mm mean vertex error, 21.6 mm
    seated and 15.5 mm arms overhead; these features, whose entries are the sines and
    (1 − cos) of the angles, 6.5 mm, 15.0 and 7.4.
    """
    parents = np.array(PART_PARENTS[1:])
    rel = np.swapaxes(G[..., parents, :, :], -1, -2) @ G[..., 1:, :, :]
    out = np.zeros(G.shape[:-3] + (15, 9))
    out[..., 1:, :] = (rel - np.eye(3)).reshape(rel.shape[:-2] + (9,))
    return out


def sample_poses(n: int, limits: np.ndarray, rng: np.random.Generator, spread: float = 0.6) -> np.ndarray:
    """Random joint angles (n, POSE_SIZE), root fixed: hinges uniform in the central
    ``spread`` of their range, ball joints within ±35 % of their half-range around rest."""
    mid = limits.mean(axis=1)
    half = 0.5 * (limits[:, 1] - limits[:, 0])
    poses = mid + rng.uniform(-1, 1, size=(n, len(mid))) * half * spread
    poses[:, :6] = 0.0
    for p, kind in enumerate(JOINT_KIND):
        s = pose_slices()[p]
        if kind == "ball":  # the rest (0) lies inside every ball joint's box
            poses[:, s] = rng.uniform(-1, 1, (n, 3)) * half[s] * 0.35
    return np.clip(poses, limits[:, 0], limits[:, 1])


def sample_wide_poses(n: int, limits: np.ndarray, rng: np.random.Generator, reach: float = 0.85,
                      max_angle: float = 2.6) -> np.ndarray:
    """Random joint angles (n, POSE_SIZE) across the whole range of every joint, root fixed.

    What a lab records reaches far beyond :func:`sample_poses`' ±35 % around rest (a seated hip
    flexed 90°, arms overhead, a half squat): every angle uniform in ``reach`` of its limits
    (scaled about rest, which lies inside every box), ball joints' rotations capped at
    ``max_angle`` rad. A triangle's deformation depends on its two nearest joints only
    (eq. 3.16), so independent draws cover the pairs a posture combines.
    """
    lo, hi = limits[:, 0] * reach, limits[:, 1] * reach
    poses = rng.uniform(lo, hi, size=(n, len(lo)))
    poses[:, :6] = 0.0
    for p, kind in enumerate(JOINT_KIND):
        s = pose_slices()[p]
        if kind == "ball":
            norm = np.linalg.norm(poses[:, s], axis=1, keepdims=True)
            poses[:, s] *= np.minimum(1.0, max_angle / np.maximum(norm, 1e-12))
    return np.clip(poses, limits[:, 0], limits[:, 1])


def default_limits(elbow_rest: float = 0.0) -> np.ndarray:
    """Anatomical limits (POSE_SIZE, 2) [low, high] in radians (translation ±10 m).

    Ball joints are boxes on the rotation-vector components in world axes
    (x: left→right axis = flexion/extension, y: front-back axis = abduction, z: twist).
    Signs follow the template facing -y with its left at +x. ``elbow_rest`` is the rest
    flexion of the template's elbows, so that a straight arm (angle ``-elbow_rest``) is
    allowed.
    """
    lim = np.zeros((POSE_SIZE, 2))
    lim[0:3] = [-10.0, 10.0]
    lim[3:6] = [-np.pi, np.pi]
    table = {
        "torso": [[-0.5, 1.2], [-0.6, 0.6], [-0.8, 0.8]],
        "head": [[-0.7, 0.9]],
        "upperarm_l": [[-2.6, 1.0], [-2.4, 0.9], [-1.6, 1.6]],
        "lowerarm_l": [[-elbow_rest - 0.15, 2.5]],
        "hand_l": [[-1.2, 1.2]],
        "upperarm_r": [[-2.6, 1.0], [-0.9, 2.4], [-1.6, 1.6]],
        "lowerarm_r": [[-elbow_rest - 0.15, 2.5]],
        "hand_r": [[-1.2, 1.2]],
        "upperleg_l": [[-2.2, 0.6], [-0.9, 0.4], [-0.8, 0.8]],
        "lowerleg_l": [[0.0, 2.6]],
        "foot_l": [[-0.5, 0.9]],
        "upperleg_r": [[-2.2, 0.6], [-0.4, 0.9], [-0.8, 0.8]],
        "lowerleg_r": [[0.0, 2.6]],
        "foot_r": [[-0.5, 0.9]],
    }
    for p, name in enumerate(PART_NAMES[1:], start=1):
        lim[_SLICES[p]] = table[name]
    return lim
