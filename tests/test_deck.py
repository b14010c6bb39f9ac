"""Few-diode receivers (the Crazyflie Lighthouse deck): simulated deck logs, the sweep
retiming, the planar twins and their Viterbi, the few-diode initialiser and a deck solve."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from lhgraph.errors import InputError, SolverError
from lhgraph.estimation.graph.optimizer import LMParams
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.graph.resolve import (
    FEW_DIODE_CALIBRATION,
    STEP_TOLERANCE_SIGMA,
    few_diode,
    prepare,
    resolve_options,
)
from lhgraph.estimation.graph.solver import solve_graph
from lhgraph.estimation.init.few_diode import FewDiodeInitialiser
from lhgraph.estimation.init.pnp import board_poses, planar_twins
from lhgraph.estimation.init.twins import resolve_twins
from lhgraph.estimation.problem import build_problem
from lhgraph.estimation.sweep_times import co_logged_fraction, retime_cycles, rotor_grid
from lhgraph.geometry.transforms import inverse, make_pose, rotation_angle, so3_exp
from lhgraph.model.boards import crazyflie_deck
from lhgraph.model.station import ideal_angles
from lhgraph.sim.config import SimulationConfig, parse_simulation_config
from lhgraph.sim.simulate import load_simulation_config, simulate

DECK = Path(__file__).parents[1] / "configs" / "simulation" / "deck.toml"


@pytest.fixture(scope="module")
def deck_capture():
    """A 20 s deck capture with the shipped deck config's character."""
    config = replace(load_simulation_config(DECK), duration_s=20.0)
    return simulate(config, seed=3)


def test_deck_log_character(deck_capture):
    cap = deck_capture
    a = cap.angles
    key = a.extra["sweep"] * 4 + a.lighthouse
    _, count = np.unique(key, return_counts=True)
    assert 3.0 < count.mean() < 3.8  # ~3.3-3.8 diodes per sweep on the real log
    # about half the sweeps logged: each station/axis is swept at 30 Hz
    assert 0.4 < len(count) / (4 * 20.0 * 30) < 0.6
    fraction = co_logged_fraction(a)
    assert min(fraction.values()) > 0.95
    assert np.all(np.diff(a.time) >= 0)


def test_few_diode_stopping_rule_when_calibrating_and_when_tracking(deck_capture):
    """Calibrating a deck tests the states' median step and the stations within a quarter
    sigma (the stations have their own test, their steps shrink unevenly); tracking tests
    95 % of the states (the path is the product) and the root variables as any solve does;
    a user's settings are kept and many-diode data keeps every state and 0.05 sigma."""
    angles = deck_capture.angles
    _, facts = prepare(angles, GraphOptions())
    assert facts.few_diode
    resolved = resolve_options(GraphOptions(), facts)
    calibrating = resolved.options.optimizer
    assert resolved.options.noise.angle_sigma_rad == GraphOptions().noise.few_diode_sigma_rad
    assert any(line.startswith("angle_sigma_rad = 6.5e-05 (few-diode data")
               for line in resolved.applied)  # the override is said, not hidden
    assert calibrating.board_step_quantile == FEW_DIODE_CALIBRATION.board_step_quantile
    assert calibrating.board_step_quantile == 0.5
    assert calibrating.step_tolerance_sigma == FEW_DIODE_CALIBRATION.step_tolerance_sigma
    assert calibrating.step_tolerance_sigma == 0.25
    tracking = resolve_options(GraphOptions(), facts, tracking=True).options.optimizer
    assert tracking.board_step_quantile == 0.95
    assert tracking.step_tolerance_sigma == STEP_TOLERANCE_SIGMA == 0.05
    given = GraphOptions.of(board_step_quantile=0.8, step_tolerance_sigma=0.0)
    chosen = resolve_options(given, facts)
    assert chosen.options.optimizer.board_step_quantile == 0.8
    assert chosen.options.optimizer.step_tolerance_sigma == 0.0
    assert not any("step" in line for line in chosen.applied)  # the user's kept, unsaid
    board = simulate(SimulationConfig(duration_s=1.0), seed=1)  # the 32-diode board
    _, many_facts = prepare(board.angles, GraphOptions())
    many = resolve_options(GraphOptions(), many_facts)
    assert not many_facts.few_diode and many.options.optimizer.board_step_quantile == 1.0
    assert LMParams.from_options(many.options).step_tolerance_sigma == STEP_TOLERANCE_SIGMA
    assert any(line.startswith("step_tolerance_sigma = 0.05") for line in many.applied)
    with pytest.raises(ValueError, match="resolved"):
        LMParams.from_options(GraphOptions())  # the rule is applied once, never skipped


