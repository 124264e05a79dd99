"""The genicam backend through harvesters and the simulated GenTL producer of the ``genicam``
wheel (``viky.cti``: three devices — red, green, blue balls on white — RGBa8/Mono8 400x400,
no device timestamps)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from rigs import Rig, RigError
from rigs.backends import _genapi

try:
    import genicam
    from rigs.backends.genicam import import_harvesters

    import_harvesters()
except (ImportError, RigError) as exc:  # `make test` installs the [genicam] extra
    pytest.skip(f"genicam backend unavailable: {exc}", allow_module_level=True)

VIKY = Path(genicam.__file__).resolve().parent / "viky.cti"
if not VIKY.is_file():
    pytest.skip(f"the genicam wheel has no simulated producer at {VIKY}", allow_module_level=True)


def viky_rig(serials=("0", "1"), **camera) -> dict:
    defaults = {"backend": "genicam", "producer": str(VIKY), "pixel_format": "RGBa8", **camera}
    return {"format": "studio.rig", "version": 1, "name": "viky", "frame_rate": 30.0,
            "trigger": {"mode": "free-run"}, "sync": {"key": "timestamp", "tolerance_ms": 30.0},
            "defaults": defaults,
            "cameras": {f"cam{s}": {"device": {"serial": s}} for s in serials}}  # fmt: skip


def test_viky_devices_deliver_rgb_in_the_right_channel_order():
    with Rig.open(viky_rig(("0", "1", "2"))) as rig:
        mfs = list(rig.multiframes(4, timeout=3.0))
        stats = {n: c.device_stats() for n, c in rig.cameras.items()}
    for mf in mfs:
        for cam, channel in (("cam0", 0), ("cam1", 1), ("cam2", 2)):
            img = mf.images[cam]
            assert img.shape == (400, 400, 3) and img.dtype == np.uint8
            ball = img.reshape(-1, 3)[(img.reshape(-1, 3) < 200).any(axis=1)]  # not the white background
            assert len(ball) > 100, f"{cam}: no ball drawn"
            assert ball.mean(axis=0).argmax() == channel, f"{cam}: ball colour {ball.mean(axis=0)}"
    for cam in ("cam0", "cam1", "cam2"):
        ids = [mf.frame_ids[cam] for mf in mfs]
        assert all(b > a for a, b in zip(ids, ids[1:]))
        assert stats[cam]["host_timestamps"] >= 4, "viky sends no timestamps: host clock, counted"
        assert stats[cam]["num_images"] >= 4


def test_viky_mono8_size_and_refusals():
    with Rig.open(viky_rig(("2",), pixel_format="Mono8", width=200, height=120)) as rig:
        img = next(rig.multiframes(1, timeout=3.0)).images["cam2"]
        assert rig.cameras["cam2"].node("Width") == 200
    assert img.shape == (120, 200) and img.dtype == np.uint8
    with pytest.raises(RigError, match=r"node PixelFormat='BayerRG8' refused: allowed values are RGBa8, Mono8"):
        Rig.open(viky_rig(("0",), pixel_format="BayerRG8"))
    with pytest.raises(RigError, match=r"node Width=4000 refused: out of range, allowed int in \[100, 800\]"):
        Rig.open(viky_rig(("0",), width=4000))
    with pytest.raises(RigError, match=r"ExposureTime=5000.0 cannot be set: the device has no GenApi node "
                                       r"ExposureTime or ExposureTimeAbs"):
        Rig.open(viky_rig(("0",), exposure=5000.0))
    with pytest.raises(RigError, match=r"GenTL device \{'serial_number': '7'\} cannot be opened"):
        Rig.open(viky_rig(("7",)))
    with pytest.raises(RigError, match=r"GenTL producer .*nope.cti does not exist"):
        Rig.open(viky_rig(("0",), producer="nope.cti"))
    assert not [t for t in _genapi._OPEN if type(t).__name__ == "HarvesterTransport"]


def test_teardown_lets_the_devices_be_opened_again():
    for _ in range(2):
        with pytest.raises(KeyboardInterrupt), Rig.open(viky_rig()) as rig:
            for mf in rig.multiframes(10, timeout=3.0):
                raise KeyboardInterrupt
        assert all(c.transport.acquirer is None for c in rig.cameras.values())
    with Rig.open(viky_rig()) as rig:
        assert len(list(rig.multiframes(2, timeout=3.0))) == 2


def test_no_producer_is_explained(monkeypatch):
    monkeypatch.delenv("GENICAM_GENTL64_PATH", raising=False)
    d = viky_rig(("0",))
    del d["defaults"]["producer"]
    with pytest.raises(RigError, match="no GenTL producer: set option producer"):
        Rig.open(d)
    monkeypatch.setenv("GENICAM_GENTL64_PATH", str(VIKY.parent))
    with Rig.open(d) as rig:
        assert rig.cameras["cam0"].node("PixelFormat") == "RGBa8"


def test_studio_devices_lists_viky_and_explains_a_missing_producer(capsys, monkeypatch):
    from studio.cli import main

    assert main(["devices", "--backend", "genicam", "--producer", str(VIKY), "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)["devices"]["genicam"]
    assert [(r["model"], r["serial"], r["pixel_format"]) for r in rows] == [("Viky", s, "RGBa8") for s in "012"]
    monkeypatch.delenv("GENICAM_GENTL64_PATH", raising=False)
    assert main(["devices", "--backend", "genicam"]) == 0
    assert "genicam: unavailable — genicam backend: no GenTL producer" in capsys.readouterr().out


def test_action_commands_need_a_producer_that_sends_them():
    d = viky_rig(("0",))
    d["trigger"] = {"mode": "action"}
    with pytest.raises(RigError, match=r"TriggerMode='On' cannot be set: the device has no GenApi node TriggerMode"):
        Rig.open(d)
    from rigs.backends.genicam import HarvesterTransport, open_harvester

    entry = open_harvester(None, [VIKY])
    transport = HarvesterTransport(entry, 0, "probe")
    try:
        assert transport.action_issuer() == ("the GenTL producer has no ActionCommand node on its interface or "
                                             "system module")
    finally:
        transport.close()


def test_chunk_mode_on_a_producer_without_timestamp_chunks():
    """viky's chunks carry no timestamp or frame id: chunk mode is on, frames still flow,
    stamped by the host clock (counted), not by a chunk."""
    with Rig.open(viky_rig(("1",), chunks=True)) as rig:
        cam = rig.cameras["cam1"]
        assert cam.node("ChunkModeActive") is True
        mfs = list(rig.multiframes(3, timeout=3.0))
        stats = cam.device_stats()
    assert len(mfs) == 3 and stats["chunk_timestamps"] == 0 and stats["host_timestamps"] >= 3
