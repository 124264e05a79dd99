"""``studio capture``: record synchronized multi-frames from a rig into a capture session."""

from __future__ import annotations

import argparse
import time
from dataclasses import replace
from pathlib import Path


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "capture",
        help="record a capture session from a camera rig",
        description=(
            "Open the cameras of a rig description, synchronize their frames into multi-frames "
            "of one trigger instant and record them into a capture session folder (crash-safe: "
            "every listed frame is complete). Shows fps per camera, drops and queue depth while "
            "recording and prints per-camera dropped/late/duplicate counts at the end. The "
            "default rig is the shipped simulated 4-camera rig (no camera needed)."
        ),
    )
    p.add_argument("--rig", type=Path, default=None,
                   help="rig description YAML (default: the shipped rigs/simulated.yaml)")
    p.add_argument("--out", type=Path, required=True, help="session folder to create")
    p.add_argument("--frames", type=int, default=60, help="multi-frames to record (default 60)")
    p.add_argument("--background", type=int, default=0, metavar="N",
                   help="record N background (empty-scene) frames first; simulated and replay "
                        "rigs take their source's background frames")
    p.add_argument("--source", type=Path, default=None,
                   help="override the simulated cameras' source (a session folder or scene spec)")
    p.add_argument("--seed", type=int, default=0, help="seed for rendering a spec source (default 0)")
    p.add_argument("--fast", action="store_true",
                   help="simulated/replay rigs: deliver as fast as possible instead of real time")
    p.add_argument("--queue", type=int, default=64, help="recorder queue size in multi-frames (default 64)")
    p.add_argument("--compression", type=int, default=0,
                   help="PNG compression level 0-9 (default 0: fastest, ~1 MB per 656x490 RGB image; "
                        "level 1 halves the size at ~4x the CPU)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing session at --out")
    p.set_defaults(func=run)


def _render_spec_sources(desc, seed: int, console):
    """Replace scene-spec sources of simulated cameras by their rendered (cached) sessions."""
    specs = sorted({
        Path(c.options["source"]) for c in desc.cameras.values()
        if c.backend == "simulated" and c.options.get("source") is not None
        and Path(c.options["source"]).suffix in (".yaml", ".yml")
    })  # fmt: skip
    if not specs:
        return desc
    from studio.simulate import ensure_rendered

    rendered = {}
    for spec in specs:
        if not spec.is_file():
            from studio.cli import CommandError

            raise CommandError(f"rig source {spec}: no such scene spec")
        console.print(f"[dim]source {spec}: rendering (cached after the first time)...[/dim]")
        rendered[spec] = ensure_rendered(spec, seed=seed)
    cams = {
        n: replace(c, options={**c.options, "source": rendered[Path(c.options["source"])]})
        if Path(c.options.get("source") or "").suffix in (".yaml", ".yml") and c.backend == "simulated"
        else c
        for n, c in desc.cameras.items()
    }
    return replace(desc, cameras=cams)


def _check_calibration(rig) -> None:
    """The rig's calibration against its cameras (names, image sizes, geometry) before anything is recorded."""
    from calibration import RigCalibration
    from studio.cli import CommandError
    from studio.workspace import WorkspaceError, validate_calibration

    sizes = {n: (int(c.get("Width")), int(c.get("Height"))) for n, c in rig.cameras.items()}
    try:
        validate_calibration(RigCalibration.load(rig.calibration_path), sizes, source=rig.calibration_path)
    except (WorkspaceError, ValueError, OSError) as exc:
        raise CommandError(f"{exc} (the rig's calibration; fix it or remove 'calibration' from the rig description)") from None


def run(args: argparse.Namespace) -> int:
    from rich.console import Console

    from rigs import Recorder, Rig, RigDescription, RigError, SessionError, SessionWriter, default_rig_path
    from studio.cli import CommandError

    if args.frames < 1:
        raise CommandError(f"--frames must be >= 1, got {args.frames}")
    if args.background < 0:
        raise CommandError(f"--background must be >= 0, got {args.background}")
    console = Console(stderr=True)
    rig_path = args.rig if args.rig is not None else Path(str(default_rig_path()))
    desc = RigDescription.load(rig_path)
    overrides = {}
    if args.source is not None:
        overrides["source"] = args.source
    if args.fast:
        overrides["realtime"] = False
    if overrides:
        desc = desc.with_overrides(**overrides)
    desc = _render_spec_sources(desc, args.seed, console)

    with Rig.open(desc) as rig:
        names = rig.camera_names
        if rig.calibration_path is not None:
            _check_calibration(rig)
        try:
            writer = SessionWriter.create(
                args.out, names, rig=rig.name, fps=desc.frame_rate,
                pixel_formats={n: c.get("PixelFormat") for n, c in rig.cameras.items()},
                calibration=rig.calibration_path,
                metadata={"rig_description": str(desc.path) if desc.path else None,
                          "backends": {n: c.backend for n, c in rig.cameras.items()}},
                overwrite=args.overwrite, compression=args.compression,
            )  # fmt: skip
        except SessionError as exc:
            raise CommandError(str(exc)) from exc
        try:
            with Recorder(writer, queue_size=args.queue) as recorder:
                if args.background:
                    _record_background(rig, writer, args.background, console)
                t_start = time.monotonic()
                _record(rig, recorder, args.frames, console)
                streams = {n: c.device_stats() for n, c in rig.cameras.items()}
                writer.record_drops(_drops(rig.stats, recorder.stats, streams))
                recorder.close()
                elapsed = time.monotonic() - t_start
        except (RigError, SessionError) as exc:  # disk full, a camera failure, ...: one clear line
            raise CommandError(str(exc)) from exc
        rstats, rig_stats = recorder.stats, rig.stats
    _summary(args.out, names, rstats, rig_stats, elapsed)
    return 0


