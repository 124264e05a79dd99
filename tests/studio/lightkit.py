"""Synthetic scenes for the light tests: our own body in a few poses, its shadows and labels."""

import numpy as np

from calibration import Camera, RigCalibration
from rigs.imageio import write_image
from rigs.session import SessionWriter
from studio.body import BodyModel
from studio.render import shadow_silhouettes, silhouette


def cameras(size=(200, 150), focal=170.0, n=3):
    out = []
    for k in range(n):
        a = 0.3 + 2 * np.pi * k / n
        eye = np.array([3.8 * np.cos(a), 3.8 * np.sin(a), 2.4])
        out.append(Camera.look_at(f"cam{k}", eye, [0, 0, 0.5], focal, size, np.array([-0.03, 0.005, 0, 0, 0])))
    return out


def bodies(n_frames=4):
    """(vertices, faces) of the female model walking across the floor, turning, arms moving."""
    model = BodyModel.load("female")
    out = []
    for i in range(n_frames):
        pose = model.default_pose()
        pose[:2] = [-0.45 + 0.3 * i, 0.1 * (i % 2)]
        pose[5] = 0.5 * i
        V = model.vertices(model.mean_shape(), pose)
        V[:, 2] -= V[:, 2].min()
        out.append((V, model.faces))
    return out


def labels(cams, body, lights):
    """Per camera (H, W) uint8 labels: 0 background, 1 person, 2 shadow (the person first)."""
    V, F = body
    shadows = shadow_silhouettes(cams, V, F, lights) if lights else [None] * len(cams)
    out = []
    for c, s in zip(cams, shadows, strict=True):
        lab = np.zeros((c.size[1], c.size[0]), np.uint8)
        if s is not None:
            lab[s] = 2
        lab[silhouette(c, V, F)] = 1
        out.append(lab)
    return out


def make_session(path, lights, n_frames=4):
    """A session folder with calibration, frames, segmentation labels and truth bodies."""
    cams = cameras()
    calib_file = path.parent / f"{path.name}-calibration.json"
    RigCalibration(cameras={c.name: c for c in cams}).save(calib_file)
    writer = SessionWriter.create(path, [c.name for c in cams], rig="test", calibration=calib_file)
    bods = bodies(n_frames)
    (path / "truth" / "bodies").mkdir(parents=True, exist_ok=True)
    np.save(path / "truth" / "faces.npy", bods[0][1])
    for i, body in enumerate(bods):
        labs = labels(cams, body, lights)
        writer.write_frame(i, {c.name: (np.array([90, 180, 30], np.uint8)[lab]).astype(np.uint8)[..., None].repeat(3, 2)
                               for c, lab in zip(cams, labs, strict=True)})
        for c, lab in zip(cams, labs, strict=True):
            p = path / "segmentation" / c.name / f"{i:06d}.png"
            p.parent.mkdir(parents=True, exist_ok=True)
            write_image(p, lab)
        np.savez(path / "truth" / "bodies" / f"{i:06d}.npz", vertices=body[0].astype(np.float32))
    writer.close()
    return cams, bods
