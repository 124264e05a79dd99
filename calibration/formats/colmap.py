"""COLMAP sparse model (``cameras`` + ``images`` [+ rigs, frames, points3D]) via pycolmap.

One COLMAP camera and one registered image per rig camera; the image is named after the
camera. Camera models: ``OPENCV`` (fx fy cx cy k1 k2 p1 p2) for up to 4 distortion
coefficients, ``FULL_OPENCV`` (… k3 k4 k5 k6) for 5 or 8; 12/14-coefficient cameras
(thin prism, tilt) are written only when those extra terms are zero. Reading also accepts
``SIMPLE_PINHOLE``, ``PINHOLE``, ``SIMPLE_RADIAL`` and ``RADIAL``.

Fisheye cameras (``Camera.model == "fisheye"``) are written as ``OPENCV_FISHEYE``
(fx fy cx cy k1 k2 k3 k4: the same equidistant model and coefficient order as
``cv2.fisheye``). Reading also accepts COLMAP's special cases of that model:
``SIMPLE_FISHEYE`` (f cx cy), ``FISHEYE`` (fx fy cx cy), ``SIMPLE_RADIAL_FISHEYE``
(f cx cy k) and ``RADIAL_FISHEYE`` (f cx cy k1 k2), read as fisheye cameras with the
missing coefficients zero (checked against ``pycolmap.Camera.img_from_cam`` to 1e-12 px).

Pixel convention: COLMAP puts (0, 0) at the top-left CORNER of the top-left pixel, we put
it at that pixel's centre, so ``c_colmap = c_opencv + 0.5``.

COLMAP has no place for the ground plane and metadata: they go to a sidecar
``studio_rig.json`` in the same folder (default floor z = 0 when absent).
"""

from __future__ import annotations

import json
import logging
import tempfile
from os import PathLike
from pathlib import Path

import numpy as np

from calibration.camera import Camera
from calibration.errors import CalibrationError
from calibration.formats import RigParts
from rigs.atomic import atomic_write_bytes, atomic_write_text
from calibration.ground import GroundPlane

log = logging.getLogger(__name__)

SIDECAR = "studio_rig.json"
PIXEL_SHIFT = 0.5  # c_colmap - c_opencv
#: COLMAP models that are ``cv2.fisheye``'s equidistant model (or special cases of it).
FISHEYE_MODELS = (
    "OPENCV_FISHEYE", "FISHEYE", "SIMPLE_FISHEYE", "RADIAL_FISHEYE", "SIMPLE_RADIAL_FISHEYE"
)
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".exr")


def _camera_name(image_name: str) -> str:
    p = Path(image_name)
    return p.stem if p.suffix.lower() in IMAGE_SUFFIXES else image_name


def _intrinsics(cam, name: str, path: Path) -> tuple[np.ndarray, np.ndarray, str]:
    model = cam.model.name
    p = np.asarray(cam.params, dtype=np.float64)
    lens = "pinhole"
    if model == "SIMPLE_PINHOLE":
        f, cx, cy = p
        fx = fy = f
        dist = np.zeros(0)
    elif model == "PINHOLE":
        fx, fy, cx, cy = p
        dist = np.zeros(0)
    elif model == "SIMPLE_RADIAL":
        f, cx, cy, k = p
        fx = fy = f
        dist = np.array([k, 0.0, 0.0, 0.0])
    elif model == "RADIAL":
        f, cx, cy, k1, k2 = p
        fx = fy = f
        dist = np.array([k1, k2, 0.0, 0.0])
    elif model == "OPENCV":
        fx, fy, cx, cy = p[:4]
        dist = p[4:8]
    elif model == "FULL_OPENCV":
        fx, fy, cx, cy = p[:4]
        dist = p[4:12]
        if not np.any(dist[5:]):
            dist = dist[:5]
    elif model in FISHEYE_MODELS:
        lens = "fisheye"
        if model in ("SIMPLE_FISHEYE", "SIMPLE_RADIAL_FISHEYE", "RADIAL_FISHEYE"):  # one f
            f, cx, cy = p[:3]
            fx = fy = f
            k = p[3:]
        else:
            fx, fy, cx, cy = p[:4]
            k = p[4:]
        dist = np.zeros(4)
        dist[: len(k)] = k
    else:
        raise CalibrationError(
            f"COLMAP camera model {model} is not an OpenCV pinhole or fisheye model "
            "(expected OPENCV, FULL_OPENCV, PINHOLE, SIMPLE_PINHOLE, SIMPLE_RADIAL, RADIAL, "
            f"or {', '.join(FISHEYE_MODELS)})",
            file=path, camera=name, field="model",
        )
    K = np.array([[fx, 0.0, cx - PIXEL_SHIFT], [0.0, fy, cy - PIXEL_SHIFT], [0.0, 0.0, 1.0]])
    return K, dist, lens


