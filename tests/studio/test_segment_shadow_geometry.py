"""Cast-shadow geometry (studio.segment.shadow_geometry): the chord test on drawn label images,
the learned object-to-shadow direction, settings, and real CDnet highway frames with shadows."""

import cv2
import numpy as np
import pytest

from studio.segment import (
    PERSON,
    SHADOW,
    AdaptiveSettings,
    BackgroundModel,
    SegmentationError,
    learn_shadow_direction,
    shadow_geometry,
)
from studio.segment.metrics import cdnet_scores


def _car(dark_body: bool = True) -> np.ndarray:
    """A 30-row car (rows 10-39, columns 20-39) casting a 6-row shadow below it (rows 40-45);
    its windscreen (rows 14-21) and, if ``dark_body``, its lower body (rows 30-39) are as dark as
    the shadow, so the colour gate labelled them shadow."""
    lab = np.zeros((60, 60), np.uint8)
    lab[10:40, 20:40] = PERSON
    lab[14:22, 22:38] = SHADOW
    if dark_body:
        lab[30:40, 20:40] = SHADOW
    lab[40:46, 20:40] = SHADOW
    return lab


def test_shadow_strip_kept_dark_body_given_back_to_the_car():
    lab = _car()
    out = shadow_geometry(lab, (0.0, 1.0), fraction=0.2)
    # chord along +y through every column: 36 rows (30 car + 6 shadow); a pixel stays shadow when
    # the steps to the exit are <= 0.2 * (steps to exit + steps to entry - 1) = 0.2 * 36 = 7.2:
    # rows 39-45 (exits 7..1), i.e. the 6 shadow rows and the car's last row
    assert np.array_equal(np.nonzero((out == SHADOW).any(1))[0], np.arange(39, 46))
    assert (out == SHADOW).sum() == 7 * 20
    assert (out[10:39, 20:40] == PERSON).all()  # windscreen and dark body: person again
    assert (out == 0).sum() == (lab == 0).sum()  # background untouched


def test_windscreen_near_the_exit_side_stays_shadow():
    """The test is geometric only: a dark patch that sits in the last fifth of the chord on the
    light-opposite side is shadow, wherever it came from."""
    lab = _car(dark_body=False)
    out = shadow_geometry(lab, (0.0, -1.0), fraction=0.2)
    # walking up from row r, the exit is r - 9 steps away; chord 36: kept when r - 9 <= 7.2, r <= 16
    assert np.array_equal(np.nonzero((out == SHADOW).any(1))[0], np.arange(14, 17))
    assert (out == SHADOW).sum() == 3 * 16
    assert (out[40:46, 20:40] == PERSON).all()  # the real shadow, on the lit side for this light: person
    # a diagonal light works on the rounded walk too
    diag = shadow_geometry(lab, (1.0, 1.0), fraction=0.2)
    assert 0 < (diag == SHADOW).sum() < (lab == SHADOW).sum()


def test_errors():
    lab = _car()
    with pytest.raises(SegmentationError, match=r"labels must be \(H, W\) uint8"):
        shadow_geometry(lab.astype(np.int32), (0, 1))
    with pytest.raises(SegmentationError, match="direction must be a non-zero"):
        shadow_geometry(lab, (0, 0))
    with pytest.raises(SegmentationError, match=r"fraction must be in \(0, 1\]"):
        shadow_geometry(lab, (0, 1), fraction=0.0)
    with pytest.raises(SegmentationError, match="shadow_direction: expected None or a non-zero"):
        AdaptiveSettings(shadow_direction=(0.0, 0.0))
    with pytest.raises(SegmentationError, match="shadow_fraction"):
        AdaptiveSettings(shadow_fraction=1.5)
    with pytest.raises(SegmentationError, match="no region with at least 20 object and shadow pixels"):
        learn_shadow_direction([np.zeros((60, 60), bool)], [np.zeros((60, 60), bool)])
    s = AdaptiveSettings(shadow_direction=(-0.5, 0.8), shadow_fraction=0.25)
    assert AdaptiveSettings.from_dict(s.to_dict()) == s


def test_learn_shadow_direction_across_an_unknown_band():
    """Two cars, shadows offset down-left by (-4, +7) px behind a 1-px unlabelled band (CDnet's
    170 'unknown'); the direction is the count-weighted centroid offset."""
    obj = np.zeros((120, 160), bool)
    sh = np.zeros_like(obj)
    for y0, x0 in ((10, 30), (60, 100)):
        obj[y0:y0 + 30, x0:x0 + 20] = True
        sh[y0 + 31:y0 + 38, x0 - 4:x0 + 16] = True  # row y0 + 30 left unlabelled
    dx, dy = learn_shadow_direction([obj], [sh])
    ex = np.array([-4.0, (31 + 37) / 2 - 14.5])
    np.testing.assert_allclose((dx, dy), ex / np.hypot(*ex), atol=1e-9)
    with pytest.raises(SegmentationError):
        learn_shadow_direction([obj], [sh], join_radius=0)  # the band splits every region


