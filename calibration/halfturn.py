"""The half-turn ambiguity of symmetric checkerboards, resolved across cameras or refused.

A checkerboard with an even number of inner corners both ways (8×6: 9×7 squares, the same
colour in all four corners) looks the same after a half turn about its normal, so a detector
may number its corners from either end: corner ``k`` in one camera is corner ``N-1-k`` in
another. One camera's pose of the board is then rotated 180° about the board's centre normal
— a reprojection error as small as the right answer, and no warning from PnP.

What decides it here:

- **Several placements** (a board moved in front of the rig): the relative pose of two cameras
  is the same for every placement only when both number the corners alike; for each camera
  (in spanning-tree order) the numbering of each shared view is chosen to agree with the
  relative rotation most views vote for (:func:`resolve_half_turns`).
- **One placement** (a board lying on the floor, every view the same): both numberings are
  self-consistent; nothing in the board tells them apart. Unless the user names corner 0 in
  both cameras (``hints``), the cameras are refused by name.
- **A calibrated rig** seeing a floor board: each camera's numbering is the one whose board
  pose agrees with the camera that sees the board best (:func:`align_to_rig`).
"""

from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np

from calibration.boards import Board
from calibration.detect import Detection
from calibration.errors import CalibrationError

__all__ = [
    "is_half_turn_symmetric",
    "turned",
    "turned_pose",
    "resolve_half_turns",
    "align_to_rig",
    "rotation_angle_deg",
]

log = logging.getLogger(__name__)

#: Views whose relative rotation is within this angle of the consensus vote for it (degrees).
VOTE_TOL_DEG = 3.0
#: Two consensus rotations this far apart are genuinely different answers (degrees).
DISTINCT_DEG = 20.0


def is_half_turn_symmetric(board: Board) -> bool:
    """True for checkerboards whose inner-corner counts are both even (odd × odd squares)."""
    cols, rows = board.corner_grid
    return board.kind == "checkerboard" and cols % 2 == 0 and rows % 2 == 0


def rotation_angle_deg(R: np.ndarray) -> float:
    """Angle (degrees) of a rotation matrix (3, 3) (:func:`calibration.rotation.rotation_angle`)."""
    from calibration.rotation import rotation_angle

    return float(np.degrees(rotation_angle(R)))


def turned(det: Detection) -> Detection:
    """The same detection numbered from the other end (corner ``k`` ↔ ``N-1-k`` of a full grid)."""
    return replace(det, image_points=det.image_points[::-1].copy(), extra={**det.extra, "turned": not det.extra.get("turned", False)})