def _check_quaternions(path: Path) -> None:
    """A zero quaternion in a text model is no rotation; pycolmap would normalise it silently."""
    for name, first in (("images.txt", 1), ("frames.txt", 2)):
        f = path / name
        if not f.is_file():
            continue
        data = 0  # images.txt: two lines per image, the pose then its POINTS2D (possibly empty)
        for number, line in enumerate(f.read_text(errors="replace").splitlines(), start=1):
            if line.startswith("#"):
                continue
            data += 1
            parts = line.split()
            if (name == "images.txt" and data % 2 == 0) or len(parts) < first + 7:
                continue
            try:
                q = np.array([float(v) for v in parts[first:first + 4]])
            except ValueError:
                continue  # a POINTS2D line, or pycolmap's own error will name it
            if not np.all(np.isfinite(q)) or np.linalg.norm(q) < 1e-12:
                raise CalibrationError(f"line {number}: quaternion {q.tolist()} is not a rotation "
                                       "(zero or non-finite norm)", file=f, field="QW QX QY QZ")


def read_colmap(path: str | PathLike):
    import pycolmap

    path = Path(path)
    if path.is_file():
        path = path.parent
    if not ((path / "cameras.txt").exists() or (path / "cameras.bin").exists()):
        raise CalibrationError("not a COLMAP model folder (no cameras.txt or cameras.bin)", file=path)
    _check_quaternions(path)
    try:
        rec = pycolmap.Reconstruction(str(path))
    except Exception as exc:  # pycolmap raises plain RuntimeError/ValueError on bad files
        raise CalibrationError(f"pycolmap cannot read the model ({exc})", file=path) from None
    cameras = {}
    try:
        for image_id in sorted(rec.images):
            image = rec.images[image_id]
            try:
                name = _camera_name(image.name)
            except UnicodeDecodeError as exc:
                raise CalibrationError(f"image {image_id}: its name is not UTF-8 text ({exc})", field="NAME") from None
            if not image.has_pose:
                log.warning("%s: image %s has no pose; skipped", path, image.name)
                continue
            K, dist, lens = _intrinsics(image.camera, name, path)
            pose = image.cam_from_world()  # a method since pycolmap 3.12 (the version required)
            R = np.asarray(pose.rotation.matrix(), dtype=np.float64)
            t = np.asarray(pose.translation, dtype=np.float64)
            cam = image.camera
            if name in cameras:
                raise CalibrationError("two images map to this camera name", camera=name, field="name")
            cameras[name] = Camera(name, K, dist, R, t, (cam.width, cam.height), lens)
        if not cameras:
            raise CalibrationError("no registered images", field="images")
        ground, meta = GroundPlane.floor(), {}
        sidecar = path / SIDECAR
        if not sidecar.exists():
            log.warning("%s: no %s beside the COLMAP model (COLMAP has no floor): the ground plane is "
                        "assumed to be z = 0 — calibrate the floor (`studio calibrate floor`) if it is not",
                        path, SIDECAR)
            meta = {"ground_source": f"assumed z = 0: no {SIDECAR} in {path}"}
        else:
            try:
                doc = json.loads(sidecar.read_text())
                if not isinstance(doc, dict):
                    raise CalibrationError(f"bad sidecar (expected a JSON object, got {type(doc).__name__})",
                                           field="ground")
                if str(doc.get("version", 1)).split(".")[0] != "1":
                    raise CalibrationError(
                        f"unknown major version {doc['version']!r} (this reader knows 1)",
                        field="version",
                    )
                g = doc.get("ground")
                if g is not None:
                    ground = GroundPlane(g["normal"], g["offset"])
                meta = doc.get("metadata", {})
            except (json.JSONDecodeError, KeyError, TypeError) as exc:
                raise CalibrationError(f"bad sidecar ({exc!r})", file=sidecar, field="ground") from None
            except CalibrationError as exc:
                raise exc.in_file(sidecar) from None
        if sidecar.exists():
            return RigParts(cameras, ground, meta, own_frame=True)
        return RigParts(cameras, ground, meta, units="arbitrary",
                        notes=(f"no {SIDECAR} beside the model: the floor is assumed to be z = 0",))
    except CalibrationError as exc:
        raise exc.in_file(path) from None


