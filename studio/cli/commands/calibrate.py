"""``studio calibrate``: board images or videos → ``calibration.json`` + ``calibration_report.html``.

Sub-commands::

    studio calibrate intrinsics --board B [NAME=]PATH ...      # PATH: image folder or video, one per camera
    studio calibrate extrinsics --board B --intrinsics FILE NAME=FOLDER|VIDEO ...
    studio calibrate floor      --board B --calibration calibration.json NAME=IMAGE|VIDEO ...
    studio calibrate all SESSION --board B [--floor-frames 0]  # everything from a capture session

Extrinsics folders: files with the same name (after removing the camera name from it) in two
cameras' folders are one board placement seen at the same instant.
"""

from __future__ import annotations

import logging
from pathlib import Path

log = logging.getLogger(__name__)

def register(subparsers) -> None:
    p = subparsers.add_parser(
        "calibrate",
        help="calibrate cameras, rig and floor from board images or videos",
        description=(
            "Calibrate a camera rig from checkerboard / ChArUco views: per-camera intrinsics, "
            "rig extrinsics (view graph + bundle adjustment), the floor (world frame z up, "
            "floor z = 0). Writes calibration.json and calibration_report.html."
        ),
    )
    sub = p.add_subparsers(dest="calibrate_command", metavar="STEP", title="steps")

    def common(q):
        q.add_argument("--board", required=True, help="board name shipped with studio (e.g. opencv_charuco_5x7) or a board YAML file")
        q.add_argument("-o", "--output", default="calibration.json", help="calibration file to write (default: calibration.json)")
        q.add_argument("--report", help="HTML report to write (default: calibration_report.html beside the output)")
        q.add_argument("--max-side", type=int, default=1000, help="checkerboard search on images downscaled to this longer side (default 1000)")

    qi = sub.add_parser("intrinsics", help="per-camera intrinsics from board views",
                        description="Intrinsics of each camera from a folder of board images or a video.")
    common(qi)
    qi.add_argument("sources", nargs="+", metavar="[NAME=]PATH", help="image folder or video per camera; NAME defaults to the folder/file name")
    qi.add_argument("--model", choices=("pinhole", "fisheye"), default="pinhole")
    qi.add_argument("--fix-aspect", action="store_true", help="keep fx = fy")
    qi.add_argument("--views", type=int, default=40, help="at most this many sharp, diverse views per camera (default 40)")
    qi.add_argument("--step", type=int, default=1, help="videos: look at every STEP-th frame")
    qi.set_defaults(func=run_intrinsics)

    qe = sub.add_parser("extrinsics", help="rig poses from board views the cameras share",
                        description="Camera poses from simultaneous board views, chained through the view graph, then bundle adjusted.")
    common(qe)
    qe.add_argument("--intrinsics", help="calibration file (any format studio convert reads) with every camera's intrinsics; "
                    "without it they are estimated from the board views (see --estimate)")
    qe.add_argument("--estimate", choices=("focal", "fixed-centre", "full"), default="focal",
                    help="without --intrinsics: focal length only (principal point at the centre, no distortion; one "
                         "tilted view suffices), everything but the principal point, or everything (default focal)")
    qe.add_argument("views", nargs="+", metavar="NAME=FOLDER|VIDEO", help="each camera's folder of synchronised board images, or its video")
    _board_view_options(qe)
    qe.add_argument("--free-intrinsics", action="store_true", help="also refine intrinsics in the bundle adjustment")
    qe.add_argument("--loss", default="soft_l1", choices=("linear", "soft_l1", "huber", "cauchy"))
    qe.add_argument("--reference", help="camera fixed at the rig origin (default: best connected)")
    qe.set_defaults(func=run_extrinsics)

    qf = sub.add_parser("floor", help="world frame and ground plane from a board on the floor",
                        description="Move a calibrated rig into the frame of a board lying on the floor (z up, floor z = 0).")
    common(qf)
    qf.add_argument("--calibration", required=True, help="calibration.json with the rig extrinsics")
    qf.add_argument("views", nargs="+", metavar="NAME=IMAGE|VIDEO", help="each camera's image (or video) of the floor board")
    qf.add_argument("--thickness", type=float, default=0.0, help="board thickness in metres")
    _board_view_options(qf)
    _floor_gates(qf)
    qf.set_defaults(func=run_floor)

    qa = sub.add_parser("all", help="intrinsics + extrinsics + floor from a capture session",
                        description="Every frame of SESSION is one board placement seen by all cameras at once; the floor frames show the board lying on the floor.")
    common(qa)
    qa.add_argument("session", help="capture session folder (frames/<cam>/NNNNNN.png)")
    qa.add_argument("--floor-frames", default="0", help="comma-separated frame indices with the board on the floor (default 0)")
    qa.add_argument("--intrinsics", help="use these intrinsics instead of calibrating them from the session")
    qa.add_argument("--free-intrinsics", action="store_true")
    qa.add_argument("--thickness", type=float, default=0.0)
    qa.add_argument("--model", choices=("pinhole",), default="pinhole")
    qa.add_argument("--corners", metavar="FILE", help='JSON {"camera": [x, y]}: pixel of corner 0 in every view of that '
                    "camera (decides a symmetric board's half turn when the board never moves)")
    _floor_gates(qa)
    qa.set_defaults(func=run_all)
    p.set_defaults(func=lambda args: (p.print_help(), 2)[1])


