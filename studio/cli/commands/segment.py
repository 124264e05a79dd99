"""``studio segment SESSION``: label every frame background / person / shadow, plus skin."""

from __future__ import annotations

import os
from pathlib import Path


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "segment",
        help="segment a capture session into background / person / shadow (+ skin)",
        description=(
            "Fit (once) a per-camera HSV background model from the session's empty-scene frames, "
            "classify every frame into background / person / cast shadow (thesis §5.5.1), fix "
            "shadow labels by multi-view voting on the calibrated floor (§5.5.2), and detect skin "
            "inside the person (§6.3.4). Writes SESSION/segmentation/<cam>/NNNNNN.png (0 background, "
            "1 person, 2 shadow), skin masks, overlays and a summary JSON."
        ),
    )
    p.add_argument("session", type=Path, help="capture-session folder")
    p.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1),
                   help="parallel worker processes over frames (default: %(default)s)")  # fmt: skip
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="run the frames on a Dask cluster: tcp://HOST:PORT of a running scheduler, or local:N "
                        "for a cluster of N local processes (needs pip install .[dask])")  # fmt: skip
    p.add_argument("--frames", default=None,
                   help="frames to segment: START:STOP[:STEP] (indices, STOP excluded) or a comma list")  # fmt: skip
    p.add_argument("--refit-background", action="store_true",
                   help="refit the background (and self-trained skin) models even if saved")  # fmt: skip
    p.add_argument("--no-voting", action="store_true", help="skip multi-view shadow voting")
    p.add_argument("--no-bridges", action="store_true",
                   help="keep the shadow that splits a person mask even where the other views see a solid there "
                        "(default: such shadow — grey trousers in front of the person's own shadow — is person)")
    p.add_argument("--no-skin", action="store_true", help="skip skin detection")
    p.add_argument("--skin-model", type=Path, default=None,
                   help="a trained skin model (.npz) to use for every camera instead of self-training")  # fmt: skip
    p.add_argument("--overlay-every", type=int, default=1,
                   help="write quick-look overlays for every N-th frame (0: none; default 1)")  # fmt: skip
    p.add_argument("--no-register", action="store_true",
                   help="do not move the background models onto the frames (default: a camera nudged since the "
                        "empty-scene capture is measured by phase correlation and compensated)")  # fmt: skip
    p.add_argument("--largest-component", action="store_true",
                   help="keep only the largest person component per view (clutter is reported either way)")
    p.add_argument("--hull", action="store_true",
                   help="drop person components the visual hull of all views does not explain (needs the calibration)")
    p.add_argument("--static", type=int, default=0, metavar="N",
                   help="label background the static changes (a box put down) once unchanged for N frames while "
                        "other foreground moved (a person who stops is kept); frames then run in order in one process")
    p.add_argument("--ignore", action="append", default=[], metavar="CAM=MASK.png|POLYGONS.json",
                   help="user region labelled background: a camera's mask image (non-zero = ignore) or a JSON of "
                        "polygons per camera ({\"cameras\": {cam: [[[x, y], ...]]}}); repeatable")
    p.add_argument("--t-hsv", type=float, default=None, help="eq. 5.5 background threshold t^HSV")
    p.add_argument("--t-s", type=float, default=None, help="eq. 5.5 saturation threshold t^S")
    p.add_argument("--force", action="store_true",
                   help="segment every selected frame again (default: frames already segmented with the same settings are kept)")  # fmt: skip
    p.add_argument("--out", type=Path, default=None,
                   help="write segmentation/ into this folder instead of the session (e.g. a read-only session)")  # fmt: skip
    p.set_defaults(func=run)


def run(args) -> int:
    from dataclasses import replace

    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeRemainingColumn

    from studio.cli import CommandError, open_workspace
    from studio.segment import SegmentOptions, Thresholds, segment_session
    from studio.workspace.frames import select_frames

    if args.workers < 1:
        raise CommandError(f"--workers must be >= 1, got {args.workers}")
    ws = open_workspace(args.session, out=args.out)
    frames = select_frames(args.frames, ws.frame_indices)
    thresholds = None
    if args.t_hsv is not None or args.t_s is not None:
        base = Thresholds()
        thresholds = replace(
            base,
            hsv=base.hsv if args.t_hsv is None else args.t_hsv,
            saturation=base.saturation if args.t_s is None else args.t_s,
        )
    options = SegmentOptions(
        thresholds=thresholds,
        refit_background=args.refit_background,
        voting=not args.no_voting,
        bridges=not args.no_bridges,
        skin=not args.no_skin,
        skin_model=args.skin_model,
        overlay_every=max(0, args.overlay_every),
        register=not args.no_register,
        largest_component=args.largest_component,
        hull=args.hull,
        static_frames=max(0, args.static),
        ignore=tuple(args.ignore),
    )
    total = len(frames) if frames is not None else len(ws.frame_indices)
    with Progress(
        "[progress.description]{task.description}", BarColumn(), MofNCompleteColumn(), TimeRemainingColumn()
    ) as bar:
        task = bar.add_task("segmenting", total=total)
        summary = segment_session(
            ws,
            options,
            frames=frames,
            workers=args.workers,
            scheduler=args.scheduler,
            force=args.force,
            progress=lambda done, n: bar.update(task, completed=done, total=n),
        )
    n = len(summary.frames)
    if summary.skipped:
        print(f"{len(summary.skipped)} frame(s) already segmented with the same settings were kept (--force redoes them)")
    print(
        f"segmented {n} frame(s) x {len(summary.cameras)} camera(s) in {summary.seconds:.1f} s "
        f"({n / max(summary.seconds, 1e-9):.1f} multi-frames/s); voting "
        f"{'on' if summary.voting else 'off'}; skin models for {summary.skin_cameras or 'no camera'}"
    )
    print(f"labels in {ws.layout.segmentation_dir}")
    return 0
