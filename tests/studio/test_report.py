"""Measurement reports: HTML and PDF pages, participant metadata, uncertainty, population, exports.

The session is tiny and not fitted: its fit results are the true body written through the
fitter's own writer (``write_frame_fit``) with the real quality gates, so every figure the
report shows has a known answer."""

import json

import numpy as np
import pytest

from calibration import Camera, RigCalibration
from studio.body import BodyModel, measure
from studio.cli import main
from studio.fit.result import FrameFit
from studio.fit.output import write_frame_fit
from studio.fit.quality import fit_quality
from studio.report import Participant, write_report
from studio.report.exports import TRC_NAMES, read_trc
from studio.report.measurements import UNITS, measurement_table
from studio.report.population import PERCENTILES_FILE, population_context, summarise_percentiles
from studio.report.uncertainty import (calibration_rms, calibration_sigma, combine, laplace_shape_covariance,
                                       load_model_error, session_uncertainty, shape_hessian)
from studio.simulate.silhouettes import write_silhouette_session
from studio.workspace import Layout, Workspace

HOSTILE = "<script>alert('x')</script> & \"Bob\""


def _cameras(size=(200, 150), focal=170.0):
    cams = []
    for k in range(3):
        a = np.pi / 4 + 2 * np.pi * k / 3
        eye = np.array([3.6 * np.cos(a), 3.6 * np.sin(a), 2.3])
        cams.append(Camera.look_at(f"cam{k}", eye, [0, 0, 0.9], focal, size, np.zeros(5)))
    return cams


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    """Two frames of the female model's body (a sampled shape), its true fits written as results."""
    root = tmp_path_factory.mktemp("report")
    path = root / "s"
    model = BodyModel.load("female")
    shape = model.sample_shapes(1, np.random.default_rng(3), scale=0.5)[0]
    cams = _cameras()
    calib = root / "calibration.json"
    RigCalibration(cameras={c.name: c for c in cams}).save(calib)
    lay = Layout(path)
    poses = []
    for i in range(2):
        pose = model.default_pose()
        pose[:2] = [0.04 * i, 0.0]
        pose[5] = 0.3
        poses.append(pose)
    for i, (pose, masks) in enumerate(zip(poses, write_silhouette_session(path, model, shape, poses, cams, calib))):
        q = fit_quality(model, cams, masks, shape, pose, {"silhouette_per_view": {c.name: 0.1 for c in cams}})
        fit = FrameFit(i, "female", shape, pose, model.joints(shape, pose), {"total": 0.1, "silhouette": 0.1},
                       {"total": 1.0}, 1, {"levels": [1, 1, 0]}, q)
        write_frame_fit(lay, fit, model, cams, masks)
    return path, model, shape, cams


def test_participant_is_checked():
    with pytest.raises(ValueError, match="participant sex: expected 'female' or 'male'"):
        Participant("a", sex="robot")
    with pytest.raises(ValueError, match="participant age: expected years between 0 and 130"):
        Participant("a", age=-3)
    with pytest.raises(ValueError, match="participant id: expected text"):
        Participant("x" * 201)


def test_report_html_pdf_and_escaping(session):
    path, model, shape, cams = session
    page = write_report(path, participant=Participant(HOSTILE, "female", 34, notes="<b>n</b>"), pdf=True).read_text()
    assert "<script>" not in page and "&lt;script&gt;alert(&#x27;x&#x27;)&lt;/script&gt;" in page
    assert "&lt;b&gt;n&lt;/b&gt;" in page
    assert str(path.parent) not in page  # no machine path in the page
    assert "eq. 4.6 px" not in page and "does not do" not in page
    assert "@media print" in page and "ISO 7250-1 4.1.2" in page and "ANSUR II" in page
    # overlays at full resolution: the embedded PNG is the camera's size
    import base64

    import cv2

    src = page.split('alt="cam0"')[0].rsplit('src="data:image/png;base64,', 1)[1].split('"')[0]
    img = cv2.imdecode(np.frombuffer(base64.b64decode(src), np.uint8), cv2.IMREAD_COLOR)
    assert img.shape[:2] == (150, 200)
    table = json.loads((path / "report" / "measurements.json").read_text())
    assert table["participant"]["id"] == HOSTILE and len(table["measurements"]) == 20
    # the true body was written as the fit: every measurement equals the model's own value
    want = measure(model, shape)
    for name, row in table["measurements"].items():
        assert row["mean"] == pytest.approx(want[name] * UNITS[name][1], rel=1e-9), name
        assert row["ci95"][0] < row["mean"] < row["ci95"][1]
    # the PDF's first page, rendered, is not blank
    pdfium = pytest.importorskip("pypdfium2")
    doc = pdfium.PdfDocument(str(path / "report" / "report.pdf"))
    assert len(doc) >= 4
    page0 = np.asarray(doc[0].render(scale=0.5).to_pil().convert("L"))
    assert (page0 < 128).mean() > 0.02 and page0.std() > 20


