"""Recorder: sessions written through the queue, back-pressure, disk full, SIGKILL mid-capture;
and the ``studio capture`` command."""

from __future__ import annotations

import errno
import json
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from rigkit import CAMERAS, kill_after_rows, make_source, rig_dict, source_image

from rigs import Frame, MultiFrame, Recorder, RecorderStats, Rig, RigError, Session, SessionWriter

HERE = Path(__file__).resolve().parent


@pytest.fixture(scope="module")
def source(tmp_path_factory) -> Path:
    return make_source(tmp_path_factory.mktemp("recsrc") / "src", n=4)


def mf(i: int, cams=("a", "b")) -> MultiFrame:
    return MultiFrame(i, {c: Frame(c, np.full((4, 5, 3), i, np.uint8), 100 * i, i) for c in cams})


class FakeWriter:
    """Records calls; optionally fails at frame ``fail_at`` or waits on ``gate`` before writing."""

    path = Path("/fake/session")

    def __init__(self, fail_at=None, exc=None, gate=None):
        self.fail_at, self.exc, self.gate = fail_at, exc, gate
        self.frames, self.status = [], None

    def write_frame(self, index, images, timestamps_ns=None, frame_ids=None, flags=None):
        if self.gate is not None:
            self.gate.wait(10)
        if index == self.fail_at:
            raise self.exc
        self.frames.append((index, frame_ids))

    def close(self, status="complete"):
        self.status = status


def test_record_simulated_rig_to_session(tmp_path, source):
    with Rig.open(rig_dict(source, jitter_ms=0.2), epoch_ns=5) as rig:
        writer = SessionWriter.create(tmp_path / "cap", rig.camera_names, rig=rig.name, fps=60.0,
                                      calibration=rig.calibration_path, compression=0)  # fmt: skip
        recorded = []
        with Recorder(writer, queue_size=3) as rec:
            for m in rig.multiframes(10):
                assert rec.submit(m)
                recorded.append(m)
        st = rec.stats
    assert isinstance(st, RecorderStats)
    assert (st.submitted, st.written, st.dropped, st.queue_depth, st.errors) == (10, 10, 0, 0, ())
    assert 1 <= st.max_queue_depth <= 3 and st.write_time > 0
    s = Session.open(tmp_path / "cap")
    assert s.status == "complete" and s.frame_indices == list(range(10)) and s.cameras == list(CAMERAS)
    assert s.calibration_json()["format"] == "studio.rig-calibration"
    for m in recorded:
        meta = s.frame_meta(m.index)
        assert meta["timestamps_ns"] == m.timestamps_ns and meta["frame_ids"] == m.frame_ids
        for c, cam in enumerate(CAMERAS):
            np.testing.assert_array_equal(s.image(cam, m.index), source_image(c, m.index % 4))


def test_disk_full_is_reported_not_hidden():
    w = FakeWriter(fail_at=3, exc=OSError(errno.ENOSPC, "No space left on device"))
    rec = Recorder(w, queue_size=2)
    with pytest.raises(RigError, match=r"disk full \(ENOSPC\).*frame 3; the 3 frames written before are readable"):
        for i in range(100):
            rec.submit(mf(i))
            time.sleep(0.002)
    assert rec.failed and len(rec.stats.errors) == 1 and rec.stats.written == 3
    with pytest.raises(RigError, match="disk full"):
        rec.close()
    assert w.status == "aborted" and [f[0] for f in w.frames] == [0, 1, 2]


def test_disk_full_raised_by_close_when_last_frame_fails():
    from rigs import SessionError

    cause = OSError(errno.ENOSPC, "No space left on device")
    err = SessionError("frame 1: disk full")
    err.__cause__ = cause
    w = FakeWriter(fail_at=1, exc=err)
    rec = Recorder(w)
    rec.submit(mf(0))
    rec.submit(mf(1))
    with pytest.raises(RigError, match="disk full.*frame 1") as info:
        rec.close()
    assert info.value.__cause__ is err
    assert w.status == "aborted"


