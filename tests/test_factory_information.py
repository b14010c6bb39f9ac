"""The factory terms' information (identifiability study): known derivatives, the ordering of
the sigmas, a confounding the geometry predicts, and the predicted shift of an unmodelled
term error against a re-solve.

Bounds and why:
- an LH1 phase moves its axis's angle by exactly -1 rad/rad on an ideal station (no gib):
  the central difference reproduces it to 1e-6;
- the shift: a 0.1 mrad phase error on station 1 given to the solver moves it by what the
  linearised prediction says within 15 % (the solve also adapts its noise levels and stops
  at its tolerance: measured within 5 %);
- an LH2 station's two planes share one rotor: the same phase on both is a yaw of the
  station, so the capture cannot tell the phases from the pose (infinite joint sigma).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from lhgraph.estimation.bound import true_values
from lhgraph.estimation.graph.factors import build_graph
from lhgraph.estimation.graph.factory_information import FactoryTerm, term_jacobian
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.graph.solver import solve_graph
from lhgraph.estimation.graph.variables import initial_values
from lhgraph.estimation.problem import build_problem
from lhgraph.geometry.transforms import inverse, se3_log
from lhgraph.sim.simulate import load_simulation_config, simulate

CONFIGS = Path(__file__).resolve().parents[1] / "configs" / "simulation"
OPTIONS = GraphOptions.of(factory_information=True)


def _sim(name: str, duration_s: float):
    cfg = dataclasses.replace(load_simulation_config(CONFIGS / f"{name}.toml"),
                              duration_s=duration_s)
    sim = simulate(cfg, 1)
    return sim, {k: s.model for k, s in sim.truth.stations.items()}


@pytest.fixture(scope="module")
def ideal():
    sim, models = _sim("default", 4.0)
    return sim, models, solve_graph(sim.board, sim.angles, models, OPTIONS)


def test_sigmas_grow_as_more_is_free_and_unused_terms_are_named(ideal):
    f = ideal[2].factory_information
    alone, free, joint = (np.array(f[k]) for k in
                          ("sigma_alone_rad", "sigma_free_rad", "sigma_joint_rad"))
    assert np.all(alone <= free * (1 + 1e-9)) and np.all(free <= joint * (1 + 1e-9))
    # ideal stations: no gib magnitude, so no residual depends on the gib phase
    assert set(f["unused"]) == {f"station {s} gibphase[{a}]" for s in (0, 1) for a in (0, 1)}
    assert len(f["terms"]) == 16


def test_unmodelled_phase_error_shifts_the_station_as_predicted(ideal):
    sim, models, result = ideal
    f = result.factory_information
    j = f["terms"].index("station 1 phase[0]")
    delta = 1e-4
    cal = models[1].calibration
    wrong = dict(models)
    wrong[1] = dataclasses.replace(models[1], calibration=dataclasses.replace(
        cal, phase=cal.phase + np.array([delta, 0.0])))
    moved = solve_graph(sim.board, sim.angles, wrong)
    xi = se3_log(inverse(result.stations.pose(1)) @ moved.stations.pose(1))
    predicted_mm = f["station_shift_mm_per_mrad"][j] * delta * 1e3
    assert np.linalg.norm(xi[3:]) * 1e3 == pytest.approx(predicted_mm, rel=0.15)
    # the full tangent shift, rotation and direction too
    predicted = np.array(f["station_shift_per_rad"][1])[:, j] * delta
    assert np.linalg.norm(xi - predicted) < 0.15 * np.linalg.norm(predicted)


def test_lh2_common_phase_cannot_be_told_from_a_yaw():
    sim, models = _sim("lh2_room4", 8.0)
    f = solve_graph(sim.board, sim.angles, models, OPTIONS).factory_information
    joint = dict(zip(f["terms"], f["sigma_joint_rad"], strict=True))
    phases = [t for t in joint if " phase[" in t]
    assert len(phases) >= 4 and all(np.isinf(joint[t]) for t in phases)
    assert all(np.isfinite(joint[t]) for t in joint if " tilt[" in t)



def test_phase_derivative_is_minus_one_on_its_axis(ideal):
    sim, models, _ = ideal
    problem = build_problem(sim.board, sim.angles, models, 0)
    _, ev = build_graph(problem, GraphOptions())
    truth = true_values(sim.motion.pose, sim.truth, problem.state_time)
    ev.evaluate(initial_values(ev.layout, truth))
    J = term_jacobian(ev, [FactoryTerm(1, "phase", 0)])[:, 0]
    mine = (problem.hits.station == 1) & (problem.hits.axis == 0)
    np.testing.assert_allclose(J[mine], -1.0, atol=1e-6)
    np.testing.assert_allclose(J[~mine], 0.0, atol=1e-12)
