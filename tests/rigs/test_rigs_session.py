"""rigs.session: writer/reader round trip, bad input, damaged sessions, disk full."""

from __future__ import annotations

import errno
import json
import os
from pathlib import Path

import numpy as np

import rigs.atomic
import pytest

from rigs import imageio
from rigs.session import Session, SessionError, SessionWriter

CAMS = ["cam0", "cam1", "cam2"]
H, W = 12, 16


def rgb8(index, k=0):
    return np.random.default_rng([index, k]).integers(0, 256, (H, W, 3), dtype=np.uint8)


def gray16(index, k=1):
    return np.random.default_rng([index, k]).integers(0, 65536, (H, W), dtype=np.uint16)


def rgbf(index, k=2):
    return np.random.default_rng([index, k]).random((H, W, 3), dtype=np.float32)


def images(index):
    return {"cam0": rgb8(index), "cam1": gray16(index), "cam2": rgbf(index)}


def simple(index):
    return {cam: rgb8(index, k) for k, cam in enumerate(CAMS)}


def make_session(path: Path, n: int = 4, *, backgrounds: int = 2, close: bool = True) -> SessionWriter:
    writer = SessionWriter.create(path, CAMS, rig="test-rig", fps=30.0)
    for b in range(backgrounds):
        for k, cam in enumerate(CAMS):
            writer.write_background(cam, b, rgb8(100 + b, k))
    for i in range(n):
        writer.write_frame(i, simple(i), timestamps_ns={c: 1000 * i + k for k, c in enumerate(CAMS)})
    if close:
        writer.close()
    return writer


# =========================================================================== round trip


def test_round_trip_every_field(tmp_path):
    calib = tmp_path / "calib_src.json"
    calib.write_bytes(b'{"format": "studio.rig-calibration", "version": 1,\n "cameras": {}}  \n')
    path = tmp_path / "s"
    with SessionWriter.create(
        path,
        CAMS,
        rig="lab-rig",
        fps=60.0,
        pixel_formats={"cam0": "BayerRG8", "cam1": "Mono12"},
        calibration=calib,
        metadata={"subject": "S1", "notes": ["a", 1]},
        compression=0,
    ) as writer:
        for b in range(3):
            writer.write_background("cam0", b, rgb8(50 + b))
            writer.write_background("cam1", b, gray16(50 + b))
            writer.write_background("cam2", b, rgbf(50 + b))
        for i in range(5):
            writer.write_frame(
                i,
                images(i),
                timestamps_ns={"cam0": 10 + i, "cam1": 20 + i},
                frame_ids={"cam0": 100 + i, "cam2": np.int64(300 + i)},
                flags={"cam1": "late"},
            )
        (writer.truth_dir / "body.json").write_text("{}")
        assert writer.frame_count == 5 and not writer.closed
    assert writer.closed

    s = Session.open(path)
    assert s.cameras == CAMS and s.fps == 60.0 and s.status == "complete" and s.rig == "lab-rig"
    assert s.frame_indices == [0, 1, 2, 3, 4] and len(s) == 5 and s.frame_count == 5
    assert s.gaps == [] and s.issues == []
    assert s.info["pixel_formats"] == {"cam0": "BayerRG8", "cam1": "Mono12"}
    assert s.info["metadata"] == {"subject": "S1", "notes": ["a", 1]}
    assert s.info["frame_count"] == 5 and s.info["end_time"] is not None
    assert s.calibration_path.read_bytes() == calib.read_bytes()  # verbatim copy
    assert s.calibration_json()["format"] == "studio.rig-calibration"
    assert (s.truth_dir / "body.json").is_file()
    for cam in CAMS:
        assert s.image_size(cam) == (W, H)
    for i in range(5):
        frame = s.frame(i)
        np.testing.assert_array_equal(frame["cam0"], rgb8(i))
        np.testing.assert_array_equal(frame["cam1"], gray16(i))
        np.testing.assert_array_equal(frame["cam2"], rgbf(i))
        assert frame["cam1"].dtype == np.uint16 and frame["cam2"].dtype == np.float32
        assert s.frame_meta(i) == {
            "index": i,
            "timestamps_ns": {"cam0": 10 + i, "cam1": 20 + i, "cam2": None},
            "frame_ids": {"cam0": 100 + i, "cam1": None, "cam2": 300 + i},
            "flags": {"cam0": "ok", "cam1": "late", "cam2": "ok"},
        }
    assert s.frame_path("cam2", 3) == path / "frames" / "cam2" / "000003.exr"
    assert s.frame_path("cam0", 3).is_file()
    assert [i for i, _ in s.frames()] == [0, 1, 2, 3, 4]
    assert s.background_indices("cam1") == [0, 1, 2]
    for got, want in zip(s.backgrounds("cam2"), [rgbf(50), rgbf(51), rgbf(52)]):
        np.testing.assert_array_equal(got, want)
    report = s.validate(deep=True)
    assert report.ok and report.frames_checked == 5 and report.images_checked == 5 * 3 + 3 * 3
    assert report.notes == () and report.gaps == ()
    header = (path / "frames.csv").read_text().splitlines()[0]
    assert header == (
        "index,cam0.timestamp_ns,cam0.frame_id,cam0.flag,cam1.timestamp_ns,cam1.frame_id,cam1.flag,"
        "cam2.timestamp_ns,cam2.frame_id,cam2.flag"
    )


