"""``studio convert``: convert a rig calibration between file formats."""

from __future__ import annotations

import argparse

FORMATS_IN = ("native", "opencv", "toml", "colmap", "qualisys")
FORMATS_OUT = ("native", "opencv", "toml", "colmap")


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "convert",
        help="convert a camera calibration between formats",
        description=(
            "Convert a rig calibration between the native calibration.json, OpenCV "
            "FileStorage YAML (EasyMocap intri.yml/extri.yml folder), Pose2Sim/anipose "
            "Calib.toml and COLMAP models (cameras + images). Qualisys .qca.txt exports can "
            "be read. Formats are inferred from the extension or folder content unless given."
        ),
        epilog=(
            "examples: studio convert Calib.toml calibration.json; "
            "studio convert calibration.json easymocap/ --to opencv; "
            "studio convert calibration.json sparse/0 --to colmap"
        ),
    )
    p.add_argument("input", help="calibration file or folder to read")
    p.add_argument("output", help="file or folder to write")
    p.add_argument("--to", choices=FORMATS_OUT, help="output format (default: from OUTPUT's name)")
    p.add_argument("--from", dest="from_", choices=FORMATS_IN, help="input format (default: detected)")
    p.add_argument("--binary", action="store_true", help="COLMAP: write .bin instead of .txt files")
    p.add_argument("--force", action="store_true", help="overwrite an existing output")
    p.set_defaults(func=run)


def _output_format(path, explicit: str | None) -> str:
    from studio.cli import CommandError

    if explicit:
        return explicit
    from calibration.formats import detect_format

    if path.suffix == "" and not path.exists():
        raise CommandError(
            f"{path}: cannot tell the output format of a new folder; pass --to opencv or --to colmap"
        )
    try:
        return detect_format(path, for_writing=True)
    except ValueError as exc:
        raise CommandError(f"{exc}; pass --to") from None


def _existing_outputs(path, fmt: str):
    if fmt == "opencv":
        if path.suffix.lower() in (".yml", ".yaml"):
            return [p for p in (path, path.with_name(path.name.replace("intri", "extri"))) if p.exists()]
        return [p for p in (path / "intri.yml", path / "extri.yml") if p.exists()]
    if fmt == "colmap":
        return [p for p in path.glob("cameras.*")] if path.is_dir() else []
    return [path] if path.exists() else []


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from calibration import RigCalibration
    from studio.cli import CommandError

    src, dst = Path(args.input), Path(args.output)
    if not src.exists():
        raise CommandError(f"{src}: no such file or folder")
    rig = RigCalibration.load_any(src, args.from_)
    fmt = _output_format(dst, args.to)
    existing = _existing_outputs(dst, fmt)
    if existing and not args.force:
        raise CommandError(f"{existing[0]} exists; pass --force to overwrite it")
    if fmt == "colmap":
        rig.to_colmap(dst, binary=args.binary)
    else:
        rig.write(dst, fmt)
    print(f"wrote {len(rig)} cameras ({', '.join(rig.camera_names)}) as {fmt} to {dst}")
    return 0
