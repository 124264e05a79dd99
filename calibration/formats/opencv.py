"""OpenCV FileStorage YAML as EasyMocap's ``intri.yml`` + ``extri.yml``.

``intri.yml``::

    names: [ "cam0", "cam1" ]           # a sequence of camera names, rig order
    K_cam0: !!opencv-matrix 3x3
    dist_cam0: !!opencv-matrix 1xn     # OpenCV order
    H_cam0: 480                        # image height (optional in EasyMocap files)
    W_cam0: 640                        # image width
    model_cam0: "pinhole"              # studio extension: "pinhole" or "fisheye"

``extri.yml``::

    names: [ ... ]
    R_cam0: !!opencv-matrix 3x1        # Rodrigues vector, world -> camera
    Rot_cam0: !!opencv-matrix 3x3      # the same rotation as a matrix
    T_cam0: !!opencv-matrix 3x1        # metres, X_c = R X_w + t
    ground_normal, ground_offset       # studio extension (default floor z = 0)
    studio_metadata: "<json>"          # studio extension

Lens model: EasyMocap's files carry none (its code chooses ``cv2.fisheye`` by hand and reads
``D_<cam>`` only as a fallback name for the coefficients). We write ``model_<cam>`` for every
camera; when absent the camera is pinhole. A fisheye camera's ``dist_<cam>`` is its 1x4
``k1 k2 k3 k4`` (readers unaware of ``model_`` would take them for ``k1 k2 p1 p2``).
``D_<cam>`` is read when ``dist_<cam>`` is absent, as EasyMocap does.

``Rot_`` is read when present (and must agree with ``R_`` to ``ROUNDING_TOL``), else ``R_``.
Files written with few decimals (EasyMocap's own writer keeps 6) hold a ``Rot_`` that is not
orthonormal to the toolkit's 1e-6: within ``ROUNDING_TOL`` (1e-4) the rotation is taken from
``R_`` (a Rodrigues vector is a rotation at any precision) or, without ``R_``, re-orthonormalised
(SVD, :func:`calibration.rotation.nearest_rotation`), and a note says so; beyond it the file
is refused. Files without
``H_``/``W_`` get the image size guessed from the principal point (``2 c + 1``), with a
warning and the camera names listed in ``metadata["size_guessed"]``.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np

from calibration.camera import Camera
from calibration.rotation import nearest_rotation, rotvec_to_matrix
from calibration.errors import CalibrationError
from calibration.formats import RigParts
from rigs.atomic import atomic_path
from calibration.ground import GroundPlane

log = logging.getLogger(__name__)

#: Largest difference between ``Rot_`` and ``R_``, and largest ``max |R Rᵀ - I|`` of ``Rot_``,
#: put down to rounding (6 decimals give ~1e-6); beyond it the file is refused.
ROUNDING_TOL = 1e-4
#: Orthonormality the toolkit requires of a rotation read as is (``Camera.ORTHONORMAL_TOL``).
EXACT_TOL = 1e-6


def _paths(intri_path, extri_path) -> tuple[Path, Path]:
    intri = Path(intri_path)
    if extri_path is None:
        if intri.suffix.lower() in (".yml", ".yaml"):
            return intri, intri.with_name(intri.name.replace("intri", "extri"))
        return intri / "intri.yml", intri / "extri.yml"
    return intri, Path(extri_path)


#: Deepest flow nesting (``[[[...``) accepted: OpenCV's parser recurses and crashes the
#: process (a segmentation fault, not an exception) on very deep input.
MAX_NESTING = 64
#: Largest calibration file read (bytes).
MAX_BYTES = 64 << 20


def _check_text(path: Path) -> None:
    """Refuse what would crash or choke OpenCV's parser, naming the file: oversized files, non-UTF-8
    text, flow collections nested deeper than ``MAX_NESTING``."""
    size = path.stat().st_size
    if size > MAX_BYTES:
        raise CalibrationError(f"{size} bytes: larger than any calibration ({MAX_BYTES} bytes at most)", file=path)
    data = path.read_bytes()
    try:
        data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise CalibrationError(f"not UTF-8 text (byte {exc.start}): expected a UTF-8 YAML/XML file", file=path) from None
    depth = deepest = 0
    for ch in _brackets(data):
        depth += 1 if ch in b"[{" else -1
        deepest = max(deepest, depth)
        if deepest > MAX_NESTING:
            raise CalibrationError(f"nested more than {MAX_NESTING} levels deep: not a calibration", file=path)


def _brackets(data: bytes) -> bytes:
    """Only the bracket bytes of ``data`` (a C-speed filter: ``bytes.translate`` deletes the rest)."""
    return data.translate(None, _NOT_BRACKETS)


_NOT_BRACKETS = bytes(b for b in range(256) if b not in b"[]{}")


def _open(path: Path):
    import cv2

    if not path.is_file():
        raise CalibrationError("no such file", file=path)
    _check_text(path)
    return open_storage(str(path), cv2.FILE_STORAGE_READ, path)


def open_storage(source: str, flags: int, path: Path):
    """``cv2.FileStorage(source, flags)``, opened, or an error naming ``path`` with OpenCV's reason."""
    import cv2

    try:
        fs = cv2.FileStorage(source, flags)
        opened = fs.isOpened()
    except (cv2.error, SystemError) as exc:  # the binding may wrap cv2.error in SystemError
        opened, reason = False, str(getattr(exc, "err", None) or exc.__cause__ or exc)
    else:
        reason = "unknown layout"
    if not opened:
        raise CalibrationError(f"not an OpenCV FileStorage file ({reason})", file=path)
    return fs


