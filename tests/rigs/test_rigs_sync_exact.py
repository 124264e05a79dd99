"""SyncGroup at its documented boundaries, with hand-counted outcomes.

"A key's frames form a multi-frame only if their device timestamps span *at most*
``tolerance_ns``"; "``max_pending``: keys kept open *at most*"; frames farthest from the
median go first (ties: the later camera name); a gap of ``g`` keys is ``g`` incomplete instants.
"""

from __future__ import annotations

import numpy as np
import pytest

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


def test_a_camera_past_a_key_finalizes_it_and_the_early_outlier_goes():
    """Key 0 is final as soon as every camera missing from it has delivered a later key; with the
    instants far from t = 0 the frame farthest from the median is the early one."""
    sync = SyncGroup(("a", "b"), TOL)
    sync.push(frame("a", 0))
    assert sync.push(frame("a", 1)) == []
    (mf,) = sync.push(frame("b", 1))  # b skipped key 0: it is incomplete, key 1 complete
    assert mf.index == 0 and mf.frame_ids == {"a": 1, "b": 1}
    assert sync.stats.incomplete == 1 and sync.stats.dropped == {"a": 0, "b": 1}
    sync = SyncGroup(("a", "b", "c"), 2_000_000)
    sync.push(frame("a", 50, dt=-5_000_000))
    sync.push(frame("b", 50))
    assert sync.push(frame("c", 50, dt=1_000_000)) == []
    assert sync.stats.mismatched == {"a": 1, "b": 0, "c": 0}
    assert sync.stats.summary() == "emitted 0; incomplete 1; mismatched a:1"  # delivered, so not dropped


def test_two_gaps_add_up():
    sync = SyncGroup(("a", "b"), TOL)
    for k in (0, 2, 5):  # 1, then 3 and 4, never arrive
        sync.push(frame("a", k))
        sync.push(frame("b", k))
    assert (sync.stats.emitted, sync.stats.incomplete, sync.stats.dropped) == (3, 3, {"a": 3, "b": 3})


def test_timestamp_keys_count_from_the_first_frame():
    sync = SyncGroup(("a", "b"), None, key="timestamp", period_ns=PERIOD)
    t0 = 1_000 * PERIOD + PERIOD // 4  # the first frame's clock reading is arbitrary (here a quarter period off)
    for k in range(3):
        sync.push(Frame("a", np.zeros((1, 1), np.uint8), t0 + k * PERIOD, 1000 + k))
        out = sync.push(Frame("b", np.zeros((1, 1), np.uint8), t0 + k * PERIOD + 999, 50 + k))
        assert [m.frame_ids for m in out] == [{"a": 1000 + k, "b": 50 + k}]


def test_smallest_allowed_arguments_and_defaults():
    sync = SyncGroup(("a", "b"), 0, max_pending=1)  # zero tolerance: identical timestamps only
    sync.push(frame("a", 0))
    (mf,) = sync.push(frame("b", 0))
    assert mf.spread_ns == 0
    assert SyncGroup(("a",), None, key="timestamp", period_ns=1).period_ns == 1
    sync = SyncGroup(("a", "b"), TOL)  # 16 keys open by default
    for k in range(20):
        sync.push(frame("a", k))
    assert sync.stats.pending == 16 and sync.stats.incomplete == 4
    with pytest.raises(ValueError, match=r"^SyncGroup needs at least one camera$"):
        SyncGroup((), TOL)
    with pytest.raises(ValueError, match=r"^SyncGroup key='timestamp' needs period_ns > 0 \(the frame period\)$"):
        SyncGroup(("a",), TOL, key="timestamp", period_ns=0)
