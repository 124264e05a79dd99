"""The measurement table and the report's figures on hand-made inputs with known answers: a
stand-in ``measure`` (values linear in a one-number shape) so that every mean, spread, σ, 95 %
interval, ISO 20685-1 verdict, truth error and CSV cell is worked out by hand here; the figures'
artists (what is drawn where, in which colour) read back from matplotlib. No body model, no fit:
each test runs in milliseconds (the session-level report tests cover the real pipeline).
"""

from __future__ import annotations

import csv
import json
from types import SimpleNamespace

import numpy as np
import pytest

import studio.body
from studio.body.iso7250 import DEFINITIONS, ISO20685_MAE
from studio.report.figures import STATUS_COLOURS, frames_figure, uncertainty_figure
from studio.report.measurements import (LOOSE_FLAGS, REPORTED, UNITS, frames_used, load_truth, measurement_table,
                                        use_batch_shape, write_measurements, write_measurements_csv)
from studio.report.population import percentile_table, population_context
from studio.workspace import Layout

POP = percentile_table()["sexes"]["female"]
#: SI values of the stand-in body at shape 0: the ANSUR II female mean (z = 0) where there is one
BASE = {d.name: POP[d.name]["mean"] if d.name in POP else {"m": 0.5, "kg": 60.0, "kg/m²": 22.0}[d.unit]
        for d in DEFINITIONS}
#: change per unit of shape: 1 mm for lengths, 0.5 kg, 0.25 kg/m²
STEP = {d.name: {"m": 0.001, "kg": 0.5, "kg/m²": 0.25}[d.unit] for d in DEFINITIONS}
MODEL = SimpleNamespace(gender="female")


@pytest.fixture(autouse=True)
def linear_body(monkeypatch):
    """``studio.body.measure`` replaced by BASE + STEP × shape[0] (the table imports it when called); it
    needs the model as the real one does."""
    def measure(model, shape):
        assert model.gender in ("female", "male")
        return {n: BASE[n] + STEP[n] * shape[0] for n in BASE}

    monkeypatch.setattr(studio.body, "measure", measure)


def fit(shape: float, status: str = "ok"):
    return SimpleNamespace(shape=[shape], status=status)


def si(name: str, shape: float) -> float:
    return BASE[name] + STEP[name] * shape


