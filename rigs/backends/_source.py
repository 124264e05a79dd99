"""One camera's view of a stored capture session, as read by the playback backends."""

from __future__ import annotations

import threading
from collections import OrderedDict
from pathlib import Path

import numpy as np

from rigs.device import RigError
from rigs.session import Session, SessionError

__all__ = ["SessionSource", "open_session"]


def open_session(path: Path, owner: str, shared: dict | None = None) -> Session:
    """Open ``path`` once per rig (``shared`` caches the :class:`Session` by folder)."""
    key = ("session", str(Path(path).resolve()))
    if shared is not None and key in shared:
        return shared[key]
    try:
        session = Session.open(path)
    except SessionError as exc:
        raise RigError(f"camera {owner!r}: cannot open source session: {exc}") from exc
    if shared is not None:
        shared[key] = session
    return session


class SessionSource:
    """Frames of camera ``camera`` of a session, decoded on demand and cached (read-only
    arrays) up to ``cache_bytes``, so a short looping source is decoded once."""

    def __init__(self, path: str | Path, camera: str, owner: str, *, shared: dict | None = None,
                 cache_bytes: int = 128 << 20):  # fmt: skip
        self.path = Path(path)
        self.session = open_session(self.path, owner, shared)
        if camera not in self.session.cameras:
            raise RigError(
                f"camera {owner!r}: source session {self.path} has no camera {camera!r} "
                f"(it has {self.session.cameras}); set option source_camera"
            )
        self.camera = camera
        self.owner = owner
        self.indices = list(self.session.frame_indices)
        if not self.indices:
            raise RigError(f"camera {owner!r}: source session {self.path} has no complete frames")
        self.size = self.session.image_size(camera)  # (width, height); listed frames exist
        self._cache: OrderedDict[int, np.ndarray] = OrderedDict()
        self._cache_bytes = int(cache_bytes)
        self._held = 0
        self._lock = threading.Lock()

    def __len__(self) -> int:
        return len(self.indices)

    def image(self, position: int) -> np.ndarray:
        """Image at ``position`` (0-based in frame-index order); read-only array."""
        index = self.indices[position]
        with self._lock:
            hit = self._cache.get(index)
            if hit is not None:
                self._cache.move_to_end(index)
                return hit
        try:
            image = self.session.image(self.camera, index)
        except SessionError as exc:
            raise RigError(f"camera {self.owner!r}: {exc}") from exc
        image.setflags(write=False)
        with self._lock:
            if image.nbytes <= self._cache_bytes:
                self._cache[index] = image
                self._held += image.nbytes
                while self._held > self._cache_bytes:
                    _, old = self._cache.popitem(last=False)
                    self._held -= old.nbytes
        return image

    def preload(self) -> int:
        """Decode frames in order until the cache is full (so real-time delivery never waits
        on a PNG decode); returns how many are cached."""
        for p in range(len(self.indices)):
            image = self.image(p)
            if self._held + image.nbytes > self._cache_bytes:
                break
        return len(self._cache)

    def meta(self, position: int) -> tuple[int | None, int | None]:
        """Recorded ``(timestamp_ns, frame_id)`` of the frame at ``position``."""
        m = self.session.frame_meta(self.indices[position])
        return m["timestamps_ns"].get(self.camera), m["frame_ids"].get(self.camera)

    def backgrounds(self) -> list[np.ndarray]:
        try:
            return self.session.backgrounds(self.camera)
        except SessionError as exc:
            raise RigError(f"camera {self.owner!r}: {exc}") from exc

    @property
    def calibration_path(self) -> Path | None:
        return self.session.calibration_path
