"""Light pulses on the photodiode lines, in sample indices of the board's clock.

The simulator produces them (sync flashes and laser sweeps as each sensor sees them); the
capture writer turns them into the ``.lhcap`` edge records a real board would record; the
decoder recovers them from edges.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray


@dataclass
class LightPulses:
    """Pulses seen by sensors: ``sensor`` id, ``start`` and ``end`` sample (end exclusive).

    ``kind`` says what caused the pulse (0 sync flash, 1 laser sweep, 2 reflection), for
    tests and diagnostics; a decoder never relies on it.
    """

    sensor: NDArray[np.int64]
    start: NDArray[np.int64]
    end: NDArray[np.int64]
    kind: NDArray[np.int64]

    SYNC = 0
    SWEEP = 1
    REFLECTION = 2

    def __len__(self) -> int:
        return len(self.sensor)

    def sorted(self) -> LightPulses:
        """Pulses ordered by start sample (then sensor)."""
        order = np.lexsort((self.sensor, self.start))
        return LightPulses(self.sensor[order], self.start[order], self.end[order],
                           self.kind[order])
