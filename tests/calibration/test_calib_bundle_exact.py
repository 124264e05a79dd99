"""Bundle adjustment against independent derivations: every residual is OpenCV's own projection
(``cv2.projectPoints`` / ``cv2.fisheye.projectPoints``, the skew added by hand for the pinhole
model, whose OpenCV projection has none) minus the observed pixel; the packed vector is the
reference-frame pose worked out with ``cv2.Rodrigues``; the Jacobian sparsity is the non-zero
pattern of a central-difference Jacobian; per-view RMS values of hand-made residuals. Small
problems only (2-3 cameras, 2-3 board views, 12 corners): no whole fits.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from calibration import CalibrationError, Camera
from calibration.bundle import N_INTR, BundleParameterization, BundleResult, Observations, bundle_adjust, pose_residuals
from calibration.detect import Detection
from calibration.rotation import rotvec_to_matrix

# a 4 x 3 board, 5 cm squares, off its origin and slightly bent out of its plane: no derivative vanishes
OBJ = np.array([[0.05 * i + 0.01, 0.05 * j + 0.02, 0.003 * ((i + 2 * j) % 3)] for j in range(3) for i in range(4)])
SKEW = 0.8


def cameras() -> dict[str, Camera]:
    """Three cameras 1.5-2 m from the boards: pinhole (5 coefficients), pinhole with skew, fisheye with skew."""
    def K(f, s, cx, cy):
        return np.array([[f, s, cx], [0.0, f * 0.995, cy], [0.0, 0.0, 1.0]])

    return {
        "a": Camera("a", K(820.0, 0.0, 321.0, 239.5), [-0.2, 0.07, 0.001, -0.0015, -0.01],
                    rotvec_to_matrix([0.05, -0.1, 0.02]), [0.02, -0.01, 1.6], (640, 480)),
        "b": Camera("b", K(790.0, SKEW, 318.5, 243.0), [0.1, -0.03, -0.0007, 0.002, 0.004],
                    rotvec_to_matrix([-0.04, 0.35, -0.03]), [-0.45, 0.02, 1.7], (640, 480)),
        "c": Camera("c", K(400.0, SKEW, 322.0, 241.0), [0.05, -0.01, 0.004, -0.001],
                    rotvec_to_matrix([0.03, -0.4, 0.01]), [0.5, 0.03, 1.8], (640, 480), "fisheye"),
    }


def board_poses() -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """World from board: three placements near the origin."""
    return {f"v{k}": (rotvec_to_matrix(r), np.array(t)) for k, (r, t) in
            enumerate([([0.1, 0.2, 0.05], [-0.1, -0.05, 0.1]), ([-0.2, 0.1, 0.3], [0.0, 0.05, -0.1]),
                       ([0.05, -0.25, -0.1], [0.05, -0.1, 0.05])])}


def opencv_pixels(cam: Camera, X: np.ndarray) -> np.ndarray:
    """(N, 2) pixels of world points by OpenCV (the skew added by hand: u += s y_d, y_d = (v - cy) / fy)."""
    rvec = cv2.Rodrigues(cam.R)[0]
    if cam.model == "fisheye":
        uv, _ = cv2.fisheye.projectPoints(X.reshape(1, -1, 3), rvec, cam.t, cam.K, cam.dist,
                                          alpha=cam.K[0, 1] / cam.K[0, 0])
        return uv.reshape(-1, 2)
    K0 = cam.K.copy()
    K0[0, 1] = 0.0
    uv = cv2.projectPoints(X, rvec, cam.t, K0, cam.dist)[0].reshape(-1, 2)
    uv[:, 0] += cam.K[0, 1] * (uv[:, 1] - cam.K[1, 2]) / cam.K[1, 1]
    return uv


def detections(cams, poses, noise=None) -> dict[str, dict[str, Detection]]:
    """Every camera sees every board view (corner pixels by OpenCV, plus ``noise`` (cam, view) → (12, 2))."""
    out = {}
    for name, cam in cams.items():
        out[name] = {}
        for v, (Rb, tb) in poses.items():
            img = opencv_pixels(cam, OBJ @ Rb.T + tb)
            if noise is not None:
                img = img + noise.get((name, v), 0.0)
            out[name][v] = Detection(v, np.arange(len(OBJ)), img, OBJ.copy(), cam.size)
    return out


@pytest.mark.parametrize("free", [False, True])
@pytest.mark.parametrize("reference", ["a", "c"])
def test_residuals_are_opencv_projections_minus_observations(free, reference):
    """Observed = OpenCV's pixel + a known offset per corner: the residual is exactly minus that offset,
    whatever the reference camera (the packing is a change of frame) and in both modes."""
    cams, poses = cameras(), board_poses()
    rng = np.random.default_rng(1)
    offsets = {(c, v): rng.normal(0.0, 2.0, (len(OBJ), 2)) for c in cams for v in poses}
    obs = detections(cams, poses, offsets)
    param = BundleParameterization(cams, list(poses), reference, free)
    o = Observations.build(obs, param.camera_names, param.view_names)
    r = pose_residuals(param.pack(cams, poses), param, o).reshape(-1, 2)
    want = np.concatenate([-offsets[(c, v)] for c in cams for v in poses])
    np.testing.assert_allclose(r, want, rtol=0, atol=1e-8)


def test_pack_is_the_reference_frame_pose_and_unpack_inverts_it():
    cams, poses = cameras(), board_poses()
    param = BundleParameterization(cams, list(poses), "b", True)
    assert param.size == 6 * 2 + N_INTR * 3 + 6 * 3
    x = param.pack(cams, poses)
    Rref, tref = cams["b"].R, cams["b"].t
    for i, name in enumerate(["a", "b", "c"]):
        cam = cams[name]
        R_rel = cam.R @ Rref.T
        sl = param.cam_pose_slice(i)
        if name == "b":
            assert sl is None
        else:
            np.testing.assert_allclose(x[sl][:3], cv2.Rodrigues(R_rel)[0].ravel(), rtol=0, atol=1e-12)
            np.testing.assert_allclose(x[sl][3:], cam.t - R_rel @ tref, rtol=0, atol=1e-12)
        d5 = np.zeros(5)
        d5[: cam.dist.size] = cam.dist
        np.testing.assert_array_equal(x[param.intr_slice(i)], [cam.K[0, 0], cam.K[1, 1], cam.K[0, 2], cam.K[1, 2], *d5])
    for j, v in enumerate(poses):
        Rb, tb = poses[v]
        np.testing.assert_allclose(x[param.view_slice(j)][:3], cv2.Rodrigues(Rref @ Rb)[0].ravel(), rtol=0, atol=1e-12)
        np.testing.assert_allclose(x[param.view_slice(j)][3:], Rref @ tb + tref, rtol=0, atol=1e-12)
    out, out_poses = param.unpack(x)
    for name, cam in cams.items():
        got = out[name]
        assert got.model == cam.model and got.dist.size == (4 if cam.model == "fisheye" else 5)
        np.testing.assert_allclose(got.R, cam.R @ Rref.T, rtol=0, atol=1e-12)
        np.testing.assert_allclose(got.t, cam.t - cam.R @ Rref.T @ tref, rtol=0, atol=1e-12)
        np.testing.assert_array_equal(got.K, cam.K)  # skew included
        np.testing.assert_array_equal(got.dist, cam.dist)
    np.testing.assert_allclose(out["b"].R, np.eye(3), rtol=0, atol=1e-15)
    np.testing.assert_allclose(out["b"].t, 0.0, rtol=0, atol=1e-15)
    for v, (Rb, tb) in poses.items():
        np.testing.assert_allclose(out_poses[v][0], Rref @ Rb, rtol=0, atol=1e-12)
        np.testing.assert_allclose(out_poses[v][1], Rref @ tb + tref, rtol=0, atol=1e-12)


def test_fixed_intrinsics_unpack_keeps_long_distortion_vectors():
    cams = cameras()
    cams["a"] = cams["a"].replace(dist=[-0.2, 0.07, 0.001, -0.0015, -0.01, 0.02, -0.004, 0.001])
    param = BundleParameterization(cams, list(board_poses()), "a", False)
    assert param.intr_slice(0) is None and param.size == 6 * 2 + 6 * 3
    out, _ = param.unpack(param.pack(cams, board_poses()))
    np.testing.assert_array_equal(out["a"].dist, cams["a"].dist)


@pytest.mark.parametrize("free", [False, True])
def test_sparsity_is_the_pattern_of_the_numerical_jacobian(free):
    """Central differences (h = 1e-6) of the residuals: a corner depends on exactly its
    camera's pose (none for the reference), its camera's intrinsics (fisheye: 8 of the 9 slots)
    and its view's pose."""
    cams = cameras()
    # boards off camera a's axis: its k3 r⁶ term is no longer below a rounding step
    poses = {v: (R, t + [0.25, 0.2, 0.0]) for v, (R, t) in board_poses().items()}
    obs = detections(cams, dict(list(poses.items())[:2]))
    param = BundleParameterization(cams, list(poses)[:2], "a", free)
    o = Observations.build(obs, param.camera_names, param.view_names)
    x = param.pack(cams, poses)
    J = np.empty((2 * len(o.cam), param.size))
    for k in range(param.size):
        h = np.zeros(param.size)
        h[k] = 1e-6
        J[:, k] = (pose_residuals(x + h, param, o) - pose_residuals(x - h, param, o)) / 2e-6
    A = param.sparsity(o).toarray()
    assert A.shape == J.shape and set(np.unique(A)) == {0, 1}
    np.testing.assert_array_equal(A[0::2], A[1::2])  # u and v of a corner: one pattern
    # (u alone does not depend on fy, cy: the pattern is per corner, the union of its two rows)
    # (a parameter a residual does not depend on leaves it bit for bit: exactly 0)
    np.testing.assert_array_equal(A[0::2] != 0, (J[0::2] != 0) | (J[1::2] != 0))


