"""Light estimation (thesis §5.7, eq. 5.9): a known light recovered from synthetic shadows, its
credible intervals, the refusal of a scene without shadows, ``studio light`` end to end."""

import json

import numpy as np
import pytest

import lightkit
from studio.cli import main
from studio.light import LightError, estimate_light, load_light
from studio.light.params import Frame, direction_of, from_light, to_light
from studio.render import DirectionalLight, PointLight

CAMS = lightkit.cameras(size=(160, 120), focal=135.0)


@pytest.fixture(scope="module")
def bodies():
    return lightkit.bodies(3)


def _masks(bodies, lights):
    return [[lab == 2 for lab in lightkit.labels(CAMS, b, lights)] for b in bodies]


def _angle(a, b):
    return float(np.degrees(np.arccos(np.clip(a @ b, -1, 1))))


def test_params_round_trip():
    frame = Frame(np.array([0.2, -0.1, 0.0]))
    for light in (PointLight([1.4, -1.1, 3.3]), DirectionalLight([-0.5, 0.6, -1.0])):
        kind = "point" if isinstance(light, PointLight) else "directional"
        back = to_light(kind, from_light(light, frame), frame)
        got = back.position if kind == "point" else back.direction
        np.testing.assert_allclose(got, light.position if kind == "point" else light.direction, atol=1e-12)


def test_compiled_objective_matches_render_then_chamfer(bodies):
    """The compiled eq. 5.9 terms (studio.light._kernels) equal rendering the visible shadow
    (predicted_shadows) and scoring it (silhouette_cost), for point, directional and two lights
    and at two levels, a shadow reaching behind a camera included; a light below the body's top
    takes the exact path."""
    from studio.cost import silhouette_cost
    from studio.light import ShadowFrame, ShadowObjective, predicted_shadows

    masks = _masks(bodies[:2], [PointLight([1.4, -1.1, 3.3])])
    rng = np.random.default_rng(1)
    groups = [[[PointLight(np.array([1.4, -1.1, 3.3]) + rng.normal(0, 0.4, 3))] for _ in range(6)],
              [[DirectionalLight(np.array([-0.5, 0.6, -1.0]) + rng.normal(0, 0.2, 3))] for _ in range(4)],
              [[PointLight([1.4, -1.1, 3.3]), PointLight(np.array([-1.5, 1.0, 3.0]) + rng.normal(0, 0.3, 3))]
               for _ in range(3)],
              [[PointLight([0.2, 0.1, 1.2])]],  # inside the body's height: no outline, the exact renderer
              [[PointLight([3.0, 0.2, 2.0])]]]  # low: the shadow reaches behind a camera (clipped)
    for level in (0, 1):
        frames = [ShadowFrame.build(i, V, F, CAMS, m, level=level) for i, ((V, F), m) in enumerate(zip(bodies, masks))]
        obj = ShadowObjective(frames, CAMS)
        for hyps in groups:
            slow = [[silhouette_cost(f.target, predicted_shadows(f, obj.cameras, h, None, obj.matrices)).per_view
                     for f in frames] for h in hyps]
            np.testing.assert_allclose(obj.terms(hyps), slow, rtol=1e-6, atol=1e-6)
        assert obj.n_evaluations == 15
    with pytest.raises(TypeError, match=r"light: expected PointLight or DirectionalLight, got object"):
        obj.terms([[object()]])


def test_recovers_a_known_point_light(bodies):
    """True bodies and exact shadows in three 160×120 views: the light within 3 cm and 0.5°, the
    truth inside the 95 % credible intervals, the emcee run summarised."""
    light = PointLight([1.4, -1.1, 3.3])
    est = estimate_light(bodies, CAMS, _masks(bodies, [light]), kind="point", level=0, n_steps=20, stop_m=0.02)
    frame = Frame(est.centre)
    err = np.linalg.norm(est.lights[0].position - light.position)
    ang = _angle(direction_of(est.lights[0], frame), direction_of(light, frame))
    assert err < 0.04 and ang < 0.5, (err, ang)
    out = est.to_json()
    assert out["kind"] == "point" and out["n_lights"] == 1
    assert ang <= out["direction_ci_deg"]
    rel = (np.linalg.norm(light.position - est.centre) / out["distance_m"] - 1) * 100
    assert out["distance_ci"][0] <= rel <= out["distance_ci"][1]
    s = out["samples_summary"]
    assert s["n_samples"] == s["n_walkers"] * (20 - s["burn_in"]) and 0 < s["effective_sample_size"] <= s["n_samples"]
    assert 0.05 < s["acceptance"] < 0.95
    assert est.cost < 0.1 * est.empty_cost


