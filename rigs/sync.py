"""Group per-camera frame streams into multi-frames of one trigger instant.

Matching rule. Frames are keyed by the instant they belong to — the device frame id (a
hardware-triggered rig's cameras count the same triggers), or, with ``key="timestamp"``,
the timestamp rounded to the frame period (free-running PTP-synchronised cameras whose
counters differ). A key's frames form a multi-frame only if their device timestamps span at
most ``tolerance_ns``; frames too far from the group's median are rejected (``mismatched``).
So an emitted multi-frame never mixes instants.

A key is *finalized* once every camera has either delivered its frame for it or delivered a
frame of a later key (each camera's stream is in order, so the missing frame is lost), or
when more than ``max_pending`` keys wait. Finalized keys are handled in order: complete →
emitted as :class:`MultiFrame` with consecutive ``index``; otherwise counted ``incomplete``
and each missing camera's ``dropped`` incremented. Keys nobody delivered (a gap in the key
sequence) count as dropped for every camera. A frame arriving for a finalized key is
``duplicates`` if that camera already delivered that key, else ``late``.
"""

from __future__ import annotations

import logging
from collections import deque
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

import numpy as np

from rigs.device import Frame, RigError

__all__ = ["MultiFrame", "SyncGroup", "SyncStats"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class MultiFrame:
    """The frames of every camera at one trigger instant; ``index`` counts emitted multi-frames."""

    index: int
    frames: dict[str, Frame] = field(compare=False)

    @property
    def cameras(self) -> list[str]:
        return list(self.frames)

    @property
    def images(self) -> dict[str, np.ndarray]:
        return {c: f.image for c, f in self.frames.items()}

    @property
    def timestamps_ns(self) -> dict[str, int]:
        return {c: f.timestamp_ns for c, f in self.frames.items()}

    @property
    def frame_ids(self) -> dict[str, int]:
        return {c: f.frame_id for c, f in self.frames.items()}

    @property
    def spread_ns(self) -> int:
        """Largest minus smallest device timestamp (the sync error of this instant)."""
        ts = [f.timestamp_ns for f in self.frames.values()]
        return int(max(ts) - min(ts))


@dataclass(frozen=True)
class SyncStats:
    """Counters of a :class:`SyncGroup` (per-camera dicts map camera name -> count)."""

    emitted: int
    incomplete: int
    dropped: dict[str, int]
    late: dict[str, int]
    duplicates: dict[str, int]
    mismatched: dict[str, int]
    pending: int = 0

    @property
    def total_dropped(self) -> int:
        return sum(self.dropped.values())

    def summary(self) -> str:
        parts = [f"emitted {self.emitted}", f"incomplete {self.incomplete}"]
        for label, counts in (
            ("dropped", self.dropped),
            ("late", self.late),
            ("duplicates", self.duplicates),
            ("mismatched", self.mismatched),
        ):
            nonzero = {c: n for c, n in counts.items() if n}
            if nonzero:
                parts.append(f"{label} " + ", ".join(f"{c}:{n}" for c, n in nonzero.items()))
        return "; ".join(parts)


class SyncGroup:
    """Turn per-camera :class:`Frame` streams into complete :class:`MultiFrame` s.

    Parameters
    ----------
    cameras : camera names; every emitted multi-frame holds exactly these.
    tolerance_ns : largest allowed spread of device timestamps within one instant
        (None: do not check timestamps).
    max_pending : keys kept open at most; the oldest is finalized beyond this.
    key : ``"frame_id"`` (default) or ``"timestamp"`` (needs ``period_ns``).
    period_ns : frame period for ``key="timestamp"``.
    """

    def __init__(
        self,
        cameras: Iterable[str],
        tolerance_ns: int | None,
        max_pending: int = 16,
        *,
        key: str = "frame_id",
        period_ns: int | None = None,
    ):
        self.cameras = tuple(cameras)
        if not self.cameras:
            raise ValueError("SyncGroup needs at least one camera")
        if len(set(self.cameras)) != len(self.cameras):
            raise ValueError(f"SyncGroup camera names must be unique, got {list(self.cameras)}")
        if tolerance_ns is not None and tolerance_ns < 0:
            raise ValueError(f"SyncGroup tolerance_ns must be >= 0 or None, got {tolerance_ns}")
        if int(max_pending) < 1:
            raise ValueError(f"SyncGroup max_pending must be >= 1, got {max_pending}")
        if key not in ("frame_id", "timestamp"):
            raise ValueError(f"SyncGroup key must be 'frame_id' or 'timestamp', got {key!r}")
        if key == "timestamp" and (period_ns is None or period_ns <= 0):
            raise ValueError("SyncGroup key='timestamp' needs period_ns > 0 (the frame period)")
        self.tolerance_ns = None if tolerance_ns is None else int(tolerance_ns)
        self.max_pending = int(max_pending)
        self.key = key
        self.period_ns = None if period_ns is None else int(period_ns)
        self._t0: int | None = None
        self._pending: dict[int, dict[str, Frame]] = {}
        self._last_key: dict[str, int | None] = dict.fromkeys(self.cameras)
        self._horizon: int | None = None  # every key < horizon is finalized
        window = max(4 * self.max_pending, 256)
        self._recent: dict[str, deque] = {c: deque(maxlen=window) for c in self.cameras}
        self._emitted = 0
        self._incomplete = 0
        self._dropped = dict.fromkeys(self.cameras, 0)
        self._late = dict.fromkeys(self.cameras, 0)
        self._duplicates = dict.fromkeys(self.cameras, 0)
        self._mismatched = dict.fromkeys(self.cameras, 0)

    # ------------------------------------------------------------------------------
    def _key(self, frame: Frame) -> int:
        if self.key == "frame_id":
            return int(frame.frame_id)
        if self._t0 is None:
            self._t0 = int(frame.timestamp_ns)
        return int(round((int(frame.timestamp_ns) - self._t0) / self.period_ns))

    def push(self, frame: Frame) -> list[MultiFrame]:
        """Add one frame; return the multi-frames it completes (in order, possibly none)."""
        cam = frame.camera
        if cam not in self._last_key:
            raise RigError(
                f"SyncGroup: frame from unknown camera {cam!r}; expected one of {list(self.cameras)}"
            )
        k = self._key(frame)
        if self._horizon is not None and k < self._horizon:
            if k in self._recent[cam]:
                self._duplicates[cam] += 1
            else:
                self._late[cam] += 1
            return []
        group = self._pending.setdefault(k, {})
        if cam in group:
            self._duplicates[cam] += 1
            return []
        group[cam] = frame
        last = self._last_key[cam]
        self._last_key[cam] = k if last is None else max(last, k)
        return self._drain(force=False)

    def flush(self) -> list[MultiFrame]:
        """Finalize every pending key (end of stream); return the complete ones."""
        return self._drain(force=True)

    @property
    def stats(self) -> SyncStats:
        return SyncStats(
            emitted=self._emitted,
            incomplete=self._incomplete,
            dropped=dict(self._dropped),
            late=dict(self._late),
            duplicates=dict(self._duplicates),
            mismatched=dict(self._mismatched),
            pending=len(self._pending),
        )

    # ------------------------------------------------------------------------------
    def _ready(self, k: int, group: Mapping[str, Frame]) -> bool:
        for cam in self.cameras:
            if cam in group:
                continue
            last = self._last_key[cam]
            if last is None or last <= k:
                return False
        return True

    def _drain(self, force: bool) -> list[MultiFrame]:
        out: list[MultiFrame] = []
        while self._pending:
            k = min(self._pending)
            group = self._pending[k]
            if not (force or len(self._pending) > self.max_pending or self._ready(k, group)):
                break
            mf = self._finalize(k)
            if mf is not None:
                out.append(mf)
        return out

    def _finalize(self, k: int) -> MultiFrame | None:
        group = self._pending.pop(k)
        if self._horizon is not None and k > self._horizon:
            gap = k - self._horizon  # keys nobody delivered
            self._incomplete += gap
            for cam in self.cameras:
                self._dropped[cam] += gap
        self._horizon = k + 1
        for cam in group:
            self._recent[cam].append(k)
        accepted = self._consistent(group)
        for cam in group:
            if cam not in accepted:
                self._mismatched[cam] += 1
        if len(accepted) == len(self.cameras):
            mf = MultiFrame(self._emitted, {c: accepted[c] for c in self.cameras})
            self._emitted += 1
            return mf
        self._incomplete += 1
        for cam in self.cameras:
            if cam not in group:
                self._dropped[cam] += 1
        log.debug("instant %d incomplete: have %s", k, sorted(accepted))
        return None

    def _consistent(self, group: dict[str, Frame]) -> dict[str, Frame]:
        """Drop the frames farthest from the median timestamp until the spread fits."""
        if self.tolerance_ns is None or len(group) < 2:
            return dict(group)
        kept = dict(group)
        while len(kept) > 1:
            ts = {c: f.timestamp_ns for c, f in kept.items()}
            if max(ts.values()) - min(ts.values()) <= self.tolerance_ns:
                break
            med = float(np.median(list(ts.values())))
            worst = max(ts, key=lambda c: (abs(ts[c] - med), c))
            del kept[worst]
        return kept
