"""SyncGroup at its documented boundaries, with hand-counted outcomes.

"A key's frames form a multi-frame only if their device timestamps span *at most*
``tolerance_ns``"; "``max_pending``: keys kept open *at most*"; frames farthest from the
median go first (ties: the later camera name); a gap of ``g`` keys is ``g`` incomplete instants.
"""

from __future__ import annotations

import numpy as np

from rigs import Frame, SyncGroup

PERIOD = 10_000_000
TOL = 2_000_000


def frame(cam: str, k: int, dt: int = 0, frame_id: int | None = None) -> Frame:
    return Frame(cam, np.zeros((1, 1), np.uint8), k * PERIOD + dt, k if frame_id is None else frame_id)


def test_spread_of_exactly_the_tolerance_is_one_instant():
    sync = SyncGroup(("a", "b"), TOL)
    sync.push(frame("a", 0))
    (mf,) = sync.push(frame("b", 0, dt=TOL))
    assert mf.spread_ns == TOL
    sync.push(frame("a", 1))
    assert sync.push(frame("b", 1, dt=TOL + 1)) == []  # one nanosecond more: not one instant
    s = sync.stats
    assert (s.emitted, s.incomplete) == (1, 1)
    # two frames: both equally far from their median; the later name ("b") is dropped
    assert s.mismatched == {"a": 0, "b": 1} and s.dropped == {"a": 0, "b": 0}


def test_the_frame_farthest_from_the_median_is_dropped_first():
    sync = SyncGroup(("a", "b", "c"), 3_000_000)
    sync.push(frame("a", 0, dt=-2_000_000))
    sync.push(frame("b", 0))
    assert sync.push(frame("c", 0, dt=2_000_000)) == []  # spread 4 ms > 3 ms; a and c tie: c goes
    assert sync.stats.mismatched == {"a": 0, "b": 0, "c": 1}
    sync.push(frame("a", 1, dt=100))
    sync.push(frame("b", 1, dt=-100))
    assert sync.push(frame("c", 1, dt=5_000_000)) == []  # c is far: a and b stay
    sync.push(frame("a", 2))
    sync.push(frame("b", 2, dt=1_000_000))
    (mf,) = sync.push(frame("c", 2, dt=3_000_000))  # spread exactly 3 ms: one instant
    assert mf.index == 0 and mf.spread_ns == 3_000_000
    assert sync.stats.mismatched == {"a": 0, "b": 0, "c": 2}
    assert sync.stats.incomplete == 2


def test_max_pending_keys_stay_open_and_no_more():
    sync = SyncGroup(("a", "b"), TOL, max_pending=3)
    for k in range(8):
        assert sync.push(frame("a", k)) == []
        s = sync.stats
        assert s.pending == min(k + 1, 3)
        assert s.incomplete == max(0, k + 1 - 3) == s.dropped["b"]
        assert s.dropped["a"] == 0
    assert sync.flush() == [] and sync.stats.pending == 0 and sync.stats.incomplete == 8


def test_a_gap_of_keys_counts_each_missing_instant_once():
    sync = SyncGroup(("a", "b"), TOL)
    for k in (0, 3):  # keys 1 and 2 never arrive from anyone
        sync.push(frame("a", k))
        sync.push(frame("b", k))
    s = sync.stats
    assert (s.emitted, s.incomplete, s.dropped) == (2, 2, {"a": 2, "b": 2})
    # a frame of a finalized key: a duplicate if that camera delivered it, else late
    sync.push(frame("a", 3))
    sync.push(frame("b", 1))
    s = sync.stats
    assert s.duplicates == {"a": 1, "b": 0} and s.late == {"a": 0, "b": 1}
    assert s.summary() == "emitted 2; incomplete 2; dropped a:2, b:2; late b:1; duplicates a:1"


def test_timestamp_key_rounds_to_the_nearest_period():
    sync = SyncGroup(("a", "b"), None, key="timestamp", period_ns=PERIOD)
    sync.push(frame("a", 0, frame_id=100))
    (mf,) = sync.push(frame("b", 0, dt=PERIOD // 2 - 1, frame_id=7))  # just under half a period: same key
    assert mf.frame_ids == {"a": 100, "b": 7}
    sync.push(frame("a", 2, frame_id=102))
    sync.push(frame("b", 2, dt=-(PERIOD // 2 - 1), frame_id=9))
    assert sync.stats.emitted == 2 and sync.stats.incomplete == 1  # key 1 in between: nobody
