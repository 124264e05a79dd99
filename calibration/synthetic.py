"""Seeded synthetic calibration scenes: a camera ring, board poses, noisy projected corners.

The test kit behind the calibration tests and ``benchmarks/calibration.py`` (after Caliscope's
``CameraSynthesizer``): every number the calibration recovers has a known truth here.

World frame: z up, floor z = 0. A board's printed face is its ``-z`` side (OpenCV: a camera
looking at the board sees the board's ``z`` axis pointing away from it), so a camera observes
a board view only when it is in front of that face, within ``max_view_angle_deg`` of its
normal — a ring of cameras around a hand-held board therefore never all see it at once.

>>> scene = make_scene(n_cameras=4, n_views=12, seed=1)
>>> sorted(scene.cameras)
['cam00', 'cam01', 'cam02', 'cam03']
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from calibration.boards import Board
from calibration.camera import Camera
from calibration.detect import Detection

__all__ = [
    "SyntheticScene",
    "camera_ring",
    "random_board_poses",
    "floor_board_pose",
    "observe",
    "make_scene",
    "default_board",
    "board_texture",
    "render_board_view",
]


def default_board() -> Board:
    """A 7x5-square ChArUco-sized board (6x4 inner corners, 10 cm squares) as a checkerboard grid."""
    return Board("synthetic_8x6", "checkerboard", 8, 6, 0.08)


def camera_ring(
    n: int = 6,
    *,
    radius: float = 3.0,
    height: float = 2.0,
    target=(0.0, 0.0, 1.0),
    size: tuple[int, int] = (1280, 800),
    focal: float = 1000.0,
    dist=(-0.12, 0.05, 0.0005, -0.0003, 0.0),
    rng: np.random.Generator | None = None,
    jitter: float = 0.0,
    start: float = 0.0,
    names=None,
    principal_offset: tuple[float, float] = (5.0, -3.0),
) -> dict[str, Camera]:
    """The toolkit's one camera ring: ``n`` cameras evenly on a circle of ``radius`` at
    ``height`` from azimuth ``start`` (radians), all looking at ``target``.

    Camera ``i`` is named ``names[i]`` (default ``cam00``, ``cam01``, ...), its principal point
    shifted by ``i × principal_offset`` pixels from the image centre (so no two are alike;
    ``(0, 0)``: centred). ``jitter`` (metres) perturbs the positions and (×0.05 rad per metre)
    the intrinsics seed.
    """
    rng = np.random.default_rng(0) if rng is None else rng
    cams = {}
    w, h = size
    du, dv = principal_offset
    for i in range(n):
        a = start + 2 * np.pi * i / n
        c = np.array([radius * np.cos(a), radius * np.sin(a), height]) + rng.normal(0, jitter, 3)
        f = focal * (1 + 0.02 * rng.standard_normal()) if jitter else focal
        K = np.array([[f, 0, (w - 1) / 2 + du * i], [0, f, (h - 1) / 2 + dv * i], [0, 0, 1.0]])
        name = f"cam{i:02d}" if names is None else names[i]
        cams[name] = Camera.look_at(name, c, target, K, size, np.array(dist, float))
    return cams


def _rot(axis, angle) -> np.ndarray:
    from calibration.rotation import rotvec_to_matrix

    a = np.asarray(axis, float)
    return rotvec_to_matrix(a / np.linalg.norm(a) * angle)


def random_board_poses(
    n: int,
    board: Board,
    rng: np.random.Generator,
    *,
    centre=(0.0, 0.0, 1.0),
    spread=(0.6, 0.6, 0.3),
    max_tilt_deg: float = 35.0,
) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """``n`` hand-held board poses ``{view: (R_world_from_board, t)}`` (X_w = R X_b + t).

    The printed face points in a uniformly random horizontal direction, tilted up/down and
    rolled by up to ``max_tilt_deg``; the board centre is uniform in ``centre ± spread``.
    """
    poses = {}
    w, h = board.extent
    for k in range(n):
        yaw = rng.uniform(0, 2 * np.pi)
        face = np.array([np.cos(yaw), np.sin(yaw), 0.0])  # direction the printed face looks
        zb = -face
        xb = np.cross([0.0, 0.0, 1.0], zb)
        xb /= np.linalg.norm(xb)
        yb = np.cross(zb, xb)
        R = np.stack([xb, yb, zb], axis=1)
        tilt = np.radians(max_tilt_deg)
        R = _rot(xb, rng.uniform(-tilt, tilt)) @ _rot(zb, rng.uniform(-tilt, tilt)) @ R
        centre_w = np.asarray(centre, float) + rng.uniform(-1, 1, 3) * np.asarray(spread, float)
        t = centre_w - R @ np.array([w / 2, h / 2, 0.0])
        poses[f"v{k:03d}"] = (R, t)
    return poses


def floor_board_pose(board: Board, origin=(0.0, 0.0), yaw: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Pose of a board lying face up on the floor with corner 0 at ``origin`` (x, y).

    With ``yaw = 0`` and ``origin = (0, 0)`` the board's x axis is world x and its
    ``-y``/``-z`` are world y/z, so a world frame built from this board is the true one.
    """
    c, s = np.cos(yaw), np.sin(yaw)
    xb = np.array([c, s, 0.0])
    zb = np.array([0.0, 0.0, -1.0])
    yb = np.cross(zb, xb)
    return np.stack([xb, yb, zb], axis=1), np.array([origin[0], origin[1], 0.0])


