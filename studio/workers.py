"""Worker processes that die with their parent.

A pool of spawned workers (``segment``, ``fit``) must never outlive the command that started
it: killed by SIGINT, SIGTERM or SIGKILL, the parent takes its workers with it. Three layers:

* :func:`die_with_parent` (run in each worker's initializer): Linux ``prctl(PR_SET_PDEATHSIG,
  SIGKILL)`` — the kernel kills the worker the instant its parent dies, whatever the signal —
  and a watchdog thread that exits the worker when its parent pid changes (other platforms, or
  a parent that died before the prctl took effect);
* :func:`worker_pool`: on an exception in the parent (Ctrl-C is a ``KeyboardInterrupt``) the
  pool's workers are terminated rather than awaited, and queued work is cancelled;
* :func:`terminate_on_sigterm`: SIGTERM in the parent becomes an orderly ``SystemExit`` so the
  same cleanup runs.

Results are written atomically by the workers (:mod:`rigs.atomic`), so a worker killed
mid-frame leaves at most a temporary file, never a torn result under a final name.
"""

from __future__ import annotations

import contextlib
import ctypes
import logging
import multiprocessing
import os
import signal
import sys
import threading
import time
from concurrent.futures import ProcessPoolExecutor
from typing import Callable, Iterator

__all__ = ["die_with_parent", "terminate_on_sigterm", "worker_pool"]

log = logging.getLogger(__name__)

_PR_SET_PDEATHSIG = 1
#: How often the watchdog looks at the parent pid (seconds).
WATCHDOG_PERIOD = 0.5


def _watch(parent: int) -> None:
    while True:
        time.sleep(WATCHDOG_PERIOD)
        if os.getppid() != parent:
            os._exit(70)  # the parent is gone: no cleanup that could block, no results half-written


def die_with_parent(parent: int | None = None) -> None:
    """Make the calling (worker) process exit when ``parent`` (default: its parent now) dies."""
    parent = os.getppid() if parent is None else parent
    if sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
        except (OSError, AttributeError):  # pragma: no cover - no prctl: the watchdog remains
            log.debug("prctl(PR_SET_PDEATHSIG) unavailable; relying on the watchdog")
    if os.getppid() != parent:  # the parent died before the prctl took effect
        os._exit(70)
    threading.Thread(target=_watch, args=(parent,), name="parent-watchdog", daemon=True).start()


def _init(parent: int, initializer: Callable | None, initargs: tuple) -> None:
    die_with_parent(parent)
    if initializer is not None:
        initializer(*initargs)


@contextlib.contextmanager
def worker_pool(workers: int, initializer: Callable | None = None, initargs: tuple = ()) -> Iterator[ProcessPoolExecutor]:
    """A ``spawn`` process pool whose workers die with this process.

    "spawn": a forked child inherits OpenCV's thread pool in an unusable state and hangs.
    Leaving the ``with`` block normally waits for the work; leaving it by an exception
    (Ctrl-C, SIGTERM via :func:`terminate_on_sigterm`, an error) cancels queued work and
    terminates the workers at once.
    """
    pool = ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"),
                               initializer=_init, initargs=(os.getpid(), initializer, initargs))
    try:
        yield pool
    except BaseException:
        # ProcessPoolExecutor has no public way to stop running work; its process table is the way in
        processes = list(getattr(pool, "_processes", {}).values())
        pool.shutdown(wait=False, cancel_futures=True)
        for p in processes:
            with contextlib.suppress(Exception):
                p.terminate()
        for p in processes:
            with contextlib.suppress(Exception):
                p.join(timeout=5)
        raise
    else:
        pool.shutdown(wait=True)


@contextlib.contextmanager
def terminate_on_sigterm() -> Iterator[None]:
    """Within the block, SIGTERM raises ``SystemExit(143)`` in the main thread (so pools and
    files are cleaned up as for Ctrl-C); the previous handler is restored afterwards."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, frame):
        raise SystemExit(128 + signum)

    previous = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)