def test_logging_options_checked():
    with pytest.raises(InputError, match="logging.cycle_fraction"):
        parse_simulation_config({"logging": {"cycle_fraction": 0.0}}, "sim.toml")
    with pytest.raises(InputError, match="logging.timestamps"):
        parse_simulation_config({"logging": {"timestamps": "late"}}, "sim.toml")


def test_retime_recovers_hit_times(deck_capture):
    cap = deck_capture
    exact = simulate(replace(cap.config, logging=replace(cap.config.logging,
                                                         timestamps="hit")), seed=3).angles
    retimed = retime_cycles(cap.angles)
    assert len(retimed) == len(cap.angles)
    # the same hits (same decoded angles): retimed = exact hit time + the log's common delay
    # (angles repeat across sweeps at 24 MHz: the nearest hit of the same station and angle)
    truth: dict[tuple, list[float]] = {}
    for key, t in zip(zip(exact.lighthouse.tolist(), exact.angle.tolist(), strict=True),
                      exact.time.tolist(), strict=True):
        truth.setdefault(key, []).append(t)
    t_true = np.array([min(truth[k], key=lambda t, r=r: abs(t - r)) for k, r in zip(
        zip(retimed.lighthouse.tolist(), retimed.angle.tolist(), strict=True),
        retimed.time.tolist(), strict=True)])
    err = retimed.time - t_true
    delay = np.median(err)
    assert abs(delay - cap.config.logging.latency_ms * 1e-3) < 1e-4
    # the per-cycle jitter (0.3 ms) is gone: every hit within 0.1 ms after the common delay
    assert np.percentile(np.abs(err - delay), 99) < 1e-4
    # one board state per logged cycle: both sweeps of a station's cycle share it
    assert len(np.unique(retimed.extra["sweep"])) < 0.6 * len(np.unique(
        cap.angles.extra["sweep"] * 4 + cap.angles.lighthouse))


def test_hit_stamped_captures_not_few_diode():
    cap = simulate(parse_simulation_config({"duration_s": 2.0}, "sim.toml"), seed=1)
    assert max(co_logged_fraction(cap.angles).values()) < 0.05
    assert not few_diode(cap.angles)


def test_hit_timed_deck_gets_the_same_cycles(deck_capture):
    # the deck's hits at their hit times (what lhgraph import crazyflie writes): the same
    # rotor-grid times (but for the log's common delay) and board states as from the stamps
    cap = deck_capture
    from_stamps = retime_cycles(cap.angles)
    # per-cycle scheduling jitter (0.3 ms) on the hit times, as the log's stamps carry
    jitter = np.random.default_rng(4).normal(0, 3e-4, from_stamps.extra["sweep"].max() + 1)
    t = from_stamps.time + jitter[from_stamps.extra["sweep"]]
    order = np.argsort(t, kind="stable")
    hit_timed = from_stamps.select(order)
    hit_timed.time, hit_timed.extra = t[order], {}
    again = retime_cycles(hit_timed)
    assert max(co_logged_fraction(hit_timed).values()) < 0.05
    assert len(np.unique(again.extra["sweep"])) == len(np.unique(from_stamps.extra["sweep"]))
    assert np.percentile(np.abs(np.sort(again.time) - np.sort(from_stamps.time)), 99) < 1e-4


def test_rotor_grid_removes_jitter_and_keeps_outliers():
    rng = np.random.default_rng(0)
    n = np.sort(rng.choice(4000, 1500, replace=False))
    truth = 0.3 + n * (1 / 30) * (1 - 0.011)  # a receiver clock 1.1 % slow
    stamps = truth + rng.normal(0, 3e-4, len(n))
    stamps[100] += 0.016  # logged half a cycle late
    grid = rotor_grid(stamps)
    ok = np.arange(len(n)) != 100
    assert np.max(np.abs(grid[ok] - truth[ok])) < 5e-5
    assert grid[100] == stamps[100]


