"""Test kit for the rigs tests: small synthetic source sessions and rig descriptions."""

from __future__ import annotations

import os
import signal
import subprocess
import time
from pathlib import Path

import numpy as np

from rigs import SessionWriter

CAMERAS = ("cam0", "cam1", "cam2", "cam3")


def calibration_dict(cameras=CAMERAS, size=(40, 30)) -> dict:
    """A valid native calibration of ``cameras`` on a ring, for ``size`` images."""
    from calibration import Camera, RigCalibration
    from calibration.formats.native import rig_to_dict

    cams = {}
    for k, name in enumerate(cameras):
        a = 2 * np.pi * k / len(cameras)
        cams[name] = Camera.look_at(name, [3 * np.cos(a), 3 * np.sin(a), 2.0], [0, 0, 1], 40.0, size)
    return rig_to_dict(RigCalibration(cameras=cams))


def source_image(cam_index: int, i: int, size=(40, 30), dtype=np.uint8) -> np.ndarray:
    """A deterministic, distinct image per (camera, frame): noise plus a frame-number band."""
    w, h = size
    rng = np.random.default_rng((cam_index, i))
    top = np.iinfo(dtype).max
    img = rng.integers(0, top // 2, size=(h, w, 3), dtype=dtype)
    img[: 2 + i % (h - 2), :, 0] = top  # saturated band: exercises clipping
    return img


def make_source(path: Path, n: int = 6, cameras=CAMERAS, size=(40, 30), backgrounds: int = 2,
                fps: float = 60.0) -> Path:  # fmt: skip
    """A session folder like ``studio simulate`` writes: ``n`` frames, backgrounds, calibration."""
    with SessionWriter.create(path, list(cameras), rig="test-source", fps=fps,
                              pixel_formats=dict.fromkeys(cameras, "RGB8"),
                              calibration=calibration_dict(cameras, size), compression=0) as w:  # fmt: skip
        for c, cam in enumerate(cameras):
            for b in range(backgrounds):
                w.write_background(cam, b, source_image(c, 1000 + b, size))
        for i in range(n):
            w.write_frame(
                i,
                {cam: source_image(c, i, size) for c, cam in enumerate(cameras)},
                timestamps_ns={cam: i * 16_666_667 for cam in cameras},
                frame_ids=dict.fromkeys(cameras, i),
            )
    return path


def rig_dict(source: Path | None, cameras=CAMERAS, **camera_options) -> dict:
    """A simulated rig description as a dict (as fast as possible, no jitter by default)."""
    defaults = {"backend": "simulated", "realtime": False, "pixel_format": "RGB8"}
    if source is not None:
        defaults["source"] = str(source)
    defaults.update(camera_options)
    return {
        "format": "studio.rig",
        "version": 1,
        "name": "test-rig",
        "frame_rate": 60.0,
        "trigger": {"mode": "software"},
        "sync": {"ptp": True, "tolerance_ms": 2.0},
        "defaults": defaults,
        "cameras": {cam: {"device": {"id": f"sim{k}"}} for k, cam in enumerate(cameras)},
    }


def kill_after_rows(cmd: list[str], session: Path, rows: int, timeout: float = 30.0) -> int:
    """Run ``cmd`` (a recording into ``session``) and SIGKILL it once ``frames.csv`` holds
    ``rows`` rows; returns the rows seen. Fails if the child exits or stalls first."""
    child = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        deadline, seen = time.monotonic() + timeout, 0
        while time.monotonic() < deadline and child.poll() is None and seen < rows:
            try:
                seen = (session / "frames.csv").read_text().count("\n") - 1
            except OSError:
                seen = 0
            time.sleep(0.01)
        assert child.poll() is None, child.stderr.read().decode()
        assert seen >= rows, f"only {seen} rows after {timeout:g} s"
        os.kill(child.pid, signal.SIGKILL)
    finally:
        child.kill()
        child.wait(10)
        child.stderr.close()
    return seen
