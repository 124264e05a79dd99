"""Render a scene spec into a capture-session folder with ground truth.

Layout (DESIGN.md "Capture session", written with :class:`rigs.session.SessionWriter`)::

    session.json, calibration.json, frames.csv, background/<cam>/, frames/<cam>/
    truth/labels/<cam>/NNNNNN.png   uint8 0 background, 1 person, 2 shadow, 3 object (a stool)
    truth/skin/<cam>/NNNNNN.png     0/255 visible skin
    truth/bodies/NNNNNN.npz         vertices (V, 3) float32 world metres + pose info
    truth/faces.npy                 (F, 3) int32
    truth/parts.npy                 (V,) uint8 body part per vertex (+ truth/scene.json names)
    truth/lights.json, truth/measurements.json, truth/scene.json, truth/calibration.json

``truth/measurements.json`` holds the body file's measurements (Anny's definitions, see
:mod:`studio.simulate.truth_build`) and, when the body file has the canonical postures
(``rest_q``, ``tpose_q``), a ``"studio"`` entry {name: value}: the same person measured by
:func:`studio.body.measure`'s definitions (:func:`studio_truth`), with ``"studio_code"``: the digest of the code and model file those
figures come from (:func:`truth_code_digest`). A cached render whose digest differs has them
recomputed on reuse (:func:`ensure_rendered`), so a change to the measurement definitions
never meets a stale truth.

The session itself is clean (every frame complete, nominal timestamps); the ``sensor``
section's ``drop`` and ``jitter_ns`` are echoed in ``session.json`` metadata
(``simulation.sensor``) for the ``simulated`` rig backend to apply at playback.
Same spec + seed → byte-identical images and truth (``session.json`` differs only in its
start/end times).
"""

from __future__ import annotations

import json
import logging
import os
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

from rigs.atomic import atomic_write_bytes
from studio.render import vertex_normals
from studio.simulate.scene import Scene, load_body
from studio.simulate.sensor import apply_sensor
from studio.simulate.spec import SimSpec, load_spec
from studio.workspace.layout import Layout

__all__ = ["simulate", "ensure_rendered", "default_cache_dir", "studio_truth", "truth_code_digest", "TRUTH_VERSION"]

log = logging.getLogger(__name__)

TRUTH_VERSION = 1
START_NS = 1_700_000_000_000_000_000  # nominal clock of simulated sessions


def _atomic_json(path: Path, obj) -> None:
    from rigs.atomic import atomic_write_json

    atomic_write_json(path, obj)


def _save_npz(path: Path, **arrays) -> None:
    from rigs.atomic import atomic_open

    with atomic_open(path, "wb") as f:
        np.savez_compressed(f, **arrays)


def _save_npy(path: Path, array: np.ndarray) -> None:
    from rigs.atomic import atomic_open

    with atomic_open(path, "wb") as f:
        np.save(f, array)


def _frame_rng(seed: int, kind: int, frame: int, cam: int) -> np.random.Generator:
    return np.random.default_rng([seed, kind, frame, cam])


