"""Multi-view shadow voting through the ground plane (thesis §5.5.2, fig. 5.3–5.4).

A cast shadow lies on the floor, so its image in one view maps onto its image in every other
view through the floor-induced homography; a torso or a background patch mislabelled as
shadow does not. For every pair of views we precompute a pixel map (camera *k* pixel → the
camera *j* pixel that sees the same floor point), computed through the ray / floor
intersection with the full lens model (so no undistortion of the masks is needed; the
distortion is handled exactly in the map, which is then applied with ``cv2.remap`` and
nearest-neighbour lookup).

Each iteration, for every view *k*:

* warp the labels of every other view *j* into *k*; view *j* *votes* for a shadow at a floor
  point when it labels it shadow (dilated by ``tolerance`` pixels against small calibration
  errors), *refutes* it when it labels it background (or, with value ratios, shadow of a
  different darkening), and is *blocked* when it labels it person (the body hides that floor
  point from *j*);
* a shadow pixel of *k* is *unexplained* when fewer than ``min_votes`` other views vote for it,
  unless the views that have it in frame are all blocked (then nothing can be said: it stays
  shadow). Floor points no other view has in frame count as unexplained — this is what
  catches a torso mislabelled as shadow, whose floor point lies far behind the person;
* connected regions of unexplained shadow that touch the person in *k* are relabelled person
  (the conservative rule of §5.5.2).

Relabelling changes both the votes and the adjacency, so the procedure repeats until nothing
changes (typically 2–4 iterations).

Photometric consistency (an extension, used when the per-view value ratios ``I^V / μ^V`` are
given): a cast shadow darkens a matte floor by the same factor whichever camera looks at it
(the ratio of ambient to total light at that floor point), while dark clothing seen in front
of a real shadow does not. A vote of view *j* then only counts where its value ratio agrees
with view *k*'s within ``ratio_tolerance``. This resolves the case the label-only rule cannot:
legs in dark trousers standing in front of the true shadow, whose floor points *are* shadow in
the other views.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass

import cv2
import numpy as np

from studio.segment.classify import BACKGROUND, PERSON, SHADOW
from studio.segment.errors import SegmentationError

__all__ = ["ShadowVoter", "VotingResult", "vote_shadows", "floor_vote_image", "FloorVotes", "encode_ratio"]

log = logging.getLogger(__name__)

NO_VIEW = 255  # warped label value where the other view does not see the floor point
RATIO_SCALE = 200.0  # value ratios are stored as uint8 round(ratio · 200), i.e. 0 … 1.275


def encode_ratio(ratio: np.ndarray) -> np.ndarray:
    """Value ratio ``I^V / μ^V`` (H, W) float → (H, W) uint8 ``round(200 · ratio)`` (clipped)."""
    return np.clip(np.rint(np.asarray(ratio, np.float32) * RATIO_SCALE), 0, 255).astype(np.uint8)


def _floor_points(camera, plane) -> np.ndarray:
    """(H·W, 3) world floor point seen by every (distorted) pixel of ``camera``; NaN: none."""
    w, h = camera.size
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    uv = np.stack([u.ravel(), v.ravel()], axis=1)
    return plane.pixel_to_ground(camera, uv, distorted=True)


@dataclass(frozen=True)
class VotingResult:
    """Labels after voting plus what happened: iterations run, pixels relabelled per view."""

    labels: dict[str, np.ndarray]
    iterations: int
    relabelled: dict[str, int]


class ShadowVoter:
    """Precomputed floor maps between the views of a calibrated rig (thesis §5.5.2).

    Parameters
    ----------
    calibration : ``calibration.RigCalibration`` (cameras + ground plane).
    cameras : the views to use (default: all, in rig order).
    min_votes : other views that must label a floor point shadow for it to be explained.
    tolerance : pixels by which other views' warped shadow is dilated before counting.
    min_region : unexplained regions smaller than this many pixels are left as shadow.
    max_iterations : cap on the relabelling iterations.
    ratio_tolerance : largest difference of value ratios for a consistent vote (used when
        ratios are passed to :meth:`vote`).
    """

    def __init__(
        self,
        calibration,
        cameras: list[str] | None = None,
        *,
        min_votes: int = 1,
        tolerance: int = 2,
        min_region: int = 20,
        max_iterations: int = 10,
        ratio_tolerance: float = 0.12,
    ):
        names = list(cameras) if cameras is not None else list(calibration.camera_names)
        for name in names:
            if name not in calibration:
                raise SegmentationError(
                    f"shadow voting: camera {name!r} is not in the calibration "
                    f"(has {list(calibration.camera_names)})"
                )
        if min_votes < 1:
            raise SegmentationError(f"shadow voting: min_votes must be >= 1, got {min_votes}")
        self.calibration = calibration
        self.names = names
        self.min_votes = int(min_votes)
        self.tolerance = int(tolerance)
        self.min_region = int(min_region)
        self.max_iterations = int(max_iterations)
        self.ratio_tolerance = float(ratio_tolerance)
        self._kernel = cv2.getStructuringElement(
            cv2.MORPH_ELLIPSE, (2 * self.tolerance + 1, 2 * self.tolerance + 1)
        )
        self._maps: dict[tuple[str, str], np.ndarray] = {}  # (k, j) → (H_k, W_k, 2) int16
        plane = calibration.ground
        for k in names:
            cam_k = calibration[k]
            floor = _floor_points(cam_k, plane)
            for j in names:
                if j == k:
                    continue
                uv = calibration[j].project_near(floor)
                uv = np.where(np.isfinite(uv), uv, -1e4)
                w, h = cam_k.size
                mx = uv[:, 0].reshape(h, w).astype(np.float32)
                my = uv[:, 1].reshape(h, w).astype(np.float32)
                self._maps[(k, j)] = cv2.convertMaps(mx, my, cv2.CV_16SC2, nninterpolation=True)[0]

    # ------------------------------------------------------------------ helpers
    def _check(self, labels_by_camera: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        out = {}
        for name in self.names:
            if name not in labels_by_camera:
                raise SegmentationError(f"shadow voting: no labels for camera {name!r}")
            lab = np.asarray(labels_by_camera[name])
            w, h = self.calibration[name].size
            if lab.shape != (h, w) or lab.dtype != np.uint8:
                raise SegmentationError(
                    f"shadow voting: labels of camera {name!r} are {lab.shape} {lab.dtype}, "
                    f"the calibration expects ({h}, {w}) uint8"
                )
            out[name] = lab
        return out

    def warp(self, labels: np.ndarray, src: str, dst: str, box=None) -> np.ndarray:
        """Labels of view ``src`` seen from view ``dst`` through the floor (255: not seen).

        ``box`` = (x, y, w, h) restricts the output to that window of ``dst``.
        """
        m1 = self._maps[(dst, src)]
        if box is not None:
            x, y, w, h = box
            m1 = m1[y : y + h, x : x + w]
        return cv2.remap(
            labels, m1, None, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=NO_VIEW
        )

    def _evidence(self, labels, ratios, j: str, k: str, box):
        """View j's (vote, refute, occlude) uint8 0/1 images over ``box`` of view k."""
        x, y, w, h = box
        if ratios is not None:  # labels[j] is then (H, W, 2): labels and ratios, one remap
            both = self.warp(labels[j], j, k, box)
            warped, other = cv2.split(both)
        else:
            warped = self.warp(labels[j], j, k, box)
        shadow = (warped == SHADOW).view(np.uint8)
        refute = (warped == BACKGROUND).view(np.uint8)
        if ratios is not None:
            diff = cv2.absdiff(other, ratios[k][y : y + h, x : x + w])
            consistent = (diff <= np.uint8(round(self.ratio_tolerance * RATIO_SCALE))).view(np.uint8)
            refute = refute | (shadow & (1 - consistent))  # j sees the floor, darkened otherwise
            shadow = shadow & consistent
        if self.tolerance > 0:
            shadow = cv2.dilate(shadow, self._kernel)
        return shadow, refute, (warped == PERSON).view(np.uint8)

    def _unexplained(self, labels: dict[str, np.ndarray], k: str, box, ratios=None, cache=None) -> np.ndarray:
        x, y, w, h = box
        votes = np.zeros((h, w), np.uint8)
        refuters = np.zeros((h, w), np.uint8)
        occluders = np.zeros((h, w), np.uint8)
        for j in self.names:
            if j == k:
                continue
            key = (j, k, box)
            evidence = None if cache is None else cache.get(key)
            if evidence is None:
                evidence = self._evidence(labels, ratios, j, k, box)
                if cache is not None:
                    cache[key] = evidence
            votes += evidence[0]
            refuters += evidence[1]
            occluders += evidence[2]
        own_labels = labels[k] if labels[k].ndim == 2 else labels[k][..., 0]  # packed with ratios
        own = own_labels[y : y + h, x : x + w] == SHADOW
        hidden = (occluders > 0) & (refuters == 0)  # only views blocked by the person see it
        return own & (votes < self.min_votes) & ~hidden

    # ------------------------------------------------------------------ voting
    def vote(
        self,
        labels_by_camera: Mapping[str, np.ndarray],
        ratios_by_camera: Mapping[str, np.ndarray] | None = None,
    ) -> VotingResult:
        """Run the iterative relabelling; returns new label images (inputs are not changed).

        ``ratios_by_camera``: optional ``{camera: (H, W) uint8}`` value ratios ``I^V / μ^V``
        encoded by :func:`encode_ratio` (as :meth:`BackgroundModel.analyse` returns them);
        when given, votes must be photometrically consistent.
        """
        labels = {k: v.copy() for k, v in self._check(labels_by_camera).items()}
        ratios = None
        if ratios_by_camera is not None:
            ratios = {}
            for name in self.names:
                r = np.asarray(ratios_by_camera.get(name)) if name in ratios_by_camera else None
                if r is None or r.shape != labels[name].shape or r.dtype != np.uint8:
                    raise SegmentationError(
                        f"shadow voting: value ratios of camera {name!r} must be a "
                        f"{labels[name].shape} uint8 image (see encode_ratio)"
                    )
                ratios[name] = r
        relabelled = {k: 0 for k in self.names}
        iterations = 0
        cache: dict = {}  # (j, k, box) → view j's evidence in k; dropped when j's labels change
        packed = {
            k: lab if ratios is None else cv2.merge([lab, ratios[k]]) for k, lab in labels.items()
        }
        near = np.ones((3, 3), np.uint8)
        for iterations in range(1, self.max_iterations + 1):
            changes = {}
            for k in self.names:
                lab = labels[k]
                shadow = (lab == SHADOW).astype(np.uint8)
                if not shadow.any():
                    continue
                box = cv2.boundingRect(shadow)
                x, y, w, h = box
                unexplained = self._unexplained(packed, k, box, ratios, cache).astype(np.uint8)
                if not unexplained.any():
                    continue
                # person adjacency, looked up with a 1-pixel margin around the box
                x0, y0 = max(x - 1, 0), max(y - 1, 0)
                x1, y1 = min(x + w + 1, lab.shape[1]), min(y + h + 1, lab.shape[0])
                person = cv2.dilate((lab[y0:y1, x0:x1] == PERSON).astype(np.uint8), near)
                person = person[y - y0 : y - y0 + h, x - x0 : x - x0 + w]
                if not (person & unexplained).any():
                    continue
                n, cc, stats, _ = cv2.connectedComponentsWithStats(unexplained, connectivity=8)
                touching = np.zeros(n, bool)
                touching[np.unique(cc[(person > 0) & (unexplained > 0)])] = True
                touching[0] = False
                touching &= stats[:, cv2.CC_STAT_AREA] >= self.min_region
                if touching.any():
                    changes[k] = (box, touching[cc])
            if not changes:
                break
            for k, (box, flip) in changes.items():
                x, y, w, h = box
                labels[k][y : y + h, x : x + w][flip] = PERSON
                relabelled[k] += int(flip.sum())
                cache = {key: v for key, v in cache.items() if key[0] != k}
                packed[k] = labels[k] if ratios is None else cv2.merge([labels[k], ratios[k]])
        else:
            log.warning("shadow voting did not converge in %d iterations", self.max_iterations)
        log.debug("shadow voting: %d iterations, relabelled %s", iterations, relabelled)
        return VotingResult(labels=labels, iterations=iterations, relabelled=relabelled)


