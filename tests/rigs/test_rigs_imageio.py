"""rigs.imageio: PNG/EXR round trips, RGB order on disk, atomic writes, clear errors."""

from __future__ import annotations

import errno
import json
from pathlib import Path

import cv2
import numpy as np

import rigs.atomic
import OpenEXR
import pytest

from rigs import imageio
from rigs.imageio import (
    ImageIOError,
    atomic_write_bytes,
    atomic_write_json,
    atomic_write_text,
    check_image_file,
    image_info,
    read_image,
    write_image,
)

RNG = np.random.default_rng(7)


def _int_image(dtype, channels, h=5, w=7):
    shape = (h, w) if channels == 1 else (h, w, channels)
    return RNG.integers(0, np.iinfo(dtype).max, shape, endpoint=True).astype(dtype)


def _no_temp_files(folder: Path) -> bool:
    return not [p for p in folder.iterdir() if p.name.startswith(".")]


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
@pytest.mark.parametrize("channels", [1, 3, 4])
@pytest.mark.parametrize("compression", [0, 1, 9])
def test_png_round_trip_is_exact(tmp_path, dtype, channels, compression):
    image = _int_image(dtype, channels)
    path = write_image(tmp_path / "a.png", image, compression=compression)
    back = read_image(path)
    assert back.dtype == dtype and back.shape == image.shape
    np.testing.assert_array_equal(back, image)
    info = image_info(path)
    assert (info.width, info.height, info.channels, info.dtype) == (7, 5, channels, np.dtype(dtype).name)
    assert info.shape == image.shape
    assert check_image_file(path) is None
    assert _no_temp_files(tmp_path)


@pytest.mark.parametrize("dtype", [np.float32, np.float16])
@pytest.mark.parametrize("channels", [1, 2, 3, 4])
def test_exr_round_trip_is_exact_and_reads_float32(tmp_path, dtype, channels):
    shape = (6, 9) if channels == 1 else (6, 9, channels)
    image = (RNG.standard_normal(shape) * 100).astype(dtype)
    path = write_image(tmp_path / "a.exr", image, fsync=True)
    back = read_image(path)
    assert back.dtype == np.float32 and back.shape == image.shape
    np.testing.assert_array_equal(back, image.astype(np.float32))
    assert image_info(path) == imageio.ImageInfo(9, 6, channels, "float32")
    assert check_image_file(path) is None
    assert _no_temp_files(tmp_path)


def test_single_channel_3d_array_is_stored_as_gray(tmp_path):
    image = _int_image(np.uint8, 1)[:, :, None]
    back = read_image(write_image(tmp_path / "g.png", image))
    np.testing.assert_array_equal(back, image[:, :, 0])


def test_rgb_order_is_kept_on_disk(tmp_path):
    """A red RGB image must be red for any other PNG reader (OpenCV reads it as BGR)."""
    image = np.zeros((4, 4, 3), np.uint8)
    image[..., 0] = 255  # red
    write_image(tmp_path / "red.png", image)
    bgr = cv2.imread(str(tmp_path / "red.png"), cv2.IMREAD_UNCHANGED)
    assert bgr[0, 0].tolist() == [0, 0, 255]
    rgba = np.zeros((4, 4, 4), np.uint8)
    rgba[..., 0] = 200
    rgba[..., 3] = 17
    write_image(tmp_path / "rgba.png", rgba)
    bgra = cv2.imread(str(tmp_path / "rgba.png"), cv2.IMREAD_UNCHANGED)
    assert bgra[0, 0].tolist() == [0, 0, 200, 17]


def test_exr_channels_are_named_rgb(tmp_path):
    image = np.stack([np.full((3, 3), v, np.float32) for v in (1.0, 2.0, 3.0)], axis=-1)
    write_image(tmp_path / "c.exr", image)
    with OpenEXR.File(str(tmp_path / "c.exr"), separate_channels=True) as exr:
        channels = {name: float(ch.pixels[0, 0]) for name, ch in exr.channels().items()}
    assert channels == {"R": 1.0, "G": 2.0, "B": 3.0}