# --------------------------------------------------------------------------- measurement_table
def test_table_row_by_hand():
    """Frames 0 and 1 (ok, unchecked) are used, frame 2 (suspect) left out. Stature: 2 mm apart, so
    std = √2, σ_frames = √2/√2 = 1 mm; calibration 2 mm and posterior 2 mm: σ = √(1 + 4 + 4) = 3 mm,
    half-width 5.88 mm > 4 mm (ISO 20685-1, heights); chest (9 mm allowed) meets it."""
    fits = {0: fit(0.0), 1: fit(2.0, "unchecked"), 2: fit(10.0, "suspect")}
    unc = {"calibration": {"stature": 0.002, "chest_circumference": 0.002},
           "posterior": {"stature": 0.002, "chest_circumference": 0.002}}
    table = measurement_table(MODEL, fits, uncertainty=unc)
    assert list(table) == list(REPORTED) and len(table) == 20
    row = table["stature"]
    mean = 1000 * si("stature", 1.0)
    assert row["unit"] == "mm" and row["title"] == "Stature" and row["clause"] == "ISO 7250-1 4.1.2"
    assert row["kind"] == "height" and row["definition"].startswith("vertical distance from the floor")
    assert row["per_frame"] == pytest.approx({"0": 1000 * BASE["stature"], "1": 1000 * si("stature", 2.0),
                                              "2": 1000 * si("stature", 10.0)}, rel=1e-12)
    assert row["per_frame_status"] == {"0": "ok", "1": "ok", "2": "suspect"}
    assert row["frames_used"] == [0, 1] and row["status"] == "ok"
    assert row["flags"] == ["1 flagged frame(s) left out of the mean"]
    assert row["mean"] == pytest.approx(mean, rel=1e-12)
    assert row["std"] == pytest.approx(np.sqrt(2.0), rel=1e-9)
    assert row["sigma_frames"] == pytest.approx(1.0, rel=1e-9)
    assert row["sigma_calibration"] == pytest.approx(2.0, rel=1e-12)
    assert row["sigma_posterior"] == pytest.approx(2.0, rel=1e-12)
    assert row["sigma"] == pytest.approx(3.0, rel=1e-9)
    assert row["ci95"] == pytest.approx([mean - 5.88, mean + 5.88], rel=1e-12)
    assert row["iso20685_max_error"] == pytest.approx(4.0, rel=1e-12) and row["iso20685_ok"] is False
    assert table["chest_circumference"]["iso20685_max_error"] == pytest.approx(9.0)
    assert table["chest_circumference"]["iso20685_ok"] is True
    assert row["population"] == population_context("stature", mean / 1000, "female")
    assert row["population"]["sex"] == "female" and row["population_z"] == row["population"]["z"]
    for key in ("truth", "error", "truth_source", "truth_anny", "error_anny"):
        assert row[key] is None
    assert "truth_in_ci95" not in row
    # the model's own error joins the root sum of squares: √(1 + 4 + 4 + 2.4²) = 3.84
    with_model = measurement_table(MODEL, fits, uncertainty={**unc, "model": {"stature": 0.0024}})["stature"]
    assert with_model["sigma_model"] == pytest.approx(2.4, rel=1e-12)
    assert with_model["sigma"] == pytest.approx(np.sqrt(9 + 2.4**2), rel=1e-9) and row["sigma_model"] is None
    # no uncertainty given: σ is the spread over frames alone; mass in kg (no ISO 20685-1 allowance)
    other = table["shoulder_height"]
    assert other["sigma_calibration"] is None and other["sigma_posterior"] is None
    assert other["sigma"] == pytest.approx(1.0, rel=1e-9)
    mass = table["mass"]
    assert mass["unit"] == "kg" and mass["mean"] == pytest.approx(si("mass", 1.0), rel=1e-12)
    assert mass["std"] == pytest.approx(np.sqrt(2.0) * 0.5, rel=1e-9)
    assert mass["iso20685_max_error"] is None and mass["iso20685_ok"] is None
    assert table["bmi"]["unit"] == "kg/m²" and table["eye_height"]["population"] is None
    assert table["eye_height"]["population_z"] is None


def test_one_frame_has_no_spread_and_the_iso_allowance_is_inclusive():
    """"meets" ISO 20685-1: a half-width 1.96 σ of exactly 4 mm meets the 4 mm allowance; the next
    float above does not. One frame: std 0, σ = the posterior σ alone."""
    x = 4.0 / 1.96  # a posterior σ (mm) whose 1.96 σ is 4.0 exactly, and the next float up whose is not
    while 1.96 * x != 4.0:
        x = np.nextafter(x, np.inf if 1.96 * x < 4.0 else -np.inf)
    above = np.nextafter(x, np.inf)
    while 1.96 * above == 4.0:
        above = np.nextafter(above, np.inf)
    s = x / 1000.0  # back to metres: find the SI value that scales to x exactly
    while s * 1000.0 != x:
        s = np.nextafter(s, np.inf if s * 1000.0 < x else -np.inf)
    t = above / 1000.0
    while t * 1000.0 < above:
        t = np.nextafter(t, np.inf)
    assert 1.96 * (s * 1000.0) == 4.0 and 1.96 * (t * 1000.0) > 4.0
    for sigma, ok in ((s, True), (t, False)):
        row = measurement_table(MODEL, {3: fit(1.0)}, uncertainty={"posterior": {"stature": sigma}})["stature"]
        assert row["std"] == 0.0 and row["sigma_frames"] == 0.0 and row["frames_used"] == [3]
        assert row["iso20685_max_error"] == 1000 * ISO20685_MAE["height"] == 4.0
        assert row["iso20685_ok"] is ok and row["flags"] == []