def _params(cam: Camera, path: Path) -> tuple[str, list[float]]:
    K = cam.K
    if K[0, 1] != 0:
        raise CalibrationError(
            "COLMAP cannot store a skewed K (K[0,1] != 0)", file=path, camera=cam.name, field="K"
        )
    base = [K[0, 0], K[1, 1], K[0, 2] + PIXEL_SHIFT, K[1, 2] + PIXEL_SHIFT]
    if cam.model == "fisheye":
        return "OPENCV_FISHEYE", base + cam.dist.tolist()
    d = cam.dist
    if d.size > 8 and np.any(d[8:]):
        raise CalibrationError(
            "thin-prism/tilt terms (coefficients 9-14) have no COLMAP model",
            file=path, camera=cam.name, field="dist",
        )
    d8 = np.zeros(8)
    d8[: min(8, d.size)] = d[:8]
    if d.size <= 4 or not np.any(d8[4:]):
        return "OPENCV", base + d8[:4].tolist()
    return "FULL_OPENCV", base + d8.tolist()


#: What a calibration is in COLMAP's files; ``points3D`` is the scene's, not ours.
CALIBRATION_FILES = ("cameras", "images", "rigs", "frames")


def write_colmap(rig, path: str | PathLike, binary: bool = False) -> Path:
    """Write the model into folder ``path`` (created); files replaced one by one atomically.

    Only the calibration's files (``cameras``, ``images``, ``rigs``, ``frames`` and the sidecar)
    are replaced, and their other flavour (``.txt``/``.bin``) removed so no stale model stays;
    a ``points3D`` already in the folder (the user's reconstruction) is kept, an empty one is
    written only where none of this flavour exists, so COLMAP can read the folder.
    """
    import pycolmap

    path = Path(path)
    rec = pycolmap.Reconstruction()
    for i, (name, cam) in enumerate(rig.cameras.items(), start=1):
        model, params = _params(cam, path)
        pc = pycolmap.Camera(model=model, width=cam.width, height=cam.height, params=params, camera_id=i)
        image = pycolmap.Image(name=name, camera_id=i, image_id=i)
        pose = pycolmap.Rigid3d(pycolmap.Rotation3d(np.asarray(cam.R)), np.asarray(cam.t))
        rec.add_camera_with_trivial_rig(pc)  # pycolmap >= 3.12 (required): rigs and frames
        rec.add_image_with_trivial_frame(image, pose)
    path.mkdir(parents=True, exist_ok=True)
    ext, other = (".bin", ".txt") if binary else (".txt", ".bin")
    has_points = (path / ("points3D" + ext)).exists()
    with tempfile.TemporaryDirectory(prefix=".colmap.", dir=path) as tmp:
        (rec.write_binary if binary else rec.write_text)(tmp)
        for f in sorted(Path(tmp).iterdir()):
            if f.stem in CALIBRATION_FILES or (f.stem == "points3D" and not has_points):
                atomic_write_bytes(path / f.name, f.read_bytes())
    for stale in CALIBRATION_FILES:
        if (path / (stale + other)).exists():
            (path / (stale + other)).unlink()  # never leave a calibration of the other flavour behind
    sidecar = {"format": "studio.rig-calibration.colmap-sidecar", "version": 1,
               "ground": rig.ground.to_dict(), "metadata": rig.metadata}
    atomic_write_text(path / SIDECAR, json.dumps(sidecar, indent=2) + "\n")
    return path