def _record(rig, recorder, n: int, console) -> None:
    """Submit ``n`` multi-frames, showing fps per camera, drops and queue depth."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    names = rig.camera_names
    columns = (TextColumn("[bold]capture"), BarColumn(), MofNCompleteColumn(),
               TimeElapsedColumn(), TextColumn("{task.fields[info]}"))  # fmt: skip
    with Progress(*columns, console=console) as progress:
        task = progress.add_task("capture", total=n, info="")
        last_t, last_counts, last_update = time.monotonic(), dict.fromkeys(names, 0), 0.0
        for mf in rig.multiframes(n):
            recorder.submit(mf)
            now = time.monotonic()
            if now - last_update > 0.25 or mf.index + 1 == n:
                stats, rs = rig.stats, recorder.stats
                dt = max(now - last_t, 1e-9)
                fps = {c: (stats.cameras[c].delivered - last_counts[c]) / dt for c in names}
                last_t, last_counts = now, {c: stats.cameras[c].delivered for c in names}
                drops = stats.sync.total_dropped + sum(c.queue_dropped for c in stats.cameras.values())
                info = (" ".join(f"{c} {fps[c]:.0f}fps" for c in names)
                        + f" | drops {drops} | queue {rs.queue_depth}/{rs.queue_size}")  # fmt: skip
                progress.update(task, completed=mf.index + 1, info=info)
                last_update = now


def _record_background(rig, writer, n: int, console) -> None:
    stored = rig.background_frames(n)
    if stored is not None:
        for cam, frames in stored.items():
            for i, image in enumerate(frames):
                writer.write_background(cam, i, image)
        console.print(f"background: {n} frames per camera from the source")
        return
    console.print(f"background: recording {n} frames — keep the scene empty")
    for i, mf in enumerate(rig.multiframes(n)):
        for cam, image in mf.images.items():
            writer.write_background(cam, i, image)


def _drops(rig_stats, rstats, streams: dict | None = None) -> dict:
    """The capture's losses as the session records them (``session info`` shows the same);
    ``streams`` holds each camera's driver counters (:meth:`rigs.CameraDevice.device_stats`:
    an Aravis stream's completed buffers, failures, underruns, ...), kept when not empty."""
    sync = rig_stats.sync
    out = {
        "incomplete_instants": int(sync.incomplete),
        "recorder_dropped": int(rstats.dropped),
        "cameras": {n: {"dropped": int(sync.dropped[n]), "late": int(sync.late[n]),
                        "duplicates": int(sync.duplicates[n]), "mismatched": int(sync.mismatched[n]),
                        "queue_dropped": int(c.queue_dropped)} for n, c in rig_stats.cameras.items()},
    }
    streams = {n: s for n, s in (streams or {}).items() if s}
    if streams:
        out["streams"] = streams
    return out


def _summary(out, names, rstats, rig_stats, elapsed: float) -> None:
    from rich.console import Console
    from rich.table import Table

    sync = rig_stats.sync
    table = Table(title=f"capture {out}")
    for col in ("camera", "delivered", "dropped", "late", "duplicates", "mismatched", "queue drops"):
        table.add_column(col, justify="right" if col != "camera" else "left")
    for n in names:
        c = rig_stats.cameras[n]
        table.add_row(n, str(c.delivered), str(sync.dropped[n]), str(sync.late[n]),
                      str(sync.duplicates[n]), str(sync.mismatched[n]), str(c.queue_dropped))  # fmt: skip
    console = Console()
    console.print(table)
    console.print(
        f"frames written: {rstats.written} ({rstats.written / max(elapsed, 1e-9):.1f} multi-frames/s); "
        f"incomplete instants: {sync.incomplete}; recorder max queue {rstats.max_queue_depth}/"
        f"{rstats.queue_size}, blocked {rstats.blocked_time:.2f} s"
    )
    console.print(f"session: {out}")