def test_flagged_figures_are_never_printed_clean(session):
    path, model, shape, cams = session
    from studio.fit import load_fits

    fits = load_fits(path)
    for f in fits.values():
        f.quality["status"] = "suspect"
    table = measurement_table(model, fits)
    assert all(r["status"] == "suspect" and "no clean frame" in r["flags"][0] for r in table.values())
    from studio.report.html import _table_html

    html = _table_html(table)
    assert html.count("<s>") == len(table) and html.count("(suspect)") == len(table)
    # an implausible value is flagged by its population z-score
    import dataclasses

    big = shape.copy()
    big[0] = 3.0 * np.sqrt(model.eigenvalues[0])
    t2 = measurement_table(model, {0: dataclasses.replace(fits[0], shape=big, quality={"status": "ok"})})
    assert any(r["status"] != "ok" and "ANSUR II" in " ".join(r["flags"]) for r in t2.values())


def test_uncertainty_components(session):
    path, model, shape, cams = session
    ws = Workspace.open(path)
    rms, src = calibration_rms(ws.calibration)
    assert src.startswith("none recorded") and set(rms.values()) == {0.5}
    cal = RigCalibration(cameras={c.name: c for c in cams}, metadata={"extrinsics": {"rms_px": 0.3, "camera_rms_px":
                                                                                     {"cam0": 0.2}}})
    assert calibration_rms(cal) == ({"cam0": 0.2, "cam1": 0.3, "cam2": 0.3}, "bundle adjustment")
    # σ_b = e·Z / f / √N: every camera 1 px at its own distance
    c = np.array([0.0, 0.0, 0.9])
    z = [float((cam.R @ c + cam.t)[2]) for cam in cams]
    want = np.sqrt(np.mean([(1.0 * d / 170.0) ** 2 for d in z]) / 3)
    assert calibration_sigma(cams, {n: 1.0 for n in rms}, c) == pytest.approx(want, rel=1e-12)
    assert combine(3.0, None, 4.0) == pytest.approx(5.0)
    from studio.fit import load_fits

    fits = load_fits(path)
    H, sigma = shape_hessian(model, cams, ws.person_masks(0), fits[0].shape, fits[0].pose)
    assert np.allclose(H, H.T) and np.all(np.linalg.eigvalsh(H) > 0)  # every direction measured, none left to the prior
    C = laplace_shape_covariance(model, cams, ws.person_masks(0), fits[0].shape, fits[0].pose, temperature=0.05)
    assert np.allclose(C, np.linalg.inv(H / 0.05 + np.diag(1 / sigma**2)))
    prior = model.eigenvalues[:len(C)]
    assert np.all(np.linalg.eigvalsh(C) > 0) and np.all(np.diag(C) < prior)
    assert C[0, 0] < 0.5 * prior[0]  # the silhouettes (200x150 px) pin the leading direction
    hot = laplace_shape_covariance(model, cams, ws.person_masks(0), fits[0].shape, fits[0].pose, temperature=5.0)
    assert np.all(np.diag(hot) > np.diag(C))  # a hotter likelihood informs less
    u = session_uncertainty(model, cams, ws.calibration, fits, [0, 1], ws.person_masks, max_frames=1)
    assert set(u["posterior"]) == set(UNITS) and u["info"]["posterior_frames"] == [0]
    shipped = load_model_error()
    assert u["model"] == shipped["model_sigma"] and set(shipped["model_sigma"]) == set(UNITS)
    assert u["info"]["temperature"] == shipped["temperature"] and u["info"]["model_error_source"] == shipped["source"]
    assert u["calibration"]["chest_circumference"] == pytest.approx(2 * np.pi * u["info"]["surface_sigma_mm"] / 1000)


