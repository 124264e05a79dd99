"""benchmarks/pose_accuracy.py: the per-family summary, with the fits' silhouette area over the truth's."""

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))

from pose_accuracy import summarise  # noqa: E402


def _row(person, family, precision, recall, surface):
    return {"person": person, "frame": 0, "family": family, "status": "ok", "surface_mm": surface,
            "stature_error_mm": 1.0, "joint_mm": 10.0, "precision": precision, "recall": recall, "time_s": 10.0}


def test_area_ratio_is_recall_over_precision(tmp_path, monkeypatch):
    monkeypatch.setenv("STUDIO_CACHE", str(tmp_path))  # no rendered people: cleanliness unknown
    # a fit covering 96 of 100 true pixels with 97 pixels of its own: 96 / 97 precise, area 0.97
    rows = [_row("person_000", "walk", 96 / 97, 0.96, 5.0), _row("person_001", "seated", 0.95, 0.95, 8.0)]
    out = summarise(rows)
    assert out["walk"]["area_ratio"] == pytest.approx(0.97)
    assert out["seated"]["area_ratio"] == pytest.approx(1.0)
    assert out["all"]["area_ratio"] == pytest.approx(0.985)
    assert out["all"]["recall"] == pytest.approx(0.955)
    assert out["all"]["surface_median_mm"] == pytest.approx(6.5)
