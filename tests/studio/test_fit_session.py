"""Session fitting, ``studio fit`` / ``studio report`` end to end on a tiny synthetic session."""

import json

import numpy as np
import pytest

from calibration import Camera, RigCalibration
from rigs.imageio import write_image
from rigs.session import SessionWriter
from studio.body import BodyModel
from studio.cli import main
from studio.fit import FitError, FitOptions, fit_session, load_fits, open_workspace
from studio.render import silhouette


def _cameras(size=(164, 124), focal=140.0):
    cams = []
    w, h = size
    for k in range(3):
        a = np.pi / 4 + 2 * np.pi * k / 3
        eye = np.array([3.6 * np.cos(a), 3.6 * np.sin(a), 2.3])
        cams.append(Camera.look_at(f"cam{k}", eye, [0, 0, 0.9], focal, (w, h), np.zeros(5)))
    return cams


def make_session(path, *, calibration=True, segmentation=True, n_frames=2, backgrounds=0):
    """A tiny session: our own female body walking 5 cm per frame, labels = true silhouettes
    (``segmentation``), ``backgrounds`` empty-scene frames per camera (for ``studio segment``)."""
    model = BodyModel.load("female")
    cams = _cameras()
    calib_file = path.parent / f"{path.name}-calibration.json"
    RigCalibration(cameras={c.name: c for c in cams}).save(calib_file)
    writer = SessionWriter.create(path, [c.name for c in cams], rig="test",
                                  calibration=calib_file if calibration else None)
    for c in cams:
        for i in range(backgrounds):
            writer.write_background(c.name, i, np.full((c.size[1], c.size[0], 3), 60, np.uint8))
    poses = []
    for i in range(n_frames):
        pose = model.default_pose()
        pose[:2] = [0.05 * i, 0.0]
        pose[5] = 0.3
        poses.append(pose)
        V = model.vertices(model.mean_shape(), pose)
        masks = [silhouette(c, V, model.faces) for c in cams]
        writer.write_frame(i, {c.name: np.where(m[..., None], 180, 60).astype(np.uint8).repeat(3, 2)
                               for c, m in zip(cams, masks, strict=True)})
        if segmentation:
            for c, m in zip(cams, masks, strict=True):
                p = path / "segmentation" / c.name / f"{i:06d}.png"
                p.parent.mkdir(parents=True, exist_ok=True)
                write_image(p, m.astype(np.uint8))
    writer.close()
    return model, cams, poses


TINY = FitOptions(levels=(2, 1, 0), n_particles=16, n_layers=3, n_particles_tracking=12, n_layers_tracking=2,
                  nm_evaluations=8, final_evaluations=10, n_shape_free=2, partition_particles=8, partition_layers=2,
                  limb_particles=6, limb_layers=1)


def test_missing_segmentation_or_calibration_is_named(tmp_path, capsys):
    make_session(tmp_path / "noseg", segmentation=False, n_frames=1)
    with pytest.raises(FitError, match=r"no segmentation/ folder — run `studio segment"):
        open_workspace(tmp_path / "noseg")
    assert main(["fit", str(tmp_path / "noseg")]) == 1
    err = capsys.readouterr().err
    assert "studio segment" in err and len(err.strip().splitlines()) == 1
    make_session(tmp_path / "nocal", calibration=False, n_frames=1)
    with pytest.raises(FitError, match="no calibration.json"):
        open_workspace(tmp_path / "nocal")
    with pytest.raises(FitError, match="no such session folder"):
        open_workspace(tmp_path / "absent")