def test_frames_used_falls_back_level_by_level():
    assert frames_used({2: fit(0), 1: fit(0, "suspect"), 0: fit(0, "unchecked")}) == ([0, 2], "ok")
    assert frames_used({2: fit(0, "failed"), 1: fit(0, "suspect"), 0: fit(0, "suspect")}) == ([0, 1], "suspect")
    assert frames_used({4: fit(0, "failed"), 3: fit(0, "failed")}) == ([3, 4], "failed")
    assert frames_used({7: SimpleNamespace(shape=[0.0])}) == ([7], "ok")  # no status attribute: ok
    row = measurement_table(MODEL, {7: SimpleNamespace(shape=[0.0]), 8: fit(2.0, "suspect")})["stature"]
    assert row["per_frame_status"] == {"7": "ok", "8": "suspect"} and row["frames_used"] == [7]
    with pytest.raises(ValueError, match="^no fitted frames to measure$"):
        frames_used({})


def test_no_clean_frame_marks_every_row():
    table = measurement_table(MODEL, {0: fit(0.0, "failed"), 1: fit(1.0, "suspect"), 2: fit(3.0, "suspect")})
    for row in table.values():
        assert row["status"] == "suspect" and row["frames_used"] == [1, 2]
        assert row["flags"] == ["no clean frame: mean over 2 suspect frame(s)"]
    assert table["stature"]["mean"] == pytest.approx(1000 * si("stature", 2.0), rel=1e-12)
    failed = measurement_table(MODEL, {0: fit(0.0, "failed")})
    assert failed["mass"]["status"] == "failed" and failed["mass"]["flags"] == ["no clean frame: mean over 1 failed frame(s)"]


@pytest.mark.parametrize("z, status", [(3.5, "ok"), (3.51, "suspect"), (-5.0, "suspect"), (5.01, "failed"),
                                       (-5.01, "failed")])
def test_population_z_thresholds_are_exclusive(z, status, monkeypatch):
    """|z| more than 3.5 is suspect, more than 5 failed (studio.fit.quality.POPULATION_Z); exactly 3.5 is not."""
    value = POP["stature"]["mean"] + z * POP["stature"]["std"]
    monkeypatch.setattr(studio.body, "measure", lambda model, shape: {**BASE, "stature": value})
    row = measurement_table(MODEL, {0: fit(0.0)})["stature"]
    assert row["population_z"] == z and row["status"] == status
    if status == "ok":
        assert row["flags"] == []
    else:
        assert row["flags"] == [f"{status}: {z:+.1f} σ from ANSUR II (female): implausible"]
    # a flagged frame does not lower a failed value: the worst wins
    worst = measurement_table(MODEL, {0: fit(0.0, "suspect")})["stature"]["status"]
    assert worst == ("failed" if status == "failed" else "suspect")


def test_population_sex_defaults_to_the_model_and_can_be_given():
    table = measurement_table(SimpleNamespace(gender="male"), {0: fit(0.0)})
    assert table["stature"]["population"]["sex"] == "male" and table["stature"]["population_z"] < 0
    table = measurement_table(SimpleNamespace(gender="male"), {0: fit(0.0)}, sex="female")
    assert table["stature"]["population"]["sex"] == "female"


def test_truth_same_definition_first_then_anny():
    fits = {0: fit(0.0), 1: fit(2.0)}
    plain = measurement_table(MODEL, fits)
    studio_truth = {n: BASE[n] + STEP[n] * 3.0 for n in REPORTED}
    studio_truth["mass"] = plain["mass"]["ci95"][1]  # exactly on the interval's upper end: inside (inclusive)
    truth = {"studio": studio_truth, "stature": 1.6, "mass": 50.0}
    table = measurement_table(MODEL, fits, truth)
    st = table["stature"]
    assert st["truth_source"] == "studio" and st["truth"] == pytest.approx(1000 * si("stature", 3.0), rel=1e-12)
    assert st["error"] == pytest.approx(-2.0, rel=1e-9) and st["truth_in_ci95"] is False
    assert st["truth_anny"] == pytest.approx(1600.0) and st["error_anny"] == pytest.approx(st["mean"] - 1600.0)
    m = table["mass"]
    assert m["truth"] == plain["mass"]["ci95"][1] and m["truth_in_ci95"] is True
    assert m["truth_anny"] == 50.0 and m["error_anny"] == pytest.approx(si("mass", 1.0) - 50.0)
    assert table["eye_height"]["truth_anny"] is None and table["eye_height"]["truth_source"] == "studio"
    below = dict(truth, studio={**studio_truth, "mass": np.nextafter(plain["mass"]["ci95"][0], -np.inf)})
    assert measurement_table(MODEL, fits, below)["mass"]["truth_in_ci95"] is False
    at_low = dict(truth, studio={**studio_truth, "mass": plain["mass"]["ci95"][0]})
    assert measurement_table(MODEL, fits, at_low)["mass"]["truth_in_ci95"] is True


