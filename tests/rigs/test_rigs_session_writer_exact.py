"""SessionWriter against what is on disk, read here with json / csv / OpenCV, and every refusal
by its whole message: the session.json written at creation and close key by key, the CSV row
of each frame, where frames and backgrounds go, what is passed to the image writer (compression,
fsync) and on which threads, the drops record, and the messages a user reads.
"""

from __future__ import annotations

import errno
import json
import logging
import re
import threading
import time

import numpy as np
import pytest

from rigs import imageio
from rigs.session import SessionError, SessionWriter
from rigs.session import writer as writer_module

CAMS = ["cam0", "cam1"]
H, W = 6, 8


def img(value=0, shape=(H, W, 3), dtype=np.uint8):
    return np.full(shape, value, dtype)


def json_reason(obj) -> str:
    """json's own message for ``obj`` (compact encoding, as the writer checks it)."""
    with pytest.raises(ValueError) as info:
        json.dumps(obj, allow_nan=False)
    return str(info.value)


def exactly(message: str):
    return pytest.raises(SessionError, match="^" + re.escape(message) + "$")


def test_created_session_json_and_csv_header(tmp_path):
    path = tmp_path / "s"
    w = SessionWriter.create(path, CAMS, rig="lab", fps=25, pixel_formats={"cam0": "BayerRG8"},
                             calibration={"k": 1}, metadata={"who": "me"}, durability="fsync", compression=3)
    info = json.loads((path / "session.json").read_text())
    start = info.pop("start_time")
    assert re.fullmatch(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{3}\+00:00", start)
    assert info == {"format": "studio.capture-session", "version": 1, "rig": "lab", "cameras": CAMS, "fps": 25.0,
                    "pixel_formats": {"cam0": "BayerRG8"}, "end_time": None, "status": "recording",
                    "frame_count": None, "images": {}, "durability": "fsync", "png_compression": 3,
                    "calibration": "calibration.json", "metadata": {"who": "me"}}
    assert isinstance(info["fps"], float)
    assert (path / "calibration.json").read_text() == '{\n  "k": 1\n}\n'
    assert (path / "frames.csv").read_text() == ("index,cam0.timestamp_ns,cam0.frame_id,cam0.flag,"
                                                 "cam1.timestamp_ns,cam1.frame_id,cam1.flag\n")
    assert sorted(p.name for p in (path / "frames").iterdir()) == CAMS
    assert sorted(p.name for p in (path / "background").iterdir()) == CAMS
    assert w.path == path and w.cameras == CAMS and w.frame_count == 0 and w.closed is False
    assert w.info == {**info, "start_time": start}
    assert repr(w) == f"SessionWriter({str(path)!r}, cameras=['cam0', 'cam1'], frames=0, open)"
    w.close()
    assert w.closed is True
    assert repr(w) == f"SessionWriter({str(path)!r}, cameras=['cam0', 'cam1'], frames=0, closed)"
    plain = SessionWriter.create(tmp_path / "p", ["a"])
    info = json.loads((tmp_path / "p" / "session.json").read_text())
    assert (info["rig"], info["fps"], info["calibration"], info["metadata"], info["durability"],
            info["png_compression"], info["pixel_formats"]) == ("unknown", None, None, {}, "rename", 1, {})
    assert not (tmp_path / "p" / "calibration.json").exists()
    plain.close()


def test_frames_rows_paths_and_close(tmp_path):
    path = tmp_path / "s"
    w = SessionWriter.create(path, CAMS)
    assert w.frame_path("cam1", 42) == path / "frames" / "cam1" / "000042.png"
    assert w.frame_path("cam1", 42, ".exr") == path / "frames" / "cam1" / "000042.exr"
    assert w.background_path("cam0", 7) == path / "background" / "cam0" / "000007.png"
    assert w.write_background("cam0", 7, img(3)) == path / "background" / "cam0" / "000007.png"
    w.write_frame(5, {"cam0": img(1), "cam1": img(2)}, timestamps_ns={"cam0": None, "cam1": 1234},
                  frame_ids={"cam0": np.int64(9), "cam1": None}, flags={"cam1": "late"})
    w.write_frame(6, {"cam0": img(1), "cam1": img(2)})
    assert (path / "frames.csv").read_text().splitlines()[1:] == [",".join(["5", "", "9", "ok", "1234", "", "late"]),
                                                                   "6,,,ok,,,ok"]
    assert (path / "frames" / "cam1" / "000005.png").is_file() and w.frame_count == 2
    assert w.truth_dir == path / "truth" and (path / "truth").is_dir()
    assert w.truth_dir == path / "truth"  # existing: fine
    w.record_drops({"incomplete_instants": 3, "cameras": {"cam0": {"dropped": 2}}})
    w.close()
    w.close()  # twice: nothing
    info = json.loads((path / "session.json").read_text())
    assert (info["status"], info["frame_count"]) == ("complete", 2)
    assert info["drops"] == {"incomplete_instants": 3, "cameras": {"cam0": {"dropped": 2}}}
    assert info["end_time"] >= info["start_time"]
    assert info["images"] == {c: {"width": W, "height": H, "channels": 3, "dtype": "uint8", "suffix": ".png"}
                              for c in CAMS}


def test_image_specs_of_one_two_and_four_channels(tmp_path):
    """(H, W, 1) is described as one channel like (H, W), which it may alternate with; a
    float (H, W, 2) image keeps two channels; RGBA is storable."""
    w = SessionWriter.create(tmp_path / "s", ["a", "b", "c"])
    w.write_frame(0, {"a": img(1, (H, W, 1)), "b": img(0.5, (H, W, 2), np.float32), "c": img(1, (H, W, 4))})
    w.write_frame(1, {"a": img(1, (H, W)), "b": img(0.5, (H, W, 2), np.float32), "c": img(1, (H, W, 4))})
    specs = json.loads((tmp_path / "s" / "session.json").read_text())["images"]
    assert [specs[c]["channels"] for c in "abc"] == [1, 2, 4]
    assert specs["b"] == {"width": W, "height": H, "channels": 2, "dtype": "float32", "suffix": ".exr"}
    with exactly("frame 2, camera 'c': shape (6, 8, 5) is not (H, W) or (H, W, C) with C in 1..4"):
        w.write_frame(2, {"a": img(1, (H, W)), "b": img(0.5, (H, W, 2), np.float32), "c": img(1, (H, W, 5))})
    w.close()


def test_image_refusals_whole(tmp_path):
    path = tmp_path / "s"
    w = SessionWriter.create(path, CAMS)
    w.write_background("cam0", 0, img(1))
    w.write_background("cam0", 1, img(1))  # same spec: nothing new recorded
    with exactly("frame 0, camera 'cam0': image is 4x3x3 uint8 (uint8), expected 8x6x3 uint8 like the camera's "
                 "first image (field 'images.cam0' of session.json)"):
        w.write_frame(0, {"cam0": img(1, (3, 4, 3)), "cam1": img(1)})
    with exactly("frame 0, camera 'cam1': dtype int32 is not storable (expected uint8, uint16, bool, float32 or "
                 "float16)"):
        w.write_frame(0, {"cam0": img(1), "cam1": img(1, dtype=np.int32)})
    with exactly("frame 0: images must be a dict {camera: array}, got list"):
        w.write_frame(0, [img(1), img(1)])
    with exactly("frame 0: missing image for camera(s) ['cam1'] (every frame needs all of ['cam0', 'cam1'])"):
        w.write_frame(0, {"cam0": img(1)})
    with exactly("frame 0: unknown camera(s) ['x'] (expected ['cam0', 'cam1'])"):
        w.write_frame(0, {"cam0": img(1), "cam1": img(1), "x": img(1)})
    with exactly("frame 0: flags['cam0'] = 'a\\nb' is not a string without commas, quotes or newlines"):
        w.write_frame(0, {"cam0": img(1), "cam1": img(1)}, flags={"cam0": "a\nb"})
    with exactly("frame 0: flags['cam0'] = 3 is not a string without commas, quotes or newlines"):
        w.write_frame(0, {"cam0": img(1), "cam1": img(1)}, flags={"cam0": 3})
    with exactly("frame 0: flags names unknown camera 'q' (expected ['cam0', 'cam1'])"):
        w.write_frame(0, {"cam0": img(1), "cam1": img(1)}, flags={"q": "ok"})
    with exactly("frame 0: timestamps_ns['cam1'] = True is not an integer"):
        w.write_frame(0, {"cam0": img(1), "cam1": img(1)}, timestamps_ns={"cam1": True})
    with exactly("frame 0: frame_ids names unknown camera 'q' (expected ['cam0', 'cam1'])"):
        w.write_frame(0, {"cam0": img(1), "cam1": img(1)}, frame_ids={"q": 1})
    w.write_frame(0, {"cam0": img(1), "cam1": img(1)})
    with exactly(f"frame 0: duplicate index (already in {path / 'frames.csv'})"):
        w.write_frame(0, {"cam0": img(1), "cam1": img(1)})
    with exactly("background 0, camera 'cam0': duplicate background index"):
        w.write_background("cam0", 0, img(1))
    with exactly("background 'x': index 'x' is not a non-negative integer"):
        w.write_background("cam0", "x", img(1))
    with exactly("background 2: unknown camera 'c9' (expected one of ['cam0', 'cam1'])"):
        w.write_background("c9", 2, img(1))
    w.close()
    with exactly(f"frame 1: session {path} is closed"):
        w.write_frame(1, {"cam0": img(1), "cam1": img(1)})
    with exactly(f"background 3: session {path} is closed"):
        w.write_background("cam0", 3, img(1))
    with exactly(f"record_drops: session {path} is closed"):
        w.record_drops({})


def test_drops_must_be_json(tmp_path):
    w = SessionWriter.create(tmp_path / "s", CAMS)
    with exactly(f"record_drops: expected JSON-serialisable counts ({json_reason({'late': float('nan')})})"):
        w.record_drops({"late": float("nan")})
    w.record_drops({"late": 1})
    w.close("aborted")
    info = json.loads((tmp_path / "s" / "session.json").read_text())
    assert (info["status"], info["drops"]) == ("aborted", {"late": 1})


def test_compression_and_fsync_reach_every_write(tmp_path, monkeypatch):
    """The writer passes its PNG level and, with durability 'fsync', fsync=True to every image
    write and every session.json update; with 'rename' fsync=False for the images."""
    calls = []
    real_write, real_json = imageio.write_image, imageio.atomic_write_json

    def write_image(path, array, compression=1, *, fsync=False):
        calls.append(("image", path.name, compression, fsync))
        return real_write(path, array, compression, fsync=fsync)

    def atomic_write_json(path, obj, *, fsync=True):
        calls.append(("json", path.name, None, fsync))
        return real_json(path, obj, fsync=fsync)

    monkeypatch.setattr(imageio, "write_image", write_image)
    monkeypatch.setattr(imageio, "atomic_write_json", atomic_write_json)
    for durability, sync in (("fsync", True), ("rename", False)):
        calls.clear()
        w = SessionWriter.create(tmp_path / durability, CAMS, durability=durability, compression=7)
        w.write_background("cam0", 0, img(1))
        w.write_frame(0, {"cam0": img(1), "cam1": img(1)})
        w.close()
        assert calls == [("json", "session.json", None, True),
                         ("image", "000000.png", 7, sync), ("json", "session.json", None, sync),
                         ("image", "000000.png", 7, sync), ("image", "000000.png", 7, sync),
                         ("json", "session.json", None, sync), ("json", "session.json", None, True)]


@pytest.mark.parametrize("workers, pooled, most", [(None, False, 1), (1, False, 1), (2, True, 2), (3, True, 3)])
def test_workers_write_a_frame_on_that_many_threads(tmp_path, monkeypatch, workers, pooled, most):
    """workers = 1 writes in the calling thread; more, on a pool of that many threads named
    session-writer (each write held 50 ms so that they overlap)."""
    names, active, peak = [], [0], [0]
    lock = threading.Lock()
    real = imageio.write_image

    def slow(path, array, compression=1, *, fsync=False):
        with lock:
            names.append(threading.current_thread().name)
            active[0] += 1
            peak[0] = max(peak[0], active[0])
        time.sleep(0.05)
        with lock:
            active[0] -= 1
        return real(path, array, compression, fsync=fsync)

    monkeypatch.setattr(imageio, "write_image", slow)
    cams = ["a", "b", "c", "d"]
    w = SessionWriter.create(tmp_path / "s", cams, **({} if workers is None else {"workers": workers}))
    w.write_frame(0, {c: img(1) for c in cams})
    w.close()
    if pooled:
        assert all(n.startswith("session-writer_") for n in names) and len(set(names)) <= workers
    else:
        assert names == [threading.current_thread().name] * 4
    assert peak[0] == most


def test_exit_with_an_exception_logs_a_failed_close(tmp_path, monkeypatch, caplog):
    w = SessionWriter.create(tmp_path / "s", CAMS)

    def full(path, obj, *, fsync=True):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(imageio, "atomic_write_json", full)
    with caplog.at_level(logging.ERROR, logger="rigs.session.writer"):
        with pytest.raises(KeyError):
            with w:
                raise KeyError("x")
    message = (f"close: cannot update {tmp_path / 's' / 'session.json'}: disk full (ENOSPC): [Errno 28] No space "
               "left on device (frames already written stay readable; status remains 'recording')")
    assert [r.getMessage() for r in caplog.records if r.name == "rigs.session.writer"] == [message]
    assert w.closed


def test_calibration_and_folder_refusals_whole(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text("{x")
    with exactly(f"calibration: {bad} is not a JSON file (Expecting property name enclosed in double quotes: line 1 "
                 "column 2 (char 1))"):
        SessionWriter.create(tmp_path / "s", CAMS, calibration=bad)
    bad.write_bytes(b"\xff")
    with exactly(f"calibration: {bad} is not a JSON file ('utf-8' codec can't decode byte 0xff in position 0: "
                 "invalid start byte)"):
        SessionWriter.create(tmp_path / "s", CAMS, calibration=bad)
    with exactly(f"calibration: cannot read {tmp_path / 'none.json'}: No such file or directory"):
        SessionWriter.create(tmp_path / "s", CAMS, calibration=tmp_path / "none.json")
    with exactly("calibration: dict is not JSON-serialisable (Out of range float values are not JSON compliant: "
                 "nan)"):
        SessionWriter.create(tmp_path / "s", CAMS, calibration={"x": float("nan")})
    good = tmp_path / "good.json"
    good.write_bytes(b'{"a": 1}  \n')
    SessionWriter.create(tmp_path / "g", CAMS, calibration=str(good)).close()
    assert (tmp_path / "g" / "calibration.json").read_bytes() == b'{"a": 1}  \n'
    (tmp_path / "f").write_text("x")
    with exactly(f"cannot create session {tmp_path / 'f'}: a file of that name exists"):
        SessionWriter.create(tmp_path / "f", CAMS)
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "x.txt").write_text("x")
    with exactly(f"cannot create session {tmp_path / 'full'}: folder exists and is not empty (pass overwrite=True "
                 "to replace an existing session)"):
        SessionWriter.create(tmp_path / "full", CAMS)
    with exactly(f"cannot overwrite {tmp_path / 'full'}: it is not a capture session (no session.json); refusing "
                 "to delete it"):
        SessionWriter.create(tmp_path / "full", CAMS, overwrite=True)
    assert (tmp_path / "full" / "x.txt").is_file()
    (tmp_path / "empty").mkdir()
    SessionWriter.create(tmp_path / "empty", CAMS).close()  # an empty folder is used
    SessionWriter.create(tmp_path / "g", ["z"], overwrite=True).close()
    assert not (tmp_path / "g" / "calibration.json").exists()
    assert json.loads((tmp_path / "g" / "session.json").read_text())["cameras"] == ["z"]


@pytest.mark.parametrize("kwargs, message", [
    ({"durability": "maybe"}, "durability: 'maybe' is not one of ('rename', 'fsync')"),
    ({"compression": True}, "compression: True is not a PNG level in 0..9"),
    ({"compression": 1.0}, "compression: 1.0 is not a PNG level in 0..9"),
    ({"compression": -1}, "compression: -1 is not a PNG level in 0..9"),
    ({"compression": 10}, "compression: 10 is not a PNG level in 0..9"),
    ({"workers": True}, "workers: True is not a positive integer"),
    ({"workers": 2.0}, "workers: 2.0 is not a positive integer"),
    ({"workers": 0}, "workers: 0 is not a positive integer"),
    ({"fps": True}, "fps: True is not a positive number or None"),
    ({"fps": "30"}, "fps: '30' is not a positive number or None"),
    ({"fps": float("inf")}, "fps: inf is not a positive number or None"),
    ({"fps": 0}, "fps: 0 is not a positive number or None"),
    ({"pixel_formats": {"q": "Mono8"}}, "pixel_formats: camera 'q' is not one of ['cam0', 'cam1']"),
    ({"pixel_formats": {"cam1": None}}, "pixel_formats['cam1']: expected a string, got None"),
    ({"metadata": "x"}, "metadata: expected a dict, got str"),
    ({"metadata": {"x": float("nan")}}, f"metadata: not JSON-serialisable ({json_reason({'x': float('nan')})})"),
    ({"calibration": 3.5}, "calibration: expected a JSON file path, a dict or None, got float"),
])
def test_create_refusals_whole(tmp_path, kwargs, message):
    with exactly(message):
        SessionWriter.create(tmp_path / "s", CAMS, **kwargs)
    assert not (tmp_path / "s").exists()


def test_create_bounds_accepted(tmp_path):
    """The documented ranges' ends: PNG levels 0 and 9, one worker, any positive fps."""
    for k, kwargs in enumerate([{"compression": 0}, {"compression": 9}, {"workers": 1}, {"fps": 0.5},
                                {"fps": np.float64(30.0)}]):
        SessionWriter.create(tmp_path / str(k), CAMS, **kwargs).close()
    assert json.loads((tmp_path / "1" / "session.json").read_text())["png_compression"] == 9


def test_failed_writes_name_the_frame_and_reason(tmp_path, monkeypatch):
    w = SessionWriter.create(tmp_path / "s", CAMS)

    def full(path, array, compression=1, *, fsync=False):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(imageio, "write_image", full)
    with exactly("frame 3: disk full (ENOSPC): [Errno 28] No space left on device; frame not recorded"):
        w.write_frame(3, {"cam0": img(1), "cam1": img(1)})
    with exactly("background 1, camera 'cam1': disk full (ENOSPC): [Errno 28] No space left on device"):
        w.write_background("cam1", 1, img(1))
    monkeypatch.undo()
    w.write_background("cam1", 1, img(1))  # the failed index is free again
    w.close()


def test_module_helpers_are_the_layout_ones():
    assert writer_module.SESSION_JSON == "session.json" and writer_module.FRAMES_CSV == "frames.csv"


def test_nested_folder_created_and_life_cycle_logged(tmp_path, caplog):
    path = tmp_path / "a" / "b" / "s"
    with caplog.at_level(logging.INFO, logger="rigs.session.writer"):
        with SessionWriter.create(path, CAMS) as w:
            w.write_frame(0, {"cam0": img(1), "cam1": img(1)})
            w.write_frame(2, {"cam0": img(1), "cam1": img(1)})
    assert [r.getMessage() for r in caplog.records if r.name == "rigs.session.writer"] == [
        f"created capture session {path} (cameras cam0, cam1)", f"closed capture session {path}: 2 frames, complete"]
    assert json.loads((path / "session.json").read_text())["status"] == "complete"


def test_parallel_writes_get_the_level_and_fsync(tmp_path, monkeypatch):
    calls = []
    real = imageio.write_image

    def write_image(path, array, compression=1, *, fsync=False):
        calls.append((compression, fsync))
        return real(path, array, compression, fsync=fsync)

    monkeypatch.setattr(imageio, "write_image", write_image)
    w = SessionWriter.create(tmp_path / "s", CAMS, durability="fsync", compression=6, workers=2)
    w.write_frame(0, {"cam0": img(1), "cam1": img(1)})
    w.close()
    assert calls == [(6, True), (6, True)]
