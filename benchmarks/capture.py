"""Capture throughput: simulated 4 × 656×490 RGB8 rig → SyncGroup → Recorder (PNG writes).

Anchor (thesis §4.8, HumanEva capture): four synchronized 644×488 / 656×490 cameras at
60 Hz "captured and stored to disk in real-time" — i.e. 60 multi-frames/s sustained. Rows:
SyncGroup alone, rig delivery (simulated cameras as fast as possible, no disk), and rig +
SyncGroup + Recorder writing PNG at zlib level 0 and 1 (the session default). The source is
a synthetic session (smooth shading + sensor noise, like a rendered frame), made in a
temporary folder.

    .venv/bin/python benchmarks/capture.py [--frames N]
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
ANCHOR = 60.0
CAMERAS = ("cam0", "cam1", "cam2", "cam3")
W, H = 656, 490


def _image(c: int, i: int) -> np.ndarray:
    rng = np.random.default_rng((c, i))
    y, x = np.mgrid[0:H, 0:W].astype(np.float32)
    base = 90 + 60 * np.sin(x / 70 + c) * np.cos(y / 50 + i / 5)
    img = np.stack([base, base * 0.8 + 20, base * 0.6 + 40], axis=2)
    img[200 + 5 * i : 420, 300:360] = (180, 120, 90)  # a "person"
    img += rng.normal(0, 2.0, img.shape)
    return np.clip(img, 0, 255).astype(np.uint8)


def make_source(path: Path, n: int) -> Path:
    from rigs import SessionWriter

    with SessionWriter.create(path, list(CAMERAS), rig="bench", fps=60.0, compression=0) as w:
        for i in range(n):
            w.write_frame(i, {cam: _image(c, i) for c, cam in enumerate(CAMERAS)},
                          timestamps_ns=dict.fromkeys(CAMERAS, i), frame_ids=dict.fromkeys(CAMERAS, i))  # fmt: skip
    return path


def rig_dict(source: Path) -> dict:
    return {
        "format": "studio.rig", "version": 1, "name": "bench", "frame_rate": 60.0,
        "sync": {"ptp": True, "tolerance_ms": 2.0},
        "defaults": {"backend": "simulated", "source": str(source), "realtime": False,
                     "jitter_ms": 0.05, "queue_size": 16},
        "cameras": {c: {} for c in CAMERAS},
    }  # fmt: skip


def bench_sync(n: int) -> float:
    from rigs import Frame, SyncGroup

    img = np.zeros((1, 1), np.uint8)
    frames = [Frame(c, img, k * 16_666_667 + j * 1000, k) for k in range(n) for j, c in enumerate(CAMERAS)]
    sync = SyncGroup(CAMERAS, 2_000_000)
    t0 = time.perf_counter()
    out = 0
    for f in frames:
        out += len(sync.push(f))
    dt = time.perf_counter() - t0
    assert out == n
    return n / dt


def bench_rig(source: Path, n: int) -> float:
    from rigs import Rig

    with Rig.open(rig_dict(source)) as rig:
        list(rig.multiframes(4))  # warm the decode cache
        t0 = time.perf_counter()
        got = sum(1 for _ in rig.multiframes(n))
        return got / (time.perf_counter() - t0)


def bench_record(source: Path, out: Path, n: int, level: int) -> tuple[float, dict]:
    from rigs import Recorder, Rig, SessionWriter

    with Rig.open(rig_dict(source)) as rig:
        list(rig.multiframes(4))
        writer = SessionWriter.create(out, rig.camera_names, rig="bench", fps=60.0, compression=level)
        t0 = time.perf_counter()
        with Recorder(writer, queue_size=64) as rec:
            for mf in rig.multiframes(n):
                rec.submit(mf)
        dt = time.perf_counter() - t0
        st = rec.stats
    size = sum(p.stat().st_size for p in (out / "frames").rglob("*.png"))
    return n / dt, {"max_queue_depth": st.max_queue_depth, "blocked_s": round(st.blocked_time, 2),
                    "write_s_per_multiframe": round(st.write_time / n, 4),
                    "mb_per_multiframe": round(size / n / 1e6, 2)}  # fmt: skip


def main() -> None:
    from rigs.atomic import atomic_write_text

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=240, help="multi-frames recorded per row")
    args = ap.parse_args()

    from rich.console import Console
    from rich.table import Table

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        source = make_source(tmp / "src", 12)
        rows.append(("SyncGroup.push only", bench_sync(20_000), {}))
        rows.append(("rig delivery (4 simulated cameras, no disk)", bench_rig(source, args.frames), {}))
        for level in (0, 1):
            rate, extra = bench_record(source, tmp / f"rec{level}", args.frames, level)
            rows.append((f"rig + SyncGroup + Recorder, PNG level {level}", rate, extra))

    table = Table(title=f"capture throughput, 4 × {W}×{H} RGB8 (anchor: {ANCHOR:.0f} multi-frames/s)")
    for col in ("path", "multi-frames/s", "vs anchor", "details"):
        table.add_column(col)
    for name, rate, extra in rows:
        table.add_row(name, f"{rate:,.1f}", f"{rate / ANCHOR:.2f}×", ", ".join(f"{k} {v}" for k, v in extra.items()))
    Console().print(table)
    result = {
        "anchor_multiframes_per_s": ANCHOR,
        "image": [W, H, 3], "cameras": len(CAMERAS), "frames": args.frames,
        "rows": [{"path": n, "multiframes_per_s": round(r, 2), **e} for n, r, e in rows],
    }  # fmt: skip
    out = ROOT / "benchmarks" / "results" / "capture.json"
    atomic_write_text(out, json.dumps(result, indent=2) + "\n", mkdir=True)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