def test_model_error_file(tmp_path):
    bad = tmp_path / "model_error.json"
    bad.write_text('{"temperature": 0.03}')
    with pytest.raises(ValueError, match=r"model_error.json: not a model-error calibration .*'model_sigma'.*calibrate"):
        load_model_error(bad)
    shipped = load_model_error()
    assert 0.002 <= shipped["temperature"] <= 2.0 and all(0.0 <= v < 0.05 for v in shipped["model_sigma"].values())
    assert "dev split" in shipped["source"]  # learned on the dev people, never the held-out ones


def test_population_percentiles(shared_data):
    rebuilt = summarise_percentiles(shared_data / "anthropometry" / "ansur2")
    shipped = json.loads(PERCENTILES_FILE.read_text())
    assert rebuilt == shipped
    male = shipped["sexes"]["male"]["stature"]
    assert population_context("stature", male["percentiles"][49], "male")["percentile"] == pytest.approx(50, abs=0.01)
    assert 1.70 < male["mean"] < 1.80 and shipped["sexes"]["female"]["stature"]["mean"] < male["mean"]
    assert population_context("stature", 2.4, "female")["text"] == "> 99th"
    assert population_context("eye_height", 1.6, "male") is None  # ANSUR measures it sitting only


def test_exports_reload(session, capsys):
    trimesh = pytest.importorskip("trimesh")
    pygltflib = pytest.importorskip("pygltflib")
    from studio.body.parameters import load_parameters

    path, model, shape, cams = session
    assert main(["export", str(path)]) == 0
    out = capsys.readouterr().out
    ex = path / "export"
    assert "wrote" in out and (ex / "frames" / "000001.glb").is_file()
    want = model.vertices(shape)
    obj = trimesh.load(ex / "body_neutral.obj", force="mesh", process=False)
    np.testing.assert_allclose(obj.vertices, want, atol=1e-6)
    np.testing.assert_array_equal(obj.faces, model.faces)
    g = pygltflib.GLTF2().load(str(ex / "body_neutral.glb"))
    acc = g.accessors[g.meshes[0].primitives[0].attributes.POSITION]
    view = g.bufferViews[acc.bufferView]
    blob = g.binary_blob()
    pos = np.frombuffer(blob[view.byteOffset:view.byteOffset + view.byteLength], "<f4").reshape(-1, 3)
    np.testing.assert_allclose(pos, want, atol=1e-6)
    glb = trimesh.load(ex / "frames" / "000001.glb", force="mesh", process=False)
    assert len(glb.vertices) == model.n_vertices
    names, times, xyz = read_trc(ex / "joints.trc")
    assert names == list(TRC_NAMES) and xyz.shape == (2, 15, 3)
    J = model.joints(shape, load_parameters(ex / "model_parameters.json").frames[1][1])
    np.testing.assert_allclose(xyz[1], np.stack([J[:, 0], J[:, 2], -J[:, 1]], axis=1), atol=2e-6)
    params = load_parameters(ex / "model_parameters.json")
    np.testing.assert_allclose(params.vertices(), want, atol=1e-9)
    rows = (ex / "measurements.csv").read_text().splitlines()
    assert len(rows) == 21 and rows[1].startswith("stature,mm,")
    bad = ex / "bad.json"
    bad.write_text(json.dumps({"format": "studio.body-parameters", "version": 1, "gender": "female", "shape": [1]}))
    with pytest.raises(ValueError, match=r"field 'shape': expected \d+ finite numbers"):
        load_parameters(bad)
    with pytest.raises(ValueError, match="not a TRC file"):
        read_trc(bad)


