"""One OpenCV FileStorage file (XML or YAML) per camera.

Two layouts, told apart by their keys:

- **course / per-camera rig files** (e.g. the Utrecht INFOMCV ``<cam>/config.xml``)::

      CameraMatrix       3x3
      DistortionCoeffs   1x5 or 5x1, OpenCV order
      Rotation           3x1 Rodrigues vector (or a 3x3 matrix), world -> camera
      Translation        3x1, X_c = R X_w + t, in the board's unit (the course: mm)

  (some versions of the course tool write ``RotationValues`` / ``TranslationValues``.)

  The world is the calibration board's frame, whose Z axis points *into* the floor for a
  board lying face up (``solvePnP`` on ``(x, y, 0)`` corners): such a world has Z down and
  :mod:`calibration.formats.checks` turns it (or refuses it). Units come from the magnitudes.
- **OpenCV's calibration sample** (``samples/cpp/calibration.cpp``, the ChArUco tutorial)::

      camera_matrix, distortion_coefficients, image_width, image_height

  Intrinsics only: the file's ``extrinsic_parameters`` are the *board's* poses per view, not
  the camera's. The camera is read with ``R = I``, ``t = 0`` and a note says so.

Sources: a folder of ``<camera>/config.xml`` (camera names from the folder names), one file
(camera named after its folder for ``config.xml``/``intrinsics.xml``, else after the file), or
``{name: file}`` pairs. The image size, which the course files lack, is read from a video or
image beside the file when there is one (``video.avi`` …), else guessed from the principal
point with a warning. A course ``checkerboard.xml`` beside the camera folders
(``CheckerBoardSquareSize``) says which unit to expect; the magnitudes still decide.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from calibration.camera import Camera
from calibration.errors import CalibrationError
from calibration.formats import RigParts
from calibration.formats.opencv import _check_text, _mat, _open, open_storage, size_from_principal_point
from calibration.ground import GroundPlane
from calibration.rotation import nearest_rotation, rotvec_to_matrix
from rigs.atomic import atomic_path

#: Names whose camera is named after the folder holding them.
GENERIC_NAMES = ("config", "intrinsics", "calibration", "camera", "calib")
#: Media beside a camera file whose frame size gives the image size (first found wins).
MEDIA = ("*.avi", "*.mp4", "*.mov", "*.mkv", "*.png", "*.jpg", "*.jpeg", "*.bmp")
#: Largest ``max |R Rᵀ - I|`` of a 3x3 ``Rotation`` put down to rounding (re-orthonormalised).
ROUNDING_TOL = 1e-4

# (key of K, key of the distortion, key of the rotation, key of the translation)
COURSE = ("CameraMatrix", "DistortionCoeffs", "Rotation", "Translation")
SAMPLE = ("camera_matrix", "distortion_coefficients", None, None)
#: Key names of the pose: (rotation, translation), first found wins.
POSE_KEYS = (("Rotation", "Translation"), ("RotationValues", "TranslationValues"))


def _name_of(path: Path) -> str:
    return path.parent.name if path.stem.lower() in GENERIC_NAMES and path.parent.name else path.stem


def _media_size(folder: Path) -> tuple[tuple[int, int], str] | None:
    """(width, height) of the first video or image in ``folder`` and its name, or None."""
    import cv2

    for pattern in MEDIA:
        for item in sorted(folder.glob(pattern)):
            if pattern in ("*.avi", "*.mp4", "*.mov", "*.mkv"):
                cap = cv2.VideoCapture(str(item))
                try:
                    w, h = int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
                finally:
                    cap.release()
            else:
                img = cv2.imread(str(item), cv2.IMREAD_UNCHANGED)
                h, w = (img.shape[:2] if img is not None else (0, 0))
            if w > 0 and h > 0:
                return (w, h), item.name
    return None


def _rotation(value: np.ndarray, path: Path, name: str, key: str) -> tuple[np.ndarray, bool]:
    if value.size == 3:
        return rotvec_to_matrix(value.reshape(3)), False
    if value.size != 9:
        raise CalibrationError(f"expected a 3x1 Rodrigues vector or a 3x3 matrix, got shape {value.shape}",
                               file=path, camera=name, field=key)
    R = value.reshape(3, 3)
    nearest, err = nearest_rotation(R)
    if err <= 1e-6 or not np.all(np.isfinite(R)) or np.linalg.det(R) < 0:
        return R, False
    if err > ROUNDING_TOL:
        raise CalibrationError(f"not a rotation: max |R Rᵀ - I| = {err:.3g} > {ROUNDING_TOL:g}",
                               file=path, camera=name, field=key)
    return nearest, True


def _open_storage(path: Path):
    """OpenCV FileStorage of ``path``; XML without its ``<?xml ...?>`` line (which OpenCV then
    parses as YAML and rejects) is read with the line added."""
    import cv2

    text = path.read_text(encoding="utf-8", errors="replace") if path.is_file() else ""
    if not text.lstrip().startswith("<opencv_storage"):
        return _open(path)
    _check_text(path)
    return open_storage('<?xml version="1.0"?>\n' + text, cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY, path)


def read_camera_file(path: Path, name: str) -> tuple[Camera, list[str], bool]:
    """One camera from ``path``: the camera, notes, and whether the file holds a pose."""
    path = Path(path)
    fs = _open_storage(path)
    try:
        layout = COURSE if not fs.getNode("CameraMatrix").empty() else SAMPLE
        if fs.getNode(layout[0]).empty():
            raise CalibrationError("missing: expected CameraMatrix (per-camera rig file) or camera_matrix "
                                   "(OpenCV calibration sample output)", file=path, camera=name, field="CameraMatrix")
        K = _mat(fs, layout[0], path, name)
        dist = _mat(fs, layout[1], path, name, required=False)
        dist = np.zeros(0) if dist is None else dist.reshape(-1)
        notes = []
        rkey, tkey = next(((r, t) for r, t in POSE_KEYS if not fs.getNode(r).empty()), POSE_KEYS[0])
        has_pose = layout is COURSE and not fs.getNode(rkey).empty()
        if has_pose:
            R, rounded = _rotation(_mat(fs, rkey, path, name), path, name, rkey)
            t = _mat(fs, tkey, path, name)
            if rounded:
                notes.append(f"camera {name!r}: Rotation re-orthonormalised (written with few decimals)")
        else:
            R, t = np.eye(3), np.zeros(3)
            what = "OpenCV calibration sample output" if layout is SAMPLE else "no Rotation/Translation"
            notes.append(f"camera {name!r}: intrinsics only ({what}): R = I, t = 0 — the camera's pose is "
                         "not in the file; calibrate the extrinsics")
        w, h = (_mat(fs, k, path, name, required=False) for k in ("image_width", "image_height"))
        if w is not None and h is not None:
            size = (float(w), float(h))
        else:
            found = _media_size(path.parent)
            if found is not None:
                size = found[0]
                notes.append(f"camera {name!r}: image size {size[0]}x{size[1]} from {found[1]} beside the file")
            else:
                size = size_from_principal_point(K, path, name, layout[0])
                notes.append(f"warning: camera {name!r}: no image size in the file and no video or image beside "
                             f"it: guessed {size[0]}x{size[1]} from the principal point (2 c + 1)")
        try:
            cam = Camera(name, K, dist, R, t, size)
        except CalibrationError as exc:
            keys = {"K": layout[0], "dist": layout[1], "R": rkey, "t": tkey,
                    "size": "image_width/image_height"}
            raise CalibrationError(exc.detail, file=path, camera=name, field=keys.get(exc.field, exc.field)) from None
        return cam, notes, has_pose
    finally:
        fs.release()


def read_camera_pairs(pairs: dict[str, Path]) -> RigParts:
    """``{camera name: file}`` → :class:`RigParts` (rig order = the pairs' order)."""
    cameras, notes, posed = {}, [], []
    for name, path in pairs.items():
        if not name:
            raise CalibrationError("empty camera name in a NAME=FILE pair", file=path, field="name")
        cam, cam_notes, has_pose = read_camera_file(Path(path), name)
        cameras[name] = cam
        notes += cam_notes
        posed.append(has_pose)
    if any(posed) and not all(posed):
        missing = [n for n, p in zip(cameras, posed) if not p]
        raise CalibrationError(f"camera(s) {', '.join(missing)} have no Rotation/Translation while the others do: "
                               "expected every camera posed in the same world", file=pairs[missing[0]])
    return RigParts(cameras, GroundPlane.floor(), {"source": "opencv per-camera files"},
                    units="m", units_fixed=False, notes=tuple(notes))


def read_opencv_camera(path) -> RigParts:
    """A folder of ``<camera>/config.xml`` (or ``.yml``) files, or one per-camera file."""
    path = Path(path)
    if path.is_dir():
        pairs = {}
        for sub in sorted(p for p in path.iterdir() if p.is_dir()):
            for candidate in ("config.xml", "config.yml", "config.yaml"):
                if (sub / candidate).is_file():
                    pairs[sub.name] = sub / candidate
                    break
        if not pairs:
            raise CalibrationError("no <camera>/config.xml sub-folders", file=path)
        return _board_hint(read_camera_pairs(pairs), path / "checkerboard.xml")
    return read_camera_pairs({_name_of(path): path})


def _board_hint(parts: RigParts, board: Path) -> RigParts:
    """The course's ``checkerboard.xml`` beside the camera folders gives the board's square size
    in the translations' unit: a size over 5 cannot be metres, so the usual unit is mm."""
    if not board.is_file():
        return parts
    fs = _open_storage(board)
    try:
        node = fs.getNode("CheckerBoardSquareSize")
        size = node.real() if not node.empty() and (node.isReal() or node.isInt()) else None
    finally:
        fs.release()
    if size is None or size <= 0:
        return parts
    unit = "mm" if size > 5 else "m"
    return parts._replace(units=unit, notes=parts.notes + (
        f"{board.name}: board squares of {size:g} in the translations' unit, so {unit} is expected",))


def write_opencv_camera(rig, path) -> Path:
    """A folder ``<camera>/config.xml`` per camera (the course layout: Rodrigues ``Rotation``,
    ``Translation`` in **millimetres**, as the course tools expect), plus ``image_width`` and
    ``image_height`` (read back by this module; other readers ignore them)."""
    import cv2

    path = Path(path)
    for name, cam in rig.cameras.items():
        if not name or any(c in name for c in "/\\") or name in (".", ".."):
            raise CalibrationError("camera names must be plain folder names", file=path, camera=name, field="name")
        if cam.model != "pinhole":
            raise CalibrationError("the per-camera OpenCV layout has no fisheye model", file=path, camera=name,
                                   field="model")
        with atomic_path(path / name / "config.xml", mkdir=True) as tmp:
            fs = cv2.FileStorage(str(tmp), cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_FORMAT_XML)
            fs.write("CameraMatrix", cam.K)
            fs.write("DistortionCoeffs", (cam.dist if cam.dist.size else np.zeros(5)).reshape(1, -1))
            fs.write("Rotation", cam.rvec.reshape(3, 1))
            fs.write("Translation", (cam.t * 1000.0).reshape(3, 1))
            fs.write("image_width", int(cam.width))
            fs.write("image_height", int(cam.height))
            fs.release()
    return path