def simulate(
    spec: SimSpec | str | Path,
    out: str | Path,
    seed: int | None = None,
    *,
    overwrite: bool = False,
    progress: Callable[[int, int], None] | None = None,
) -> Path:
    """Render ``spec`` into the session folder ``out``; returns ``out``.

    ``seed`` overrides the spec's seed (camera jitter, skin tone, sensor noise).
    ``progress(done, total)`` is called after every frame.
    """
    from rigs.imageio import write_image
    from rigs.session import SessionWriter

    spec = spec if isinstance(spec, SimSpec) else load_spec(spec)
    scene = Scene(spec, seed)
    seed = scene.seed
    out = Path(out)
    lay = Layout(out)
    cams = scene.cameras
    names = [c.name for c in cams]
    sensor = spec["sensor"]
    fps = float(spec["fps"])
    with tempfile.TemporaryDirectory() as tmp:
        calib_path = scene.calibration.save(Path(tmp) / "calibration.json")
        metadata = {
            "simulation": {"spec": spec.name, "seed": seed, "digest": spec.digest(),
                           "sensor": {k: sensor[k] for k in ("drop", "jitter_ns")}},
        }
        fmt = "BayerRG8" if sensor["bayer"] else "RGB8"
        writer = SessionWriter.create(
            out, names, rig="simulated", fps=fps, pixel_formats={n: fmt for n in names},
            calibration=calib_path, metadata=metadata, overwrite=overwrite)
        truth = writer.truth_dir
        truth.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(Layout(out).truth_calibration, Path(calib_path).read_bytes())
    try:
        for sub in ("labels", "skin"):
            for n in names:
                (truth / sub / n).mkdir(parents=True, exist_ok=True)
        (truth / "bodies").mkdir(exist_ok=True)
        _write_static_truth(scene, truth, seed)
        for k, cam in enumerate(cams):
            bd = scene.backdrop(cam)
            for i in range(int(spec["background_frames"])):
                writer.write_background(cam.name, i, apply_sensor(bd.radiance(), sensor,
                                                                  _frame_rng(seed, 2, i, k)))
        total = len(scene.frame_range)
        for index, frame in enumerate(scene.frame_range):
            V = scene.dressed(frame)
            normals = vertex_normals(V, scene.body.faces)
            images = {}
            for k, cam in enumerate(cams):
                r = scene.render(frame, cam, V, normals)
                images[cam.name] = apply_sensor(r.radiance, sensor, _frame_rng(seed, 3, index, k))
                write_image(lay.truth_labels(cam.name, index), r.labels)
                write_image(lay.truth_skin(cam.name, index), (r.skin * np.uint8(255)).astype(np.uint8))
            _write_body(scene, truth, index, frame)
            t_ns = START_NS + round(index * 1e9 / fps)
            writer.write_frame(index, images, timestamps_ns={n: t_ns for n in names},
                               frame_ids={n: index for n in names})
            if progress is not None:
                progress(index + 1, total)
        writer.close()
    except BaseException:
        writer.close(status="aborted")
        raise
    return out


def _write_static_truth(scene: Scene, truth: Path, seed: int) -> None:
    spec, body = scene.spec, scene.body
    _save_npy(truth / "faces.npy", body.faces.astype(np.int32))
    _save_npy(truth / "parts.npy", body.parts)
    _save_npy(truth / "skin_vertices.npy", scene.is_skin)
    lights = [light.to_dict() for light in scene.lights]
    _atomic_json(truth / "lights.json", {"ambient": scene.ambient, "lights": lights,
                                         "ground": {"normal": [0.0, 0.0, 1.0], "offset": 0.0}})
    _atomic_json(truth / "measurements.json", _truth_measurements(body.extra))
    phen = {}
    if "phenotype_names" in body.extra:
        phen = dict(zip((str(s) for s in body.extra["phenotype_names"]),
                        (float(v) for v in body.extra["phenotype_values"])))
    _atomic_json(truth / "scene.json", {
        "format": "studio.sim-truth", "version": TRUTH_VERSION, "seed": seed,
        "spec": spec.data, "digest": spec.digest(), "skin_tone": scene.skin_tone,
        "body_frames": [scene.frame_range.start, scene.frame_range.stop],
        "part_names": list(body.part_names), "phenotype": phen,
        "source": str(body.extra.get("source", "")),
        "labels": {"0": "background", "1": "person", "2": "shadow", "3": "object (a prop such as a stool)"},
    })


STUDIO_TRUTH_SOURCE = (
    "studio.body.measure definitions on the true body: body.npz rest_q (Anny rest pose = the "
    "model's default pose) and tpose_q (upper arms horizontal, elbows straight) mapped into the "
    "model topology (anny_correspondence), joints by the model's joint regressor"
)


#: Modules whose code decides the same-definition truth (with the body model file they load).
_TRUTH_MODULES = ("studio.body.measure", "studio.body.iso7250", "studio.body.skeleton", "studio.body.model")


def truth_code_digest() -> str:
    """Digest of what :func:`studio_truth`'s figures depend on besides the body file: the source
    of the measurement modules and the shipped body model file."""
    from studio.body.model import DATA_FILE
    from studio.provenance import code_digest

    return code_digest(*_TRUTH_MODULES, files=(DATA_FILE,))


def _truth_measurements(extra: dict) -> dict:
    """``truth/measurements.json`` of a body file's arrays: Anny's own figures, and the
    same-definition ones (:func:`studio_truth`) with the code digest they were computed by."""
    meas = json.loads(str(extra["measurements"])) if "measurements" in extra else {}
    same = studio_truth(extra, meas.get("sex"))
    if same is not None:
        meas["studio"] = same
        meas["studio_source"] = STUDIO_TRUTH_SOURCE
        meas["studio_code"] = truth_code_digest()
    return meas


