"""A software trigger fanned out to every camera of a rig from one host timer.

With ``trigger: {mode: software}`` each GenICam camera waits for ``TriggerSoftware``. One
:class:`SoftwareTrigger` per rig (kept in the backends' ``shared`` dict) fires it on every
armed camera at ``rate_hz``, tick ``k`` at ``t0 + k / rate_hz`` (no drift from sleep
overshoot; a tick that falls more than one period behind is skipped and counted in
``missed``), and two ticks are never closer than half a period (a camera still reading out
the last frame would merge or refuse a trigger that comes too soon). It waits until all ``expected`` cameras are armed, so every camera sees the same
first trigger and their frame counters agree, and it stops firing as soon as one disarms.
The thread is a daemon: it never outlives the process, and it holds no camera after
:meth:`disarm`.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

__all__ = ["SoftwareTrigger", "shared_trigger"]

log = logging.getLogger(__name__)


class SoftwareTrigger:
    """Fire ``fire()`` callbacks of ``expected`` armed cameras together at ``rate_hz``."""

    def __init__(self, rate_hz: float, expected: int):
        if not rate_hz > 0:
            raise ValueError(f"SoftwareTrigger rate_hz must be > 0, got {rate_hz}")
        self.period_s = 1.0 / float(rate_hz)
        self.expected = int(expected)
        self._armed: dict[str, Callable[[], None]] = {}
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._thread: threading.Thread | None = None
        self._stop = False
        self.fired = 0
        self.missed = 0
        self.errors: list[str] = []

    def arm(self, camera: str, fire: Callable[[], None]) -> None:
        """Add a started camera; firing begins when all ``expected`` cameras are armed."""
        with self._lock:
            self._armed[camera] = fire
            if len(self._armed) == self.expected and self._thread is None:
                self._stop = False
                self.fired = 0
                self._thread = threading.Thread(target=self._run, name="software-trigger", daemon=True)
                self._thread.start()

    def disarm(self, camera: str) -> None:
        """Remove a camera (before it stops); the timer stops with the first disarm."""
        with self._lock:
            self._armed.pop(camera, None)
            thread, self._thread = self._thread, None
            self._stop = True
        self._wake.set()
        if thread is not None and thread is not threading.current_thread():
            thread.join()
        self._wake.clear()

    def _run(self) -> None:
        t0 = time.monotonic()
        k = 0
        while True:
            with self._lock:
                if self._stop:
                    return
                targets = list(self._armed.items())
            for name, fire in targets:
                try:
                    fire()
                except Exception as exc:  # one camera's failure must not stop the others' triggers
                    msg = f"camera {name!r}: TriggerSoftware failed: {exc}"
                    if len(self.errors) < 16:
                        self.errors.append(msg)
                    log.error(msg)
            self.fired += 1
            fired_at = time.monotonic()
            k += 1
            late = fired_at - (t0 + k * self.period_s)
            if late > self.period_s:
                skip = int(late // self.period_s)
                self.missed += skip
                k += skip
            due = max(t0 + k * self.period_s, fired_at + 0.5 * self.period_s)
            if self._wake.wait(max(0.0, due - time.monotonic())):
                return


def shared_trigger(shared: dict | None, rate_hz: float, expected: int) -> SoftwareTrigger:
    """The rig's one :class:`SoftwareTrigger` (created on first use, kept in ``shared``)."""
    if shared is None:
        return SoftwareTrigger(rate_hz, 1)
    key = ("software_trigger",)
    if key not in shared:
        shared[key] = SoftwareTrigger(rate_hz, expected)
    return shared[key]
