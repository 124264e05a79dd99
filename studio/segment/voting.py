"""Multi-view shadow voting through the ground plane (thesis §5.5.2, fig. 5.3–5.4).

A cast shadow lies on the floor, so its image in one view maps onto its image in every other
view through the floor-induced homography; a torso or a background patch mislabelled as
shadow does not. For every pair of views we precompute a pixel map (camera *k* pixel → the
camera *j* pixel that sees the same floor point), computed through the ray / floor
intersection with the full lens model (so no undistortion of the masks is needed; the
distortion is handled exactly in the map, which is then applied with nearest-neighbour lookup:
by ``cv2.remap`` over the shadow's bounding box in the reference path, ``vote(method="remap")``,
or as flat pixel indices read at the shadow pixels only by the compiled kernels of
:mod:`studio.segment.voting_kernel`, the default: the same labels, ~4× faster).

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
from studio.segment.voting_kernel import consistent_shadow, touching_regions, unexplained_in_box

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
        self._ratio_tolerance8 = int(round(self.ratio_tolerance * RATIO_SCALE))
        sizes = [int(np.prod(calibration[k].size)) for k in names]
        self._offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        self._indices = {}  # k → (H_k, W_k, J) int32: every other view's flat indices, interleaved per pixel
        for k in names:
            w, h = calibration[k].size
            others = [self._flat_indices(k, j) for j in names if j != k]
            self._indices[k] = np.stack(others, axis=-1) if others else np.empty((h, w, 0), np.int32)

    def _flat_indices(self, k: str, j: str) -> np.ndarray:
        """(H_k, W_k) int32: the map (k, j) as indices into the flat buffer of every view's
        labels (-1 where ``cv2.remap`` would read outside view j, i.e. return ``NO_VIEW``)."""
        xy = self._maps[(k, j)].astype(np.int64)
        w, h = self.calibration[j].size
        inside = (xy[..., 0] >= 0) & (xy[..., 0] < w) & (xy[..., 1] >= 0) & (xy[..., 1] < h)
        flat = self._offsets[self.names.index(j)] + xy[..., 1] * w + xy[..., 0]
        return np.where(inside, flat, -1).astype(np.int32)

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

    def _check_ratios(self, labels_by_camera, ratios_by_camera) -> dict[str, np.ndarray] | None:
        if ratios_by_camera is None:
            return None
        ratios = {}
        for name in self.names:
            r = np.asarray(ratios_by_camera[name]) if name in ratios_by_camera else None
            if r is None or r.shape != np.shape(labels_by_camera[name]) or r.dtype != np.uint8:
                raise SegmentationError(
                    f"shadow voting: value ratios of camera {name!r} must be a "
                    f"{np.shape(labels_by_camera[name])} uint8 image (see encode_ratio)"
                )
            ratios[name] = r
        return ratios

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

    def _evidence(self, state, j: str, k: str, box):
        """View j's (vote, refute, occlude) uint8 0/1 images over ``box`` of view k (reference path)."""
        x, y, w, h = box
        ratios = state.ratios
        if ratios is not None:  # packed labels and ratios, one remap
            warped, other = cv2.split(self.warp(state.packed(j), j, k, box))
        else:
            warped = self.warp(state.packed(j), j, k, box)
        shadow = (warped == SHADOW).view(np.uint8)
        refute = (warped == BACKGROUND).view(np.uint8)
        if ratios is not None:
            diff = cv2.absdiff(other, ratios[k][y : y + h, x : x + w])
            consistent = (diff <= np.uint8(self._ratio_tolerance8)).view(np.uint8)
            refute = refute | (shadow & (1 - consistent))  # j sees the floor, darkened otherwise
            shadow = shadow & consistent
        if self.tolerance > 0:
            shadow = cv2.dilate(shadow, self._kernel)
        return shadow, refute, (warped == PERSON).view(np.uint8)

    def _unexplained_remap(self, state, k: str, box) -> np.ndarray:
        """(h, w) uint8 unexplained shadow of k over ``box``: every other view warped over the
        whole box with ``cv2.remap`` (the readable reference of the compiled path)."""
        x, y, w, h = box
        votes = np.zeros((h, w), np.uint8)
        refuters = np.zeros((h, w), np.uint8)
        occluders = np.zeros((h, w), np.uint8)
        for j in self.names:
            if j == k:
                continue
            key = (j, k, box)
            evidence = state.cache.get(key)
            if evidence is None:
                evidence = state.cache[key] = self._evidence(state, j, k, box)
            votes += evidence[0]
            refuters += evidence[1]
            occluders += evidence[2]
        own = state.labels[k][y : y + h, x : x + w] == SHADOW
        hidden = (occluders > 0) & (refuters == 0)  # only views blocked by the person see it
        return (own & (votes < self.min_votes) & ~hidden).view(np.uint8)

    def _relabel_remap(self, state, k: str, box) -> np.ndarray | None:
        """Reference: flat indices into k's labels of the unexplained shadow regions touching the
        person (connected components of the whole box), or None."""
        unexplained = self._unexplained_remap(state, k, box)
        if not unexplained.any():
            return None
        lab = state.labels[k]
        x, y, w, h = box
        # person adjacency, looked up with a 1-pixel margin around the box
        x0, y0 = max(x - 1, 0), max(y - 1, 0)
        x1, y1 = min(x + w + 1, lab.shape[1]), min(y + h + 1, lab.shape[0])
        person = cv2.dilate((lab[y0:y1, x0:x1] == PERSON).view(np.uint8), np.ones((3, 3), np.uint8))
        person = person[y - y0 : y - y0 + h, x - x0 : x - x0 + w]
        if not (person & unexplained).any():
            return None
        n, cc, stats, _ = cv2.connectedComponentsWithStats(unexplained, connectivity=8)
        touching = np.zeros(n, bool)
        touching[np.unique(cc[(person > 0) & (unexplained > 0)])] = True
        touching[0] = False
        touching &= stats[:, cv2.CC_STAT_AREA] >= self.min_region
        if not touching.any():
            return None
        rows, cols = np.nonzero(touching[cc])
        return (rows + y) * lab.shape[1] + cols + x

    def _relabel_compiled(self, state, k: str, box) -> np.ndarray | None:
        """The same pixels as :meth:`_relabel_remap`, evaluated near the shadow of k only."""
        x, y, w, h = box
        lab = state.labels[k]
        use = state.ratios is not None
        own_ratios = state.ratios[k] if use else lab
        near = (lab[y : y + h, x : x + w] == SHADOW).view(np.uint8)
        if self.tolerance > 0:
            near = cv2.dilate(near, self._kernel)  # the pixels whose votes reach a shadow pixel
        votes = consistent_shadow(self._indices[k], state.flat, state.flat_ratios, own_ratios, near, box, use,
                                  self._ratio_tolerance8)  # fmt: skip
        if self.tolerance > 0 and votes.shape[2]:
            votes = cv2.dilate(votes, self._kernel)  # (h, w, J): every view's channel at once
            votes = votes.reshape(h, w, -1)  # (OpenCV drops a single view's channel axis)
        unexplained, positions = unexplained_in_box(self._indices[k], state.flat, state.flat_ratios, lab, own_ratios,
                                                    box, votes, self.min_votes, use, self._ratio_tolerance8)  # fmt: skip
        flip = touching_regions(unexplained, positions, lab, box, self.min_region) if len(positions) else positions
        return flip if len(flip) else None

    # ------------------------------------------------------------------ voting
    def vote(
        self,
        labels_by_camera: Mapping[str, np.ndarray],
        ratios_by_camera: Mapping[str, np.ndarray] | None = None,
        *,
        method: str = "compiled",
    ) -> VotingResult:
        """Run the iterative relabelling; returns new label images (inputs are not changed).

        ``ratios_by_camera``: optional ``{camera: (H, W) uint8}`` value ratios ``I^V / μ^V``
        encoded by :func:`encode_ratio` (as :meth:`BackgroundModel.analyse` returns them);
        when given, votes must be photometrically consistent.

        ``method``: ``"compiled"`` (default) evaluates the rule on the shadow pixels only
        (:mod:`studio.segment.voting_kernel`); ``"remap"`` warps whole bounding boxes with
        ``cv2.remap`` — the reference, same labels bit for bit, ~4× slower.
        """
        if method not in ("compiled", "remap"):
            raise SegmentationError(f"shadow voting: method must be 'compiled' or 'remap', got {method!r}")
        state = _VoteState(self, self._check(labels_by_camera), self._check_ratios(labels_by_camera, ratios_by_camera))
        relabel = self._relabel_compiled if method == "compiled" else self._relabel_remap
        relabelled = {k: 0 for k in self.names}
        iterations = 0
        for iterations in range(1, self.max_iterations + 1):
            changes = {}
            for k in self.names:
                shadow = (state.labels[k] == SHADOW).view(np.uint8)
                if not shadow.any():
                    continue
                flip = relabel(state, k, cv2.boundingRect(shadow))
                if flip is not None:
                    changes[k] = flip
            if not changes:
                break
            for k, flip in changes.items():
                state.labels[k].reshape(-1)[flip] = PERSON  # a view of the flat buffer
                relabelled[k] += len(flip)
                state.changed(k)
        else:
            log.warning("shadow voting did not converge in %d iterations", self.max_iterations)
        log.debug("shadow voting: %d iterations, relabelled %s", iterations, relabelled)
        return VotingResult(labels=state.labels, iterations=iterations, relabelled=relabelled)


