"""A camera that delivers stored frames from a producer thread, as a live camera would.

:class:`PlaybackCamera` is the shared engine of the ``simulated`` and ``replay`` backends:
each camera runs one producer thread that walks a schedule of frames, optionally sleeping
to keep real time, processes the pixels for the configured features and puts the frames in
a bounded :class:`~rigs.device.FrameQueue`.

- ``realtime=True``: frames are due at their scheduled instants; when the consumer falls
  behind, the oldest queued frame is dropped and counted (``stats.queue_dropped``), as a
  GenTL buffer pool with ``OldestFirstOverwrite`` does.
- ``realtime=False``: as fast as possible; the producer waits for room instead of dropping,
  so the stream is deterministic (tests, offline replays).
"""

from __future__ import annotations

import abc
import logging
import queue
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from rigs.backends._pixels import convert_pixels, gain_scale
from rigs.device import CameraDevice, EndOfStream, Frame, FrameQueue, FrameTimeout, RigError

log = logging.getLogger(__name__)

_END = object()


@dataclass(frozen=True)
class Scheduled:
    """One frame of the schedule: device ``frame_id`` and ``timestamp_ns``, ``due_s`` seconds
    after start (real-time pacing), ``load()`` the stored image, ``copies`` how many times the
    transport delivers it (2 = a duplicate)."""

    frame_id: int
    timestamp_ns: int
    due_s: float
    load: Callable[[], np.ndarray]
    copies: int = 1


class PlaybackCamera(CameraDevice):
    """Base of cameras that play stored frames: subclasses implement :meth:`_schedule`."""

    def __init__(
        self,
        name: str,
        features: dict[str, Any],
        *,
        source_size: tuple[int, int],
        reference_exposure: float,
        realtime: bool,
        queue_size: int,
    ):
        self._source_size = (int(source_size[0]), int(source_size[1]))  # (width, height)
        self._reference_exposure = float(reference_exposure)
        self.realtime = bool(realtime)
        self._queue = FrameQueue(queue_size)
        self._stop_event = threading.Event()
        self._thread: threading.Thread | None = None
        self._ended = False
        self._error: BaseException | None = None
        w, h = self._source_size
        super().__init__(name, None)
        defaults = {"Width": w, "Height": h, "ExposureTime": self._reference_exposure}
        merged = {**defaults, **{k: v for k, v in (features or {}).items() if v is not None}}
        self.configure(**merged)

    @property
    def consumer_paced(self) -> bool:
        return not self.realtime

    # -- hooks for subclasses -----------------------------------------------------------
    @abc.abstractmethod
    def _schedule(self) -> Iterator[Scheduled]:
        """The frames to deliver, in order (may be endless)."""

    # -- CameraDevice hooks ---------------------------------------------------------------
    def _apply(self, f: dict[str, Any]) -> None:
        sw, sh = self._source_size
        x, y, w, h = f["OffsetX"], f["OffsetY"], f.get("Width", sw), f.get("Height", sh)
        if x + w > sw or y + h > sh:
            raise RigError(
                f"camera {self.name!r}: region {w}x{h}+{x}+{y} exceeds the source size {sw}x{sh}"
            )

    def _pixels(self, image: np.ndarray) -> np.ndarray:
        f = self._features  # the session reader guarantees every image has the source size
        scale = gain_scale(f["ExposureTime"], f["Gain"], self._reference_exposure)
        roi = (f["OffsetX"], f["OffsetY"], f["Width"], f["Height"])
        return convert_pixels(image, f["PixelFormat"], scale, roi)

    def _start(self) -> None:
        self._queue.clear()
        self._stop_event.clear()
        self._ended = False
        self._error = None
        self._thread = threading.Thread(
            target=self._produce, name=f"rigs-{self.backend}-{self.name}", daemon=True
        )
        self._thread.start()

    def _stop(self) -> None:
        self._stop_event.set()
        if self._thread is not None:
            self._thread.join(timeout=10.0)
            if self._thread.is_alive():  # pragma: no cover - a wedged source read
                log.warning("camera %s: producer thread did not stop within 10 s", self.name)
            self._thread = None
        self._queue.clear()

    def _next(self, timeout: float) -> Frame:
        if self._ended:
            raise EndOfStream(f"camera {self.name!r}: end of stream")
        try:
            item = self._queue.get(timeout)
        except queue.Empty:  # a producer failure arrives as the end marker, reported below
            raise FrameTimeout(f"camera {self.name!r}: no frame within {timeout:g} s") from None
        if item is _END:
            self._ended = True
            if self._error is not None:
                raise RigError(f"camera {self.name!r}: producer failed: {self._error}") from self._error
            raise EndOfStream(f"camera {self.name!r}: end of stream")
        return item

    def _queue_dropped(self) -> int:
        return self._queue.dropped

    def _queue_depth(self) -> int:
        return len(self._queue)

    # -- producer thread ----------------------------------------------------------------
    def _put(self, item: Any, block: bool) -> bool:
        if not block:
            self._queue.put(item)
            return True
        while not self._stop_event.is_set():
            if self._queue.put_wait(item, timeout=0.05):
                return True
        return False

    def _produce(self) -> None:
        t0 = time.monotonic()
        try:
            for ev in self._schedule():
                if self._stop_event.is_set():
                    return
                if self.realtime:
                    delay = t0 + ev.due_s - time.monotonic()
                    if delay > 0 and self._stop_event.wait(delay):
                        return
                frame = Frame(self.name, self._pixels(ev.load()), int(ev.timestamp_ns), int(ev.frame_id))
                for _ in range(ev.copies):
                    if not self._put(frame, block=not self.realtime):
                        return
        except Exception as exc:  # reported to the consumer by _next, never swallowed
            log.error("camera %s: producer failed: %s", self.name, exc)
            self._error = exc
        self._put(_END, block=True)