def vote_shadows(
    labels_by_camera: Mapping[str, np.ndarray],
    calibration,
    *,
    voter: ShadowVoter | None = None,
    ratios_by_camera: Mapping[str, np.ndarray] | None = None,
    **options,
) -> dict[str, np.ndarray]:
    """Multi-view shadow voting (§5.5.2): relabel shadow no other view explains as person.

    Parameters
    ----------
    labels_by_camera : ``{camera: (H, W) uint8}`` labels 0 background / 1 person / 2 shadow,
        one per camera of ``calibration`` (after single-view morphology).
    calibration : ``calibration.RigCalibration`` of the rig (cameras and ground plane).
    voter : a prebuilt :class:`ShadowVoter` for this calibration (reuses its maps).
    ratios_by_camera : optional encoded value ratios for photometric consistency.
    options : passed to :class:`ShadowVoter` when it is built here.

    Returns
    -------
    ``{camera: (H, W) uint8}`` new labels.
    """
    if voter is None:
        voter = ShadowVoter(calibration, [c for c in calibration.camera_names if c in labels_by_camera], **options)
    return voter.vote(labels_by_camera, ratios_by_camera).labels


class FloorVotes:
    """Shadow votes on a top-down floor raster (thesis fig. 5.4), with the maps precomputed.

    Parameters
    ----------
    calibration : ``calibration.RigCalibration``.
    grid : ``calibration.FloorGrid`` of the raster.
    cameras : the views to accumulate (default: all).
    """

    def __init__(self, calibration, grid, cameras: list[str] | None = None):
        names = list(cameras) if cameras is not None else list(calibration.camera_names)
        for name in names:
            if name not in calibration:
                raise SegmentationError(f"floor votes: camera {name!r} is not in the calibration")
        self.grid = grid
        self.names = names
        X, Y = grid.cell_centers()
        world = calibration.ground.from_plane_coords(np.stack([X.ravel(), Y.ravel()], axis=1))
        rows, cols = grid.shape
        self._maps = {}
        for name in names:
            uv = calibration[name].project_near(world)
            uv = np.where(np.isfinite(uv), uv, -1e4)
            mx = uv[:, 0].reshape(rows, cols).astype(np.float32)
            my = uv[:, 1].reshape(rows, cols).astype(np.float32)
            self._maps[name] = cv2.convertMaps(mx, my, cv2.CV_16SC2, nninterpolation=True)[0]

    def __call__(self, labels_by_camera: Mapping[str, np.ndarray]) -> np.ndarray:
        """(rows, cols) uint8: number of views labelling each floor cell shadow."""
        votes = np.zeros(self.grid.shape, np.uint8)
        for name, labels in labels_by_camera.items():
            if name not in self._maps:
                raise SegmentationError(f"floor votes: camera {name!r} is not in the calibration")
            shadow = (np.asarray(labels) == SHADOW).view(np.uint8)
            votes += cv2.remap(shadow, self._maps[name], None, cv2.INTER_NEAREST,
                               borderMode=cv2.BORDER_CONSTANT, borderValue=0)  # fmt: skip
        return votes


def floor_vote_image(labels_by_camera: Mapping[str, np.ndarray], calibration, grid) -> np.ndarray:
    """Shadow votes on a top-down floor raster (thesis fig. 5.4).

    Parameters
    ----------
    labels_by_camera : ``{camera: (H, W) uint8}`` labels.
    calibration : ``calibration.RigCalibration``.
    grid : ``calibration.FloorGrid`` of the raster.

    Returns
    -------
    (rows, cols) uint8: number of views labelling each floor cell shadow. For many frames,
    build a :class:`FloorVotes` once instead.
    """
    return FloorVotes(calibration, grid, list(labels_by_camera))(labels_by_camera)
