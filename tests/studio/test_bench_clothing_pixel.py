"""benchmarks/clothing_pixel.py: the true body taken into the model (its shape, then each frame's pose by
pose_ceiling.fit_to_mesh with the shape kept), finer cameras and a pixel's size."""

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))

import clothing_pixel  # noqa: E402
import pose_ceiling  # noqa: E402


def test_a_model_body_is_recovered_as_its_shape_and_pose():
    from studio.body import BodyModel

    model = BodyModel.load("female")
    sig = np.sqrt(model.eigenvalues)
    shape = np.random.default_rng(3).uniform(-1.5, 1.5, model.n_shape) * sig
    rest = model.vertices(shape, model.default_pose()) + np.array([0.1, -0.2, 0.05])  # anywhere in the room
    got, rms = clothing_pixel.model_space_truth(model, rest)
    assert rms < 1e-4  # 0.1 mm: the default-pose body is linear in the coefficients up to float32 rounding
    assert np.max(np.abs(got - shape) / sig) < 0.01

    lo, hi = model.pose_limits[:, 0], model.pose_limits[:, 1]
    pose = np.clip(model.default_pose() + 0.2, lo, hi)  # every joint bent, the root turned and moved
    target = model.vertices(shape, pose)
    start = np.clip(pose + np.random.default_rng(4).normal(0, 0.05, pose.size), lo, hi)  # as a single fit's pose
    kept, found = pose_ceiling.fit_to_mesh(model, target, shape, start, 0, max_nfev=300, keep_tail=True)
    assert np.array_equal(kept, shape)
    err = np.sqrt(np.mean(np.sum((model.vertices(shape, found) - target) ** 2, axis=1)))
    start_err = np.sqrt(np.mean(np.sum((model.vertices(shape, start) - target) ** 2, axis=1)))
    assert start_err > 0.01  # the start is 1 cm or more away
    assert err < 1e-5  # 0.01 mm: found exactly (a step the float32 body resolves)


def test_a_pixel_at_the_person():
    from calibration.camera import Camera

    cam = Camera(name="c", K=np.diag([500.0, 500.0, 1.0]), dist=np.zeros(5), R=np.eye(3), t=np.array([0.0, 0.0, 4.0]),
                 size=(656, 490))
    # the camera's centre is at (0, 0, -4): 5 m from (0, 0, 1), 5 m / 500 px = 10 mm
    assert clothing_pixel.mm_per_pixel([cam]) == 10.0


def test_finer_cameras_undo_a_pyramid_level():
    """Cameras with twice the pixels, taken one pyramid level down, are the cameras again."""
    from calibration.camera import Camera
    from studio.render.pyramid import level_camera

    K = np.array([[563.2, 0.0, 327.1], [0.0, 562.8, 244.6], [0.0, 0.0, 1.0]])
    cam = Camera(name="c", K=K, dist=np.zeros(5), R=np.eye(3), t=np.array([0.0, 0.0, 4.0]), size=(656, 490))
    (fine,) = clothing_pixel.finer_cameras([cam], 2)
    assert tuple(fine.size) == (1312, 980)
    back = level_camera(fine, 1)
    assert tuple(back.size) == (656, 490)
    np.testing.assert_allclose(back.K, K, atol=1e-12)
    assert abs(clothing_pixel.mm_per_pixel([fine]) - clothing_pixel.mm_per_pixel([cam]) / 2) < 1e-9
