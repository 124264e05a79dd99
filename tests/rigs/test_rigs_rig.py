"""Rig descriptions, the simulated backend, the camera interface and Rig.open."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from rigkit import CAMERAS, make_source, rig_dict, source_image

from rigs import (
    CameraDevice,
    EndOfStream,
    Frame,
    FrameQueue,
    FrameTimeout,
    Rig,
    RigDescription,
    RigError,
    default_rig_path,
    register_backend,
)
from rigs.backends._pixels import convert_pixels, gain_scale

PERIOD = 1e9 / 60.0


@pytest.fixture(scope="module")
def source(tmp_path_factory) -> Path:
    return make_source(tmp_path_factory.mktemp("rigsrc") / "src", n=5)


# -- descriptions -----------------------------------------------------------------------------
def test_shipped_default_rig():
    desc = RigDescription.load(Path(str(default_rig_path())))
    assert desc.name == "simulated" and desc.frame_rate == 60.0
    assert desc.camera_names == ["cam0", "cam1", "cam2", "cam3"]
    for cam in desc.cameras.values():
        assert (cam.backend, cam.pixel_format, cam.width, cam.height) == ("simulated", "RGB8", 656, 490)
        assert cam.options["source"].parts[-3:] == ("samples", "walk", "spec.yaml")
    assert desc.sync.ptp and desc.sync.tolerance_ns == 2_000_000
    assert desc.trigger.genicam == {"TriggerMode": "On", "TriggerSelector": "FrameStart", "TriggerSource": "Software"}


def test_spec_source_must_be_rendered_first():
    with pytest.raises(RigError, match="scene spec.*ensure_rendered"):
        Rig.open(Path(str(default_rig_path())))


def test_load_yaml_every_field(tmp_path, source):
    d = rig_dict("src", exposure=8000.0, gain=1.5, width=32, height=20, jitter_ms=0.1)
    d["trigger"] = {"mode": "hardware", "line": "Line1"}
    d["sync"] = {"ptp": False, "tolerance_ms": 0.5, "key": "timestamp", "max_pending": 5}
    d["calibration"] = "calib/calibration.json"
    d["cameras"]["cam2"] = {"pixel_format": "Mono16", "device": {"serial": "21345"}}
    (tmp_path / "rig.yaml").write_text(yaml.safe_dump(d))
    desc = RigDescription.load(tmp_path / "rig.yaml")
    assert desc.calibration == (tmp_path / "calib/calibration.json").resolve()
    assert desc.trigger.genicam["TriggerSource"] == "Line1"
    assert (desc.sync.ptp, desc.sync.tolerance_ns, desc.sync.key, desc.sync.max_pending) == (False, 500_000, "timestamp", 5)
    c2, c0 = desc.cameras["cam2"], desc.cameras["cam0"]
    assert c2.pixel_format == "Mono16" and c2.device == {"serial": "21345"}
    assert c0.options["source"] == (tmp_path / "src").resolve()
    f = c0.features(desc.frame_rate, desc.trigger, desc.sync.ptp)
    assert f == {"PixelFormat": "RGB8", "AcquisitionFrameRate": 60.0, "Width": 32, "Height": 20,
                 "ExposureTime": 8000.0, "Gain": 1.5, "TriggerMode": "On", "TriggerSelector": "FrameStart",
                 "TriggerSource": "Line1", "GevIEEE1588": False}  # fmt: skip
    free = RigDescription.from_dict({**d, "trigger": {"mode": "free-run"}})
    assert free.trigger.genicam == {"TriggerMode": "Off"}
    over = desc.with_overrides(frame_rate=30, exposure=5000.0, realtime=True, source=tmp_path, calibration="x.json")
    assert over.frame_rate == 30.0 and over.cameras["cam1"].exposure == 5000.0
    assert over.cameras["cam3"].options["realtime"] is True and over.cameras["cam3"].options["source"] == tmp_path
    assert over.calibration == Path("x.json").resolve()


def _broken(**changes):
    d = rig_dict("src")
    for key, value in changes.items():
        if value is ...:
            d.pop(key)
        else:
            d[key] = value
    return d


@pytest.mark.parametrize(
    "d, match",
    [
        (["not", "a", "mapping"], "mapping at the top level"),
        (_broken(format="studio.other"), "field 'format'"),
        (_broken(version="1"), "field 'version': expected an integer"),
        (_broken(version=2), "unsupported major version 2"),
        (_broken(extra=1), "field 'extra': unknown key"),
        (_broken(name=""), "field 'name'"),
        (_broken(frame_rate=...), "field 'frame_rate': expected a number"),
        (_broken(frame_rate=-5), "field 'frame_rate': expected a positive"),
        (_broken(trigger=[1]), "field 'trigger'"),
        (_broken(trigger={"mode": "laser"}), "field 'trigger.mode'"),
        (_broken(trigger={"mode": "hardware"}), "field 'trigger.line'"),
        (_broken(trigger={"selector": "LineStart"}), "field 'trigger.selector'"),
        (_broken(sync=3), "field 'sync'"),
        (_broken(sync={"ptp": "yes"}), "field 'sync.ptp'"),
        (_broken(sync={"tolerance_ms": -1}), "field 'sync.tolerance_ms'"),
        (_broken(sync={"key": "index"}), "field 'sync.key'"),
        (_broken(sync={"max_pending": 0}), "field 'sync.max_pending'"),
        (_broken(calibration=5), "field 'calibration'"),
        (_broken(defaults=[1]), "field 'defaults'"),
        (_broken(cameras={}), "field 'cameras'"),
        (_broken(cameras={"a/b": {}}), "without '/'"),
        (_broken(cameras={"cam0": 7}), "field 'cameras.cam0'"),
        (_broken(defaults={}, cameras={"cam0": {}}), "field 'cameras.cam0.backend'"),
        (_broken(cameras={"cam0": {"device": 3}}), "field 'cameras.cam0.device'"),
        (_broken(cameras={"cam0": {"pixel_format": "YUV422_8"}}), "field 'cameras.cam0.pixel_format'"),
        (_broken(cameras={"cam0": {"width": 0}}), "field 'cameras.cam0.width'"),
        (_broken(cameras={"cam0": {"exposure": "long"}}), "field 'cameras.cam0.exposure'"),
        (_broken(cameras={"cam0": {"source": 5}}), "field 'cameras.cam0.source': expected a path"),
    ],
)
def test_description_errors_name_file_and_field(tmp_path, d, match):
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(d))
    with pytest.raises(RigError, match=f"bad.yaml.*{match}"):
        RigDescription.load(path)


def test_description_file_errors(tmp_path):
    with pytest.raises(RigError, match="missing.yaml: cannot read"):
        RigDescription.load(tmp_path / "missing.yaml")
    (tmp_path / "x.yaml").write_text("a: [1, 2\n")
    with pytest.raises(RigError, match="x.yaml: not valid YAML"):
        RigDescription.load(tmp_path / "x.yaml")
    desc = RigDescription.from_dict(rig_dict("src"))
    with pytest.raises(RigError, match="field 'frame_rate'"):
        desc.with_overrides(frame_rate=0)
    with pytest.raises(RigError, match="field 'sync'"):
        desc.with_overrides(sync={"ptp": True})
    with pytest.raises(TypeError, match="Rig.open expects"):
        Rig.open(42)


# -- simulated backend ----------------------------------------------------------------------------
def test_simulated_rig_delivers_looping_source_with_clock_and_ids(source):
    with Rig.open(rig_dict(source), epoch_ns=1_000) as rig:
        assert rig.calibration_path == source / "calibration.json"
        mfs = list(rig.multiframes(12))
        st = rig.stats
    assert [mf.index for mf in mfs] == list(range(12))
    for k, mf in enumerate(mfs):
        assert mf.frame_ids == dict.fromkeys(CAMERAS, k)
        assert mf.timestamps_ns == dict.fromkeys(CAMERAS, 1_000 + int(round(k * PERIOD)))
        for c, cam in enumerate(CAMERAS):
            np.testing.assert_array_equal(mf.images[cam], source_image(c, k % 5))
    assert st.sync.emitted == 12 and st.sync.incomplete == 0
    assert all(s.delivered >= 12 and s.queue_dropped == 0 for s in st.cameras.values())


def test_simulated_drops_duplicates_jitter_and_end_of_stream(source):
    d = rig_dict(source, loop=False, jitter_ms=0.3)
    d["cameras"]["cam1"].update(drop_frames=[1, 3])
    d["cameras"]["cam2"].update(duplicate_frames=[0, 2, 4])
    with Rig.open(d) as rig:
        mfs = list(rig.multiframes(None))  # ends with the source (loop: false)
        st = rig.stats.sync
    assert [mf.frame_ids["cam0"] for mf in mfs] == [0, 2, 4]
    assert st.dropped == {"cam0": 0, "cam1": 2, "cam2": 0, "cam3": 0}
    assert st.duplicates["cam2"] == 3 and st.incomplete == 2
    spreads = [mf.spread_ns for mf in mfs]
    assert 0 < max(spreads) <= 2_000_000


def test_simulated_random_drops_are_seeded(source):
    def run(seed):
        with Rig.open(rig_dict(source, drop_probability=0.2, max_frames=40, seed=seed)) as rig:
            ids = [mf.frame_ids["cam0"] for mf in rig.multiframes(None)]
            return ids, rig.stats.sync
    a, sa = run(1)
    b, _ = run(1)
    c, _ = run(2)
    assert a == b != c
    assert sa.emitted == len(a) and 38 <= sa.emitted + sa.incomplete <= 40  # trailing all-lost instants are invisible
    assert 10 < sum(sa.dropped.values()) < 60  # 160 frames at p = 0.2


def test_clock_offset_beyond_tolerance_never_mixes_instants(source):
    d = rig_dict(source, max_frames=6)
    d["cameras"]["cam3"]["clock_offset_ms"] = 5.0
    with Rig.open(d) as rig:
        assert list(rig.multiframes(None)) == []
        st = rig.stats.sync
    assert st.mismatched == {"cam0": 0, "cam1": 0, "cam2": 0, "cam3": 6} and st.incomplete == 6


def test_exposure_gain_roi_and_pixel_formats(source):
    src0 = source_image(0, 0)
    with Rig.open(rig_dict(source, cameras=("cam0",), exposure=20000.0)) as rig:
        cam = rig.cameras["cam0"]
        with _started(cam).fetch(timeout=5) as f:
            expected = np.clip(src0.astype(np.int32) * 2, 0, 255).astype(np.uint8)
            np.testing.assert_array_equal(f.image, expected)
        cam.stop()
        cam.configure(ExposureTime=10000.0, Gain=6.020599913, PixelFormat="Mono16", Width=10, Height=8,
                      OffsetX=3, OffsetY=2)  # fmt: skip
        assert cam.get("Width") == 10 and cam.features["PixelFormat"] == "Mono16"
        with _started(cam).fetch(timeout=5) as f:
            assert f.image.shape == (8, 10) and f.image.dtype == np.uint16
            gray = np.rint(src0[2:10, 3:13].astype(np.float32) @ np.float32([0.299, 0.587, 0.114]))
            expected = np.clip(np.rint(gray * 257 * np.float32(2.0)), 0, 65535)
            np.testing.assert_allclose(f.image, expected, atol=1)
        assert cam.stats.delivered == 2


def _started(cam):
    cam.start()
    return cam


def test_pixel_conversion_functions():
    rgb = np.array([[[10, 20, 30]]], np.uint8)
    assert convert_pixels(rgb, "RGB8") is rgb
    np.testing.assert_array_equal(convert_pixels(rgb, "RGB16"), rgb.astype(np.uint16) * 257)
    assert convert_pixels(rgb, "Mono8")[0, 0] == round(0.299 * 10 + 0.587 * 20 + 0.114 * 30)
    mono16 = np.array([[65535, 256]], np.uint16)
    np.testing.assert_array_equal(convert_pixels(mono16, "RGB8"), [[[255] * 3, [1] * 3]])
    assert convert_pixels(rgb, "RGB8", scale=100.0)[0, 0].tolist() == [255, 255, 255]
    assert gain_scale(5000.0, 20.0, 10000.0) == pytest.approx(5.0)


def test_realtime_pacing_timeout_and_queue_drops(source):
    with Rig.open(rig_dict(source, cameras=("cam0",), realtime=True), frame_rate=30.0) as rig:
        t0 = time.monotonic()
        mfs = list(rig.multiframes(6))
        assert time.monotonic() - t0 >= 5 / 30 - 0.01
        assert len(mfs) == 6
    with Rig.open(rig_dict(source, cameras=("cam0",), realtime=True), frame_rate=2.0) as rig:
        cam = rig.cameras["cam0"]
        cam.start()
        with cam.fetch(timeout=2.0) as f:  # frame 0 is due at once
            assert f.frame_id == 0
        with pytest.raises(FrameTimeout, match="no frame within 0.01 s"):
            with cam.fetch(timeout=0.01):
                pass
    with Rig.open(rig_dict(source, cameras=("cam0",), realtime=True, queue_size=2), frame_rate=500.0) as rig:
        cam = rig.cameras["cam0"]
        cam.start()
        time.sleep(0.1)
        assert cam.stats.queue_dropped > 5 and cam.stats.queue_depth == 2


def test_camera_feature_errors(source):
    with Rig.open(rig_dict(source, cameras=("cam0",))) as rig:
        cam = rig.cameras["cam0"]
        assert "simulated" in repr(cam) and "idle" in repr(cam)
        with pytest.raises(RigError, match="'cam0': unknown feature 'Brightness'"):
            cam.configure(Brightness=3)
        with pytest.raises(RigError, match="unknown feature 'Brightness'"):
            cam.get("Brightness")
        with pytest.raises(RigError, match="Width expects int"):
            cam.configure(Width=10.5)
        with pytest.raises(RigError, match="GevIEEE1588 expects bool"):
            cam.configure(GevIEEE1588=1)
        with pytest.raises(RigError, match="PixelFormat expects str"):
            cam.configure(PixelFormat=8)
        with pytest.raises(RigError, match="Gain expects float"):
            cam.configure(Gain=True)
        with pytest.raises(RigError, match="PixelFormat='BayerRG8' not supported"):
            cam.configure(PixelFormat="BayerRG8")
        with pytest.raises(RigError, match="OffsetX must be >= 0"):
            cam.configure(OffsetX=-1)
        with pytest.raises(RigError, match="ExposureTime must be > 0"):
            cam.configure(ExposureTime=0.0)
        with pytest.raises(RigError, match="region 50x30\\+0\\+0 exceeds the source size 40x30"):
            cam.configure(Width=50)
        with pytest.raises(RigError, match="fetch\\(\\) before start\\(\\)"):
            with cam.fetch():
                pass
        cam.start()
        assert "streaming" in repr(cam)
        with pytest.raises(RigError, match="Width cannot change while streaming"):
            cam.configure(Width=20)
        cam.configure(Gain=2.0)  # allowed while streaming
        assert cam.get("Gain") == 2.0
        rig.close()
        assert "closed" in repr(cam)
        with pytest.raises(RigError, match="camera 'cam0' is closed"):
            cam.start()
        with pytest.raises(RigError, match="rig 'test-rig' is closed"):
            next(rig.multiframes(1))


@pytest.mark.parametrize(
    "options, match",
    [
        ({"no_source": True}, "needs option 'source'"),
        ({"bogus": 1}, "unknown simulated option 'bogus'"),
        ({"drop_probability": 2}, r"field 'cameras.cam0.drop_probability': expected a number between 0.0 and 1.0, got 2"),
        ({"duplicate_frames": 5}, "duplicate_frames must be a list"),
        ({"max_frames": -1}, r"field 'cameras.cam0.max_frames': expected an integer >= 0, got -1"),
        ({"jitter_ms": -1.0}, r"field 'cameras.cam0.jitter_ms': expected a number between 0.0 and 1000.0"),
        ({"jitter_ms": float("nan")}, r"field 'cameras.cam0.jitter_ms': expected a finite number, got nan"),
        ({"queue_size": "8"}, r"field 'cameras.cam0.queue_size': expected an integer, got '8'"),
        ({"queue_size": 2.5}, r"field 'cameras.cam0.queue_size': expected an integer, got 2.5"),
        ({"realtime": "no"}, r"field 'cameras.cam0.realtime': expected true or false, got 'no'"),
        ({"source_camera": "camZ"}, "has no camera 'camZ'"),
    ],
)
def test_simulated_option_errors(source, options, match):
    no_source = options.pop("no_source", False)
    d = rig_dict(None if no_source else source, cameras=("cam0",), **options)
    with pytest.raises(RigError, match=match):
        Rig.open(d)


def test_source_errors(tmp_path):
    with pytest.raises(RigError, match="cannot open source session.*no such capture-session folder"):
        Rig.open(rig_dict(tmp_path / "nope"))
    empty = make_source(tmp_path / "empty", n=0)
    with pytest.raises(RigError, match="has no complete frames"):
        Rig.open(rig_dict(empty))
    no_bg = make_source(tmp_path / "nobg", n=2, cameras=("cam0",), backgrounds=0)
    with Rig.open(rig_dict(no_bg, cameras=("cam0",))) as rig:
        with pytest.raises(RigError, match="has no background frames"):
            rig.background_frames(2)


def test_background_frames_cycle_source(source):
    with Rig.open(rig_dict(source, cameras=("cam0", "cam1"))) as rig:
        bg = rig.background_frames(3)
    assert sorted(bg) == ["cam0", "cam1"] and len(bg["cam1"]) == 3
    np.testing.assert_array_equal(bg["cam1"][2], source_image(1, 1000))


# -- backend registry and the CameraDevice base ---------------------------------------------------
class FakeCamera(CameraDevice):
    """A minimal backend: frames from a list, records its lifecycle in a shared log."""

    backend = "fake"
    buffers_reused = True

    def __init__(self, name, log, frames):
        super().__init__(name, {"Width": 4})
        self.log, self.frames = log, list(frames)

    def _start(self):
        self.log.append(("start", self.name))

    def _stop(self):
        self.log.append(("stop", self.name))

    def _next(self, timeout):
        if not self.frames:
            time.sleep(min(timeout, 0.001))
            raise FrameTimeout(self.name)
        return self.frames.pop(0)

    def _release(self, frame):
        self.log.append(("release", self.name))

    def _close(self):
        self.log.append(("close", self.name))


def test_custom_backend_cleanup_order_and_timeout():
    log = []

    def factory(config, description, *, epoch_ns, shared):
        n = 2 if config.name == "a" else 1
        return FakeCamera(config.name, log, [Frame(config.name, np.zeros(1), k, k) for k in range(n)])

    register_backend("fake", factory)
    d = rig_dict(None, cameras=("a", "b"))
    d["defaults"] = {"backend": "fake"}
    rig = Rig.open(d)
    assert rig.cameras["a"].get("Width") == 4
    with pytest.raises(RigError, match="Width is not set yet|feature Height is not set yet"):
        rig.cameras["a"].get("Height")
    (mf,) = rig.multiframes(1)
    assert mf.frame_ids == {"a": 0, "b": 0}
    with pytest.raises(RigError, match="no frame from any camera for 0.05 s"):
        list(rig.multiframes(2, timeout=0.05))
    with rig:
        pass
    assert log[:2] == [("start", "a"), ("start", "b")]
    assert log[-4:] == [("stop", "b"), ("close", "b"), ("stop", "a"), ("close", "a")]
    assert ("release", "a") in log
    with pytest.raises(ValueError, match="non-empty string"):
        register_backend("", factory)


@pytest.mark.parametrize("backend, match", [("gopro", "unknown camera backend 'gopro'")])
def test_unknown_backends(backend, match):
    d = rig_dict(None)
    d["defaults"]["backend"] = backend
    with pytest.raises(RigError, match=match):
        Rig.open(d)


def test_frame_queue_drops_oldest():
    q = FrameQueue(2)
    assert q.put(1) and q.put(2) and not q.put(3)
    assert q.dropped == 1 and len(q) == 2 and not q.put_wait(4, timeout=0.01)
    assert q.get(0) == 2 and q.put_wait(5, timeout=0.01) and q.dropped == 1
    with pytest.raises(ValueError, match="maxsize must be >= 1"):
        FrameQueue(0)


def test_end_of_stream_is_sticky(source):
    with Rig.open(rig_dict(source, cameras=("cam0",), loop=False)) as rig:
        cam = rig.cameras["cam0"]
        cam.start()
        for _ in range(5):
            with cam.fetch(timeout=5):
                pass
        for _ in range(2):
            with pytest.raises(EndOfStream, match="end of stream"):
                with cam.fetch(timeout=5):
                    pass


class FailingCamera(FakeCamera):
    fail = ()

    def _start(self):
        if "start" in self.fail:
            raise RigError(f"camera {self.name!r}: start refused")
        super()._start()

    def _stop(self):
        super()._stop()
        if "stop" in self.fail:
            raise RigError(f"camera {self.name!r}: stop failed")

    def _close(self):
        super()._close()
        if "close" in self.fail:
            raise RigError(f"camera {self.name!r}: close failed")


def _failing_rig(log, fails):
    def factory(config, description, *, epoch_ns, shared):
        cam = FailingCamera(config.name, log, [])
        cam.fail = fails.get(config.name, ())
        return cam

    register_backend("failing", factory)
    d = rig_dict(None, cameras=("a", "b", "c"))
    d["defaults"] = {"backend": "failing"}
    return Rig.open(d)


def test_start_failure_stops_the_cameras_already_started():
    log = []
    rig = _failing_rig(log, {"c": ("start",)})
    with pytest.raises(RigError, match="'c': start refused"):
        rig.start()
    assert log == [("start", "a"), ("start", "b"), ("stop", "b"), ("stop", "a")]
    assert not rig.is_streaming
    with pytest.raises(ValueError, match="n must be >= 0"):
        next(rig.multiframes(-1))
    rig.close()


def test_stop_and_close_reach_every_camera_then_report_the_first_failure():
    log = []
    rig = _failing_rig(log, {"b": ("stop", "close")})
    rig.start()
    with pytest.raises(RigError, match="'b': stop failed"):
        rig.stop()
    assert [e for e in log if e[0] == "stop"] == [("stop", "c"), ("stop", "b"), ("stop", "a")]
    log.clear()
    rig.start()
    with pytest.raises(RigError, match="'b': close failed"):
        rig.close()
    assert [e[1] for e in log if e[0] == "close"] == ["c", "b", "a"]
    rig.close()  # idempotent


def test_corrupt_source_frame_is_reported_by_fetch(tmp_path):
    src = make_source(tmp_path / "src", n=3, cameras=("cam0",))
    with Rig.open(rig_dict(src, cameras=("cam0",), preload=False)) as rig:
        (src / "frames" / "cam0" / "000001.png").write_bytes(b"\x89PNG\r\n\x1a\n" + b"\0" * 50)
        (src / "background" / "cam0" / "000000.png").write_bytes(b"garbage")
        with pytest.raises(RigError, match="'cam0': producer failed"):
            list(rig.multiframes(3))
        with pytest.raises(RigError, match="'cam0'.*background 0"):
            rig.background_frames(1)