def test_bool_masks_and_calibration_dict(tmp_path):
    with SessionWriter.create(tmp_path / "s", ["a"], calibration={"k": [1, 2]}) as writer:
        writer.write_frame(0, {"a": np.eye(4, dtype=bool)})
    s = Session.open(tmp_path / "s")
    np.testing.assert_array_equal(s.image("a", 0), np.eye(4, dtype=np.uint8) * 255)
    assert s.calibration_json() == {"k": [1, 2]}
    assert s.truth_dir is None and s.fps is None


def test_exception_in_block_closes_as_aborted(tmp_path):
    with pytest.raises(KeyError):
        with SessionWriter.create(tmp_path / "s", CAMS) as writer:
            writer.write_frame(0, simple(0))
            raise KeyError("boom")
    s = Session.open(tmp_path / "s")
    assert s.status == "aborted" and s.frame_indices == [0]


def test_reader_works_while_the_writer_is_open(tmp_path):
    writer = make_session(tmp_path / "s", n=3, close=False)
    s = Session.open(tmp_path / "s")
    assert s.status == "recording" and s.frame_indices == [0, 1, 2] and s.issues == []
    np.testing.assert_array_equal(s.image("cam1", 2), rgb8(2, 1))
    writer.write_frame(3, simple(3))
    assert Session.open(tmp_path / "s").frame_indices == [0, 1, 2, 3]
    writer.close()
    writer.close()  # second close is a no-op
    assert Session.open(tmp_path / "s").status == "complete"


def test_skipped_index_is_reported_as_gap(tmp_path):
    with SessionWriter.create(tmp_path / "s", CAMS) as writer:
        for i in (0, 1, 4):
            writer.write_frame(i, simple(i))
    s = Session.open(tmp_path / "s")
    assert s.frame_indices == [0, 1, 4]
    assert [g[0] for g in s.gaps] == [2, 3]
    assert "absent from frames.csv (no row between frames 1 and 4)" in s.gaps[0][1]
    report = s.validate()
    assert report.ok and len(report.gaps) == 2  # dropped frames are gaps, not damage
    with pytest.raises(SessionError, match=r"frame 3 is not complete: index absent from frames.csv"):
        s.frame(3)


def test_overwrite(tmp_path):
    make_session(tmp_path / "s", n=3)
    with pytest.raises(SessionError, match=r"folder exists and is not empty \(pass overwrite=True"):
        SessionWriter.create(tmp_path / "s", CAMS)
    SessionWriter.create(tmp_path / "s", ["x"], overwrite=True).close()
    s = Session.open(tmp_path / "s")
    assert s.cameras == ["x"] and s.frame_indices == []
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "precious.txt").write_text("keep")
    with pytest.raises(SessionError, match=r"not a capture session \(no session.json\); refusing to delete"):
        SessionWriter.create(tmp_path / "other", CAMS, overwrite=True)
    assert (tmp_path / "other" / "precious.txt").read_text() == "keep"
    (tmp_path / "empty").mkdir()
    SessionWriter.create(tmp_path / "empty", CAMS).close()  # an empty folder is fine
    (tmp_path / "file").write_text("x")
    with pytest.raises(SessionError, match=r"a file of that name exists"):
        SessionWriter.create(tmp_path / "file", CAMS)


