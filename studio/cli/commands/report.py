"""``studio report SESSION``: the measurement report of a fitted session."""

from __future__ import annotations

from pathlib import Path


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "report",
        help="write report/index.html (and report.pdf) and measurements.json/.csv of a fitted session",
        description=(
            "Measure the fitted body by ISO 7250-1 definitions (stature, eye, shoulder, elbow, crotch and "
            "knee heights, breadths, depth, girths, segment lengths, arm span, mass, BMI) with a 95 %% interval "
            "(spread over frames, calibration, fit posterior), the ISO 20685-1 allowance, ANSUR II percentiles "
            "and the quality flags; write a self-contained printable HTML report (landmarks, overlays, quality "
            "over frames, calibration and segmentation figures), optionally a PDF, plus "
            "report/measurements.json and .csv."
        ),
    )
    p.add_argument("session", type=Path, help="a session fitted with `studio fit`")
    p.add_argument("--out", type=Path, default=None,
                   help="the folder `studio fit --out` wrote to (the report goes there too)")
    p.add_argument("--participant", default="", metavar="ID", help="participant identifier shown on every page")
    p.add_argument("--sex", choices=["female", "male"], default=None,
                   help="participant's sex for the population percentiles (default: the fitted model's)")
    p.add_argument("--age", type=float, default=None, help="participant's age in years")
    p.add_argument("--notes", default="", help="free text shown with the participant")
    p.add_argument("--pdf", action="store_true", help="also write report/report.pdf (printable pages)")
    p.add_argument("--no-posterior", action="store_true",
                   help="leave the fit posterior out of the uncertainty (faster; the page says so)")
    p.set_defaults(func=run)


def run(args) -> int:
    from studio.cli import CommandError, open_workspace
    from studio.fit import FitError
    from studio.report import Participant, write_report

    try:
        who = Participant(args.participant, args.sex, args.age, args.notes)
    except ValueError as exc:
        raise CommandError(str(exc)) from None
    ws = open_workspace(args.session, out=args.out)
    ws.check_writable(ws.layout.report_dir)
    try:
        path = write_report(ws, participant=who, pdf=args.pdf, posterior=not args.no_posterior)
    except FitError as exc:
        raise CommandError(str(exc)) from None
    print(f"report: {path}")
    if args.pdf:
        print(f"pdf: {ws.layout.report_pdf}")
    return 0