# ----------------------------------------------------------------------------- helpers
def _board_view_options(q) -> None:
    q.add_argument("--video-frames", metavar="START:STOP[:STEP]",
                   help="videos: the frames used (default: 5 spread over the video); frame k of every camera is one instant")
    q.add_argument("--corners", metavar="FILE",
                   help='JSON {"camera": [x, y]} (pixel of corner 0: decides a symmetric board\'s half turn) or '
                        '{"camera": [[x, y] x 4]} (outer inner corners from corner 0 along its row: for boards no detector finds)')


def _floor_gates(q) -> None:
    q.add_argument("--max-tilt", type=float, default=3.0, help="refuse when a camera sees the floor board tilted more than this "
                   "from the fitted floor (degrees, default 3)")
    q.add_argument("--max-plane-mm", type=float, default=50.0, help="refuse when a camera puts the floor corners further than "
                   "this from z = 0 (default 50 mm)")


def _rig_table(title: str, rows: dict, columns: list[str]) -> None:
    from rich.console import Console
    from rich.table import Table

    t = Table(title=title)
    t.add_column("camera")
    for c in columns:
        t.add_column(c, justify="right")
    for name, values in rows.items():
        t.add_row(name, *[values.get(c, "") for c in columns])
    Console().print(t)


def _error(msg: str):
    from studio.cli import CommandError

    return CommandError(msg)


def _board(args):
    from calibration.boards import load_board

    return load_board(args.board)


def _split(spec: str, what: str) -> tuple[str, Path]:
    if "=" in spec:
        name, path = spec.split("=", 1)
        if not name or not path:
            raise _error(f"{spec!r}: expected NAME=PATH with both parts ({what})")
        return name, Path(path)
    p = Path(spec)
    if any(ch in spec for ch in "*?["):
        raise _error(f"{spec!r}: name the camera of a glob pattern, e.g. left='{spec}'")
    return p.stem if p.suffix else p.name, p


def _glob_source(pattern: Path):
    import glob

    from calibration.detect import read_image

    files = sorted(glob.glob(str(pattern)))
    if not files:
        raise _error(f"{pattern}: no file matches this pattern")
    return ((Path(f).name, read_image(f)) for f in files)


def _report_path(args) -> Path:
    return Path(args.report) if args.report else Path(args.output).with_name("calibration_report.html")


def _progress():
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    return Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(), transient=False)


def _save(cameras: dict, metadata: dict, args, ground=None):
    from calibration import GroundPlane, RigCalibration

    rig = RigCalibration(cameras, ground or GroundPlane.floor(), metadata)
    path = rig.save(args.output)
    print(f"wrote {path}")
    return rig