def _names(fs, path: Path) -> list[str]:
    node = fs.getNode("names")
    if node.empty() or node.isNone():
        single = next((k for k in ("camera_matrix", "CameraMatrix") if not fs.getNode(k).empty()), None)
        if single:
            raise CalibrationError(f"missing: this is a single-camera OpenCV file ({single}), not EasyMocap's "
                                   "intri.yml: read it as format opencv_camera (load_any detects it)",
                                   file=path, field="names")
        raise CalibrationError("missing", file=path, field="names")
    names = []
    for i in range(node.size()):
        item = node.at(i)
        if item.isString():
            names.append(item.string())
        elif item.isInt():
            names.append(str(int(item.real())))
        else:
            names.append(f"{item.real():g}")
    if not names:
        raise CalibrationError("empty camera list", file=path, field="names")
    for i, n in enumerate(names):
        if names.index(n) != i:
            raise CalibrationError(f"camera {n!r} is listed twice (entries {names.index(n)} and {i}): "
                                   "expected unique names", file=path, field="names")
    return names


def _is_number(node) -> bool:
    return node.isReal() or node.isInt()


def _check_numbers(node, path: Path, camera: str, key: str) -> None:
    """Every element of a matrix node is a number (OpenCV reads text as 1.8e308 or 0)."""
    data = node.getNode("data") if node.isMap() else node
    items = [data.at(i) for i in range(data.size())] if data.isSeq() else [data]
    for i, item in enumerate(items):
        if not _is_number(item):
            shown = item.string() if item.isString() else ("a mapping" if item.isMap() else "not a number")
            raise CalibrationError(f"element {i} is {shown!r}: expected a number", file=path, camera=camera,
                                   field=key)


def _mat(fs, key: str, path: Path, camera: str, required: bool = True):
    node = fs.getNode(key)
    if node.empty() or node.isNone():
        if required:
            raise CalibrationError("missing", file=path, camera=camera, field=key)
        return None
    _check_numbers(node, path, camera, key)
    if node.isMap() or node.isSeq():
        import cv2

        try:
            m = node.mat()
        except cv2.error:
            m = None
        if m is None:
            raise CalibrationError("not an OpenCV matrix", file=path, camera=camera, field=key)
        return np.asarray(m, dtype=np.float64)
    return np.array(node.real(), dtype=np.float64)


def _model(fs, name: str, path: Path) -> str:
    """``model_<name>``: ``"pinhole"`` when absent."""
    node = fs.getNode(f"model_{name}")
    if node.empty() or node.isNone():
        return "pinhole"
    if not node.isString():
        raise CalibrationError(
            "expected a string, 'pinhole' or 'fisheye'", file=path, camera=name, field=f"model_{name}"
        )
    return node.string()


