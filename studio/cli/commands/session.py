"""``studio session``: inspect capture sessions on disk.

``studio session info DIR`` prints cameras, frame count, fps, status, gaps and issues;
``--check`` also decodes every image and exits with code 1 when anything is damaged
(missing/truncated/undecodable/mis-sized images, torn or malformed ``frames.csv`` lines,
cameras with different background counts). Dropped frames (indices absent from
``frames.csv``) are listed as gaps but do not fail the check.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

__all__ = ["register", "run"]

MAX_LISTED = 10


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "session",
        help="inspect capture sessions (frames, gaps, integrity)",
        description="Inspect a capture session folder written by the recorder or the simulator.",
    )
    actions = p.add_subparsers(dest="session_action", metavar="ACTION", title="actions")
    info = actions.add_parser(
        "info",
        help="summarise a session: cameras, frames, fps, gaps, status",
        description="Summarise a capture session; with --check, decode every image and exit "
        "non-zero on damage.",
    )
    info.add_argument("directory", type=Path, help="the session folder (holds session.json)")
    info.add_argument(
        "--check", action="store_true", help="decode every image; exit code 1 if anything is damaged"
    )
    info.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(func=run, _session_parser=p)


def run(args: argparse.Namespace) -> int:
    if getattr(args, "session_action", None) != "info":
        args._session_parser.print_help()
        return 2
    return _info(args)


def _camera_line(session, cam: str) -> str:
    spec = session.info.get("images", {}).get(cam)
    fmt = session.info.get("pixel_formats", {}).get(cam)
    parts = [cam]
    if spec:
        parts.append(f"{spec['width']}x{spec['height']}, {spec['channels']} ch, {spec['dtype']}")
    if fmt:
        parts.append(fmt)
    parts.append(f"{len(session.background_indices(cam))} background")
    return " | ".join(parts)


def _check(session):
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn

    with Progress(
        TextColumn("checking frames"), BarColumn(), MofNCompleteColumn(),
        console=Console(stderr=True), transient=True,
    ) as progress:  # fmt: skip
        task = progress.add_task("check", total=max(1, len(session.frame_indices)))
        return session.validate(deep=True, progress=lambda done, total: progress.update(task, completed=done))


def _info(args: argparse.Namespace) -> int:
    from rigs.session import Session

    session = Session.open(args.directory)
    report = _check(session) if args.check else None
    calibration_problems, calibration_warnings = [], []
    if args.check and session.calibration_path is not None:
        from studio.workspace import WorkspaceError, validate_calibration

        try:
            from calibration import RigCalibration

            calib = RigCalibration.load(session.calibration_path)
            calibration_warnings = validate_calibration(
                calib, {c: session.image_size(c) for c in session.cameras}, source=session.calibration_path)
        except (WorkspaceError, ValueError, OSError) as exc:  # CalibrationError is a ValueError
            calibration_problems.append(str(exc))
    indices = session.frame_indices
    summary = {
        "path": str(session.path),
        "status": session.status,
        "rig": session.rig,
        "cameras": session.cameras,
        "fps": session.fps,
        "frames": len(indices),
        "first_index": indices[0] if indices else None,
        "last_index": indices[-1] if indices else None,
        "backgrounds": {cam: len(session.background_indices(cam)) for cam in session.cameras},
        "calibration": session.calibration_path is not None,
        "truth": session.truth_dir is not None,
        "gaps": [[i, r] for i, r in session.gaps],
        "drops": session.drops,
        "issues": list(session.issues),
    }
    if report is not None:
        summary["check"] = {
            "ok": report.ok and not calibration_problems,
            "calibration_problems": calibration_problems,
            "calibration_warnings": calibration_warnings,
            "images_checked": report.images_checked,
            "problems": list(report.problems),
            "notes": list(report.notes),
        }
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        span = f" (indices {indices[0]}..{indices[-1]})" if indices else ""
        print(f"session   {session.path}")
        print(f"status    {session.status}")
        print(f"rig       {session.rig}")
        print(f"fps       {session.fps if session.fps is not None else 'unknown'}")
        print(f"frames    {len(indices)} complete{span}")
        print("cameras")
        for cam in session.cameras:
            print(f"  {_camera_line(session, cam)}")
        print(f"calibration {'calibration.json' if summary['calibration'] else 'none'}; "
              f"truth {'yes' if summary['truth'] else 'no'}")  # fmt: skip
        print(f"gaps      {len(session.gaps)}")
        drops = session.drops
        if drops:
            per_cam = ", ".join(f"{c} dropped {d['dropped']} late {d['late']} duplicates {d['duplicates']} "
                                f"queue {d['queue_dropped']}" for c, d in drops.get("cameras", {}).items())
            print(f"drops     {drops.get('incomplete_instants', 0)} incomplete trigger instant(s) not in frames.csv; "
                  f"recorder dropped {drops.get('recorder_dropped', 0)}; {per_cam}")
            for cam, counters in (drops.get("streams") or {}).items():
                print(f"stream    {cam}: " + ", ".join(f"{k} {v}" for k, v in counters.items()))
        for index, reason in session.gaps[:MAX_LISTED]:
            print(f"  {index}: {reason}")
        if len(session.gaps) > MAX_LISTED:
            print(f"  ... and {len(session.gaps) - MAX_LISTED} more")
        if session.issues:
            print(f"issues    {len(session.issues)}")
            for msg in session.issues:
                print(f"  {msg}")
        if report is not None:
            n_problems = len(report.problems) + len(calibration_problems)
            verdict = "OK" if n_problems == 0 else f"{n_problems} problem(s)"
            print(f"check     {verdict} ({report.images_checked} images decoded, calibration "
                  f"{'absent' if session.calibration_path is None else 'invalid' if calibration_problems else 'valid'})")
            for msg in list(report.problems[len(session.issues):]) + calibration_problems:
                print(f"  {msg}")
            for msg in calibration_warnings:
                print(f"  warning: {msg}")
            for note in report.notes:
                print(f"  note: {note}")
    if report is not None and (not report.ok or calibration_problems):
        return 1
    return 0
