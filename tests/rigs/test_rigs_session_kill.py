"""Crash safety: SIGKILL a session writer at random instants, then read what it left.

Every listed frame must be complete and pixel-exact, nothing torn may be listed, and the
reader must work on the never-closed session (status "recording").
"""

from __future__ import annotations

import importlib.util
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from rigs.session import Session

HELPER = Path(__file__).with_name("session_kill_writer.py")
_spec = importlib.util.spec_from_file_location("session_kill_writer", HELPER)
kw = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(kw)

KILLS = 5


def _frames_listed(path: Path) -> int:
    """Rows after the header of the session's ``frames.csv`` (0 before it exists)."""
    try:
        return max(len((path / "frames.csv").read_text().splitlines()) - 1, 0)
    except FileNotFoundError:
        return 0


def _run_and_kill(path: Path, durability: str, delay: float, after_frames: int = 0) -> None:
    """SIGKILL the writer ``delay`` s after it created the session (and, with ``after_frames``,
    listed that many frames: on a loaded machine start-up alone can outlast every delay)."""
    proc = subprocess.Popen(
        [sys.executable, str(HELPER), str(path), durability],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    try:
        deadline = time.monotonic() + 30.0
        while not (path / "session.json").exists() or _frames_listed(path) < after_frames:
            if proc.poll() is not None:
                raise AssertionError(f"writer exited early: {proc.stderr.read().decode()}")
            if time.monotonic() > deadline:
                raise AssertionError(f"writer did not create the session and list {after_frames} frames within 30 s")
            time.sleep(0.002)
        time.sleep(delay)
    finally:
        proc.kill()  # SIGKILL
        proc.wait()
        proc.stderr.close()
    assert proc.returncode == -9, "the writer must have been killed, not have finished"


def _check_session(path: Path) -> int:
    session = Session.open(path)
    assert session.status == "recording"
    assert session.cameras == kw.CAMERAS
    n = len(session.frame_indices)
    # the writer writes 0, 1, 2, ...: the complete frames are a prefix with no gap
    assert session.frame_indices == list(range(n))
    assert session.gaps == []
    assert not [msg for msg in session.issues if "frames.csv" in msg]
    for index in session.frame_indices:
        frame = session.frame(index)
        meta = session.frame_meta(index)
        for cam in kw.CAMERAS:
            want = kw.expected_image(cam, index)
            assert frame[cam].dtype == want.dtype
            np.testing.assert_array_equal(frame[cam], want)
            assert meta["timestamps_ns"][cam] == kw.expected_timestamp(cam, index)
            assert meta["frame_ids"][cam] == index + 7
    for cam in kw.CAMERAS:
        indices = session.background_indices(cam)
        assert indices == list(range(len(indices)))
        for b, image in zip(indices, session.backgrounds(cam)):
            np.testing.assert_array_equal(image, kw.expected_image(cam, b, background=True))
    # only a background set cut off mid-way may be reported, never a torn or mixed image
    report = session.validate(deep=True)
    assert all(p.startswith("background/") for p in report.problems), report.problems
    return n


def test_sigkill_at_random_instants_leaves_only_complete_pixel_exact_frames(tmp_path):
    rng = np.random.default_rng(20261121)
    delays = [0.0, *rng.uniform(0.02, 0.3, KILLS - 1)]
    counts = []
    for k, delay in enumerate(delays):
        path = tmp_path / f"run{k}"
        last = k == KILLS - 1  # killed once frames are being written, whatever the load
        _run_and_kill(path, "fsync" if last else "rename", float(delay), after_frames=int(last))
        counts.append(_check_session(path))
    # the test is only meaningful if kills landed while frames were being written
    assert max(counts) > 0, counts


def test_helper_images_are_deterministic_and_distinct():
    np.testing.assert_array_equal(kw.expected_image("cam2", 5), kw.expected_image("cam2", 5))
    assert not np.array_equal(kw.expected_image("cam0", 5), kw.expected_image("cam0", 6))
    assert not np.array_equal(kw.expected_image("cam0", 5), kw.expected_image("cam0", 5, background=True))
