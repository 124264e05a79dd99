"""``studio study``: three small sessions, one broken on purpose — two reports, one clear failure,
study.csv with the sessions' own measurements, and a rerun that keeps what was done."""

from __future__ import annotations

import csv
import json

import pytest
import yaml

from studio.cli import main
from studio.study import FitSettings, StudyError, StudySession, StudySpec, load_study, run_study

from test_fit_session import TINY, make_session


def _study(tmp_path):
    for name in ("p1", "p2", "p3"):
        make_session(tmp_path / "sessions" / name, segmentation=False, n_frames=2, backgrounds=3)
    (tmp_path / "sessions" / "p3" / "calibration.json").unlink()  # broken on purpose
    doc = {"format": "studio.study", "version": 1, "output": "out", "fit": {"gender": "female"},
           "sessions": ["sessions/p1", {"path": "sessions/p2", "seed": 3}, "sessions/p3"]}
    (tmp_path / "study.yaml").write_text(yaml.safe_dump(doc))
    return tmp_path / "study.yaml"


def test_a_study_of_three_sessions_one_broken(tmp_path, capsys):
    spec = load_study(_study(tmp_path))
    assert [s.participant for s in spec.sessions] == ["p1", "p2", "p3"] and spec.sessions[1].fit.seed == 3
    stages = []
    state = run_study(spec, options=TINY, progress=lambda p, stage, d, n: stages.append((p, stage)))
    out = tmp_path / "out"
    assert {p: e["status"] for p, e in state.items()} == {"p1": "done", "p2": "done", "p3": "failed"}
    assert "no calibration.json" in state["p3"]["reason"] and "p3" in state["p3"]["reason"]
    assert ("p1", "fit") in stages and ("p3", "failed") in stages
    for p in ("p1", "p2"):
        assert (out / "sessions" / p / "report" / "index.html").is_file()
        assert not (tmp_path / "sessions" / p / "fit").exists()  # the captures are only read
    assert not (out / "sessions" / "p3" / "report").exists()
    rows = list(csv.DictReader((out / "study.csv").read_text().splitlines()))
    assert [r["participant"] for r in rows] == ["p1", "p2", "p3"]
    for r in rows[:2]:
        table = json.loads((out / "sessions" / r["participant"] / "report" / "measurements.json").read_text())
        stature = table["measurements"]["stature"]
        assert float(r["stature_mm"]) == pytest.approx(stature["mean"], abs=0.01)
        assert 1400 < float(r["stature_mm"]) < 2000 and r["gender"] == "female" and r["frames"] == "2"
        assert r["stature_status"] == stature["status"] and r["flagged"] in ("yes", "no")
        assert float(r["stature_z"]) == pytest.approx(stature["population_z"])
    assert rows[2]["status"] == "failed" and "no calibration.json" in rows[2]["reason"] and rows[2]["stature_mm"] == ""
    page = (out / "report" / "index.html").read_text()
    assert "2 measured" in page and "1 failed" in page and "ANSUR II female" not in page  # in the figure, not text
    assert "data:image/png;base64," in page and "sessions/p1/report/index.html" in page
    assert "<h2>Failed sessions</h2><ul><li><b>p3</b>" in page
    # rerun from the command line: p1 and p2 kept untouched, p3 tried again and reported
    stamp = (out / "sessions" / "p1" / "fit" / "sequence.json").stat().st_mtime_ns
    assert main(["study", str(tmp_path / "study.yaml")]) == 0
    printed = capsys.readouterr().out
    assert "2 of 3 participant(s) measured, 1 failed" in printed and "p3: failed:" in printed
    assert (out / "sessions" / "p1" / "fit" / "sequence.json").stat().st_mtime_ns == stamp


def test_study_descriptions_are_checked(tmp_path, capsys):
    path = tmp_path / "s.yaml"
    cases = [
        ({"format": "other", "version": 1, "sessions": ["a"]}, "field 'format': expected 'studio.study'"),
        ({"format": "studio.study", "version": 2, "sessions": ["a"]}, "field 'version'"),
        ({"format": "studio.study", "version": 1, "sessions": []}, "at least one session"),
        ({"format": "studio.study", "version": 1, "sessions": ["a"], "fit": {"gender": "robot"}}, "field 'gender'"),
        ({"format": "studio.study", "version": 1, "sessions": ["a", "x/a"]}, "participant 'a' named twice"),
        ({"format": "studio.study", "version": 1, "sessions": [{"path": "a", "speed": 3}]}, r"unknown field\(s\)"),
        ({"format": "studio.study", "version": 1, "sessions": [{"path": "a", "participant": "../x"}]},
         "participant '../x'"),
    ]
    for doc, message in cases:
        path.write_text(yaml.safe_dump(doc))
        with pytest.raises(StudyError, match=message):
            load_study(path)
    with pytest.raises(StudyError, match="cannot read"):
        load_study(tmp_path / "absent.yaml")
    with pytest.raises(StudyError, match="no study folder"):
        run_study(StudySpec([StudySession("a", tmp_path / "a", FitSettings())]))
    assert main(["study", str(tmp_path / "a"), str(tmp_path / "b")]) == 1
    assert "give the study folder with -o STUDY" in capsys.readouterr().err