def test_parallel_workers_round_trip(tmp_path):
    with SessionWriter.create(tmp_path / "s", CAMS, workers=3, compression=0) as writer:
        for i in range(4):
            writer.write_frame(i, images(i))
    s = Session.open(tmp_path / "s")
    assert s.frame_indices == [0, 1, 2, 3]
    for i in range(4):
        for cam, want in images(i).items():
            np.testing.assert_array_equal(s.image(cam, i), want)


def test_parallel_workers_disk_full_removes_the_whole_frame(tmp_path, monkeypatch):
    writer = SessionWriter.create(tmp_path / "s", CAMS, workers=3)
    writer.write_frame(0, simple(0))
    real = imageio.write_image

    def full_for_cam1(path, *args, **kwargs):
        if "cam1" in str(path):
            raise OSError(errno.ENOSPC, f"No space left on device: writing {path}")
        return real(path, *args, **kwargs)

    monkeypatch.setattr(imageio, "write_image", full_for_cam1)
    with pytest.raises(SessionError, match=r"frame 1: disk full \(ENOSPC\).*cam1/000001\.png"):
        writer.write_frame(1, simple(1))
    for cam in CAMS:
        assert not (tmp_path / "s" / "frames" / cam / "000001.png").exists()
    monkeypatch.undo()
    writer.close()
    assert Session.open(tmp_path / "s").frame_indices == [0]


def test_fsync_durability_round_trip(tmp_path):
    with SessionWriter.create(tmp_path / "s", CAMS, durability="fsync") as writer:
        writer.write_background("cam0", 0, rgb8(9))
        writer.write_frame(0, simple(0))
    s = Session.open(tmp_path / "s")
    assert s.info["durability"] == "fsync"
    np.testing.assert_array_equal(s.image("cam2", 0), rgb8(0, 2))


# =========================================================================== writer errors


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"cameras": []}, r"cameras: expected a non-empty list"),
        ({"cameras": "cam0"}, r"cameras: expected a non-empty list"),
        ({"cameras": ["a.b"]}, r"cameras: name 'a.b' is not valid"),
        ({"cameras": ["a", "a"]}, r"cameras: duplicate names"),
        ({"durability": "maybe"}, r"durability: 'maybe' is not one of"),
        ({"compression": 12}, r"compression: 12 is not a PNG level"),
        ({"workers": 0}, r"workers: 0 is not a positive integer"),
        ({"fps": -3}, r"fps: -3 is not a positive number"),
        ({"fps": float("nan")}, r"fps: nan is not a positive number"),
        ({"pixel_formats": {"camX": "Mono8"}}, r"pixel_formats: camera 'camX' is not one of"),
        ({"pixel_formats": {"cam0": 8}}, r"pixel_formats\['cam0'\]: expected a string"),
        ({"metadata": [1]}, r"metadata: expected a dict, got list"),
        ({"metadata": {"x": object()}}, r"metadata: not JSON-serialisable"),
        ({"calibration": 5}, r"calibration: expected a JSON file path, a dict or None, got int"),
        ({"calibration": {"x": object()}}, r"calibration: dict is not JSON-serialisable"),
    ],
)
def test_create_rejects_bad_arguments(tmp_path, kwargs, match):
    kwargs = {"cameras": CAMS, **kwargs}
    cameras = kwargs.pop("cameras")
    with pytest.raises(SessionError, match=match):
        SessionWriter.create(tmp_path / "s", cameras, **kwargs)
    assert not (tmp_path / "s").exists()


def test_create_rejects_missing_or_non_json_calibration(tmp_path):
    with pytest.raises(SessionError, match=r"calibration: cannot read .*nope\.json"):
        SessionWriter.create(tmp_path / "s", CAMS, calibration=tmp_path / "nope.json")
    (tmp_path / "bad.json").write_text("K = [1, 2]")
    with pytest.raises(SessionError, match=r"calibration: .*bad\.json is not a JSON file"):
        SessionWriter.create(tmp_path / "s", CAMS, calibration=str(tmp_path / "bad.json"))