def test_bad_inputs_are_named(tmp_path, capsys):
    from studio.body.parameters import load_parameters
    from studio.fit import FitError
    from studio.report.data import gather
    from studio.report.exports import export_session
    from studio.report.measurements import frames_used

    with pytest.raises(ValueError, match="participant notes: expected text"):
        Participant("a", notes=3)
    with pytest.raises(FileNotFoundError, match="ANSUR_II_FEMALE_Public.csv: ANSUR II CSV not found"):
        summarise_percentiles(tmp_path)
    (tmp_path / "ANSUR_II_FEMALE_Public.csv").write_text("stature,weightkg\n1600,600\n")
    with pytest.raises(ValueError, match="FEMALE_Public.csv: no column 'acromialheight'"):
        summarise_percentiles(tmp_path)
    (tmp_path / "ANSUR_II_FEMALE_Public.csv").write_text("stature,weightkg\ntall,600\n")
    with pytest.raises(ValueError, match="FEMALE_Public.csv: column 'stature': could not convert"):
        summarise_percentiles(tmp_path)
    p = tmp_path / "p.json"
    p.write_text("{")
    with pytest.raises(ValueError, match="not a readable JSON file"):
        load_parameters(p)
    p.write_text(json.dumps({"format": "other"}))
    with pytest.raises(ValueError, match="expected format 'studio.body-parameters' version 1"):
        load_parameters(p)
    p.write_text(json.dumps({"format": "studio.body-parameters", "version": 1, "gender": "robot"}))
    with pytest.raises(ValueError, match="field 'gender': expected one of"):
        load_parameters(p)
    shape = [0.0] * BodyModel.load("female").n_shape
    p.write_text(json.dumps({"format": "studio.body-parameters", "version": 1, "gender": "female", "shape": shape,
                             "frames": {"3": []}}))
    with pytest.raises(ValueError, match="field 'frames.3': expected an object"):
        load_parameters(p)
    trc = tmp_path / "bad.trc"
    trc.write_text("PathFileType\t4\n\n1\t1\t5\t15\n\n\n\n1\t0\t1\n")
    with pytest.raises(ValueError, match="header says 5 frames of 15 markers"):
        read_trc(trc)
    with pytest.raises(ValueError, match="export kind"):
        export_session(tmp_path, ("stl",))
    with pytest.raises(ValueError, match="no fitted frames"):
        frames_used({})
    with pytest.raises(FitError, match="no such session folder"):
        gather(tmp_path / "absent")
    assert main(["report", str(tmp_path), "--age", "-4"]) == 1
    assert "participant age" in capsys.readouterr().err


