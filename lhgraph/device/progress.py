"""Progress of a capture and its download: the callback type and a text progress bar."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

Progress = Callable[[str, int, int], None]
"""``progress(phase, done, total)``; phase is ``"capture"`` (samples) or ``"download"``
(bytes)."""


class ProgressBar:
    """A one-line text progress bar on a stream (stderr by default)."""

    def __init__(self, stream: Any = None, width: int = 30):
        import sys

        self.stream = stream if stream is not None else sys.stderr
        self.width = width
        self._phase = ""
        self._last = (-1.0, "")
        self._t0 = time.monotonic()
        self._tty = bool(getattr(self.stream, "isatty", lambda: False)())

    def __call__(self, phase: str, done: int, total: int) -> None:
        """Draw the bar (a new line per phase)."""
        if phase != self._phase:
            if self._phase:
                self.stream.write("\n")
            self._phase = phase
            self._t0 = time.monotonic()
        frac = done / total if total else 1.0
        now = time.monotonic()
        step = 0.01 if self._tty else 0.25
        if frac < 1.0 and (frac - self._last[0] < step and self._last[1] == phase):
            return
        self._last = (frac, phase)
        filled = int(self.width * frac)
        unit = "samples" if phase == "capture" else "bytes"
        line = (f"{phase:8s} [{'#' * filled}{'.' * (self.width - filled)}] {frac * 100:5.1f}% "
                f"{done}/{total} {unit} {now - self._t0:5.1f} s")
        self.stream.write(("\r" if self._tty else "") + line + ("" if self._tty else "\n"))
        self.stream.flush()

    def close(self) -> None:
        """End the bar's line."""
        if self._phase and self._tty:
            self.stream.write("\n")
            self.stream.flush()
