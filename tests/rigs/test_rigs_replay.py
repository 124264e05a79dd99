"""Replay backend: a recorded session played back as a rig, bit for bit."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
from rigkit import CAMERAS, make_source

from rigs import Recorder, Rig, RigError, Session, SessionWriter


def replay_dict(session, cameras=CAMERAS, **options) -> dict:
    return {
        "format": "studio.rig",
        "version": 1,
        "name": "replay",
        "frame_rate": 60.0,
        "sync": {"tolerance_ms": 2.0},
        "defaults": {"backend": "replay", "session": str(session), "realtime": False, **options},
        "cameras": {c: {} for c in cameras},
    }


def record(rig: Rig, out: Path, n=None) -> Path:
    writer = SessionWriter.create(out, rig.camera_names, rig=rig.name, fps=60.0,
                                  calibration=rig.calibration_path, compression=0)  # fmt: skip
    with Recorder(writer, queue_size=4) as rec:
        for m in rig.multiframes(n):
            rec.submit(m)
    return out


@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> Path:
    """A capture with jitter, drops and duplicates, from a simulated rig."""
    tmp = tmp_path_factory.mktemp("replay")
    src = make_source(tmp / "src", n=5)
    d = {
        "format": "studio.rig", "version": 1, "name": "sim", "frame_rate": 60.0,
        "defaults": {"backend": "simulated", "source": str(src), "realtime": False, "jitter_ms": 0.4,
                     "drop_probability": 0.1, "duplicate_probability": 0.1, "seed": 3},
        "cameras": {c: {} for c in CAMERAS},
    }  # fmt: skip
    with Rig.open(d) as rig:
        return record(rig, tmp / "a", n=14)


def test_replay_reproduces_a_recording_bit_for_bit(recorded, tmp_path):
    a = Session.open(recorded)
    assert len(a) == 14
    with Rig.open(replay_dict(recorded)) as rig:
        assert rig.calibration_path == recorded / "calibration.json"
        b = Session.open(record(rig, tmp_path / "b"))
        st = rig.stats.sync
    ids = [a.frame_meta(i)["frame_ids"]["cam0"] for i in a.frame_indices]
    assert st.emitted == 14 and st.duplicates == dict.fromkeys(CAMERAS, 0)
    assert st.incomplete == ids[-1] - ids[0] + 1 - 14 > 0  # instants lost live are gaps again
    assert b.frame_indices == a.frame_indices and b.cameras == a.cameras
    for i in a.frame_indices:
        ma, mb = a.frame_meta(i), b.frame_meta(i)
        assert ma["timestamps_ns"] == mb["timestamps_ns"] and ma["frame_ids"] == mb["frame_ids"]
        for cam in a.cameras:
            ia, ib = a.image(cam, i), b.image(cam, i)
            assert ia.dtype == ib.dtype and ia.tobytes() == ib.tobytes()
            assert (recorded / "frames" / cam / f"{i:06d}.png").read_bytes() == (
                b.path / "frames" / cam / f"{i:06d}.png"
            ).read_bytes()


def test_replay_loop_continues_ids_and_timestamps(recorded):
    a = Session.open(recorded)
    first, last = a.frame_meta(0), a.frame_meta(a.frame_indices[-1])
    with Rig.open(replay_dict(recorded, cameras=("cam0",), loop=True)) as rig:
        mfs = list(rig.multiframes(20))
    span = last["frame_ids"]["cam0"] - first["frame_ids"]["cam0"] + 1
    assert mfs[14].frame_ids["cam0"] == first["frame_ids"]["cam0"] + span
    ts = [m.timestamps_ns["cam0"] for m in mfs]
    assert all(t1 > t0 for t0, t1 in zip(ts, ts[1:]))
    np.testing.assert_array_equal(mfs[15].images["cam0"], mfs[1].images["cam0"])


def test_replay_realtime_follows_recorded_timestamps(recorded):
    a = Session.open(recorded)
    duration = (a.frame_meta(7)["timestamps_ns"]["cam0"] - a.frame_meta(0)["timestamps_ns"]["cam0"]) / 1e9
    with Rig.open(replay_dict(recorded, cameras=("cam0",), realtime=True)) as rig:
        t0 = time.monotonic()
        assert len(list(rig.multiframes(8))) == 8
        assert time.monotonic() - t0 >= duration - 0.01


def test_replay_backgrounds_and_pixel_format(recorded, tmp_path):
    src = make_source(tmp_path / "src", n=2, cameras=("cam0",), backgrounds=2)
    with Rig.open(replay_dict(src, cameras=("cam0",))) as rig:
        bg = rig.background_frames(3)["cam0"]
        np.testing.assert_array_equal(bg[2], bg[0])
        cam = rig.cameras["cam0"]
        assert cam.get("PixelFormat") == "RGB8" and cam.get("AcquisitionFrameRate") == 60.0
    nobg = make_source(tmp_path / "nobg", n=2, cameras=("cam0",), backgrounds=0)
    with Rig.open(replay_dict(nobg, cameras=("cam0",))) as rig:
        with pytest.raises(RigError, match="has no background frames"):
            rig.background_frames(1)


@pytest.mark.parametrize(
    "change, match",
    [
        ({"no_session": True}, "needs option 'session'"),
        ({"jitter_ms": 1.0}, "unknown replay option 'jitter_ms'"),
        ({"source_camera": "camZ"}, "has no camera 'camZ'"),
    ],
)
def test_replay_errors(recorded, change, match):
    change = dict(change)
    no_session = change.pop("no_session", False)
    d = replay_dict(recorded, cameras=("cam0",), **change)
    if no_session:
        d["defaults"].pop("session")
    with pytest.raises(RigError, match=match):
        Rig.open(d)
