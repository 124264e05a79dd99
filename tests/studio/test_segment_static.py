"""Static changes (:mod:`studio.segment.static`): a box put down while a person moves becomes
background; a person who stops is kept; the user's ignore regions."""

import json

import numpy as np
import pytest

from rigs.imageio import write_image
from studio.segment import PERSON, BackgroundModel, SegmentationError, StaticDetector, StaticSettings, ignore_masks
from studio.segment.static import StaticChanges, polygon_mask

H, W, N = 120, 160, 20
BOX = (slice(70, 95), slice(110, 135))


class Scene:
    """A textured room; a striped 'person' 16 px wide (changes colour as it moves) and a box."""

    def __init__(self, seed=0):
        self.rng = np.random.default_rng(seed)
        base = np.empty((H, W, 3), np.float32)
        base[:] = (90, 140, 110)
        self.base = base + self.rng.normal(0, 6, base.shape)

    def frame(self, people=(), box=False):
        f = self.base + self.rng.normal(0, 2, self.base.shape)
        if box:
            f[BOX] = (160, 60, 40)
        for x, y in people:
            stripe = (((np.arange(x, x + 16) // 4) % 2) == 1)[None, :, None]
            f[y:y + 70, x:x + 16] = np.where(stripe, (200, 180, 150), (40, 40, 120))
        return np.clip(f, 0, 255).astype(np.uint8)


def walk(t, lo=10, span=60, speed=2):
    p = t * speed % (2 * span)
    return lo + (p if p < span else 2 * span - p)


@pytest.fixture
def scene():
    s = Scene()
    return s, BackgroundModel.fit([s.frame() for _ in range(8)])


def _run(scene, positions, box_from=None, box_until=10**9, settings=StaticSettings(frames=N)):
    """Per frame: (share of the box's uncovered pixels labelled person, share of each person labelled
    person, static px)."""
    s, model = scene
    det = StaticDetector((H, W), settings)
    rows = []
    for t, people in enumerate(positions):
        box = box_from is not None and box_from <= t < box_until
        f = s.frame(people, box)
        labels, static = det.update(f, model.classify(f))
        kept = [float(np.mean(labels[y:y + 70, x:x + 16] == PERSON)) for x, y in people]
        uncovered = np.ones((H, W), bool)
        for x, y in people:
            uncovered[y:y + 70, x:x + 16] = False
        rows.append((float(np.mean(labels[BOX][uncovered[BOX]] == PERSON)), kept, int(static.sum())))
    return rows, det


def test_a_box_put_down_while_the_person_moves_becomes_background_after_n_frames(scene):
    rows, det = _run(scene, [[(walk(t), 30)] for t in range(70)], box_from=10)
    assert [r[0] > 0.95 for r in rows[10:10 + N]] == [True] * N  # person-like while it is new
    # static within N + N/10 frames (the components are checked every N/10 frames)
    assert max(r[0] for r in rows[10 + N + N // 10:]) == 0.0
    assert rows[10 + N + N // 10][2] >= 0.95 * 25 * 25
    assert min(min(r[1]) for r in rows) > 0.97  # the moving person is kept every frame
    assert det.layer[BOX].mean() > 0.95 and det.layer.sum() < 1.1 * 25 * 25


def test_a_person_who_stops_is_kept_however_long(scene):
    # walks for 15 frames, then stands still for 4 N frames: nothing else moves
    rows, det = _run(scene, [[(walk(min(t, 15)), 30)] for t in range(15 + 4 * N)])
    assert min(r[1][0] for r in rows) > 0.97 and max(r[2] for r in rows) == 0 and not det.layer.any()
    # the guard is what keeps them: without it (plain persistence, witness=0), or with a second person
    # walking elsewhere, the still one is absorbed N frames after stopping
    rows, _ = _run(scene, [[(walk(min(t, 15)), 30)] for t in range(15 + 4 * N)],
                   settings=StaticSettings(frames=N, witness=0.0))
    assert 15 + N <= next(t for t, r in enumerate(rows) if r[1][0] < 0.5) <= 15 + N + N // 10
    rows, _ = _run(scene, [[(walk(min(t, 15)), 30), (walk(t, lo=110, span=30), 20)] for t in range(15 + 4 * N)])
    first_static = next(t for t, r in enumerate(rows) if r[1][0] < 0.5)
    assert 15 + N <= first_static <= 15 + N + N // 10 and min(r[1][1] for r in rows) > 0.97


def test_a_person_in_front_of_the_static_box_is_person_and_a_removed_box_leaves_no_ghost(scene):
    # the box is put down at 5; the person walks right, crosses the box (110-135) around frame 50
    xs = [min(10 + max(t - 30, 0) * 4, 140) if t >= 30 else walk(t) for t in range(90)]
    rows, det = _run(scene, [[(x, 50)] for x in xs], box_from=5, box_until=80)
    assert max(r[0] for r in rows[5 + N:30]) < 0.01  # static before the person reaches it
    crossing = [t for t in range(30, 80) if 110 <= xs[t] <= 119]
    assert crossing and min(rows[t][1][0] for t in crossing) > 0.95  # in front of the box: person
    assert max(r[0] for r in rows[5 + N:80]) < 0.03  # the uncovered rest stays static (morphology: edge px)
    assert rows[-1][2] == 0 and not det.layer[BOX].any()  # box taken away at 80: empty scene again


def test_ignore_regions_from_polygons_and_masks(tmp_path):
    square = [[2, 2], [5, 2], [5, 5], [2, 5]]
    assert polygon_mask([square], (8, 8)).sum() == 16
    (tmp_path / "p.json").write_text(json.dumps({"cameras": {"a": [square]}}))
    mask = np.zeros((8, 8), np.uint8)
    mask[0, :3] = 255
    write_image(tmp_path / "m.png", mask)
    got = ignore_masks([str(tmp_path / "p.json"), f"a={tmp_path / 'm.png'}"], {"a": (8, 8), "b": (8, 8)})
    assert set(got) == {"a"} and got["a"].sum() == 19
    labels = {"a": np.ones((8, 8), np.uint8), "b": np.ones((8, 8), np.uint8)}
    frames = {c: np.zeros((8, 8, 3), np.uint8) for c in labels}
    figures = StaticChanges(got)(0, frames, labels)
    assert figures == {"a": {"ignored": 19}, "b": {}} and labels["a"].sum() == 64 - 19 and labels["b"].sum() == 64
    with pytest.raises(SegmentationError, match="unknown camera"):
        ignore_masks([str(tmp_path / "p.json")], {"b": (8, 8)})
    with pytest.raises(SegmentationError, match="8x8, camera 'a' is 9x8"):
        ignore_masks([f"a={tmp_path / 'm.png'}"], {"a": (8, 9)})
    with pytest.raises(SegmentationError, match="frames"):
        StaticSettings(frames=1)


def test_studio_segment_static_and_ignore_on_a_session(tmp_path):
    """A box painted into cam0 from frame 1 on (put down while the person walks) is person for the
    plain run and background from frame 1 + N with ``--static N``; ``--ignore`` polygons drop a
    region; the person keeps its recall; both figures land in segmentation.json."""
    from rigs.imageio import read_image
    from studio.cli import main
    from studio.segment.metrics import label_scores
    from studio.segment.synthetic import write_session

    path = write_session(tmp_path / "box", size=(96, 72), frames=9)
    for i in range(1, 9):
        f = path / "frames" / "cam0" / f"{i:06d}.png"
        img = read_image(f)
        img[2:12, 2:14] = (250, 20, 200)
        write_image(f, img)

    def run(*extra, workers="1"):
        assert main(["segment", str(path), "--no-skin", "--no-voting", "--overlay-every", "0", "--workers", workers,
                     *extra]) == 0  # fmt: skip
        labels = [read_image(path / "segmentation" / "cam0" / f"{i:06d}.png") for i in range(9)]
        return labels, json.loads((path / "segmentation" / "segmentation.json").read_text())

    truth = [read_image(path / "truth" / "labels" / "cam0" / f"{i:06d}.png") for i in range(9)]
    plain, _ = run()
    static, meta = run("--static", "3", workers="2")  # one chain, in order, whatever the workers
    assert [bool((lab[2:12, 2:14] == PERSON).mean() > 0.85) for lab in plain] == [False] + [True] * 8
    assert [bool((lab[2:12, 2:14] == PERSON).any()) for lab in static] == [False] + [True] * 3 + [False] * 5
    assert [meta["frame_quality"][str(i)]["cam0"]["static"] >= 100 for i in range(9)] == [False] * 4 + [True] * 5
    r_plain, r_static = (label_scores(v[4:], truth[4:])["person"] for v in (plain, static))
    assert r_static["recall"] >= r_plain["recall"] - 1e-9 and r_static["precision"] > r_plain["precision"] + 0.02
    assert meta["settings"]["static_frames"] == 3 and meta["quality"]["cam1"]["static_mean"] == 0
    (tmp_path / "ignore.json").write_text(json.dumps({"cameras": {"cam0": [[[0, 0], [20, 0], [20, 14], [0, 14]]]}}))
    ignored, meta = run("--ignore", str(tmp_path / "ignore.json"))
    assert all(not lab[:14, :20].any() for lab in ignored) and meta["frame_quality"]["5"]["cam0"]["ignored"] >= 100
    assert "ignored" not in meta["frame_quality"]["5"]["cam1"]
