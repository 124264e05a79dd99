"""Loose garments drape by posture (studio.simulate.garments.drape): cloth rests where the body
carries it, hangs away below; the true body and tight clothing are untouched."""

import numpy as np
import pytest

from studio.simulate import SAMPLES, load_spec
from studio.simulate.garments import cut_gap, drape, gravity_gap
from studio.simulate.scene import LABEL_BOTTOM, LABEL_TOP, Scene


def _scene(looseness=0.035, top="long_shirt", bottom="trousers", sleeves="long"):
    spec = {"format": "studio.sim-spec", "version": 1, "name": "g", "fps": 1, "background_frames": 0,
            "body": str(SAMPLES / "clothing_poses" / "body.npz"),
            "cameras": {"count": 1, "size": [160, 120], "focal_px": 140.0},
            "person": {"skin_tone": 0.3, "looseness": looseness, "top": {"kind": top, "sleeves": sleeves},
                       "bottom": {"kind": bottom, "length": "long"}}}
    return Scene(load_spec(spec), seed=0)


@pytest.fixture(scope="module")
def loose():
    return _scene()


def _pose(scene, name):
    return [str(n) for n in scene.body.extra["pose_names"]].index(name)


def _region(scene, parts, lo, hi):
    b = scene.body
    h = b.rest_height.astype(np.float64)
    return np.isin(b.parts, [b.part_names.index(p) for p in parts]) & (h >= lo) & (h < hi)


def _gap_mm(scene, frame):
    return 1000 * np.linalg.norm(scene.dressed(frame) - scene.true_vertices(frame).astype(np.float64), axis=1)


def test_gravity_and_cut_shares():
    n = np.array([[0, 0, 1.0], [0, 0.6, 0.8], [0.8, 0, 0.6], [1.0, 0, 0], [0, 0, -1.0]])
    g = gravity_gap(n)
    assert g[0] == 0.0 and g[1] == 0.0  # facing up (37 deg off vertical): carries the cloth
    assert 0.15 < g[2] < 0.2  # 53 deg off vertical: smoothstep(0.25) = 0.156
    assert g[3] == 1.0 and g[4] == 1.0  # sideways, down: hangs at full looseness
    labels = np.array([LABEL_TOP, LABEL_TOP, LABEL_TOP, LABEL_BOTTOM, LABEL_BOTTOM, LABEL_BOTTOM, 0])
    h = np.array([0.88, 0.75, 0.60, 0.56, 0.5125, 0.40, 0.95])
    c = cut_gap(labels, h, LABEL_TOP, LABEL_BOTTOM)
    np.testing.assert_allclose(c, [0.0, 0.5, 1.0, 0.0, 0.5, 1.0, 1.0], atol=1e-12)


def test_standing_shirt_rests_on_shoulders_and_hangs_at_the_hem(loose):
    """A-pose, long shirt 1.2 x 3.5 cm: measured medians 0.5 mm on the shoulders, 27 mm at the
    chest, 36 mm at the waist, 41.9 mm at the hem."""
    gap = _gap_mm(loose, _pose(loose, "a_pose"))
    shoulder = np.median(gap[_region(loose, ["torso"], 0.80, 0.85)])
    chest = np.median(gap[_region(loose, ["torso"], 0.70, 0.75)])
    waist = np.median(gap[_region(loose, ["torso"], 0.58, 0.62)])
    hem = np.median(gap[_region(loose, ["upperleg_l", "upperleg_r"], 0.42, 0.47)])
    assert shoulder < 2.0
    assert 20.0 < chest < 32.0
    assert chest < waist < hem
    assert 40.0 < hem <= 42.0 + 1e-6


def test_sleeve_rests_on_top_of_raised_arm(loose):
    """T-pose: the sleeve lies on the top of the upper arm (0.5 mm) and hangs below it (32 mm);
    arms forward vs the A-pose: the vertices on top of the forward arm carry the sleeve (1.4 mm),
    the same vertices of the lowered arm face sideways (19.8 mm)."""
    from studio.render import vertex_normals

    arm = _region(loose, ["upperarm_l", "upperarm_r"], 0.0, 0.80)

    def top_and_under(pose):
        f = _pose(loose, pose)
        nz = vertex_normals(loose.true_vertices(f).astype(np.float64), loose.body.faces)[:, 2]
        return arm & (nz > 0.9), arm & (nz < -0.7), _gap_mm(loose, f)

    top, under, gap = top_and_under("t_pose")
    assert np.median(gap[top]) < 2.0 and np.median(gap[under]) > 28.0
    top, _, gap = top_and_under("arms_forward")
    lowered = _gap_mm(loose, _pose(loose, "a_pose"))
    assert np.median(gap[top]) < 3.0 and np.median(lowered[top]) > 15.0


def test_trousers_held_at_waistband_and_hips():
    scene = _scene(top="shirt", bottom="trousers")
    gap = _gap_mm(scene, _pose(scene, "a_pose"))
    waistband = np.median(gap[_region(scene, ["pelvis", "upperleg_l", "upperleg_r"], 0.555, 0.575)])
    shin = np.median(gap[_region(scene, ["lowerleg_l", "lowerleg_r"], 0.1, 0.25)])
    assert waistband < 3.0 and shin > 30.0


def test_tight_clothing_and_truth_untouched(loose):
    tight = _scene(looseness=0.0)
    for f in range(2):
        assert np.array_equal(tight.dressed(f), tight.true_vertices(f).astype(np.float64))
        assert np.array_equal(loose.true_vertices(f), tight.true_vertices(f))
    clothed = np.isin(loose.labels, [LABEL_TOP, LABEL_BOTTOM])
    gap = _gap_mm(loose, 0)
    assert np.all(gap[~clothed] == 0.0) and gap.max() < 1.2 * 35.0 + 1e-6


def test_drape_smoothing_stays_in_range(loose):
    from studio.render import vertex_normals

    V = loose.true_vertices(1).astype(np.float64)
    d = drape(vertex_normals(V, loose.body.faces), loose.body.faces, loose.labels, loose.body.rest_height,
              LABEL_TOP, LABEL_BOTTOM)
    assert d.min() >= 0.0 and d.max() <= 1.0
    assert np.all(d[~np.isin(loose.labels, [LABEL_TOP, LABEL_BOTTOM])] == 1.0)


def test_loose_render_cache_key_has_the_garment_model(monkeypatch):
    import studio.simulate.spec as spec_mod

    loose, tight = _scene().spec, _scene(looseness=0.0).spec
    a, t = loose.digest(), tight.digest()
    monkeypatch.setattr(spec_mod, "GARMENT_MODEL", "another")
    assert loose.digest() != a and tight.digest() == t
