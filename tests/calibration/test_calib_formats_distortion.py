"""Distortion coefficients of the real files in ``../shared/data/calibration/interop``, read back
field by field with an independent parser (tomllib, PyYAML, ``cv2.FileStorage``, ElementTree).

The MANIFEST's reference covers focal lengths and centres only, so an importer that swapped
p1 and p2 (or k2 and k3) passed every other test. Each file here has non-zero tangential terms.
"""

from __future__ import annotations

import tomllib
import xml.etree.ElementTree as ET

import cv2
import numpy as np
import pytest
import yaml

from calibration import RigCalibration


def _rig_dists(path) -> list[np.ndarray]:
    rig = RigCalibration.load_any(path)
    return sorted((np.asarray(c.dist, float) for c in rig), key=lambda d: tuple(d))


def _assert_same(read, expected, what):
    """The rig's coefficient vectors equal the file's (each padded to the file's length)."""
    expected = sorted((np.asarray(e, float) for e in expected), key=lambda d: tuple(d))
    read = sorted((d[: max(len(e) for e in expected)] for d in read), key=lambda d: tuple(d))
    assert len(read) == len(expected), what
    for r, e in zip(read, expected):
        np.testing.assert_allclose(r, e, rtol=0, atol=1e-12, err_msg=what)


@pytest.mark.parametrize("name", ["caliscope/4_cam_recording/camera_array.toml",
                                  "caliscope/base_data/camera_array.toml",
                                  "pose2sim/sarkadava_trial_0/Calib_checkerboard.toml"])
def test_toml_distortions_in_file_order(shared_data, name):
    path = shared_data / "calibration/interop" / name
    data = tomllib.loads(path.read_text())
    sections = data["cameras"].values() if "cameras" in data else [v for v in data.values() if "distortions" in v]
    expected = [s["distortions"] for s in sections if not s.get("ignore", False)]
    assert any(abs(d[2]) > 1e-4 and abs(d[3]) > 1e-4 for d in expected)  # p1, p2 both set: a swap shows
    _assert_same(_rig_dists(path), expected, name)


def test_kalibr_radtan_distortion_coeffs(shared_data):
    path = shared_data / "calibration/interop/kalibr/openvins_zed_mini/camchain-imucam-1107_raw.yaml"
    text = path.read_text()
    data = yaml.safe_load(text.split("\n", 1)[1] if text.startswith("%YAML:1.0") else text)  # OpenCV's header
    expected = [cam["distortion_coeffs"] for cam in data.values()]
    assert all(cam["distortion_model"] == "radtan" for cam in data.values())
    _assert_same(_rig_dists(path), expected, path.name)


@pytest.mark.parametrize("name", ["opencv_calibrate/opencv_samples_left/left_intrinsics.yml",
                                  "opencv_calibrate/opencv_aruco_tutorial/tutorial_camera_charuco.yml"])
def test_opencv_filestorage_distortion(shared_data, name):
    path = shared_data / "calibration/interop" / name
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    expected = fs.getNode("distortion_coefficients").mat().ravel()
    fs.release()
    _assert_same(_rig_dists(path), [expected], name)


def test_opencv_xml_per_camera_distortion(shared_data):
    folder = shared_data / "calibration/interop/opencv_xml_course/uu_infomcv_cv2021a2/data"
    expected = []
    for cam in sorted(folder.glob("cam*")):
        fs = cv2.FileStorage(str(cam / "intrinsics.xml"), cv2.FILE_STORAGE_READ)
        expected.append(fs.getNode("DistortionCoeffs").mat().ravel().astype(float))
        fs.release()
    read = _rig_dists(folder)
    # the file stores float32: the toolkit keeps the same numbers
    _assert_same([d.astype(np.float32).astype(float) for d in read], expected, folder.name)


def test_optitrack_tangential_x_is_p1(shared_data):
    """Motive's ``TangentialX/Y`` → OpenCV ``p1 p2`` and ``k1 k2 k3`` → ``k1 k2 k3`` (dist[4])."""
    path = shared_data / "calibration/interop/optitrack_mcal/kechuan_multical/optitrack.mcal"
    text = path.read_bytes().decode("utf-16")
    root = ET.fromstring(text.split("?>", 1)[1])
    expected = []
    for cam in root.iter("Camera"):
        props = cam.find("Properties")
        if props is not None and props.get("Enabled", "1") == "0":
            continue
        m = cam.find("IntrinsicStandardCameraModel")
        expected.append([float(m.get(k)) for k in ("k1", "k2", "TangentialX", "TangentialY", "k3")])
    assert all(abs(e[2] - e[3]) > 1e-5 for e in expected)
    _assert_same(_rig_dists(path), expected, path.name)
