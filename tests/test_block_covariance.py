"""The honest (time-block sandwich) station covariance: known answers on linear problems,
the graph's white covariance reproduced from its own linear system, what a solve stores.

Bounds and why:
- AR(1) noise of correlation 0.95 between neighbours: the estimate's true variance is
  ~39x the white one (long-run variance factor (1 + rho) / (1 - rho) for a slowly varying
  regressor); the white variance is over 10x too small, the sandwich over 40 blocks of 50
  samples within 0.45-1.25 of the Monte-Carlo spread: it misses the correlation across
  block borders (the correlation time, 20 samples, is not short beside the 50-sample
  block) and the plain estimator reads low by each block's share of the information too
  (measured 0.50-0.55 plain, 0.60-0.65 jackknife; docs/uncertainty.md);
- independent noise: the plain sandwich is 0.7-1.15 of the (exact) white variance
  (measured 0.96-0.99), the jackknife 0.95-1.35 (measured 1.11-1.22: the leave-one-block-out
  estimate is conservative by each block's leverage, most for the end blocks of the slope);
- the jackknife scores (linearised) equal the exact leave-one-block-out estimates of a
  linear problem with one nuisance column per block (the path's states) to 1e-9;
- the white covariance of the graph's own sparse system equals GTSAM's marginal to 1e-6
  relative: same linearisation, same columns.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import gtsam
import numpy as np
import pytest
import scipy.sparse as sp

from lhgraph.estimation.graph.block_covariance import block_length_s, block_sandwich, floor_at
from lhgraph.estimation.graph.linear_system import linear_system
from lhgraph.estimation.graph.options import GraphOptions, UncertaintyOptions
from lhgraph.estimation.graph.solver import solve_graph
from lhgraph.estimation.graph.variables import BOARD_POSE, STATION_POSE, VariableLayout
from lhgraph.estimation.receiver_scale import receiver_scale_covariance
from lhgraph.io.stations import load_stations, save_stations
from lhgraph.sim.simulate import load_simulation_config, simulate

CONFIGS = Path(__file__).resolve().parents[1] / "configs" / "simulation"
N, BLOCKS = 2000, 40


def _regression(rng: np.random.Generator, rho: float, draws: int,
                estimator: str = "jackknife"):
    """Line fits y = a + b s of ``draws`` AR(1) noise series (unit innovations scaled to unit
    variance): the estimates, white covariances and sandwiches (``estimator``'s)."""
    s = np.linspace(-1, 1, N)
    X = np.column_stack([np.ones(N), s, np.sin(3 * s)])
    A = sp.csr_matrix(X)
    block = np.arange(N) // (N // BLOCKS)
    est, whites, sandwiches = [], [], []
    for _ in range(draws):
        e = np.empty(N)
        e[0] = rng.normal()
        innovations = rng.normal(size=N) * np.sqrt(1 - rho**2)
        for i in range(1, N):
            e[i] = rho * e[i - 1] + innovations[i]
        beta = np.linalg.lstsq(X, e, rcond=None)[0]
        white, sandwich, n = block_sandwich(A, e - X @ beta, block, np.arange(3),
                                            estimator=estimator)
        assert n == BLOCKS
        est.append(beta)
        whites.append(white)
        sandwiches.append(sandwich)
    return np.array(est), np.mean(whites, axis=0), np.mean(sandwiches, axis=0)


def test_white_part_is_the_inverse_normal_matrix():
    rng = np.random.default_rng(0)
    X = rng.normal(size=(200, 4))
    white, _, _ = block_sandwich(sp.csr_matrix(X), rng.normal(size=200),
                                 np.arange(200) // 10, np.array([1, 3]),
                                 order=np.array([3, 1, 0, 2]))
    np.testing.assert_allclose(white, np.linalg.inv(X.T @ X)[np.ix_([1, 3], [1, 3])],
                               rtol=1e-10)


def test_sandwich_predicts_the_spread_of_correlated_noise():
    ratios = {}
    for estimator in ("plain", "jackknife"):
        est, white, sandwich = _regression(np.random.default_rng(1), 0.95, 150, estimator)
        spread = np.var(est, axis=0)
        ratios[estimator] = np.diag(sandwich) / spread
        assert np.all((ratios[estimator] > 0.45) & (ratios[estimator] < 1.25)), ratios
        assert np.all(np.diag(white) < spread / 10)
    assert np.all(ratios["jackknife"] > ratios["plain"]), ratios


def test_sandwich_agrees_with_white_on_independent_noise():
    bounds = {"plain": (0.7, 1.15), "jackknife": (0.95, 1.35)}
    for estimator, (low, high) in bounds.items():
        _, white, sandwich = _regression(np.random.default_rng(2), 0.0, 100, estimator)
        ratio = np.diag(sandwich) / np.diag(white)
        assert np.all((ratio > low) & (ratio < high)), (estimator, ratio)


def test_jackknife_is_the_leave_one_block_out_estimate():
    """Three shared parameters and an intercept per block (the path's states): the
    jackknife sandwich equals (C - 1) / C times the scatter of the exact estimates with one
    block (its rows and its own intercept) left out."""
    rng = np.random.default_rng(4)
    blocks, per = 12, 30
    block = np.repeat(np.arange(blocks), per)
    # unequal blocks: the third regressor lives mostly in the first three blocks
    shared = np.column_stack([rng.normal(size=blocks * per), np.linspace(-1, 1, blocks * per),
                              rng.normal(size=blocks * per) * np.where(block < 3, 3.0, 0.3)])
    X = np.column_stack([shared, (block[:, None] == np.arange(blocks)).astype(float)])
    y = rng.normal(size=len(X)) + np.repeat(rng.normal(size=blocks), per)
    beta = np.linalg.lstsq(X, y, rcond=None)[0]
    _, sandwich, n = block_sandwich(sp.csr_matrix(X), y - X @ beta, block, np.arange(3),
                                    order=np.arange(X.shape[1])[::-1])
    left_out = []
    for c in range(blocks):
        rows, cols = block != c, np.r_[0:3, 3 + np.flatnonzero(np.arange(blocks) != c)]
        left_out.append(np.linalg.lstsq(X[np.ix_(rows, cols)], y[rows], rcond=None)[0][:3])
    d = np.array(left_out) - np.mean(left_out, axis=0)
    assert n == blocks
    np.testing.assert_allclose(sandwich, d.T @ d * (blocks - 1) / blocks, rtol=1e-9)
    _, plain, _ = block_sandwich(sp.csr_matrix(X), y - X @ beta, block, np.arange(3),
                                 estimator="plain")
    assert plain[2, 2] < 0.8 * sandwich[2, 2]  # the plain one misses the leverage


def test_a_block_holding_a_direction_alone_gives_a_finite_sandwich():
    rng = np.random.default_rng(5)
    block = np.repeat(np.arange(10), 20)
    X = np.column_stack([rng.normal(size=200), (block == 0) * rng.normal(size=200)])
    _, sandwich, _ = block_sandwich(sp.csr_matrix(X), rng.normal(size=200), block,
                                    np.arange(2))
    assert np.all(np.isfinite(sandwich)) and sandwich[1, 1] > 0


def test_floor_widens_only_where_narrower():
    rng = np.random.default_rng(3)
    M = rng.normal(size=(6, 6))
    floor = M @ M.T + np.eye(6)
    narrow = floor_at(floor, 0.1 * floor)
    np.testing.assert_allclose(narrow, floor, rtol=1e-9)
    wide = floor_at(floor, 4 * floor)
    np.testing.assert_allclose(wide, 4 * floor, rtol=1e-9)
    mixed = floor_at(floor, np.diag([100.0, 0, 0, 0, 0, 0]))
    assert np.linalg.eigvalsh(mixed - floor).min() > -1e-9
    assert mixed[0, 0] >= 100 - 1e-9


def test_block_length_from_the_capture():
    o = UncertaintyOptions()
    assert block_length_s(120.0, o) == pytest.approx(4.0)
    assert block_length_s(6.0, o) == pytest.approx(o.min_block_s)


@pytest.fixture(scope="module")
def simulated():
    cfg = dataclasses.replace(load_simulation_config(CONFIGS / "default.toml"), duration_s=4.0)
    sim = simulate(cfg, 1)
    models = {k: s.model for k, s in sim.truth.stations.items()}
    return sim, models


def test_solve_stores_both_and_white_is_gtsams(simulated):
    sim, models = simulated
    honest = solve_graph(sim.board, sim.angles, models)
    white = solve_graph(sim.board, sim.angles, models, GraphOptions.of(covariance="white"))
    assert honest.diagnostics["covariance_blocks"] >= 2
    for k, s in honest.stations.stations.items():
        if k == honest.stations.reference:
            continue
        w = white.stations.stations[k]
        np.testing.assert_allclose(s.covariance_white, w.covariance, rtol=1e-6)
        np.testing.assert_allclose(w.covariance_white, w.covariance)
        # never narrower than the white one; on white simulated noise not much wider
        assert np.linalg.eigvalsh(s.covariance - s.covariance_white).min() > -1e-12
        ratio = np.trace(s.covariance[3:, 3:]) / np.trace(s.covariance_white[3:, 3:])
        assert 1.0 <= ratio < 4.0, ratio


def test_receiver_scale_covariance_is_the_scaled_position_in_the_stations_frame():
    """A station 3 m out along x, turned 90 deg about z: the world scaled by 1 + k moves it
    by 3k m along world x, which is its own -y; nothing turns."""
    T = np.eye(4)
    T[:3, :3] = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]
    T[:3, 3] = [3.0, 0.0, 0.0]
    C = receiver_scale_covariance(T, 0.01)
    expected = np.zeros((6, 6))
    expected[4, 4] = 0.03**2
    np.testing.assert_allclose(C, expected, atol=1e-15)
    np.testing.assert_array_equal(receiver_scale_covariance(np.eye(4), 0.01), 0.0)