def _intrinsics_table(results: dict) -> None:
    from rich.console import Console
    from rich.table import Table

    t = Table(title="intrinsics")
    for c in ("camera", "fx", "fy", "cx", "cy", "RMS px", "views", "rejected"):
        t.add_column(c)
    for n, r in results.items():
        t.add_row(n, f"{r.fx:.2f}", f"{r.fy:.2f}", f"{r.cx:.2f}", f"{r.cy:.2f}", f"{r.rms:.3f}", str(len(r.view_errors)), str(len(r.rejected)))
    Console().print(t)


def _metadata_intrinsics(board, results: dict) -> dict:
    return {
        "calibrated_by": "studio calibrate",
        "board": board.to_dict(),
        "intrinsics": {n: r.summary() for n, r in results.items()},
    }


# ----------------------------------------------------------------------------- steps
def run_intrinsics(args) -> int:
    from calibration.errors import CalibrationError
    from calibration.intrinsics import calibrate_intrinsics
    from calibration.sampling import sample_views

    board = _board(args)
    sources = [_split(s, "intrinsics source") for s in args.sources]
    results, detections = {}, {}
    with _progress() as prog:
        for name, path in sources:
            task = prog.add_task(f"detect {name}", total=None)
            source = _glob_source(path) if any(ch in str(path) for ch in "*?[") else path
            sampled = sample_views(source, board, n_views=args.views, step=args.step, max_side=args.max_side,
                                   progress=lambda k, n, task=task: prog.update(task, completed=k))
            dets = list(sampled.kept)
            from calibration.detect import Detection

            dets += [Detection.rejected(v, sampled.kept[0].image_size, why) for v, why in sampled.dropped.items()]
            detections[name] = dets
            try:
                results[name] = calibrate_intrinsics(dets, camera=name, model=args.model, fix_aspect_ratio=args.fix_aspect)
            except CalibrationError as exc:
                raise _error(f"{path}: {exc}") from None
    _intrinsics_table(results)
    from calibration.report import write_report

    _save({n: r.to_camera() for n, r in results.items()}, {**_metadata_intrinsics(board, results), "extrinsics": "not calibrated"}, args)
    rep = write_report(_report_path(args), title="Intrinsics calibration", intrinsics=results, detection_summary=detections)
    print(f"wrote {rep}")
    return 0


def _load_rig(path: str):
    from calibration import RigCalibration

    try:
        return RigCalibration.load(path)
    except (OSError, ValueError) as exc:
        raise _error(f"{path}: {exc}") from None


def run_extrinsics(args) -> int:
    from calibration.extrinsics import calibrate_extrinsics
    from calibration.report import write_report
    from studio.cli.commands._board_views import detect_views, load_corners

    board = _board(args)
    specs = [_split(s, "extrinsics views") for s in args.views]
    outer, hints = load_corners(args.corners)
    if args.intrinsics:
        rig = _load_any(args.intrinsics)
        unknown = [n for n, _ in specs if n not in rig.cameras]
        if unknown:
            raise _error(f"{args.intrinsics}: no intrinsics for cameras {unknown} (has {rig.camera_names})")
    with _progress() as prog:
        obs = detect_views(board, specs, max_side=args.max_side, frames=args.video_frames, outer=outer, progress=prog)
    if args.intrinsics:
        cams = {n: rig.cameras[n] for n, _ in specs}
        meta0 = dict(rig.metadata)
    else:
        cams = _estimate_intrinsics(obs, args.estimate)
        meta0 = {"intrinsics": f"estimated from the extrinsics views ({args.estimate})"}
    ex = calibrate_extrinsics(cams, obs, reference=args.reference, free_intrinsics=args.free_intrinsics, loss=args.loss,
                              board=board, hints=hints)
    print(f"bundle adjustment: RMS {ex.bundle.rms_before:.3f} -> {ex.bundle.rms_after:.3f} px ({ex.bundle.method})")
    rows = {n: {"views": str(sum(d.usable for d in obs[n].values())),
                "method": ",".join(sorted({d.extra.get("method", "?") for d in obs[n].values() if d.usable})),
                "RMS px": f"{ex.bundle.camera_rms.get(n, float('nan')):.3f}",
                "half turn": str(ex.info.get("half_turn", {}).get(n, "-"))} for n in cams}
    _rig_table("extrinsics", rows, ["views", "method", "RMS px", "half turn"])
    meta = {**meta0, "calibrated_by": "studio calibrate", "board": board.to_dict(),
            "extrinsics": {"reference": ex.info["reference"], "rms_px": ex.bundle.rms_after, "camera_rms_px": ex.bundle.camera_rms,
                           "method": ex.bundle.method, "half_turn": ex.info.get("half_turn", {})},
            "world_frame": f"camera {ex.info['reference']} (run 'studio calibrate floor' for the floor frame)"}
    _save(ex.cameras, meta, args)
    rep = write_report(_report_path(args), title="Rig extrinsics", extrinsics=ex, cameras=ex.cameras,
                       detection_summary={n: list(v.values()) for n, v in obs.items()})
    print(f"wrote {rep}")
    return 0