def test_recovers_a_directional_light(bodies):
    light = DirectionalLight([-0.5, 0.6, -1.0])
    est = estimate_light(bodies, CAMS, _masks(bodies, [light]), kind="directional", level=0, n_steps=20, stop_m=0.02)
    frame = Frame(est.centre)
    ang = _angle(direction_of(est.lights[0], frame), direction_of(light, frame))
    assert ang < 0.5, ang
    out = est.to_json()
    assert "position" not in out and len(out["direction"]) == 3 and ang <= out["direction_ci_deg"]


def test_refine_floor_recovers_a_tilted_lowered_floor(bodies):
    """Shadows cast on a floor 3 cm below the calibration's and tilted 1.6°: the refined plane is
    within 0.15° of its normal and 5 mm of its height at the subject, and explains the shadows
    (cost) far better than the calibration's plane."""
    from calibration import GroundPlane
    from studio.light.floor import describe_floor
    from studio.render import shadow_silhouettes, silhouette

    light = PointLight([1.4, -1.1, 3.3])
    tilt = np.radians(1.5)
    true = GroundPlane.from_point_normal(np.array([0.0, 0.0, -0.03]), [np.sin(tilt), 0.3 * np.sin(tilt), 1.0])
    masks = [[s & ~silhouette(c, V, F) for s, c in zip(shadow_silhouettes(CAMS, V, F, [light], true), CAMS,
                                                       strict=True)] for V, F in bodies]
    est = estimate_light(bodies, CAMS, masks, kind="point", level=0, n_steps=10, stop_m=0.02, refine_floor=True)
    truth = describe_floor(true, GroundPlane.floor(), est.centre)
    out = est.to_json()["floor"]
    assert _angle(np.asarray(out["normal"]), np.asarray(truth["normal"])) < 0.15, (out, truth)
    assert abs(out["height_at_centre_m"] - truth["height_at_centre_m"]) < 0.005, (out, truth)
    assert out["calibration"] == {"normal": [0.0, 0.0, 1.0], "offset": 0.0} and est.settings["refine_floor"]
    # the floor's height trades against the light's distance: the direction holds, the distance within 3 %
    frame = Frame(est.centre)
    assert _angle(direction_of(est.lights[0], frame), direction_of(light, frame)) < 0.5
    r_est, r_true = (np.linalg.norm(p - est.centre) for p in (est.lights[0].position, light.position))
    assert abs(r_est / r_true - 1) < 0.03
    assert est.cost < 0.2 * est.candidates["point"]["cost"]  # the calibration's floor explains them worse


def test_no_visible_shadow_is_refused(bodies):
    with pytest.raises(LightError, match=r"no visible shadow: 0 of 3 frame\(s\)"):
        estimate_light(bodies, CAMS, _masks(bodies, []))
    with pytest.raises(LightError, match=r"kind: expected 'point', 'directional' or 'auto'"):
        estimate_light(bodies, CAMS, _masks(bodies, []), kind="spot")
    with pytest.raises(LightError, match=r"need one body and one set of shadow masks per frame"):
        estimate_light(bodies[:2], CAMS, _masks(bodies, []))


def test_shadows_of_another_scene_are_not_explained(bodies):
    """Shadows that no light could cast with these bodies (each view's shadow mirrored upside
    down) are refused rather than answered with a confident light."""
    masks = [[m[::-1] for m in frame] for frame in _masks(bodies, [PointLight([1.4, -1.1, 3.3])])]
    with pytest.raises(LightError, match=r"not explained by a point light"):
        estimate_light(bodies, CAMS, masks, kind="point", level=1, n_steps=10, stop_m=0.05)