def test_truth_written_before_the_iso_definitions():
    """Only the names whose definition did not change count; 'inseam' is the crotch height; the rest
    fall back to Anny's own values."""
    truth = {"studio": {"stature": 1.7, "inseam": 0.8, "eye_height": 1.6, "mass": 61.0}, "eye_height": 1.55,
             "knee_height": 0.45}
    table = measurement_table(MODEL, {0: fit(0.0)}, truth)
    assert (table["stature"]["truth"], table["stature"]["truth_source"]) == (pytest.approx(1700.0), "studio")
    assert (table["crotch_height"]["truth"], table["crotch_height"]["truth_source"]) == (pytest.approx(800.0), "studio")
    assert (table["mass"]["truth"], table["mass"]["truth_source"]) == (61.0, "studio")
    assert (table["eye_height"]["truth"], table["eye_height"]["truth_source"]) == (pytest.approx(1550.0), "anny")
    assert (table["knee_height"]["truth"], table["knee_height"]["truth_source"]) == (pytest.approx(450.0), "anny")
    assert table["arm_span"]["truth"] is None and table["arm_span"]["error"] is None
    assert table["knee_height"]["error"] == pytest.approx(1000 * BASE["knee_height"] - 450.0)
    with pytest.raises(ValueError, match=r"^truth measurements: 'studio' must be a mapping name → value, got list$"):
        measurement_table(MODEL, {0: fit(0.0)}, {"studio": [1.7]})


# --------------------------------------------------------------------------- use_batch_shape
def test_batch_shape_moves_mean_and_interval_only():
    fits = {0: fit(0.0), 1: fit(2.0)}
    truth = {"studio": {n: si(n, 3.0) for n in REPORTED}, "stature": 1.6}
    table = measurement_table(MODEL, fits, truth)
    no_truth = measurement_table(MODEL, fits)
    out = use_batch_shape(table, MODEL, [4.0], truth, frames=[1, 0])
    st, old = out["stature"], table["stature"]
    assert st["mean"] == pytest.approx(1000 * si("stature", 4.0), rel=1e-12) and old["mean"] != st["mean"]
    assert st["ci95"] == pytest.approx([c + 3.0 for c in old["ci95"]], rel=1e-12)
    assert st["shape_source"] == "batch" and st["batch_frames"] == [1, 0] and "shape_source" not in old
    assert st["per_frame"] == old["per_frame"] and st["std"] == old["std"] and st["sigma"] == old["sigma"]
    # σ = 1 mm: the truth 1 mm off is inside the moved interval (±1.96 mm), 2 mm off was outside the old one
    assert st["error"] == pytest.approx(1.0, rel=1e-9) and st["error_anny"] == pytest.approx(st["mean"] - 1600.0)
    assert st["truth_in_ci95"] is True and old["truth_in_ci95"] is False
    assert st["population"] == population_context("stature", si("stature", 4.0), "female") != old["population"]
    assert st["population_z"] == st["population"]["z"]
    assert out["eye_height"]["population"] is None and out["eye_height"]["population_z"] is None
    # a table without truth takes the same-definition truth (and its error) from ``truth``
    filled = use_batch_shape(no_truth, MODEL, [5.0], truth)
    assert filled["stature"]["truth"] == pytest.approx(1000 * si("stature", 3.0), rel=1e-12)
    assert filled["stature"]["error"] == pytest.approx(2.0, rel=1e-9) and filled["stature"]["batch_frames"] == []
    assert filled["stature"]["error_anny"] is None and "truth_in_ci95" not in filled["stature"]
    # the moved interval includes its ends: a truth exactly on either end is inside, a float beyond is not
    moved = use_batch_shape(table, MODEL, [4.0], truth)["mass"]["ci95"]
    for truth_value, inside in ((moved[0], True), (moved[1], True), (np.nextafter(moved[0], -np.inf), False),
                                (np.nextafter(moved[1], np.inf), False)):
        edged = {**table, "mass": {**table["mass"], "truth": truth_value}}
        assert use_batch_shape(edged, MODEL, [4.0], truth)["mass"]["truth_in_ci95"] is inside
    bare = use_batch_shape(no_truth, MODEL, [5.0])
    assert bare["stature"]["truth"] is None and bare["stature"]["error"] is None
    assert use_batch_shape(no_truth, SimpleNamespace(gender="male"), [0.0])["stature"]["population"]["sex"] == "male"
    assert use_batch_shape(no_truth, MODEL, [0.0], sex="male")["stature"]["population"]["sex"] == "male"