def test_fit_session_checks_frames_and_arguments(tmp_path):
    make_session(tmp_path / "s", n_frames=1)
    with pytest.raises(FitError, match=r"frame\(s\) \[5\] are not complete frames"):
        fit_session(tmp_path / "s", frames=[5], gender="female")
    with pytest.raises(FitError, match="gender"):
        fit_session(tmp_path / "s", gender="robot")
    with pytest.raises(FitError, match="workers"):
        fit_session(tmp_path / "s", workers=0)
    (tmp_path / "s" / "segmentation" / "cam1" / "000000.png").unlink()
    with pytest.raises(FitError, match="missing segmentation of frame 0"):
        fit_session(tmp_path / "s", frames=[0], gender="female")
    with pytest.raises(FitError, match="no fit/ folder"):
        load_fits(tmp_path / "s")


def test_fit_session_writes_results_and_tracks(tmp_path):
    model, cams, poses = make_session(tmp_path / "s", n_frames=2)
    summary = fit_session(tmp_path / "s", gender="female", options=TINY, seed=0)
    assert summary["frames"] == [0, 1] and summary["gender"] == "female"
    fits = load_fits(tmp_path / "s")
    for f, fit in fits.items():
        # even a tiny budget lands the root near the truth
        assert np.linalg.norm(fit.pose[:2] - poses[f][:2]) < 0.08
        d = json.loads((tmp_path / "s" / "fit" / f"{f:06d}.json").read_text())
        assert set(d["overlays"]) == {"cam0", "cam1", "cam2"}
        assert (tmp_path / "s" / "fit" / d["overlays"]["cam0"]).is_file()
        assert (tmp_path / "s" / "fit" / f"{f:06d}.ply").is_file()
        assert d["silhouette_agreement"]["cam0"]["recall"] > 0.6
    seq = json.loads((tmp_path / "s" / "fit" / "sequence.json").read_text())
    np.testing.assert_allclose(seq["shape"], np.mean([fits[0].shape, fits[1].shape], axis=0))


def test_cli_fit_then_report(tmp_path, capsys, monkeypatch):
    import studio.cli.commands.fit as fit_cmd

    make_session(tmp_path / "s", n_frames=1)
    monkeypatch.setattr(fit_cmd, "QUICK", {k: v for k, v in TINY.to_dict().items() if k != "levels"})
    assert main(["fit", str(tmp_path / "s"), "--frames", "0", "--gender", "female", "--quick"]) == 0
    out = capsys.readouterr().out
    assert "fitted 1 frame(s) with the female model" in out
    status = json.loads((tmp_path / "s" / "fit" / "000000.json").read_text())["quality"]["status"]
    assert f"quality: 1 {status}" in out
    assert main(["report", str(tmp_path / "s")]) == 0
    html = (tmp_path / "s" / "report" / "index.html").read_text()
    assert "Measurements" in html and "data:image/png;base64," in html and "model only" in html
    assert "<h2>Quality</h2>" in html and f"1 {status}" in html
    table = json.loads((tmp_path / "s" / "report" / "measurements.json").read_text())["measurements"]
    assert 1400 < table["stature"]["mean"] < 2000 and table["stature"]["unit"] == "mm"
    csv = (tmp_path / "s" / "report" / "measurements.csv").read_text().splitlines()
    assert csv[0].startswith("name,unit,mean,std,status,flags,truth,error") and len(csv) == 21  # 20 ISO measurements
    assert main(["report", str(tmp_path / "absent")]) == 1