def test_real_session_writer_enospc(tmp_path, monkeypatch):
    import rigs.imageio as imageio

    writer = SessionWriter.create(tmp_path / "s", ["a", "b"], compression=0)
    real = imageio.write_image
    calls = []

    def flaky(path, image, *args, **kwargs):
        calls.append(path)
        if len(calls) > 4:
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        return real(path, image, *args, **kwargs)

    monkeypatch.setattr(imageio, "write_image", flaky)
    rec = Recorder(writer)
    for i in range(3):
        rec.submit(mf(i))
    with pytest.raises(RigError, match="disk full"):
        rec.close()
    s = Session.open(tmp_path / "s")
    assert s.frame_indices == [0, 1] and s.status == "aborted"
    np.testing.assert_array_equal(s.image("b", 1), mf(1).frames["b"].image)


def test_back_pressure_policies():
    gate = threading.Event()
    w = FakeWriter(gate=gate)
    rec = Recorder(w, queue_size=2, policy="raise")
    with pytest.raises(RigError, match="queue full \\(2 multi-frames waiting\\).*/fake/session"):
        for i in range(10):
            rec.submit(mf(i))
    gate.set()
    rec.close()
    assert rec.stats.submitted == len(w.frames) and w.status == "complete"

    gate = threading.Event()
    w = FakeWriter(gate=gate)
    with Recorder(w, queue_size=2, policy="drop") as rec:
        results = [rec.submit(mf(i)) for i in range(10)]
        gate.set()
    assert results.count(False) == rec.stats.dropped >= 5
    assert rec.stats.written + rec.stats.dropped == 10
    assert [f[0] for f in w.frames] == [i for i, ok in enumerate(results) if ok]

    gate = threading.Event()
    w = FakeWriter(gate=gate)
    rec = Recorder(w, queue_size=1, policy="block")
    threading.Timer(0.2, gate.set).start()
    for i in range(4):
        rec.submit(mf(i))
    rec.close()
    assert rec.stats.blocked_time >= 0.1 and rec.stats.max_queue_depth == 1
    assert [f[0] for f in w.frames] == [0, 1, 2, 3]


def test_recorder_errors():
    with pytest.raises(ValueError, match="queue_size must be a positive integer"):
        Recorder(FakeWriter(), queue_size=0)
    with pytest.raises(ValueError, match="policy must be one of"):
        Recorder(FakeWriter(), policy="ignore")
    rec = Recorder(FakeWriter())
    rec.close()
    rec.close()  # idempotent
    with pytest.raises(RigError, match="submit\\(\\) after close\\(\\)"):
        rec.submit(mf(0))

    class BadClose(FakeWriter):
        def close(self, status="complete"):
            raise OSError("read-only file system")

    with pytest.raises(RigError, match="closing /fake/session failed: read-only"):
        Recorder(BadClose()).close()
    with pytest.raises(KeyError):  # the original exception wins over the recorder's
        with Recorder(FakeWriter(fail_at=0, exc=OSError(errno.ENOSPC, "full"))) as rec:
            rec.submit(mf(0))
            time.sleep(0.05)
            raise KeyError("boom")


def test_recorder_survives_sigkill_mid_capture(tmp_path, source):
    out = tmp_path / "killed"
    kill_after_rows([sys.executable, str(HERE / "rigrec_kill_child.py"), str(source), str(out)], out, 8)
    s = Session.open(out)
    assert s.status == "recording"  # never closed
    n = len(s.frame_indices)
    assert n >= 8 and s.frame_indices == list(range(n))
    for i in s.frame_indices:
        meta = s.frame_meta(i)
        assert meta["frame_ids"] == dict.fromkeys(CAMERAS, i)
        assert meta["timestamps_ns"] == dict.fromkeys(CAMERAS, int(round(i * 1e9 / 60)))
        for c, cam in enumerate(CAMERAS):
            np.testing.assert_array_equal(s.image(cam, i), source_image(c, i % 4))


