"""``segment_session`` and ``studio segment`` on a small synthetic capture session."""

import json
import shutil

import numpy as np
import pytest

from rigs.imageio import read_image
from rigs.session import SessionWriter
from studio.cli import main
from studio.segment import BackgroundModel, SegmentationError, SegmentOptions, segment_session
from studio.segment.metrics import label_scores
from studio.segment.synthetic import write_session


@pytest.fixture(scope="module")
def session_dir(tmp_path_factory):
    return write_session(tmp_path_factory.mktemp("seg") / "box", size=(96, 72), frames=3)


@pytest.fixture
def fresh(session_dir, tmp_path):
    dst = tmp_path / "box"
    shutil.copytree(session_dir, dst)
    return dst


def _labels(path, cams, frames, kind=None):
    root = path / "segmentation" if kind is None else path / "truth" / kind
    return [read_image(root / c / f"{i:06d}.png") for c in cams for i in frames]


def test_segment_session_writes_labels_skin_overlays(fresh):
    summary = segment_session(fresh, workers=1)
    cams, frames = summary.cameras, summary.frames
    assert cams == ["cam0", "cam1", "cam2"] and frames == [0, 1, 2] and summary.voting
    pred = _labels(fresh, cams, frames)
    truth = _labels(fresh, cams, frames, "labels")
    assert all(p.dtype == np.uint8 and set(np.unique(p)) <= {0, 1, 2} for p in pred)
    scores = label_scores(pred, truth)
    assert scores["person"]["f1"] > 0.9 and scores["shadow"]["f1"] > 0.8
    skin = read_image(fresh / "segmentation" / "skin" / "cam1" / "000001.png")
    assert skin.dtype == np.uint8 and set(np.unique(skin)) <= {0, 255}
    assert (skin > 0).sum() > 0 and not ((skin > 0) & (pred[4] != 1)).any()
    assert (fresh / "segmentation" / "overlay" / "cam2" / "000002.png").is_file()
    assert (fresh / "segmentation" / "floor_votes" / "000000.png").is_file()
    meta = json.loads((fresh / "segmentation" / "segmentation.json").read_text())
    assert meta["format"] == "studio.segmentation" and meta["frames"] == [0, 1, 2]
    # the studio's clean-up (fingers kept), in the settings and in the saved background model
    studio = {"median": 3, "open_radius": 0, "close_radius": 2}
    assert {k: meta["settings"]["morphology"][k] for k in studio} == studio
    stored = json.loads((fresh / "segmentation" / "background" / "cam0" / "model.json").read_text())["morphology"]
    assert {k: stored[k] for k in studio} == studio
    # the background model is computed once, then reused
    model_json = fresh / "segmentation" / "background" / "cam0" / "model.json"
    stamp = model_json.stat().st_mtime_ns
    segment_session(fresh, SegmentOptions(overlay_every=0, skin=False), frames=[1])
    assert model_json.stat().st_mtime_ns == stamp


def test_parallel_workers_give_the_same_labels(fresh):
    segment_session(fresh, SegmentOptions(overlay_every=0, skin=False), workers=1)
    first = _labels(fresh, ["cam0", "cam1", "cam2"], [0, 1, 2])
    segment_session(fresh, SegmentOptions(overlay_every=0, skin=False), workers=2)
    second = _labels(fresh, ["cam0", "cam1", "cam2"], [0, 1, 2])
    for a, b in zip(first, second):
        np.testing.assert_array_equal(a, b)


def test_missing_background_fails_clearly(tmp_path):
    path = tmp_path / "nobg"
    with SessionWriter.create(path, ["a", "b"]) as writer:
        writer.write_frame(0, {"a": np.zeros((8, 8, 3), np.uint8), "b": np.zeros((8, 8, 3), np.uint8)})
    with pytest.raises(SegmentationError, match=r"camera 'a' has no empty-scene frames in background/a/"):
        segment_session(path)