def test_receiver_scale_sigma_widens_the_honest_covariance_only(simulated):
    sim, models = simulated
    base = solve_graph(sim.board, sim.angles, models)
    scaled = solve_graph(sim.board, sim.angles, models,
                         GraphOptions.of(receiver_scale_sigma=0.005))
    assert base.options["uncertainty"]["receiver_scale_sigma"] == 0.0  # many diodes: none
    assert "receiver_scale_sigma" not in base.stations.extra
    assert scaled.stations.extra["receiver_scale_sigma"] == 0.005  # recorded for compare
    for k, s in scaled.stations.stations.items():
        b = base.stations.stations[k]
        np.testing.assert_allclose(s.covariance_white, b.covariance_white, rtol=1e-9)
        np.testing.assert_allclose(s.covariance - b.covariance,
                                   receiver_scale_covariance(s.T_world_lh, 0.005), atol=1e-12)


def test_covariance_white_round_trips_through_the_stations_file(simulated, tmp_path):
    sim, models = simulated
    result = solve_graph(sim.board, sim.angles, models)
    back = load_stations(save_stations(result.stations, tmp_path / "st.toml"))
    for k, s in result.stations.stations.items():
        np.testing.assert_allclose(back.stations[k].covariance, s.covariance)
        np.testing.assert_allclose(back.stations[k].covariance_white, s.covariance_white)


