"""``backend: replay`` — a recorded capture session played back as a rig.

Camera ``camK`` plays the session's camera of the same name (or ``source_camera``) with the
recorded device timestamps and frame ids, and the recorded images bit for bit (exposure and
gain are at scale 1 unless changed after opening). Frames the recording lost stay lost: the
frame-id gaps reach the :class:`~rigs.SyncGroup` as they did live. With ``realtime: true``
frames are paced by the recorded timestamps; ``loop: true`` restarts at the end with frame
ids and timestamps shifted past the recording, else the stream ends (:class:`EndOfStream`).

Options: ``session`` (folder, required), ``source_camera``, ``realtime`` (default true),
``loop`` (default false), ``queue_size`` (default 8).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from rigs.backends._playback import PlaybackCamera, Scheduled
from rigs.backends._source import SessionSource
from rigs.backends.simulated import _check_options
from rigs.device import RigError

__all__ = ["ReplayCamera", "open_camera"]

_OPTIONS = {"session", "source_camera", "realtime", "loop", "queue_size"}


class ReplayCamera(PlaybackCamera):
    """A camera replaying one camera of a recorded session."""

    backend = "replay"

    def __init__(self, name: str, features: dict[str, Any], options: dict[str, Any],
                 shared: dict | None = None):  # fmt: skip
        _check_options(name, "replay", options, _OPTIONS)
        session = options.get("session")
        if session is None:
            raise RigError(f"camera {name!r}: replay backend needs option 'session' (a session folder)")
        self.source = SessionSource(Path(session), str(options.get("source_camera", name)),
                                    owner=name, shared=shared)  # fmt: skip
        self.loop = bool(options.get("loop", False))
        fps = self.source.session.fps
        features = dict(features)
        if fps:  # the recording's rate wins over the description's
            features["AcquisitionFrameRate"] = float(fps)
        images = self.source.session.info.get("images", {}).get(self.source.camera, {})
        recorded = _recorded_format(images)
        if recorded is not None:  # deliver what was recorded, bit for bit
            features["PixelFormat"] = recorded
        super().__init__(
            name,
            features,
            source_size=self.source.size,
            reference_exposure=float(features.get("ExposureTime") or 10000.0),
            realtime=bool(options.get("realtime", True)),
            queue_size=int(options.get("queue_size", 8)),
        )

    def _schedule(self) -> Iterator[Scheduled]:
        n = len(self.source)
        metas = [self.source.meta(p) for p in range(n)]
        fps = float(self._features["AcquisitionFrameRate"])
        ts0 = next((t for t, _ in metas if t is not None), 0)
        ids = [fid if fid is not None else p for p, (_, fid) in enumerate(metas)]
        tss = [t if t is not None else ts0 + int(round(p * 1e9 / fps)) for p, (t, _) in enumerate(metas)]
        id_span = max(ids) - min(ids) + 1
        ts_span = max(tss) - min(tss) + int(round(1e9 / fps))
        cycle = 0
        while True:
            for p in range(n):
                ts = tss[p] + cycle * ts_span
                yield Scheduled(ids[p] + cycle * id_span, ts, (ts - ts0) / 1e9,
                                lambda i=p: self.source.image(i))  # fmt: skip
            if not self.loop:
                return
            cycle += 1

    def background_frames(self, n: int) -> list[np.ndarray]:
        """The recorded background frames (up to ``n``, cycled if fewer)."""
        bgs = self.source.backgrounds()
        if not bgs:
            raise RigError(f"camera {self.name!r}: session {self.source.path} has no background frames")
        return [self._pixels(bgs[i % len(bgs)]) for i in range(int(n))]

    @property
    def calibration_source(self) -> Path | None:
        return self.source.calibration_path


def _recorded_format(spec: dict) -> str | None:
    """The delivered pixel format implied by a session's image spec."""
    ch, dt = spec.get("channels"), spec.get("dtype")
    table = {(3, "uint8"): "RGB8", (1, "uint8"): "Mono8", (3, "uint16"): "RGB16", (1, "uint16"): "Mono16"}
    return table.get((ch, dt))


def open_camera(config, description, *, epoch_ns: int, shared: dict | None = None) -> ReplayCamera:
    """Backend factory: a :class:`ReplayCamera` for ``config``."""
    features = config.features(description.frame_rate, description.trigger, description.sync.ptp)
    return ReplayCamera(config.name, features, dict(config.options), shared)