def test_foreign_exr_channel_names(tmp_path):
    z = np.arange(12, dtype=np.float32).reshape(3, 4)
    with OpenEXR.File({}, {"Z": z}) as exr:
        exr.write(str(tmp_path / "z.exr"))
    np.testing.assert_array_equal(read_image(tmp_path / "z.exr"), z)
    with OpenEXR.File({}, {"V": z + 100, "U": z}) as exr:
        exr.write(str(tmp_path / "uv.exr"))
    uv = read_image(tmp_path / "uv.exr")
    np.testing.assert_array_equal(uv, np.stack([z, z + 100], axis=-1))  # alphabetical: U, V


def test_bool_mask_is_written_as_0_255(tmp_path):
    mask = RNG.random((5, 6)) > 0.5
    back = read_image(write_image(tmp_path / "m.png", mask))
    assert back.dtype == np.uint8
    np.testing.assert_array_equal(back, mask.astype(np.uint8) * 255)
    np.testing.assert_array_equal(back > 0, mask)


def test_write_replaces_existing_file_atomically(tmp_path):
    path = tmp_path / "a.png"
    write_image(path, np.zeros((3, 3), np.uint8))
    write_image(path, np.full((3, 3), 9, np.uint8))
    np.testing.assert_array_equal(read_image(path), np.full((3, 3), 9, np.uint8))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.png"]


# --------------------------------------------------------------------------- write errors


@pytest.mark.parametrize(
    ("name", "array", "match"),
    [
        ("a.png", np.zeros((3, 3), np.float32), r"float32 image must be written to a '\.exr' file"),
        ("a.exr", np.zeros((3, 3), np.uint8), r"uint8 image must be written to a '\.png' file"),
        ("a.tif", np.zeros((3, 3), np.uint16), r"suffix '\.tif'"),
        ("a.png", np.zeros((3, 3), np.int32), r"dtype int32 is not storable"),
        ("a.exr", np.zeros((3, 3), np.float64), r"dtype float64 is not storable"),
        ("a.png", np.zeros((3, 3, 5), np.uint8), r"a\.png: image shape \(3, 3, 5\)"),
        ("a.png", np.zeros((3,), np.uint8), r"image shape \(3,\)"),
        ("a.png", np.zeros((0, 3), np.uint8), r"is empty"),
        ("a.png", np.zeros((3, 3, 2), np.uint8), r"2-channel images are only storable as EXR"),
        ("a.png", [[1, 2]], r"expected a numpy array, got list"),
    ],
)
def test_write_rejects_bad_input_naming_the_file(tmp_path, name, array, match):
    with pytest.raises(ImageIOError, match=match):
        write_image(tmp_path / name, array)
    assert list(tmp_path.iterdir()) == []


def test_write_rejects_bad_compression(tmp_path):
    with pytest.raises(ImageIOError, match=r"PNG compression 10 not in 0\.\.9"):
        write_image(tmp_path / "a.png", np.zeros((3, 3), np.uint8), compression=10)


def test_write_into_missing_folder_names_the_file(tmp_path):
    with pytest.raises(OSError, match=r"nope/a\.png") as info:
        write_image(tmp_path / "nope" / "a.png", np.zeros((3, 3), np.uint8))
    assert info.value.errno == errno.ENOENT
    with pytest.raises(OSError, match=r"nope/a\.exr") as info:
        write_image(tmp_path / "nope" / "a.exr", np.zeros((3, 3), np.float32))
    assert info.value.errno == errno.ENOENT


