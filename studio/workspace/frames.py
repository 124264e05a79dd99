"""Frame selections as users type them: ``START:STOP[:STEP]`` or ``1,4,9`` (one parser for every command).

>>> select_frames("2:8:3", range(10))
[2, 5]
>>> select_frames("4,1,4", range(10))
[4, 1]
"""

from __future__ import annotations

import logging
from collections.abc import Iterable

__all__ = ["FrameSelectionError", "select_frames"]

log = logging.getLogger(__name__)


class FrameSelectionError(ValueError):
    """A frame selection that cannot be read, or selects nothing; the message says what is expected."""


def _int(text: str, spec: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise FrameSelectionError(f"--frames {spec!r}: {text!r} is not an integer "
                                  "(expected START:STOP[:STEP] or a comma list like 1,2,3)") from None


def select_frames(spec: str | None, available: Iterable[int]) -> list[int] | None:
    """The frames of ``available`` that ``spec`` names, in the order given (None: all).

    ``START:STOP[:STEP]``: frame indices from START (inclusive) to STOP (exclusive), every STEP-th
    (STEP ≥ 1; an empty START/STOP means the first/last). A comma list names frames one by one;
    a frame named twice is fitted once (the repeat is dropped with a warning). Frames that are not
    in ``available`` are an error, as is a selection of no frame.
    """
    if spec is None:
        return None
    available = list(available)
    text = spec.strip()
    if ":" in text:
        parts = text.split(":")
        if len(parts) > 3:
            raise FrameSelectionError(f"--frames {spec!r}: expected START:STOP[:STEP]")
        start = _int(parts[0], spec) if parts[0].strip() else None
        stop = _int(parts[1], spec) if parts[1].strip() else None
        step = _int(parts[2], spec) if len(parts) > 2 and parts[2].strip() else 1
        if step < 1:
            raise FrameSelectionError(f"--frames {spec!r}: STEP must be a positive integer, got {step}")
        if start is not None and stop is not None and stop <= start:
            raise FrameSelectionError(f"--frames {spec!r}: STOP ({stop}) must be greater than START ({start}); "
                                      "STOP is excluded")
        first = start if start is not None else (min(available) if available else 0)
        chosen = [i for i in sorted(available) if i >= first and (stop is None or i < stop) and (i - first) % step == 0]
    else:
        listed = [_int(v.strip(), spec) for v in text.split(",") if v.strip()]
        chosen = list(dict.fromkeys(listed))
        if len(chosen) < len(listed):
            log.warning("--frames %r: %d repeated frame(s) dropped", spec, len(listed) - len(chosen))
        missing = [i for i in chosen if i not in set(available)]
        if missing:
            raise FrameSelectionError(f"--frames {spec!r}: frame(s) {missing} are not complete frames of the session")
    if not chosen:
        raise FrameSelectionError(f"--frames {spec!r} selects no frame (the session has {len(available)})")
    return chosen
