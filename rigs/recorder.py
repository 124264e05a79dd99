"""Record multi-frames to a capture session through a bounded queue and a writer thread.

The acquisition loop calls :meth:`Recorder.submit`; one writer thread calls the session
writer (:class:`rigs.session.SessionWriter`, which is not thread-safe, so only that thread
touches it). Back-pressure — the disk slower than the cameras — is explicit, by ``policy``:

- ``"block"`` (default): ``submit`` waits for room; the waiting time is ``blocked_time``;
- ``"raise"``: ``submit`` raises :class:`RigError` when the queue is full;
- ``"drop"``: the multi-frame is discarded and counted in ``dropped`` (its index becomes a
  gap the session reader reports).

A failure of the writer thread (disk full: ``OSError`` with ``errno.ENOSPC``, directly or as
the cause of a ``SessionError``) stops the recording: it is re-raised as :class:`RigError`
from the next :meth:`submit` or from :meth:`close`, never swallowed. Frames written before
it stay readable (the session writer lists a frame only once all its images are on disk).
"""

from __future__ import annotations

import errno
import logging
import queue
import threading
import time
from dataclasses import dataclass

from rigs.device import RigError
from rigs.sync import MultiFrame

__all__ = ["Recorder", "RecorderStats"]

log = logging.getLogger(__name__)

_STOP = object()
POLICIES = ("block", "raise", "drop")


@dataclass(frozen=True)
class RecorderStats:
    """Counters of a :class:`Recorder`; times in seconds."""

    submitted: int
    written: int
    dropped: int
    queue_depth: int
    max_queue_depth: int
    queue_size: int
    blocked_time: float
    write_time: float
    errors: tuple[str, ...]


def _is_disk_full(exc: BaseException) -> bool:
    seen = set()
    while exc is not None and id(exc) not in seen:
        seen.add(id(exc))
        if isinstance(exc, OSError) and exc.errno == errno.ENOSPC:
            return True
        exc = exc.__cause__ or exc.__context__
    return False


class Recorder:
    """Write submitted :class:`MultiFrame` s as frames ``start_index, start_index + 1, ...``.

    Parameters
    ----------
    writer : a session writer (``write_frame(index, images, timestamps_ns=, frame_ids=, flags=)``
        and ``close(status)``).
    queue_size : multi-frames waiting at most (memory: ``queue_size`` × cameras × image size).
    policy : ``"block"``, ``"raise"`` or ``"drop"`` (module docstring).
    close_writer : close the writer in :meth:`close` (status ``"complete"``, or ``"aborted"``
        after an error).
    """

    def __init__(self, writer, queue_size: int = 64, *, policy: str = "block", start_index: int = 0,
                 close_writer: bool = True):  # fmt: skip
        if isinstance(queue_size, bool) or not isinstance(queue_size, int) or queue_size < 1:
            raise ValueError(f"Recorder queue_size must be a positive integer, got {queue_size!r}")
        if policy not in POLICIES:
            raise ValueError(f"Recorder policy must be one of {POLICIES}, got {policy!r}")
        self.writer = writer
        self.queue_size = queue_size
        self.policy = policy
        self.close_writer = close_writer
        self._queue: queue.Queue = queue.Queue(maxsize=queue_size)
        self._next_index = int(start_index)
        self._submitted = 0
        self._written = 0
        self._dropped = 0
        self._max_depth = 0
        self._blocked = 0.0
        self._write_time = 0.0
        self._error: BaseException | None = None
        self._error_index: int | None = None
        self._closed = False
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._run, name="rigs-recorder", daemon=True)
        self._thread.start()

    # -- producer side --------------------------------------------------------------------
    def submit(self, multiframe: MultiFrame) -> bool:
        """Queue ``multiframe`` for writing; returns False when dropped (``policy="drop"``).

        Raises :class:`RigError` when the writer thread failed (e.g. disk full), when the
        queue is full with ``policy="raise"``, or after :meth:`close`.
        """
        if self._closed:
            raise RigError("Recorder: submit() after close()")
        self._raise_if_failed()
        index = self._next_index
        self._next_index += 1
        self._submitted += 1
        item = (index, multiframe)
        try:
            self._queue.put_nowait(item)
        except queue.Full:
            if self.policy == "drop":
                self._dropped += 1
                log.warning("recorder queue full (%d): dropped frame %d", self.queue_size, index)
                return False
            if self.policy == "raise":
                self._next_index -= 1
                self._submitted -= 1
                raise RigError(
                    f"Recorder: queue full ({self.queue_size} multi-frames waiting): the disk "
                    f"cannot keep up with the cameras (writing {self._path()})"
                ) from None
            t0 = time.monotonic()
            while True:
                try:
                    self._queue.put(item, timeout=0.05)
                    break
                except queue.Full:
                    self._raise_if_failed()
            self._blocked += time.monotonic() - t0
        self._max_depth = max(self._max_depth, self._queue.qsize())
        return True

    @property
    def stats(self) -> RecorderStats:
        errors = () if self._error is None else (self._message(),)
        return RecorderStats(
            submitted=self._submitted,
            written=self._written,
            dropped=self._dropped,
            queue_depth=self._queue.qsize(),
            max_queue_depth=self._max_depth,
            queue_size=self.queue_size,
            blocked_time=self._blocked,
            write_time=self._write_time,
            errors=errors,
        )

    @property
    def failed(self) -> bool:
        return self._error is not None

    def close(self, status: str | None = None) -> None:
        """Write what is queued, stop the thread, close the writer; re-raise a writer failure.

        ``status`` (``"complete"``/``"aborted"``) overrides the status given to the writer.
        """
        if self._closed:
            return
        self._closed = True
        while self._thread.is_alive():
            try:
                self._queue.put(_STOP, timeout=0.05)
                break
            except queue.Full:
                continue
        self._thread.join()
        if self.close_writer:
            final = status or ("aborted" if self._error is not None else "complete")
            try:
                self.writer.close(final)
            except Exception as exc:
                if self._error is None:
                    raise RigError(f"Recorder: closing {self._path()} failed: {exc}") from exc
                log.error("closing %s after a failure: %s", self._path(), exc)
        self._raise_if_failed()

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
            return
        try:
            self.close("aborted")
        except RigError as close_exc:  # the original exception propagates
            log.error("%s", close_exc)

    # -- writer thread --------------------------------------------------------------------
    def _run(self) -> None:
        while True:
            item = self._queue.get()
            if item is _STOP:
                return
            if self._error is not None:
                continue  # failed: drain so a blocked submit wakes up and sees the error
            index, mf = item
            t0 = time.monotonic()
            try:
                self.writer.write_frame(index, mf.images, timestamps_ns=mf.timestamps_ns,
                                        frame_ids=mf.frame_ids)  # fmt: skip
            except BaseException as exc:
                self._error = exc
                self._error_index = index
                log.error("recorder: %s", self._message())
                continue
            self._write_time += time.monotonic() - t0
            self._written += 1

    def _path(self) -> str:
        return str(getattr(self.writer, "path", "the session"))

    def _message(self) -> str:
        exc = self._error
        what = f"disk full (ENOSPC): {exc}" if _is_disk_full(exc) else f"{type(exc).__name__}: {exc}"
        return (
            f"recording to {self._path()} stopped: {what} while writing frame {self._error_index}; "
            f"the {self._written} frames written before are readable"
        )

    def _raise_if_failed(self) -> None:
        if self._error is not None:
            raise RigError(self._message()) from self._error
