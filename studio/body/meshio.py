"""Mesh export: binary PLY, Wavefront OBJ and binary glTF 2.0 (.glb), written atomically."""

from __future__ import annotations

from pathlib import Path

import json
import struct

import numpy as np

from rigs.atomic import atomic_open

__all__ = ["glb_bytes", "write_mesh", "read_ply"]


def _check(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces)
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"vertices must be (V, 3), got {v.shape}")
    if f.ndim != 2 or f.shape[1] != 3 or (f.size and (f.min() < 0 or f.max() >= len(v))):
        raise ValueError(f"faces must be (F, 3) indices into {len(v)} vertices")
    return v, f.astype(np.int64)


def write_mesh(path: str | Path, vertices: np.ndarray, faces: np.ndarray, colors: np.ndarray | None = None) -> Path:
    """Write ``path`` (.ply binary little-endian, .obj or .glb); optional per-vertex RGB uint8
    colors (PLY only). Coordinates as given (metres, Z up; glTF readers expecting Y up see the
    body lying on its back — the world frame is kept so that every export agrees)."""
    path = Path(path)
    v, f = _check(vertices, faces)
    suffix = path.suffix.lower()
    if suffix not in (".ply", ".obj", ".glb"):
        raise ValueError(f"{path}: mesh format must be .ply, .obj or .glb")
    with atomic_open(path, "wb") as fh:
        if suffix == ".glb":
            fh.write(glb_bytes(v, f))
        elif suffix == ".ply":
            header = ["ply", "format binary_little_endian 1.0", f"element vertex {len(v)}",
                      "property float x", "property float y", "property float z"]
            if colors is not None:
                header += ["property uchar red", "property uchar green", "property uchar blue"]
            header += [f"element face {len(f)}", "property list uchar int vertex_indices", "end_header"]
            fh.write(("\n".join(header) + "\n").encode())
            if colors is None:
                fh.write(v.astype("<f4").tobytes())
            else:
                c = np.asarray(colors, dtype=np.uint8).reshape(len(v), 3)
                rec = np.zeros(len(v), dtype=[("p", "<f4", 3), ("c", "u1", 3)])
                rec["p"], rec["c"] = v, c
                fh.write(rec.tobytes())
            rec = np.zeros(len(f), dtype=[("n", "u1"), ("i", "<i4", 3)])
            rec["n"], rec["i"] = 3, f
            fh.write(rec.tobytes())
        else:
            lines = [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in v]
            lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in f]
            fh.write(("\n".join(lines) + "\n").encode())
    return path


def _pad(data: bytes, fill: bytes) -> bytes:
    return data + fill * (-len(data) % 4)


def glb_bytes(vertices: np.ndarray, faces: np.ndarray) -> bytes:
    """A binary glTF 2.0 file of one triangle mesh: POSITION (float32, with min/max) and
    uint32 indices in one buffer, one node, one scene."""
    v = np.ascontiguousarray(vertices, dtype="<f4")
    idx = np.ascontiguousarray(faces, dtype="<u4").ravel()
    pos, ind = v.tobytes(), _pad(idx.tobytes(), b"\0")
    gltf = {
        "asset": {"version": "2.0", "generator": "Silhouette & Shadow Studio"},
        "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0, "name": "body"}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "mode": 4}]}],
        "buffers": [{"byteLength": len(pos) + len(ind)}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": len(pos), "target": 34962},
                        {"buffer": 0, "byteOffset": len(pos), "byteLength": idx.nbytes, "target": 34963}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": len(v), "type": "VEC3",
                       "min": v.min(axis=0).tolist(), "max": v.max(axis=0).tolist()},
                      {"bufferView": 1, "componentType": 5125, "count": int(idx.size), "type": "SCALAR"}],
    }
    js = _pad(json.dumps(gltf, separators=(",", ":")).encode(), b" ")
    binary = pos + ind
    total = 12 + 8 + len(js) + 8 + len(binary)
    return (struct.pack("<4sII", b"glTF", 2, total) + struct.pack("<I4s", len(js), b"JSON") + js
            + struct.pack("<I4s", len(binary), b"BIN\0") + binary)


def read_ply(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Read a binary PLY written by :func:`write_mesh` (no colors): vertices, faces."""
    path = Path(path)
    data = path.read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode().splitlines()
    if "format binary_little_endian 1.0" not in header:
        raise ValueError(f"{path}: only binary little-endian PLY is supported")
    nv = int(next(h for h in header if h.startswith("element vertex")).split()[-1])
    nf = int(next(h for h in header if h.startswith("element face")).split()[-1])
    if any("uchar red" in h for h in header):
        raise ValueError(f"{path}: colored PLY not supported by read_ply")
    v = np.frombuffer(data, dtype="<f4", count=nv * 3, offset=end).reshape(nv, 3).astype(np.float64)
    rec = np.frombuffer(data, dtype=[("n", "u1"), ("i", "<i4", 3)], count=nf, offset=end + nv * 12)
    return v, rec["i"].astype(np.int64)