def test_view_rms_of_hand_made_residuals():
    res = BundleResult(cameras={}, board_poses={}, rms_before=0.0, rms_after=0.0, camera_rms={},
                       residuals=np.array([[3.0, 4.0], [0.0, 0.0], [6.0, 8.0], [1.0, 1.0]]),
                       obs_camera=np.array([0, 0, 1, 1]), obs_view=np.array([0, 0, 0, 1]))
    assert res.view_rms(["a", "b", "c"], ["v0", "v1", "v2"]) == {
        "a": {"v0": np.sqrt(25.0 / 2)}, "b": {"v0": 10.0, "v1": np.sqrt(2.0)}, "c": {}}


def test_observations_keep_usable_views_of_known_cameras_in_order():
    cams, poses = cameras(), board_poses()
    obs = detections(cams, poses)
    d = obs["b"]["v1"]
    obs["b"]["v1"] = Detection(d.view, d.ids, d.image_points, d.object_points, d.image_size, status="rejected")
    obs["b"]["v9"] = d  # a view without a board pose
    obs = {"zz": {"v0": d}, **obs}  # a camera not adjusted, met first
    o = Observations.build(obs, ["a", "b", "c"], ["v0", "v1", "v2"])
    n = len(OBJ)
    assert o.cam.tolist() == [0] * 3 * n + [1] * 2 * n + [2] * 3 * n
    assert o.view.tolist() == ([0] * n + [1] * n + [2] * n) + ([0] * n + [2] * n) + ([0] * n + [1] * n + [2] * n)
    np.testing.assert_array_equal(o.img[3 * n : 4 * n], obs["b"]["v0"].image_points)
    np.testing.assert_array_equal(o.obj[4 * n : 5 * n], OBJ)
    with pytest.raises(CalibrationError, match="^bundle adjustment: no observations$"):
        Observations.build({"zz": {"v0": d}}, ["a"], ["v0"])