def test_create_reports_unwritable_folder(tmp_path, monkeypatch):
    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(rigs.atomic, "_write_all", full)
    with pytest.raises(SessionError, match=r"cannot create session .*: disk full \(ENOSPC\)"):
        SessionWriter.create(tmp_path / "s", CAMS, calibration={"a": 1})


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda w: w.write_frame(0, {"cam0": rgb8(0), "cam1": rgb8(0)}), r"frame 0: missing image for camera\(s\) \['cam2'\]"),
        (lambda w: w.write_frame(0, {**simple(0), "cam9": rgb8(0)}), r"frame 0: unknown camera\(s\) \['cam9'\]"),
        (lambda w: w.write_frame(0, [rgb8(0)]), r"frame 0: images must be a dict"),
        (lambda w: w.write_frame(-1, simple(0)), r"frame -1: index -1 is not a non-negative integer"),
        (lambda w: w.write_frame(1.0, simple(0)), r"index 1.0 is not a non-negative integer"),
        (lambda w: w.write_frame(True, simple(0)), r"index True is not a non-negative integer"),
        (lambda w: w.write_frame(0, {**simple(0), "cam1": [1, 2]}), r"frame 0, camera 'cam1': expected a numpy array, got list"),
        (lambda w: w.write_frame(0, {**simple(0), "cam1": np.zeros((H, W), np.int16)}), r"camera 'cam1': dtype int16 is not storable"),
        (lambda w: w.write_frame(0, {**simple(0), "cam1": np.zeros((H, W, 7), np.uint8)}), r"camera 'cam1': shape \(12, 16, 7\) is not"),
        (lambda w: w.write_frame(0, {**simple(0), "cam1": np.zeros((0, W), np.uint8)}), r"camera 'cam1': shape \(0, 16\) is not"),
        (lambda w: w.write_frame(0, {**simple(0), "cam1": np.zeros((H, W, 2), np.uint8)}), r"camera 'cam1': 2-channel integer images"),
        (lambda w: w.write_frame(0, simple(0), timestamps_ns={"camZ": 1}), r"frame 0: timestamps_ns names unknown camera 'camZ'"),
        (lambda w: w.write_frame(0, simple(0), frame_ids={"cam0": 1.5}), r"frame 0: frame_ids\['cam0'\] = 1.5 is not an integer"),
        (lambda w: w.write_frame(0, simple(0), flags={"cam0": "a,b"}), r"flags\['cam0'\] = 'a,b' is not a string without commas"),
        (lambda w: w.write_frame(0, simple(0), flags={"camQ": "ok"}), r"flags names unknown camera 'camQ'"),
        (lambda w: w.write_background("camX", 0, rgb8(0)), r"background 0: unknown camera 'camX'"),
        (lambda w: w.close("weird"), r"close: status 'weird' is not 'complete' or 'aborted'"),
    ],
)
def test_write_rejects_bad_input(tmp_path, call, match):
    writer = SessionWriter.create(tmp_path / "s", CAMS)
    with pytest.raises(SessionError, match=match):
        call(writer)
    assert writer.frame_count == 0
    assert (tmp_path / "s" / "frames.csv").read_text().count("\n") == 1  # header only
    writer.close()


def test_write_rejects_size_or_dtype_change_and_duplicates(tmp_path):
    writer = SessionWriter.create(tmp_path / "s", CAMS)
    writer.write_background("cam1", 0, rgb8(0))
    with pytest.raises(SessionError, match=r"background 0, camera 'cam1': duplicate background index"):
        writer.write_background("cam1", 0, rgb8(0))
    with pytest.raises(SessionError, match=r"background 1, camera 'cam1': image is 8x12x3 uint8 .*expected 16x12x3 uint8"):
        writer.write_background("cam1", 1, rgb8(0)[:, :8])
    writer.write_frame(0, simple(0))
    with pytest.raises(SessionError, match=r"frame 0: duplicate index \(already in .*frames.csv\)"):
        writer.write_frame(0, simple(0))
    bad = {**simple(1), "cam2": np.zeros((H + 1, W, 3), np.uint8)}
    with pytest.raises(SessionError, match=r"frame 1, camera 'cam2': image is 16x13x3 uint8 .*expected 16x12x3 uint8 like the camera's first image \(field 'images.cam2'"):
        writer.write_frame(1, bad)
    with pytest.raises(SessionError, match=r"frame 1, camera 'cam0': image is 16x12x3 uint16"):
        writer.write_frame(1, {**simple(1), "cam0": rgb8(1).astype(np.uint16)})
    assert not (tmp_path / "s" / "frames" / "cam0" / "000001.png").exists()  # nothing half-written
    writer.close()
    with pytest.raises(SessionError, match=r"frame 1: session .* is closed"):
        writer.write_frame(1, simple(1))
    assert Session.open(tmp_path / "s").frame_indices == [0]


# =========================================================================== disk full


