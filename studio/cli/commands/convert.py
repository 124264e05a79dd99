"""``studio convert``: convert a rig calibration between file formats."""

from __future__ import annotations

import argparse

from calibration.formats import FORMATS as FORMATS_IN, WRITABLE as FORMATS_OUT
from calibration.formats.checks import UNIT_SCALE, Z_DOWN_CHOICES

#: Metadata key under which the notes of the load are kept in the converted file.
NOTES_KEY = "import_notes"


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "convert",
        help="convert a camera calibration between formats",
        description=(
            "Convert a rig calibration between the native calibration.json, OpenCV "
            "FileStorage YAML (EasyMocap intri.yml/extri.yml folder), per-camera OpenCV files "
            "(<cam>/config.xml folders, NAME=FILE pairs, OpenCV's calibration sample output), "
            "Pose2Sim/anipose/FreeMoCap Calib.toml, Caliscope camera_array.toml, multical "
            "calibration.json, Kalibr camchain.yaml and COLMAP models; Qualisys .qca.txt, Vicon .xcp "
            "and OptiTrack .mcal can be read. Formats are inferred from the extension or content "
            "unless given. Every read is converted to metres (units detected from the magnitudes "
            "unless --units) and to world Z up (a Z-down world is turned half a turn about X unless "
            "--z-down says otherwise); what was read and assumed is printed and kept in the output's "
            "metadata (import_notes)."
        ),
        epilog=(
            "examples: studio convert Calib.toml calibration.json; "
            "studio convert data/ calibration.json  (data/cam1/config.xml ...); "
            "studio convert cam1=a.xml cam2=b.xml calibration.json; "
            "studio convert calibration.json easymocap/ --to opencv; "
            "studio convert calibration.json sparse/0 --to colmap"
        ),
    )
    p.add_argument("inputs", nargs="+", metavar="INPUT",
                   help="calibration file or folder to read, or NAME=FILE per-camera OpenCV files")
    p.add_argument("output", help="file or folder to write")
    p.add_argument("--units", choices=tuple(UNIT_SCALE),
                   help="units of the input's translations (default: detected from their magnitudes)")
    p.add_argument("--z-down", choices=Z_DOWN_CHOICES,
                   help="a world whose Z points down: flip it (default for other tools' files), refuse it, "
                        "or keep it (default for this toolkit's own files)")
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
            f"{path}: cannot tell the output format of a new folder; pass --to opencv, opencv_camera or colmap"
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

    from studio.cli import CommandError

    dst = Path(args.output)
    rig, src = _load(args)
    fmt = _output_format(dst, args.to)
    existing = _existing_outputs(dst, fmt)
    if existing and not args.force:
        raise CommandError(f"{existing[0]} exists; pass --force to overwrite it")
    print(f"read {len(rig)} cameras from {src}:")
    for note in rig.notes:
        print(f"  - {note}")
    if rig.notes:  # kept in the output, after the notes of earlier conversions
        earlier = [str(n) for n in rig.metadata.get(NOTES_KEY, [])]
        rig = rig.replace(metadata={**rig.metadata, NOTES_KEY: earlier + [n for n in rig.notes if n not in earlier]})
    if fmt == "colmap":
        rig.to_colmap(dst, binary=args.binary)
    else:
        rig.write(dst, fmt)
    print(f"wrote {len(rig)} cameras ({', '.join(rig.camera_names)}) as {fmt} to {dst}")
    return 0


def _load(args):
    """The rig of the command's inputs (one file or folder, or NAME=FILE pairs) and how to name them."""
    from pathlib import Path

    from calibration import RigCalibration
    from studio.cli import CommandError, name_path_pairs

    inputs = args.inputs
    if len(inputs) == 1 and ("=" not in inputs[0] or Path(inputs[0]).exists()):
        src = Path(inputs[0])
        if not src.exists():
            raise CommandError(f"{src}: no such file or folder")
        return RigCalibration.load_any(src, args.from_, units=args.units, z_down=args.z_down), src
    pairs = name_path_pairs(inputs, "when several inputs are given")
    for name, file in pairs.items():
        if not file.is_file():
            raise CommandError(f"{file}: no such file (camera {name!r})")
    if args.from_ not in (None, "opencv_camera"):
        raise CommandError(f"NAME=FILE inputs are per-camera OpenCV files; --from {args.from_} does not apply")
    rig = RigCalibration.from_camera_files(pairs, units=args.units, z_down=args.z_down)
    return rig, f"{len(pairs)} per-camera files"