def read_opencv(intri_path, extri_path=None):
    intri_p, extri_p = _paths(intri_path, extri_path)
    fi, fe = _open(intri_p), _open(extri_p)
    try:
        names = _names(fi, intri_p)
        enames = _names(fe, extri_p) if not fe.getNode("names").empty() else names
        missing = [n for n in names if n not in enames]
        if missing:
            raise CalibrationError(
                "listed in intri but not in extri", file=extri_p, camera=missing[0], field="names"
            )
        cameras = {}
        guessed, rounded = [], []
        for name in names:
            K = _mat(fi, f"K_{name}", intri_p, name)
            dist = _mat(fi, f"dist_{name}", intri_p, name, required=False)
            if dist is None:
                dist = _mat(fi, f"D_{name}", intri_p, name, required=False)
            dist = np.zeros(0) if dist is None else dist.reshape(-1)
            model = _model(fi, name, intri_p)
            H = _mat(fi, f"H_{name}", intri_p, name, required=False)
            W = _mat(fi, f"W_{name}", intri_p, name, required=False)
            if H is None or W is None:
                size = size_from_principal_point(K, intri_p, name, f"K_{name}")
                guessed.append(name)
            else:
                size = (float(W), float(H))
            Rot = _mat(fe, f"Rot_{name}", extri_p, name, required=False)
            rvec = _mat(fe, f"R_{name}", extri_p, name, required=False)
            if Rot is None and rvec is None:
                raise CalibrationError(
                    f"missing (neither Rot_{name} nor R_{name})", file=extri_p, camera=name, field=f"R_{name}"
                )
            if rvec is not None and rvec.size == 9 and Rot is None:
                Rot = rvec.reshape(3, 3)  # some writers put the matrix under R_
                rvec = None
            if rvec is not None and rvec.size != 3:
                raise CalibrationError(
                    f"expected a 3x1 Rodrigues vector, got shape {rvec.shape}",
                    file=extri_p, camera=name, field=f"R_{name}",
                )
            Rot, note = _rotation(Rot, rvec, extri_p, name)
            if note:
                rounded.append(name)
            T = _mat(fe, f"T_{name}", extri_p, name)
            try:
                cameras[name] = Camera(name, K, dist, Rot, T, size, model)
            except CalibrationError as exc:
                fld = exc.field
                src = intri_p if fld in ("K", "dist", "size", "model") else extri_p
                key = {"K": f"K_{name}", "dist": f"dist_{name}", "R": f"Rot_{name}", "t": f"T_{name}",
                       "size": f"W_{name}/H_{name}", "model": f"model_{name}"}.get(fld, fld)
                raise CalibrationError(exc.detail, file=src, camera=name, field=key) from None
        ground = GroundPlane.floor()
        gn = _mat(fe, "ground_normal", extri_p, None, required=False)
        if gn is not None:
            go = _mat(fe, "ground_offset", extri_p, None)
            try:
                ground = GroundPlane(gn.reshape(-1), float(go))
            except CalibrationError as exc:
                raise exc.in_file(extri_p) from None
        meta = {}
        node = fe.getNode("studio_metadata")
        if not node.empty():
            try:
                meta = json.loads(node.string())
            except json.JSONDecodeError as exc:
                raise CalibrationError(f"not JSON ({exc})", file=extri_p, field="studio_metadata") from None
        notes = ["units: EasyMocap's documentation asks for metres"]
        if rounded:
            notes.append(f"rotations of {', '.join(rounded)} written with few decimals (not orthonormal to "
                         f"{EXACT_TOL:g}, within {ROUNDING_TOL:g}): taken from R_ (Rodrigues) or the nearest rotation (SVD)")
        if guessed:
            notes.append(f"warning: no H_/W_ image size for {', '.join(guessed)}: guessed from the principal point "
                         "(2 c + 1)")
            log.warning(
                "%s: no H_/W_ image size for %s; guessed from the principal point",
                intri_p,
                ", ".join(guessed),
            )
            meta["size_guessed"] = guessed
        own = not fe.getNode("ground_normal").empty()
        return RigParts(cameras, ground, meta, units="m", units_fixed=False, own_frame=own, notes=tuple(notes))
    finally:
        fi.release()
        fe.release()


