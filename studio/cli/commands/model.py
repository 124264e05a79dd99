"""``studio model``: build the SCAPE body models from Anny, or describe the shipped ones."""

from __future__ import annotations

import argparse
from pathlib import Path


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "model",
        help="build or describe the SCAPE body models",
        description="Build the male/female/neutral SCAPE models from the open Anny population "
        "(needs `pip install .[model-build]`), or print what the shipped models hold.",
    )
    sub = p.add_subparsers(dest="model_command", metavar="ACTION")
    b = sub.add_parser("build", help="learn the models from Anny (torch + anny, a few minutes)")
    b.add_argument("--out", type=Path, default=None, help="output folder (default: the package data folder)")
    b.add_argument("--seed", type=int, default=0, help="random seed (same seed, same model)")
    b.add_argument("--train", type=int, default=500, help="training bodies per population")
    b.add_argument("--test", type=int, default=100, help="held-out bodies per population")
    b.add_argument("--poses", type=int, default=100, help="poses of the reference body (>= 80)")
    b.add_argument("--wide-poses", type=int, default=100,
                   help="poses across each joint's whole range (seated, arms overhead; >= 0)")
    b.add_argument("--scratch", type=Path, default=None, help="folder for held-out sets (benchmark)")
    b.set_defaults(func=run_build)
    i = sub.add_parser("info", help="summarise the shipped models")
    i.add_argument("--path", type=Path, default=None, help="model file (default: shipped)")
    i.set_defaults(func=run_info)
    p.set_defaults(func=lambda args: (p.print_help(), 2)[1])


def run_build(args: argparse.Namespace) -> int:
    from studio.cli import CommandError

    if args.poses < 80:
        raise CommandError(f"--poses must be at least 80 (70 training poses + held-out), got {args.poses}")
    if args.wide_poses < 0:
        raise CommandError(f"--wide-poses must be 0 or more, got {args.wide_poses}")
    if args.train < 40:
        raise CommandError(f"--train must be at least 40 bodies, got {args.train}")
    try:
        import anny  # noqa: F401
        import fast_simplification  # noqa: F401
        import torch  # noqa: F401
    except ImportError as exc:
        raise CommandError(
            f"`studio model build` needs the model-build extra ({exc.name} missing): pip install .[model-build]"
        ) from exc
    from rich.console import Console
    from rich.progress import Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

    from studio.body.build import build_models
    from studio.body.model import DATA_FILE

    out = args.out or DATA_FILE.parent
    console = Console()
    with Progress(SpinnerColumn(), TextColumn("{task.description}"), TimeElapsedColumn(), console=console) as prog:
        task = prog.add_task("starting", total=None)

        def say(msg: str) -> None:
            prog.console.log(msg)
            prog.update(task, description=msg)

        summary = build_models(
            out, seed=args.seed, n_train=args.train, n_test=args.test, n_poses=args.poses, n_wide_poses=args.wide_poses,
            scratch=args.scratch, progress=say,
        )
    console.print(f"wrote {out / 'scape_models.npz'} ({summary['file_bytes'] / 1e6:.1f} MB)")
    return 0


def run_info(args: argparse.Namespace) -> int:
    from rich.console import Console
    from rich.table import Table

    from studio.body import GENDERS, BodyModel, measure

    table = Table(title="SCAPE body models")
    for col in ("gender", "vertices", "triangles", "shape comps", "pose size", "mean stature", "mean mass"):
        table.add_column(col)
    for g in GENDERS:
        m = BodyModel.load(g, args.path)
        meas = measure(m, m.mean_shape())
        table.add_row(
            g, str(m.n_vertices), str(len(m.faces)), str(m.n_shape), str(m.pose_size),
            f"{meas['stature']:.3f} m", f"{meas['mass']:.1f} kg",
        )
    Console().print(table)
    return 0
