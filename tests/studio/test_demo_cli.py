"""``studio demo`` orchestration (simulate and segment replaced by a tiny ready-made session)."""

import numpy as np
import pytest

from calibration import Camera, RigCalibration
from rigs.imageio import write_image
from rigs.session import SessionWriter
from studio.body import BodyModel
from studio.cli import main
from studio.render import silhouette
from studio.simulate.samples import SAMPLES


def _tiny_session(path):
    model = BodyModel.load("female")
    w, h, f = 164, 124, 140.0
    cams = []
    for k in range(3):
        a = np.pi / 4 + 2 * np.pi * k / 3
        eye = np.array([3.6 * np.cos(a), 3.6 * np.sin(a), 2.3])
        cams.append(Camera.look_at(f"cam{k}", eye, [0, 0, 0.9], f, (w, h), np.zeros(5)))
    calib = path.parent / "calib.json"
    RigCalibration(cameras={c.name: c for c in cams}).save(calib)
    writer = SessionWriter.create(path, [c.name for c in cams], rig="test", calibration=calib)
    V = model.vertices(model.mean_shape(), model.default_pose())
    masks = [silhouette(c, V, model.faces) for c in cams]
    writer.write_frame(0, {c.name: np.repeat(np.where(m, 200, 50).astype(np.uint8)[..., None], 3, 2)
                           for c, m in zip(cams, masks, strict=True)})
    for c, m in zip(cams, masks, strict=True):
        p = path / "segmentation" / c.name / "000000.png"
        p.parent.mkdir(parents=True, exist_ok=True)
        write_image(p, m.astype(np.uint8))
    writer.close()


def test_demo_runs_the_pipeline_and_says_what_is_missing(tmp_path, monkeypatch, capsys):
    import studio.cli.commands.fit as fit_cmd
    import studio.segment
    import studio.simulate

    session = tmp_path / "walk"
    _tiny_session(session)
    calls = {}
    monkeypatch.setattr(studio.simulate, "ensure_rendered",
                        lambda spec, seed=0, progress=None: calls.setdefault("spec", spec) and session)
    monkeypatch.setattr(studio.segment, "segment_session",
                        lambda path, frames=None, workers=1, progress=None, force=False: calls.setdefault("segment", frames))
    monkeypatch.setattr(fit_cmd, "QUICK", dict(n_particles=12, n_layers=2, nm_evaluations=4, final_evaluations=4,
                                               partition_particles=8, partition_layers=1, n_shape_free=2))
    spec = tmp_path / "spec.yaml"
    spec.write_text("name: walk\n")
    # a sample's folder stands for its spec.yaml (as the README and the demo's own hint write it)
    assert main(["demo", "--spec", str(tmp_path), "--frames", "0", "--workers", "1", "--quick"]) == 0
    out = capsys.readouterr().out
    assert calls["spec"] == spec and calls["segment"] == [0]
    assert "Not run by this demo" in out and "light: not estimated (no visible shadow" in out
    assert "--spec studio/samples/clothing_11 " in out and (SAMPLES / "clothing_11" / "spec.yaml").is_file()
    assert f"report: {(session / 'report' / 'index.html').resolve()}" in out
    html = (session / "report" / "index.html").read_text()
    assert "Not run by this demo" not in html and "does not do" not in html  # the report is for a study, not about the demo
    assert str(tmp_path) not in html  # no machine path in the page
    assert (session / "report" / "report.pdf").read_bytes().startswith(b"%PDF")


def test_demo_rejects_a_missing_spec(tmp_path, capsys):
    assert main(["demo", "--spec", str(tmp_path / "nope.yaml")]) == 1
    assert "spec not found" in capsys.readouterr().err
    assert main(["demo", "--spec", str(tmp_path)]) == 1  # a folder without a spec.yaml
    assert f"{tmp_path}: sample sequence spec not found" in capsys.readouterr().err