def _enospc_after(monkeypatch, calls_ok: int, partial: bool = False):
    real = rigs.atomic._write_all
    state = {"n": 0}

    def flaky(fd, data):
        state["n"] += 1
        if state["n"] > calls_ok:
            if partial:
                os.write(fd, bytes(data)[: len(data) // 2])
            raise OSError(errno.ENOSPC, "No space left on device")
        real(fd, data)

    monkeypatch.setattr(rigs.atomic, "_write_all", flaky)


def test_disk_full_on_an_image_keeps_the_session_consistent(tmp_path, monkeypatch):
    writer = make_session(tmp_path / "s", n=3, backgrounds=0, close=False)
    _enospc_after(monkeypatch, calls_ok=1)  # cam0's image of frame 3 fits, cam1's does not
    with pytest.raises(SessionError, match=r"frame 3: disk full \(ENOSPC\).*000003\.png; frame not recorded"):
        writer.write_frame(3, simple(3))
    assert not list((tmp_path / "s" / "frames" / "cam0").glob("000003*"))  # partial frame removed
    s = Session.open(tmp_path / "s")
    assert s.frame_indices == [0, 1, 2] and s.gaps == [] and s.issues == []
    monkeypatch.undo()
    writer.write_frame(3, simple(3))  # space freed: the same index can be written
    writer.close()
    s = Session.open(tmp_path / "s")
    assert s.frame_indices == [0, 1, 2, 3] and s.validate(deep=True).ok


def test_disk_full_on_the_csv_append_leaves_no_torn_line(tmp_path, monkeypatch):
    writer = make_session(tmp_path / "s", n=2, backgrounds=0, close=False)
    _enospc_after(monkeypatch, calls_ok=3, partial=True)  # 3 images fit, the row half-fits
    with pytest.raises(SessionError, match=r"frame 2: disk full \(ENOSPC\)"):
        writer.write_frame(2, simple(2))
    assert (tmp_path / "s" / "frames.csv").read_bytes().endswith(b"\n")
    monkeypatch.undo()
    writer.write_frame(2, simple(2))
    writer.close()
    s = Session.open(tmp_path / "s")
    assert s.frame_indices == [0, 1, 2] and s.issues == []


def test_failed_csv_restore_stops_the_writer(tmp_path, monkeypatch):
    writer = make_session(tmp_path / "s", n=1, backgrounds=0, close=False)
    _enospc_after(monkeypatch, calls_ok=3, partial=True)

    def no_truncate(fd, size):
        raise OSError(errno.EIO, "I/O error")

    monkeypatch.setattr(os, "ftruncate", no_truncate)
    with pytest.raises(SessionError, match=r"frame 1: disk full"):
        writer.write_frame(1, simple(1))
    monkeypatch.undo()
    with pytest.raises(SessionError, match=r"cannot take more frames: frames.csv could not be restored"):
        writer.write_frame(2, simple(2))
    writer.close()
    s = Session.open(tmp_path / "s")  # the torn row is ignored and reported
    assert s.frame_indices == [0]
    assert any("torn write" in msg for msg in s.issues)


def test_disk_full_on_background_and_close(tmp_path, monkeypatch, caplog):
    writer = make_session(tmp_path / "s", n=1, backgrounds=0, close=False)
    _enospc_after(monkeypatch, calls_ok=0)
    with pytest.raises(SessionError, match=r"background 0, camera 'cam0': disk full \(ENOSPC\)"):
        writer.write_background("cam0", 0, rgb8(0))
    with pytest.raises(SessionError, match=r"close: cannot update .*session.json: disk full .*status remains 'recording'"):
        writer.close()
    # in a with-block that already raised, a failing close is logged, not raised over the error
    monkeypatch.undo()
    writer2 = SessionWriter.create(tmp_path / "t", CAMS)
    _enospc_after(monkeypatch, calls_ok=0)
    with pytest.raises(ValueError, match="original"):
        with writer2:
            raise ValueError("original")
    assert "cannot update" in caplog.text
    monkeypatch.undo()
    s = Session.open(tmp_path / "s")
    assert s.status == "recording" and s.frame_indices == [0] and s.background_indices("cam0") == []


# =========================================================================== reading damaged sessions


def test_torn_and_malformed_csv_lines_are_ignored_and_reported(tmp_path):
    make_session(tmp_path / "s", n=6)
    csv = tmp_path / "s" / "frames.csv"
    lines = csv.read_bytes().split(b"\n")
    lines[2] = b"1,2,3"  # wrong field count (frame 1)
    lines[3] = b"x" + lines[3]  # bad index (frame 2)
    lines[4] = lines[4].replace(b",3000,", b",3e3,")  # bad timestamp (frame 3)
    lines.insert(5, lines[5])  # duplicate row of frame 4
    lines.insert(6, b"\xff\xfe")  # not UTF-8
    body = b"\n".join(lines[:-1]) + b"\n" + b"9,12"  # torn last line, no newline
    csv.write_bytes(body)
    s = Session.open(tmp_path / "s")
    assert s.frame_indices == [0, 4, 5]
    text = "\n".join(s.issues)
    assert "line 3: 3 fields, expected 10 (ignored)" in text
    assert "line 4: field 'index' is 'x2', expected a non-negative integer" in text
    assert "line 5: field 'cam0.timestamp_ns' is '3e3', expected an integer or empty" in text
    assert "line 8: duplicate row for frame 4 (line 6 kept)" in text
    assert "line 7: not UTF-8 text" in text
    assert "last line has no newline (torn write, ignored): '9,12'" in text
    assert "'frame_count' is 6 but frames.csv has 3 valid rows" in text
    report = s.validate()
    assert not report.ok and len(report.problems) == len(s.issues)
    assert [g[0] for g in s.gaps] == [1, 2, 3]


def test_missing_truncated_or_empty_image_makes_a_reported_gap(tmp_path):
    make_session(tmp_path / "s", n=5)
    frames = tmp_path / "s" / "frames"
    (frames / "cam1" / "000001.png").unlink()
    data = (frames / "cam2" / "000002.png").read_bytes()
    (frames / "cam2" / "000002.png").write_bytes(data[: len(data) // 2])
    (frames / "cam0" / "000003.png").write_bytes(b"")
    s = Session.open(tmp_path / "s")
    assert s.frame_indices == [0, 4]
    reasons = dict(s.gaps)
    assert set(reasons) == {1, 2, 3}
    assert reasons[1] == "row on line 3 of frames.csv, but frames/cam1/000001.png is missing"
    assert "frames/cam2/000002.png is truncated" in reasons[2]
    assert "frames/cam0/000003.png is empty (0 bytes)" in reasons[3]
    with pytest.raises(SessionError, match=r"frame 1 is not complete: .*cam1/000001.png is missing"):
        s.frame(1)
    quick = Session.open(tmp_path / "s", verify=False)  # existence only: sees the missing file
    assert quick.frame_indices == [0, 2, 3, 4] and dict(quick.gaps)[1] == reasons[1]
    with pytest.raises(SessionError, match=r"frame 2 is not complete"):
        s.image("cam0", 2)  # no silent mix: the intact camera of a broken frame is not served
    with pytest.raises(SessionError, match=r"frame 2 is not complete"):
        s.frame_meta(2)
    report = s.validate(deep=True)
    assert not report.ok and len(report.problems) == 3
    assert report.frames_checked == 2


def test_image_of_the_wrong_size_or_type_is_an_error_naming_the_file(tmp_path):
    make_session(tmp_path / "s", n=3)
    imageio.write_image(tmp_path / "s" / "frames" / "cam1" / "000002.png", np.zeros((H, W + 4, 3), np.uint8))
    imageio.write_image(tmp_path / "s" / "frames" / "cam2" / "000001.png", np.zeros((H, W, 3), np.uint16))
    s = Session.open(tmp_path / "s")
    assert s.frame_indices == [0, 1, 2]  # header-level damage is found by validate / on read
    with pytest.raises(SessionError, match=r"cam1/000002.png is 20x12: larger than the 16x12 expected \(refused before decoding\)"):
        s.frame(2)
    with pytest.raises(SessionError, match=r"cam2/000001.png: image is 16x12x3 uint16, expected 16x12x3 uint8"):
        s.image("cam2", 1)
    shallow = s.validate()
    assert len(shallow.problems) == 1 and "image size is 20x12, expected 16x12" in shallow.problems[0]
    deep = s.validate(deep=True)
    assert len(deep.problems) == 2


def test_size_check_without_image_specs_in_session_json(tmp_path):
    """An older/hand-made session.json without 'images': sizes come from the first frame."""
    make_session(tmp_path / "s", n=3)
    info_path = tmp_path / "s" / "session.json"
    info = json.loads(info_path.read_text())
    del info["images"]
    info_path.write_text(json.dumps(info))
    imageio.write_image(tmp_path / "s" / "frames" / "cam0" / "000002.png", np.zeros((H + 1, W, 3), np.uint8))
    s = Session.open(tmp_path / "s")
    assert s.image_size("cam0") == (W, H)
    np.testing.assert_array_equal(s.image("cam0", 1), rgb8(1, 0))
    with pytest.raises(SessionError, match=r"000002.png: image size is 16x13, expected 16x12 like camera 'cam0''s first image"):
        s.image("cam0", 2)


def test_camera_with_fewer_background_frames_is_reported(tmp_path):
    make_session(tmp_path / "s", n=1, backgrounds=3)
    (tmp_path / "s" / "background" / "cam2" / "000001.png").unlink()
    s = Session.open(tmp_path / "s")
    assert s.background_indices("cam2") == [0, 2]
    assert s.issues == ["background/cam2: 2 background frames, other cameras have 3 (missing indices [1])"]
    with pytest.raises(SessionError, match=r"camera 'cam2' has no background frame 1"):
        s.background("cam2", 1)
    assert not s.validate().ok


def test_leftover_temp_and_unlisted_files_are_notes(tmp_path):
    make_session(tmp_path / "s", n=2)
    folder = tmp_path / "s" / "frames" / "cam0"
    (folder / ".000002.png.tmp-123-0").write_bytes(b"\x89PNG partial")
    imageio.write_image(folder / "000002.png", rgb8(2))
    s = Session.open(tmp_path / "s")
    assert s.frame_indices == [0, 1] and s.gaps == []
    report = s.validate()
    assert report.ok
    assert any("1 image file(s) not listed in frames.csv" in n for n in report.notes)
    assert any("1 leftover temporary file(s)" in n for n in report.notes)


def test_session_with_no_frames_and_unsized_camera(tmp_path):
    SessionWriter.create(tmp_path / "s", ["a"]).close()
    s = Session.open(tmp_path / "s")
    assert s.frame_indices == [] and s.gaps == []
    with pytest.raises(SessionError, match=r"camera 'a' has no images to size"):
        s.image_size("a")
    with pytest.raises(SessionError, match=r"frame 0 is not in frames.csv \(0 complete frames, indices none\)"):
        s.frame(0)


def test_reader_argument_errors(tmp_path):
    make_session(tmp_path / "s", n=2)
    s = Session.open(tmp_path / "s")
    with pytest.raises(SessionError, match=r"unknown camera 'camX' \(cameras: \['cam0', 'cam1', 'cam2'\]\)"):
        s.image("camX", 0)
    with pytest.raises(SessionError, match=r"frame 7 is not in frames.csv \(2 complete frames, indices 0..1\)"):
        s.frame(7)
    with pytest.raises(SessionError, match=r"frame index '1' is not an integer"):
        s.frame("1")


def test_decode_failure_names_camera_and_file(tmp_path):
    make_session(tmp_path / "s", n=2)
    path = tmp_path / "s" / "frames" / "cam1" / "000001.png"
    data = bytearray(path.read_bytes())
    data[40:-20] = b"\x00" * (len(data) - 60)
    path.write_bytes(bytes(data))
    s = Session.open(tmp_path / "s")  # the cheap open-time check cannot see inside the PNG
    with pytest.raises(SessionError, match=r"camera 'cam1' frame 1: image file .*000001.png is corrupt"):
        s.frame(1)
    assert not s.validate(deep=True).ok


# =========================================================================== opening bad folders


def _edit_info(path: Path, **changes):
    info = json.loads((path / "session.json").read_text())
    info.update(changes)
    (path / "session.json").write_text(json.dumps(info))


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"format": "other"}, r"session.json: field 'format' is 'other', expected 'studio.capture-session'"),
        ({"version": 2}, r"session.json: field 'version' is 2; this reader understands major version 1 only"),
        ({"version": "2.0"}, r"field 'version' is '2.0'; this reader understands major version 1"),
        ({"version": "one"}, r"field 'version' is 'one', expected an integer"),
        ({"version": True}, r"field 'version' is True, expected an integer"),
        ({"cameras": ["a", "a"]}, r"session.json: field cameras: duplicate names"),
        ({"fps": "fast"}, r"field 'fps' is 'fast', expected a positive number or null"),
        ({"images": []}, r"field 'images' is \[\], expected an object"),
        ({"images": {"cam0": {"width": 3}}}, r"field 'images.cam0' is .*expected keys"),
    ],
)
def test_open_rejects_bad_session_json(tmp_path, changes, match):
    make_session(tmp_path / "s", n=1)
    _edit_info(tmp_path / "s", **changes)
    with pytest.raises(SessionError, match=match):
        Session.open(tmp_path / "s")


