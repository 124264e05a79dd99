"""``studio simulate``: render a scene spec into a capture session with ground truth.

``studio simulate --spec SPEC --out DIR [--seed S]`` renders any spec; the same seed gives
identical files. ``studio simulate build-truth [--out sample_sequences] [NAME ...]`` rebuilds
the true Anny bodies of the sample sequences (needs the ``model-build`` extra; anny honours
``ANNY_CACHE_DIR``; the first model construction takes about a minute).
"""

from __future__ import annotations

import argparse
from pathlib import Path


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "simulate",
        help="render a simulated capture session (frames + ground truth) from a scene spec",
        description="Render a simulated studio session: K calibrated cameras, floor and backdrop, "
        "point/directional lights with hard shadows, a person (true Anny body) and sensor "
        "effects; writes a capture-session folder with truth/ (masks, meshes, lights, "
        "measurements). `studio simulate build-truth` rebuilds the true bodies.",
    )
    p.add_argument("action", nargs="?", choices=["render", "build-truth"], default="render",
                   help="render (default) a spec, or build-truth: rebuild body.npz files from Anny")
    p.add_argument("names", nargs="*", help="build-truth: sequences to build (default all)")
    p.add_argument("--spec", type=Path, help="scene spec (spec.yaml or its folder)")
    p.add_argument("--out", type=Path, help="session folder to write (build-truth: the "
                   "samples folder; default: the installed studio/samples)")
    p.add_argument("--seed", type=int, default=None, help="override the spec's seed")
    p.add_argument("--overwrite", action="store_true", help="replace an existing session")
    p.add_argument("--sheet", type=Path, help="also write a contact sheet PNG of one multi-frame "
                   "(all cameras above their truth masks)")
    p.add_argument("--sheet-frame", type=int, default=0, help="frame of the contact sheet")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from studio.cli import CommandError

    if args.action == "build-truth":
        return _build_truth(args)
    if args.names:
        raise CommandError(f"unexpected arguments {args.names} (only build-truth takes names)")
    if args.spec is None or args.out is None:
        raise CommandError("simulate needs --spec SPEC and --out DIR")
    from rich.progress import Progress

    from studio.simulate import load_spec, simulate

    spec = load_spec(args.spec)
    with Progress(transient=True) as bar:
        task = bar.add_task(f"rendering {spec.name}", total=None)

        def progress(done: int, total: int) -> None:
            bar.update(task, completed=done, total=total)

        try:
            out = simulate(spec, args.out, args.seed, overwrite=args.overwrite, progress=progress)
        except FileExistsError as exc:
            raise CommandError(str(exc)) from None
    print(f"wrote {out}")
    if args.sheet is not None:
        from rigs.imageio import write_image
        from studio.simulate.sheet import contact_sheet

        args.sheet.parent.mkdir(parents=True, exist_ok=True)
        write_image(args.sheet, contact_sheet(out, args.sheet_frame), compression=9)
        print(f"wrote {args.sheet}")
    return 0


def _build_truth(args: argparse.Namespace) -> int:
    from studio.simulate.truth_build import SEQUENCES, build_truth

    from studio.simulate import SAMPLES

    out = args.out or SAMPLES
    names = args.names or list(SEQUENCES)
    for path in build_truth(out, names):
        print(f"wrote {path}")
    return 0