def test_cdnet_highway_tuning_frames_shadow_out_cars_kept(shared_data):
    """Real frames of the CDnet tuning split with shadows (GT 660-690, every 10th), models started
    on frame 1 with the tuning split's learned tint and direction (benchmarks/segmentation_cdnet.py
    tries value ratio 0.05-0.2, chroma 0.3 there). Measured on these 4 frames (849 shadow pixels):
    the colour gate alone recall 0.860, F 0.918, FPR-S 0.214, shadow precision 0.256; with the
    geometry recall 0.985 (the dark cars given back), F 0.985, FPR-S still 0.214, shadow precision
    0.774."""
    root = shared_data / "segmentation" / "cdnet2014_highway"
    if not root.is_dir():
        pytest.skip(f"{root} not found")
    roi = cv2.imread(str(root / "ROI.bmp"), cv2.IMREAD_GRAYSCALE) > 0
    keep = range(660, 700, 10)
    truths = [cv2.imread(str(root / "groundtruth" / f"gt{i:06d}.png"), cv2.IMREAD_GRAYSCALE) for i in keep]
    direction = learn_shadow_direction([t == 255 for t in truths], [(t == 50) & roi for t in truths])
    assert -0.6 < direction[0] < -0.4 and 0.8 < direction[1] < 0.92  # down-left: the sun behind-right
    gate = AdaptiveSettings(value_ratio=(0.05, 0.2), chroma=0.3, tint=(0.986, 0.932, 1.082))
    geom = AdaptiveSettings.from_dict({**gate.to_dict(), "shadow_direction": direction})
    models, out = None, {0: [], 1: []}
    for i in range(1, 691):
        rgb = cv2.cvtColor(cv2.imread(str(root / "input" / f"in{i:06d}.jpg")), cv2.COLOR_BGR2RGB)
        models = models or [BackgroundModel.start(rgb, adaptive=s) for s in (gate, geom)]
        for k, m in enumerate(models):
            lab = m.apply(rgb)
            if i in keep:
                out[k].append(lab)
    plain, shaped = (cdnet_scores(out[k], truths, roi) for k in (0, 1))
    assert plain["recall"] < 0.9 and shaped["recall"] > 0.96  # dark car pixels kept as car
    assert shaped["precision"] > 0.98
    assert shaped["fpr_shadow"] <= 0.3 and shaped["fpr_shadow"] == pytest.approx(plain["fpr_shadow"], abs=0.02)
    assert shaped["shadow_recall"] > 0.7 and shaped["shadow_precision"] > plain["shadow_precision"] + 0.3
    assert shaped["f_measure"] > 0.975


def _reference(labels, direction, fraction, reach=96):
    """The chord test pixel by pixel in plain Python (full walks both ways, no early stop)."""
    dx, dy = np.asarray(direction, float) / np.hypot(*direction)
    h, w = labels.shape

    def walk(y, x, sx, sy):
        for t in range(1, reach):
            yy, xx = int(np.floor(y + t * sy + 0.5)), int(np.floor(x + t * sx + 0.5))
            if not (0 <= yy < h and 0 <= xx < w) or labels[yy, xx] == 0:
                return t
        return reach

    out = labels.copy()
    for y, x in zip(*np.nonzero(labels == SHADOW)):
        ahead = walk(y, x, dx, dy)
        if ahead > fraction * (ahead + walk(y, x, -dx, -dy) - 1):
            out[y, x] = PERSON
    return out


@pytest.mark.parametrize("direction, fraction", [((-0.51, 0.86), 0.15), ((1.0, 0.3), 0.2), ((0.0, -1.0), 0.5)])
def test_compiled_walk_matches_the_plain_reference(direction, fraction):
    rng = np.random.default_rng(7)
    blobs = cv2.GaussianBlur(rng.uniform(0, 1, (70, 90)), (0, 0), 3)
    labels = np.where(blobs > 0.5, np.where(rng.uniform(0, 1, blobs.shape) < 0.6, SHADOW, PERSON), 0).astype(np.uint8)
    assert (labels == SHADOW).sum() > 500
    got = shadow_geometry(labels, direction, fraction, reach=40)
    ref = _reference(labels, direction, fraction, reach=40)
    assert np.array_equal(got, ref)
    assert 0 < (got != labels).sum() < (labels == SHADOW).sum()


def test_long_object_keeps_its_shadow_at_any_size():
    """A 150-row truck (rows 20-169) casting a 20-row shadow (rows 170-189) straight down: the
    chord is 170 px, the strip 20 / 170 = 0.118 of it. At fraction 0.15 a pixel stays shadow when
    its exit e <= 0.15 * 170 = 25.5: all 20 shadow rows and the truck's last 5 (dark, gated) rows.
    The old cap (reach 96) walked at most 96 px back: a shadow pixel with e steps ahead needed
    e / 0.15 - e + 1 <= 96 steps behind, e <= 16, so the 4 shadow rows next to the truck went back."""
    lab = np.zeros((220, 40), np.uint8)
    lab[20:170, 10:30] = PERSON
    lab[165:190, 10:30] = SHADOW  # 5 dark truck rows and the 20 shadow rows: the gate's view
    new = shadow_geometry(lab, (0.0, 1.0), fraction=0.15)
    assert np.array_equal(np.nonzero((new == SHADOW).any(1))[0], np.arange(165, 190))
    assert (new[170:190, 10:30] == SHADOW).all()
    old = shadow_geometry(lab, (0.0, 1.0), fraction=0.15, reach=96)
    assert np.array_equal(np.nonzero((old == SHADOW).any(1))[0], np.arange(174, 190))
    # the same scene drawn at half size: the same share of rows kept (scale-free)
    half = cv2.resize(lab, (20, 110), interpolation=cv2.INTER_NEAREST)
    kept = np.nonzero((shadow_geometry(half, (0.0, 1.0), fraction=0.15) == SHADOW).any(1))[0]
    assert kept[0] == 83 and kept[-1] == 94  # rows 165-189 halved (82.5-94.5): the strip and ~2 truck rows