def test_loose_batch_figures_are_flagged():
    """Under loose clothes the batch body is bounded only from outside at the torso and limbs: its
    girths, depths, hip breadth, mass and BMI are never printed as clean figures (upper bounds), nor
    its heights and lengths (the knees, crotch and elbows are hidden: estimates); the shoulder
    breadth keeps its status; a tight batch changes nothing; a failed row stays failed."""
    table = measurement_table(MODEL, {0: fit(0.0), 1: fit(2.0)})
    assert {r["status"] for r in table.values()} == {"ok"}
    loose = use_batch_shape(table, MODEL, [4.0], clothing="loose")
    bounded = {n for n, r in loose.items() if r["flags"] == [LOOSE_FLAGS["bounded"]]}
    assert bounded == {"neck_circumference", "chest_circumference", "waist_circumference", "hip_circumference",
                       "thigh_circumference", "upper_arm_circumference", "chest_depth", "hip_breadth", "mass", "bmi"}
    joints = {n for n, r in loose.items() if r["flags"] == [LOOSE_FLAGS["joints"]]}
    assert joints == {"stature", "eye_height", "shoulder_height", "elbow_height", "crotch_height", "knee_height",
                      "shoulder_elbow_length", "elbow_wrist_length", "arm_span"}
    assert {n for n, r in loose.items() if r["status"] == "suspect"} == bounded | joints
    assert loose["chest_circumference"]["flags"] == ["suspect: loose clothing hides the body here — an upper bound"]
    assert loose["biacromial_breadth"]["status"] == "ok" and loose["biacromial_breadth"]["flags"] == []
    tight = use_batch_shape(table, MODEL, [4.0], clothing="tight")
    assert {r["status"] for r in tight.values()} == {"ok"} and all(r["flags"] == [] for r in tight.values())
    failed = {**table, "mass": {**table["mass"], "status": "failed", "flags": ["failed: +5.0 σ"]}}
    assert use_batch_shape(failed, MODEL, [4.0], clothing="loose")["mass"]["status"] == "failed"


def test_uncertain_gender_flags_every_batch_figure():
    """A batch whose gender is within its frames' noise: every figure is of that gender's body, so
    every row carries the warning after its own flags and is at least suspect; failed stays failed."""
    table = measurement_table(MODEL, {0: fit(0.0), 1: fit(2.0)})
    failed = {**table, "mass": {**table["mass"], "status": "failed", "flags": ["failed: +5.0 σ"]}}
    out = use_batch_shape(failed, MODEL, [4.0], clothing="loose", warning="gender uncertain: x")
    assert all(r["flags"][-1] == "gender uncertain: x" for r in out.values())
    assert {n for n, r in out.items() if r["status"] == "suspect"} == set(out) - {"mass"}
    assert out["mass"]["status"] == "failed" and out["mass"]["flags"] == ["failed: +5.0 σ", LOOSE_FLAGS["bounded"],
                                                                          "gender uncertain: x"]
    assert out["biacromial_breadth"]["flags"] == ["gender uncertain: x"]
    assert all(r["flags"] == [] for r in use_batch_shape(table, MODEL, [4.0], warning=None).values())


