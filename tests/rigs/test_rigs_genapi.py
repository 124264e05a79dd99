"""The shared GenICam camera (rigs.backends._genapi) over a GenTL-level fake: triggers, sync,
pixel formats, chunk timestamps, PTP lock, refused settings, underruns, teardown."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

import fake_gentl
from fake_gentl import FLAT_RGB12, scene_mono12
from rigs import Rig
from rigs.backends._genapi import close_leftovers, unwrap_frame_id
from rigs.device import FrameTimeout, RigError


def fake_rig(n=2, trigger=None, sync=None, frame_rate=100.0, **camera):
    defaults = {"backend": "fake-gentl", "pixel_format": "Mono8", "width": 32, "height": 24, **camera}
    return {"format": "studio.rig", "version": 1, "name": "fake", "frame_rate": frame_rate,
            "trigger": trigger or {"mode": "software"}, "sync": sync or {"tolerance_ms": 50.0},
            "defaults": defaults, "cameras": {f"cam{k}": {"device": {"id": f"dev{k}"}} for k in range(n)}}  # fmt: skip


@pytest.fixture(autouse=True)
def _fresh_fakes():
    fake_gentl.DEVICES.clear()
    fake_gentl.CREATED.clear()
    yield
    assert all(t.closed for t in fake_gentl.CREATED), "a fake camera was left open"
    assert not [t for t in threading.enumerate() if t.name == "software-trigger"], "trigger thread leaked"


def test_software_trigger_fans_out_and_every_trigger_becomes_one_frame():
    """3 cameras at 100 Hz, device block ids wrapping at 65535: each trigger reaches every
    camera; frame ids stay consecutive across the wrap; nothing is dropped."""
    with Rig.open(fake_rig(3)) as rig:
        mfs = list(rig.multiframes(20))
        trigger = next(iter(rig.cameras.values()))._trigger
        rig.stop()
        fired = trigger.fired
        stats = {n: c.device_stats() for n, c in rig.cameras.items()}
        sync = rig.stats.sync
    assert [mf.frame_ids for mf in mfs] == [dict.fromkeys(["cam0", "cam1", "cam2"], k) for k in range(20)]
    for t in fake_gentl.CREATED:
        assert t.exposures == fired, "every trigger exposes every camera"
        assert t.block_id < 65530, "the device counter wrapped (first id 65530)"
    for s in stats.values():
        assert s["triggers"] == fired and s["n_underruns"] == 0 and s["n_completed_buffers"] == fired
    assert sync.emitted == 20 and sync.total_dropped == 0 and sync.incomplete == 0
    assert fired >= 20


def test_hardware_trigger_line_counts_frames_and_writes_activation():
    d = fake_rig(2, trigger={"mode": "hardware", "line": "Line1"}, buffers=32,
                 trigger_activation="FallingEdge", nodes={"LineSelector": "Line1", "LineMode": "Input"})
    with Rig.open(d) as rig:
        rig.start()
        transports = [c.transport for c in rig.cameras.values()]
        assert transports[0].values["TriggerSource"] == "Line1"
        assert transports[0].values["TriggerActivation"] == "FallingEdge"
        assert transports[0].values["LineSelector"] == "Line1"
        for _ in range(15):
            for t in transports:
                t.pulse("Line1")
            transports[0].pulse("Line0")  # another line: ignored
        mfs = list(rig.multiframes(15, timeout=1.0))
        with pytest.raises(RigError, match="no frame from any camera for 0.2 s"):
            list(rig.multiframes(1, timeout=0.2))
    assert len(mfs) == 15 and [mf.index for mf in mfs] == list(range(15))
    assert [t.exposures for t in transports] == [15, 15]


def test_stalled_stream_times_out_instead_of_hanging():
    with Rig.open(fake_rig(1, trigger={"mode": "hardware", "line": "Line0"}, timeout=0.2)) as rig:
        cam = rig.cameras["cam0"]
        cam.start()
        t0 = time.monotonic()
        with pytest.raises(FrameTimeout, match="camera 'cam0': no frame within 0.2 s"):
            with cam.fetch():  # the camera's timeout option
                pass
        assert 0.15 < time.monotonic() - t0 < 1.0
        with pytest.raises(FrameTimeout, match="no frame within 0.05 s"):
            with cam.fetch(timeout=0.05):
                pass


def test_underruns_become_frame_id_gaps_and_sync_drops():
    """cam0 has 4 buffers, cam1 16: 10 triggers unconsumed lose 6 of cam0's frames."""
    d = fake_rig(2, trigger={"mode": "hardware", "line": "Line0"})
    d["cameras"]["cam0"]["buffers"] = 4
    d["cameras"]["cam1"]["buffers"] = 16
    with Rig.open(d) as rig:
        rig.start()
        ts = [c.transport for c in rig.cameras.values()]
        for _ in range(10):
            for t in ts:
                t.pulse()
        first = list(rig.multiframes(4, timeout=1.0))
        for _ in range(4):  # cam0's 4 buffers are free again
            for t in ts:
                t.pulse()
        rest = list(rig.multiframes(4, timeout=1.0))
        sync, stats = rig.stats.sync, rig.cameras["cam0"].device_stats()
    assert [mf.frame_ids["cam0"] for mf in first + rest] == [0, 1, 2, 3, 10, 11, 12, 13]
    assert stats["n_underruns"] == 6
    assert sync.dropped == {"cam0": 6, "cam1": 0} and sync.incomplete == 6