def _estimate_intrinsics(obs: dict, mode: str) -> dict:
    from calibration.intrinsics import calibrate_intrinsics

    cams = {}
    for name, dets in obs.items():
        r = calibrate_intrinsics(list(dets.values()), camera=name, focal_only=mode == "focal",
                                 fix_principal_point=mode == "fixed-centre", fix_aspect_ratio=mode == "fixed-centre")
        print(f"camera {name}: intrinsics estimated ({mode}): f {r.fx:.1f} px, RMS {r.rms:.3f} px")
        cams[name] = r.to_camera()
    return cams


def _load_any(path: str):
    from calibration import RigCalibration

    try:
        return RigCalibration.load_any(path)
    except (OSError, ValueError) as exc:
        raise _error(f"{path}: {exc}") from None


def run_floor(args) -> int:
    from calibration.floor import calibrate_floor
    from calibration.report import write_report
    from studio.cli.commands._board_views import detect_views, load_corners

    board = _board(args)
    rig = _load_rig(args.calibration)
    specs = [_split(spec, "floor view") for spec in args.views]
    for name, _ in specs:
        if name not in rig.cameras:
            raise _error(f"{args.calibration}: camera {name!r} is not calibrated (has {rig.camera_names})")
    outer, _hints = load_corners(args.corners)
    with _progress() as prog:
        views = detect_views(board, specs, max_side=args.max_side, frames=args.video_frames, outer=outer, progress=prog)
    dets = {}
    for name, per_view in views.items():
        usable = [d for d in per_view.values() if d.usable]
        dets[name] = usable[0] if usable else next(iter(per_view.values()))
        if not usable:
            log.warning("camera %s: floor board not used (%s)", name, dets[name].reason)
    fl = calibrate_floor(rig.cameras, dets, thickness=args.thickness, board=board,
                         max_tilt_deg=args.max_tilt, max_plane_mm=args.max_plane_mm)
    checks = _floor_summary(fl, board)
    meta = {**rig.metadata, "world_frame": "floor board (z up, floor z = 0)", "floor_check": fl.check, **checks}
    _save(fl.cameras, meta, args, fl.ground)
    rep = write_report(_report_path(args), title="Floor calibration", floor=fl, cameras=fl.cameras)
    print(f"wrote {rep}")
    return 0


def _floor_summary(fl, board) -> dict:
    """Per-camera floor table, the scale and height checks (raise when implausible); their metadata."""
    from calibration.rigchecks import camera_heights, scale_check

    heights = camera_heights(fl.cameras, fl.ground)
    scale = scale_check(fl.cameras, fl.placements[0], board)
    dets = fl.placements[0]
    rows = {}
    for key, v in fl.check.items():  # key: camera, or camera/placement with several floor placements
        cam = key.split("/")[0]
        det = dets.get(cam)
        rows[key] = {"method": det.extra.get("method", "-") if det is not None else "-", "tilt deg": f"{v['tilt_deg']:.2f}",
                     "off plane mm": f"{v['plane_mm']:.1f}", "RMS px": f"{v['reproj_px']:.3f}", "height m": f"{heights[cam]:.3f}"}
    _rig_table("floor", rows, ["method", "tilt deg", "off plane mm", "RMS px", "height m"])
    if scale["ratio"] is None:
        print(f"scale check skipped: {scale['skipped']}")
    else:
        print(f"scale: board squares {1000 * scale['square_m']:.1f} mm triangulated vs {1000 * board.square_size:.1f} mm "
              f"printed (ratio {scale['ratio']:.4f})")
    print("world z up, every camera above the floor")
    return {"camera_heights_m": heights, "scale_check": scale}


