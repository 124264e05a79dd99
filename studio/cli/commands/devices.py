"""``studio devices``: the cameras each GenICam backend sees, or why a backend is unavailable."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

BACKENDS = ("aravis", "genicam")


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "devices",
        help="list the cameras the aravis and genicam backends see",
        description=(
            "List the cameras each GenICam backend sees (backend, vendor, model, serial, interface, "
            "current pixel format) and the id to put under 'device:' in a rig YAML. A backend that "
            "cannot run (package, introspection data or GenTL producer missing) is explained in one "
            "line. Listing GigE Vision cameras sends a discovery broadcast on the local networks; "
            "--aravis-interfaces limits Aravis to the interfaces named."
        ),
    )
    p.add_argument("--backend", choices=(*BACKENDS, "all"), default="all", help="which backend (default all)")
    p.add_argument("--producer", type=Path, action="append", default=None,
                   help="GenTL producer (.cti) for the genicam backend; repeatable "
                        "(default: the .cti files in $GENICAM_GENTL64_PATH)")  # fmt: skip
    p.add_argument("--aravis-interfaces", default=None, metavar="LIST",
                   help="comma-separated Aravis interfaces to enable, e.g. USB3Vision,GigEVision or Fake "
                        "(default: Aravis' own)")  # fmt: skip
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")
    p.set_defaults(func=run)


def _aravis(interfaces: str | None) -> list[dict]:
    from rigs.backends.aravis import AravisTransport, import_aravis, list_devices, select_interfaces

    arv, glib = import_aravis()
    select_interfaces(arv, interfaces.split(",") if interfaces else None)
    rows = []
    for d in list_devices(arv):
        transport = AravisTransport(arv, glib, d["id"], d["id"])
        try:
            fmt = transport.camera.get_pixel_format_as_string()
        finally:
            transport.close()
        rows.append({**d, "pixel_format": fmt})
    return rows


def _genicam(producers: list[Path] | None) -> list[dict]:
    from rigs.backends.genicam import HarvesterTransport, open_harvester, producer_files

    files = producer_files(producers)
    entry = open_harvester(None, files)
    rows = []
    try:
        infos = list(entry["harvester"].device_info_list)
        for i, d in enumerate(infos):
            entry["users"] += 1
            transport = HarvesterTransport(entry, i, str(d.id_))
            try:
                fmt = str(transport.read("PixelFormat")) if transport.kind("PixelFormat") else ""
            finally:
                transport.close()
            rows.append({"id": str(d.id_), "vendor": str(d.vendor), "model": str(d.model),
                         "serial": str(d.serial_number), "interface": str(d.tl_type), "pixel_format": fmt,
                         "producer": ", ".join(p.name for p in files)})  # fmt: skip
    finally:
        entry["harvester"].reset()
    return rows


def run(args: argparse.Namespace) -> int:
    from rigs import RigError

    chosen = BACKENDS if args.backend == "all" else (args.backend,)
    found: dict[str, list[dict]] = {}
    missing: dict[str, str] = {}
    for backend in chosen:
        try:
            found[backend] = _aravis(args.aravis_interfaces) if backend == "aravis" else _genicam(args.producer)
        except RigError as exc:
            missing[backend] = str(exc)
    if args.json:
        print(json.dumps({"devices": found, "unavailable": missing}, indent=2))
        return 0
    from rich.console import Console
    from rich.table import Table

    table = Table(title="cameras")
    for col in ("backend", "vendor", "model", "serial", "interface", "pixel format", "device id"):
        table.add_column(col)
    for backend, rows in found.items():
        for r in rows:
            table.add_row(backend, r["vendor"], r["model"], r["serial"], r["interface"], r["pixel_format"], r["id"])
    console = Console()
    console.print(table)
    for backend, reason in missing.items():
        console.print(f"{backend}: unavailable — {reason}", markup=False, soft_wrap=True)
    for backend, rows in found.items():
        if not rows:
            console.print(f"{backend}: no cameras found")
    return 0