def test_bayer12p_debayered_and_raw_with_pattern():
    with Rig.open(fake_rig(1, pixel_format="BayerGR12p", trigger={"mode": "free-run"})) as rig:
        mf = next(rig.multiframes(1))
        stats = rig.cameras["cam0"].device_stats()
    img = mf.images["cam0"]
    assert img.shape == (24, 32, 3) and img.dtype == np.uint16
    np.testing.assert_array_equal(img[2:-2, 2:-2].reshape(-1, 3).min(0), np.array(FLAT_RGB12) << 4)
    np.testing.assert_array_equal(img[2:-2, 2:-2].reshape(-1, 3).max(0), np.array(FLAT_RGB12) << 4)
    assert stats["bayer_pattern"] == "GR" and stats["debayered"] is True
    with Rig.open(fake_rig(1, pixel_format="BayerGR8", debayer=False, trigger={"mode": "free-run"})) as rig:
        raw = next(rig.multiframes(1)).images["cam0"]
    assert raw.shape == (24, 32)
    assert raw[0, 0] == FLAT_RGB12[1] >> 4 and raw[0, 1] == FLAT_RGB12[0] >> 4 and raw[1, 0] == FLAT_RGB12[2] >> 4


@pytest.mark.parametrize("fmt", ["Mono12p", "Mono12Packed", "Mono12", "Mono8"])
def test_mono_pattern_unpacked_from_the_device(fmt):
    with Rig.open(fake_rig(1, pixel_format=fmt, chunks=True)) as rig:
        mf = next(rig.multiframes(1))
        stats = rig.cameras["cam0"].device_stats()
    t = fake_gentl.CREATED[0]
    block = 65530  # the device's first block id
    truth = scene_mono12(32, 24, block)
    got = mf.images["cam0"]
    expect = truth >> 4 if fmt == "Mono8" else truth << 4
    np.testing.assert_array_equal(got, expect.astype(got.dtype))
    # chunk data: the exposure timestamp (the buffer's is 1 ms later), counted
    assert stats["chunk_timestamps"] >= 1 and t.values["ChunkModeActive"] is True


def test_chunk_timestamp_is_used_over_the_buffer_timestamp():
    with Rig.open(fake_rig(1, chunks=True, trigger={"mode": "hardware", "line": "Line0"})) as rig:
        rig.start()
        t = rig.cameras["cam0"].transport
        before = time.time_ns()
        t.pulse()
        after = time.time_ns()
        frame = next(rig.multiframes(1)).frames["cam0"]
    assert before <= frame.timestamp_ns <= after, "chunk timestamp = exposure instant, not arrival (+1 ms)"


def test_ptp_waits_for_lock_or_says_why_not():
    fake_gentl.DEVICES.update(dev0={"ptp_lock_s": 0.1, "clock_offset_ns": 5_000_000},
                              dev1={"ptp_lock_s": 0.2, "clock_offset_ns": -3_000_000})
    d = fake_rig(2, sync={"ptp": True, "tolerance_ms": 1.0})
    with Rig.open(d) as rig:
        assert {c.info["ptp_status"] for c in rig.cameras.values()} == {"Slave"}
        mfs = list(rig.multiframes(5))
    assert max(mf.spread_ns for mf in mfs) < 1_000_000, "locked clocks: offsets of 5 and -3 ms gone"
    fake_gentl.DEVICES.update(dev0={"ptp_lock_s": 60.0})
    with pytest.raises(RigError, match=r"camera 'cam0': PTP did not lock within 0.2 s \(GevIEEE1588Status="
                                       r"'Listening', expected Master or Slave\)"):
        Rig.open(fake_rig(1, sync={"ptp": True}, ptp_timeout=0.2))