def test_refined_intrinsics_come_back_from_the_vector():
    """fx + 10 and k1 + 0.01 in the vector come back in the cameras (the skew stays); an 8-coefficient
    pinhole camera packs its first five."""
    cams = cameras()
    cams["a"] = cams["a"].replace(dist=[-0.2, 0.07, 0.001, -0.0015, -0.01, 0.02, -0.004, 0.001])
    param = BundleParameterization(cams, list(board_poses()), "a", True)
    x = param.pack(cams, board_poses())
    np.testing.assert_array_equal(x[param.intr_slice(0)][4:], [-0.2, 0.07, 0.001, -0.0015, -0.01])
    for i in range(3):
        x[param.intr_slice(i).start] += 10.0
        x[param.intr_slice(i).start + 4] += 0.01
    out, _ = param.unpack(x)
    for name, cam in cams.items():
        want = cam.K.copy()
        want[0, 0] += 10.0
        np.testing.assert_array_equal(out[name].K, want)
        n = 4 if cam.model == "fisheye" else 5
        np.testing.assert_allclose(out[name].dist, cam.dist[:n] + np.r_[0.01, np.zeros(n - 1)], rtol=0, atol=1e-15)


def test_residuals_near_and_at_the_camera_plane():
    """Depths below 1e-9 m are taken as +1e-9 (no division by zero): u = fx x / 1e-9 + cx; -1e-9
    itself is kept. A board 0.4 m in front of the camera is projected as OpenCV does."""
    cam = Camera("p", [[500.0, 0, 320.0], [0, 500.0, 240.0], [0, 0, 1]], np.zeros(5), np.eye(3), np.zeros(3),
                 (640, 480))
    obj = np.array([[0.1, 0.05, 0.0], [0.1, 0.05, -1e-9], [0.1, 0.05, 5e-10], [0.1, 0.05, 0.4], [-0.05, 0.1, 0.6]])
    o = Observations(np.zeros(5, int), np.zeros(5, int), obj, np.zeros((5, 2)))
    param = BundleParameterization({"p": cam}, ["v"], "p", False)
    r = pose_residuals(param.pack({"p": cam}, {"v": (np.eye(3), np.zeros(3))}), param, o).reshape(-1, 2)
    np.testing.assert_allclose(r[0], [500.0 * 0.1 / 1e-9 + 320.0, 500.0 * 0.05 / 1e-9 + 240.0], rtol=1e-12)
    np.testing.assert_allclose(r[1], [-500.0 * 0.1 / 1e-9 + 320.0, -500.0 * 0.05 / 1e-9 + 240.0], rtol=1e-12)
    np.testing.assert_allclose(r[2], r[0], rtol=1e-12)
    np.testing.assert_allclose(r[3:], opencv_pixels(cam, obj[3:]), rtol=0, atol=1e-9)