def _deck_views(n: int, rng: np.random.Generator):
    """n deck poses ~3 m in front of a station and their ideal angles."""
    board = crazyflie_deck()
    rot = so3_exp(rng.normal(0, 0.4, (n, 3))) @ so3_exp(np.tile([0, -np.pi / 2, 0], (n, 1)))
    T = make_pose(rot, np.c_[rng.uniform(2.5, 3.5, n), rng.uniform(-0.5, 0.5, (n, 2))])
    p = np.einsum("nij,sj->nsi", T[:, :3, :3], board.positions) + T[:, None, :3, 3]
    ang = ideal_angles(p.reshape(-1, 3)).reshape(n, 4, 2)
    return board, T, ang


def test_planar_twins_contain_the_truth_and_board_poses_unchanged():
    rng = np.random.default_rng(1)
    board, T, ang = _deck_views(50, rng)
    tw = planar_twins(ang[..., 0], ang[..., 1], board.positions, board.normals)
    err = np.stack([rotation_angle(np.swapaxes(tw.T_lh_board[:, j, :3, :3], 1, 2)
                                   @ T[:, :3, :3]) for j in (0, 1)], axis=1)
    assert np.all(np.min(err, axis=1) < 1e-4)
    # the default PnP needs 5 diodes: a 4-diode deck gives it nothing
    assert not board_poses(ang[..., 0], ang[..., 1], board.positions, board.normals).valid.any()


def test_resolve_twins_follows_the_smooth_chain():
    rng = np.random.default_rng(2)
    M = 200
    t = np.arange(M) * 0.033
    R_true = so3_exp(np.c_[np.sin(t), 0.5 * np.cos(2 * t), 0.2 * t])
    R_wrong = so3_exp(np.c_[np.sin(t) + 1.2, 0.5 * np.cos(2 * t) - 0.8, 0.2 * t])
    swap = rng.random(M) < 0.5  # which slot holds the truth is arbitrary per measurement
    R = np.stack([np.where(swap[:, None, None], R_wrong, R_true),
                  np.where(swap[:, None, None], R_true, R_wrong)], axis=1)
    # the fit prefers the truth slightly, but the wrong twin on 30 % of the measurements
    prefer_truth = rng.random(M) >= 0.3
    cost_true = np.where(prefer_truth, 0.0, 1.0)
    emission = np.where(swap[:, None], np.c_[1.0 - cost_true, cost_true],
                        np.c_[cost_true, 1.0 - cost_true])
    choice = resolve_twins(t, R, emission, 0.3)
    assert np.all(choice == swap.astype(int))
    # an impossible twin (inf) is never chosen; rows with neither possible get -1
    e = np.zeros((M, 2))
    e[::3, 0] = np.inf
    e[5] = np.inf
    choice = resolve_twins(t, R, e, 0.3)
    assert choice[5] == -1 and np.all(choice[::3] == 1)


def test_few_diode_initialiser_near_truth(deck_capture):
    cap = deck_capture
    angles = retime_cycles(cap.angles)
    models = {i: cap.truth.stations[i].model for i in cap.truth.indices()}
    problem = build_problem(cap.board, angles, models, 0)
    init = FewDiodeInitialiser()(cap.board, angles, problem)
    E = inverse(cap.truth.stations[1].T_world_lh) @ init.L[1]
    assert np.linalg.norm(E[:3, 3]) < 0.15
    assert np.degrees(rotation_angle(E[:3, :3])) < 3.0


def test_deck_solve_calibrates(deck_capture):
    cap = deck_capture
    models = {i: cap.truth.stations[i].model for i in cap.truth.indices()}
    res = solve_graph(cap.board, cap.angles, models)
    assert res.status == "converged"
    E = inverse(cap.truth.stations[1].T_world_lh) @ res.stations.stations[1].T_world_lh
    assert np.linalg.norm(E[:3, 3]) < 0.01
    assert np.degrees(rotation_angle(E[:3, :3])) < 0.2
    assert not res.warnings