def test_open_accepts_minor_versions(tmp_path):
    make_session(tmp_path / "s", n=1)
    _edit_info(tmp_path / "s", version="1.4")
    assert Session.open(tmp_path / "s").frame_indices == [0]


def test_open_rejects_non_sessions(tmp_path):
    with pytest.raises(SessionError, match=r"nothing: no such capture-session folder"):
        Session.open(tmp_path / "nothing")
    (tmp_path / "d").mkdir()
    with pytest.raises(SessionError, match=r"not a capture session \(session.json missing"):
        Session.open(tmp_path / "d")
    (tmp_path / "d" / "session.json").write_text("{broken")
    with pytest.raises(SessionError, match=r"d/session.json: not valid JSON"):
        Session.open(tmp_path / "d")
    (tmp_path / "d" / "session.json").write_text("[1]")
    with pytest.raises(SessionError, match=r"session.json: expected a JSON object, got list"):
        Session.open(tmp_path / "d")
    (tmp_path / "d" / "session.json").write_bytes(b"\xff\xfe\x00")
    with pytest.raises(SessionError, match=r"session.json: cannot read"):
        Session.open(tmp_path / "d")


def test_open_rejects_missing_csv_or_wrong_header(tmp_path):
    make_session(tmp_path / "s", n=1)
    csv = tmp_path / "s" / "frames.csv"
    text = csv.read_text()
    csv.write_text(text.replace("cam1.frame_id", "cam1.id"))
    with pytest.raises(SessionError, match=r"frames.csv: header is .*'cam1.id'.*expected .*'cam1.frame_id'"):
        Session.open(tmp_path / "s")
    csv.unlink()
    with pytest.raises(SessionError, match=r"frames.csv: missing"):
        Session.open(tmp_path / "s")


