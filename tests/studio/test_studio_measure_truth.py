"""Same-definition measurement truth: ``measure_mesh``, the true bodies' canonical postures
(``rest_q``/``tpose_q`` of the sample ``body.npz``), the report's two truths."""

import json
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from studio.body import BodyModel, measure
from studio.body.iso7250 import ISO_NAMES
from studio.body.measure import MEASUREMENT_NAMES, measure_anny_body, measure_mesh, place_canonical, t_pose
from studio.report.measurements import REPORTED, UNITS, measurement_table, write_measurements
from studio.simulate.session import studio_truth

ROOT = Path(__file__).resolve().parents[2] / "studio" / "samples"


@pytest.fixture(scope="module")
def female():
    return BodyModel.load("female")


def _arrays(path: Path) -> dict:
    with np.load(path) as z:
        return {k: z[k] for k in z.files}


@pytest.fixture(scope="module")
def walk():
    return _arrays(ROOT / "walk" / "body.npz")


@pytest.fixture(scope="module")
def walk_truth(walk):
    return studio_truth(walk, "female")


def test_measure_mesh_is_what_measure_computes(female):
    shape = female.sample_shapes(1, np.random.default_rng(5))[0]
    want = measure(female, shape)
    v = female.vertices(shape)
    vt = female.vertices(shape, t_pose(female, shape))
    got = measure_mesh(v, vt, female.joints(shape), female.faces, female.parts, female.face_parts)
    assert got == want  # bit for bit: measure is measure_mesh on the model's meshes
    assert set(got) == set(MEASUREMENT_NAMES) | set(ISO_NAMES)
    # a translated body measures the same (only the sagittal plane x = 0 is fixed)
    shift = np.array([0.0, 0.4, 0.25])
    moved = measure_mesh(v + shift, vt + shift, female.joints(shape) + shift, female.faces,
                         female.parts, female.face_parts)
    for k in got:
        assert moved[k] == pytest.approx(want[k], abs=2e-3), k


def test_measure_mesh_rejects_bad_input(female):
    s = female.mean_shape()
    v, J = female.vertices(s), female.joints(s)
    f, p, fp = female.faces, female.parts, female.face_parts
    with pytest.raises(ValueError, match=r"tpose_vertices must have shape \(\d+, 3\), got \(5, 3\)"):
        measure_mesh(v, v[:5], J, f, p, fp)
    with pytest.raises(ValueError, match=r"joints must have shape \(15, 3\)"):
        measure_mesh(v, v, J[:14], f, p, fp)
    with pytest.raises(ValueError, match=r"face_parts must have shape"):
        measure_mesh(v, v, J, f, p, fp[:-1])
    bad = v.copy()
    bad[3, 0] = np.nan
    with pytest.raises(ValueError, match="vertices contains NaN"):
        measure_mesh(bad, v, J, f, p, fp)
    with pytest.raises(ValueError, match=r"faces index vertices 0\.\.\d+, the mesh has 100"):
        measure_mesh(v[:100], v[:100], J, f, p[:100], fp)
    with pytest.raises(ValueError, match="density must be a positive"):
        measure_mesh(v, v, J, f, p, fp, density=0.0)
    with pytest.raises(ValueError, match=r"rest_vertices must have shape \(13348, 3\)"):
        measure_anny_body(female, v, v)
    anny = np.zeros((13348, 3))
    fake = SimpleNamespace(n_vertices=10, gender="tiny")
    with pytest.raises(ValueError, match="maps to .* vertices, the tiny model has 10"):
        measure_anny_body(fake, anny, anny)