def test_an_all_person_frame_is_refused_never_measured(tmp_path, capsys):
    """Frame 0 (the would-be key frame) segmented as all person: it gets a failed record and no
    body, frame 1 becomes the key frame, the report lists frame 0 as failed."""
    from studio.fit import load_quality

    make_session(tmp_path / "s", n_frames=2)
    for c in ("cam0", "cam1", "cam2"):
        p = tmp_path / "s" / "segmentation" / c / "000000.png"
        write_image(p, np.ones((124, 164), np.uint8))
    assert main(["fit", str(tmp_path / "s"), "--gender", "female", "--quick"]) == 0
    out = capsys.readouterr().out
    assert "frame 0 failed: cam0: the silhouette covers 100% of the image" in out
    rec = json.loads((tmp_path / "s" / "fit" / "000000.json").read_text())
    assert rec["fitted"] is False and "shape" not in rec and rec["quality"]["status"] == "failed"
    assert not (tmp_path / "s" / "fit" / "000000.ply").exists()
    assert sorted(load_fits(tmp_path / "s")) == [1]
    q = load_quality(tmp_path / "s")
    assert q[0]["status"] == "failed" and q[1]["status"] in ("ok", "suspect", "failed")
    seq = json.loads((tmp_path / "s" / "fit" / "sequence.json").read_text())
    assert seq["key_frame"] == 1 and seq["quality"]["0"] == "failed" and list(seq["costs"]) == ["1"]
    assert main(["report", str(tmp_path / "s")]) == 0
    html = (tmp_path / "s" / "report" / "index.html").read_text()
    assert "covers 100% of the image" in html
    # every frame refused: a clear error, the records still written
    for c in ("cam0", "cam1", "cam2"):
        write_image(tmp_path / "s" / "segmentation" / c / "000001.png", np.ones((124, 164), np.uint8))
    with pytest.raises(FitError, match="no frame passed the segmentation checks"):
        fit_session(tmp_path / "s", gender="female", options=TINY, force=True)
    assert json.loads((tmp_path / "s" / "fit" / "000001.json").read_text())["fitted"] is False


def test_rerun_keeps_frames_fitted_with_the_same_settings(tmp_path, monkeypatch):
    import studio.fit.units as fs

    make_session(tmp_path / "s", n_frames=3)
    first = fit_session(tmp_path / "s", gender="female", options=TINY, seed=0)
    assert first["kept"] == [] and first["frames"] == [0, 1, 2]
    (tmp_path / "s" / "fit" / "000002.json").unlink()  # as if killed before frame 2 finished
    fitted = []
    real = fs.fit_frame

    def counting(*args, **kwargs):
        fitted.append(kwargs["frame"])
        return real(*args, **kwargs)

    monkeypatch.setattr(fs, "fit_frame", counting)
    again = fit_session(tmp_path / "s", gender="female", options=TINY, seed=0)
    assert again["kept"] == [0, 1] and sorted(set(fitted)) == [2]
    assert again["costs"]["0"] == first["costs"]["0"]
    fitted.clear()
    other_seed = fit_session(tmp_path / "s", gender="female", options=TINY, seed=1)
    assert other_seed["kept"] == [] and sorted(set(fitted)) == [1, 2]  # frame 0: the key frame, fitted by gender
    fitted.clear()
    forced = fit_session(tmp_path / "s", gender="female", options=TINY, seed=1, force=True)
    assert forced["kept"] == [] and sorted(set(fitted)) == [1, 2]
    # the masks relabelled since (other segmentation settings or code): nothing kept
    summary = tmp_path / "s" / "segmentation" / "segmentation.json"
    summary.write_text(json.dumps({"settings": {"voting": True, "code": "0" * 16}}))
    fitted.clear()
    relabelled = fit_session(tmp_path / "s", gender="female", options=TINY, seed=1)
    assert relabelled["kept"] == [] and sorted(set(fitted)) == [1, 2]
    assert fit_session(tmp_path / "s", gender="female", options=TINY, seed=1)["kept"] == [0, 1, 2]


def test_unwritable_fit_folder_fails_before_any_work(tmp_path, monkeypatch):
    import studio.fit.units as fs

    make_session(tmp_path / "s", n_frames=1)
    (tmp_path / "s" / "fit").write_text("not a folder")
    monkeypatch.setattr(fs, "fit_frame_gender", lambda *a, **k: pytest.fail("fitted before checking the output"))
    with pytest.raises(FitError, match=r"fit: cannot write results there .*--out DIR"):
        fit_session(tmp_path / "s", gender="female", options=TINY)


