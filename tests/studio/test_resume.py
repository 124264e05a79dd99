"""Interrupted ``studio segment`` / ``studio fit``: workers die with the command, nothing torn is
left under a final name, and a rerun continues where the last one stopped (defect 1)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from rigs.atomic import is_temporary
from rigs.imageio import read_image
from studio.segment import SegmentOptions, segment_session
from studio.segment.synthetic import write_session
from studio.workspace import Layout

from prockit import children, kill_and_time

ROOT = Path(__file__).parents[2]


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_killed_segment_leaves_no_workers_and_resumes(tmp_path):
    session = write_session(tmp_path / "s", size=(192, 144), frames=60)
    lay = Layout(session)
    cams = ["cam0", "cam1", "cam2"]
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.Popen([sys.executable, "-m", "studio", "segment", str(session), "--workers", "2",
                             "--overlay-every", "0"], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    workers: set[int] = set()
    t0 = time.monotonic()
    while time.monotonic() - t0 < 60:
        workers |= set(children(proc.pid))
        if len(workers) >= 2 and (lay.segmentation_dir / "cam2").is_dir() and \
                len(list((lay.segmentation_dir / "cam2").glob("*.png"))) >= 4:
            break
        assert proc.poll() is None, "segment finished before it could be interrupted"
        time.sleep(0.02)
    gone, leftover = kill_and_time(proc, workers)
    assert not leftover and gone < 5.0, f"workers {leftover} alive {gone:.1f} s after the parent was killed"
    # every label under a final name is whole; complete frames are those with all cameras' labels
    done = [i for i in range(60) if all(lay.labels(c, i).is_file() for c in cams)]
    assert 0 < len(done) < 60
    for p in lay.segmentation_dir.glob("cam*/*.png"):
        if not is_temporary(p.name):  # a writer killed mid-file leaves only its hidden temporary
            assert read_image(p).shape == (144, 192)
    # the rerun keeps them and does the rest; --force-like rerun redoes everything, same labels
    summary = segment_session(session, SegmentOptions(overlay_every=0), workers=1)
    assert summary.skipped == done and summary.frames == list(range(60))
    resumed = [read_image(lay.labels(c, i)) for c in cams for i in range(0, 60, 7)]
    again = segment_session(session, SegmentOptions(overlay_every=0), workers=1, force=True)
    assert again.skipped == []
    assert all(np.array_equal(a, read_image(lay.labels(c, i)))
               for a, (c, i) in zip(resumed, [(c, i) for c in cams for i in range(0, 60, 7)], strict=True))
    meta = json.loads(lay.segmentation_summary.read_text())
    assert meta["status"] == "complete" and meta["skipped"] == []
    assert not [p for p in lay.segmentation_dir.rglob("*") if is_temporary(p.name)]  # the rerun cleared them


def test_segment_settings_change_redoes_frames(tmp_path):
    session = write_session(tmp_path / "s", size=(64, 48), frames=3)
    first = segment_session(session, SegmentOptions(overlay_every=0, skin=False))
    assert first.skipped == []
    assert segment_session(session, SegmentOptions(overlay_every=0, skin=False)).skipped == [0, 1, 2]
    assert segment_session(session, SegmentOptions(overlay_every=0, skin=False, voting=False)).skipped == []


def test_segment_rerun_clears_a_killed_writers_temporary(tmp_path):
    session = write_session(tmp_path / "s", size=(64, 48), frames=2)
    segment_session(session, SegmentOptions(overlay_every=0, skin=False))
    lay = Layout(session)
    left = lay.labels("cam0", 1).parent / ".000001.png.tmp-abc123.png"
    left.write_bytes(b"")  # what a writer killed between creating and filling its file leaves
    assert is_temporary(left.name)
    again = segment_session(session, SegmentOptions(overlay_every=0, skin=False))
    assert again.skipped == [0, 1] and not left.exists()
    assert read_image(lay.labels("cam0", 1)).shape == (48, 64)


def test_segment_rerun_keeps_what_the_skipped_frames_measured(tmp_path):
    """A rerun that skips finished frames keeps their per-frame quality (voting relabels included)
    as the run that segmented them recorded it, not figures recomputed from the stored labels."""
    session = write_session(tmp_path / "s", size=(96, 72), frames=3)
    lay = Layout(session)
    first = segment_session(session, SegmentOptions(overlay_every=0, skin=False))
    meta = json.loads(lay.segmentation_summary.read_text())
    assert first.skipped == [] and set(meta["frame_quality"]) == {"0", "1", "2"}
    assert all("relabelled" in q for f in meta["frame_quality"].values() for q in f.values())
    again = segment_session(session, SegmentOptions(overlay_every=0, skin=False))
    kept = json.loads(lay.segmentation_summary.read_text())
    assert again.skipped == [0, 1, 2]
    assert kept["frame_quality"] == meta["frame_quality"]
    assert kept["relabelled_by_voting"] == meta["relabelled_by_voting"]
    # a figure only the segmenting run knows survives the rerun (here: planted in the summary)
    meta["frame_quality"]["1"]["cam0"]["bridged"] = 7
    from rigs.atomic import atomic_write_json

    atomic_write_json(lay.segmentation_summary, meta)
    segment_session(session, SegmentOptions(overlay_every=0, skin=False))
    assert json.loads(lay.segmentation_summary.read_text())["frame_quality"]["1"]["cam0"]["bridged"] == 7