def _refresh_truth(folder: Path, spec: SimSpec) -> None:
    """Recompute a cached render's same-definition truth when the code that measures it changed
    since it was rendered (the images and labels do not depend on that code)."""
    path = Layout(folder).truth_measurements
    try:
        stored = json.loads(path.read_text())
    except (OSError, ValueError):
        stored = None
    if stored is not None and ("studio" not in stored or stored.get("studio_code") == truth_code_digest()):
        return
    meas = _truth_measurements(load_body(spec.body_path).extra)
    if meas != stored:
        _atomic_json(path, meas)
        log.info("%s: same-definition truth recomputed (measurement code changed)", path)


def studio_truth(extra: dict, sex: str | None = None) -> dict[str, float] | None:
    """Same-definition truth {name: value} (metres, kg) of a ``body.npz``, or None.

    ``extra``: the body file's arrays (``rest_q``, ``tpose_q`` (13348, 3) int16 in units
    of ``scale``); None when the file predates them. The measurements are
    :func:`studio.body.measure.measure_anny_body` — exactly what
    :func:`studio.body.measure` reports for a fitted body — so that fit errors measure
    the fit, not differing definitions. ``sex`` picks the model whose topology is used
    (all genders share it; default neutral).
    """
    if "rest_q" not in extra or "tpose_q" not in extra:
        return None
    from studio.body import BodyModel
    from studio.body.measure import measure_anny_body

    scale = float(extra["scale"])
    gender = sex if sex in ("male", "female") else "neutral"
    model = BodyModel.load(gender)
    rest = np.asarray(extra["rest_q"], dtype=np.float64) * scale
    tpose = np.asarray(extra["tpose_q"], dtype=np.float64) * scale
    return measure_anny_body(model, rest, tpose)


def _write_body(scene: Scene, truth: Path, index: int, frame: int) -> None:
    body = scene.body
    arrays = {"vertices": scene.true_vertices(frame).astype(np.float32), "body_frame": np.int64(frame)}
    for key in ("bone_rotvecs", "root_translation", "yaw", "pose_names", "bob"):
        if key in body.extra:
            arrays[key] = body.extra[key][frame]
    if "pose_bones" in body.extra:
        arrays["pose_bones"] = body.extra["pose_bones"]
    _save_npz(Layout(truth.parent).truth_body(index), **arrays)


def default_cache_dir(spec: SimSpec) -> Path:
    """``<cache root>/renders/<name>`` (:func:`studio.simulate.samples.cache_root`: ``$STUDIO_CACHE``,
    ``$XDG_CACHE_HOME/studio`` or ``~/.cache/studio``), never beside the spec."""
    from studio.simulate.samples import cache_root

    return cache_root() / "renders" / spec.name


def _complete(folder: Path, digest: str) -> bool:
    try:
        info = json.loads((folder / "session.json").read_text())
        scene = json.loads((folder / "truth" / "scene.json").read_text())
    except (OSError, ValueError):
        return False
    return info.get("status") == "complete" and scene.get("digest") == digest


def ensure_rendered(spec_path: str | Path, seed: int = 0, cache_dir: str | Path | None = None,
                    progress: Callable[[int, int], None] | None = None) -> Path:
    """Render ``spec_path`` into the cache unless a complete render is there; return the session.

    The session folder is ``<cache_dir>/seed<seed>`` (cache default: :func:`default_cache_dir`).
    A render is reused only when it finished (status ``complete``) from the same spec and
    body file (digest in ``truth/scene.json``), its same-definition truth recomputed when the
    measurement code changed since (:func:`truth_code_digest`); otherwise it is rendered into a temporary
    folder and renamed into place, so concurrent callers never see half a session.
    """
    spec = load_spec(spec_path)
    cache = Path(cache_dir) if cache_dir is not None else default_cache_dir(spec)
    folder = cache / f"seed{int(seed)}"
    digest = spec.digest()
    if _complete(folder, digest):
        _refresh_truth(folder, spec)
        return folder
    cache.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".seed{seed}-", dir=cache))
    try:
        simulate(spec, tmp / "session", seed, progress=progress)
        if _complete(folder, digest):  # another process finished first: keep its render
            return folder
        if folder.exists():
            shutil.rmtree(folder)
        os.replace(tmp / "session", folder)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    log.info("rendered %s into %s", spec.path, folder)
    return folder