def test_disk_full_keeps_old_file_and_leaves_no_temp(tmp_path, monkeypatch):
    path = tmp_path / "a.png"
    write_image(path, np.full((4, 4), 3, np.uint8))
    before = path.read_bytes()

    def full(fd, data):
        import os

        os.write(fd, bytes(data)[: len(data) // 2])
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(rigs.atomic, "_write_all", full)
    with pytest.raises(OSError, match=r"No space left on device: writing .*a\.png") as info:
        write_image(path, np.full((4, 4), 5, np.uint8))
    assert info.value.errno == errno.ENOSPC
    assert path.read_bytes() == before
    assert _no_temp_files(tmp_path)


def test_exr_library_failure_is_an_oserror_naming_the_file(tmp_path, monkeypatch):
    class Broken:
        def __init__(self, *args, **kwargs):
            pass

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return False

        def write(self, filename):
            Path(filename).write_bytes(b"partial")
            raise RuntimeError("disk trouble")

    monkeypatch.setattr(OpenEXR, "File", Broken)
    with pytest.raises(OSError, match=r"OpenEXR failed \(disk trouble\): writing .*b\.exr") as info:
        write_image(tmp_path / "b.exr", np.zeros((2, 2), np.float32))
    assert info.value.errno == errno.EIO
    assert list(tmp_path.iterdir()) == []


def test_interrupt_during_write_leaves_no_temp(tmp_path, monkeypatch):
    def interrupted(fd, data):
        raise KeyboardInterrupt

    monkeypatch.setattr(rigs.atomic, "_write_all", interrupted)
    with pytest.raises(KeyboardInterrupt):
        atomic_write_bytes(tmp_path / "x.bin", b"abc")
    assert list(tmp_path.iterdir()) == []


# --------------------------------------------------------------------------- read errors


def _png_bytes(tmp_path) -> bytes:
    return write_image(tmp_path / "ok.png", _int_image(np.uint8, 3, 20, 20)).read_bytes()


def test_read_missing_file_names_it(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"image file not found: .*gone\.png"):
        read_image(tmp_path / "gone.png")
    with pytest.raises(FileNotFoundError, match=r"image file not found: .*gone\.exr"):
        read_image(tmp_path / "gone.exr")


def test_read_truncated_png(tmp_path):
    data = _png_bytes(tmp_path)
    (tmp_path / "t.png").write_bytes(data[: len(data) // 2])
    with pytest.raises(ImageIOError, match=r"t\.png is truncated: no PNG end chunk \(IEND\) after \d+ bytes"):
        read_image(tmp_path / "t.png")
    assert "truncated" in check_image_file(tmp_path / "t.png")


def test_read_empty_png(tmp_path):
    (tmp_path / "e.png").write_bytes(b"")
    with pytest.raises(ImageIOError, match=r"e\.png is empty \(0 bytes\)"):
        read_image(tmp_path / "e.png")
    assert "empty" in check_image_file(tmp_path / "e.png")


def test_read_corrupt_png_body(tmp_path):
    data = bytearray(_png_bytes(tmp_path))
    data[40:-20] = b"\x00" * (len(data) - 60)  # keep signature and IEND, destroy the data
    (tmp_path / "c.png").write_bytes(bytes(data))
    with pytest.raises(ImageIOError, match=r"c\.png is corrupt: OpenCV could not decode"):
        read_image(tmp_path / "c.png")


def test_read_not_a_png(tmp_path):
    (tmp_path / "n.png").write_bytes(b"hello world, no image here")
    with pytest.raises(ImageIOError, match=r"n\.png is not a PNG \(bad signature\)"):
        read_image(tmp_path / "n.png")
    assert "bad signature" in check_image_file(tmp_path / "n.png")


def test_read_truncated_or_empty_exr(tmp_path):
    data = write_image(tmp_path / "ok.exr", RNG.random((30, 30, 3)).astype(np.float32)).read_bytes()
    (tmp_path / "t.exr").write_bytes(data[: len(data) // 2])
    with pytest.raises(ImageIOError, match=r"t\.exr is corrupt or truncated"):
        read_image(tmp_path / "t.exr")
    (tmp_path / "e.exr").write_bytes(b"")
    with pytest.raises(ImageIOError, match=r"e\.exr is not an OpenEXR file"):
        read_image(tmp_path / "e.exr")
    (tmp_path / "x.exr").write_bytes(b"garbage!")
    assert "bad magic number" in check_image_file(tmp_path / "x.exr")


def test_read_unsupported_suffix_and_folder(tmp_path):
    (tmp_path / "a.jpg").write_bytes(b"x")
    with pytest.raises(ImageIOError, match=r"cannot read .*a\.jpg: unsupported suffix '\.jpg'"):
        read_image(tmp_path / "a.jpg")
    (tmp_path / "d.png").mkdir()
    with pytest.raises(ImageIOError, match=r"expected an image file, found a folder: .*d\.png"):
        read_image(tmp_path / "d.png")
    assert "is a folder" in check_image_file(tmp_path / "d.png")
    assert "unsupported suffix" in check_image_file(tmp_path / "a.jpg")
    assert "is missing" in check_image_file(tmp_path / "zz.png")


def test_image_info_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"image file not found: .*q\.png"):
        image_info(tmp_path / "q.png")
    (tmp_path / "h.png").write_bytes(b"\x89PNG\r\n\x1a\nshort")
    with pytest.raises(ImageIOError, match=r"h\.png is not a valid PNG \(missing or short IHDR"):
        image_info(tmp_path / "h.png")
    (tmp_path / "h.exr").write_bytes(b"not an exr at all")
    with pytest.raises(ImageIOError, match=r"h\.exr is not a readable OpenEXR file"):
        image_info(tmp_path / "h.exr")
    (tmp_path / "h.bmp").write_bytes(b"BM")
    with pytest.raises(ImageIOError, match=r"unsupported suffix '\.bmp'"):
        image_info(tmp_path / "h.bmp")


def test_image_info_unknown_png_colour_type(tmp_path):
    data = bytearray(_png_bytes(tmp_path))
    data[25] = 5  # colour type 5 does not exist
    (tmp_path / "u.png").write_bytes(bytes(data))
    with pytest.raises(ImageIOError, match=r"u\.png: unknown PNG colour type 5"):
        image_info(tmp_path / "u.png")


def test_image_suffix():
    assert imageio.image_suffix(np.zeros(1, np.bool_)) == ".png"
    assert imageio.image_suffix(np.zeros(1, np.float16)) == ".exr"
    with pytest.raises(ImageIOError, match=r"dtype complex128 is not storable"):
        imageio.image_suffix(np.zeros(1, np.complex128))


# --------------------------------------------------------------------------- atomic text/json


def test_atomic_text_and_json(tmp_path):
    atomic_write_text(tmp_path / "t.txt", "héllo\n")
    assert (tmp_path / "t.txt").read_text(encoding="utf-8") == "héllo\n"
    atomic_write_json(tmp_path / "j.json", {"a": [1, 2.5], "b": "ü"}, fsync=False)
    assert json.loads((tmp_path / "j.json").read_text(encoding="utf-8")) == {"a": [1, 2.5], "b": "ü"}
    assert _no_temp_files(tmp_path)


def test_atomic_json_rejects_unserialisable(tmp_path):
    with pytest.raises(TypeError, match=r"cannot write .*j\.json: content is not JSON-serialisable"):
        atomic_write_json(tmp_path / "j.json", {"a": object()})
    with pytest.raises(TypeError, match=r"not JSON-serialisable"):
        atomic_write_json(tmp_path / "j.json", {"a": float("nan")})
    assert list(tmp_path.iterdir()) == []


def _forged_png(width: int, height: int) -> bytes:
    """A PNG whose header claims ``width`` × ``height`` (8-bit RGB) with one tiny IDAT: decoding it
    would allocate width × height × 3 bytes."""
    import struct
    import zlib

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(b"\x00" * 64))
            + chunk(b"IEND", b""))


def test_huge_png_header_is_refused_before_decoding(tmp_path):
    """Defect 10: a 40000x40000 header (a 100-byte file) used to be decoded, allocating 4.8 GB."""
    p = tmp_path / "huge.png"
    p.write_bytes(_forged_png(40000, 40000))
    assert p.stat().st_size < 200
    with pytest.raises(ImageIOError, match=r"huge\.png is 40000x40000 = 1600000000 pixels: more than the limit of 100000000"):
        read_image(p)
    with pytest.raises(ImageIOError, match=r"huge\.png is 40000x40000: larger than the 656x490 expected"):
        read_image(p, max_size=(656, 490))
    small = tmp_path / "small.png"
    write_image(small, np.zeros((20, 30), np.uint8))
    with pytest.raises(ImageIOError, match=r"small\.png is 30x20: larger than the 16x16 expected"):
        read_image(small, max_size=(16, 16))
    assert read_image(small, max_size=(30, 20)).shape == (20, 30)


def test_session_bounds_decoding_by_the_cameras_size(tmp_path):
    from rigs.session import Session, SessionError, SessionWriter

    with SessionWriter.create(tmp_path / "s", ["cam0"]) as w:
        w.write_frame(0, {"cam0": np.zeros((12, 16, 3), np.uint8)})
    (tmp_path / "s" / "frames" / "cam0" / "000000.png").write_bytes(_forged_png(40000, 40000))
    s = Session.open(tmp_path / "s")
    with pytest.raises(SessionError, match=r"camera 'cam0' .*000000\.png is 40000x40000: larger than the 16x12 expected"):
        s.image("cam0", 0)
