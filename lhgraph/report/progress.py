"""Progress lines in a user's words: the solvers' messages (optimiser error, motion-prior
statistics) turned into what a user can act on; ``verbose`` keeps the solver's own line."""

from __future__ import annotations

import re
from collections.abc import Callable

_ITERATION = re.compile(r"iteration (\d+): error ([-+.\deE]+)")
_NOISE = re.compile(r"motion prior: .*angle noise ([.\d]+) urad")
_SETTLED = 1e-3
"""Relative decrease of the error below which an iteration counts as settling."""


class PlainProgress:
    """Callable progress printer: ``PlainProgress(print_line)(message)``.

    ``iteration N: error E`` becomes ``iteration N: converging`` (or ``settling`` once the
    error falls by less than 0.1 %); the motion prior's statistics become ``noise level
    learned: X µrad per diode``; other lines pass unchanged. With ``verbose`` the solver's
    line follows in brackets. Units are written as a user reads them (µrad, not urad).
    """

    def __init__(self, emit: Callable[[str], None], verbose: bool = False):
        self.emit, self.verbose = emit, verbose
        self.last_error: float | None = None

    def plain(self, message: str) -> str:
        """The user's wording of one solver message."""
        tail = message.rsplit("] ", 1)[-1]
        head = message[:len(message) - len(tail)]
        if m := _ITERATION.fullmatch(tail):
            error = float(m[2])
            settling = (self.last_error is not None
                        and self.last_error - error <= _SETTLED * abs(self.last_error))
            self.last_error = error
            return f"{head}iteration {m[1]}: {'settling' if settling else 'converging'}"
        if m := _NOISE.match(tail):
            return f"{head}noise level learned: {float(m[1]):.0f} µrad per diode"
        if tail.endswith("solving"):
            self.last_error = None
        return message

    def __call__(self, message: str) -> None:
        text = self.plain(message)
        if self.verbose and text != message:
            text += f"  ({message.rsplit('] ', 1)[-1]})"
        self.emit(text.replace(" urad", " µrad"))