def test_a_loose_batch_reports_the_standing_height_as_its_stature():
    """ISO 7250-1 stature read off posed bodies: the highest head point above the floor, median over
    the standing poses (a squat's head 220 mm lower is left out); on the mean woman standing it is
    her rest body's stature within 5 mm. A loose batch with its poses reports it (``method`` says
    so, status kept); without the poses, with none standing (a lone squat), or tight, the rest
    body's stature stands."""
    from studio.body.skeleton import PART_NAMES, pose_slices
    from studio.fit.init import standing_pose
    from studio.fit.library import stand_on_floor
    from studio.report.measurements import LOOSE_FLAGS, standing_height, use_batch_shape

    model = BodyModel.load("female")
    shape, sl = model.mean_shape(), pose_slices()
    stand, turned = standing_pose(model), standing_pose(model)
    turned[5] = 1.0
    squat = standing_pose(model)
    for leg, angle in (("upperleg_l", -1.2), ("upperleg_r", -1.2), ("lowerleg_l", 1.5), ("lowerleg_r", 1.5)):
        squat[sl[PART_NAMES.index(leg)].start] = angle
    poses = stand_on_floor(model, shape, np.array([squat, stand, turned]))
    head = model.parts == PART_NAMES.index("head")
    tops = [model.vertices(shape, p)[head, 2].max() for p in poses]
    assert tops[1] - tops[0] > 0.2
    height, used = standing_height(model, shape, poses)
    assert used == [1, 2] and height == pytest.approx(np.median(tops[1:]), abs=1e-12)
    rest = measure(model, shape)["stature"]
    assert abs(height - rest) < 0.005
    # lifted 40 mm off the floor, the standing height says so (the floor is world z = 0)
    lifted = poses.copy()
    lifted[:, 2] += 0.04
    assert standing_height(model, shape, lifted)[0] == pytest.approx(height + 0.04, abs=1e-9)
    row = {"mean": 1000 * rest, "ci95": [1000 * rest - 5, 1000 * rest + 5], "status": "ok", "flags": [],
           "truth": None, "truth_anny": None, "per_frame": {}}
    table = {"stature": dict(row), "knee_height": dict(row)}
    loose = use_batch_shape(table, model, shape, frames=[10, 11, 12], clothing="loose", poses=lifted)
    assert loose["stature"]["mean"] == pytest.approx(1000 * (height + 0.04), abs=1e-6)
    assert loose["stature"]["status"] == "ok" and "frame(s) [11, 12]" in loose["stature"]["method"]
    assert loose["knee_height"]["flags"] == [LOOSE_FLAGS["joints"]]
    bare = use_batch_shape(table, model, shape, frames=[10, 11, 12], clothing="loose")
    assert bare["stature"]["mean"] == pytest.approx(1000 * rest, abs=1e-6)
    assert bare["stature"]["flags"] == [LOOSE_FLAGS["joints"]] and "method" not in bare["stature"]
    crouched = use_batch_shape(table, model, shape, frames=[10], clothing="loose", poses=poses[:1])
    assert crouched["stature"]["mean"] == pytest.approx(1000 * rest, abs=1e-6)  # no frame stood: the rest body's
    assert crouched["stature"]["flags"] == [LOOSE_FLAGS["joints"]] and "method" not in crouched["stature"]
    tight = use_batch_shape(table, model, shape, frames=[10, 11, 12], clothing="tight", poses=lifted)
    assert tight["stature"]["mean"] == pytest.approx(1000 * rest, abs=1e-6) and "method" not in tight["stature"]


def test_heights_leave_out_sitting_and_squatting_frames_and_are_flagged_without_a_standing_one(session):
    """Our model's hips shorten a seated or squatting body (pose benchmark: stature −26 to −34 mm
    median): the heights are measured on the frames that stand, and ``suspect`` when none does;
    the other measurements keep every frame."""
    import dataclasses

    from studio.fit import load_fits
    from studio.fit.library import family_pose
    from studio.report.measurements import BENT_FLAG, bent_frames

    path, model, shape, cams = session
    fits = load_fits(path)
    postures = {name: dataclasses.replace(fits[0], pose=family_pose(model, name))
                for name in ("a_pose", "t_pose", "walk", "run", "lunge", "wide_stance", "half_squat", "seated")}
    assert bent_frames(model, postures) == {"half_squat", "seated"}
    seated = dataclasses.replace(fits[1], pose=family_pose(model, "seated"))
    clean = measurement_table(model, fits)
    mixed = measurement_table(model, {0: fits[0], 1: seated})
    row = mixed["stature"]
    assert row["frames_used"] == [0] and row["status"] == "ok" and row["mean"] == row["per_frame"]["0"]
    assert row["flags"] == ["1 sitting or squatting frame(s) left out of the mean"]
    assert mixed["chest_circumference"]["frames_used"] == [0, 1] and not mixed["chest_circumference"]["flags"]
    alone = measurement_table(model, {1: seated})
    assert alone["stature"]["status"] == "suspect" and alone["stature"]["flags"] == [BENT_FLAG]
    assert alone["knee_height"]["status"] == "suspect" and alone["waist_circumference"]["status"] == "ok"
    assert clean["stature"]["frames_used"] == [0, 1]
    assert not any("sit" in flag for r in clean.values() for flag in r["flags"])
