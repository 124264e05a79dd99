"""``studio import`` / :mod:`rigs.importer`: footage written here with OpenCV (MJPG AVIs, PNG folders).

Each test frame carries its number as its grey level (10 + 10 k), so a frame's content tells
which source frame it came from even through lossy MJPG (tolerance 6 grey levels).
"""

from __future__ import annotations

import csv
import json

import cv2
import numpy as np
import pytest

from rigs.importer import FootageError, check_sources, probe, repair_times
from rigs.session import Session
from studio.cli import main

SIZE = (64, 48)


def grey(k: int, size=SIZE) -> np.ndarray:
    return np.full((size[1], size[0], 3), 10 + 10 * k, np.uint8)


def write_video(path, n: int, fps: float = 25.0, size=SIZE):
    vw = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, size)
    assert vw.isOpened()
    for k in range(n):
        vw.write(grey(k, size))
    vw.release()
    return path


@pytest.fixture()
def footage(tmp_path):
    return {c: write_video(tmp_path / f"{c}.avi", 12) for c in ("a", "b", "c")}


def test_repair_times_keeps_container_times_and_flags_repairs():
    t, nominal = repair_times(np.array([60.0, 80.0, 100.0, 0.0, 140.0]), 50.0)
    assert (t / 1e6).tolist() == [60.0, 80.0, 100.0, 120.0, 140.0]
    assert nominal.tolist() == [False, False, False, True, False]
    t, nominal = repair_times(np.zeros(3), 50.0)  # no container times at all: k / fps
    assert (t / 1e6).tolist() == [0.0, 20.0, 40.0] and nominal.all()


def test_import_selected_frames_into_a_session(footage, tmp_path):
    out = tmp_path / "sess"
    bg = write_video(tmp_path / "bg.avi", 7)
    argv = ["import", str(out), "--frames", "2:11:3", "--background", f"b={bg}", "--background-frames", "3"]
    argv += [a for c, p in footage.items() for a in ("--video", f"{c}={p}")]
    assert main(argv) == 0
    s = Session.open(out)
    assert s.cameras == ["a", "b", "c"] and s.frame_indices == [0, 1, 2] and s.info["fps"] == 25.0
    for j, k in enumerate((2, 5, 8)):
        for cam, img in s.frame(j).items():
            assert img.shape == (48, 64, 3)
            assert abs(float(img.mean()) - (10 + 10 * k)) < 6, (cam, j, k)
    rows = list(csv.DictReader((out / "frames.csv").read_text().splitlines()))
    assert [int(r["a.frame_id"]) for r in rows] == [2, 5, 8]  # source frame numbers kept
    assert [int(r["b.timestamp_ns"]) for r in rows] == [int(round(k * 40e6)) for k in (2, 5, 8)]  # container times, 25 fps
    backgrounds = sorted(p.name for p in (out / "background" / "b").iterdir())
    assert backgrounds == ["000000.png", "000001.png", "000002.png"]
    info = json.loads((out / "session.json").read_text())
    assert info["status"] == "complete" and info["metadata"]["imported_from"]["a"]["frames"] == 12


def test_unequal_lengths_refused_or_trimmed(footage, tmp_path, capsys):
    short = write_video(tmp_path / "short.avi", 9)
    argv = ["--video", f"a={footage['a']}", "--video", f"b={short}"]
    assert main(["import", str(tmp_path / "s1"), *argv]) == 1
    err = capsys.readouterr().err
    assert "differ in length" in err and "a.avi (12 frames)" in err and "['b']" in err and "--trim" in err
    assert not (tmp_path / "s1").exists()
    assert main(["import", str(tmp_path / "s2"), "--trim", *argv]) == 0
    assert Session.open(tmp_path / "s2").frame_indices == list(range(9))


def test_rates_sizes_and_arguments_checked(footage, tmp_path, capsys):
    fast = write_video(tmp_path / "fast.avi", 12, fps=50.0)
    with pytest.raises(FootageError, match=r"different frame rates: \{'f': 50.0\} fps vs 25"):
        check_sources([probe("a", footage["a"]), probe("b", footage["b"]), probe("f", fast)])
    big = write_video(tmp_path / "big.avi", 12, size=(80, 48))
    assert main(["import", str(tmp_path / "s"), "--video", f"a={footage['a']}", "--background", f"a={big}"]) == 1
    assert "camera a:" in capsys.readouterr().err
    cases = [
        (["--video", "a"], "expected NAME=FILE"),
        (["--video", f"a={footage['a']}", "--video", f"a={footage['b']}"], "camera 'a' is given twice"),
        (["--video", f"a={tmp_path}/none.avi"], "camera a: "),
        (["--video", f"a={footage['a']}", "--background", f"z={footage['b']}"], "have no --video"),
        (["--video", f"a={footage['a']}", "--frames", "5:40:0"], "STEP must be a positive integer"),
    ]
    for argv, message in cases:
        assert main(["import", str(tmp_path / "x"), *argv]) == 1, argv
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1, (argv, err)


def test_numbered_image_folders(tmp_path):
    for cam in ("l", "r"):
        (tmp_path / cam).mkdir()
        for k in range(11):  # natural order: img_2 before img_10
            cv2.imwrite(str(tmp_path / cam / f"img_{k}.png"), grey(k))
    out = tmp_path / "sess"
    assert main(["import", str(out), "--video", f"l={tmp_path / 'l'}", "--video", f"r={tmp_path / 'r'}", "--fps", "10"]) == 0
    s = Session.open(out)
    assert len(s.frame_indices) == 11
    assert abs(float(s.frame(10)["r"].mean()) - 110) < 1
    rows = list(csv.DictReader((out / "frames.csv").read_text().splitlines()))
    assert int(rows[3]["l.timestamp_ns"]) == 300_000_000 and rows[3]["l.flag"] == "ts_nominal"
    cv2.imwrite(str(tmp_path / "r" / "img_11.png"), grey(11, (32, 48)))
    cv2.imwrite(str(tmp_path / "l" / "img_11.png"), grey(11))
    with pytest.raises(FootageError, match=r"img_11.png: image is 32x48, expected 64x48"):
        from rigs.importer import import_session

        import_session(tmp_path / "s2", [probe("l", tmp_path / "l"), probe("r", tmp_path / "r")], list(range(12)))
    assert Session.open(tmp_path / "s2").info["status"] == "aborted"


def test_time_spread_between_cameras():
    from pathlib import Path

    from rigs.importer import Source, time_spread_ms

    def src(name, ms):
        return Source(name, Path(name), "video", len(ms), 50.0, SIZE, np.array(ms) * 1_000_000, np.zeros(len(ms), bool))

    a, b = src("a", [60, 80, 100]), src("b", [40, 80, 100])  # as the UU cam4 video against the others
    assert time_spread_ms([a, b], [0, 1]) == 20.0
    assert time_spread_ms([a, b], [1, 2]) == 0.0
