"""Compiled inner loops of multi-view shadow voting (thesis §5.5.2), on the shadow pixels only.

:class:`studio.segment.voting.ShadowVoter` labels a shadow pixel of view *k* *unexplained* when
fewer than ``min_votes`` other views label its floor point shadow (their shadow dilated by the
tolerance disk, photometrically consistent when value ratios are given), unless the views that
see it are all blocked by the person; connected unexplained regions touching the person are
relabelled person. The readable reference (``method="remap"``) warps every other view's labels
over the whole shadow bounding box with ``cv2.remap``, dilates and counts; these kernels compute
the same masks bit for bit, but only where they are needed:

* :func:`unexplained_in_box` visits the shadow pixels of *k* only, and reads the other views
  through precomputed flat pixel indices (``-1``: the floor point is out of that view) into one
  buffer holding every view's labels. The dilated vote of view *j* at pixel *p* is "any pixel
  *q* of the disk around *p* (inside the box, as ``cv2.dilate`` sees it) whose floor point *j*
  labels consistent shadow"; each *q*'s test is computed once and memoised.
* :func:`touching_regions` flood-fills (8-connected, inside the box) only the unexplained
  regions that touch the person, instead of labelling every component of the box.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from studio.segment.classify import BACKGROUND, PERSON, SHADOW

__all__ = ["consistent_shadow", "unexplained_in_box", "touching_regions"]


@njit(cache=True, nogil=True)
def consistent_shadow(indices, flat_labels, flat_ratios, own_ratios, near, box, use_ratios, tolerance):
    """Per other view *j*, where it labels the floor point of a pixel of *k* shadow (photometrically
    consistent: encoded value ratios within ``tolerance`` when ``use_ratios``).

    Parameters
    ----------
    indices : (H, W, J) int32, for each other view *j* the flat index into ``flat_labels`` of the
        pixel of *j* seeing the floor point of each pixel of *k* (-1: not in view).
    flat_labels, flat_ratios : (N,) uint8 labels and encoded value ratios of every view, one buffer
        (``flat_ratios`` is read only when ``use_ratios``).
    own_ratios : (H, W) uint8 encoded value ratios of view *k*.
    near : (h, w) uint8, the pixels of ``box`` = (x, y, w, h) to evaluate (elsewhere 0).

    Returns
    -------
    (h, w, J) uint8 0/1.
    """
    x0, y0, w, h = box
    nj = indices.shape[2]
    out = np.zeros((h, w, nj), np.uint8)
    for r in range(h):
        for c in range(w):
            if near[r, c] == 0:
                continue
            ratio = np.int32(own_ratios[y0 + r, x0 + c])
            for j in range(nj):
                i = indices[y0 + r, x0 + c, j]
                if i >= 0 and flat_labels[i] == SHADOW:
                    if not use_ratios or abs(np.int32(flat_ratios[i]) - ratio) <= tolerance:
                        out[r, c, j] = 1
    return out


@njit(cache=True, nogil=True)
def unexplained_in_box(indices, flat_labels, flat_ratios, own, own_ratios, box, votes, min_votes, use_ratios,
                       tolerance):  # fmt: skip
    """Unexplained shadow of view *k* over ``box`` (the rule of §5.5.2 as ``ShadowVoter`` states it).

    ``votes`` : (h, w, J) uint8, view *j*'s consistent shadow (:func:`consistent_shadow`) dilated
    by the tolerance disk; the other arguments as there, ``own`` the (H, W) labels of *k*.

    Returns
    -------
    ``(mask, positions)``: (h, w) uint8 0/1 mask of the shadow of *k* that fewer than ``min_votes``
    views vote for, unless the views that see its floor point are all blocked by the person, and
    (n,) int32 the flat positions ``r · w + c`` of its pixels in the box, in raster order.
    """
    x0, y0, w, h = box
    nj = indices.shape[2]
    out = np.zeros((h, w), np.uint8)
    positions = np.empty(h * w, np.int32)
    n = 0
    for r in range(h):
        for c in range(w):
            if own[y0 + r, x0 + c] != SHADOW:
                continue
            n_votes = 0
            for j in range(nj):
                n_votes += votes[r, c, j]
            if n_votes >= min_votes:
                continue
            refuters = 0
            occluders = 0
            ratio = np.int32(own_ratios[y0 + r, x0 + c])
            for j in range(nj):
                i = indices[y0 + r, x0 + c, j]
                if i < 0:
                    continue
                lab = flat_labels[i]
                if lab == BACKGROUND:
                    refuters += 1
                elif lab == PERSON:
                    occluders += 1
                elif lab == SHADOW and use_ratios and abs(np.int32(flat_ratios[i]) - ratio) > tolerance:
                    refuters += 1  # j sees the floor point, darkened otherwise
            if not (occluders > 0 and refuters == 0):
                out[r, c] = 1
                positions[n] = r * w + c
                n += 1
    return out, positions[:n]


@njit(cache=True, nogil=True)
def touching_regions(unexplained, positions, labels, box, min_region):
    """8-connected regions of ``unexplained`` (inside ``box``) with a pixel next to the person.

    ``positions`` lists the unexplained pixels (``r · w + c``, as :func:`unexplained_in_box` returns
    them): only they are visited, and only the regions they seed are flood-filled. A pixel touches
    the person when one of its 8 neighbours in the whole image ``labels`` (H, W) is ``PERSON``.
    Regions of fewer than ``min_region`` pixels are left out. ``unexplained`` is used as the
    visited mark (its region pixels become 2).

    Returns
    -------
    (n,) int64 flat indices into ``labels`` of the pixels to relabel person.
    """
    x0, y0, w, h = box
    height, width = labels.shape
    queue = np.empty(positions.shape[0], np.int32)  # breadth-first; accepted regions stay in queue[:tail]
    tail = 0
    for p0 in positions:
        r = p0 // w
        c = p0 - r * w
        if unexplained[r, c] != 1:
            continue  # already in a region
        near = False
        for yy in range(max(y0 + r - 1, 0), min(y0 + r + 2, height)):
            for xx in range(max(x0 + c - 1, 0), min(x0 + c + 2, width)):
                if labels[yy, xx] == PERSON:
                    near = True
        if not near:
            continue
        unexplained[r, c] = 2
        start = tail
        queue[tail] = p0
        tail += 1
        head = start
        while head < tail:
            p = queue[head]
            head += 1
            pr = p // w
            pc = p - pr * w
            for nr in range(max(pr - 1, 0), min(pr + 2, h)):
                for nc in range(max(pc - 1, 0), min(pc + 2, w)):
                    if unexplained[nr, nc] == 1:
                        unexplained[nr, nc] = 2
                        queue[tail] = nr * w + nc
                        tail += 1
        if tail - start < min_region:
            tail = start  # too small: dropped (its pixels stay marked, so never revisited)
    flat = np.empty(tail, np.int64)
    for m in range(tail):
        r = queue[m] // w
        flat[m] = (y0 + r) * width + x0 + queue[m] - r * w
    return flat
