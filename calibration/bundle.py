"""Bundle adjustment of all cameras and board poses (SciPy sparse least squares).

Unknowns: every camera's pose in the rig frame (the reference camera is fixed at the
identity: the gauge) and every board view's pose; optionally every camera's intrinsics
(fx fy cx cy k1 k2 p1 p2 k3). The board corners are *known* 3-D points rigidly attached to
each board pose, so the scale comes from the square size. Residuals are the pixel errors
``project(K, dist, R_c (R_v X_b + t_v) + t_c) - x`` of every observed corner, with a robust
loss (``soft_l1``/``huber``/``cauchy``, scale ``f_scale`` pixels).

Why SciPy and not pycolmap 4.2: pycolmap's ``bundle_adjustment`` / ``BundleAdjustmentConfig``
optimise a ``Reconstruction`` whose 3-D points are independent tracks (variable or constant,
``add_constant_point``). A board pose — a rigid object carrying 3-D points of known geometry
— has no direct counterpart. It can be emulated by inverting the roles: one COLMAP ``Frame``
per board placement whose ``rig_from_world`` is the board pose, the cameras as the sensors of
one ``Rig`` (``sensor_from_rig`` = the extrinsics, ``refine_sensor_from_rig``), and the board
corners as *constant* points of a shared board frame (pycolmap 4.2 exposes all of these).
We did not take that route: it ties the calibration to COLMAP's rig/frame/track bookkeeping
and camera models (our k1 k2 p1 p2 k3 maps only to FULL_OPENCV), hides the per-corner
residuals the report needs, and needs a careful gauge set-up; the problem is small (tens of
poses, thousands of residuals), so ``scipy.optimize.least_squares`` with ``jac_sparsity``
(finite differences grouped by the sparsity pattern) and a robust loss solves it in about a
second (fixed intrinsics, 6 cameras, 150 views: 8-10 s). Free-intrinsics mode refines
fx fy cx cy k1 k2 p1 p2 k3 (longer distortion vectors are cut to these five).

Fisheye cameras (``Camera.model == "fisheye"``) project through their own ``cv2.fisheye``
model (:func:`calibration.camera.distort_fisheye`); in free-intrinsics mode their
``k1 k2 k3 k4`` take the first four distortion slots and the fifth stays 0 (no Jacobian
entries).

Parameter packing lives in :class:`BundleParameterization` (pack / unpack / sparsity); the
residual depends only on the parameter vector and never mutates a camera.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import coo_matrix

from calibration.camera import Camera
from calibration.distortion import lens_distort, normalized_to_pixels
from calibration.rotation import matrix_to_rotvec, rotvec_to_matrix
from calibration.detect import Detection
from calibration.errors import CalibrationError

__all__ = ["BundleParameterization", "BundleResult", "bundle_adjust", "pose_residuals"]

log = logging.getLogger(__name__)

N_INTR = 9  # fx fy cx cy k1 k2 p1 p2 k3


@dataclass(frozen=True)
class Observations:
    """All corner observations concatenated: M corners.

    cam (M,) int, view (M,) int, obj (M, 3) board-frame metres, img (M, 2) pixels.
    """

    cam: np.ndarray
    view: np.ndarray
    obj: np.ndarray
    img: np.ndarray

    @classmethod
    def build(cls, observations: dict, camera_names: list, view_names: list) -> "Observations":
        ci = {c: i for i, c in enumerate(camera_names)}
        vi = {v: i for i, v in enumerate(view_names)}
        cam, view, obj, img = [], [], [], []
        for c, dets in observations.items():
            if c not in ci:
                continue
            for v, det in dets.items():
                if v not in vi or not det.usable:
                    continue
                cam.append(np.full(det.n, ci[c]))
                view.append(np.full(det.n, vi[v]))
                obj.append(det.object_points)
                img.append(det.image_points)
        if not cam:
            raise CalibrationError("bundle adjustment: no observations")
        return cls(np.concatenate(cam), np.concatenate(view), np.concatenate(obj), np.concatenate(img))


class BundleParameterization:
    """Pack / unpack cameras and board poses to one vector; the Jacobian sparsity.

    Layout: ``[camera poses (6 each, reference camera omitted) | intrinsics (9 each, only when
    free) | board poses (6 each)]``; a pose is ``(rvec, t)``.
    """

    def __init__(self, cameras: dict[str, Camera], view_names: list[str], reference: str, free_intrinsics: bool):
        if reference not in cameras:
            raise CalibrationError(f"bundle adjustment: reference camera {reference!r} not in {list(cameras)}")
        self.templates = dict(cameras)
        self.camera_names = list(cameras)
        self.models = [c.model for c in cameras.values()]
        self.fisheye = [m == "fisheye" for m in self.models]
        self.view_names = list(view_names)
        self.reference = reference
        self.ref_index = self.camera_names.index(reference)
        self.free_intrinsics = bool(free_intrinsics)
        self.posed = [i for i in range(len(self.camera_names)) if i != self.ref_index]
        self.n_cam_pose = 6 * len(self.posed)
        self.n_intr = N_INTR * len(self.camera_names) if free_intrinsics else 0
        self.n_view = 6 * len(self.view_names)

    @property
    def size(self) -> int:
        return self.n_cam_pose + self.n_intr + self.n_view

    def cam_pose_slice(self, i: int) -> slice | None:
        if i == self.ref_index:
            return None
        k = self.posed.index(i)
        return slice(6 * k, 6 * k + 6)

    def intr_slice(self, i: int) -> slice | None:
        if not self.free_intrinsics:
            return None
        s = self.n_cam_pose + N_INTR * i
        return slice(s, s + N_INTR)

    def view_slice(self, j: int) -> slice:
        s = self.n_cam_pose + self.n_intr + 6 * j
        return slice(s, s + 6)

    def pack(self, cameras: dict[str, Camera], board_poses: dict[str, tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
        x = np.zeros(self.size)
        ref = cameras[self.reference]
        R0, t0 = ref.R, ref.t
        for i, name in enumerate(self.camera_names):
            cam = cameras[name]
            # express in the reference camera's frame (ref becomes the identity)
            R = cam.R @ R0.T
            t = cam.t - R @ t0
            sl = self.cam_pose_slice(i)
            if sl is not None:
                x[sl] = np.concatenate([matrix_to_rotvec(R), t])
            isl = self.intr_slice(i)
            if isl is not None:
                head = cam.dist[:5]  # longer vectors are cut to k1 k2 p1 p2 k3; fisheye k1..k4 + 0
                d = np.zeros(5)
                d[: head.size] = head
                x[isl] = [cam.K[0, 0], cam.K[1, 1], cam.K[0, 2], cam.K[1, 2], *d]
        for j, v in enumerate(self.view_names):
            Rb, tb = board_poses[v]
            Rr = R0 @ Rb
            tr = R0 @ tb + t0
            x[self.view_slice(j)] = np.concatenate([matrix_to_rotvec(Rr), tr])
        return x

    def arrays(self, x: np.ndarray):
        """Camera rotations (C, 3, 3), translations (C, 3), intrinsic matrices (C, 3, 3) (the skew
        stays the template's), distortion vectors (list of C), view rotations (V, 3, 3), translations (V, 3)."""
        C = len(self.camera_names)
        cam_r = np.zeros((C, 3))
        cam_t = np.zeros((C, 3))
        if self.posed:
            p = x[: self.n_cam_pose].reshape(-1, 6)
            cam_r[self.posed] = p[:, :3]
            cam_t[self.posed] = p[:, 3:]
        Rc = rotvec_to_matrix(cam_r)
        Ks = np.array([c.K for c in self.templates.values()])
        if self.free_intrinsics:
            intr = x[self.n_cam_pose : self.n_cam_pose + self.n_intr].reshape(C, N_INTR)
            Ks[:, 0, 0], Ks[:, 1, 1], Ks[:, 0, 2], Ks[:, 1, 2] = intr[:, :4].T
            dists = [intr[i, 4:8] if self.fisheye[i] else intr[i, 4:] for i in range(C)]
        else:
            dists = [c.dist for c in self.templates.values()]
        v = x[self.n_cam_pose + self.n_intr :].reshape(-1, 6)
        Rv = rotvec_to_matrix(v[:, :3])
        return Rc, cam_t, Ks, dists, Rv, v[:, 3:]

    def unpack(self, x: np.ndarray) -> tuple[dict[str, Camera], dict[str, tuple[np.ndarray, np.ndarray]]]:
        """Cameras (in the reference camera's frame) and board poses (rig from board)."""
        Rc, tc, Ks, dists, Rv, tv = self.arrays(x)
        cams = {}
        for i, name in enumerate(self.camera_names):
            cams[name] = self.templates[name].replace(K=Ks[i], dist=dists[i], R=Rc[i], t=tc[i])
        poses = {v: (Rv[j], tv[j]) for j, v in enumerate(self.view_names)}
        return cams, poses

    def sparsity(self, obs: Observations) -> coo_matrix:
        """(2M, size) 0/1 pattern: a corner's two residuals depend on its camera and its view."""
        M = len(obs.cam)
        rows, cols = [], []
        for i in range(len(self.camera_names)):
            sel = np.flatnonzero(obs.cam == i)
            isl = self.intr_slice(i)
            if isl is not None and self.fisheye[i]:
                isl = slice(isl.start, isl.stop - 1)  # fisheye: the fifth coefficient slot is unused
            for sl in (self.cam_pose_slice(i), isl):
                if sl is None or len(sel) == 0:
                    continue
                k = np.arange(sl.start, sl.stop)
                for off in (0, 1):
                    rows.append(np.repeat(2 * sel + off, len(k)))
                    cols.append(np.tile(k, len(sel)))
        k = np.arange(6)
        base = self.n_cam_pose + self.n_intr + 6 * obs.view
        for off in (0, 1):
            rows.append(np.repeat(2 * np.arange(M) + off, 6))
            cols.append((base[:, None] + k[None]).ravel())
        r, c = np.concatenate(rows), np.concatenate(cols)
        return coo_matrix((np.ones(len(r), np.int8), (r, c)), shape=(2 * M, self.size))


def pose_residuals(x: np.ndarray, param: BundleParameterization, obs: Observations) -> np.ndarray:
    """Pixel residuals (2M,) ``projected - observed`` for the parameter vector ``x``."""
    Rc, tc, Ks, dists, Rv, tv = param.arrays(x)
    Xr = np.einsum("mij,mj->mi", Rv[obs.view], obs.obj) + tv[obs.view]
    Xc = np.einsum("mij,mj->mi", Rc[obs.cam], Xr) + tc[obs.cam]
    z = Xc[:, 2]
    z = np.where(np.abs(z) < 1e-9, 1e-9, z)
    xy = Xc[:, :2] / z[:, None]
    uv = np.empty_like(xy)
    for i, d in enumerate(dists):  # the cameras' own projection (calibration.camera)
        sel = obs.cam == i
        if sel.any():
            uv[sel] = normalized_to_pixels(lens_distort(xy[sel], d, param.models[i]), Ks[i])
    return (uv - obs.img).ravel()


@dataclass(frozen=True)
class BundleResult:
    """Outcome of :func:`bundle_adjust`.

    cameras : dict[str, Camera]      in the reference camera's frame
    board_poses : dict[str, (R, t)]  rig (reference camera) from board
    rms_before, rms_after : float    pixels, all corners
    camera_rms : dict[str, float]    pixels per camera after
    residuals : (M, 2) float64       per corner after
    method : str                     solver description for the report
    """

    cameras: dict
    board_poses: dict
    rms_before: float
    rms_after: float
    camera_rms: dict
    residuals: np.ndarray = field(repr=False)
    obs_camera: np.ndarray = field(repr=False)
    obs_view: np.ndarray = field(repr=False)
    method: str = ""
    nfev: int = 0

    def view_rms(self, camera_names, view_names) -> dict:
        """{camera: {view: rms px}} after adjustment."""
        out = {}
        e2 = (self.residuals**2).sum(1)
        for i, c in enumerate(camera_names):
            out[c] = {}
            for j, v in enumerate(view_names):
                sel = (self.obs_camera == i) & (self.obs_view == j)
                if sel.any():
                    out[c][v] = float(np.sqrt(e2[sel].mean()))
        return out


def bundle_adjust(
    cameras: dict[str, Camera],
    board_poses: dict[str, tuple[np.ndarray, np.ndarray]],
    observations: dict[str, dict[str, Detection]],
    *,
    reference: str | None = None,
    free_intrinsics: bool = False,
    loss: str = "soft_l1",
    f_scale: float = 1.0,
    max_nfev: int = 200,
) -> BundleResult:
    """Jointly refine all camera poses, board poses (and intrinsics when ``free_intrinsics``).

    Parameters
    ----------
    cameras : dict[str, Camera]
        Initial cameras (any common frame); their intrinsics are the start / fixed values.
    board_poses : dict[str, (R (3, 3), t (3,))]
        Initial board poses in the same frame (X = R X_b + t).
    observations : dict[str, dict[str, Detection]]
        camera → view → detection; views without a board pose are ignored.
    reference : str
        Camera fixed at the identity (default: the first camera).
    loss, f_scale :
        SciPy robust loss and its scale in pixels.

    Returns the cameras and board poses in the reference camera's frame.
    """
    if loss not in ("linear", "soft_l1", "huber", "cauchy", "arctan"):
        raise CalibrationError(f"bundle adjustment: unknown loss {loss!r}")
    reference = reference or next(iter(cameras))
    views = [v for v in board_poses if any(v in observations.get(c, {}) for c in cameras)]
    param = BundleParameterization(cameras, views, reference, free_intrinsics)
    obs = Observations.build(observations, param.camera_names, views)
    x0 = param.pack(cameras, board_poses)
    r0 = pose_residuals(x0, param, obs)
    sparsity = param.sparsity(obs)
    sol = least_squares(
        pose_residuals,
        x0,
        jac_sparsity=sparsity,
        args=(param, obs),
        loss=loss,
        f_scale=f_scale,
        method="trf",
        x_scale="jac",
        max_nfev=max_nfev,
    )
    cams, poses = param.unpack(sol.x)
    res = sol.fun.reshape(-1, 2)
    e2 = (res**2).sum(1)
    cam_rms = {c: float(np.sqrt(e2[obs.cam == i].mean())) for i, c in enumerate(param.camera_names) if (obs.cam == i).any()}
    rms0 = float(np.sqrt((r0.reshape(-1, 2) ** 2).sum(1).mean()))
    rms1 = float(np.sqrt(e2.mean()))
    mode = "free" if free_intrinsics else "fixed"
    log.info("bundle adjustment (%s intrinsics): RMS %.3f -> %.3f px in %d evaluations", mode, rms0, rms1, sol.nfev)
    return BundleResult(
        cameras=cams,
        board_poses=poses,
        rms_before=rms0,
        rms_after=rms1,
        camera_rms=cam_rms,
        residuals=res,
        obs_camera=obs.cam,
        obs_view=obs.view,
        method=f"scipy least_squares trf, {loss} loss (f_scale {f_scale} px), {mode} intrinsics, "
        f"{param.size} parameters, {len(obs.cam)} corners",
        nfev=int(sol.nfev),
    )