def test_report_escapes_hostile_names(tmp_path):
    from studio.report import write_report

    hostile = tmp_path / "<img src=x onerror=alert(1)>"
    make_session(hostile, n_frames=1)
    fit_session(hostile, gender="female", options=TINY)
    page = write_report(hostile).read_text()
    assert "<img src=x" not in page and "onerror=alert(1)>" not in page
    assert "&lt;img src=x onerror=alert(1)&gt;" in page
    assert page.count("<img ") >= 3  # the report's own pictures are still there
    rows = (hostile / "report" / "measurements.csv").read_text().splitlines()
    assert rows[0].startswith("name,unit,mean,std,status,flags,truth,error") and len(rows) > 5
    table = json.loads((hostile / "report" / "measurements.json").read_text())["measurements"]
    assert 1000 < table["stature"]["mean"] < 2200 and table["stature"]["truth"] is None


def test_every_frame_refused_says_why_not_run_fit(tmp_path):
    """A session whose every frame the quality gates refused has results, but no body: loading
    them names the refused frames and their first reason instead of asking for a fit."""
    from studio.fit.errors import UnusableFrame
    from studio.fit.output import write_unfitted
    from studio.workspace import Layout

    lay = Layout(tmp_path)
    for f, msg in ((3, "2 disconnected blobs in the silhouette"), (5, "the mask covers 97% of the image")):
        quality = {"status": "failed", "reasons": [{"check": "blobs", "severity": "failed", "view": "cam1",
                                                    "message": msg}]}
        write_unfitted(lay, UnusableFrame(f, quality))
    with pytest.raises(FitError, match=r"refused every frame \(2 failed — frame 3 failed: cam1: 2 disconnected "
                                       r"blobs in the silhouette; frame 5 failed: cam1: the mask covers 97%"):
        load_fits(tmp_path)
    with pytest.raises(FitError, match="no fitted frames — run `studio fit"):
        load_fits(tmp_path, frames=[4])


