"""Worker processes die with their parent, whatever kills it (defect 1 of the hardening issue)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from prockit import alive

HERE = Path(__file__).parent
ROOT = HERE.parents[1]


def _start_parent():
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.Popen([sys.executable, str(HERE / "workers_parent.py")], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env, start_new_session=True)
    line = proc.stdout.readline()
    pids = [int(v) for v in line.split()]
    assert len(pids) == 2 and all(alive(p) for p in pids), proc.stderr.read() if not pids else pids
    return proc, pids


def _seconds_until_gone(pids, limit=10.0) -> float:
    t0 = time.monotonic()
    while time.monotonic() - t0 < limit:
        if not any(alive(p) for p in pids):
            return time.monotonic() - t0
        time.sleep(0.02)
    for p in pids:  # do not leave them behind even when the test fails
        if alive(p):
            os.kill(p, signal.SIGKILL)
    return float("inf")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM, signal.SIGINT])
def test_busy_workers_exit_within_seconds_of_the_parent(sig):
    """Both workers are mid-task (600 s each) when the parent gets ``sig``; they are gone within 5 s
    (measured: ~0.01 s after SIGKILL through PR_SET_PDEATHSIG, ~0.1 s after SIGTERM/SIGINT through
    the pool's own termination)."""
    proc, pids = _start_parent()
    try:
        time.sleep(0.3)
        os.kill(proc.pid, sig)
        gone = _seconds_until_gone(pids)
    finally:  # the parent exits on its own; never leave it behind, even when the wait above fails
        try:
            proc.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.communicate()
    print(f"{sig.name}: workers gone {gone:.3f} s after the parent's signal")
    assert gone < 5.0, f"workers still alive {gone} s after {sig.name}"
    if sig != signal.SIGKILL:
        assert proc.returncode in (128 + sig, -sig, 130, 1), proc.returncode
