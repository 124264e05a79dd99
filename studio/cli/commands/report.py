"""``studio report SESSION``: the measurement report of a fitted session."""

from __future__ import annotations

from pathlib import Path


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "report",
        help="write report/index.html and measurements.json/.csv of a fitted session",
        description=(
            "Measure the fitted bodies of every frame (stature, arm span, circumferences, ...), "
            "and write a self-contained HTML report (overlays, body views, measurement table with "
            "the spread over frames and, for simulated sessions, the truth; cost per frame) plus "
            "report/measurements.json and .csv."
        ),
    )
    p.add_argument("session", type=Path, help="a session fitted with `studio fit`")
    p.add_argument("--out", type=Path, default=None,
                   help="the folder `studio fit --out` wrote to (the report goes there too)")
    p.set_defaults(func=run)


def run(args) -> int:
    from studio.cli import CommandError, open_workspace
    from studio.fit import FitError
    from studio.report import write_report

    ws = open_workspace(args.session, out=args.out)
    ws.check_writable(ws.layout.report_dir)
    try:
        path = write_report(ws)
    except FitError as exc:
        raise CommandError(str(exc)) from None
    print(f"report: {path}")
    return 0