def test_cli_batch_writes_batch_json_mesh_and_the_report_uses_it(tmp_path, capsys, monkeypatch):
    """``studio fit --batch``: single-frame fits, then one shared shape (fit/batch.json with the
    frames, per-frame poses and costs, fit/batch_neutral.ply); ``studio report`` measures it."""
    import studio.cli.commands.fit as fit_cmd

    make_session(tmp_path / "s", n_frames=2)
    monkeypatch.setattr(fit_cmd, "QUICK", {k: v for k, v in TINY.to_dict().items() if k != "levels"})
    assert main(["fit", str(tmp_path / "s"), "--frames", "0,1", "--gender", "female", "--quick", "--batch",
                 "--clothing", "tight"]) == 0
    out = capsys.readouterr().out
    assert "batch of 2 frames [0, 1]: female, clothing tight" in out
    obj = json.loads((tmp_path / "s" / "fit" / "batch.json").read_text())
    assert obj["format"] == "studio.fit-batch" and obj["frames"] == [0, 1] and obj["clothing"] == "tight"
    assert set(obj["poses"]) == set(obj["costs"]) == {"0", "1"} and obj["gender_margin"] is None
    assert 1.4 < obj["measurements"]["stature"] < 2.0
    assert (tmp_path / "s" / "fit" / "batch_neutral.ply").stat().st_size > 10000
    assert main(["report", str(tmp_path / "s")]) == 0
    html = (tmp_path / "s" / "report" / "index.html").read_text()
    assert "batch shape" in html
    table = json.loads((tmp_path / "s" / "report" / "measurements.json").read_text())
    assert table["measurements"]["stature"]["shape_source"] == "batch"
    assert table["measurements"]["stature"]["mean"] == pytest.approx(1000 * obj["measurements"]["stature"], abs=1.0)
    # the gender was given: no test; quality from the consistency check alone
    assert obj["gender_test"] is None
    assert obj["quality"]["reasons"] == obj["consistency"]["reasons"]
    assert obj["quality"]["status"] == ("suspect" if obj["consistency"]["flagged"] else "ok")
    # a batch whose gender the frames cannot tell (gender_test uncertain): the report flags every figure
    obj["gender_test"] = {"winner": "female", "margin": 0.003, "per_frame": [0.05, -0.044], "frames_for_winner": 1,
                          "se": 0.047, "confidence": 0.95, "interval": [-0.594, 0.600], "uncertain": True}
    (tmp_path / "s" / "fit" / "batch.json").write_text(json.dumps(obj))
    assert main(["report", str(tmp_path / "s")]) == 0
    html = (tmp_path / "s" / "report" / "index.html").read_text()
    assert "Flagged: gender uncertain: female by 0.003 per frame, 95 % interval -0.594 … +0.600 reaches 0" in html
    rows = json.loads((tmp_path / "s" / "report" / "measurements.json").read_text())["measurements"]
    assert all(r["status"] in ("suspect", "failed") and r["flags"][-1].startswith("gender uncertain") for r in rows.values())
    assert main(["fit", str(tmp_path / "s"), "--batch", "--batch-frames", "1"]) == 1
    assert "--batch-frames must be >= 2" in capsys.readouterr().err
    assert main(["fit", str(tmp_path / "s"), "--batch", "--shadows"]) == 1
    assert "--shadows and --batch together" in capsys.readouterr().err
    with pytest.raises(SystemExit):  # argparse's choices
        main(["fit", str(tmp_path / "s"), "--batch", "--gender-step", "round"])
    assert "invalid choice: 'round'" in capsys.readouterr().err
    # --gender-step reaches the batch's options; without it the per-condition default stands
    from dataclasses import replace

    import studio.fit.batch_session as bs

    seen = []

    def stop(ws, **kw):
        seen.append(kw)
        raise FitError("stopped here")

    monkeypatch.setattr(bs, "fit_batch_session", stop)
    for extra in (["--gender-step", "neutral"], []):
        assert main(["fit", str(tmp_path / "s"), "--batch", "--clothing", "tight", *extra]) == 1
        assert "stopped here" in capsys.readouterr().err
    assert [kw["options"].gender_step for kw in seen] == ["neutral", None]
    # the command's options are the loose defaults; fit_batch_session sets the clothing it fits
    assert [replace(kw["options"], clothing="tight").gender_fit for kw in seen] == ["neutral", "full"]


def test_auto_clothing_called_tight_fits_the_batch_tight_fits(tmp_path, monkeypatch):
    """``--clothing auto`` that calls the clothes tight fits the very batch ``--clothing tight``
    fits (from the single fits, the tight gender rule), not a tight round from the loose batch's
    body: the figures measured with ``--clothing tight`` are those auto gives a tightly dressed
    person."""
    import studio.fit.batch_session as bs
    from studio.fit.batch import BatchOptions

    make_session(tmp_path / "s", n_frames=2)
    opts = BatchOptions(levels=(2, 1), rounds=1, pose_evaluations=20, shape_evaluations=30, final_evaluations=20,
                        pose_iterations=2)
    run = dict(frames=[0, 1], gender="female", single_options=TINY, options=opts, chain_length=1)
    tight = bs.fit_batch_session(tmp_path / "s", clothing="tight", **run)
    calls = []
    monkeypatch.setattr(bs, "clothing_from_coverage", lambda c: calls.append(c) or "tight")
    auto = bs.fit_batch_session(tmp_path / "s", clothing="auto", **run)
    assert len(calls) == 1 and 0.5 < calls[0] <= 1.0  # the loose batch body covers the (tight) clothes
    assert auto["clothing"] == "tight" and auto["clothing_auto"]["chosen"] == "tight"
    assert auto["shape"] == tight["shape"] and auto["poses"] == tight["poses"] and auto["total"] == tight["total"]
    n = len(tight["history"])
    assert auto["settings"]["clothing"] == "tight"
    assert [h["cost"] for h in auto["history"][-n:]] == [h["cost"] for h in tight["history"]]
    assert len(auto["history"]) > len(tight["history"])  # the loose batch's rounds before it