def test_deck_seen_by_one_station_is_refused(deck_capture):
    cap = deck_capture
    a = cap.angles
    one = a.select(a.lighthouse == 0)
    models = {i: cap.truth.stations[i].model for i in cap.truth.indices()}
    with pytest.raises(SolverError, match="need at least two"):
        solve_graph(cap.board, one, models)


def test_cross_station_cost_with_one_measurement_of_the_other_station():
    # the other station's path has a single measurement: every twin is compared with it
    from lhgraph.estimation.init.few_diode import cross_station_cost
    from lhgraph.estimation.init.twins import TwinPath

    R = so3_exp(np.array([[0.2, -0.1, 0.3]]))[0]  # the board at rest
    T = np.repeat(np.eye(4)[None, None], 3, axis=0).repeat(2, axis=1)
    T[:, 0, :3, :3] = R
    T[:, 1, :3, :3] = R @ so3_exp(np.array([[0.0, 1.0, 0.0]]))[0]  # its mirror for station 0
    T_other = T[1:2].copy()  # station 1's mirror is another one (its own line of sight)
    T_other[0, 1, :3, :3] = R @ so3_exp(np.array([[1.0, 0.0, 0.0]]))[0]
    own = TwinPath(np.array([0.0, 0.1, 0.2]), T, np.zeros((3, 2)), np.zeros((3, 2)))
    other = TwinPath(np.array([0.1]), T_other, np.zeros((1, 2)), np.zeros((1, 2)))
    L = np.repeat(np.eye(4)[None], 2, axis=0)
    cost = cross_station_cost([own, other], L, 0, sigma_rad=0.15, max_gap_s=0.5)
    assert cost.shape == (3, 2)
    assert np.all(cost[:, 0] < 1e-12)  # the true orientation is common to both stations
    assert np.all(cost[:, 1] > 30)  # the mirror twins are 1 rad apart: (1 / 0.15)^2 = 44


def test_partial_view_cost_prefers_the_true_twin(deck_capture):
    # the other station's few-diode sweeps near each measurement tell its twins apart, and
    # with that cost the Viterbi keeps fewer wrong twins
    from lhgraph.estimation.init.few_diode import (
        cross_station_cost,
        partial_view_cost,
        station_twins,
    )

    cap = deck_capture
    angles = retime_cycles(cap.angles)
    models = {i: cap.truth.stations[i].model for i in cap.truth.indices()}
    problem = build_problem(cap.board, angles, models, 0)
    init = FewDiodeInitialiser()
    twins = station_twins(cap.board, angles, problem)
    T0 = cap.truth.pose(0)
    L = np.stack([inverse(T0) @ cap.truth.pose(s) for s in problem.station_ids])
    wrong = {}
    for slot, tw in enumerate(twins):
        R_true = (inverse(L[slot]) @ inverse(T0) @ cap.trajectory.at(tw.time))[:, :3, :3]
        err = np.degrees(rotation_angle(np.swapaxes(R_true[:, None], -1, -2)
                                        @ tw.T_lh_board[..., :3, :3]))  # (M, 2)
        cost = partial_view_cost(twins, problem, L, slot, 3e-4, 0.05)
        clear = (np.nanmin(err, axis=1) < 5) & (np.nanmax(err, axis=1) > 30)
        seen = clear & (cost.max(axis=1) > 0) & np.isfinite(cost).all(axis=1)
        true_twin = np.nanargmin(err, axis=1)
        assert seen.sum() > 100
        own = cost[np.arange(len(err)), true_twin]
        other = cost[np.arange(len(err)), 1 - true_twin]
        assert np.mean(own[seen] < other[seen]) > 0.9
        cross = cross_station_cost(twins, L, slot, init.cross_sigma_rad, init.cross_max_gap_s,
                                   init.turn_sigma)
        for name, e in (("without", tw.emission + cross), ("with", tw.emission + cross + cost)):
            choice = resolve_twins(tw.time, tw.T_lh_board[..., :3, :3], e, init.turn_sigma)
            picked = err[np.arange(len(err)), np.maximum(choice, 0)]
            wrong[name] = wrong.get(name, 0) + int(np.sum((picked > 10) & (choice >= 0)))
    assert wrong["with"] < 0.75 * wrong["without"]  # 57 against 99
