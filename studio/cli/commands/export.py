"""``studio export SESSION --to obj|glb|trc|csv|json``: standard files of a fitted session."""

from __future__ import annotations

from pathlib import Path


def register(subparsers) -> None:
    from studio.report.exports import EXPORT_KINDS

    p = subparsers.add_parser(
        "export",
        help="write export/: meshes (OBJ, binary glTF), joints (TRC), measurements (CSV), model parameters (JSON)",
        description=(
            "Write the fitted person into export/: the mesh in the neutral pose and per frame as OBJ and "
            "binary glTF (metres, Z up), joint trajectories as TRC with named joints (OpenSim / Pose2Sim, "
            "Y up), the ISO measurements as CSV and the model parameters as JSON that studio.body reloads "
            "(studio.body.parameters.load_parameters)."
        ),
    )
    p.add_argument("session", type=Path, help="a session fitted with `studio fit`")
    p.add_argument("--out", type=Path, default=None, help="the folder `studio fit --out` wrote to")
    p.add_argument("--to", action="append", choices=EXPORT_KINDS, default=None,
                   help="what to export (repeatable; default: all)")
    p.set_defaults(func=run)


def run(args) -> int:
    from studio.cli import CommandError, open_workspace
    from studio.fit import FitError
    from studio.report.exports import EXPORT_KINDS, export_session

    ws = open_workspace(args.session, out=args.out)
    ws.check_writable(ws.layout.export_dir)
    try:
        files = export_session(ws, tuple(args.to or EXPORT_KINDS))
    except FitError as exc:
        raise CommandError(str(exc)) from None
    for f in files:
        if f.parent == ws.layout.export_dir:
            print(f"wrote {f}")
    n_frames = sum(1 for f in files if f.parent != ws.layout.export_dir)
    if n_frames:
        print(f"wrote {n_frames} per-frame mesh file(s) in {ws.layout.export_dir / 'frames'}")
    return 0
