"""A parent for the worker-lifecycle tests: starts a pool of 2 (``studio.workers.worker_pool``),
keeps both workers busy, prints their pids, then waits for its own death."""

import os
import signal
import sys
import time

from studio.workers import terminate_on_sigterm, worker_pool


def busy(seconds: float) -> int:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        time.sleep(0.01)
    return os.getpid()


def pid(_):
    time.sleep(0.3)  # both workers take one each
    return os.getpid()


if __name__ == "__main__":
    # Ctrl-C as in a terminal: a shell that starts commands in the background (nohup, `&` without
    # job control) hands them SIGINT ignored, and Python then leaves it ignored (the SIGINT test
    # failed so, workers alive 10 s later)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    with terminate_on_sigterm(), worker_pool(2) as pool:
        pids = sorted(set(pool.map(pid, range(2))))
        print(" ".join(map(str, pids)), flush=True)
        futures = [pool.submit(busy, 600) for _ in range(4)]
        for f in futures:
            f.result()
    sys.exit(0)
