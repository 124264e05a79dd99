"""``backend: simulated`` — a camera that plays a pre-rendered frame source live.

The source is a capture-session folder (typically rendered by ``studio simulate``); ``rigs``
never renders scenes itself. Camera ``camK`` plays the source's camera of the same name (or
``source_camera``). Trigger instant ``k`` (``k = 0, 1, ...`` at ``AcquisitionFrameRate``):

- device ``frame_id = k`` (a lost frame leaves a gap, as a GigE block id does);
- ``timestamp_ns = epoch_ns + round(k·1e9/fps) + clock_offset + N(0, jitter)``, one simulated
  clock shared by the rig (PTP-like); free-run (``TriggerMode=Off``) adds a random phase;
- image = source frame ``k mod n`` (``loop: true``) through exposure/gain scaling + clipping,
  ROI and pixel-format conversion;
- frames are lost with ``drop_probability`` or at the ids in ``drop_frames``, delivered twice
  with ``duplicate_probability`` or at ``duplicate_frames``.

Options (rig YAML camera keys or ``Rig.open`` overrides): ``source`` (session folder,
required), ``source_camera``, ``realtime`` (default true), ``loop`` (default true),
``max_frames``, ``jitter_ms``, ``clock_offset_ms``, ``drop_probability``, ``drop_frames``,
``duplicate_probability``, ``duplicate_frames``, ``reference_exposure`` (µs at which the
source is at scale 1, default 10000), ``queue_size`` (default 8), ``seed`` (default 0),
``preload`` (default true: decode the source into memory, up to 128 MB per camera, when the
camera opens, so real-time delivery never waits on a decode).
Random draws come from ``numpy.random.default_rng((seed, crc32(camera name)))``, so a rig is
reproducible camera by camera.
"""

from __future__ import annotations

import zlib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from rigs.backends._playback import PlaybackCamera, Scheduled
from rigs.backends._source import SessionSource
from rigs.device import RigError

__all__ = ["SimulatedCamera", "open_camera"]

_OPTIONS = {
    "source", "source_camera", "realtime", "loop", "max_frames", "jitter_ms", "clock_offset_ms",
    "drop_probability", "drop_frames", "duplicate_probability", "duplicate_frames",
    "reference_exposure", "queue_size", "seed", "epoch_ns", "preload",
}


def _check_options(camera: str, backend: str, options: dict[str, Any], known: set[str]) -> None:
    unknown = sorted(set(options) - known)
    if unknown:
        raise RigError(
            f"camera {camera!r}: unknown {backend} option {unknown[0]!r}; expected any of {sorted(known)}"
        )


def _probability(camera: str, key: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0.0 <= value <= 1.0:
        raise RigError(f"camera {camera!r}: option {key} must be a probability in [0, 1], got {value!r}")
    return float(value)


def _id_set(camera: str, key: str, value: Any) -> frozenset[int]:
    if value is None:
        return frozenset()
    try:
        return frozenset(int(v) for v in value)
    except (TypeError, ValueError):
        raise RigError(f"camera {camera!r}: option {key} must be a list of frame ids, got {value!r}") from None


class SimulatedCamera(PlaybackCamera):
    """A simulated camera; see the module docstring for the model."""

    backend = "simulated"

    def __init__(self, name: str, features: dict[str, Any], options: dict[str, Any], epoch_ns: int,
                 shared: dict | None = None):  # fmt: skip
        _check_options(name, "simulated", options, _OPTIONS)
        src = options.get("source")
        if src is None:
            raise RigError(f"camera {name!r}: simulated backend needs option 'source' (a session folder)")
        src = Path(src)
        if src.suffix in (".yaml", ".yml"):
            raise RigError(
                f"camera {name!r}: source {src} is a scene spec, not a rendered session; render it "
                "first (studio.simulate.ensure_rendered, which `studio capture` calls) and pass "
                "the folder as Rig.open(..., source=DIR)"
            )
        self.source = SessionSource(src, str(options.get("source_camera", name)), owner=name, shared=shared)
        self.loop = bool(options.get("loop", True))
        mf = options.get("max_frames")
        if mf is not None and (isinstance(mf, bool) or not isinstance(mf, int) or mf < 0):
            raise RigError(f"camera {name!r}: option max_frames must be a non-negative integer, got {mf!r}")
        self.max_frames = mf
        self.jitter_ns = float(options.get("jitter_ms", 0.0)) * 1e6
        if self.jitter_ns < 0:
            raise RigError(f"camera {name!r}: option jitter_ms must be >= 0, got {options.get('jitter_ms')!r}")
        self.clock_offset_ns = int(round(float(options.get("clock_offset_ms", 0.0)) * 1e6))
        self.p_drop = _probability(name, "drop_probability", options.get("drop_probability", 0.0))
        self.p_dup = _probability(name, "duplicate_probability", options.get("duplicate_probability", 0.0))
        self.drop_ids = _id_set(name, "drop_frames", options.get("drop_frames"))
        self.dup_ids = _id_set(name, "duplicate_frames", options.get("duplicate_frames"))
        self.seed = int(options.get("seed", 0))
        self.epoch_ns = int(options.get("epoch_ns", epoch_ns))
        if options.get("preload", True):
            self.source.preload()
        super().__init__(
            name,
            features,
            source_size=self.source.size,
            reference_exposure=float(options.get("reference_exposure", 10000.0)),
            realtime=bool(options.get("realtime", True)),
            queue_size=int(options.get("queue_size", 8)),
        )

    def _schedule(self) -> Iterator[Scheduled]:
        rng = np.random.default_rng((self.seed, zlib.crc32(self.name.encode())))
        n = len(self.source)
        fps = float(self._features["AcquisitionFrameRate"])
        period_ns = 1e9 / fps
        phase_ns = rng.uniform(0.0, period_ns) if self._features["TriggerMode"] == "Off" else 0.0
        k = 0
        while True:
            if self.max_frames is not None and k >= self.max_frames:
                return
            if not self.loop and k >= n:
                return
            u_drop, z_jit, u_dup = rng.random(), rng.standard_normal(), rng.random()
            fid = k
            k += 1
            if fid in self.drop_ids or u_drop < self.p_drop:
                continue
            ts = self.epoch_ns + self.clock_offset_ns + int(round(fid * period_ns + phase_ns + z_jit * self.jitter_ns))
            copies = 2 if (fid in self.dup_ids or u_dup < self.p_dup) else 1
            src_i = fid % n
            yield Scheduled(fid, ts, (fid * period_ns + phase_ns) / 1e9,
                            lambda i=src_i: self.source.image(i), copies)

    def background_frames(self, n: int) -> list[np.ndarray]:
        """The source's background frames (up to ``n``, cycled if fewer) as this camera delivers them."""
        bgs = self.source.backgrounds()
        if not bgs:
            raise RigError(f"camera {self.name!r}: source {self.source.path} has no background frames")
        return [self._pixels(bgs[i % len(bgs)]) for i in range(int(n))]

    @property
    def calibration_source(self) -> Path | None:
        return self.source.calibration_path


def open_camera(config, description, *, epoch_ns: int, shared: dict | None = None) -> SimulatedCamera:
    """Backend factory: a :class:`SimulatedCamera` for ``config`` (a :class:`rigs.description.CameraConfig`)."""
    features = config.features(description.frame_rate, description.trigger, description.sync.ptp)
    return SimulatedCamera(config.name, features, dict(config.options), epoch_ns, shared)
