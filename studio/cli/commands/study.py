"""``studio study STUDY.yaml`` or ``studio study SESSION... -o STUDY``: many participants at once."""

from __future__ import annotations

from pathlib import Path


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "study",
        help="segment, fit and report many sessions; study.csv and a study report",
        description=(
            "Run segment → fit → report over every session of a study (a STUDY.yaml, or session folders "
            "with -o), one session after another, each session's frames over --workers processes or a Dask "
            "cluster. Resumable: participants done with the same settings are skipped. A failed session is "
            "recorded with its reason and the others go on. Writes STUDY/study.csv (one row per participant: "
            "measurements with their spread, quality flags, ANSUR II z-scores), STUDY/report/index.html and "
            "each session's outputs under STUDY/sessions/<participant>/."
        ),
    )
    p.add_argument("sources", nargs="+", type=Path, metavar="STUDY.yaml | SESSION",
                   help="a study description (format: studio.study) or capture-session folders")  # fmt: skip
    p.add_argument("-o", "--out", type=Path, default=None,
                   help="the study folder (required with session folders; overrides `output:` of a STUDY.yaml)")  # fmt: skip
    p.add_argument("--workers", type=int, default=1, help="local worker processes per session (default: %(default)s)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="run the frames on a Dask cluster: tcp://HOST:PORT, or local:N (one cluster for the study)")  # fmt: skip
    p.add_argument("--gender", default="auto", choices=["auto", "female", "male", "neutral"],
                   help="with session folders: body model (default: %(default)s)")  # fmt: skip
    p.add_argument("--frames", default=None, help="with session folders: frames to fit (default: all)")
    p.add_argument("--seed", type=int, default=0, help="with session folders: random seed (default: %(default)s)")
    p.add_argument("--quick", action="store_true", help="with session folders: fewer particles and evaluations")
    p.add_argument("--force", action="store_true", help="run participants done before again")
    p.set_defaults(func=run)


def run(args) -> int:
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeElapsedColumn

    from studio.cli import CommandError
    from studio.study import FitSettings, StudyError, load_study, run_study, study_from_sessions

    if args.workers < 1:
        raise CommandError(f"--workers must be >= 1, got {args.workers}")
    first = args.sources[0]
    try:
        if len(args.sources) == 1 and first.suffix in (".yaml", ".yml"):
            spec = load_study(first)
        else:
            if args.out is None:
                raise CommandError("studio study SESSION...: give the study folder with -o STUDY")
            spec = study_from_sessions(args.sources, args.out,
                                       FitSettings(args.gender, args.frames, args.seed, args.quick))
    except StudyError as exc:
        raise CommandError(str(exc)) from None
    cols = ("[progress.description]{task.description}", BarColumn(), MofNCompleteColumn(), TimeElapsedColumn())
    with Progress(*cols) as bar:
        sessions = bar.add_task("sessions", total=len(spec.sessions))
        frames = bar.add_task("", total=None)
        finished = []

        def progress(participant, stage, done, total):
            if stage in ("done", "failed", "kept"):
                finished.append(participant)
                bar.update(sessions, completed=len(finished))
            else:
                bar.update(frames, description=f"{participant}: {stage}", completed=done, total=total)

        try:
            state = run_study(spec, output=args.out, workers=args.workers, scheduler=args.scheduler,
                              force=args.force, progress=progress)
        except StudyError as exc:
            raise CommandError(str(exc)) from None
    root = (args.out or spec.output).resolve()
    failed = {p: e for p, e in state.items() if e["status"] == "failed" and p in {s.participant for s in spec.sessions}}
    done = sum(1 for s in spec.sessions if state.get(s.participant, {}).get("status") == "done")
    print(f"study: {done} of {len(spec.sessions)} participant(s) measured, {len(failed)} failed")
    for participant, entry in failed.items():
        print(f"  {participant}: failed: {entry['reason']}")
    print(f"table: {root / 'study.csv'}")
    print(f"report: {root / 'report' / 'index.html'}")
    return 1 if failed and not done else 0
