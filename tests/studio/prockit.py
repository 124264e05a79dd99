"""Processes seen through ``/proc`` (Linux), for the tests that kill commands and count workers."""

from __future__ import annotations

from pathlib import Path


def alive(pid: int) -> bool:
    """The process exists and is not a zombie (a process that dies between the open and the read of
    its ``stat`` raises ``ProcessLookupError``: gone too)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(") ")[1][0] != "Z"
    except (FileNotFoundError, ProcessLookupError):
        return False


def children(pid: int) -> list[int]:
    """Children started by the process's main thread."""
    try:
        return [int(v) for v in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]
    except (FileNotFoundError, ProcessLookupError):
        return []


def descendants(pid: int) -> set[int]:
    """Every process below ``pid``, started by any of the threads (Dask spawns from its own)."""
    out, todo = set(), [pid]
    while todo:
        p = todo.pop()
        kids = []
        for task in Path(f"/proc/{p}/task").glob("*"):
            try:
                kids += [int(v) for v in (task / "children").read_text().split()]
            except (FileNotFoundError, ProcessLookupError):
                continue
        out |= set(kids)
        todo += kids
    return out


def kill_and_time(proc, pids, limit: float = 10.0) -> tuple[float, list[int]]:
    """SIGKILL ``proc`` (a Popen); seconds until every one of ``pids`` is gone, and those still alive
    after ``limit`` s (killed then, so that none is ever left behind)."""
    import os
    import signal
    import time

    os.kill(proc.pid, signal.SIGKILL)
    proc.wait(timeout=10)
    t_kill = time.monotonic()
    while any(alive(p) for p in pids) and time.monotonic() - t_kill < limit:
        time.sleep(0.02)
    gone = time.monotonic() - t_kill
    leftover = [p for p in pids if alive(p)]
    for p in leftover:
        os.kill(p, signal.SIGKILL)
    return gone, leftover