def observe(
    cameras: dict[str, Camera],
    board: Board,
    poses: dict[str, tuple[np.ndarray, np.ndarray]],
    rng: np.random.Generator,
    *,
    noise_px: float = 0.3,
    max_view_angle_deg: float = 70.0,
    min_corners: int = 6,
    partial: bool = False,
) -> dict[str, dict[str, Detection]]:
    """Project every board pose into every camera: ``{camera: {view: Detection}}``.

    A camera sees a view when the printed face is toward it within ``max_view_angle_deg``,
    and (checkerboard, ``partial=False``) every corner is in the image; with ``partial``
    the corners in the image are kept when there are at least ``min_corners``.
    Gaussian noise of ``noise_px`` (per axis) is added to every corner.
    """
    obj = board.object_points
    out: dict[str, dict[str, Detection]] = {name: {} for name in cameras}
    cos_max = np.cos(np.radians(max_view_angle_deg))
    for view, (R, t) in poses.items():
        Xw = obj @ R.T + t
        face = -R[:, 2]
        mid = Xw.mean(0)
        for name, cam in cameras.items():
            to_cam = cam.center - mid
            if face @ to_cam / np.linalg.norm(to_cam) < cos_max:
                continue
            uv, depth, front = cam.project_points(Xw)
            inside = front & cam.in_image(uv)
            # keep a margin of 3 px so noisy corners stay in the image
            inside &= (uv[:, 0] > 2) & (uv[:, 1] > 2) & (uv[:, 0] < cam.width - 3) & (uv[:, 1] < cam.height - 3)
            if partial:
                if inside.sum() < min_corners:
                    continue
            elif not inside.all():
                continue
            ids = np.flatnonzero(inside)
            pts = uv[ids] + rng.normal(0.0, noise_px, (len(ids), 2))
            status = "ok" if len(ids) == len(obj) else "partial"
            out[name][view] = Detection(view, ids.astype(np.int64), pts, obj[ids].copy(), cam.size, status)
    return out


@dataclass(frozen=True)
class SyntheticScene:
    """Truth and observations of a synthetic calibration capture.

    Attributes
    ----------
    cameras : dict[str, Camera]      true cameras (world frame, floor z = 0)
    board : Board
    poses : dict[str, (R, t)]        true board poses, world from board
    observations : dict[str, dict[str, Detection]]   camera → view → noisy corners
    floor_poses : list of (R, t)     the board lying on the floor, one per placement (first = origin)
    floor_observations : list of dict[str, Detection]   per placement: camera → floor corners
    """

    cameras: dict
    board: Board
    poses: dict
    observations: dict
    floor_poses: list
    floor_observations: list
    noise_px: float = 0.3
    seed: int = 0
    extra: dict = field(default_factory=dict)


