"""The scale-evidence benchmark's helpers (benchmarks/scale_evidence.py) on known answers;
the benchmark itself reads the unlicensed Crazyflie logs and is not run here."""

import numpy as np

from benchmarks.anchored_stations import AnchoringHits
from benchmarks.scale_evidence import robust_slope, sweep_pairs


def _hits(time, station, axis, sensor) -> AnchoringHits:
    n = len(time)
    return AnchoringHits(np.tile(np.eye(4), (n, 1, 1)), np.zeros((n, 3)), np.asarray(station),
                         np.asarray(axis), np.zeros(n), {}, {}, np.zeros(3),
                         np.asarray(time, dtype=float), np.asarray(sensor))


def test_sweep_pairs_pair_only_hits_of_one_sweep():
    # sweep A: sensors 0-3 of station 0, axis 0; sweep B: sensors 0 and 2 of station 1
    # 0.1 ms later (another station: another sweep); sweep C: sensor 1 and 3, 9 ms later
    hits = _hits([0.0, 1e-4, 2e-4, 3e-4, 4e-4, 5e-4, 9e-3, 9.1e-3],
                 [0, 0, 0, 0, 1, 1, 0, 0], [0, 0, 0, 0, 0, 0, 1, 1],
                 [0, 1, 2, 3, 0, 2, 1, 3])
    found = {tuple(p) for p in sweep_pairs(hits)}
    assert found == {(0, 2), (1, 3), (0, 1), (2, 3), (4, 5), (6, 7)}


def test_robust_slope_ignores_outliers_and_gives_a_standard_error():
    rng = np.random.default_rng(3)
    predicted = rng.uniform(-5e-3, 5e-3, 4000)
    measured = 1.006 * predicted + rng.normal(0.0, 5e-5, predicted.size)
    measured[::50] += 0.01
    k, se = robust_slope(measured, predicted)
    assert abs(k - 1.006) < 3 * se
    assert 0 < se < 1e-3