# --------------------------------------------------------------------------- files
HEADER = ["name", "unit", "mean", "std", "status", "flags", "truth", "error", "truth_anny", "error_anny", "clause",
          "sigma", "ci95_low", "ci95_high", "iso20685_max_error", "iso20685_ok", "percentile", "z"]


def test_csv_cells(tmp_path):
    table = {
        "a": {"unit": "mm", "mean": 1651.004, "std": 1.41421, "status": "suspect", "flags": ["x", "y"],
              "truth": 1650.0, "error": 1.004, "truth_anny": 1649.5, "error_anny": 1.504, "clause": "c 1",
              "sigma": 3.0, "ci95": [1645.124, 1656.884], "iso20685_max_error": 4.0, "iso20685_ok": False,
              "population": {"percentile": 51.23, "z": 0.04}, "per_frame": {"10": 1.0, "2": 2.345}},
        "b": {"unit": "kg", "mean": 60.0, "std": 0.0, "truth": None, "error": None, "per_frame": {"2": 60.0},
              "iso20685_ok": True},
        "c": {"unit": "kg/m²", "mean": 22.0, "std": 0.5, "truth": None, "error": None, "per_frame": {},
              "iso20685_ok": None, "clause": "mass / stature²"},
    }
    path = write_measurements_csv(tmp_path / "deep" / "m.csv", table)
    assert path == tmp_path / "deep" / "m.csv"
    rows = list(csv.reader(path.read_text().splitlines()))
    assert rows[0] == HEADER + ["frame_2", "frame_10"]
    assert rows[1] == ["a", "mm", "1651.00", "1.41", "suspect", "x; y", "1650.00", "1.00", "1649.50", "1.50", "c 1",
                       "3.00",
                       "1645.12", "1656.88", "4.00", "no", "51.23", "0.04", "2.35", "1.00"]
    assert rows[2] == ["b", "kg", "60.00", "0.00", "ok", "", "", "", "", "", "", "", "", "", "", "yes", "", "",
                       "60.00", ""]
    assert rows[3] == ["c", "kg/m²", "22.00", "0.50", "ok", "", "", "", "", "", "mass / stature²", "", "", "", "", "",
                       "", "", "", ""]


def test_measurements_json_and_truth_files(tmp_path):
    table = measurement_table(MODEL, {0: fit(0.0)})
    jp, cp = write_measurements(tmp_path / "s", table, {"id": "p1"})
    lay = Layout(tmp_path / "s")
    assert (jp, cp) == (lay.report_measurements_json, lay.report_measurements_csv)
    data = json.loads(jp.read_text())
    assert data["format"] == "studio.measurements" and data["version"] == 2 and data["participant"] == {"id": "p1"}
    assert data["measurements"]["stature"]["mean"] == pytest.approx(table["stature"]["mean"])
    assert len(cp.read_text().splitlines()) == 21
    assert json.loads(write_measurements(lay, table)[0].read_text())["participant"] == {}
    assert load_truth(tmp_path / "s") is None
    lay.truth_measurements.parent.mkdir(parents=True)
    lay.truth_measurements.write_text(json.dumps({"stature": 1.7}))
    assert load_truth(lay) == {"stature": 1.7} == load_truth(tmp_path / "s")


# --------------------------------------------------------------------------- figures
def _uncertainty_table():
    return {
        "stature": {"unit": "mm", "title": "Stature", "iso20685_max_error": 4.0, "sigma": 2.0, "mean": 1650.0,
                    "per_frame": {"0": 1651.0, "1": 1648.5}, "truth": 1653.0},
        "mass": {"unit": "kg", "mean": 60.0, "per_frame": {"0": 60.0}},  # not a length: left out
        "arm_span": {"unit": "mm", "mean": 1700.0, "per_frame": {"0": 1700.0}, "iso20685_max_error": None,
                     "truth": None},
    }


