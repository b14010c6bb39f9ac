"""The deck's pulse clock against the Crazyflie log's (lhgraph.importers.crazyflie.clock)."""

import numpy as np
import pytest

from lhgraph.importers.crazyflie.clock import FPGA_HZ, FPGA_WRAP, deck_clock
from lhgraph.importers.crazyflie.usdlog import UsdLog


def _log(deck_s: np.ndarray, log_s: np.ndarray) -> UsdLog:
    frames = np.zeros(len(deck_s), dtype=[("id", "<u2"), ("timestamp", "<u8"),
                                          ("timestampFPGA", "<u4")])
    frames["timestamp"] = np.round(log_s * 1e6).astype(np.uint64)
    frames["timestampFPGA"] = (np.round(deck_s * FPGA_HZ).astype(np.int64) % FPGA_WRAP)
    return UsdLog(2, (), {"lhUartFrame": frames})


def test_deck_clock_finds_a_slow_log_clock_through_wraps_gaps_and_jitter():
    rng = np.random.default_rng(7)
    deck = np.sort(rng.uniform(0.0, 40.0, 20000))
    deck = deck[(deck < 12.0) | (deck > 13.5)]  # a 1.5 s gap: two wraps hidden in it
    log = 5.0 + deck / 1.011 + rng.uniform(0.0, 1e-3, deck.size)  # read up to 1 ms late
    log[::97] += 0.02  # some read much later
    order = np.argsort(log + rng.normal(0.0, 2e-4, deck.size))  # logged out of order
    clock = deck_clock(_log(deck[order], log[order]))
    assert clock.scale == pytest.approx(1.011, abs=2e-5)
    assert clock.plausible and clock.frames > 0.9 * deck.size
    assert "1.09 % slow" in clock.line()


def test_deck_clock_needs_frames_and_refuses_a_counter_of_another_rate():
    t = np.linspace(0.0, 10.0, 50)
    assert deck_clock(_log(t, t)) is None
    t = np.linspace(0.0, 10.0, 5000)
    other = deck_clock(_log(t * 2.0, t))
    assert other.scale == pytest.approx(2.0, rel=1e-4) and not other.plausible
    assert "not applied" in other.line()
