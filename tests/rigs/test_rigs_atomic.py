"""The one atomic writer: unique temporary names, all-or-nothing, errors name the file."""

from __future__ import annotations

import errno
import threading

import numpy as np
import pytest

from rigs.atomic import (atomic_open, atomic_path, atomic_write_bytes, atomic_write_json, is_temporary,
                         remove_temporaries)


def test_concurrent_writers_never_mix_one_file(tmp_path):
    """Eight threads write 1 MB payloads of their own byte to the same name, many times: the file
    always holds exactly one writer's payload, and no temporary file is left."""
    target = tmp_path / "mesh.ply"
    size = 1 << 20

    def write(k):
        for _ in range(5):
            atomic_write_bytes(target, bytes([k]) * size, fsync=False)

    threads = [threading.Thread(target=write, args=(k,)) for k in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    data = np.frombuffer(target.read_bytes(), np.uint8)
    assert data.size == size and np.all(data == data[0]) and 0 <= data[0] < 8
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mesh.ply"]


def test_temporary_names_are_unique_and_recognised(tmp_path):
    names = set()
    for _ in range(50):
        with atomic_path(tmp_path / "a.png", fsync=False) as tmp:
            assert tmp.suffix == ".png" and is_temporary(tmp) and tmp.parent == tmp_path
            names.add(tmp.name)
            tmp.write_bytes(b"x")
    assert len(names) == 50
    assert not is_temporary("a.png") and not is_temporary(".hidden")


def test_error_inside_block_keeps_the_old_file(tmp_path):
    target = tmp_path / "calibration.json"
    atomic_write_json(target, {"version": 1})
    with pytest.raises(RuntimeError, match="boom"):
        with atomic_open(target, "w") as f:
            f.write('{"version": 2, "trunc')
            raise RuntimeError("boom")
    assert target.read_text() == '{\n  "version": 1\n}\n'
    assert [p.name for p in tmp_path.iterdir()] == ["calibration.json"]


def test_missing_folder_error_names_the_destination(tmp_path):
    target = tmp_path / "nope" / "x.json"
    with pytest.raises(OSError, match=r"nope/x\.json") as info:
        atomic_write_bytes(target, b"{}")
    assert info.value.errno == errno.ENOENT
    atomic_write_bytes(target, b"{}", mkdir=True)
    assert target.read_bytes() == b"{}"


def test_json_refuses_nan_and_bad_mode(tmp_path):
    with pytest.raises(ValueError, match="Out of range float"):
        atomic_write_json(tmp_path / "x.json", {"fx": float("nan")})
    assert not (tmp_path / "x.json").exists() and list(tmp_path.iterdir()) == []
    with pytest.raises(ValueError, match="mode must be 'w' or 'wb'"):
        with atomic_open(tmp_path / "y", "a"):
            pass


def test_remove_temporaries_clears_only_leftovers(tmp_path):
    (tmp_path / "000001.png").write_bytes(b"keep")
    (tmp_path / ".000002.png.tmp-abc123.png").write_bytes(b"torn")
    removed = remove_temporaries(tmp_path)
    assert [p.name for p in removed] == [".000002.png.tmp-abc123.png"]
    assert [p.name for p in tmp_path.iterdir()] == ["000001.png"]


def test_remove_temporaries_recursive_reaches_sub_folders(tmp_path):
    deep = tmp_path / "overlay" / "cam0"
    deep.mkdir(parents=True)
    (deep / "000001.png").write_bytes(b"keep")
    (deep / ".000002.png.tmp-x1.png").write_bytes(b"torn")
    (tmp_path / ".sequence.json.tmp-y2.json").write_bytes(b"torn")
    assert remove_temporaries(tmp_path) == [tmp_path / ".sequence.json.tmp-y2.json"]  # not below by default
    (tmp_path / ".sequence.json.tmp-y2.json").write_bytes(b"torn")
    removed = remove_temporaries(tmp_path, recursive=True)
    assert sorted(p.name for p in removed) == [".000002.png.tmp-x1.png", ".sequence.json.tmp-y2.json"]
    assert sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*") if p.is_file()) == [
        "overlay/cam0/000001.png"]
