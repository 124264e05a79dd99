"""Frame sampling from videos / folders: sharp, diverse views are kept, the rest say why not."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from calibration.boards import load_board
from calibration.errors import CalibrationError
from calibration.sampling import iter_video_frames, sample_views, select_diverse, sharpness, view_descriptor
from calibration.synthetic import camera_ring, random_board_poses, render_board_view

BOARD = load_board("studio_charuco_a1")


@pytest.fixture(scope="module")
def frames():
    """12 rendered views of one camera: 8 distinct poses, 2 near-duplicates, 2 motion-blurred."""
    rng = np.random.default_rng(2)
    cam = camera_ring(1, radius=1.4, height=1.0, size=(640, 400), focal=520.0, dist=(0, 0, 0, 0, 0))["cam00"]
    # board faces toward the camera (+x): yaw pi means the printed face looks along +x
    poses = []
    while len(poses) < 8:
        p = random_board_poses(1, BOARD, rng, centre=(0.0, -0.2, 0.9), spread=(0.15, 0.2, 0.15), max_tilt_deg=30)["v000"]
        if -p[0][:, 2] @ (cam.center - p[1]) > 0.8 * np.linalg.norm(cam.center - p[1]):
            poses.append(p)
    out = [(f"f{k:02d}", render_board_view(cam, BOARD, p, rng=rng)) for k, p in enumerate(poses)]
    out += [("dup0", render_board_view(cam, BOARD, poses[0], rng=rng)), ("dup1", render_board_view(cam, BOARD, poses[1], rng=rng))]
    for k in (2, 3):
        img = render_board_view(cam, BOARD, poses[k], rng=rng)
        out.append((f"blur{k}", cv2.GaussianBlur(img, (0, 0), 1.3)))
    return out


def test_sharpness_measures_edge_blur(frames):
    img = frames[0][1]
    from calibration.detect import detect_board, to_gray

    det = detect_board(img, BOARD)
    g = to_gray(img)
    crisp = sharpness(g, det.image_points)
    blurred = sharpness(cv2.GaussianBlur(g, (0, 0), 2.5), det.image_points)
    assert 0.2 < crisp < 0.6 and blurred < 0.6 * crisp
    assert sharpness(g) > sharpness(cv2.GaussianBlur(g, (0, 0), 2.5))  # whole-image fallback
    assert sharpness(np.full((20, 20), 100, np.uint8), np.array([[10.0, 10.0]])) == 0.0


def test_sample_views_keeps_sharp_diverse(frames):
    # blur of 1.3 px on top of the rendering's 0.6 px: sharpness drops to ~0.7 of the crisp views
    res = sample_views(frames, BOARD, n_views=7, min_rel_sharpness=0.85)
    kept = {d.view for d in res.kept}
    assert len(kept) == 7
    assert res.dropped["blur2"].startswith("blurred: sharpness")
    assert "blur3" in res.dropped  # blurred, or its markers no longer decode
    # of each near-duplicate pair at most one survives
    assert not {"f00", "dup0"} <= kept and not {"f01", "dup1"} <= kept
    assert sum("diversity" in r for r in res.dropped.values()) == 12 - 2 - 7


def test_select_diverse_spreads_out():
    pts = np.array([[0.0, 0], [0.01, 0], [1, 0], [1, 0.01], [0, 1]])
    chosen = select_diverse(pts, 3)
    assert chosen[0] == 0 and chosen[-1] == 4 and chosen[1] in (2, 3)  # one of each cluster
    assert select_diverse(pts, 10) == [0, 1, 2, 3, 4]


def test_view_descriptor_tracks_position(frames):
    from calibration.detect import detect_board

    d = detect_board(frames[0][1], BOARD)
    desc = view_descriptor(d)
    assert desc.shape == (6,)
    assert np.allclose(desc[:2], d.image_points.mean(0) / [640, 400])


def test_video_and_folder_sources(frames, tmp_path):
    path = tmp_path / "board.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10, (640, 400))
    assert writer.isOpened()
    for _, img in frames[:6]:
        writer.write(cv2.cvtColor(img, cv2.COLOR_RGB2BGR))
    writer.release()
    got = list(iter_video_frames(path, step=2))
    assert [k for k, _ in got] == [0, 2, 4] and got[0][1].shape == (400, 640, 3)
    res = sample_views(path, BOARD, n_views=4, step=1)
    assert len(res.kept) == 4 and all(d.view.startswith("board#") for d in res.kept)
    folder = tmp_path / "imgs"
    folder.mkdir()
    for name, img in frames[:4]:
        cv2.imwrite(str(folder / f"{name}.png"), cv2.cvtColor(img, cv2.COLOR_RGB2BGR))
    assert len(sample_views(folder, BOARD, n_views=10).kept) == 4


def test_sampling_errors(tmp_path):
    with pytest.raises(CalibrationError, match="frame step must be >= 1"):
        next(iter_video_frames(tmp_path / "x.avi", step=0))
    with pytest.raises(CalibrationError, match="cannot open this video"):
        next(iter_video_frames(tmp_path / "missing.avi"))
    with pytest.raises(CalibrationError, match="no images"):
        sample_views(tmp_path, BOARD)
    with pytest.raises(CalibrationError, match="no such video or image folder"):
        sample_views(tmp_path / "nope.txt", BOARD)
    (tmp_path / "notes.txt").write_text("x")
    with pytest.raises(CalibrationError, match="not a folder or a video"):
        sample_views(tmp_path / "notes.txt", BOARD)
    blank = [("b0", np.full((100, 100, 3), 128, np.uint8))]
    with pytest.raises(CalibrationError, match="was not detected in any of 1 frames"):
        sample_views(blank, BOARD)
