"""``studio session info``: summary, --json, --check exit codes."""

from __future__ import annotations

import json

import numpy as np

from rigs.session import SessionWriter
from studio.cli import main

CAMS = ["left", "right"]


def _make(path, n=4, skip=()):
    with SessionWriter.create(path, CAMS, rig="cli-rig", fps=25.0, pixel_formats={"left": "RGB8"}) as w:
        w.write_background("left", 0, np.zeros((6, 8, 3), np.uint8))
        w.write_background("right", 0, np.zeros((6, 8, 3), np.uint8))
        for i in range(n):
            if i not in skip:
                w.write_frame(i, {c: np.full((6, 8, 3), i, np.uint8) for c in CAMS})


def test_info_prints_summary(tmp_path, capsys):
    _make(tmp_path / "s", n=5, skip=(2,))
    assert main(["session", "info", str(tmp_path / "s")]) == 0
    out = capsys.readouterr().out
    assert "status    complete" in out
    assert "fps       25.0" in out
    assert "frames    4 complete (indices 0..4)" in out
    assert "left | 8x6, 3 ch, uint8 | RGB8 | 1 background" in out
    assert "gaps      1\n  2: index absent from frames.csv" in out


def test_info_json(tmp_path, capsys):
    _make(tmp_path / "s", n=3)
    assert main(["session", "info", str(tmp_path / "s"), "--json", "--check"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["frames"] == 3 and summary["cameras"] == CAMS and summary["rig"] == "cli-rig"
    assert summary["check"]["ok"] is True and summary["check"]["images_checked"] == 3 * 2 + 2


def test_check_fails_on_damage(tmp_path, capsys):
    _make(tmp_path / "s", n=3)
    target = tmp_path / "s" / "frames" / "right" / "000001.png"
    data = bytearray(target.read_bytes())
    data[40:-20] = b"\x00" * (len(data) - 60)  # undecodable but not visibly truncated
    target.write_bytes(bytes(data))
    assert main(["session", "info", str(tmp_path / "s")]) == 0  # summary alone does not decode
    capsys.readouterr()
    assert main(["session", "info", str(tmp_path / "s"), "--check"]) == 1
    out = capsys.readouterr().out
    assert "check     1 problem(s) (8 images decoded, calibration absent)" in out
    assert "000001.png is corrupt" in out


def test_not_a_session_is_one_clear_error(tmp_path, capsys):
    assert main(["session", "info", str(tmp_path)]) == 1
    assert "not a capture session (session.json missing" in capsys.readouterr().err


def test_session_without_action_prints_help(capsys):
    assert main(["session"]) == 2
    assert "info" in capsys.readouterr().out
