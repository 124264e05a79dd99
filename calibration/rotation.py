"""Rotations: the one place the toolkit converts between axis-angle, matrices and quaternions.

Everything here goes through SciPy's :class:`scipy.spatial.transform.Rotation` (Shepperd's
method: exact at 0 and at π, where hand-written Rodrigues inverses lose the axis), batched
over any leading shape. ``cv2.Rodrigues`` stays at the OpenCV boundary only.
Axis-angle is Rodrigues' parameterisation (thesis App. B): direction = axis, norm = angle
in radians, the same convention as OpenCV's ``rvec``.

>>> R = rotvec_to_matrix([0.0, 0.0, np.pi / 2])
>>> np.round(R @ [1.0, 0.0, 0.0], 12) + 0.0
array([0., 1., 0.])
>>> np.allclose(matrix_to_rotvec(rotvec_to_matrix([np.pi, 0, 0])), [np.pi, 0, 0])
True
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

__all__ = [
    "is_rotation",
    "look_at",
    "matrix_to_quaternion",
    "matrix_to_rotvec",
    "nearest_rotation",
    "quaternion_to_matrix",
    "rotation_angle",
    "rotvec_to_matrix",
]


def rotvec_to_matrix(rotvec) -> np.ndarray:
    """Rodrigues' formula (App. B): axis-angle ``(..., 3)`` → rotation matrices ``(..., 3, 3)``."""
    r = np.asarray(rotvec, dtype=np.float64)
    if r.shape[-1:] != (3,):
        raise ValueError(f"rotvec_to_matrix: expected axis-angle vectors of shape (..., 3), got {r.shape}")
    flat = np.array(r.reshape(-1, 3))  # a writeable copy: SciPy's Cython refuses read-only buffers
    return Rotation.from_rotvec(flat).as_matrix().reshape(r.shape[:-1] + (3, 3))


def matrix_to_rotvec(R) -> np.ndarray:
    """Axis-angle ``(..., 3)`` (angle in [0, π]) of rotation matrices ``(..., 3, 3)``.

    Exact at 0 and at π (SciPy goes through the quaternion).
    """
    m = np.asarray(R, dtype=np.float64)
    if m.shape[-2:] != (3, 3):
        raise ValueError(f"matrix_to_rotvec: expected matrices of shape (..., 3, 3), got {m.shape}")
    flat = np.array(m.reshape(-1, 3, 3))
    return Rotation.from_matrix(flat).as_rotvec().reshape(m.shape[:-2] + (3,))


def quaternion_to_matrix(q, *, scalar_first: bool = True) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` of quaternions ``(..., 4)`` (``w x y z`` by default,
    COLMAP's and Qualisys' order). The quaternion is normalised; one of zero or non-finite
    norm is refused with a ``ValueError``."""
    q = np.asarray(q, dtype=np.float64)
    if q.shape[-1:] != (4,):
        raise ValueError(f"quaternion_to_matrix: expected quaternions of shape (..., 4), got {q.shape}")
    flat = q.reshape(-1, 4)
    norm = np.linalg.norm(flat, axis=1)
    if not np.all(np.isfinite(norm)) or np.any(norm < 1e-12):
        raise ValueError(f"quaternion_to_matrix: a quaternion of zero or non-finite norm is not a rotation: "
                         f"{flat[(~np.isfinite(norm)) | (norm < 1e-12)][0].tolist()}")
    xyzw = np.roll(flat, -1, axis=1) if scalar_first else np.array(flat)
    return Rotation.from_quat(xyzw).as_matrix().reshape(q.shape[:-1] + (3, 3))


def matrix_to_quaternion(R, *, scalar_first: bool = True) -> np.ndarray:
    """Unit quaternions ``(..., 4)`` (``w ≥ 0``; ``w x y z`` by default) of rotation matrices."""
    m = np.asarray(R, dtype=np.float64)
    q = Rotation.from_matrix(np.array(m.reshape(-1, 3, 3))).as_quat(canonical=True)
    if scalar_first:
        q = np.roll(q, 1, axis=1)
    return q.reshape(m.shape[:-2] + (4,))


def rotation_angle(R) -> np.ndarray:
    """Angle in radians ``(...)`` of rotation matrices ``(..., 3, 3)`` (e.g. ``R_a @ R_b.T``)."""
    m = np.asarray(R, dtype=np.float64)
    return Rotation.from_matrix(np.array(m.reshape(-1, 3, 3))).magnitude().reshape(m.shape[:-2])


def is_rotation(R, tol: float = 1e-6) -> bool:
    """Whether ``R`` (3, 3) is finite, orthonormal within ``tol`` and has determinant +1."""
    m = np.asarray(R, dtype=np.float64)
    if m.shape != (3, 3) or not np.all(np.isfinite(m)):
        return False
    return bool(np.max(np.abs(m @ m.T - np.eye(3))) <= tol and np.linalg.det(m) > 0)


def nearest_rotation(M) -> tuple[np.ndarray, float]:
    """The rotation nearest ``M`` (3, 3) in the Frobenius norm (SVD: ``U diag(1, 1, det) Vᵀ``)
    and how far ``M`` was from orthonormal (``max |M Mᵀ - I|``). Files written with few
    decimals (6 in EasyMocap's ``extri.yml``) hold matrices off by ~1e-6.

    >>> R, err = nearest_rotation(np.round(rotvec_to_matrix([0.3, -1.2, 0.5]), 6))
    >>> bool(err > 1e-7) and is_rotation(R, 1e-12)
    True
    """
    m = np.asarray(M, dtype=np.float64)
    err = float(np.max(np.abs(m @ m.T - np.eye(3))))
    U, _, Vt = np.linalg.svd(m)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    return U @ D @ Vt, err


def look_at(center, target, up=(0.0, 0.0, 1.0)) -> tuple[np.ndarray, np.ndarray]:
    """``(R_cam_from_world (3, 3), t (3,))`` of a camera at ``center`` looking at ``target``.

    OpenCV axes: z forward, x right (perpendicular to ``up``), y down, so ``up`` points up
    in the image. Raises ``ValueError`` when the view direction is parallel to ``up``.

    >>> R, t = look_at([0.0, -3.0, 1.0], [0.0, 0.0, 1.0])
    >>> np.round(R @ [0.0, 0.0, 1.0] + t, 9) + 0.0  # the target, 3 m straight ahead
    array([0., 0., 3.])
    """
    c = np.asarray(center, dtype=np.float64)
    z = np.asarray(target, dtype=np.float64) - c
    z /= np.linalg.norm(z)
    x = np.cross(z, np.asarray(up, dtype=np.float64))
    if np.linalg.norm(x) < 1e-9:
        raise ValueError(f"look_at: the view direction {z.tolist()} is parallel to up {list(up)}; "
                         "give a target off that axis or another up vector")
    x /= np.linalg.norm(x)
    R = np.stack([x, np.cross(z, x), z])
    return R, -R @ c