def test_cli_light_writes_light_json_and_refuses_no_shadow(tmp_path, capsys):
    light = PointLight([1.2, 1.3, 3.4])
    lightkit.make_session(tmp_path / "lit", [light], n_frames=3)
    assert main(["light", str(tmp_path / "lit"), "--bodies", "truth", "--kind", "point", "--workers", "1",
                 "--steps", "12"]) == 0
    out = json.loads((tmp_path / "lit" / "light" / "light.json").read_text())
    assert out["format"] == "studio.light" and out["frames"] == [0, 1, 2]
    assert np.linalg.norm(np.asarray(out["position"]) - light.position) < 0.05
    assert {"direction_ci_deg", "distance_ci", "samples_summary", "timings", "direction"} <= set(out)
    lights, _ = load_light(tmp_path / "lit" / "light" / "light.json")
    assert isinstance(lights[0], PointLight)
    assert len(out["samples"]) == out["samples_summary"]["n_samples"] and len(out["samples"][0]) == 3
    from studio.light.figures import posterior_figure, top_view_figure
    from studio.report.html import _light_html

    corner = posterior_figure(out)
    assert len(corner.axes) == 9 and corner.axes[0].patches  # 3 × 3, histograms on the diagonal
    top = top_view_figure(out, {"cam0": [3.0, 1.0, 2.4]})
    assert len(top.axes[0].lines) >= 4  # camera, subject, samples, light
    import matplotlib.pyplot as plt

    plt.close(corner)
    plt.close(top)
    html = _light_html(out, None)
    assert html.count("data:image/png;base64") == 2 and "light 1: point" in html
    assert "light 1: point" in capsys.readouterr().out
    lightkit.make_session(tmp_path / "dark", [], n_frames=3)
    assert main(["light", str(tmp_path / "dark"), "--bodies", "truth", "--workers", "1"]) == 1
    assert "no visible shadow" in capsys.readouterr().err
    assert not (tmp_path / "dark" / "light" / "light.json").exists()
    with pytest.raises(LightError, match=r"no light estimated"):
        load_light(tmp_path / "dark" / "light" / "light.json")


def test_bad_inputs_are_named(tmp_path, bodies):
    from studio.light import ShadowObjective
    from studio.light.session import estimate_session_light, session_bodies, session_shadows
    from studio.workspace import Workspace

    with pytest.raises(ValueError, match=r"frames: at least one frame is needed"):
        ShadowObjective([], CAMS)
    with pytest.raises(LightError, match=r"lights: expected 1 or 2, got 3"):
        estimate_light(bodies, CAMS, _masks(bodies, []), n_lights=3)
    lightkit.make_session(tmp_path / "s", [PointLight([1.2, 1.3, 3.4])], n_frames=2)
    ws = Workspace.open(tmp_path / "s")
    with pytest.raises(LightError, match=r"bodies: expected one of \('fit', 'truth'\), got 'x'"):
        session_bodies(ws, [0], "x")
    with pytest.raises(LightError, match=r"shadows: expected 'segmentation' or 'truth', got 'x'"):
        session_shadows(ws, [0], "x")
    with pytest.raises(LightError, match=r"no true labels — --shadows truth needs a simulated session"):
        session_shadows(ws, [0], "truth")
    with pytest.raises(LightError, match=r"no fit/ folder — run `studio fit"):
        estimate_session_light(ws)
    with pytest.raises(LightError, match=r"no fitted frames — run `studio fit"):
        (tmp_path / "s" / "fit").mkdir()
        session_bodies(ws, [0], "fit")
    (tmp_path / "s" / "truth" / "faces.npy").unlink()
    with pytest.raises(LightError, match=r"no true bodies — --bodies truth needs a simulated session"):
        session_bodies(ws, [0], "truth")
    bad = tmp_path / "light.json"
    bad.write_text("{")
    with pytest.raises(LightError, match=r"not JSON"):
        load_light(bad)
    bad.write_text(json.dumps({"format": "other"}))
    with pytest.raises(LightError, match=r"not a studio.light version 1 file"):
        load_light(bad)
    bad.write_text(json.dumps({"format": "studio.light", "version": 1, "lights": [{"kind": "spot"}]}))
    with pytest.raises(LightError, match=r"lights\[0\].kind': expected 'point' or 'directional', got 'spot'"):
        load_light(bad)
    bad.write_text(json.dumps({"format": "studio.light", "version": 1, "lights": []}))
    with pytest.raises(LightError, match=r"field 'lights': expected at least one light"):
        load_light(bad)
    bad.write_text(json.dumps({"format": "studio.light", "version": 1,
                               "lights": [{"kind": "directional", "direction": [0.0, 0.6, 0.8]}]}))
    lights, _ = load_light(bad)
    np.testing.assert_allclose(lights[0].direction, [0.0, -0.6, -0.8])
