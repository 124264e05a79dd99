"""``studio import``: recorded videos or folders of numbered images → a capture session.

    studio import OUT --video cam1=cam1/video.avi --video cam2=cam2/video.avi \\
        [--background cam1=cam1/background.avi ...] [--frames 0:400:10] [--calibration FILE] [--trim]

Frame k of every camera's footage is one instant (the footage must be synchronised: one
trigger, equal rates). The session is written by :mod:`rigs.importer` through the session
writer, so it is crash-safe and opens like a captured one in every command.
"""

from __future__ import annotations

import argparse
from pathlib import Path


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "import",
        help="import synchronised videos or image folders as a capture session",
        description=(
            "Turn one video (any format OpenCV reads) or folder of numbered images per camera into a capture "
            "session: frame counts, rates and image sizes are checked across cameras, frame times come from the "
            "container where it has them, empty-scene footage becomes the background frames, and a calibration "
            "in any supported format is stored with the session."
        ),
    )
    p.add_argument("out", type=Path, help="session folder to create")
    p.add_argument("--video", action="append", required=True, metavar="NAME=FILE|FOLDER",
                   help="one camera's footage; repeat per camera (frame k of every camera = one instant)")
    p.add_argument("--background", action="append", default=[], metavar="NAME=FILE|FOLDER",
                   help="one camera's empty-scene footage (background frames)")
    p.add_argument("--background-frames", type=int, default=30,
                   help="at most this many background frames per camera, spread over its footage (default 30)")
    p.add_argument("--frames", metavar="START:STOP[:STEP]",
                   help="frames to import (source frame numbers; STOP excluded) or a comma list (default: all)")
    p.add_argument("--calibration", help="calibration file in any format 'studio convert' reads, stored as calibration.json")
    p.add_argument("--trim", action="store_true", help="footage of unequal length: keep the first frames of each, "
                   "as many as the shortest has (default: refuse)")
    p.add_argument("--fps", type=float, help="frame rate of image folders (videos carry their own)")
    p.add_argument("--compression", type=int, default=1, help="PNG compression level 0-9 (default 1)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing session at OUT")
    p.set_defaults(func=run)


def _calibration(path: str, sizes: dict) -> dict:
    """The calibration as native JSON, checked against the cameras' names and image sizes."""
    from calibration import RigCalibration
    from calibration.formats.native import rig_to_dict
    from studio.cli import CommandError
    from studio.workspace import WorkspaceError, validate_calibration

    try:
        rig = RigCalibration.load_any(path)
        validate_calibration(rig, sizes, source=path)
    except (WorkspaceError, OSError, ValueError) as exc:
        raise CommandError(str(exc)) from None
    return rig_to_dict(rig)


def run(args: argparse.Namespace) -> int:
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
    from rich.table import Table

    from rigs.importer import check_sources, import_session, probe, time_spread_ms
    from rigs.session import SessionError
    from studio.cli import CommandError, name_path_pairs
    from studio.workspace.frames import FrameSelectionError, select_frames

    if args.background_frames < 1:
        raise CommandError(f"--background-frames must be >= 1, got {args.background_frames}")
    what = "(camera name, then its video or image folder)"
    videos = name_path_pairs(args.video, f"after --video {what}").items()
    backgrounds = name_path_pairs(args.background, f"after --background {what}").items()
    unknown = [n for n, _ in backgrounds if n not in dict(videos)]
    if unknown:
        raise CommandError(f"--background names cameras {unknown} that have no --video")
    console = Console(stderr=True)
    try:
        with console.status("probing footage (decoding every frame once)..."):
            sources = [probe(n, p, fps=args.fps) for n, p in videos]
            bgs = [probe(n, p, fps=args.fps) for n, p in backgrounds]
        n = check_sources(sources, trim=args.trim)
        for bg in bgs:
            size = next(s.size for s in sources if s.camera == bg.camera)
            if bg.size != size:
                raise CommandError(f"camera {bg.camera}: {bg.path}: background is {bg.size[0]}x{bg.size[1]}, "
                                   f"its footage {size[0]}x{size[1]}")
        try:
            frames = select_frames(args.frames, range(n)) if args.frames else list(range(n))
        except FrameSelectionError as exc:
            raise CommandError(f"{exc} (the footage has frames 0..{n - 1})") from None
        calibration = _calibration(args.calibration, {s.camera: s.size for s in sources}) if args.calibration else None
        table = Table(title="footage")
        for col in ("camera", "file", "frames", "fps", "size", "times"):
            table.add_column(col)
        for s in sources + bgs:
            role = "" if s in sources else " (background)"
            table.add_row(s.camera + role, str(s.path), str(s.frame_count), f"{s.fps:g}" if s.fps else "-",
                          f"{s.size[0]}x{s.size[1]}", "container" if s.container_times else "nominal")
        Console().print(table)
        columns = (TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn())
        with Progress(*columns, console=console) as prog:
            tasks = {}

            def progress(stage, done, total):
                if stage not in tasks:
                    tasks[stage] = prog.add_task(stage, total=total)
                prog.update(tasks[stage], completed=done)

            writer = import_session(args.out, sources, sorted(set(frames)), backgrounds=bgs,
                                    background_frames=args.background_frames, calibration=calibration,
                                    overwrite=args.overwrite, compression=args.compression, progress=progress)
    except SessionError as exc:
        raise CommandError(str(exc)) from None
    spread = time_spread_ms(sources, sorted(set(frames)))
    period = 1000.0 / sources[0].fps if sources[0].fps else None
    if period and spread > 0.5 * period:
        console.print(f"[yellow]note: the container times of one frame differ by up to {spread:.0f} ms between cameras "
                      f"({spread / period:.1f} frame periods): check that the footage starts at the same instant[/yellow]")
    print(f"imported {writer.frame_count} frames of {len(sources)} cameras into {args.out}"
          + (" (with calibration.json)" if calibration else " (no calibration: run 'studio calibrate' and copy it in)"))
    return 0