def test_mismatched_image_size_fails_clearly(fresh):
    _, frames = None, [np.zeros((10, 12, 3), np.uint8)] * 2
    BackgroundModel.fit(frames).save(fresh / "segmentation" / "background" / "cam1")
    with pytest.raises(SegmentationError, match=r"background model is 12x10, camera 'cam1''s frames are 96x72"):
        segment_session(fresh)


def test_calibration_is_needed_for_voting(fresh):
    (fresh / "calibration.json").unlink()
    with pytest.raises(SegmentationError, match="no calibration.json, needed for multi-view shadow voting"):
        segment_session(fresh)
    summary = segment_session(fresh, SegmentOptions(voting=False, skin=False, overlay_every=0))
    assert not summary.voting


def test_bad_frame_selection(fresh):
    with pytest.raises(SegmentationError, match=r"frame\(s\) \[9\] are not complete frames of the session"):
        segment_session(fresh, frames=[9])


def test_cli_segment(fresh, capsys):
    assert main(["segment", str(fresh), "--workers", "1", "--overlay-every", "0", "--frames", "0:2"]) == 0
    out = capsys.readouterr().out
    assert "segmented 2 frame(s) x 3 camera(s)" in out
    assert (fresh / "segmentation" / "cam0" / "000001.png").is_file()
    assert not (fresh / "segmentation" / "cam0" / "000002.png").exists()
    assert main(["segment", str(fresh), "--frames", "x:y"]) == 1
    assert "--frames 'x:y': 'x' is not an integer" in capsys.readouterr().err
    assert main(["segment", str(fresh), "--workers", "0"]) == 1
    assert "--workers must be >= 1" in capsys.readouterr().err
    assert main(["segment", str(fresh), "--frames", "50:60"]) == 1
    assert "selects no frame" in capsys.readouterr().err
    assert main(["segment", str(fresh), "--no-voting", "--no-skin", "--t-hsv", "5", "--t-s", "6", "--frames", "2"]) == 0
    meta = json.loads((fresh / "segmentation" / "segmentation.json").read_text())
    assert meta["thresholds"]["hsv"] == 5 and meta["thresholds"]["saturation"] == 6 and not meta["voting"]


def test_calibration_size_or_camera_mismatch_fails_clearly(fresh):
    data = json.loads((fresh / "calibration.json").read_text())
    data["cameras"]["cam2"]["size"] = [100, 80]
    (fresh / "calibration.json").write_text(json.dumps(data))
    with pytest.raises(SegmentationError, match=r"calibration.json: camera 'cam2': field 'size': calibrated for 100x80 images, the session's are 96x72"):
        segment_session(fresh, SegmentOptions(skin=False, overlay_every=0))
    del data["cameras"]["cam2"]
    (fresh / "calibration.json").write_text(json.dumps(data))
    with pytest.raises(SegmentationError, match=r"calibration.json: no calibration for camera\(s\) \['cam2'\] of the session"):
        segment_session(fresh, SegmentOptions(skin=False, overlay_every=0))


def test_reserved_camera_names_and_empty_sessions(tmp_path):
    image = np.zeros((8, 8, 3), np.uint8)
    with SessionWriter.create(tmp_path / "skin", ["skin"]) as writer:
        writer.write_frame(0, {"skin": image})
    with pytest.raises(SegmentationError, match=r"camera names \['skin'\] clash with output folders"):
        segment_session(tmp_path / "skin")
    with SessionWriter.create(tmp_path / "empty", ["a"]) as writer:
        writer.write_background("a", 0, image)
    with pytest.raises(SegmentationError, match="no complete frames to segment"):
        segment_session(tmp_path / "empty")