def test_sparsity_of_a_single_corner_camera_and_an_unseen_view():
    """Camera b sees one corner, view v1 no corner at all: the pattern still has b's pose columns for
    that corner and the full width (v1's columns empty)."""
    cams = cameras()
    param = BundleParameterization(cams, ["v0", "v1"], "a", True)
    o = Observations(np.array([0, 0, 1]), np.array([0, 0, 0]), OBJ[:3], np.zeros((3, 2)))
    A = param.sparsity(o).toarray()
    assert A.shape == (6, param.size) and A.dtype == np.int8
    b_pose, b_intr, v0 = param.cam_pose_slice(1), param.intr_slice(1), param.view_slice(0)
    want = np.zeros(param.size, np.int8)
    want[b_pose] = want[b_intr] = want[v0] = 1
    np.testing.assert_array_equal(A[4], want)
    np.testing.assert_array_equal(A[5], want)
    assert not A[:, param.view_slice(1)].any()


def test_bundle_adjust_reports_rms_per_camera_and_the_method():
    """Observations 0.5 px off OpenCV's pixels (camera c: 1.5 px), one view's pose started 2 cm off:
    RMS before is that of OpenCV's pixels of the start; after, every residual is OpenCV's pixel of the
    adjusted cameras and poses minus the observation, and the RMS values are those of these residuals."""
    cams, poses = cameras(), board_poses()
    rng = np.random.default_rng(7)
    noise = {(c, v): rng.normal(0.0, 1.5 if c == "c" else 0.5, (len(OBJ), 2)) for c in cams for v in poses}
    obs = detections(cams, poses, noise)
    start = dict(poses)
    Rb, tb = poses["v1"]
    start["v1"] = (Rb, tb + [0.02, 0.0, 0.0])
    ba = bundle_adjust(cams, start, obs, reference="b", loss="linear", max_nfev=50)
    e2 = np.concatenate([((opencv_pixels(cams[c], OBJ @ R.T + t) - obs[c][v].image_points) ** 2).sum(1)
                         for c in cams for v, (R, t) in start.items()])
    assert ba.rms_before == pytest.approx(np.sqrt(e2.mean()), rel=1e-9) and ba.rms_before > 3.0
    res = {c: np.concatenate([opencv_pixels(ba.cameras[c], OBJ @ R.T + t) - obs[c][v].image_points
                              for v, (R, t) in ba.board_poses.items()]) for c in cams}
    np.testing.assert_allclose(ba.residuals, np.concatenate([res[c] for c in cams]), rtol=0, atol=1e-8)
    assert ba.camera_rms == pytest.approx({c: np.sqrt((r**2).sum(1).mean()) for c, r in res.items()}, rel=1e-9)
    assert ba.camera_rms["c"] > 2 * ba.camera_rms["a"]
    assert ba.rms_after == pytest.approx(np.sqrt(np.concatenate([(r**2).sum(1) for r in res.values()]).mean()), rel=1e-9)
    assert ba.rms_after < 1.5 < ba.rms_before and ba.residuals.shape == (3 * 3 * len(OBJ), 2) and ba.nfev >= 2
    assert ba.method == ("scipy least_squares trf, linear loss (f_scale 1.0 px), fixed intrinsics, "
                         f"{6 * 2 + 6 * 3} parameters, {9 * len(OBJ)} corners")
    assert ba.view_rms(["a", "b", "c"], ["v0", "v1", "v2"])["c"]["v2"] == pytest.approx(
        np.sqrt((res["c"][2 * len(OBJ):] ** 2).sum(1).mean()), rel=1e-9)
    np.testing.assert_allclose(ba.cameras["b"].R, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(ba.cameras["b"].t, 0.0, atol=1e-12)
    assert all(ba.cameras[c].model == cams[c].model and ba.cameras[c].K.tolist() == cams[c].K.tolist() for c in cams)


def test_bundle_adjust_defaults_and_solver_call(monkeypatch, caplog):
    """Defaults: the first camera is the reference, soft-L1 loss at 1 px, fixed intrinsics, at most
    200 evaluations of SciPy's trf with Jacobian scaling and the sparsity pattern; board poses no
    camera observed are left out. The solver is SciPy's own, called through a spy."""
    import logging

    import calibration.bundle as bundle

    calls = []

    def spy(fun, x0, **kwargs):
        calls.append((fun, x0.copy(), kwargs))
        return bundle.least_squares.__wrapped_ls__(fun, x0, **kwargs)

    spy.__wrapped_ls__ = bundle.least_squares
    monkeypatch.setattr(bundle, "least_squares", spy)
    cams, poses = cameras(), board_poses()
    obs = detections(cams, poses)
    extra = dict(poses, unseen=(np.eye(3), np.zeros(3)))
    with caplog.at_level(logging.INFO, logger="calibration.bundle"):
        ba = bundle_adjust(cams, extra, obs)
    (fun, x0, kw), = calls
    assert fun is pose_residuals and set(kw) == {"jac_sparsity", "args", "loss", "f_scale", "method", "x_scale",
                                                 "max_nfev"}
    param, o = kw["args"]
    assert param.reference == "a" and param.view_names == ["v0", "v1", "v2"] and not param.free_intrinsics
    assert (kw["loss"], kw["f_scale"], kw["method"], kw["x_scale"], kw["max_nfev"]) == ("soft_l1", 1.0, "trf", "jac", 200)
    np.testing.assert_array_equal(kw["jac_sparsity"].toarray(), param.sparsity(o).toarray())
    np.testing.assert_array_equal(x0, param.pack(cams, poses))
    assert set(ba.board_poses) == {"v0", "v1", "v2"} and "unseen" not in ba.board_poses
    np.testing.assert_allclose(ba.cameras["a"].R, np.eye(3), atol=1e-12)
    assert ba.method.startswith("scipy least_squares trf, soft_l1 loss (f_scale 1.0 px), fixed intrinsics, ")
    assert ba.obs_camera.tolist() == o.cam.tolist() and ba.obs_view.tolist() == o.view.tolist()
    (record,) = [r for r in caplog.records if r.name == "calibration.bundle"]
    assert record.levelno == logging.INFO
    assert record.getMessage() == (f"bundle adjustment (fixed intrinsics): RMS {ba.rms_before:.3f} -> "
                                   f"{ba.rms_after:.3f} px in {ba.nfev} evaluations")


@pytest.mark.parametrize("loss", ["linear", "soft_l1", "huber", "cauchy", "arctan"])
def test_every_scipy_loss_is_accepted(loss):
    cams, poses = cameras(), board_poses()
    ba = bundle_adjust(cams, poses, detections(cams, poses), loss=loss, f_scale=2.5, free_intrinsics=True, max_nfev=1)
    assert ba.nfev == 1
    assert ba.method == (f"scipy least_squares trf, {loss} loss (f_scale 2.5 px), free intrinsics, "
                         f"{6 * 2 + N_INTR * 3 + 6 * 3} parameters, {9 * len(OBJ)} corners")


def test_a_camera_without_observations_keeps_its_start():
    """Camera c (met first) has no entry in the observations: its pose is carried over (in the
    reference frame), it gets no RMS, the views are those the others saw."""
    cams, poses = cameras(), board_poses()
    obs = detections({n: cams[n] for n in ("a", "b")}, poses)
    cams = {n: cams[n] for n in ("c", "a", "b")}
    ba = bundle_adjust(cams, poses, obs, reference="a", loss="linear", max_nfev=5)
    assert set(ba.camera_rms) == {"a", "b"} and set(ba.board_poses) == set(poses)
    np.testing.assert_allclose(ba.cameras["c"].R, cams["c"].R @ cams["a"].R.T, atol=1e-12)
    np.testing.assert_allclose(ba.cameras["c"].t, cams["c"].t - cams["c"].R @ cams["a"].R.T @ cams["a"].t, atol=1e-12)
