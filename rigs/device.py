"""The camera interface every backend implements, and the frame it delivers.

A backend (``simulated``, ``replay``, ``genicam`` through harvesters, ``aravis``)
subclasses :class:`CameraDevice` and fills in five hooks (``_apply``, ``_start``, ``_stop``,
``_next``, ``_close``). Features use GenICam standard names (SFNC) so that a GenTL camera's
node map can be driven with the same calls:

=======================  ==========================================  ================
feature                  meaning                                     type / unit
=======================  ==========================================  ================
``Width``, ``Height``    region of interest size                     int, pixels
``OffsetX``, ``OffsetY`` region of interest origin                   int, pixels
``PixelFormat``          ``RGB8``, ``Mono8``, ``RGB16``, ``Mono16``  str (GenICam backends:
                                                                     any PFNC name of
                                                                     :mod:`rigs.pixelformats`)
``ExposureTime``         exposure                                    float, µs
``Gain``                 analogue gain                               float, dB
``AcquisitionFrameRate`` frame (trigger) rate                        float, Hz
``TriggerMode``          ``On`` (triggered) / ``Off`` (free-run)      str
``TriggerSource``        ``Software``, ``Line0`` .. ``Line3``,        str
                         ``Action0``, ``Action1``
``TriggerSelector``      ``FrameStart``                              str
``GevIEEE1588``          PTP (IEEE 1588) clock synchronisation       bool
=======================  ==========================================  ================

Frames are leased, as harvesters' buffers are: ``with camera.fetch(timeout=1.0) as frame:``
returns the buffer to the driver when the block exits. Copy ``frame.image`` to keep it
beyond the block (the simulated and replay backends hand out fresh arrays; a backend that
lends driver memory sets ``buffers_reused``; the GenICam backends convert every buffer into a
fresh array and return the buffer at once).
"""

from __future__ import annotations

import abc
import contextlib
import logging
import queue
import threading
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = [
    "CameraDevice",
    "CameraStats",
    "EndOfStream",
    "FEATURES",
    "Frame",
    "FrameQueue",
    "FrameTimeout",
    "PIXEL_FORMATS",
    "RigError",
]

log = logging.getLogger(__name__)


class RigError(RuntimeError):
    """A rig, camera or recording failure; the message names the camera or file."""


class FrameTimeout(RigError, TimeoutError):
    """No frame arrived within the fetch timeout."""


class EndOfStream(RigError):
    """The camera's source is exhausted (a replayed session ended); no more frames will come."""


#: pixel format -> (channels, dtype)
PIXEL_FORMATS: dict[str, tuple[int, type]] = {
    "Mono8": (1, np.uint8),
    "Mono16": (1, np.uint16),
    "RGB8": (3, np.uint8),
    "RGB16": (3, np.uint16),
}

_TRIGGER_SOURCES = ("Software", "Line0", "Line1", "Line2", "Line3", "Action0", "Action1")

#: GenICam feature name -> (python type, allowed values or None)
FEATURES: dict[str, tuple[type, tuple | None]] = {
    "Width": (int, None),
    "Height": (int, None),
    "OffsetX": (int, None),
    "OffsetY": (int, None),
    "PixelFormat": (str, tuple(PIXEL_FORMATS)),
    "ExposureTime": (float, None),
    "Gain": (float, None),
    "AcquisitionFrameRate": (float, None),
    "TriggerMode": (str, ("On", "Off")),
    "TriggerSource": (str, _TRIGGER_SOURCES),
    "TriggerSelector": (str, ("FrameStart",)),
    "GevIEEE1588": (bool, None),
}

#: features a camera refuses to change while streaming (GenICam ``TLParamsLocked``)
LOCKED_WHILE_STREAMING = frozenset({"Width", "Height", "OffsetX", "OffsetY", "PixelFormat"})


@dataclass(frozen=True)
class Frame:
    """One image from one camera.

    ``image`` is ``(H, W, 3)`` RGB or ``(H, W)`` mono, uint8 or uint16; ``timestamp_ns`` is the
    device clock at exposure (PTP-synchronised across cameras when the rig uses PTP);
    ``frame_id`` the device's frame (block) counter, which skips a value when a frame is lost.
    """

    camera: str
    image: np.ndarray = field(repr=False, compare=False)
    timestamp_ns: int
    frame_id: int


@dataclass(frozen=True)
class CameraStats:
    """Delivery counters of one camera: ``delivered`` frames fetched, ``queue_dropped`` frames
    discarded because the bounded queue was full, ``queue_depth`` frames waiting now."""

    delivered: int
    queue_dropped: int
    queue_depth: int


