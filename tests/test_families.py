"""The factor families' interface: every family's declared keys are its factors' keys, its
declared variables are in the graph, and the evaluator's cost is the graph's error."""

from __future__ import annotations

import dataclasses

import gtsam
import numpy as np
import pytest

from lhgraph.estimation.graph.evaluator import FactorEvaluator
from lhgraph.estimation.graph.factors import build_graph, factor_families, graph_layout
from lhgraph.estimation.graph.families.base import BoardPoint, FactorFamily
from lhgraph.estimation.graph.families.motion import MotionPrior
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.graph.variables import initial_values
from lhgraph.estimation.imu.inertial import inertial_data, initial_gravity
from lhgraph.estimation.init.pnp_kabsch import PnPKabschInitialiser
from lhgraph.estimation.problem import build_problem
from lhgraph.sim.imu import ImuConfig
from lhgraph.sim.simulate import default_simulation_config, simulate

OPTIONS = {
    "plain": GraphOptions(),
    "corrections": GraphOptions.of(diode_bias_sigma_rad=1e-4, sensor_offset_sigma_m=1e-3),
    "twist": GraphOptions.of(imu_factors="twist", gyro_scale_sigma=0.1, gyro_preintegration=True),
    "combined": GraphOptions.of(imu_factors="combined"),
}


@pytest.fixture(scope="module")
def capture():
    config = dataclasses.replace(default_simulation_config(), duration_s=1.5, imu=ImuConfig())
    return simulate(config, 3)


@pytest.fixture(scope="module", params=list(OPTIONS))
def built(request, capture):
    options = OPTIONS[request.param]
    problem = build_problem(capture.board, capture.angles, {}, capture.truth.indices()[0])
    init = PnPKabschInitialiser()(capture.board, capture.angles, problem)
    inertial = (inertial_data(capture.imu.stream, problem.state_time, options.imu.imu_max_gap_s)
                if options.imu.imu_factors != "auto" else None)
    graph, ev = build_graph(problem, options, inertial=inertial)
    gravity = None if inertial is None else initial_gravity(inertial, init.X)
    return graph, ev, initial_values(ev.layout, init, gravity)


def test_declared_keys_are_the_factors_keys(built):
    graph, ev, _ = built
    covered = []
    for family in ev.families:
        for i, index in enumerate(family.indices):
            assert family.keys(i) == list(graph.at(index).keys()), (family.name, i)
        covered += list(family.indices)
    assert covered == list(range(graph.size()))  # the families hold every factor, in order


def test_declared_variables_cover_the_factors(built):
    graph, ev, _ = built
    for family in ev.families:
        symbols = {v.symbol for v in family.variables}
        for index in family.indices:
            for key in graph.at(index).keys():
                assert chr(gtsam.Symbol(key).chr()) in symbols, family.name


def test_cost_is_the_graphs_error(built):
    graph, ev, values = built
    assert ev.cost(values) == pytest.approx(graph.error(values), rel=1e-9)


def test_missing_variables_are_refused(capture):
    problem = build_problem(capture.board, capture.angles, {}, capture.truth.indices()[0])
    options = OPTIONS["twist"]
    inertial = inertial_data(capture.imu.stream, problem.state_time, options.imu.imu_max_gap_s)
    families = factor_families(problem, graph_layout(problem, options, False, True), options,
                               inertial)
    with pytest.raises(ValueError, match="IMU calibration"):
        FactorEvaluator(problem, graph_layout(problem, options, False, False), families)


def test_a_family_reads_the_shared_point(capture):
    problem = build_problem(capture.board, capture.angles, {}, capture.truth.indices()[0])
    prior = MotionPrior(problem, (1.0, 1.0))
    assert isinstance(prior, FactorFamily)
    K = problem.n_states
    X = np.repeat(np.eye(4)[None], K, axis=0)
    prior.read(gtsam.Values(), BoardPoint(X, np.zeros((K, 6)), np.eye(4)[None]))
    assert prior.cost(gtsam.Values()) == 0.0  # at rest, no residual
