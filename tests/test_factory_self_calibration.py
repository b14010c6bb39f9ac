"""The stations' self-calibration (``factory_terms``): solved factory terms on simulated
captures with known, perturbed decoded values; the Jacobian's layout; options and output.

Bounds and why:
- recovery: an LH2 room of 4 (8 s: 3 stations seen) whose decoded tilts and gib
  magnitudes are each 2 mrad (1 sigma) off the truth; with the terms solved every solved
  term lies within 3 of its sigmas of the truth (12 terms: the benchmark's 2-sigma
  fraction over seeds is the statistical check, docs/results/factory_self_calibration.md)
  and every station moves nearer the truth by at least 5x (measured 12x and 32x here);
- an LH1 phase moves its own axis's angle by exactly -1 rad/rad (ideal station, no gib)
  and the other axis's not at all: the central difference finds it to 1e-6, in the column
  of its own station, key and axis;
- the reported sigma is the corrections' marginal: never above the prior's spread.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from lhgraph.cli import main
from lhgraph.errors import InputError
from lhgraph.estimation.bound import true_values
from lhgraph.estimation.graph.factors import build_graph
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.graph.solver import solve_graph
from lhgraph.estimation.graph.streaming import StreamingSolver
from lhgraph.estimation.graph.variables import initial_values
from lhgraph.estimation.metrics import station_errors
from lhgraph.estimation.problem import build_problem
from lhgraph.io.stations import load_stations
from lhgraph.model.board import Board
from lhgraph.report.text import format_solution
from lhgraph.sim.factory_errors import with_factory_errors
from lhgraph.sim.simulate import (
    load_simulation_config,
    simulate,
    simulate_imu,
    write_simulation,
)

CONFIGS = Path(__file__).resolve().parents[1] / "configs" / "simulation"
KEYS = ("tilt", "gibmag")


def _sim(name: str, duration_s: float):
    cfg = dataclasses.replace(load_simulation_config(CONFIGS / f"{name}.toml"),
                              duration_s=duration_s)
    sim = simulate(cfg, 1)
    return sim, {k: s.model for k, s in sim.truth.stations.items()}


@pytest.fixture(scope="module")
def lh2_room():
    sim, truth = _sim("lh2_room4", 8.0)
    given = with_factory_errors(truth, KEYS, 2e-3, np.random.default_rng(3))
    held = solve_graph(sim.board, sim.angles, given)
    solved = solve_graph(sim.board, sim.angles, given,
                         GraphOptions.of(factory_terms=",".join(KEYS)))
    return sim, truth, given, held, solved


def test_perturbed_factory_terms_are_recovered_within_their_sigmas(lh2_room):
    sim, truth, _, held, solved = lh2_room
    z = []
    for sid, terms in solved.factory_terms.items():
        assert set(terms) == set(KEYS)
        for key, v in terms.items():
            err = np.array(v["solved_rad"]) - getattr(truth[sid].calibration, key)
            z.extend(err / np.array(v["sigma_rad"]))
            assert np.allclose(v["shift_rad"], np.subtract(v["solved_rad"], v["decoded_rad"]))
    assert len(z) == 3 * 2 * len(KEYS)
    assert np.max(np.abs(z)) < 3.0
    before = {e.station: e.position_norm_m for e in station_errors(sim.truth, held.stations)}
    for e in station_errors(sim.truth, solved.stations):
        assert e.position_norm_m * 5 < before[e.station]


def test_the_result_carries_the_solved_terms(lh2_room):
    _, _, given, held, solved = lh2_room
    assert held.factory_terms is None
    for sid, terms in solved.factory_terms.items():
        cal = solved.stations.stations[sid].model.calibration
        for key, v in terms.items():
            assert np.allclose(getattr(cal, key), v["solved_rad"])
            assert np.allclose(getattr(given[sid].calibration, key), v["decoded_rad"])
            assert np.all(np.array(v["sigma_white_rad"]) <= 3e-3 * (1 + 1e-9))
            assert np.all(np.array(v["sigma_rad"]) >= np.array(v["sigma_white_rad"]) * 0.999)
    text = format_solution(solved)
    assert text.count("factory terms, mrad") == len(solved.factory_terms) == 3 and "gibmag" in text
    assert "factory terms" not in format_solution(held)


def test_phase_jacobian_is_minus_one_on_its_own_axis_and_station():
    sim, truth = _sim("default", 2.0)
    problem = build_problem(sim.board, sim.angles, truth, sim.truth.indices()[0])
    options = GraphOptions.of(factory_terms="phase")
    graph, ev = build_graph(problem, options)
    values = initial_values(ev.layout, true_values(sim.motion.pose, sim.truth,
                                                         problem.state_time))
    ev.evaluate(values)
    h = ev.corrections.hits
    for k in (0, problem.n_states - 1):
        a, b = problem.bounds[k], problem.bounds[k + 1]
        J = ev.factory.hit_jacobian(a, b, 1.0)[0]
        axis = h.axis[a:b]
        expected = np.zeros((b - a, 2))
        expected[np.arange(b - a), axis] = -1.0
        assert np.allclose(J, expected, atol=1e-6)
        factor = graph.at(ev.bearing.indices[k])
        assert ev.factory.family.key(int(problem.state_station[k])) in factor.keys()


def test_factory_options_are_checked_and_streaming_refuses_them():
    assert GraphOptions.of(factory_terms=" tilt, gibmag ").factory.terms == KEYS
    assert GraphOptions().factory.terms == ()
    for bad in ("tilt,tilt", "tilts", "tilt;gibmag"):
        with pytest.raises(InputError, match="factory_terms"):
            GraphOptions.of(factory_terms=bad)
    with pytest.raises(InputError, match="factory_sigma_rad"):
        GraphOptions.of(factory_sigma_rad=0.0)
    sim, truth = _sim("default", 1.0)
    with pytest.raises(InputError, match="factory_terms"):
        StreamingSolver(sim.board, sorted(truth), truth, GraphOptions.of(factory_terms="phase"))


def test_solve_command_solves_prints_and_writes_the_terms(tmp_path, capsys):
    sim, _ = _sim("default", 2.0)
    write_simulation(sim, tmp_path)
    out = tmp_path / "result.toml"
    args = ["solve", "--board", str(tmp_path / "board.toml"), "--angles",
            str(tmp_path / "angles.csv"), "--output", str(out)]
    assert main([*args, "--factory-terms", "tilt,tilts"]) == 2
    assert "--factory-terms" in capsys.readouterr().err and not out.exists()
    assert main([*args, "--factory-terms", "gibmag", "--method", "paper"]) == 2
    assert "graph method only" in capsys.readouterr().err and not out.exists()
    assert main([*args, "--factory-terms", "gibmag"]) == 0
    printed = capsys.readouterr().out
    assert printed.count("factory terms, mrad") == 2 and "gibmag" in printed
    written = load_stations(out).stations[1].model.calibration.gibmag
    assert np.any(written != 0.0)  # the solved values, not the simulation's ideal zeros


def test_board_scale_is_solved_from_the_imu_and_refused_without_one():
    """A deck board file 1 % too large: with the IMU and the scale solved the station comes
    back (measured 0.27 mm against 4.4 mm held; bound 1.5 mm) and the scale within 4 of its
    sigmas of the truth (measured 2.3); without an IMU the option is refused."""
    cfg = dataclasses.replace(load_simulation_config(CONFIGS / "deck.toml"), duration_s=60.0)
    sim = simulate(cfg, 1)
    imu = simulate_imu(sim, seed=1).stream
    truth = {k: s.model for k, s in sim.truth.stations.items()}
    b = sim.board
    wrong = Board(b.ids, b.positions * 1.01, b.normals, b.name)
    options = GraphOptions.of(board_scale_sigma=0.02)
    held = solve_graph(wrong, sim.angles, truth, imu=imu)
    solved = solve_graph(wrong, sim.angles, truth, options, imu=imu)
    (e_held,), (e_solved,) = (station_errors(sim.truth, r.stations) for r in (held, solved))
    assert e_solved.position_norm_m < 1.5e-3 < e_held.position_norm_m
    k = solved.board_scale
    assert abs(k["correction"] - (1 / 1.01 - 1)) < 4 * k["sigma"]
    corrected = solved.corrected_board(wrong)
    assert np.allclose(corrected.positions, wrong.positions * (1 + k["correction"]))
    assert "board scale solved" in format_solution(solved)
    with pytest.raises(InputError, match="board_scale_sigma"):
        solve_graph(wrong, sim.angles, truth, options)