def _line(line):
    return line.get_xdata().tolist(), line.get_ydata().tolist()


def test_uncertainty_figure_draws_each_length_row():
    """Rows top-down in table order (stature at y = 1, arm span at y = 0): the ISO allowance as a
    green band ±4 mm, the 95 % interval ±1.96σ in blue, per-frame ticks 0.18 above, the truth as ×."""
    import matplotlib.pyplot as plt
    from matplotlib.colors import to_hex

    fig = uncertainty_figure(_uncertainty_table())
    try:
        assert tuple(fig.get_size_inches()) == pytest.approx((7.5, 0.32 * 2 + 1.2))
        (ax,) = fig.axes
        (band,) = ax.collections
        xy = band.get_paths()[0].vertices
        assert (xy[:, 0].min(), xy[:, 0].max(), xy[:, 1].min(), xy[:, 1].max()) == pytest.approx((-4.0, 4.0, 0.65, 1.35))
        assert to_hex(band.get_facecolor()[0]) == "#d9ead3" and band.get_linewidth()[0] == 0
        lines = ax.get_lines()
        interval, ticks, cross, interval2, ticks2, zero = lines
        assert _line(interval) == ([-3.92, 3.92], [1.0, 1.0])
        assert to_hex(interval.get_color()) == "#1f4e9c" and interval.get_linewidth() == 3
        assert interval.get_solid_capstyle() == "butt"
        assert _line(ticks) == ([1.0, -1.5], [1.18, 1.18])
        assert ticks.get_marker() == "|" and to_hex(ticks.get_color()) == "#555555" and ticks.get_markersize() == 6
        assert ticks.get_linestyle() == "None"
        assert _line(cross) == ([3.0], [1.0]) and cross.get_marker() == "x"
        assert to_hex(cross.get_color()) == "#c0000f" and cross.get_markersize() == 8 and cross.get_markeredgewidth() == 2
        assert _line(interval2) == ([-0.0, 0.0], [0.0, 0.0]) and _line(ticks2) == ([0.0], [0.18])
        assert list(zero.get_xdata()) == [0, 0] and to_hex(zero.get_color()) == "#000000"
        assert zero.get_linewidth() == 0.6
        assert ax.get_yticks().tolist() == [0, 1]
        assert [t.get_text() for t in ax.get_yticklabels()] == ["arm_span", "Stature"]
        assert all(t.get_fontsize() == 8 for t in ax.get_yticklabels())
        assert ax.get_xlabel() == "difference from the reported value (mm)"
        assert ax.get_title() == "blue: 95 % interval · green: ISO 20685-1 allowance · ticks: single frames · ×: truth"
        assert ax.title.get_fontsize() == 8
        assert ax.xaxis.get_gridlines()[0].get_visible() and not ax.yaxis.get_gridlines()[0].get_visible()
        assert ax.xaxis.get_gridlines()[0].get_alpha() == 0.3
    finally:
        plt.close(fig)


def _fits_and_qualities():
    fits = {
        3: SimpleNamespace(costs={"total": 5.0, "silhouette": 2.5}, status="ok"),
        1: SimpleNamespace(costs={"total": 4.0}, status="suspect"),
        2: SimpleNamespace(costs={"total": 6.0, "silhouette": 1.5}, status="failed"),
        4: SimpleNamespace(costs={"total": 1.0, "silhouette": 0.5}, status="unchecked"),
        5: SimpleNamespace(costs={"total": 1.0, "silhouette": 0.75}, status="odd"),
    }
    qualities = {
        3: {"silhouette_precision": 0.9, "silhouette_recall": 0.5},
        1: {"silhouette_precision": 0.95, "silhouette_recall": 0.85},
        2: {"silhouette_precision": "n/a"},  # not a number: not plotted
        4: {},
    }
    return fits, qualities