class FrameQueue:
    """A bounded FIFO between a producer (driver thread) and the consumer that says when it drops.

    When full, :meth:`put` discards the *oldest* frame (as a GenTL ``OldestFirstOverwrite``
    buffer policy does) and counts it in :attr:`dropped`.
    """

    def __init__(self, maxsize: int):
        if int(maxsize) < 1:
            raise ValueError(f"FrameQueue maxsize must be >= 1, got {maxsize}")
        self._q: queue.Queue = queue.Queue(maxsize=int(maxsize))
        self._lock = threading.Lock()
        self.dropped = 0

    def put(self, item: Any) -> bool:
        """Enqueue ``item``; return False when an older item had to be dropped to make room."""
        with self._lock:
            dropped = False
            while True:
                try:
                    self._q.put_nowait(item)
                    return not dropped
                except queue.Full:
                    try:
                        self._q.get_nowait()
                        self.dropped += 1
                        dropped = True
                    except queue.Empty:  # pragma: no cover - consumer raced us
                        pass

    def put_wait(self, item: Any, timeout: float) -> bool:
        """Enqueue ``item`` waiting up to ``timeout`` s for room (never drops); False if still full."""
        try:
            self._q.put(item, timeout=timeout)
            return True
        except queue.Full:
            return False

    def get(self, timeout: float | None) -> Any:
        """Next item; raises :class:`queue.Empty` after ``timeout`` seconds (0 = poll)."""
        if timeout is not None and timeout <= 0:
            return self._q.get_nowait()
        return self._q.get(timeout=timeout)

    def clear(self) -> None:
        while True:
            try:
                self._q.get_nowait()
            except queue.Empty:
                return

    def __len__(self) -> int:
        return self._q.qsize()


def _coerce_feature(camera: str, name: str, value: Any, rules: dict | None = None) -> Any:
    rules = FEATURES if rules is None else rules
    if name not in rules:
        raise RigError(
            f"camera {camera!r}: unknown feature {name!r}; known GenICam features: "
            f"{', '.join(sorted(rules))}"
        )
    kind, allowed = rules[name]
    try:
        if kind is bool:
            if not isinstance(value, (bool, np.bool_)):
                raise TypeError
            coerced: Any = bool(value)
        elif kind is int:
            if isinstance(value, bool) or int(value) != value:
                raise TypeError
            coerced = int(value)
        elif kind is float:
            if isinstance(value, bool):
                raise TypeError
            coerced = float(value)
        else:
            if not isinstance(value, str):
                raise TypeError
            coerced = value
    except (TypeError, ValueError):
        raise RigError(
            f"camera {camera!r}: feature {name} expects {kind.__name__}, got {value!r}"
        ) from None
    if allowed is not None and coerced not in allowed:
        raise RigError(
            f"camera {camera!r}: feature {name}={coerced!r} not supported; expected one of "
            f"{', '.join(allowed)}"
        )
    if kind in (int, float) and name != "Gain" and coerced < 0:
        raise RigError(f"camera {camera!r}: feature {name} must be >= 0, got {coerced}")
    if name in ("Width", "Height", "AcquisitionFrameRate", "ExposureTime") and coerced <= 0:
        raise RigError(f"camera {camera!r}: feature {name} must be > 0, got {coerced}")
    return coerced