def test_walk_truth_by_our_definitions_agrees_with_anny_where_they_coincide(walk, walk_truth):
    """Stature: our rest-pose height vs Anny's T-pose height (same body, arms do not reach the
    head): within 5 mm. Volume/mass: our decimated topology vs Anny's mesh, within 1 %."""
    anny = json.loads(str(walk["measurements"]))
    t = walk_truth
    assert set(t) == set(MEASUREMENT_NAMES) | set(ISO_NAMES)
    assert t["stature"] == pytest.approx(anny["stature"], abs=0.005)
    assert t["mass"] == pytest.approx(anny["mass"], rel=0.01)
    # waist by our definition (narrowest trunk slice) is well below Anny's anthropometric waist
    assert 0.04 < anny["waist_circumference"] - t["waist_circumference"] < 0.12
    assert t["waist_circumference"] < t["chest_circumference"] < t["hip_circumference"]
    assert 0.42 < t["inseam"] / t["stature"] < 0.48
    assert 0.27 < t["shoulder_breadth"] / t["stature"] < 0.31


def test_walk_arm_span_is_the_straight_arm_t_pose(female, walk, walk_truth):
    """Arm span: the T-pose of tpose_q mapped into our topology keeps Anny's fingertip span
    within 5 mm; span ≈ stature (0.95–1.02); our joint regressor on it finds shoulder, elbow and
    wrist on one horizontal line along x (within 1 cm): upper arms horizontal, elbows straight."""
    from studio.body import anny_correspondence
    from studio.body.skeleton import PART_NAMES

    sc = float(walk["scale"])
    tpose = walk["tpose_q"] * sc
    assert walk_truth["arm_span"] == pytest.approx(np.ptp(tpose[:, 0]), abs=0.005)
    assert 0.95 < walk_truth["arm_span"] / walk_truth["stature"] < 1.02
    J = female.joint_regressor @ (anny_correspondence() @ tpose)
    for side in ("l", "r"):
        s, e, w = (J[PART_NAMES.index(f"{p}_{side}")] for p in ("upperarm", "lowerarm", "hand"))
        np.testing.assert_allclose(e[1:], s[1:], atol=0.01)
        np.testing.assert_allclose(w[1:], s[1:], atol=0.01)
        assert abs(w[0] - s[0]) > 0.4  # shoulder → wrist along ±x: the whole arm


def test_anny_static_t_pose_bends_the_elbows():
    """clothing_poses' "t_pose" frame (Anny's STATIC_POSES, elbows bent ~43°) spans 10–25 cm
    less than the measurement T-pose of the same person: why the truth uses tpose_q."""
    body = _arrays(ROOT / "clothing_poses" / "body.npz")
    i = [str(n) for n in body["pose_names"]].index("t_pose")
    world = body["vertices_q"][i] * float(body["scale"])
    a = float(body["yaw"][i]) + math.pi / 2  # Anny's +x in the world (truth_build._to_world)
    static_span = np.ptp(world[:, :2] @ [math.cos(a), math.sin(a)])
    straight_span = np.ptp(body["tpose_q"][:, 0] * float(body["scale"]))
    assert 0.10 < straight_span - static_span < 0.25


def test_place_canonical_centres_pelvis_on_the_floor(female, walk):
    from studio.body import anny_correspondence

    v = place_canonical(anny_correspondence() @ (walk["rest_q"] * float(walk["scale"])), female.parts)
    np.testing.assert_allclose(v[female.parts == 0].mean(axis=0)[:2], 0.0, atol=1e-12)
    assert v[:, 2].min() == 0.0


def test_studio_truth_needs_the_canonical_postures(walk):
    old = {k: v for k, v in walk.items() if k not in ("rest_q", "tpose_q")}
    assert studio_truth(old) is None


def _fits(model, n=2):
    shapes = model.sample_shapes(n, np.random.default_rng(1), scale=0.5)
    return {i * 4: SimpleNamespace(shape=s) for i, s in enumerate(shapes)}


