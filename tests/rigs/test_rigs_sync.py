"""SyncGroup: exact multi-frames under injected drops, jitter, duplicates, late and bad frames."""

from __future__ import annotations

import numpy as np
import pytest

from rigs import Frame, MultiFrame, RigError, SyncGroup, SyncStats

CAMS = ("cam0", "cam1", "cam2", "cam3")
PERIOD = 16_666_667  # 60 fps
TOL = 2_000_000


def frame(cam: str, k: int, dt: int = 0) -> Frame:
    return Frame(cam, np.full((2, 2), k % 256, np.uint8), k * PERIOD + dt, k)


def interleave(streams: dict[str, list], rng, max_lag: float = 4.0) -> list:
    """Merge per-camera lists by arrival time ``frame_id + U(0, max_lag)`` periods (transport
    latency), keeping each camera's own order."""
    arrivals = []
    for c, s in streams.items():
        t = -1.0
        for j, f in enumerate(s):
            t = max(t, f.frame_id + rng.uniform(0, max_lag))
            arrivals.append((t, c, j, f))
    return [a[3] for a in sorted(arrivals, key=lambda a: a[:3])]


def test_exactly_the_complete_instants_under_drops_jitter_duplicates_and_late_frames():
    rng = np.random.default_rng(7)
    n = 400
    streams: dict[str, list] = {c: [] for c in CAMS}
    delivered = {c: set() for c in CAMS}
    bad = {}  # instant -> the one camera whose timestamp is 5 ms off
    dups = dict.fromkeys(CAMS, 0)
    held: list[Frame] = []  # delivered after the instant closed -> late
    for k in range(n):
        bad_cam = CAMS[rng.integers(4)] if (k % 37 == 5) else None
        if bad_cam:
            bad[k] = bad_cam
        for c in CAMS:
            if 0 < k < n - 1 and rng.random() < 0.06:  # lost frame
                continue
            if 0 < k < n - 40 and rng.random() < 0.01 and bad_cam is None:
                held.append(frame(c, k, int(rng.uniform(-0.9e6, 0.9e6))))
                continue
            dt = int(rng.uniform(-0.9e6, 0.9e6))  # spread <= 1.8 ms < 2 ms tolerance
            if c == bad_cam:
                dt = 5_000_000
            f = frame(c, k, dt)
            streams[c].append(f)
            delivered[c].add(k)
            if rng.random() < 0.03:  # transport resend: same frame twice
                streams[c].append(f)
                dups[c] += 1
    order = interleave(streams, rng) + held
    sync = SyncGroup(CAMS, TOL, max_pending=8)
    out: list[MultiFrame] = []
    for f in order:
        out += sync.push(f)
    out += sync.flush()

    expected = [k for k in range(n) if all(k in delivered[c] for c in CAMS) and k not in bad]
    got = [mf.frame_ids["cam0"] for mf in out]
    assert got == expected
    assert [mf.index for mf in out] == list(range(len(expected)))
    for mf in out:
        assert set(mf.frame_ids.values()) == {mf.frame_ids["cam0"]}  # one instant
        assert mf.spread_ns <= TOL
        assert list(mf.frames) == list(CAMS)
    st = sync.stats
    assert st.emitted == len(expected)
    assert st.incomplete == n - len(expected)
    for c in CAMS:
        assert st.dropped[c] == n - len(delivered[c]), c
        assert st.duplicates[c] == dups[c], c
        assert st.late[c] == sum(1 for f in held if f.camera == c), c
        assert st.mismatched[c] == sum(1 for cam in bad.values() if cam == c), c
    assert sum(st.late.values()) == len(held) > 0
    assert st.pending == 0
    assert "emitted" in st.summary() and "dropped" in st.summary()


def test_instant_nobody_delivered_counts_as_dropped_for_every_camera():
    sync = SyncGroup(CAMS[:2], TOL)
    out = []
    for k in (0, 1, 4, 5):  # 2 and 3 lost by both cameras
        for c in CAMS[:2]:
            out += sync.push(frame(c, k))
    out += sync.flush()
    assert [mf.frame_ids["cam0"] for mf in out] == [0, 1, 4, 5]
    assert sync.stats.dropped == {"cam0": 2, "cam1": 2}
    assert sync.stats.incomplete == 2


def test_complete_instant_is_emitted_as_soon_as_it_is_complete():
    sync = SyncGroup(CAMS, TOL)
    for c in CAMS[:3]:
        assert sync.push(frame(c, 0)) == []
    (mf,) = sync.push(frame("cam3", 0))
    assert mf.index == 0 and mf.timestamps_ns == dict.fromkeys(CAMS, 0)
    assert mf.images["cam2"].shape == (2, 2) and mf.cameras == list(CAMS)


def test_dead_camera_bounded_by_max_pending():
    sync = SyncGroup(CAMS[:2], TOL, max_pending=4)
    for k in range(20):
        assert sync.push(frame("cam0", k)) == []
        assert sync.stats.pending <= 5
    assert sync.stats.incomplete == 20 - sync.stats.pending
    assert sync.stats.dropped["cam1"] == sync.stats.incomplete


def test_tolerance_none_checks_frame_ids_only():
    sync = SyncGroup(CAMS[:2], None)
    sync.push(frame("cam0", 0))
    (mf,) = sync.push(frame("cam1", 0, dt=9_000_000))
    assert mf.spread_ns == 9_000_000


def test_timestamp_key_matches_free_running_cameras_with_different_counters():
    sync = SyncGroup(CAMS[:2], TOL, key="timestamp", period_ns=PERIOD)
    out = []
    for k in range(10):
        out += sync.push(Frame("cam0", np.zeros(1), k * PERIOD + 100, k))
        if k != 6:
            out += sync.push(Frame("cam1", np.zeros(1), k * PERIOD - 300_000, 1000 + k))
    out += sync.flush()
    assert len(out) == 9
    assert all(mf.frame_ids["cam1"] - mf.frame_ids["cam0"] == 1000 for mf in out)
    assert sync.stats.dropped == {"cam0": 0, "cam1": 1}


def test_syncstats_is_a_frozen_snapshot():
    sync = SyncGroup(CAMS[:1], TOL)
    st = sync.stats
    assert isinstance(st, SyncStats)
    sync.push(frame("cam0", 0))
    assert st.emitted == 0 and sync.stats.emitted == 1 and sync.stats.total_dropped == 0
    with pytest.raises(AttributeError):
        st.emitted = 3


def test_unknown_camera_is_an_error():
    with pytest.raises(RigError, match="unknown camera 'camX'"):
        SyncGroup(CAMS, TOL).push(frame("camX", 0))


@pytest.mark.parametrize(
    "args, kwargs, match",
    [
        ((), {}, "at least one camera"),
        ((["a", "a"],), {}, "unique"),
        ((["a"],), {"tolerance_ns": -1}, "tolerance_ns"),
        ((["a"],), {"max_pending": 0}, "max_pending"),
        ((["a"],), {"key": "index"}, "key must be"),
        ((["a"],), {"key": "timestamp"}, "period_ns"),
    ],
)
def test_invalid_arguments(args, kwargs, match):
    cams = args[0] if args else []
    kwargs = {"tolerance_ns": TOL, **kwargs}
    with pytest.raises(ValueError, match=match):
        SyncGroup(cams, **kwargs)