class CameraDevice(abc.ABC):
    """Common interface of a camera: configure, start/stop, leased frames, close.

    Subclasses implement ``_apply(features)`` (push validated features to the device; may
    raise :class:`RigError`), ``_start()``, ``_stop()``, ``_next(timeout) -> Frame`` (raise
    :class:`FrameTimeout` or :class:`EndOfStream`), optionally ``_release(frame)`` (return
    the buffer) and ``_close()``. The base class keeps the feature values, the streaming
    state and the counters, and guarantees ``stop`` before ``close``.
    """

    backend = "abstract"
    #: the features this backend takes: name -> (type, allowed values or None)
    feature_rules: dict[str, tuple[type, tuple | None]] = FEATURES
    #: True when a frame's image memory goes back to the driver at the end of the lease
    #: (GenTL buffers); consumers that keep frames must then copy them.
    buffers_reused = False

    @property
    def consumer_paced(self) -> bool:
        """True when frames wait for the consumer instead of being dropped (offline playback);
        the rig then merges streams deterministically in timestamp order."""
        return False

    def __init__(self, name: str, features: dict[str, Any] | None = None):
        self.name = str(name)
        self._features: dict[str, Any] = {
            "PixelFormat": "RGB8",
            "ExposureTime": 10000.0,
            "Gain": 0.0,
            "AcquisitionFrameRate": 30.0,
            "TriggerMode": "On",
            "TriggerSource": "Software",
            "TriggerSelector": "FrameStart",
            "GevIEEE1588": False,
            "OffsetX": 0,
            "OffsetY": 0,
        }
        self._streaming = False
        self._closed = False
        self._delivered = 0
        if features:
            self._features.update(
                {k: _coerce_feature(self.name, k, v, self.feature_rules) for k, v in features.items()
                 if v is not None}
            )

    # -- features ---------------------------------------------------------------------
    def configure(self, **features: Any) -> None:
        """Set GenICam features, e.g. ``configure(ExposureTime=8000.0, Gain=3.0)``.

        Raises :class:`RigError` naming the camera and the feature for an unknown name, a
        wrong type or value, or a size/format change while streaming.
        """
        self._check_open()
        coerced = {k: _coerce_feature(self.name, k, v, self.feature_rules) for k, v in features.items()}
        if self._streaming:
            locked = sorted(set(coerced) & LOCKED_WHILE_STREAMING)
            if locked:
                raise RigError(
                    f"camera {self.name!r}: {', '.join(locked)} cannot change while streaming; "
                    "stop() first"
                )
        merged = {**self._features, **coerced}
        self._apply(merged)
        self._features = merged

    def get(self, feature: str) -> Any:
        """Current value of a GenICam feature."""
        if feature not in self.feature_rules:
            raise RigError(f"camera {self.name!r}: unknown feature {feature!r}")
        if feature not in self._features:
            raise RigError(f"camera {self.name!r}: feature {feature} is not set yet")
        return self._features[feature]

    @property
    def features(self) -> dict[str, Any]:
        return dict(self._features)

    # -- streaming --------------------------------------------------------------------
    @property
    def is_streaming(self) -> bool:
        return self._streaming

    def start(self) -> None:
        """Start acquisition (idempotent)."""
        self._check_open()
        if not self._streaming:
            self._start()
            self._streaming = True

    def stop(self) -> None:
        """Stop acquisition (idempotent); frames still queued are discarded."""
        if self._streaming:
            self._streaming = False
            self._stop()

    @contextlib.contextmanager
    def fetch(self, timeout: float = 1.0) -> Iterator[Frame]:
        """Lease the next frame: ``with camera.fetch(timeout=1.0) as frame: ...``.

        Raises :class:`FrameTimeout` when nothing arrives within ``timeout`` seconds (0 polls),
        :class:`EndOfStream` when the source is exhausted, :class:`RigError` when not started.
        """
        self._check_open()
        if not self._streaming:
            raise RigError(f"camera {self.name!r}: fetch() before start()")
        frame = self._next(timeout)
        self._delivered += 1
        try:
            yield frame
        finally:
            self._release(frame)

    def background_frames(self, n: int) -> list[np.ndarray] | None:
        """Empty-scene frames the source already holds (simulated, replay), or None for a
        live camera, whose background is captured by recording with the scene cleared."""
        return None

    @property
    def calibration_source(self):
        """A calibration file the source provides (simulated/replay session), else None."""
        return None

    def device_stats(self) -> dict[str, Any]:
        """The driver's own counters (a GenTL/Aravis stream's completed buffers, failures,
        underruns, resent packets, ...) as a JSON-serialisable dict; empty for playback."""
        return {}

    @property
    def stats(self) -> CameraStats:
        return CameraStats(self._delivered, self._queue_dropped(), self._queue_depth())

    # -- lifetime ---------------------------------------------------------------------
    def close(self) -> None:
        """Stop and release the device (idempotent)."""
        if self._closed:
            return
        try:
            self.stop()
        finally:
            self._closed = True
            self._close()

    def __enter__(self) -> CameraDevice:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        state = "closed" if self._closed else ("streaming" if self._streaming else "idle")
        return f"<{type(self).__name__} {self.name!r} ({self.backend}, {state})>"

    def _check_open(self) -> None:
        if self._closed:
            raise RigError(f"camera {self.name!r} is closed")

    # -- hooks ------------------------------------------------------------------------
    def _apply(self, features: dict[str, Any]) -> None:  # pragma: no cover - trivial default
        pass

    @abc.abstractmethod
    def _start(self) -> None:
        """Begin acquisition (open streams, start producer threads)."""

    @abc.abstractmethod
    def _stop(self) -> None:
        """End acquisition and discard queued frames."""

    @abc.abstractmethod
    def _next(self, timeout: float) -> Frame:
        """The next frame, or :class:`FrameTimeout` / :class:`EndOfStream`."""

    def _release(self, frame: Frame) -> None:
        pass

    def _close(self) -> None:
        pass

    def _queue_dropped(self) -> int:
        return 0

    def _queue_depth(self) -> int:
        return 0
