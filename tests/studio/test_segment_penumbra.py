"""The shadow rim of the adaptive model (AdaptiveSettings.penumbra, studio.segment.adaptive):
hysteresis growth from the gated shadow into loosely gated person pixels, counted on a drawn scene."""

import numpy as np
import pytest

from studio.segment import PERSON, SHADOW, AdaptiveSettings, SegmentationError
from studio.segment.adaptive import adaptive_step, penumbra_rim

H, W = 48, 64
GATE = dict(noise_scale=2.0, distance=12.0, value_ratio=(0.05, 0.3), chroma=0.2)


def _scene():
    """A flat road (120 per channel) with a neutral shadow core (rows 20–27, cols 10–30, 8 × 21 =
    168 px, 20 % of the road) inside two lighter rings (45 % and 50 %: the penumbra, outside the
    core gate's 0.3, inside the loose gate's 0.6): ring 1 has 62 px, ring 2 70 px, but their right
    columns (31 and 32: 10 and 12 px) are red paint, not shadow. A neutral dark blob (5 × 11 =
    55 px at 45 %) away from the shadow passes the loose gate but touches no shadow."""
    mean = np.full((H, W, 3), 120.0, np.float32)
    frame = np.full((H, W, 3), 120.0, np.float32)
    frame[18:30, 8:33] = 60.0  # ring 2
    frame[19:29, 9:32] = 54.0  # ring 1
    frame[20:28, 10:31] = 24.0  # core
    frame[19:29, 31] = (200.0, 30.0, 30.0)
    frame[18:30, 32] = (200.0, 30.0, 30.0)
    frame[5:10, 45:56] = 54.0  # dark blob
    return frame.astype(np.uint8), mean


def _step(penumbra: int, rim: bool = True):
    frame, mean = _scene()
    dev = np.ones_like(mean)
    s = AdaptiveSettings(**GATE, penumbra=penumbra)
    labels, _ = adaptive_step(frame, mean, dev, s, seen=10**6, rim=rim)
    return labels, mean, dev


@pytest.mark.parametrize("penumbra, shadow", [(0, 168), (1, 168 + 52), (2, 168 + 52 + 58), (5, 168 + 52 + 58)])
def test_rim_grows_one_ring_per_step_into_loosely_gated_pixels_next_to_shadow(penumbra, shadow):
    """Core 168 px; step 1 takes ring 1 less its red column (62 − 10 = 52), step 2 ring 2 less its
    red column (70 − 12 = 58); nothing further is loosely gated, so 5 steps stop at 278. The red
    columns (22 px) and the blob (55 px) stay person whatever the steps; the foreground is the
    same 168 + 132 + 55 = 355 px, and the running model is updated identically."""
    labels, mean, dev = _step(penumbra)
    assert np.count_nonzero(labels == SHADOW) == shadow
    assert np.count_nonzero(labels > 0) == 355
    assert (labels[5:10, 45:56] == PERSON).all()
    assert (labels[19:29, 31] == PERSON).all() and (labels[18:30, 32] == PERSON).all()  # red paint
    assert set(np.unique(labels).tolist()) <= {0, PERSON, SHADOW}
    _, mean0, dev0 = _step(0)
    np.testing.assert_array_equal(mean, mean0)
    np.testing.assert_array_equal(dev, dev0)


def test_rim_grown_on_scattered_pixels_matches_the_full_step():
    """The benchmark's replay: the step on the foreground pixels alone (a 1 × n image, rim=False),
    scattered back, then :func:`penumbra_rim` on the image — the same labels as the full step."""
    frame, mean = _scene()
    full, _, _ = _step(2)
    raw, _, _ = _step(2, rim=False)
    assert np.count_nonzero(raw == 3) == 52 + 58 + 55  # the rings' grey pixels and the blob
    idx = np.flatnonzero(full > 0)
    s = AdaptiveSettings(**GATE, penumbra=2)
    sub, _ = adaptive_step(frame.reshape(-1, 3)[idx][None], mean.reshape(-1, 3)[idx][None],
                           np.ones((1, len(idx), 3), np.float32), s, seen=10**6, rim=False)  # fmt: skip
    image = np.zeros((H, W), np.uint8)
    image.reshape(-1)[idx] = sub[0]
    np.testing.assert_array_equal(penumbra_rim(image, 2), full)


def test_settings_and_errors():
    s = AdaptiveSettings(penumbra=2, penumbra_ratio=0.7, penumbra_chroma=0.3)
    assert AdaptiveSettings.from_dict(s.to_dict()) == s
    old = {k: v for k, v in AdaptiveSettings().to_dict().items() if not k.startswith("penumbra")}
    assert AdaptiveSettings.from_dict(old).penumbra == 0  # settings written before the rim existed
    with pytest.raises(SegmentationError, match="penumbra: expected an int"):
        AdaptiveSettings(penumbra=-1)
    with pytest.raises(SegmentationError, match="penumbra_ratio"):
        AdaptiveSettings(value_ratio=(0.2, 0.5), penumbra_ratio=0.1)
    with pytest.raises(SegmentationError, match="penumbra_chroma"):
        AdaptiveSettings(penumbra_chroma=0.0)
    with pytest.raises(SegmentationError, match="penumbra_rim: labels must be"):
        penumbra_rim(np.zeros((4, 4), np.int32), 1)