def test_frames_figure_plots_costs_by_status_and_precision_recall():
    """Frames in order; the silhouette cost (else the total) coloured by status; precision and recall
    of the frames that have them; the y range down to the lowest value shown (at most 0.7)."""
    import matplotlib.pyplot as plt
    from matplotlib.colors import to_hex

    fits, qualities = _fits_and_qualities()
    fig = frames_figure(fits, qualities)
    try:
        assert tuple(fig.get_size_inches()) == (9, 3)
        a1, a2 = fig.axes
        assert a1.get_position().x1 < a2.get_position().x0  # side by side
        assert a1.get_position().y0 == pytest.approx(a2.get_position().y0)
        (line,) = a1.get_lines()
        assert _line(line) == ([1, 2, 3, 4, 5], [4.0, 1.5, 2.5, 0.5, 0.75])
        assert to_hex(line.get_color()) == "#999999" and line.get_linewidth() == 1 and line.get_linestyle() == "-"
        (dots,) = a1.collections
        assert dots.get_offsets().tolist() == [[1, 4.0], [2, 1.5], [3, 2.5], [4, 0.5], [5, 0.75]]
        assert [to_hex(c) for c in dots.get_facecolors()] == [STATUS_COLOURS[s] for s in
                                                              ("suspect", "failed", "ok", "unchecked")] + ["#777777"]
        assert dots.get_zorder() == 3
        assert a1.get_xlabel() == "frame" and a1.get_ylabel() == "silhouette disagreement\n(mean contour distance, pixels)"
        precision, recall = a2.get_lines()
        assert _line(precision) == ([1, 3], [0.95, 0.9]) and precision.get_marker() == "o"
        assert _line(recall) == ([1, 3], [0.85, 0.5]) and recall.get_marker() == "s"
        assert precision.get_linestyle() == recall.get_linestyle() == "-"
        assert [t.get_text() for t in a2.get_legend().get_texts()] == ["precision", "recall"]
        assert a2.get_legend().get_texts()[0].get_fontsize() == 8
        assert a2.get_ylim() == (0.5, 1.0)  # recall 0.5 is the lowest value shown
        assert a2.get_xlabel() == "frame" and a2.get_ylabel() == "share of silhouette pixels"
        for ax in (a1, a2):
            assert ax.xaxis.get_gridlines()[0].get_visible() and ax.yaxis.get_gridlines()[0].get_visible()
            assert ax.xaxis.get_gridlines()[0].get_alpha() == 0.3
            fig.canvas.draw()
            assert all(float(t).is_integer() for t in ax.get_xticks())
    finally:
        plt.close(fig)


def test_frames_figure_y_range_without_quality_and_when_all_is_good():
    import matplotlib.pyplot as plt

    fits, _ = _fits_and_qualities()
    fig = frames_figure(fits, {})
    try:
        assert fig.axes[1].get_lines() == [] and fig.axes[1].get_legend() is None
        assert fig.axes[1].get_ylim() == (0.7, 1.0)
    finally:
        plt.close(fig)
    fig = frames_figure(fits, {1: {"silhouette_precision": 0.99, "silhouette_recall": 0.98}})
    try:
        assert fig.axes[1].get_ylim() == (0.7, 1.0)
    finally:
        plt.close(fig)


def test_frames_figure_y_range_follows_the_lowest_precision_too():
    import matplotlib.pyplot as plt

    fits, _ = _fits_and_qualities()
    fig = frames_figure(fits, {1: {"silhouette_precision": 0.6, "silhouette_recall": 0.8}})
    try:
        assert fig.axes[1].get_ylim() == (0.6, 1.0)
    finally:
        plt.close(fig)


def test_figures_keep_their_styles_under_another_matplotlib_style():
    """The figures set their own line style and marker sizes: a user's matplotlibrc (dashed lines,
    large markers) does not change them."""
    import matplotlib.pyplot as plt

    fits, qualities = _fits_and_qualities()
    with plt.rc_context({"lines.linestyle": "--", "lines.markersize": 11.0}):
        fig = frames_figure(fits, qualities)
        fig2 = uncertainty_figure(_uncertainty_table())
    try:
        assert fig.axes[0].get_lines()[0].get_linestyle() == "-"
        ticks = fig2.axes[0].get_lines()[1]
        assert ticks.get_marker() == "|" and ticks.get_markersize() == 6
    finally:
        plt.close(fig)
        plt.close(fig2)