def run_all(args) -> int:
    from calibration.detect import Detection, detect_board
    from calibration.extrinsics import calibrate_extrinsics
    from calibration.floor import calibrate_floor
    from calibration.intrinsics import calibrate_intrinsics
    from calibration.report import write_report

    try:
        from rigs.session import Session
    except ImportError as exc:  # pragma: no cover - rigs ships with studio
        raise _error(f"capture sessions need rigs.session: {exc}") from None
    board = _board(args)
    try:
        session = Session.open(args.session)
    except (OSError, ValueError, RuntimeError) as exc:
        raise _error(f"{args.session}: {exc}") from None
    try:
        floor_frames = [int(v) for v in str(args.floor_frames).split(",") if v.strip()]
    except ValueError:
        raise _error(f"--floor-frames must be comma-separated frame indices, got {args.floor_frames!r}") from None
    missing = [f for f in floor_frames if f not in session.frame_indices]
    if missing:
        raise _error(f"{args.session}: floor frames {missing} are not complete frames of this session")
    obs: dict[str, dict[str, Detection]] = {c: {} for c in session.cameras}
    floor: list[dict[str, Detection]] = [{} for _ in floor_frames]
    with _progress() as prog:
        task = prog.add_task("detect board", total=len(session.frame_indices))
        for k, index in enumerate(session.frame_indices):
            for cam, image in session.frame(index).items():
                det = detect_board(image, board, view=f"{index:06d}", max_side=args.max_side, robust=index in floor_frames)
                if index in floor_frames:
                    floor[floor_frames.index(index)][cam] = det
                obs[cam][det.view] = det  # floor views are board views too (bundle adjustment)
            prog.update(task, completed=k + 1)
    if args.intrinsics:
        rig0 = _load_rig(args.intrinsics)
        cams = {c: rig0.cameras[c] for c in session.cameras if c in rig0.cameras}
        results = {}
    else:
        results = {c: calibrate_intrinsics(list(obs[c].values()), camera=c) for c in session.cameras}
        cams = {c: r.to_camera() for c, r in results.items()}
    from studio.cli.commands._board_views import load_corners

    _outer, hints = load_corners(args.corners)
    ex = calibrate_extrinsics(cams, obs, free_intrinsics=args.free_intrinsics, board=board, hints=hints)
    fl = calibrate_floor(ex.cameras, floor, thickness=args.thickness, board=board, max_tilt_deg=args.max_tilt,
                         max_plane_mm=args.max_plane_mm)
    if results:
        _intrinsics_table(results)
    print(f"bundle adjustment: RMS {ex.bundle.rms_before:.3f} -> {ex.bundle.rms_after:.3f} px")
    checks = _floor_summary(fl, board)
    meta = {**checks, **(_metadata_intrinsics(board, results) if results else {"calibrated_by": "studio calibrate", "board": board.to_dict()}),
            "session": str(args.session),
            "extrinsics": {"reference": ex.info["reference"], "rms_px": ex.bundle.rms_after, "camera_rms_px": ex.bundle.camera_rms,
                           "method": ex.bundle.method},
            "world_frame": "floor board (z up, floor z = 0)", "floor_check": fl.check}
    _save(fl.cameras, meta, args, fl.ground)
    rep = write_report(_report_path(args), title=f"Calibration of {Path(args.session).name}", intrinsics=results or None,
                       extrinsics=ex, floor=fl, cameras=fl.cameras,
                       detection_summary={c: list(v.values()) for c, v in obs.items()})
    print(f"wrote {rep}")
    return 0
