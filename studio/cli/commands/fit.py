"""``studio fit SESSION``: fit the body model to every frame's silhouettes (thesis ch. 4)."""

from __future__ import annotations

from pathlib import Path

from studio.fit.session import CHAIN_LENGTH


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "fit",
        help="fit the SCAPE body (pose per frame, shared shape) to a segmented session",
        description=(
            "Fit the body model to the person silhouettes of a segmented, calibrated session: "
            "annealed particle filter on the pose, then staged Nelder-Mead on pose and shape "
            "(thesis ch. 4). Writes SESSION/fit/NNNNNN.json (shape, pose, costs, joints, timings), "
            "NNNNNN.ply meshes, overlays fit/overlay/<cam>/NNNNNN.png and fit/sequence.json."
        ),
    )
    p.add_argument("session", type=Path, help="capture-session folder (with calibration.json and segmentation/)")
    p.add_argument("--frames", default=None,
                   help="frames to fit: START:STOP[:STEP] (STOP excluded) or a comma list (default: all)")  # fmt: skip
    p.add_argument("--gender", default="auto", choices=["auto", "female", "male", "neutral"],
                   help="body model; auto fits female and male on the first frame and keeps the lower cost")  # fmt: skip
    p.add_argument("--workers", type=int, default=1, help="parallel worker processes (default: %(default)s)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="run the frames on a Dask cluster: tcp://HOST:PORT of a running scheduler, or local:N "
                        "for a cluster of N local processes (needs pip install .[dask])")  # fmt: skip
    p.add_argument("--chain-length", type=int, default=CHAIN_LENGTH,
                   help="longest run of frames tracked one from the other; each run starts with a search from the "
                        "silhouettes and runs on one worker (default: %(default)s)")  # fmt: skip
    p.add_argument("--seed", type=int, default=0, help="random seed (default: %(default)s)")
    p.add_argument("--quick", action="store_true", help="fewer particles and evaluations (about 3x faster, coarser)")
    p.add_argument("--force", action="store_true",
                   help="fit every selected frame again (default: frames already fitted with the same settings are kept)")  # fmt: skip
    p.add_argument("--out", type=Path, default=None,
                   help="write fit/ into this folder instead of the session (e.g. a read-only session; "
                        "its segmentation/ is read from there too)")  # fmt: skip
    p.add_argument("--shadows", action="store_true",
                   help="add the shadow term (thesis eq. 5.7) with the light of light/light.json; without one, fit "
                        "from the silhouettes, estimate the light (studio light) and fit again with the shadows")  # fmt: skip
    p.add_argument("--shadow-weight", type=float, default=1.0,
                   help="weight of the shadow term, whose views are averaged (default: %(default)s)")  # fmt: skip
    p.add_argument("--batch", action="store_true",
                   help="after the single-frame fits, fit one shape shared by several frames under clothing "
                        "(thesis ch. 6): gender by batch, fit/batch.json and fit/batch_neutral.ply")  # fmt: skip
    p.add_argument("--clothing", default="auto", choices=["auto", "tight", "loose"],
                   help="--batch: clothing-robust cost; auto fits loose and calls it tight when the body fills "
                        "the clothes (default: %(default)s)")  # fmt: skip
    p.add_argument("--gender-step", default=None, choices=["neutral", "full"],
                   help="--batch --gender auto: neutral = the thesis' step (neutral batch, then each gender's shape "
                        "with the poses fixed), full = a complete batch per gender (default: full under tight "
                        "clothing, neutral under loose)")  # fmt: skip
    p.add_argument("--batch-frames", type=int, default=8,
                   help="--batch without --frames: how many frames to choose (good quality, diverse postures; "
                        "default: %(default)s)")  # fmt: skip
    p.set_defaults(func=run)


QUICK = dict(n_particles=48, n_layers=6, n_particles_tracking=32, n_layers_tracking=4,
             nm_evaluations=50, final_evaluations=60)


def run(args) -> int:
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeElapsedColumn

    from studio.cli import CommandError
    from studio.fit import FitError, FitOptions, fit_session, open_workspace
    from studio.workspace.frames import select_frames

    if args.workers < 1:
        raise CommandError(f"--workers must be >= 1, got {args.workers}")
    try:
        ws = open_workspace(args.session, out=args.out)
    except FitError as exc:
        raise CommandError(str(exc)) from None
    frames = select_frames(args.frames, ws.frame_indices)
    options = FitOptions(**QUICK) if args.quick else FitOptions()
    if args.shadows and args.batch:
        raise CommandError("--shadows and --batch together: the batch fit has no shadow term yet; "
                           "run `studio fit --shadows` and `studio fit --batch` separately")
    if args.shadows and args.shadow_weight < 0:
        raise CommandError(f"--shadow-weight must be >= 0, got {args.shadow_weight}")
    if args.shadows and not ws.layout.light_json.is_file():
        _light_first(ws, args, frames, options)
    if args.batch:
        from studio.fit.batch_session import run_batch_command

        return run_batch_command(args, ws, frames, options)
    with Progress("[progress.description]{task.description}", BarColumn(), MofNCompleteColumn(),
                  TimeElapsedColumn()) as bar:
        n = len(frames) if frames is not None else len(ws.frame_indices)
        task = bar.add_task("fitting", total=n)
        try:
            summary = fit_session(ws, frames=frames, gender=args.gender, workers=args.workers,
                                  scheduler=args.scheduler, chain_length=args.chain_length, options=options,
                                  seed=args.seed, force=args.force, shadows=args.shadow_weight if args.shadows else None,
                                  progress=lambda done, total: bar.update(task, completed=done))
        except FitError as exc:
            raise CommandError(str(exc)) from None
    costs = list(summary["costs"].values())
    if summary["kept"]:
        print(f"{len(summary['kept'])} frame(s) already fitted with the same settings were kept (--force fits them again)")
    print(f"fitted {len(costs)} frame(s) with the {summary['gender']} model in {summary['wall_time']:.1f} s "
          f"on {summary['executor']} "
          f"(cost mean {sum(costs) / len(costs):.2f}); results in {ws.layout.fit_dir}")
    print(f"quality: {summary['quality_summary']}")
    if args.shadows:
        from studio.fit import load_fits

        shadow = [f.costs.get("shadow") for f in load_fits(ws, frames).values() if f.costs.get("shadow") is not None]
        if shadow:
            print(f"shadow term (eq. 5.7, weight {args.shadow_weight:g}): mean {sum(shadow) / len(shadow):.2f} "
                  f"over {len(shadow)} frame(s)")
    return 0


def _light_first(ws, args, frames, options) -> None:
    """No light yet: fit from the silhouettes alone (eq. 5.8), estimate the light (eq. 5.9)."""
    from studio.cli import CommandError
    from studio.fit import FitError, fit_session
    from studio.light import LightError, estimate_session_light

    print(f"no {ws.layout.light_json}: fitting from the silhouettes, then estimating the light")
    try:
        fit_session(ws, frames=frames, gender=args.gender, workers=args.workers, scheduler=args.scheduler,
                    chain_length=args.chain_length, options=options, seed=args.seed)
        light = estimate_session_light(ws, frames=None, workers=min(args.workers, 2), seed=args.seed)
    except (FitError, LightError) as exc:
        raise CommandError(str(exc)) from None
    print(f"light: {light['kind']}, direction ±{light['direction_ci_deg']:.2f}° (95%); now fitting with the shadows")
