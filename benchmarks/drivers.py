"""Capture through each camera backend to disk: sustained multi-frames/s, CPU use, drops.

Anchor (thesis §4.8): four synchronized 656×490 cameras at 60 Hz stored in real time — 60
multi-frames/s with no drops. Rows: the ``simulated`` backend (4 cameras, real-time pacing,
as a reference), ``aravis`` (4 Aravis Fake cameras, free-running at 60 Hz on the host clock,
matched by timestamp) in Mono8 and RGB8, and ``genicam`` (one device of the genicam
wheel's ``viky.cti`` producer, RGBa8 400×400, at 60 Hz: its devices send no timestamps and
their frame counters drift apart, so they cannot form a synchronised rig). Every row runs the full path: driver
→ pixel conversion → SyncGroup → Recorder writing PNG level 0 to a temporary session. CPU is
this process's CPU time over wall time (2.0 = two cores busy). Drops = incomplete instants +
stream underruns + recorder drops while recording (the instants lost while the cameras start one
after another, before the warm-up ends, are not counted). A backend whose package is missing is reported, not run.

    .venv/bin/python benchmarks/drivers.py [--seconds 20]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ANCHOR = 60.0
W, H = 656, 490


def _rig(name: str, cameras: dict, defaults: dict, key: str = "frame_id", trigger: str = "software",
         tolerance_ms: float | None = 5.0) -> dict:
    return {"format": "studio.rig", "version": 1, "name": name, "frame_rate": ANCHOR,
            "trigger": {"mode": trigger}, "sync": {"key": key, "tolerance_ms": tolerance_ms},
            "defaults": defaults, "cameras": cameras}  # fmt: skip


def simulated_rig(tmp: Path) -> dict:
    from capture import make_source

    source = make_source(tmp / "src", 12)
    return _rig("simulated", {f"cam{k}": {} for k in range(4)},
                {"backend": "simulated", "source": str(source), "realtime": True, "queue_size": 16})


def aravis_rig(pixel_format: str) -> dict:
    from rigs.backends.aravis import import_aravis

    import_aravis()
    return _rig(f"aravis-{pixel_format}", {f"cam{k}": {} for k in range(4)},
                {"backend": "aravis", "interfaces": ["Fake"], "device": {"id": "Fake_1"}, "pixel_format": pixel_format,
                 "width": W, "height": H, "buffers": 32}, key="timestamp", trigger="free-run")  # fmt: skip


def genicam_rig() -> dict:
    import genicam

    from rigs.backends.genicam import import_harvesters

    import_harvesters()
    cti = Path(genicam.__file__).resolve().parent / "viky.cti"
    # one device: viky's devices are not synchronised (no timestamps, frame counters that drift apart)
    return _rig("genicam-viky", {"cam0": {"device": {"serial": "0"}}},
                {"backend": "genicam", "producer": str(cti), "pixel_format": "RGBa8", "buffers": 32},
                trigger="free-run", tolerance_ms=None)  # fmt: skip


def record(desc: dict, out: Path, seconds: float) -> dict:
    from rigs import Recorder, Rig, SessionWriter

    with Rig.open(desc) as rig:
        list(rig.multiframes(10, timeout=5.0))  # warm up: caches, first buffers, cameras started in turn
        before = rig.stats.sync.incomplete, sum(c.device_stats().get("n_underruns", 0) for c in rig.cameras.values())
        writer = SessionWriter.create(out, rig.camera_names, rig=desc["name"], fps=ANCHOR, compression=0)
        t0, c0, n = time.perf_counter(), time.process_time(), 0
        with Recorder(writer, queue_size=64) as rec:
            for mf in rig.multiframes(None, timeout=5.0):
                rec.submit(mf)
                n += 1
                if time.perf_counter() - t0 >= seconds:
                    break
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        sync, rstats = rig.stats.sync, rec.stats
        underruns = sum(c.device_stats().get("n_underruns", 0) for c in rig.cameras.values()) - before[1]
        queue_drops = sum(c.queue_dropped for c in rig.stats.cameras.values())
        shape = next(iter(mf.images.values())).shape
    return {"multiframes_per_s": round(n / wall, 1), "cpu_cores": round(cpu / wall, 2),
            "incomplete": int(sync.incomplete - before[0]), "underruns": int(underruns), "queue_drops": int(queue_drops),
            "recorder_dropped": int(rstats.dropped), "image": list(shape), "cameras": len(desc["cameras"])}  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=20.0, help="recording time per row (default 20)")
    args = ap.parse_args()

    from rich.console import Console
    from rich.table import Table

    from rigs import RigError
    from rigs.atomic import atomic_write_json

    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        makers = {"simulated RGB8": lambda: simulated_rig(tmp), "aravis Fake Mono8": lambda: aravis_rig("Mono8"),
                  "aravis Fake RGB8": lambda: aravis_rig("RGB8"), "genicam viky RGBa8": genicam_rig}  # fmt: skip
        for k, (name, make) in enumerate(makers.items()):
            try:
                desc = make()
            except (ImportError, RigError) as exc:
                rows[name] = {"unavailable": str(exc)}
                continue
            rows[name] = record(desc, tmp / f"rec{k}", args.seconds)

    table = Table(title=f"capture to disk per backend, {args.seconds:g} s per row (anchor: {ANCHOR:.0f} "
                        "multi-frames/s, no drops)")  # fmt: skip
    for col in ("backend", "cameras × image", "multi-frames/s", "CPU cores", "drops (incomplete/underrun/queue/recorder)"):
        table.add_column(col)
    for name, r in rows.items():
        if "unavailable" in r:
            table.add_row(name, "—", "—", "—", r["unavailable"])
            continue
        drops = f"{r['incomplete']}/{r['underruns']}/{r['queue_drops']}/{r['recorder_dropped']}"
        table.add_row(name, f"{r['cameras']} × {'×'.join(map(str, r['image']))}", f"{r['multiframes_per_s']:.1f}",
                      f"{r['cpu_cores']:.2f}", drops)  # fmt: skip
    Console().print(table)
    out = ROOT / "benchmarks" / "results" / "drivers.json"
    atomic_write_json(out, {"anchor_multiframes_per_s": ANCHOR, "seconds": args.seconds, "rows": rows}, mkdir=True)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