def size_from_principal_point(K: np.ndarray, path: Path, camera: str, key: str) -> tuple[int, int]:
    """The image size a centred principal point implies, ``(2 cx + 1, 2 cy + 1)`` rounded (pixel
    centres at integers: an image of ``w`` pixels has its centre at ``(w - 1) / 2``); the guess of
    files that do not state the size. ``K`` must be 3x3 (the error names ``key``)."""
    if K.shape != (3, 3):
        raise CalibrationError(f"expected shape (3, 3), got {K.shape}", file=path, camera=camera, field=key)
    return int(round(2 * K[0, 2] + 1)), int(round(2 * K[1, 2] + 1))


def _rotation(Rot, rvec, path: Path, name: str) -> tuple[np.ndarray, bool]:
    """The camera's rotation from ``Rot_`` (3x3) and/or ``R_`` (Rodrigues); True when rounding
    had to be undone (see the module docstring)."""
    if Rot is None:
        return rotvec_to_matrix(rvec.reshape(3)), False
    if Rot.shape != (3, 3) or not np.all(np.isfinite(Rot)):
        return Rot, False  # Camera names the shape or the NaN
    from_rvec = None
    if rvec is not None and np.all(np.isfinite(rvec)):
        from_rvec = rotvec_to_matrix(rvec.reshape(3))
        gap = float(np.max(np.abs(from_rvec - Rot)))
        if gap > ROUNDING_TOL:
            raise CalibrationError(f"disagrees with R_{name} (max difference {gap:.3g} > {ROUNDING_TOL:g})",
                                   file=path, camera=name, field=f"Rot_{name}")
    nearest, err = nearest_rotation(Rot)
    if err <= EXACT_TOL or np.linalg.det(Rot) < 0:
        return Rot, False  # exact enough, or a reflection Camera refuses by name
    if err > ROUNDING_TOL:
        raise CalibrationError(f"not a rotation: max |R Rᵀ - I| = {err:.3g}, more than rounding to few decimals "
                               f"explains ({ROUNDING_TOL:g})", file=path, camera=name, field=f"Rot_{name}")
    return (nearest if from_rvec is None else from_rvec), True


def _write_names(fs, names):
    import cv2

    fs.startWriteStruct("names", cv2.FileNode_SEQ)
    for n in names:
        fs.write("", n)
    fs.endWriteStruct()


def _fix_header(path: Path) -> None:
    """EasyMocap and OpenCV 4 expect ``%YAML:1.0``; OpenCV 5 writes ``%YAML 1.2``."""
    text = path.read_text()
    if text.startswith("%YAML 1.2"):
        path.write_text("%YAML:1.0" + text[len("%YAML 1.2"):])


def write_opencv(rig, intri_path, extri_path=None) -> tuple[Path, Path]:
    import cv2

    intri_p, extri_p = _paths(intri_path, extri_path)
    for name in rig.camera_names:
        bad = [c for c in name if c.isspace() or c in ":{}[],#&*!|>'\"%@`"]
        if bad or not name:
            raise CalibrationError(
                "camera names must be plain words to form FileStorage keys like K_<name>",
                file=intri_p, camera=name, field="name",
            )
    with atomic_path(intri_p, mkdir=True) as tmp:
        fs = cv2.FileStorage(str(tmp), cv2.FILE_STORAGE_WRITE)
        _write_names(fs, rig.camera_names)
        for name, cam in rig.cameras.items():
            fs.write(f"K_{name}", cam.K)
            fs.write(f"dist_{name}", cam.dist.reshape(1, -1) if cam.dist.size else np.zeros((1, 5)))
            fs.write(f"H_{name}", int(cam.height))
            fs.write(f"W_{name}", int(cam.width))
            fs.write(f"model_{name}", cam.model)
        fs.release()
        _fix_header(tmp)
    with atomic_path(extri_p, mkdir=True) as tmp:
        fs = cv2.FileStorage(str(tmp), cv2.FILE_STORAGE_WRITE)
        _write_names(fs, rig.camera_names)
        for name, cam in rig.cameras.items():
            fs.write(f"R_{name}", cam.rvec.reshape(3, 1))
            fs.write(f"Rot_{name}", cam.R)
            fs.write(f"T_{name}", cam.t.reshape(3, 1))
        fs.write("ground_normal", rig.ground.normal.reshape(3, 1))
        fs.write("ground_offset", float(rig.ground.offset))
        fs.write("studio_metadata", json.dumps(rig.metadata))
        fs.release()
        _fix_header(tmp)
    return intri_p, extri_p