def test_refused_settings_name_the_node_and_the_allowed_values():
    with pytest.raises(RigError, match=r"camera 'cam0': node PixelFormat='RGB16' refused: allowed values are "
                                       r"Mono8, Mono12, Mono12p, Mono12Packed, Mono16, RGB8, BGR8, BayerRG8"):
        Rig.open(fake_rig(1, pixel_format="RGB16"))
    with pytest.raises(RigError, match=r"node Width=1000 refused: out of range, allowed int in \[8, 256\]"):
        Rig.open(fake_rig(1, width=1000))
    with pytest.raises(RigError, match=r"node LineMode='Bogus' refused: allowed values are Input, Output"):
        Rig.open(fake_rig(1, nodes={"LineMode": "Bogus"}))
    with pytest.raises(RigError, match=r"node LineInverter=True: the device has no GenApi node 'LineInverter'"):
        Rig.open(fake_rig(1, nodes={"LineInverter": True}))
    with pytest.raises(RigError, match=r"node Gain='x' refused: expected a number, float in \[0, 24\]"):
        Rig.open(fake_rig(1, nodes={"Gain": "x"}))
    with pytest.raises(RigError, match=r"option buffers must be an integer in 1..4096, got 0"):
        Rig.open(fake_rig(1, buffers=0))
    with pytest.raises(RigError, match=r"option timeout must be a positive number of seconds, got 0"):
        Rig.open(fake_rig(1, timeout=0))
    with pytest.raises(RigError, match=r"option debayer must be true or false, got 'yes'"):
        Rig.open(fake_rig(1, debayer="yes"))
    with pytest.raises(RigError, match=r"option nodes must be a mapping of GenApi node -> value"):
        Rig.open(fake_rig(1, nodes=["Gain"]))
    with pytest.raises(RigError, match=r"unknown fake-gentl option 'bufers'; expected any of \['buffers'"):
        Rig.open(fake_rig(1, bufers=4))
    with Rig.open(fake_rig(1, trigger={"mode": "free-run"})) as rig:
        cam = rig.cameras["cam0"]
        cam.configure(ExposureTime=2500.0, Gain=6.0)
        assert cam.node("ExposureTime") == 2500.0 and cam.node("Gain") == 6.0
        with pytest.raises(RigError, match=r"node Gain=30.0 refused: out of range, allowed float in \[0, 24\]"):
            cam.configure(Gain=30.0)
        cam.start()
        with pytest.raises(RigError, match="Width cannot change while streaming"):
            cam.configure(Width=64)
        with pytest.raises(RigError, match=r"node Height=16 refused by the device \(Height is locked while streaming"):
            cam.set_node("Height", 16)
    assert len(fake_gentl.CREATED) == 6  # every refused open closed its camera (checked by the fixture)


def test_interrupt_and_failed_open_leave_nothing_open():
    d = fake_rig(3)
    d["cameras"]["cam2"]["pixel_format"] = "BayerXY8"
    with pytest.raises(RigError, match="pixel_format"):
        Rig.open(d)
    d = fake_rig(3)
    d["cameras"]["cam2"]["width"] = 999
    with pytest.raises(RigError, match="cam2.*Width=999"):
        Rig.open(d)
    assert len(fake_gentl.CREATED) == 3 and all(t.closed for t in fake_gentl.CREATED)
    with pytest.raises(KeyboardInterrupt):
        with Rig.open(fake_rig(2)) as rig:
            for mf in rig.multiframes(100):
                if mf.index == 3:
                    raise KeyboardInterrupt
    assert all(t.closed and not t.streaming for t in fake_gentl.CREATED)
    rig = Rig.open(fake_rig(1))  # never closed by its user
    assert close_leftovers() >= 1 and fake_gentl.CREATED[-1].closed
    rig.close()


def test_unwrap_frame_id_across_the_gige_wrap():
    ids = [65533, 65534, 65535, 1, 2, 4]
    out, last_raw, last = [], None, None
    for raw in ids:
        last = unwrap_frame_id(raw, last_raw, last)
        last_raw = raw
        out.append(last)
    assert out == [65533, 65534, 65535, 65536, 65537, 65539]


def test_action_commands_trigger_every_matching_camera_from_one_issuer():
    """trigger mode action: cam0's transport issues one action command per tick; all three
    cameras (keys matching) expose on each; a camera with another group key never does."""
    d = fake_rig(3, trigger={"mode": "action", "action": {"device_key": 7, "group_key": 2, "group_mask": 1}})
    with Rig.open(d) as rig:
        ts = [c.transport for c in rig.cameras.values()]
        assert ts[1].values["ActionDeviceKey"] == 7 and ts[1].values["TriggerSource"] == "Action1"
        mfs = list(rig.multiframes(10))
        trigger = rig.cameras["cam0"]._trigger
        trigger.disarm("cam0")
        issued = ts[0].actions_issued
        ts[2].values["ActionGroupKey"] = 3  # no longer in the group
        rig.cameras["cam0"].transport.issue_action(7, 2, 1)
    assert [mf.frame_ids["cam2"] for mf in mfs] == list(range(10))
    assert issued == trigger.fired and [t.actions_issued for t in ts[1:]] == [0, 0]
    assert [t.exposures for t in ts] == [issued + 1, issued + 1, issued]