# -- studio capture -------------------------------------------------------------------------------
def test_studio_capture_command(tmp_path, source, capsys):
    from studio.cli import main

    d = rig_dict(str(source), drop_frames=[2])
    d["cameras"]["cam1"]["duplicate_frames"] = [4]
    (tmp_path / "rig.yaml").write_text(yaml.safe_dump(d))
    out = tmp_path / "cap"
    code = main(["capture", "--rig", str(tmp_path / "rig.yaml"), "--out", str(out), "--frames", "6",
                 "--background", "3", "--compression", "0"])  # fmt: skip
    assert code == 0
    text = capsys.readouterr().out
    assert "frames written: 6" in text and "incomplete instants: 1" in text
    s = Session.open(out)
    assert s.status == "complete" and len(s) == 6 and s.calibration_path is not None
    assert [s.frame_meta(i)["frame_ids"]["cam0"] for i in range(6)] == [0, 1, 3, 4, 5, 6]
    assert s.background_indices("cam3") == [0, 1, 2]
    np.testing.assert_array_equal(s.background("cam3", 2), source_image(3, 1000))
    assert s.info["pixel_formats"] == dict.fromkeys(CAMERAS, "RGB8")
    # a duplicate, per camera, in the summary table row of cam1
    row = next(line for line in text.splitlines() if "cam1" in line)
    assert [int(x) for x in row.replace("│", " ").split()[1:]][3] == 1
    # defect 5: the drops live in the session and `session info` shows the capture's figures
    drops = s.drops
    assert drops["incomplete_instants"] == 1 and drops["recorder_dropped"] == 0
    assert drops["cameras"]["cam1"]["duplicates"] == 1 and sum(c["dropped"] for c in drops["cameras"].values()) >= 1
    assert main(["session", "info", str(out)]) == 0
    info = capsys.readouterr().out
    assert "drops     1 incomplete trigger instant(s) not in frames.csv" in info
    assert "cam1 dropped" in info and "duplicates 1" in info
    assert main(["session", "info", str(out), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["drops"] == drops


@pytest.mark.parametrize(
    "extra, match",
    [
        (["--frames", "0"], "--frames must be >= 1"),
        (["--background", "-1"], "--background must be >= 0"),
        (["--source", "nowhere/spec.yaml"], "no such scene spec"),
    ],
)
def test_studio_capture_errors(tmp_path, source, capsys, extra, match):
    from studio.cli import main

    (tmp_path / "rig.yaml").write_text(yaml.safe_dump(rig_dict(str(source))))
    code = main(["capture", "--rig", str(tmp_path / "rig.yaml"), "--out", str(tmp_path / "o"), *extra])
    assert code == 1
    assert match in capsys.readouterr().err


def test_studio_capture_refuses_existing_session(tmp_path, source, capsys):
    from studio.cli import main

    (tmp_path / "rig.yaml").write_text(yaml.safe_dump(rig_dict(str(source))))
    code = main(["capture", "--rig", str(tmp_path / "rig.yaml"), "--out", str(source), "--frames", "1"])
    assert code == 1 and "overwrite" in capsys.readouterr().err


def test_studio_capture_reports_disk_full(tmp_path, source, capsys, monkeypatch):
    import rigs.imageio as imageio
    from studio.cli import main

    real, calls = imageio.write_image, []

    def flaky(path, image, *args, **kwargs):
        calls.append(path)
        if len(calls) > 10:
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        return real(path, image, *args, **kwargs)

    monkeypatch.setattr(imageio, "write_image", flaky)
    (tmp_path / "rig.yaml").write_text(yaml.safe_dump(rig_dict(str(source))))
    code = main(["capture", "--rig", str(tmp_path / "rig.yaml"), "--out", str(tmp_path / "o"), "--frames", "40"])
    assert code == 1
    err = capsys.readouterr().err
    assert "disk full (ENOSPC)" in err and "the 2 frames written before are readable" in err
    s = Session.open(tmp_path / "o")
    assert s.frame_indices == [0, 1] and s.status == "aborted"
