"""Rig extrinsics: initial poses through the view graph, then bundle adjustment.

1. Each camera's pose of each board view by PnP (``cv2.solvePnP``, IPPE then iterative).
2. The *view graph*: cameras are nodes, two cameras share an edge weighted by the number of
   board views both saw. A maximum spanning tree from the reference camera chains the
   relative poses, so the board never needs to be seen by all cameras at once (a ring of
   cameras around a hand-held board).
3. Each edge's relative pose is the robust average over its shared views (chordal mean of
   the rotations, median of the translations).
4. Board poses in the rig frame from the camera that saw each view with most corners, then
   :func:`calibration.bundle.bundle_adjust` refines everything.

Cameras with no board view, or sharing none with the rest, raise :class:`CalibrationError`
naming the camera and what to capture.

Checkerboards have no identity: seen from opposite sides (a ring of cameras) OpenCV may
number the corners from the other end, so views disagree by 180 deg; use ChArUco boards for
rigs (checkerboards are fine for stereo pairs looking the same way). A large disagreement
between an edge's shared views is logged.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from calibration.bundle import BundleResult, bundle_adjust
from calibration.camera import Camera
from calibration.detect import Detection
from calibration.errors import CalibrationError

__all__ = [
    "ExtrinsicsResult",
    "solve_board_pose",
    "view_graph",
    "spanning_tree",
    "initial_rig",
    "calibrate_extrinsics",
    "rotation_mean",
    "relative_pose",
]

log = logging.getLogger(__name__)

#: Median disagreement (degrees) between the shared views of a view-graph edge above which
#: the initial relative pose is suspicious (logged; the robust bundle adjustment still runs).
MAX_EDGE_SPREAD_DEG = 2.0


def solve_board_pose(camera: Camera, det: Detection) -> tuple[np.ndarray, np.ndarray, float]:
    """Board pose in the camera frame ``(R_cam_from_board, t, rms px)`` by PnP with the camera's K, dist.

    Fisheye cameras: the corners are first undistorted through the camera's own model
    (:meth:`Camera.undistort_pixels`) and PnP runs on those ideal pinhole pixels; the RMS
    is measured in the observed (fisheye) image.
    """
    import cv2

    obj = det.object_points.astype(np.float64)
    img = det.image_points.astype(np.float64)
    if camera.model == "fisheye":
        return _solve_board_pose_fisheye(camera, det, obj, img)
    ok, rvec, tvec = cv2.solvePnP(obj, img, camera.K, camera.dist, flags=cv2.SOLVEPNP_IPPE)
    if not ok or not (np.all(np.isfinite(rvec)) and np.all(np.isfinite(tvec))):
        raise CalibrationError(
            f"view {det.view!r}: no board pose from {det.n} corners (collinear or too few); "
            "drop this view or recapture it with the board whole and tilted",
            camera=camera.name,
        )
    rvec, tvec = cv2.solvePnPRefineLM(obj, img, camera.K, camera.dist, rvec, tvec)
    proj, _ = cv2.projectPoints(obj, rvec, tvec, camera.K, camera.dist)
    rms = float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - img) ** 2, axis=1))))
    R, _ = cv2.Rodrigues(rvec)
    return R, tvec.reshape(3), rms


def _solve_board_pose_fisheye(camera: Camera, det: Detection, obj: np.ndarray, img: np.ndarray):
    import cv2

    ideal = camera.undistort_pixels(img)
    keep = np.all(np.isfinite(ideal), axis=1)
    ok = keep.sum() >= 4
    if ok:
        ok, rvec, tvec = cv2.solvePnP(obj[keep], ideal[keep], camera.K, None, flags=cv2.SOLVEPNP_IPPE)
    if not ok or not (np.all(np.isfinite(rvec)) and np.all(np.isfinite(tvec))):
        raise CalibrationError(
            f"view {det.view!r}: no board pose from {det.n} corners (collinear or too few); "
            "drop this view or recapture it with the board whole and tilted",
            camera=camera.name,
        )
    rvec, tvec = cv2.solvePnPRefineLM(obj[keep], ideal[keep], camera.K, None, rvec, tvec)
    R, _ = cv2.Rodrigues(rvec)
    t = tvec.reshape(3)
    proj = camera.replace(R=R, t=t).project(obj)
    rms = float(np.sqrt(np.mean(np.sum((proj - img) ** 2, axis=1))))
    return R, t, rms


def rotation_mean(Rs: np.ndarray) -> np.ndarray:
    """Chordal L2 mean of rotations (N, 3, 3) → (3, 3) (projection of the sum onto SO(3))."""
    U, _, Vt = np.linalg.svd(np.sum(Rs, axis=0))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    return U @ D @ Vt


def relative_pose(poses_a: list, poses_b: list) -> tuple[np.ndarray, np.ndarray, float]:
    """``T_b_from_a`` averaged over shared views, from board poses ``[(R, t), ...]`` in a and b.

    Returns ``(R, t, spread_deg)``: spread is the median rotation disagreement between views.
    """
    Rs, ts = [], []
    for (Ra, ta), (Rb, tb) in zip(poses_a, poses_b):
        R = Rb @ Ra.T
        Rs.append(R)
        ts.append(tb - R @ ta)
    Rs = np.array(Rs)
    R = rotation_mean(Rs)
    # re-centre translations with the mean rotation: t_b = R_b_from_a t_a + t
    t = np.median([tb - R @ ta for (Ra, ta), (Rb, tb) in zip(poses_a, poses_b)], axis=0)
    ang = [np.degrees(np.arccos(np.clip((np.trace(R.T @ Ri) - 1) / 2, -1, 1))) for Ri in Rs]
    return R, t, float(np.median(ang))


def view_graph(observations: dict[str, dict[str, Detection]]) -> dict[tuple[str, str], list[str]]:
    """Shared views per camera pair ``{(a, b): [view, ...]}`` (a before b in input order)."""
    names = list(observations)
    usable = {c: {v for v, d in observations[c].items() if d.usable} for c in names}
    graph = {}
    for i, a in enumerate(names):
        for b in names[i + 1 :]:
            shared = sorted(usable[a] & usable[b])
            if shared:
                graph[(a, b)] = shared
    return graph


def spanning_tree(names: list[str], graph: dict, reference: str) -> tuple[list[tuple[str, str]], list[str]]:
    """Maximum spanning tree (Prim) by shared-view count from ``reference``.

    Returns ``(edges [(parent, child)] in visiting order, unreached camera names)``.
    """
    weight = {}
    for (a, b), views in graph.items():
        weight[(a, b)] = weight[(b, a)] = len(views)
    inside = {reference}
    edges = []
    while True:
        best = None
        for (a, b), w in weight.items():
            if a in inside and b not in inside and (best is None or w > best[0]):
                best = (w, a, b)
        if best is None:
            break
        edges.append((best[1], best[2]))
        inside.add(best[2])
    return edges, [n for n in names if n not in inside]


def _check_coverage(cameras: dict[str, Camera], observations: dict) -> None:
    for name in cameras:
        dets = observations.get(name, {})
        if not any(d.usable for d in dets.values()):
            raise CalibrationError(
                "the board was never detected in any extrinsics view; capture views where this "
                "camera sees the whole board together with at least one other camera",
                camera=name,
            )


def initial_rig(
    cameras: dict[str, Camera],
    observations: dict[str, dict[str, Detection]],
    reference: str | None = None,
) -> tuple[dict[str, Camera], dict[str, tuple[np.ndarray, np.ndarray]], dict]:
    """Initial cameras (in ``reference``'s frame) and board poses from PnP chained through the view graph.

    Returns ``(cameras, board_poses, info)`` with ``info = {"tree": [(parent, child, n_shared,
    spread_deg)], "pnp_rms": {cam: {view: px}}, "reference": name}``.
    """
    names = list(cameras)
    missing = [n for n in names if n not in observations]
    if missing:
        raise CalibrationError(f"no board observations for cameras {missing}; each camera needs views")
    _check_coverage(cameras, observations)
    obs = {c: {v: d for v, d in observations[c].items() if d.usable} for c in names}
    graph = view_graph(obs)
    degree = {n: sum(len(v) for (a, b), v in graph.items() if n in (a, b)) for n in names}
    reference = reference or max(names, key=lambda n: degree[n])
    if reference not in cameras:
        raise CalibrationError(f"reference camera {reference!r} is not one of {names}")
    edges, unreached = spanning_tree(names, graph, reference)
    if unreached:
        reached = [n for n in names if n not in unreached]
        raise CalibrationError(
            f"cameras {unreached} share no board view with cameras {reached}: capture views where the "
            f"board is seen at the same time by one of {unreached} and one of {reached}"
        )
    pnp = {c: {v: solve_board_pose(cameras[c], d) for v, d in obs[c].items()} for c in names}
    # T_c_from_ref
    T = {reference: (np.eye(3), np.zeros(3))}
    tree = []
    for parent, child in edges:
        key = (parent, child) if (parent, child) in graph else (child, parent)
        shared = graph[key]
        Rpc, tpc, spread = relative_pose([pnp[parent][v][:2] for v in shared], [pnp[child][v][:2] for v in shared])
        Rp, tp = T[parent]
        T[child] = (Rpc @ Rp, Rpc @ tp + tpc)
        tree.append((parent, child, len(shared), spread))
        if spread > MAX_EDGE_SPREAD_DEG:
            log.warning(
                "cameras %s and %s: their shared board views disagree on the relative rotation by %.1f deg "
                "(median); a checkerboard seen from opposite sides flips its corner order - use a ChArUco board",
                parent, child, spread,
            )
    new_cams = {n: cameras[n].replace(R=T[n][0], t=T[n][1]) for n in names}
    views = sorted({v for c in names for v in obs[c]})
    poses = {}
    for v in views:
        best = max((c for c in names if v in obs[c]), key=lambda c: (obs[c][v].n, -pnp[c][v][2]))
        Rcb, tcb, _ = pnp[best][v]
        Rc, tc = T[best]
        poses[v] = (Rc.T @ Rcb, Rc.T @ (tcb - tc))
    info = {
        "tree": tree,
        "pnp_rms": {c: {v: p[2] for v, p in pnp[c].items()} for c in names},
        "reference": reference,
        "shared_views": {f"{a}-{b}": len(v) for (a, b), v in graph.items()},
    }
    return new_cams, poses, info


@dataclass(frozen=True)
class ExtrinsicsResult:
    """Rig cameras (in the reference camera's frame), board poses and the adjustment report."""

    cameras: dict
    board_poses: dict
    bundle: BundleResult
    initial: dict = field(repr=False)
    info: dict = field(default_factory=dict)


def calibrate_extrinsics(
    cameras: dict[str, Camera],
    observations: dict[str, dict[str, Detection]],
    *,
    reference: str | None = None,
    free_intrinsics: bool = False,
    loss: str = "soft_l1",
    f_scale: float = 1.0,
    max_nfev: int = 200,
    board=None,
    hints: dict | None = None,
) -> ExtrinsicsResult:
    """Poses of all cameras (intrinsics given) from board views they share.

    Parameters
    ----------
    cameras : dict[str, Camera]
        Intrinsically calibrated cameras (poses ignored).
    observations : dict[str, dict[str, Detection]]
        camera → view key → detection; a view key names one board placement, the same key
        in two cameras means both saw that placement at the same time.
    free_intrinsics : bool
        Also refine fx fy cx cy k1 k2 p1 p2 k3 (fisheye cameras: k1 k2 k3 k4) in the bundle
        adjustment.

    board : Board, optional
        With a half-turn-symmetric checkerboard, every camera's corner numbering is first made
        to agree (:func:`calibration.halfturn.resolve_half_turns`, using ``hints``: camera →
        pixel of corner 0); undecidable cameras are refused by name.

    Fisheye cameras (``model="fisheye"``) are honoured throughout: PnP on corners undistorted
    through their model, bundle adjustment projecting through ``cv2.fisheye``'s model.
    """
    half_turn = {}
    if board is not None:
        from calibration.halfturn import resolve_half_turns

        observations, half_turn = resolve_half_turns(cameras, observations, board, hints=hints, reference=reference)
    init_cams, init_poses, info = initial_rig(cameras, observations, reference)
    info["half_turn"] = half_turn
    ba = bundle_adjust(
        init_cams,
        init_poses,
        observations,
        reference=info["reference"],
        free_intrinsics=free_intrinsics,
        loss=loss,
        f_scale=f_scale,
        max_nfev=max_nfev,
    )
    return ExtrinsicsResult(ba.cameras, ba.board_poses, ba, {"cameras": init_cams, "board_poses": init_poses}, info)