def test_cli_with_a_trained_skin_model_and_a_frame_list(fresh, tmp_path):
    from studio.segment import SkinClassifier

    images = [read_image(fresh / "frames" / "cam0" / f"{i:06d}.png") for i in range(3)]
    masks = [read_image(fresh / "truth" / "skin" / "cam0" / f"{i:06d}.png") > 0 for i in range(3)]
    model_path = SkinClassifier().train(images, masks).save(tmp_path / "skin.npz")
    argv = ["segment", str(fresh), "--workers", "1", "--skin-model", str(model_path), "--frames", "0,2"]
    assert main(argv) == 0
    truth = read_image(fresh / "truth" / "skin" / "cam0" / "000002.png") > 0
    pred = read_image(fresh / "segmentation" / "skin" / "cam0" / "000002.png") > 0
    assert (pred & truth).sum() > 0.7 * truth.sum()
    assert not (fresh / "segmentation" / "skin" / "cam0" / "000001.png").exists()


def test_a_nudged_camera_is_registered_and_mask_quality_is_written(fresh):
    """cam1's empty scene captured 1.5 px left / 1 px down of where the session was filmed:
    registration measures the shift and gives back the clean masks; quality figures are written."""
    from rigs.imageio import write_image
    from studio.segment.registration import shift_image

    for path in sorted((fresh / "background" / "cam1").glob("*.png")):
        write_image(path, shift_image(read_image(path), -1.5, 1.0))
    truth = _labels(fresh, ["cam1"], [0, 1, 2], "labels")
    scores = {}
    for register in (False, True):
        segment_session(fresh, SegmentOptions(overlay_every=0, skin=False, register=register, refit_background=True))
        scores[register] = label_scores(_labels(fresh, ["cam1"], [0, 1, 2]), truth)["person"]
    meta = json.loads((fresh / "segmentation" / "segmentation.json").read_text())
    dx, dy = meta["settings"]["registration"]["cam1"]
    assert dx == pytest.approx(1.5, abs=0.2) and dy == pytest.approx(-1.0, abs=0.2)
    assert meta["settings"]["registration"]["cam0"] == [0.0, 0.0]
    assert scores[True]["precision"] > scores[False]["precision"] + 0.05, scores
    assert scores[True]["f1"] > 0.9
    q = meta["quality"]["cam1"]
    assert 0.01 < q["person_fraction_mean"] < 0.5 and 0.0 <= q["clutter_mean"] <= q["clutter_max"] < 0.2
    assert set(meta["frame_quality"]) == {"0", "1", "2"}
    assert meta["frame_quality"]["1"]["cam0"]["components"] >= 1


def test_hull_check_drops_clutter_one_view_alone_sees(fresh):
    """A bright patch painted into cam0's frames (a lamp, a moved tripod) is person in cam0 only;
    the visual hull of the three views does not explain it and --hull drops it, the person stays."""
    from rigs.imageio import write_image

    for path in sorted((fresh / "frames" / "cam0").glob("*.png")):
        img = read_image(path)
        img[2:12, 2:14] = (250, 20, 200)
        write_image(path, img)
    truth = _labels(fresh, ["cam0"], [0, 1, 2], "labels")
    runs = {}
    for hull in (False, True):
        assert main(["segment", str(fresh), "--no-skin", "--overlay-every", "0"] + (["--hull"] if hull else [])) == 0
        meta = json.loads((fresh / "segmentation" / "segmentation.json").read_text())
        runs[hull] = (label_scores(_labels(fresh, ["cam0"], [0, 1, 2]), truth)["person"], meta)
    plain, checked = runs[False][0], runs[True][0]
    assert all(_labels(fresh, ["cam0"], [i])[0][2:12, 2:14].mean() == 0 for i in (0, 1, 2))
    assert checked["precision"] > plain["precision"] + 0.02 and checked["recall"] >= plain["recall"] - 0.01
    q_plain, q_checked = runs[False][1]["frame_quality"]["1"]["cam0"], runs[True][1]["frame_quality"]["1"]["cam0"]
    assert q_plain["components"] == 2 and q_plain["clutter"] > 0.05
    assert q_checked["components"] == 1 and q_checked["clutter"] == 0 and q_checked["hull_dropped"] >= 100
    assert runs[True][1]["settings"]["hull"] is True
    # the other views keep their person whole
    assert runs[True][1]["frame_quality"]["1"]["cam1"]["hull_dropped"] == 0