def turned_pose(R: np.ndarray, t: np.ndarray, centre: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Camera-from-board pose after renumbering the board by a half turn about ``centre`` (3,).

    The new board frame is ``X_old = Rz X_new + 2 c`` with ``Rz = diag(-1, -1, 1)`` and ``c``
    the grid centre on the board plane.
    """
    Rz = np.diag([-1.0, -1.0, 1.0])
    c = np.array([centre[0], centre[1], 0.0])
    return R @ Rz, R @ (2 * c) + t


def _corner0_pick(det: Detection, hint: np.ndarray) -> Detection:
    """The numbering of ``det`` whose corner 0 is nearer the user's ``hint`` pixel."""
    d0 = np.linalg.norm(det.image_points[0] - hint)
    d1 = np.linalg.norm(det.image_points[-1] - hint)
    return det if d0 <= d1 else turned(det)


def _consensus(candidates: list[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, int, int]:
    """Best relative rotation voted by views (each view offers two), its votes, and the votes of the best distinct rival."""
    flat = [R for pair in candidates for R in pair]

    def votes(X):
        return sum(min(rotation_angle_deg(X.T @ a), rotation_angle_deg(X.T @ b)) < VOTE_TOL_DEG for a, b in candidates)

    scored = [(votes(X), k) for k, X in enumerate(flat)]
    best_votes, best_k = max(scored)
    best = flat[best_k]
    rival = max((v for v, k in scored if rotation_angle_deg(best.T @ flat[k]) > DISTINCT_DEG), default=0)
    return best, best_votes, rival


def resolve_half_turns(
    cameras: dict,
    observations: dict[str, dict[str, Detection]],
    board: Board,
    *,
    hints: dict[str, np.ndarray] | None = None,
    reference: str | None = None,
) -> tuple[dict[str, dict[str, Detection]], dict]:
    """Renumber each camera's views of a symmetric board so that all cameras agree.

    Parameters
    ----------
    cameras : dict[str, Camera]
        Intrinsics of every camera (poses ignored).
    observations : camera → view → Detection (as for :func:`calibration.extrinsics.calibrate_extrinsics`)
    hints : camera → (2,) pixel of corner 0, optional
        The user's word on which end is corner 0 in that camera's views.

    Returns ``(observations, report)``; ``report`` maps each camera to ``"as detected"``,
    ``"renumbered in N views"``, ``"from the corner-0 hint"`` or ``"reference"``.

    Raises
    ------
    CalibrationError
        Two cameras whose shared views cannot decide (a single placement) and not both hinted:
        the message names them and how to decide (a corner-0 hint, or moving the board).
    """
    from calibration.extrinsics import solve_board_pose, spanning_tree, view_graph

    hints = {k: np.asarray(v, float) for k, v in (hints or {}).items()}
    if not is_half_turn_symmetric(board):
        return observations, {c: "board not symmetric" for c in observations}
    obs = {c: {v: (_corner0_pick(d, hints[c]) if c in hints and d.usable and d.n == board.n_corners else d)
               for v, d in views.items()} for c, views in observations.items()}  # fmt: skip
    names = list(obs)
    graph = view_graph(obs)
    counts = {c: sum(d.usable for d in obs[c].values()) for c in names}
    if reference is None:
        reference = max(names, key=lambda c: (c in hints, counts[c], sum(len(v) for k, v in graph.items() if c in k)))
    edges, _unreached = spanning_tree(names, graph, reference)
    centre = board.object_points[:, :2].mean(0)
    report = {reference: "from the corner-0 hint" if reference in hints else "reference"}
    pose = {}

    def board_pose(c, v):
        if (c, v) not in pose:
            R, t, _ = solve_board_pose(cameras[c], obs[c][v])
            pose[c, v] = (R, t)
        return pose[c, v]

    R_ref = {reference: np.eye(3)}  # camera-from-reference rotations of the cameras placed so far
    seen_rot: dict[str, np.ndarray] = {}  # view -> board rotation in the reference frame

    def register(c):
        for v, d in obs[c].items():
            if d.usable and d.n == board.n_corners and v not in seen_rot:
                seen_rot[v] = R_ref[c].T @ board_pose(c, v)[0]

    register(reference)
    ambiguous = []
    for parent, child in edges:
        key = (parent, child) if (parent, child) in graph else (child, parent)
        full = [v for v in graph[key] if obs[child][v].n == board.n_corners and obs[parent][v].n == board.n_corners]
        cands = []
        for v in full:
            Rp, _ = board_pose(parent, v)
            Rc, tc = board_pose(child, v)
            Rc2, _ = turned_pose(Rc, tc, centre)
            cands.append((Rc @ Rp.T, Rc2 @ Rp.T))
        if not cands:
            report[child] = "as detected (no full shared view)"
            continue
        X, votes, rival = _consensus(cands)
        if rival >= votes:
            if parent in hints and child in hints:
                report[child] = "from the corner-0 hint"
                R_ref[child] = cands[0][0] @ R_ref[parent]
                register(child)
            else:
                ambiguous.append((parent, child, len(full)))
            continue
        R_ref[child] = X @ R_ref[parent]
        flips = 0
        for v, d in list(obs[child].items()):
            if not (d.usable and d.n == board.n_corners and v in seen_rot):
                continue
            Rc, tc = board_pose(child, v)
            Rc2, _ = turned_pose(Rc, tc, centre)
            keep = rotation_angle_deg((R_ref[child].T @ Rc).T @ seen_rot[v])
            turn = rotation_angle_deg((R_ref[child].T @ Rc2).T @ seen_rot[v])
            if turn < keep:
                if child in hints:
                    raise CalibrationError(
                        f"view {v!r}: the corner-0 hint contradicts the rig geometry (camera {parent!r} and the "
                        "other views agree on the other numbering); check the hint's pixel",
                        camera=child,
                    )
                obs[child][v] = turned(d)
                pose.pop((child, v), None)
                flips += 1
        register(child)
        report[child] = f"renumbered in {flips} views" if flips else "as detected"
    if ambiguous:
        pairs = ", ".join(f"{p}-{c}" for p, c, _ in ambiguous)
        raise CalibrationError(
            f"the {board.corner_grid[0]}x{board.corner_grid[1]} checkerboard looks the same after a half turn and the "
            f"views shared by cameras {pairs} cannot tell which end is corner 0 (one board placement, or views that all "
            "agree both ways); name corner 0 in each of these cameras' views (--corners FILE with "
            '{"camera": [x, y]}), or move the board to several tilted placements, or use a ChArUco board'
        )
    return obs, report


def align_to_rig(cameras: dict, detections: dict[str, Detection], board: Board) -> tuple[dict[str, Detection], list[str]]:
    """Number a calibrated rig's views of one board placement alike; returns ``(detections, renumbered cameras)``.

    The camera seeing most corners (best PnP) fixes the numbering; every other camera's board
    rotation, put in the rig frame through its calibrated pose, must agree with it, so the
    numbering closer to it is kept. Non-symmetric boards are returned unchanged.
    """
    from calibration.extrinsics import solve_board_pose

    seen = {c: d for c, d in detections.items() if c in cameras and d.usable}
    if not is_half_turn_symmetric(board) or len(seen) < 2:
        return dict(detections), []
    best = max(seen, key=lambda c: seen[c].n)
    Rb, _, _ = solve_board_pose(cameras[best], seen[best])
    R_ref = cameras[best].R.T @ Rb
    centre = board.object_points[:, :2].mean(0)
    out, renumbered = dict(detections), []
    for c, d in seen.items():
        if c == best or d.n != board.n_corners:
            continue
        R, t, _ = solve_board_pose(cameras[c], d)
        R2, _ = turned_pose(R, t, centre)
        keep = rotation_angle_deg((cameras[c].R.T @ R).T @ R_ref)
        turn = rotation_angle_deg((cameras[c].R.T @ R2).T @ R_ref)
        if turn < keep:
            out[c] = turned(d)
            renumbered.append(c)
    return out, renumbered
