"""benchmarks/segmentation_cdnet.py: the unseen frames are scored only on the sequence the shared copy
was cut from (frames 1-1200 and their truth byte for byte), and a wrong folder is named."""

import shutil
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))

import segmentation_cdnet as cd  # noqa: E402


@pytest.fixture()
def sequences(tmp_path, monkeypatch):
    """A shared copy of 6 frames (truth from 3) and a full sequence of 9 (unseen 7-9)."""
    monkeypatch.setattr(cd, "LAST", 6)
    monkeypatch.setattr(cd, "UNSEEN", (7, 9))
    shared, full = tmp_path / "shared", tmp_path / "full"
    for root, last in ((shared, 6), (full, 9)):
        (root / "input").mkdir(parents=True)
        (root / "groundtruth").mkdir()
        (root / "ROI.bmp").write_bytes(b"roi")
        for i in range(1, last + 1):
            (root / "input" / f"in{i:06d}.jpg").write_bytes(f"frame {i}".encode())
            if i >= 3:
                (root / "groundtruth" / f"gt{i:06d}.png").write_bytes(f"truth {i}".encode())
    return shared, full


def test_same_sequence_accepted(sequences):
    shared, full = sequences
    cd._same_sequence(full, shared, 3)  # no error


def test_other_frame_named(sequences):
    shared, full = sequences
    (full / "input" / "in000004.jpg").write_bytes(b"another camera")
    with pytest.raises(SystemExit, match=r"in000004\.jpg: differs from"):
        cd._same_sequence(full, shared, 3)


def test_other_truth_named(sequences):
    shared, full = sequences
    (full / "groundtruth" / "gt000005.png").write_bytes(b"relabelled")
    with pytest.raises(SystemExit, match=r"gt000005\.png: differs from"):
        cd._same_sequence(full, shared, 3)


def test_missing_unseen_truth_named(sequences):
    shared, full = sequences
    (full / "groundtruth" / "gt000008.png").unlink()
    with pytest.raises(SystemExit, match=r"gt000008\.png: missing; expected frames and truth 7–9"):
        cd._same_sequence(full, shared, 3)


def test_shared_copy_is_not_the_full_sequence(sequences):
    shared, _ = sequences
    with pytest.raises(SystemExit, match=r"in000007\.jpg: missing"):
        cd._same_sequence(shared, shared, 3)


def test_missing_early_frame_named(sequences):
    shared, full = sequences
    shutil.rmtree(full / "input")
    with pytest.raises(SystemExit, match=r"in000001\.jpg: missing; expected the full CDnet 2014 highway"):
        cd._same_sequence(full, shared, 3)