def make_scene(
    n_cameras: int = 6,
    n_views: int = 40,
    *,
    noise_px: float = 0.3,
    seed: int = 0,
    board: Board | None = None,
    radius: float = 3.0,
    height: float = 2.0,
    max_view_angle_deg: float = 70.0,
    floor_origins=((0.0, 0.0),),
) -> SyntheticScene:
    """A ring of ``n_cameras`` around ``n_views`` hand-held board poses, plus a floor board
    laid at each of ``floor_origins`` (the first with yaw 0 defines the true world frame).

    Everything random comes from ``numpy.random.default_rng(seed)``.
    """
    rng = np.random.default_rng(seed)
    board = default_board() if board is None else board
    cams = camera_ring(n_cameras, radius=radius, height=height, rng=rng)
    poses = random_board_poses(n_views, board, rng)
    obs = observe(cams, board, poses, rng, noise_px=noise_px, max_view_angle_deg=max_view_angle_deg)
    fposes, floor_obs = [], []
    for k, origin in enumerate(floor_origins):
        fpose = floor_board_pose(board, origin, yaw=0.0 if k == 0 else rng.uniform(0, 2 * np.pi))
        fobs = observe(cams, board, {"floor": fpose}, rng, noise_px=noise_px, max_view_angle_deg=85.0)
        fposes.append(fpose)
        floor_obs.append({name: d["floor"] for name, d in fobs.items() if "floor" in d})
    return SyntheticScene(cams, board, poses, obs, fposes, floor_obs, noise_px, seed)


def board_texture(board: Board, px_per_square: int = 40) -> tuple[np.ndarray, np.ndarray]:
    """Printable board image ``(H, W) uint8`` and the (3, 3) map from its pixels to board metres.

    ``A @ [x, y, 1]`` gives the board-frame point (z = 0) at texture pixel (x, y), pixel (0, 0)
    being the centre of the top-left pixel.
    """
    s = int(px_per_square)
    m = s  # one-square white margin
    sq = board.square_size
    if board.kind == "charuco":
        size = (board.columns * s + 2 * m, board.rows * s + 2 * m)
        tex = board.cv_board.generateImage(size, marginSize=m, borderBits=1)
        x0 = m - 0.5  # board origin is the outer corner
    else:
        cols, rows = board.columns + 1, board.rows + 1  # squares
        jj, ii = np.meshgrid(np.arange(rows * s), np.arange(cols * s), indexing="ij")
        inner = (((ii // s) + (jj // s)) % 2 == 0).astype(np.uint8) * 255
        tex = np.full((rows * s + 2 * m, cols * s + 2 * m), 255, np.uint8)
        tex[m : m + rows * s, m : m + cols * s] = 255 - inner
        x0 = m + s - 0.5  # board origin is the first inner corner
    A = np.array([[sq / s, 0, -x0 * sq / s], [0, sq / s, -x0 * sq / s], [0, 0, 1.0]])
    return tex, A


def render_board_view(
    camera: Camera,
    board: Board,
    pose: tuple[np.ndarray, np.ndarray],
    *,
    background: int = 90,
    blur_sigma: float = 0.6,
    rng: np.random.Generator | None = None,
    noise_level: float = 2.0,
) -> np.ndarray:
    """RGB ``(H, W, 3) uint8`` image of ``board`` at ``pose`` (world from board) seen by ``camera``.

    Pinhole rendering through the plane homography (the camera's lens distortion is ignored:
    use distortion-free cameras for rendered tests); light blur and Gaussian pixel noise.
    """
    import cv2

    tex, A = board_texture(board, 40)
    R, t = pose
    Rc = camera.R @ R
    tc = camera.R @ t + camera.t
    H = camera.K @ np.column_stack([Rc[:, 0], Rc[:, 1], tc]) @ A
    w, h = camera.size
    img = cv2.warpPerspective(tex, H, (w, h), flags=cv2.INTER_AREA, borderMode=cv2.BORDER_CONSTANT, borderValue=background)
    # pixels behind the camera / outside the board stay background
    mask = cv2.warpPerspective(np.ones_like(tex), H, (w, h), flags=cv2.INTER_NEAREST, borderValue=0)
    img = np.where(mask > 0, img, background).astype(np.float32)
    if blur_sigma > 0:
        img = cv2.GaussianBlur(img, (0, 0), blur_sigma)
    if rng is not None and noise_level > 0:
        img = img + rng.normal(0, noise_level, img.shape)
    g = np.clip(np.round(img), 0, 255).astype(np.uint8)
    return np.repeat(g[:, :, None], 3, axis=2)
