"""LH2 calibration on simulated captures: two stations, and a room of four stations that do
not all see the board at once (the initialiser chains them to the reference)."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from lhgraph.errors import SolverError
from lhgraph.estimation.graph.solver import solve_graph
from lhgraph.estimation.init.pnp_kabsch import chain_to_reference, join_paths, overlap_tree
from lhgraph.estimation.metrics import station_errors
from lhgraph.geometry.transforms import inverse, so3_exp
from lhgraph.model.boards import board_by_name
from lhgraph.sim.simulate import load_simulation_config, simulate

CONFIGS = Path(__file__).resolve().parent.parent / "configs"


def _solve(config, seed: int):
    sim = simulate(config, seed)
    result = solve_graph(sim.board, sim.angles,
                         {k: s.model for k, s in sim.truth.stations.items()})
    return sim, result


def test_two_lh2_stations_within_a_millimetre():
    sim, result = _solve(load_simulation_config(CONFIGS / "sim_lh2.toml"), 3)
    (err,) = station_errors(sim.truth, result.stations)
    assert err.position_norm_m < 1e-3
    assert np.degrees(err.rotation_rad) < 0.02
    assert result.status == "converged"


def test_four_station_room_chained_to_the_reference():
    config = dataclasses.replace(load_simulation_config(CONFIGS / "simulation/lh2_room4.toml"),
                                 duration_s=20.0)
    sim, result = _solve(config, 2)
    # the reference (0) and the station opposite it (2) never see the board together
    a = sim.angles
    t0, t2 = a.time[a.lighthouse == 0], a.time[a.lighthouse == 2]
    gap = np.abs(t0[np.clip(np.searchsorted(t0, t2), 0, len(t0) - 1)] - t2)
    assert np.min(gap) > 0.05
    errors = station_errors(sim.truth, result.stations)
    assert [e.station for e in errors] == [1, 2, 3]
    for e in errors:
        assert e.position_norm_m < 3e-3, e
        assert np.degrees(e.rotation_rad) < 0.05, e
    assert result.status == "converged"
    assert not result.warnings


def test_overlap_tree_star_chain_and_unlinked():
    # every station overlaps the reference: all joined to it (LH1 behaviour kept), even
    # where a stronger link between two others exists
    star = np.array([[0, 5, 4], [5, 0, 90], [4, 90, 0]])
    assert overlap_tree(star) == [0, 0, 0]
    # station 2 never with the reference: every station joined through the chain whose
    # weakest link is strongest (3 through 1 and 2, weakest 30, not straight to 0 with 8)
    chain = np.array([[0, 50, 0, 8], [50, 0, 30, 9], [0, 30, 0, 40], [8, 9, 40, 0]])
    assert overlap_tree(chain) == [0, 0, 1, 2]
    # station 2 seen with nobody: unlinked
    alone = np.array([[0, 50, 0], [50, 0, 2], [0, 2, 0]])
    assert overlap_tree(alone) == [0, 0, -1]


def _paths(windows, L, rms=1e-4):
    """Paths ``(times, T_lh_board, rms)`` of stations ``L`` (S, 4, 4) seeing a board that
    moves and turns along a known path, each within its time window."""
    out = []
    for (lo, hi), T_world_lh in zip(windows, L, strict=True):
        t = np.arange(lo, hi, 0.02)
        T = np.repeat(np.eye(4)[None], len(t), axis=0)
        T[:, :3, :3] = so3_exp(np.c_[0.3 * np.sin(t), 0.2 * np.cos(t), 0.1 * t])
        T[:, :3, 3] = np.c_[np.cos(t), np.sin(t), 2 + 0.1 * t]
        out.append((t, inverse(T_world_lh) @ T, np.full(len(t), rms)))
    return out


def test_join_paths_chains_and_names_an_unlinked_station():
    board = board_by_name("paper32")
    rng = np.random.default_rng(0)
    L = np.repeat(np.eye(4)[None], 4, axis=0)
    L[1:, :3, :3] = so3_exp(rng.normal(0, 0.5, (3, 3)))
    L[1:, :3, 3] = rng.normal(0, 2, (3, 3))
    problem = SimpleNamespace(station_ids=[0, 1, 2, 3])
    # 0 with 1 and 3; 2 only with 3 (never with the reference)
    windows = [(0, 2), (1, 3), (4, 6), (1.5, 5)]
    parents: list[int] = []
    L0, overlap = join_paths(board, problem, _paths(windows, L), parents=parents)
    assert parents == [0, 0, 3, 1]  # 3 through 1 (75 matches) rather than 0 (25)
    assert overlap[2] > 0
    np.testing.assert_allclose(L0, L, atol=1e-6)
    # 2 seen by nobody else: a clear error naming it
    windows[2] = (6, 7)
    with pytest.raises(SolverError, match="station\\(s\\) 2:"):
        join_paths(board, problem, _paths(windows, L))


def test_weak_link_warning_names_thechain_to_reference():
    # slot 3 was joined to slot 1, slot 1 to the reference
    assert chain_to_reference(3, [0, 0, 3, 1]) == [3, 1, 0]
    assert chain_to_reference(2, [0, 0, 3, 1]) == [2, 3, 1, 0]
    assert chain_to_reference(2, []) == [2, 0]  # parents unknown: the station and the reference


def test_eight_station_room():
    base = load_simulation_config(CONFIGS / "simulation/lh2_room8.toml")
    # once round the room in 15 s instead of 30: half the hits, every station still sees it
    config = dataclasses.replace(base, duration_s=15.0, motion=dataclasses.replace(
        base.motion, speed_mps=2 * base.motion.speed_mps))
    sim, result = _solve(config, 4)
    errors = station_errors(sim.truth, result.stations)
    assert [e.station for e in errors] == list(range(1, 8))
    for e in errors:
        assert e.position_norm_m < 2e-3, e
        assert np.degrees(e.rotation_rad) < 0.05, e
    assert result.status == "converged" and not result.warnings
