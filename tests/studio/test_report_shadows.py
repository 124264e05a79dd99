"""The report's shadow overlays: the fitted (here: true) bodies' shadows under the estimated light
against the segmented ones (thesis §5.4–5.6)."""

import numpy as np
import pytest

import lightkit
from studio.fit import OVERLAY_COLORS
from studio.render import PointLight
from studio.report.html import _shadow_overlays_html
from studio.report.shadows import shadow_agreement, shadow_overlays
from studio.workspace import Workspace

LIGHT = PointLight([1.2, 1.3, 3.4])
META = {"frames": [0, 1, 2], "sources": {"bodies": "truth", "shadows": "segmentation"}}


@pytest.fixture(scope="module")
def ws(tmp_path_factory):
    path = tmp_path_factory.mktemp("shadows") / "lit"
    lightkit.make_session(path, [LIGHT], n_frames=3)
    return Workspace.open(path)


def test_agreement_counts_pixels():
    p = np.zeros((4, 5), bool)
    o = np.zeros((4, 5), bool)
    p[0, :4] = True          # 4 predicted
    o[0, 2:] = True          # 3 observed, 2 of them predicted
    assert shadow_agreement(p, o) == (2 / 4, 2 / 3)
    assert shadow_agreement(np.zeros_like(p), o) == (None, 0.0)
    assert shadow_agreement(p, np.zeros_like(o)) == (0.0, None)


def test_true_light_explains_the_shadows_a_moved_one_does_not(ws):
    good = shadow_overlays(ws, [LIGHT], META)
    assert sorted({s.frame for s in good}) == [0, 2]          # two frames spread over the three
    assert [s.camera for s in good] == ws.camera_names * 2
    for s in good:
        assert s.precision >= 0.97 and s.recall >= 0.97, (s.frame, s.camera, s.precision, s.recall)
        observed = ws.labels(s.camera, s.frame) == 2
        agree = np.all(s.image == OVERLAY_COLORS["agreement"], axis=2)
        assert np.count_nonzero(agree) == pytest.approx(s.recall * np.count_nonzero(observed), abs=0.5)
    moved = shadow_overlays(ws, [PointLight([1.2 + 0.8, 1.3 - 0.8, 3.4])], META)
    assert min(min(s.precision, s.recall) for s in moved) < 0.8


def test_overlay_section_lists_every_camera(ws):
    shadows = shadow_overlays(ws, [LIGHT], META, max_frames=1)
    html = _shadow_overlays_html(shadows)
    assert html.count("data:image/png;base64") == len(ws.camera_names)
    assert "Shadows of frame 0" in html
    assert f"precision {shadows[0].precision:.3f}, recall {shadows[0].recall:.3f}" in html
    assert _shadow_overlays_html([]) == ""
