"""One execution layer for the per-frame work of ``segment`` and ``fit``: local processes or Dask.

The commands cut their work into **units** (a frame, or a frame that continues the pose of the
one before it) and hand them to a runner; which runner runs them changes nothing in the
results:

* ``open_runner(1)``: in this process, one unit after the other;
* ``open_runner(N)``: ``N`` spawned worker processes that die with this process
  (:mod:`studio.workers`), BLAS and OpenCV on one thread each (:mod:`studio.blas`);
* ``open_runner(scheduler="tcp://HOST:PORT")``: the workers of a running Dask ``distributed``
  cluster (``dask scheduler`` / ``dask worker``); ``scheduler="local:N"``: a ``LocalCluster``
  of ``N`` worker processes on the loopback interface, closed with the runner. Dask is imported
  only here, only then (``pip install .[dask]``).

Units read their inputs from the session folder (shared storage on a cluster) and write their
results atomically through the workspace, so a worker lost mid-unit loses only that unit, which
the Dask scheduler runs again on another worker; a unit first looks for its own result on disk
(written with the same settings) and returns it without redoing the work.

:func:`run_chains` drives lists of dependent units (a frame tracked from the previous frame's
pose): the units of one chain run in order, each given its predecessor's result; chains run side
by side; ``progress(done, total)`` is called as each unit's future completes.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import logging
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

__all__ = ["ExecutionError", "Runner", "open_runner", "parse_scheduler", "run_chains", "shared_scheduler",
           "worker_setup"]

log = logging.getLogger(__name__)


class ExecutionError(RuntimeError):
    """A runner cannot be set up as asked (bad scheduler address, Dask missing, no workers)."""


def parse_scheduler(text: str | None) -> tuple[str, int | str] | None:
    """``None``, ``("local", N)`` for ``local:N`` or ``("address", "tcp://HOST:PORT")``.

    >>> parse_scheduler("local:2"), parse_scheduler("tcp://127.0.0.1:8786")
    (('local', 2), ('address', 'tcp://127.0.0.1:8786'))
    """
    if text is None:
        return None
    text = text.strip()
    if text.startswith("local:"):
        n = text.split(":", 1)[1]
        if not n.isdigit() or int(n) < 1:
            raise ExecutionError(f"--scheduler {text!r}: expected local:N with N >= 1 worker processes")
        return "local", int(n)
    scheme, sep, rest = text.partition("://")
    host, colon, port = rest.rpartition(":")
    if not sep or scheme not in ("tcp", "tls", "inproc", "ucx") or not colon or not host or not port.isdigit():
        raise ExecutionError(f"--scheduler {text!r}: expected a Dask scheduler address tcp://HOST:PORT "
                             "(or local:N for a cluster of N local processes)")
    return "address", text


def worker_setup(die_with_parent: bool = True) -> None:
    """What every worker process runs once: die with the parent (local processes), BLAS, OpenCV
    and the fit's batches on one thread (one worker per core; :mod:`studio.blas`,
    :mod:`studio.threads`), freed image-sized blocks kept for reuse (a Dask nanny's malloc
    setting undone; :mod:`studio.allocator`)."""
    import cv2

    from studio.allocator import keep_large_blocks
    from studio.blas import limit_blas_threads
    from studio.threads import set_threads
    from studio.workers import die_with_parent as tie

    if die_with_parent:
        tie()
    set_threads(1)
    cv2.setNumThreads(1)
    limit_blas_threads()
    keep_large_blocks()


@dataclass
class Runner:
    """Submits units and waits for them; ``workers`` is how many run at once, ``where`` says
    where (for logs and summaries). Built by :func:`open_runner`."""

    workers: int
    where: str
    _submit: Callable
    _first_completed: Callable

    def submit(self, fn: Callable, *args) -> Any:
        """A future of ``fn(*args)`` (``result()`` returns its value or raises its exception)."""
        return self._submit(fn, *args)

    def first_completed(self, futures: Sequence) -> set:
        """Wait until at least one of ``futures`` is done; the done ones."""
        return self._first_completed(futures)


def _run_here(fn, *args) -> concurrent.futures.Future:
    fut = concurrent.futures.Future()
    try:
        fut.set_result(fn(*args))
    except Exception as exc:  # noqa: BLE001 - handed to the caller through the future, as a pool would
        fut.set_exception(exc)
    return fut


def _wait_local(futures) -> set:
    done, _ = concurrent.futures.wait(futures, return_when=concurrent.futures.FIRST_COMPLETED)
    return done


def _dask():
    try:
        import studio._dask as dask_side
    except ImportError:
        raise ExecutionError("--scheduler needs Dask: pip install 'silhouette-shadow-studio[dask]' "
                             "(or pip install 'dask[distributed]')") from None
    return dask_side


@contextlib.contextmanager
def shared_scheduler(scheduler: str | None) -> Iterator[str | None]:
    """For many runs in a row (a study): ``local:N`` becomes one ``LocalCluster`` started here and
    closed on exit (its ``tcp://`` address yielded); ``None`` and addresses are yielded as given."""
    parsed = parse_scheduler(scheduler)
    if parsed is None or parsed[0] == "address":
        yield scheduler
        return
    with _dask().local_cluster(parsed[1]) as address:
        yield address


@contextlib.contextmanager
def open_runner(workers: int = 1, scheduler: str | None = None, *, timeout: float = 30.0) -> Iterator[Runner]:
    """A :class:`Runner`: this process (``workers`` 1), ``workers`` local processes, or the Dask
    cluster at ``scheduler`` (``tcp://HOST:PORT`` or ``local:N``; see :func:`parse_scheduler`).
    Leaving the block by an exception (Ctrl-C) stops the local workers at once."""
    from studio.workers import worker_pool

    parsed = parse_scheduler(scheduler)
    if parsed is not None:
        with _dask().dask_runner(*parsed, timeout=timeout) as runner:
            yield runner
        return
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ExecutionError(f"workers: expected an integer >= 1, got {workers!r}")
    if workers == 1:
        yield Runner(1, "this process", _run_here, _wait_local)
        return
    with worker_pool(workers, worker_setup, (False,)) as pool:  # worker_pool ties them to us already
        yield Runner(workers, f"{workers} local processes", pool.submit, _wait_local)


def run_chains(runner: Runner, fn: Callable, chains: Sequence[Sequence], *, spec: Any,
               starts: Sequence | None = None, progress: Callable[[int, int], None] | None = None,
               done: int = 0, total: int | None = None) -> list[list]:
    """Run ``fn(spec, item, previous)`` for every item of every chain; returns the results by chain.

    ``previous`` is the result of the item before in the same chain (``starts[i]``, default
    None, for the first item of chain ``i``), so a chain's units run in order while chains run
    side by side. ``progress(done + units finished, total)`` after each unit. A unit's exception
    ends the run (the runner's context then stops the other workers).
    """
    starts = list(starts) if starts is not None else [None] * len(chains)
    total = done + sum(len(c) for c in chains) if total is None else total
    results: list[list] = [[] for _ in chains]
    pending = {}
    for i, chain in enumerate(chains):
        if chain:
            pending[runner.submit(fn, spec, chain[0], starts[i])] = i
    finished = done
    try:
        while pending:
            for fut in runner.first_completed(list(pending)):
                i = pending.pop(fut)
                value = fut.result()
                results[i].append(value)
                finished += 1
                if progress:
                    progress(finished, total)
                k = len(results[i])
                if k < len(chains[i]):
                    pending[runner.submit(fn, spec, chains[i][k], value)] = i
    except BaseException:
        for fut in pending:  # queued units are dropped; running local ones stop with their pool
            fut.cancel()
        raise
    return results
