"""Rig descriptions: every numeric field finite and in range, no silently merged cameras, and
errors that name the file and the field (defects 2, 4, 12, 15 of the hardening issue)."""

from __future__ import annotations

import pytest

from rigs import RigDescription, RigError

BASE = """format: studio.rig
version: 1
frame_rate: {fps}
cameras:
  cam0: {{backend: simulated, gain: {gain}, width: {width}}}
  {second}: {{backend: simulated}}
"""


def _write(tmp_path, fps="60", gain="0", width="640", second="cam1", text=None):
    p = tmp_path / "rig.yaml"
    if text is None:
        text = BASE.format(fps=fps, gain=gain, width=width, second=second)
    p.write_bytes(text.encode() if isinstance(text, str) else text)
    return p


def test_a_valid_description_loads(tmp_path):
    d = RigDescription.load(_write(tmp_path))
    assert d.camera_names == ["cam0", "cam1"] and d.frame_rate == 60.0 and d.cameras["cam0"].width == 640


def test_two_cameras_of_the_same_name_are_refused(tmp_path):
    """PyYAML kept the last 'cam0' and dropped the first without a word."""
    with pytest.raises(RigError, match=r"rig\.yaml: not valid YAML .*key 'cam0' appears twice \(lines 5 and 6\)"):
        RigDescription.load(_write(tmp_path, second="cam0"))


@pytest.mark.parametrize("fields, message", [
    ({"gain": ".nan"}, r"field 'cameras.cam0.gain': expected a finite number, got nan"),
    ({"gain": "100"}, r"field 'cameras.cam0.gain': expected a number between -20.0 and 60.0, got 100"),
    ({"fps": ".nan"}, r"field 'frame_rate': expected a finite number, got nan"),
    ({"fps": ".inf"}, r"field 'frame_rate': expected a finite number, got inf"),
    ({"fps": "1.0e+9"}, r"field 'frame_rate': expected a number between 0.001 and 100000.0"),
    ({"width": "true"}, r"field 'cameras.cam0.width': expected a positive integer, got True"),
])
def test_numeric_fields_are_finite_and_in_range(tmp_path, fields, message):
    with pytest.raises(RigError, match=rf"rig description .*rig\.yaml: {message}"):
        RigDescription.load(_write(tmp_path, **fields))


def test_non_utf8_and_deeply_nested_files(tmp_path):
    with pytest.raises(RigError, match=r"rig\.yaml: not UTF-8 text \(byte 8\)"):
        RigDescription.load(_write(tmp_path, text=b"format: \xff\xfe\n"))
    with pytest.raises(RigError, match=r"rig\.yaml: nested too deeply to be a rig description"):
        RigDescription.load(_write(tmp_path, text="cameras: " + "[" * 50_000 + "]" * 50_000 + "\n"))
