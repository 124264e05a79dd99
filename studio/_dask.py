"""The Dask side of :mod:`studio.execution` (imported only when a scheduler is given; needs
``pip install .[dask]``)."""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Iterator

import distributed

from studio.execution import ExecutionError, Runner, worker_setup

__all__ = ["DASK_RETRIES", "WorkerSetup", "dask_runner", "local_cluster"]

log = logging.getLogger(__name__)

#: Times Dask runs a unit again after an exception in it (a unit on a lost worker is run again
#: by the scheduler itself, up to its ``distributed.scheduler.allowed-failures``).
DASK_RETRIES = 1


class WorkerSetup(distributed.WorkerPlugin):
    """Runs :func:`studio.execution.worker_setup` on every worker, those that join later too."""

    def __init__(self, die_with_parent: bool):
        self.die_with_parent = die_with_parent

    def setup(self, worker) -> None:
        worker_setup(self.die_with_parent)


@contextlib.contextmanager
def local_cluster(n_workers: int) -> Iterator[str]:
    """A ``LocalCluster`` of ``n_workers`` single-threaded processes on the loopback interface,
    its workers tied to this process (they are its children); yields the scheduler address. The
    scheduler's HTTP server takes a free loopback port (its default 8787 may be another cluster's:
    distributed would warn and move, and the test suite treats warnings as errors)."""
    with distributed.LocalCluster(n_workers=int(n_workers), threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address="127.0.0.1:0", silence_logs=logging.ERROR) as cluster, \
            distributed.Client(cluster, set_as_default=False) as client:
        client.register_plugin(WorkerSetup(die_with_parent=True), name="studio-worker-tied")
        yield cluster.scheduler_address


@contextlib.contextmanager
def dask_runner(kind: str, value, *, timeout: float = 30.0) -> Iterator[Runner]:
    """A :class:`~studio.execution.Runner` on a :func:`local_cluster` of ``value`` processes
    (``kind`` "local", closed on exit) or on the scheduler at address ``value``."""
    with contextlib.ExitStack() as stack:
        address = stack.enter_context(local_cluster(value)) if kind == "local" else value
        try:
            client = stack.enter_context(distributed.Client(address, timeout=timeout, set_as_default=False))
        except OSError as exc:
            raise ExecutionError(f"--scheduler {address}: cannot reach the Dask scheduler ({exc})") from None
        client.register_plugin(WorkerSetup(die_with_parent=False), name="studio-worker-setup")
        if not client.scheduler_info()["workers"]:
            try:
                client.wait_for_workers(1, timeout=timeout)
            except TimeoutError:
                raise ExecutionError(f"--scheduler {address}: no Dask worker joined within {timeout:g} s "
                                     "(start some with `dask worker ADDRESS`)") from None
        threads = sum(w.get("nthreads", 1) for w in client.scheduler_info()["workers"].values())
        log.info("Dask scheduler %s: %d worker thread(s)", address, threads)

        def submit(fn, *args):
            return client.submit(fn, *args, pure=False, retries=DASK_RETRIES)

        def first_completed(futures):
            done = {f for f in futures if f.done()}
            return done or {next(iter(distributed.as_completed(list(futures), loop=client.loop)))}

        yield Runner(threads, f"dask {address}", submit, first_completed)
