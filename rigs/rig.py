"""A rig: the cameras of a description, started together, delivering synchronized multi-frames."""

from __future__ import annotations

import logging
import time
from collections import deque
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from rigs.backends import create_camera
from rigs.description import RigDescription
from rigs.device import CameraDevice, CameraStats, EndOfStream, FrameTimeout, RigError
from rigs.sync import MultiFrame, SyncGroup, SyncStats

__all__ = ["Rig", "RigStats"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class RigStats:
    """Per-camera delivery counters and the synchronisation counters of the current run."""

    cameras: dict[str, CameraStats]
    sync: SyncStats


def _as_description(description: RigDescription | str | Path | Mapping) -> RigDescription:
    if isinstance(description, RigDescription):
        return description
    if isinstance(description, (str, Path)):
        return RigDescription.load(description)
    if isinstance(description, Mapping):
        return RigDescription.from_dict(description)
    raise TypeError(
        f"Rig.open expects a RigDescription, a YAML path or a dict, got {type(description).__name__}"
    )


class Rig:
    """The cameras of a rig. Open with :meth:`open`; use as a context manager::

        with Rig.open("rigs/simulated.yaml", source=session_dir) as rig:
            for mf in rig.multiframes(100):
                ...

    Cameras are started in description order and stopped/closed in reverse order; closing
    always reaches every camera, and the first failure is re-raised afterwards.
    """

    def __init__(self, description: RigDescription, cameras: dict[str, CameraDevice]):
        self.description = description
        self.cameras = cameras
        self._sync: SyncGroup | None = None
        self._ready: deque[MultiFrame] = deque()
        self._ended: set[str] = set()
        self._last_ts: dict[str, int] = {}
        self._closed = False

    @classmethod
    def open(cls, description: RigDescription | str | Path | Mapping, **overrides: Any) -> Rig:
        """Open every camera of ``description`` (a :class:`RigDescription`, a YAML path or a
        dict); ``overrides`` go through :meth:`RigDescription.with_overrides` (e.g.
        ``source=DIR``, ``realtime=False``, ``frame_rate=30``)."""
        desc = _as_description(description)
        if overrides:
            desc = desc.with_overrides(**overrides)
        epoch_ns = time.time_ns()
        shared: dict = {}
        cameras: dict[str, CameraDevice] = {}
        try:
            for name, cfg in desc.cameras.items():
                cameras[name] = create_camera(cfg, desc, epoch_ns=epoch_ns, shared=shared)
        except BaseException:
            _close_all(list(cameras.values()))
            raise
        log.info("opened rig %s: %s", desc.name, ", ".join(f"{n} ({c.backend})" for n, c in cameras.items()))
        return cls(desc, cameras)

    # -- properties -----------------------------------------------------------------------
    @property
    def name(self) -> str:
        return self.description.name

    @property
    def camera_names(self) -> list[str]:
        return list(self.cameras)

    @property
    def calibration_path(self) -> Path | None:
        """The description's calibration file, else the one the cameras' source provides."""
        if self.description.calibration is not None:
            return self.description.calibration
        for cam in self.cameras.values():
            if cam.calibration_source is not None:
                return Path(cam.calibration_source)
        return None

    @property
    def is_streaming(self) -> bool:
        return any(c.is_streaming for c in self.cameras.values())

    @property
    def stats(self) -> RigStats:
        sync = self._sync.stats if self._sync is not None else _new_sync(self).stats
        return RigStats({n: c.stats for n, c in self.cameras.items()}, sync)

    # -- streaming ------------------------------------------------------------------------
    def start(self) -> None:
        """Start every camera (a failure stops those already started) and reset the sync."""
        self._check_open()
        if self.is_streaming:
            return
        self._sync = _new_sync(self)
        self._ready.clear()
        self._ended = set()
        self._last_ts = {}
        started: list[CameraDevice] = []
        try:
            for cam in self.cameras.values():
                cam.start()
                started.append(cam)
        except BaseException:
            for cam in reversed(started):
                try:
                    cam.stop()
                except Exception as exc:  # keep stopping the others
                    log.error("camera %s: stop failed: %s", cam.name, exc)
            raise

    def stop(self) -> None:
        """Stop every camera, in reverse order."""
        errors = []
        for cam in reversed(list(self.cameras.values())):
            try:
                cam.stop()
            except Exception as exc:
                errors.append(exc)
        if errors:
            raise errors[0]

    def close(self) -> None:
        """Stop and close every camera in reverse order (idempotent)."""
        if self._closed:
            return
        self._closed = True
        _close_all(list(self.cameras.values()))

    def __enter__(self) -> Rig:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _check_open(self) -> None:
        if self._closed:
            raise RigError(f"rig {self.name!r} is closed")

    def multiframes(self, n: int | None = None, timeout: float = 5.0) -> Iterator[MultiFrame]:
        """Yield up to ``n`` synchronized multi-frames (all if None), starting the rig if needed.

        Stops early when every camera's stream has ended (replay). Raises :class:`RigError`
        when no camera delivers anything for ``timeout`` seconds. Incomplete instants are
        counted in :attr:`stats` (``sync``), never yielded.
        """
        self._check_open()
        if n is not None and n < 0:
            raise ValueError(f"multiframes: n must be >= 0 or None, got {n}")
        if not self.is_streaming:
            self.start()
        sync = self._sync
        paced = all(c.consumer_paced for c in self.cameras.values())
        order = {name: i for i, name in enumerate(self.cameras)}
        count = 0
        last = time.monotonic()
        while n is None or count < n:
            if self._ready:
                yield self._ready.popleft()
                count += 1
                continue
            live = [name for name in self.cameras if name not in self._ended]
            if not live:
                self._ready.extend(sync.flush())
                if not self._ready:
                    return
                continue
            if paced:  # offline: always take the camera that is furthest behind (deterministic)
                name = min(live, key=lambda c: (self._last_ts.get(c, -1), order[c]))
                candidates, wait = [name], 0.05
            else:  # live: poll every camera, never let one stall the others
                candidates, wait = live, 0.0
            got = False
            for name in candidates:
                cam = self.cameras[name]
                try:
                    with cam.fetch(timeout=wait) as frame:
                        if cam.buffers_reused:
                            frame = _copy_frame(frame)
                        self._last_ts[name] = frame.timestamp_ns
                        self._ready.extend(sync.push(frame))
                    got = True
                except FrameTimeout:
                    continue
                except EndOfStream:
                    self._ended.add(name)
                    got = True
            now = time.monotonic()
            if got:
                last = now
            elif now - last > timeout:
                raise RigError(
                    f"rig {self.name!r}: no frame from any camera for {timeout:g} s "
                    f"(sync: {sync.stats.summary()})"
                )
            elif not paced:
                time.sleep(0.0005)

    def background_frames(self, n: int) -> dict[str, list[np.ndarray]] | None:
        """Each camera's stored background frames (simulated/replay sources), or None when
        any camera is live (then record the empty scene instead)."""
        out = {}
        for name, cam in self.cameras.items():
            frames = cam.background_frames(n)
            if frames is None:
                return None
            out[name] = frames
        return out

    def __repr__(self) -> str:
        return f"<Rig {self.name!r}: {', '.join(self.cameras)}>"


def _new_sync(rig: Rig) -> SyncGroup:
    s = rig.description.sync
    period = int(round(1e9 / rig.description.frame_rate))
    return SyncGroup(rig.camera_names, s.tolerance_ns, s.max_pending, key=s.key, period_ns=period)


def _copy_frame(frame):
    from dataclasses import replace

    return replace(frame, image=np.array(frame.image, copy=True))


def _close_all(cameras: list[CameraDevice]) -> None:
    errors = []
    for cam in reversed(cameras):
        try:
            cam.close()
        except Exception as exc:  # close the rest, then report
            log.error("camera %s: close failed: %s", cam.name, exc)
            errors.append(exc)
    if errors:
        raise errors[0]