class _VoteState:
    """Labels being relabelled by one :meth:`ShadowVoter.vote`: every view's labels are views into
    one flat buffer (``flat``, read by the compiled kernels through the voter's indices); the
    reference path keeps its packed label+ratio images and its evidence cache."""

    def __init__(self, voter: ShadowVoter, labels: dict, ratios: dict | None):
        self.flat = np.empty(voter._offsets[-1], np.uint8)
        self.flat_ratios = np.zeros(voter._offsets[-1] if ratios is not None else 1, np.uint8)
        self.labels, self.ratios = {}, ratios
        for i, k in enumerate(voter.names):
            part = self.flat[voter._offsets[i] : voter._offsets[i + 1]].reshape(labels[k].shape)
            part[...] = labels[k]
            self.labels[k] = part
            if ratios is not None:
                self.flat_ratios[voter._offsets[i] : voter._offsets[i + 1]] = ratios[k].ravel()
        self.cache: dict = {}  # reference path: (j, k, box) → view j's evidence in k
        self._packed: dict = {}  # reference path: k → labels (with ratios: (H, W, 2) labels, ratios)

    def packed(self, k: str) -> np.ndarray:
        if k not in self._packed:
            lab = self.labels[k]
            self._packed[k] = lab if self.ratios is None else cv2.merge([lab, self.ratios[k]])
        return self._packed[k]

    def changed(self, k: str) -> None:
        """View k was relabelled: drop what was derived from its labels."""
        self.cache = {key: v for key, v in self.cache.items() if key[0] != k}
        self._packed.pop(k, None)


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
