"""The aravis backend against Aravis' in-process Fake camera (no network: only the Fake
interface is enabled; the device list is never updated with GigE Vision enabled)."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pytest

from rigs import Rig, RigDescription, RigError, Session
from rigs.device import FrameTimeout

try:
    from rigs.backends.aravis import import_aravis

    ARV, _ = import_aravis()
except RigError as exc:  # PyGObject or gir1.2-aravis-0.8 missing: `make test` installs both
    pytest.skip(f"aravis backend unavailable: {exc}", allow_module_level=True)

RIG_YAML = Path(__file__).resolve().parents[2] / "rigs" / "aravis_fake.yaml"


def fake_rig(n=2, **overrides) -> RigDescription:
    desc = RigDescription.load(RIG_YAML)
    if n == 1:
        from dataclasses import replace

        desc = replace(desc, cameras={"cam0": desc.cameras["cam0"]})
    return desc.with_overrides(**overrides) if overrides else desc


def ramp_offset(image: np.ndarray) -> int:
    """The Fake camera's diagonal ramp (arvfakecamera.c): Mono8 ``(x + y + id) mod 255``;
    returns the offset after checking every pixel."""
    h, w = image.shape
    y, x = np.mgrid[0:h, 0:w]
    c = int(image[0, 0])
    np.testing.assert_array_equal(image, ((x + y + c) % 255).astype(np.uint8))
    return c


def mono16_frame_id(image: np.ndarray) -> int:
    """The Fake camera's Mono16 ramp ``256 (x + y + id) mod 65535``: the device frame id that
    reproduces every pixel."""
    h, w = image.shape
    y, x = np.mgrid[0:h, 0:w]
    ids = np.flatnonzero(256 * np.arange(65536) % 65535 == int(image[0, 0]))
    fits = [i for i in ids if np.array_equal(image, 256 * (x + y + int(i)) % 65535)]
    assert len(fits) == 1, f"no single frame id reproduces the Mono16 ramp: {fits}"
    return int(fits[0])


def test_two_fake_cameras_stream_the_known_ramp_in_sync():
    with Rig.open(fake_rig()) as rig:
        mfs = list(rig.multiframes(8))
        stats = {n: c.device_stats() for n, c in rig.cameras.items()}
        info = rig.cameras["cam0"].info
    assert info == {"vendor": "Aravis", "model": "Fake", "serial": "1"}
    for cam in ("cam0", "cam1"):
        ids = [mf.frame_ids[cam] for mf in mfs]
        offsets = [ramp_offset(mf.images[cam]) for mf in mfs]
        assert all(b > a for a, b in zip(ids, ids[1:])), f"{cam}: frame ids not increasing: {ids}"
        # the ramp advances by one per device frame: offset steps equal frame-id steps
        assert [(b - a) % 255 for a, b in zip(offsets, offsets[1:])] == [(b - a) % 255 for a, b in zip(ids, ids[1:])]
        assert mfs[0].images[cam].shape == (120, 160)
        assert stats[cam]["n_completed_buffers"] >= 8 and stats[cam]["n_failures"] == 0
        assert stats[cam]["host_timestamps"] == 0, "the Fake stream stamps buffers itself"
    assert max(mf.spread_ns for mf in mfs) <= 5_000_000


def test_mono16_and_rgb8_formats():
    with Rig.open(fake_rig(1, pixel_format="Mono16")) as rig:
        img = next(rig.multiframes(1)).images["cam0"]
    assert img.dtype == np.uint16
    assert 65400 < mono16_frame_id(img) < 65500  # the Fake counter starts at 65401
    with Rig.open(fake_rig(1, pixel_format="RGB8")) as rig:
        rgb = next(rig.multiframes(1)).images["cam0"]
    assert rgb.shape == (120, 160, 3) and rgb.dtype == np.uint8
    # a colour map of the same ramp: constant along anti-diagonals, varying across them
    assert np.array_equal(rgb[0, 1], rgb[1, 0]) and np.array_equal(rgb[5, 9], rgb[9, 5])
    assert len(np.unique(rgb.reshape(-1, 3), axis=0)) > 50


def test_fake_bayer_kept_raw_with_its_pattern():
    with Rig.open(fake_rig(1, pixel_format="BayerRG8", debayer=False)) as rig:
        raw = next(rig.multiframes(1)).images["cam0"]
        stats = rig.cameras["cam0"].device_stats()
    assert raw.shape == (120, 160) and stats["bayer_pattern"] == "RG" and stats["debayered"] is False
    with Rig.open(fake_rig(1, pixel_format="BayerRG8")) as rig:
        rgb = next(rig.multiframes(1)).images["cam0"]
    assert rgb.shape == (120, 160, 3)


def test_refused_settings_name_node_and_allowed_values():
    with pytest.raises(RigError, match=r"camera 'cam0': node PixelFormat='BayerRG12' refused: allowed values are "
                                       r"BayerBG8, BayerGB8, BayerGR8, BayerRG8, Mono8, RGB8, Mono16"):
        Rig.open(fake_rig(1, pixel_format="BayerRG12"))
    with pytest.raises(RigError, match=r"node Width=100000 refused: out of range, allowed int in \[1, 2048\]"):
        Rig.open(fake_rig(1, width=100000))
    with pytest.raises(RigError, match=r"GevIEEE1588=True cannot be set: the device has no GenApi node "
                                       r"GevIEEE1588 or PtpEnable"):
        Rig.open({**_as_dict(), "sync": {"ptp": True}})
    with pytest.raises(RigError, match=r"option chunks: the device has no GenApi node 'ChunkModeActive'"):
        Rig.open(fake_rig(1, chunks=True))
    with pytest.raises(RigError, match=r"options \['packet_size'\] apply to GigE Vision cameras only; 'Fake' is not one"):
        Rig.open(fake_rig(1, packet_size=8164))
    with pytest.raises(RigError, match=r"Aravis cannot open device 'Fake_9'"):
        Rig.open({**_as_dict(), "cameras": {"cam0": {"device": {"id": "Fake_9"}}}})


def _as_dict() -> dict:
    import yaml

    d = yaml.safe_load(RIG_YAML.read_text())
    d["cameras"] = {"cam0": {}}
    return d


def test_teardown_releases_the_device_and_errors_leak_nothing():
    d = _as_dict()
    d["cameras"] = {"cam0": {}, "cam1": {"width": 99999}}
    with pytest.raises(RigError, match="cam1"):
        Rig.open(d)
    from rigs.backends import _genapi

    assert not [t for t in _genapi._OPEN if type(t).__name__ == "AravisTransport"], "cam0 left open"
    for _ in range(2):  # re-open after a clean close and after an interrupted capture
        with pytest.raises(KeyboardInterrupt), Rig.open(fake_rig()) as rig:
            for mf in rig.multiframes(50):
                if mf.index == 2:
                    raise KeyboardInterrupt
        assert all(c.transport.camera is None for c in rig.cameras.values())
    with Rig.open(fake_rig()) as rig:
        assert len(list(rig.multiframes(3))) == 3


def test_throttled_consumer_counts_underruns():
    """2 buffers at 100 Hz and a consumer that takes 50 ms per frame: the stream underruns."""
    with Rig.open(fake_rig(1, frame_rate=100.0, buffers=2)) as rig:
        cam = rig.cameras["cam0"]
        cam.start()
        for _ in range(6):
            with cam.fetch(timeout=1.0):
                time.sleep(0.05)
        stats = cam.device_stats()
    assert stats["n_underruns"] >= 5, stats


def test_capture_session_records_frames_and_stream_statistics(tmp_path, capsys):
    from studio.cli import main

    out = tmp_path / "s"
    assert main(["capture", "--rig", str(RIG_YAML), "--out", str(out), "--frames", "12"]) == 0
    s = Session.open(out)
    assert len(s.frame_indices) == 12 and s.cameras == ["cam0", "cam1"]
    streams = s.drops["streams"]
    for cam in ("cam0", "cam1"):
        assert streams[cam]["n_completed_buffers"] >= 12 and streams[cam]["n_failures"] == 0
        assert {"n_underruns", "n_transferred_bytes"} <= set(streams[cam])
        ramp_offset(s.image(cam, s.frame_indices[5]))
    info = json.loads((out / "session.json").read_text())
    assert info["pixel_formats"] == {"cam0": "Mono8", "cam1": "Mono8"}
    capsys.readouterr()
    assert main(["session", "info", str(out)]) == 0
    text = capsys.readouterr().out
    assert f"stream    cam0: n_completed_buffers {streams['cam0']['n_completed_buffers']}" in text


@pytest.fixture
def gige_camera():
    """Aravis' fake GigE Vision camera on loopback (in-process, port 3956 of 127.0.0.1),
    with a packet capture on every interface when we may open one (root)."""
    import gc
    import os

    from netguard import PacketGuard

    guard = PacketGuard() if os.geteuid() == 0 else None
    gv = ARV.GvFakeCamera.new("lo", "GV01")
    if not gv.is_running():
        if guard is not None:
            guard.close()
        pytest.skip("Aravis' fake GigE camera could not bind 127.0.0.1:3956")
    yield gv
    del gv
    gc.collect()
    if guard is not None:
        guard.close()
        assert any(p[4] == 3956 for p in guard.packets), "the capture saw no GVCP traffic: it proves nothing"
        assert not guard.offending(), f"GigE traffic beyond unicast on loopback: {guard.offending()[:5]}"


def gige_rig(**camera) -> dict:
    # 5 Hz: the fake GigE camera looks at its (one-flag) trigger register every 40 ms, so
    # two triggers closer than that would merge into one frame (a loaded machine delays it)
    return {"format": "studio.rig", "version": 1, "name": "gige", "frame_rate": 5.0,
            "trigger": {"mode": "software"}, "sync": {"tolerance_ms": 50.0},
            "cameras": {"cam0": {"backend": "aravis", "interfaces": ["GigEVision"],
                                 "device": {"address": "127.0.0.1"}, "pixel_format": "Mono8",
                                 "width": 64, "height": 48, **camera}}}  # fmt: skip


def test_gige_software_trigger_packet_size_and_stream_statistics(gige_camera):
    """Every software trigger of the rig's timer becomes one frame over GVSP on loopback; the
    packet size is the one asked for; the GigE stream counters land in device_stats."""
    with Rig.open(gige_rig(packet_size=1000, packet_resend=True, buffers=16)) as rig:
        cam = rig.cameras["cam0"]
        assert cam.node("GevSCPSPacketSize") == 1000
        mfs = list(rig.multiframes(6, timeout=2.0))
        trigger = cam._trigger
        trigger.disarm("cam0")  # no more triggers: fetch what is still on its way
        while True:
            try:
                with cam.fetch(timeout=0.5):
                    pass
            except FrameTimeout:
                break
        stats = cam.device_stats()
        delivered = cam.stats.delivered
    assert [mf.frame_ids["cam0"] for mf in mfs] == list(range(6))
    for mf in mfs:
        ramp_offset(mf.images["cam0"])
    assert delivered == trigger.fired == stats["triggers"] == stats["n_completed_buffers"], stats
    assert stats["n_missing_packets"] == 0 and stats["n_failures"] == 0
    assert stats["n_received_packets"] >= 6 * 4  # 3072-byte frames in 1000-byte packets + leader/trailer
    assert {"n_resent_packets", "n_resend_requests"} <= set(stats)


def test_gige_address_must_be_an_ip_literal():
    with pytest.raises(RigError, match=r"device address 'camera.local' is not an IPv4 address"):
        Rig.open(gige_rig(device={"address": "camera.local"}))


def test_studio_devices_lists_the_fake_camera(capsys):
    from studio.cli import main

    assert main(["devices", "--backend", "aravis", "--aravis-interfaces", "Fake", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["unavailable"] == {}
    assert out["devices"]["aravis"] == [{"id": "Fake_1", "vendor": "Aravis", "model": "Fake", "serial": "1",
                                         "interface": "Fake", "address": "0.0.0.0", "pixel_format": "Mono8"}]
    assert main(["devices", "--backend", "aravis", "--aravis-interfaces", "Firewire"]) == 0
    assert ("aravis: unavailable — aravis backend: option interfaces ['Firewire']: expected a list of "
            "['Fake', 'USB3Vision', 'GigEVision']") in capsys.readouterr().out


def test_capture_killed_at_a_random_instant_leaves_a_readable_session(tmp_path):
    import sys

    from rigkit import kill_after_rows

    out = tmp_path / "killed"
    kill_after = int(np.random.default_rng(16).integers(3, 15))  # rows on disk when SIGKILL lands
    kill_after_rows([sys.executable, "-m", "studio", "capture", "--rig", str(RIG_YAML), "--out", str(out),
                     "--frames", "100000"], out, kill_after, timeout=60.0)  # fmt: skip
    s = Session.open(out)
    assert s.status == "recording" and len(s.frame_indices) >= kill_after
    assert s.frame_indices == list(range(len(s.frame_indices)))
    for i in s.frame_indices:
        for cam in ("cam0", "cam1"):
            ramp_offset(s.image(cam, i))
    ids = [s.frame_meta(i)["frame_ids"]["cam0"] for i in s.frame_indices]
    assert all(b > a for a, b in zip(ids, ids[1:]))


def test_action_mode_is_refused_with_the_reason():
    d = _as_dict()
    d["trigger"] = {"mode": "action"}
    with pytest.raises(RigError, match=r"node TriggerSource='Action1' refused: allowed values are Line0, Software"):
        Rig.open(d)
