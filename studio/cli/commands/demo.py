"""``studio demo``: the main job on the default sample sequence, no camera needed.

simulate (once, cached) → segment → fit → light → report, with progress, then prints where the
report is and (on the terminal, not in the report) what the demo leaves out.
"""

from __future__ import annotations

import time
from pathlib import Path

from studio.simulate.samples import SAMPLES

DEFAULT_SPEC = SAMPLES / "walk" / "spec.yaml"

NOT_DONE = (
    "Not run by this demo (available):\n"
    "  - the fit with the shadow term (studio fit SESSION --shadows, thesis eq. 5.7): the demo estimates the light only\n"
    "  - the shape under clothing (thesis ch. 6): studio demo --batch --spec studio/samples/clothing_11 --frames 0:11\n"
    "  - every walk frame: the demo fits a subset (--frames) to finish in a few minutes on 2 cores"
)


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "demo",
        help="run simulate → segment → fit → light → report on the default sample sequence",
        description=(
            "The main job with no camera: render the 'walk' sample sequence if it is not cached, "
            "segment it, fit the body model to a subset of its frames in parallel, estimate the light from "
            "their shadows and write the "
            "measurement report; prints where the report is."
        ),
    )
    p.add_argument("--spec", type=Path, default=DEFAULT_SPEC, help="sample sequence spec, or a sample's folder (default: walk)")
    p.add_argument("--frames", default="0:24:6",
                   help="frames to fit, START:STOP[:STEP] or a comma list (default: %(default)s, 4 frames)")  # fmt: skip
    p.add_argument("--workers", type=int, default=2, help="worker processes (default: %(default)s)")
    p.add_argument("--gender", default="female", choices=["auto", "female", "male", "neutral"],
                   help="body model (default: %(default)s; 'auto' fits both on the first frame, slower)")  # fmt: skip
    p.add_argument("--quick", action="store_true", help="fewer particles and evaluations")
    p.add_argument("--batch", action="store_true",
                   help="after the single-frame fits, one shape shared by the frames under clothing (thesis ch. 6; "
                        "e.g. --spec studio/samples/clothing_poses --frames 0:6)")  # fmt: skip
    p.set_defaults(func=run)


def run(args) -> int:
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeElapsedColumn

    from studio.cli import CommandError, open_workspace
    from studio.cli.commands.fit import QUICK
    from studio.fit import FitError, FitOptions, fit_session
    from studio.report import write_report
    from studio.segment import segment_session
    from studio.simulate import ensure_rendered
    from studio.workspace.frames import select_frames

    spec = args.spec / "spec.yaml" if args.spec.is_dir() else args.spec  # a sample's folder names its spec
    if not spec.is_file():
        raise CommandError(f"{args.spec}: sample sequence spec not found (a spec.yaml or a folder holding one)")
    args.spec = spec
    if args.workers < 1:
        raise CommandError(f"--workers must be >= 1, got {args.workers}")
    t0 = time.perf_counter()
    cols = ("[progress.description]{task.description}", BarColumn(), MofNCompleteColumn(), TimeElapsedColumn())
    with Progress(*cols) as bar:
        task = bar.add_task("1/4 simulate (cached after the first run)", total=None)
        session = ensure_rendered(args.spec, seed=0,
                                  progress=lambda d, n: bar.update(task, completed=d, total=n))
        bar.update(task, total=1, completed=1)
    ws = open_workspace(session)
    frames = select_frames(args.frames, ws.frame_indices)
    t_seg = time.perf_counter()
    with Progress(*cols) as bar:
        task = bar.add_task("2/4 segment", total=len(frames))
        segment_session(ws, frames=frames, workers=args.workers, force=True,
                        progress=lambda d, n: bar.update(task, completed=d, total=n))
    t_fit = time.perf_counter()
    options = FitOptions(**QUICK) if args.quick else FitOptions()
    with Progress(*cols) as bar:
        task = bar.add_task(f"3/4 fit {len(frames)} frames ({args.workers} workers)", total=len(frames))
        try:
            if args.batch:
                from studio.fit.batch_session import fit_batch_session

                batch = fit_batch_session(ws, frames=frames, clothing="auto", gender=args.gender,
                                          workers=args.workers, single_options=options, chain_length=1, force=True,
                                          progress=lambda d, n: bar.update(task, completed=d, total=n))
                summary = {"gender": batch["gender"]}
                print(f"batch: {batch['gender']}, clothing {batch['clothing']}, stature "
                      f"{batch['measurements']['stature'] * 1000:.0f} mm over frames {batch['frames']}")
            else:
                summary = fit_session(ws, frames=frames, gender=args.gender, workers=args.workers, options=options,
                                      force=True, progress=lambda d, n: bar.update(task, completed=d, total=n))
        except FitError as exc:
            raise CommandError(str(exc)) from None
    t_light = time.perf_counter()
    light_msg = _light(ws, frames, args.workers)
    t_rep = time.perf_counter()
    report = write_report(ws, pdf=True)
    t_end = time.perf_counter()
    print(f"4/4 report written in {t_end - t_rep:.1f} s")
    print(f"demo: fitted frames {frames} of {session} with the {summary['gender']} model")
    print(light_msg)
    print(f"times: simulate {t_seg - t0:.1f} s, segment {t_fit - t_seg:.1f} s, fit {t_light - t_fit:.1f} s, "
          f"light {t_rep - t_light:.1f} s, total {t_end - t0:.1f} s")
    print(NOT_DONE)
    print(f"report: {report.resolve()}")
    return 0


def _light(ws, frames, workers: int) -> str:
    """Estimate the point light from the fitted frames and their shadows (thesis §5.7); a scene
    whose shadows cannot fix one is reported, not fatal."""
    from studio.light import LightError, estimate_session_light

    try:
        out = estimate_session_light(ws, frames=frames, kind="point", workers=1)
    except LightError as exc:
        return f"light: not estimated ({exc})"
    return (f"light: point light at {[round(v, 2) for v in out['position']]} m, direction ±"
            f"{out['direction_ci_deg']:.2f}°, distance {out['distance_ci'][0]:+.1f}..{out['distance_ci'][1]:+.1f} % "
            f"(95 %), in {out['timings']['total']:.1f} s -> {ws.layout.light_json}")