def test_invalid_calibration_json_in_session(tmp_path):
    make_session(tmp_path / "s", n=1)
    assert Session.open(tmp_path / "s").calibration_json() is None
    (tmp_path / "s" / "calibration.json").write_text("{nope")
    with pytest.raises(SessionError, match=r"calibration.json: not valid JSON"):
        Session.open(tmp_path / "s").calibration_json()


def test_create_under_a_file_is_a_clear_error(tmp_path):
    (tmp_path / "f").write_text("x")
    with pytest.raises(SessionError, match=r"cannot create session folder .*f/s"):
        SessionWriter.create(tmp_path / "f" / "s", CAMS)


def test_unreadable_first_image_when_sizing_without_specs(tmp_path):
    with SessionWriter.create(tmp_path / "s", ["a"]) as writer:
        writer.write_background("a", 0, rgb8(0))
    _edit_info(tmp_path / "s", images={})
    (tmp_path / "s" / "background" / "a" / "000000.png").write_bytes(b"junk")
    s = Session.open(tmp_path / "s")
    with pytest.raises(SessionError, match=r"camera 'a': image file .*000000.png is not a valid PNG"):
        s.image_size("a")


def test_huge_index_hole_is_one_gap_and_unknown_status_is_an_issue(tmp_path):
    with SessionWriter.create(tmp_path / "s", CAMS) as writer:
        writer.write_frame(0, simple(0))
        writer.write_frame(5000, simple(1))
    _edit_info(tmp_path / "s", status="paused")
    s = Session.open(tmp_path / "s")
    assert s.frame_indices == [0, 5000]
    assert s.gaps == [(1, "indices 1..4999 (4999 frames) absent from frames.csv")]
    assert s.issues == ["session.json: field 'status' is 'paused', expected one of ('recording', 'complete', 'aborted')"]


def test_disk_full_when_recording_image_specs_then_retry(tmp_path, monkeypatch):
    writer = make_session(tmp_path / "s", n=0, backgrounds=0, close=False)
    _enospc_after(monkeypatch, calls_ok=3)  # the 3 images fit, the session.json update does not
    with pytest.raises(SessionError, match=r"frame 0: disk full.*session\.json; frame not recorded"):
        writer.write_frame(0, simple(0))
    monkeypatch.undo()
    assert Session.open(tmp_path / "s").info["images"] == {}
    writer.write_frame(0, simple(0))
    writer.close()
    s = Session.open(tmp_path / "s")
    assert s.frame_indices == [0] and s.info["images"]["cam2"]["width"] == W
