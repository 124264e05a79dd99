"""Writer process for ``test_rigs_session_kill.py``: records frames until it is killed.

Usage: ``python session_kill_writer.py SESSION_DIR DURABILITY``. Every image is a
deterministic function of (camera, index), so the test can check pixel-exactness of
whatever the reader lists after a SIGKILL at a random instant. The three cameras cover
the three storage paths: 8-bit RGB PNG, 16-bit gray PNG and float32 RGB OpenEXR.
"""

from __future__ import annotations

import sys

import numpy as np

CAMERAS = ["cam0", "cam1", "cam2"]
HEIGHT, WIDTH = 48, 64
BACKGROUNDS = 3
MAX_FRAMES = 100_000


def expected_image(camera: str, index: int, background: bool = False) -> np.ndarray:
    """The image the writer writes for ``camera`` at ``index`` (frame or background)."""
    k = CAMERAS.index(camera)
    rng = np.random.default_rng([index, k, int(background)])
    if k == 0:
        return rng.integers(0, 256, (HEIGHT, WIDTH, 3), dtype=np.uint8)
    if k == 1:
        return rng.integers(0, 65536, (HEIGHT, WIDTH), dtype=np.uint16)
    return rng.random((HEIGHT, WIDTH, 3), dtype=np.float32)


def expected_timestamp(camera: str, index: int) -> int:
    return 1_000_000_000 + index * 16_666_667 + CAMERAS.index(camera)


def main(path: str, durability: str) -> None:
    from rigs.session import SessionWriter

    writer = SessionWriter.create(path, CAMERAS, rig="kill-test", fps=60.0, durability=durability)
    for b in range(BACKGROUNDS):
        for cam in CAMERAS:
            writer.write_background(cam, b, expected_image(cam, b, background=True))
    for i in range(MAX_FRAMES):
        writer.write_frame(
            i,
            {cam: expected_image(cam, i) for cam in CAMERAS},
            timestamps_ns={cam: expected_timestamp(cam, i) for cam in CAMERAS},
            frame_ids={cam: i + 7 for cam in CAMERAS},
        )
    writer.close()


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