def test_linear_system_reproduces_gtsams_marginals():
    """A small pose graph of board states and stations: the sparse system's white
    covariance equals GTSAM's marginals, and every row of a state's factor is that state's."""
    layout = VariableLayout.of_problem(4, 3)
    rng = np.random.default_rng(4)
    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    noise = gtsam.noiseModel.Diagonal.Sigmas(np.array([0.01, 0.02, 0.01, 0.1, 0.05, 0.2]))
    for k in range(4):
        values.insert(BOARD_POSE.key(k), gtsam.Pose3.Expmap(rng.normal(size=6)))
        graph.add(gtsam.PriorFactorPose3(BOARD_POSE.key(k), gtsam.Pose3(), noise))
    for slot in layout.indices(STATION_POSE):
        values.insert(STATION_POSE.key(slot), gtsam.Pose3.Expmap(rng.normal(size=6)))
        for k in range(4):
            graph.add(gtsam.BetweenFactorPose3(BOARD_POSE.key(k), STATION_POSE.key(slot),
                                               gtsam.Pose3.Expmap(rng.normal(size=6)), noise))
    system = linear_system(graph, values, layout)
    keys = [STATION_POSE.key(s) for s in layout.indices(STATION_POSE)]
    white, _, n = block_sandwich(system.A, system.b, system.row_state, system.columns(keys))
    marginals = gtsam.Marginals(graph, values)
    for i, key in enumerate(keys):
        np.testing.assert_allclose(white[6 * i:6 * i + 6, 6 * i:6 * i + 6],
                                   marginals.marginalCovariance(key), rtol=1e-6)
    assert n == 4
    assert np.array_equal(np.unique(system.row_state), np.arange(4))