def test_action_mode_needs_the_keys_and_an_issuer():
    from rigs import RigDescription

    with pytest.raises(RigError, match=r"field 'trigger.action.group_mask': expected an integer between 0 and "):
        RigDescription.from_dict(fake_rig(1, trigger={"mode": "action", "action": {"group_mask": -1}}))
    with pytest.raises(RigError, match=r"field 'trigger.action': expected a mapping of \['device_key'"):
        RigDescription.from_dict(fake_rig(1, trigger={"mode": "action", "action": {"key": 1}}))
    d = fake_rig(1, trigger={"mode": "action"})
    fake_gentl.DEVICES["dev0"] = {}
    original = fake_gentl.FakeTransport.action_issuer
    try:
        fake_gentl.FakeTransport.action_issuer = lambda self: "this fake cannot send them"
        with pytest.raises(RigError, match="camera 'cam0': trigger mode action: this fake cannot send them; use mode "
                                           "software or hardware"):
            Rig.open(d)
    finally:
        fake_gentl.FakeTransport.action_issuer = original


def test_throttled_capture_records_underruns_as_drops_in_the_session(tmp_path, monkeypatch, capsys):
    """studio capture with a consumer slower than the cameras: cam0 (2 buffers) loses
    exposures, which become frame-id gaps, sync drops in session.json and in session info."""
    import yaml

    import rigs
    from rigs import Session
    from studio.cli import main

    d = fake_rig(2, frame_rate=100.0)
    d["cameras"]["cam0"]["buffers"] = 2
    d["cameras"]["cam1"]["buffers"] = 256
    rig_yaml = tmp_path / "rig.yaml"
    rig_yaml.write_text(yaml.safe_dump(d))
    submit = rigs.Recorder.submit

    def slow_submit(self, mf):
        time.sleep(0.03)  # a consumer slower than the 100 Hz trigger
        return submit(self, mf)

    monkeypatch.setattr(rigs.Recorder, "submit", slow_submit)
    assert main(["capture", "--rig", str(rig_yaml), "--out", str(tmp_path / "s"), "--frames", "20"]) == 0
    s = Session.open(tmp_path / "s")
    drops, streams = s.drops, s.drops["streams"]
    assert len(s.frame_indices) == 20
    lost = drops["cameras"]["cam0"]["dropped"]
    assert lost >= 5 and drops["cameras"]["cam1"]["dropped"] == 0 and drops["incomplete_instants"] == lost
    assert lost <= streams["cam0"]["n_underruns"] and streams["cam1"]["n_underruns"] == 0
    ids = [s.frame_meta(i)["frame_ids"]["cam0"] for i in s.frame_indices]
    gaps = ids[-1] - ids[0] + 1 - len(ids)  # ids missing between the recorded frames
    assert 1 <= gaps <= lost, "the lost exposures are gaps between recorded frame ids"
    capsys.readouterr()
    assert main(["session", "info", str(tmp_path / "s")]) == 0
    out = capsys.readouterr().out
    assert f"{lost} incomplete trigger instant(s) not in frames.csv" in out and f"cam0 dropped {lost}" in out
    assert f"stream    cam0: n_completed_buffers {streams['cam0']['n_completed_buffers']}, n_underruns" in out


def test_software_trigger_waits_for_live_cameras_only(tmp_path):
    """A rig mixing a simulated camera with two GenICam ones: the timer fires once both
    GenICam cameras are armed (the simulated one paces itself)."""
    from rigkit import make_source

    d = fake_rig(2, sync={"tolerance_ms": None})
    d["cameras"]["sim"] = {"backend": "simulated", "source": str(make_source(tmp_path / "src", cameras=("sim",))),
                           "realtime": False, "pixel_format": "RGB8", "width": None, "height": None}  # fmt: skip
    with Rig.open(d) as rig:
        rig.start()
        for name in ("cam0", "cam1"):
            with rig.cameras[name].fetch(timeout=2.0) as frame:
                assert frame.frame_id == 0
        assert rig.cameras["cam0"]._trigger.expected == 2 and rig.cameras["cam0"].issuer
