"""UU capture part of ``benchmarks/segmentation.py`` (real, 4 views, 644×486, no silhouette truth).

* **Empty-scene stability**: each camera's model is fitted on the even frames of the first half
  of ``background.avi``; the held-out second half (the room still empty) is then labelled.
  Every person pixel there is a false positive: reported as the mean and worst fraction of the
  image per frame, for the fixed model (``classify``), the adaptive one (``apply``, run over the
  held-out frames) and OpenCV GSOC / MOG2 (trained on the same first half).
* **Person frames** (``video.avi`` frames 100, 200, 300; the person sits on a chair that is not
  in the empty scene): the registration shift measured per camera, and the person mask's quality
  figures (:func:`studio.segment.morphology.person_components`: fraction of the image,
  components, clutter = share outside the largest component) without and with registration.
* **The chair case as a picture**: ``benchmarks/results/segmentation_uu_chair.png``, the four
  views of frame 200 with the labels (person blue, shadow red) after registration.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from studio.segment import PERSON, SHADOW, BackgroundModel
from studio.segment.morphology import person_components

CAMS = ("cam1", "cam2", "cam3", "cam4")


def _video(path: Path, wanted=None) -> dict[int, np.ndarray]:
    cap = cv2.VideoCapture(str(path))
    out, i = {}, 0
    while True:
        ok, f = cap.read()
        if not ok:
            break
        if wanted is None or i in wanted:
            out[i] = cv2.cvtColor(f, cv2.COLOR_BGR2RGB)
        i += 1
    cap.release()
    return out


def _overlay(image: np.ndarray, labels: np.ndarray) -> np.ndarray:
    out = image.copy()
    for value, color in ((PERSON, (40, 90, 255)), (SHADOW, (230, 30, 30))):
        m = labels == value
        out[m] = (0.5 * out[m] + 0.5 * np.asarray(color)).astype(np.uint8)
    return out


def bench_uu(data: Path, results_dir: Path, quick: bool) -> dict | None:
    root = data / "multiview" / "uu_infomcv_4cam_person"
    if not root.is_dir():
        print(f"\n== 6. UU capture: data not found at {root}, skipped")
        return None
    person_frames = (100, 200, 300)
    stability, persons, tiles = {}, {}, []
    for cam in CAMS:
        bg = _video(root / cam / "background.avi")
        n = len(bg)
        train = [bg[i] for i in range(0, n // 2, 2)]
        held = [bg[i] for i in range(n // 2, n, 2 if quick else 1)]
        model = BackgroundModel.fit(train)
        fp = {"toolkit classify (fixed)": [float(np.mean(model.classify(f) == PERSON)) for f in held]}
        adaptive = model.with_settings()
        fp["toolkit apply (adaptive)"] = [float(np.mean(adaptive.apply(f) == PERSON)) for f in held]
        for name, make in (("OpenCV GSOC", cv2.bgsegm.createBackgroundSubtractorGSOC),
                           ("OpenCV MOG2", cv2.createBackgroundSubtractorMOG2)):  # fmt: skip
            sub = make()
            for f in train:
                sub.apply(cv2.cvtColor(f, cv2.COLOR_RGB2BGR))
            fp[name] = [float(np.mean(sub.apply(cv2.cvtColor(f, cv2.COLOR_RGB2BGR)) == 255)) for f in held]
        stability[cam] = {k: {"mean": float(np.mean(v)), "max": float(np.max(v)), "frames": len(v)} for k, v in fp.items()}
        video = _video(root / cam / "video.avi", set(person_frames))
        shift = model.estimate_shift([video[i] for i in person_frames])
        registered = model.shifted(*shift)
        rows = {}
        for name, m in (("plain", model), ("registered", registered)):
            figs = [person_components(m.classify(video[i]))[1] for i in person_frames]
            rows[name] = {k: float(np.mean([f[k] for f in figs])) for k in ("person_fraction", "components", "clutter")}
        persons[cam] = {"shift": [round(shift[0], 3), round(shift[1], 3)], **rows}
        tiles.append(_overlay(video[200], registered.classify(video[200])))
    h = min(t.shape[0] for t in tiles)
    w = min(t.shape[1] for t in tiles)
    grid = np.vstack([np.hstack([tiles[0][:h, :w], tiles[1][:h, :w]]), np.hstack([tiles[2][:h, :w], tiles[3][:h, :w]])])
    picture = results_dir / "segmentation_uu_chair.png"
    results_dir.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(picture), cv2.cvtColor(cv2.resize(grid, None, fx=0.5, fy=0.5, interpolation=cv2.INTER_AREA),
                                           cv2.COLOR_RGB2BGR))  # fmt: skip
    print(f"\n== 6. UU capture (real, 4 × 644×486): empty-scene stability on held-out background frames "
          f"(person pixels = false positives, % of the image per frame, mean / worst)")  # fmt: skip
    methods = list(next(iter(stability.values())))
    print(f"{'camera':<7}" + "".join(f"{m:>28}" for m in methods))
    for cam, rows in stability.items():
        print(f"{cam:<7}" + "".join(f"{100 * rows[m]['mean']:>17.3f} / {100 * rows[m]['max']:.3f}" for m in methods))
    print("   person frames 100/200/300 (seated on a chair absent from the empty scene): registration shift, "
          "person % of image, components, clutter (share outside the largest component)")  # fmt: skip
    for cam, r in persons.items():
        p, g = r["plain"], r["registered"]
        print(f"{cam:<7} shift ({r['shift'][0]:+.2f}, {r['shift'][1]:+.2f}) px   plain: {100 * p['person_fraction']:.2f} % "
              f"{p['components']:.1f} comp. clutter {p['clutter']:.3f}   registered: {100 * g['person_fraction']:.2f} % "
              f"{g['components']:.1f} comp. clutter {g['clutter']:.3f}")  # fmt: skip
    print(f"   the chair case: {picture.name} (frame 200, person blue, shadow red). The chair is labelled "
          "person: it is a real object absent from the empty scene, seen consistently by all views")  # fmt: skip
    return {"empty_scene_false_positives": stability, "person_frames": persons, "picture": picture.name}
