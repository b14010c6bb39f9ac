"""How a Crazyflie Lighthouse deck logs its hits (docs/simulator.md, "Deck logging").

The deck does not time-stamp each hit: the firmware logs a station's two sweeps of one rotor
cycle together, one event per (sensor, axis) a few microseconds apart, at the moment it
hands the frame over, and keeps only part of the cycles. :func:`log_like_deck` turns the
simulator's hits (exact decoded times) into such a log: cycles dropped, sweeps that lose one
half of the board, and every hit of a logged cycle stamped at the log instant.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from lhgraph.config import check_fields, option

TIMESTAMPS = ("hit", "deck")


@dataclass(frozen=True)
class LoggingConfig:
    """The ``[logging]`` table of a simulation config (defaults: every hit, exact times).

    ``timestamps``: ``"hit"`` (each hit at its decoded time) or ``"deck"`` (the deck's log:
    a station's two sweeps of a cycle stamped together ``latency_ms`` after the centre of its
    axis-1 sweep, plus Gaussian ``jitter_ms`` per cycle, events ``event_spacing_us`` apart);
    ``cycle_fraction``: fraction of (station, rotor cycle) pairs logged; ``side_loss_fraction``:
    fraction of sweeps that lose the diodes of one half of the board (board x < 0 or > 0,
    chosen at random). Only ``"deck"`` applies the last four.
    """

    timestamps: str = option("hit", choices=TIMESTAMPS)
    latency_ms: float = option(0.5, ge=0, le=20)
    jitter_ms: float = option(0.3, ge=0, le=10)
    event_spacing_us: float = option(10.0, ge=0, le=100)
    cycle_fraction: float = option(1.0, gt=0, le=1)
    side_loss_fraction: float = option(0.0, ge=0, le=1)

    def __post_init__(self) -> None:
        check_fields(self)


def log_like_deck(config: LoggingConfig, k: NDArray[np.int64], phase: int, slot_s: float,
                  board_x: NDArray[np.float64], sensor: NDArray[np.int64],
                  axis: NDArray[np.int64], sweep_centre_s: NDArray[np.float64],
                  rng: np.random.Generator) -> tuple[NDArray[np.bool_], NDArray[np.float64]]:
    """Which hits the deck logs, and the stamps (s) of those kept.

    Per hit: slot ``k`` (slot k is swept on axis ``(k + phase) % 2`` by the station of
    ``(k + phase) // 2``; the two slots of one such pair are that station's rotor cycle),
    the diode's board ``x`` (m), its ``sensor`` id and ``axis``, and ``sweep_centre_s``, the
    time its slot's sweep passes angle 0 (sync start + T/4); ``slot_s`` = T/2 on the board
    clock. A logged cycle is stamped at its axis-1 sweep's centre + latency + jitter.
    """
    cycle = (k + phase) // 2
    cycles, inv = np.unique(cycle, return_inverse=True)
    kept_cycle = rng.random(len(cycles)) < config.cycle_fraction
    jitter = rng.normal(0.0, config.jitter_ms * 1e-3, len(cycles))
    slots, slot_inv = np.unique(k, return_inverse=True)
    lose = rng.random(len(slots)) < config.side_loss_fraction
    side = rng.choice([-1.0, 1.0], len(slots))
    lost = lose[slot_inv] & (np.sign(board_x) == side[slot_inv])
    keep = kept_cycle[inv] & ~lost
    inv, axis, sensor = inv[keep], axis[keep], sensor[keep]
    axis_1_centre = sweep_centre_s[keep] + np.where(axis == 1, 0.0, slot_s)
    # every event of a cycle in the deck's order (sensor, then axis), a few us apart
    order = np.lexsort((axis, sensor, inv))
    rank = np.empty(len(inv), dtype=np.int64)
    rank[order] = np.arange(len(inv)) - np.searchsorted(inv[order], inv[order])
    first = np.full(len(cycles), np.inf)
    np.minimum.at(first, inv, axis_1_centre)
    stamp = (first[inv] + config.latency_ms * 1e-3 + jitter[inv]
             + rank * config.event_spacing_us * 1e-6)
    return keep, stamp