def test_report_prefers_same_definition_truth_and_keeps_anny(female, walk, walk_truth, tmp_path):
    fits = _fits(female)
    anny = json.loads(str(walk["measurements"]))
    table = measurement_table(female, fits, dict(anny, studio=walk_truth))
    for name in REPORTED:
        r = table[name]
        scale = UNITS[name][1]
        assert r["truth_source"] == "studio"
        assert r["truth"] == pytest.approx(walk_truth[name] * scale)
        assert r["error"] == pytest.approx(r["mean"] - r["truth"])
    assert table["waist_circumference"]["truth_anny"] == pytest.approx(anny["waist_circumference"] * 1000)
    w = table["waist_circumference"]
    assert w["error_anny"] - w["error"] == pytest.approx(w["truth"] - w["truth_anny"])
    assert table["arm_span"]["truth_anny"] is None and table["arm_span"]["error_anny"] is None
    _, csv_path = write_measurements(tmp_path, table)
    rows = csv_path.read_text().splitlines()
    assert rows[0].startswith("name,unit,mean,std,status,flags,truth,error,truth_anny,error_anny,clause,sigma,")
    assert rows[0].endswith(",frame_0,frame_4")
    arm = next(r.split(",") for r in rows if r.startswith("arm_span"))
    assert arm[4] == "ok" and arm[6] == f"{walk_truth['arm_span'] * 1000:.2f}" and arm[8] == arm[9] == ""


def test_report_without_studio_truth_falls_back_to_anny(female, walk, tmp_path):
    """Sessions rendered before the "studio" entry existed still report their truth."""
    fits = _fits(female, 1)
    anny = json.loads(str(walk["measurements"]))
    table = measurement_table(female, fits, anny)
    assert table["stature"]["truth_source"] == "anny"
    assert table["stature"]["truth"] == table["stature"]["truth_anny"] == pytest.approx(anny["stature"] * 1000)
    assert table["arm_span"]["truth"] is None and table["arm_span"]["truth_source"] is None
    bare = measurement_table(female, fits, None)
    assert all(r["truth"] is None and r["truth_anny"] is None for r in bare.values())
    with pytest.raises(ValueError, match="'studio' must be a mapping"):
        measurement_table(female, fits, {"studio": [1.0]})


def test_simulated_session_carries_both_truths(tmp_path, walk_truth):
    """A (tiny) render of the walk body writes Anny's values and the "studio" entry."""
    from studio.report.measurements import load_truth
    from studio.simulate import simulate

    spec = tmp_path / "spec.yaml"
    spec.write_text(
        "format: studio.sim-spec\nversion: 1\nname: tiny_walk\n"
        f"body: {json.dumps(str(ROOT / 'walk' / 'body.npz'))}\n"
        "fps: 24\nseed: 0\nframes: [0, 1]\nbackground_frames: 1\n"
        "cameras: {count: 1, size: [40, 30], radius: 3.6, height: 2.3, focal_px: 35}\n")
    out = simulate(spec, tmp_path / "s")
    truth = load_truth(out)
    assert truth["studio"] == pytest.approx(walk_truth, abs=1e-12)
    assert "definitions" in truth["studio_source"] and truth["sex"] == "female"
    assert truth["waist_circumference"] == pytest.approx(0.8118, abs=1e-4)  # Anny's, kept as is


def test_cached_render_truth_is_recomputed_when_the_measurement_code_changed(tmp_path, walk, walk_truth):
    """A cached render keeps its images, but its same-definition truth follows the code: a stale
    ``studio_code`` is recomputed on reuse, a current one is left alone (same bytes, same mtime)."""
    from studio.simulate.session import _refresh_truth, truth_code_digest

    path = tmp_path / "truth" / "measurements.json"
    path.parent.mkdir()
    stale = {"sex": "female", "stature": 1.6, "studio": {"stature": walk_truth["stature"] + 0.05},
             "studio_code": "0000000000000000"}
    path.write_text(json.dumps(stale))
    spec = SimpleNamespace(body_path=ROOT / "walk" / "body.npz")
    _refresh_truth(tmp_path, spec)
    fresh = json.loads(path.read_text())
    assert fresh["studio_code"] == truth_code_digest() != stale["studio_code"]
    assert fresh["studio"]["stature"] == pytest.approx(walk_truth["stature"], abs=1e-9)
    assert fresh["sex"] == json.loads(str(walk["measurements"]))["sex"]  # Anny's own figures from the body file
    stamp = path.stat().st_mtime_ns
    _refresh_truth(tmp_path, spec)
    assert path.stat().st_mtime_ns == stamp
