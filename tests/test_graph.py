"""Factor-graph solver end to end on simulated captures with known truth."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import gtsam
import numpy as np
import pytest

from lhgraph.errors import SolverError
from lhgraph.estimation.graph.factors import build_graph
from lhgraph.estimation.graph.loss import RobustLoss
from lhgraph.estimation.graph.noise import NoiseAdaptation, redundancy
from lhgraph.estimation.graph.optimizer import (
    LMParams,
    Status,
    largest_board_step,
    levenberg_marquardt,
    limit_board_steps,
    remaining_sigmas,
)
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.graph.resolve import FEW_DIODE_SCALE_SIGMA, DataFacts, resolve_options
from lhgraph.estimation.graph.solver import solve_graph
from lhgraph.estimation.graph.variables import (
    BOARD_POSE,
    BOARD_TWIST,
    DIODE_BIAS,
    SENSOR_OFFSET,
    STATION_POSE,
    SWEEP_OFFSET,
    VariableFamily,
    VariableLayout,
    chain_dissection,
    initial_values,
)
from lhgraph.estimation.init.pnp_kabsch import PnPKabschInitialiser
from lhgraph.estimation.init.twins import consistent_path
from lhgraph.estimation.metrics import station_errors
from lhgraph.estimation.problem import build_problem
from lhgraph.geometry.transforms import inverse, make_pose, se3_exp, se3_log, so3_exp
from lhgraph.io.angles import Angles
from lhgraph.sim.simulate import load_simulation_config, simulate

CONFIGS = Path(__file__).resolve().parents[1] / "configs" / "simulation"


def _capture(name: str, duration_s: float = 3.0, seed: int = 1, **noise):
    cfg = load_simulation_config(CONFIGS / f"{name}.toml")
    cfg = dataclasses.replace(cfg, duration_s=duration_s)
    if noise:
        cfg = dataclasses.replace(cfg, noise=dataclasses.replace(cfg.noise, **noise))
    return simulate(cfg, seed)


def _models(sim):
    return {k: s.model for k, s in sim.truth.stations.items()}


@pytest.mark.parametrize(("name", "max_mm", "max_deg"), [
    ("default", 2.0, 0.05),
    ("ninety", 2.0, 0.05),
    ("fast", 2.0, 0.05),
    ("far", 15.0, 0.2),
    ("facing", 3.0, 0.05),  # stations 160 deg apart, non-planar board
])
def test_recovers_station_pose(name, max_mm, max_deg):
    sim = _capture(name)
    result = solve_graph(sim.board, sim.angles, _models(sim))
    (err,) = station_errors(sim.truth, result.stations)
    assert err.position_norm_m * 1e3 < max_mm
    assert np.degrees(err.rotation_rad) < max_deg
    assert result.residuals.rms_urad() < 120
    cov = result.stations.stations[1].covariance
    np.testing.assert_allclose(cov, cov.T, atol=1e-15)
    assert np.all(np.linalg.eigvalsh(cov) > 0)
    assert len(result.trajectory.time) == len(np.unique(sim.angles.sweep_ids()))


def test_board_trajectory_matches_truth():
    sim = _capture("default")
    result = solve_graph(sim.board, sim.angles, _models(sim))
    T_true = sim.trajectory.at(result.trajectory.time)
    err = np.linalg.norm(result.trajectory.T_world_board[:, :3, 3] - T_true[:, :3, 3], axis=1)
    assert np.median(err) < 2e-3


def test_reflections_are_rejected():
    clean = _capture("default")
    dirty = _capture("default", reflection_fraction=0.03)
    e_clean = station_errors(clean.truth, solve_graph(clean.board, clean.angles).stations)[0]
    result = solve_graph(dirty.board, dirty.angles)
    e_dirty = station_errors(dirty.truth, result.stations)[0]
    assert e_dirty.position_norm_m < max(3 * e_clean.position_norm_m, 2e-3)
    assert 0.9 < result.residuals.inlier_fraction() < 0.995


def test_reference_station_defines_the_world():
    sim = _capture("default", duration_s=2.0)
    result = solve_graph(sim.board, sim.angles, options=GraphOptions.of(reference=1))
    assert result.stations.reference == 1
    np.testing.assert_allclose(result.stations.pose(1), np.eye(4))
    (err,) = station_errors(sim.truth, result.stations)
    assert err.station == 0 and err.position_norm_m < 3e-3


def test_single_station_is_an_error():
    sim = _capture("default", duration_s=1.0)
    only0 = sim.angles.select(sim.angles.lighthouse == 0)
    with pytest.raises(SolverError, match="need at least two"):
        solve_graph(sim.board, only0)


def test_isam2_agrees_with_lm():
    """Both solvers reach the same station, within a tenth of its standard deviation per
    coordinate (LM stops when it is within 0.05 sigma of convergence)."""
    sim = _capture("default", duration_s=1.0)
    a = solve_graph(sim.board, sim.angles,
                    options=GraphOptions.of(solver="lm", adapt_motion_prior=False))
    b = solve_graph(sim.board, sim.angles, options=GraphOptions.of(solver="isam2"))
    difference = se3_log(inverse(a.stations.pose(1)) @ b.stations.pose(1))
    sigma = np.sqrt(np.diag(a.stations.stations[1].covariance))
    assert np.all(np.abs(difference) < 0.1 * sigma)


def test_motion_prior_adapts_to_the_motion():
    """The simulated wave is far smoother than the starting prior: the variance-component
    update lowers the prior's PSD until its whitened residuals have unit variance, or to the
    floor; with a wider floor it reaches chi2/dof ~ 1."""
    sim = _capture("default")
    start = GraphOptions().motion
    d = solve_graph(sim.board, sim.angles).diagnostics
    assert d["accel_psd_pos"] == pytest.approx(start.min_psd_factor * start.accel_psd_pos)
    free = solve_graph(sim.board, sim.angles, options=GraphOptions.of(min_psd_factor=1e-4))
    assert free.diagnostics["accel_psd_pos"] < 0.1 * start.accel_psd_pos
    assert 0.7 < free.diagnostics["motion_chi2_per_dof"] < 1.4


def test_three_and_four_stations(tmp_path):
    """Two to four stations without code changes (LH2 brings more)."""
    stations = "".join(
        f"[[stations]]\nposition = [{x}, -1.0, 2.0]\n"
        "quaternion = [0.7071067811865476, 0.0, 0.0, 0.7071067811865476]\n"
        for x in (0.0, 1.5, -1.5, 0.8))
    path = tmp_path / "four.toml"
    path.write_text(f"duration_s = 3.0\nseed = 5\n{stations}[motion]\ncentre_m = [0.0, 1.5, 1.6]\n")
    sim = simulate(load_simulation_config(path))
    result = solve_graph(sim.board, sim.angles)
    errors = station_errors(sim.truth, result.stations)
    assert [e.station for e in errors] == [1, 2, 3]
    for e in errors:
        assert e.position_norm_m < 3e-3 and np.degrees(e.rotation_rad) < 0.1
    three = sim.angles.select(sim.angles.lighthouse != 3)
    result3 = solve_graph(sim.board, three)
    assert sorted(result3.stations.indices()) == [0, 1, 2]


def test_angle_noise_is_learned_from_the_residuals():
    """With 70 urad of extra Gaussian noise the solver raises its per-diode sigma to the
    residuals' robust spread, so the robust loss keeps the normal hits and the covariance
    widens; with quantisation noise only it stays at the configured floor (within the 2 %
    that the first update, one iteration from the initial values, may put on it)."""
    noisy = _capture("default", angle_sigma_rad=7e-5)
    result = solve_graph(noisy.board, noisy.angles)
    sigma = result.diagnostics["angle_sigma_rad"]
    assert 6.5e-5 < sigma < 9e-5
    assert result.residuals.inlier_fraction() > 0.97
    clean = _capture("default")
    assert solve_graph(clean.board, clean.angles).diagnostics["angle_sigma_rad"] == (
        pytest.approx(GraphOptions().noise.angle_sigma_rad, rel=0.02))


def test_consistent_path_drops_jumps_and_turned_twins():
    t = np.arange(40) * 0.016
    rot = so3_exp(np.stack([np.zeros(40), 2.0 * t, np.zeros(40)], axis=1))  # 2 rad/s turn
    p = np.stack([0.5 * t, np.zeros(40), 2.0 + 0.1 * t], axis=1)
    T = make_pose(rot, p)
    T[10, :3, :3] = so3_exp([0.0, 0.0, 0.8]) @ T[10, :3, :3]  # a twin turned 46 deg
    T[25, :3, 3] += [0.3, 0.0, 0.0]  # a pose 30 cm off the path
    keep = consistent_path(t, T)
    assert not keep[10] and not keep[25]
    assert keep.sum() == 38


def test_simultaneous_sweeps_of_two_stations_still_solve():
    """Stations whose time stamps overlap put two states at (nearly) the same time: the
    motion prior's covariance (dt^3) must not become singular (was an indeterminate
    system, raised from GTSAM as a traceback)."""
    sim = _capture("default", duration_s=2.0)
    a = sim.angles
    sweep = a.sweep_ids()
    first = [np.mean(a.time[sweep == sweep[a.lighthouse == k][0]]) for k in (0, 1)]
    t = np.where(a.lighthouse == 1, a.time - (first[1] - first[0]), a.time)
    order = np.argsort(t, kind="stable")
    shifted = Angles(t[order], a.lighthouse[order], a.axis[order], a.sensor[order],
                     a.angle[order], {k: v[order] for k, v in a.extra.items()})
    result = solve_graph(sim.board, shifted, _models(sim))
    dt = np.diff(result.trajectory.time)
    assert dt.min() < 1e-4  # the case: states of both stations at one time
    assert np.all(np.isfinite(result.stations.pose(1)))
    assert result.residuals.inlier_fraction() > 0.5


def _graph(sim, options):
    """Problem, graph, evaluator and initial values of a capture (reference station 0)."""
    problem = build_problem(sim.board, sim.angles, {}, 0)
    graph, ev = build_graph(problem, options)
    init = PnPKabschInitialiser()(sim.board, sim.angles, problem)
    return problem, graph, ev, initial_values(ev.layout, init)


@pytest.mark.parametrize("loss", ["cauchy", "huber"])
def test_numpy_cost_is_the_graph_error(loss):
    """The LM's numpy cost equals GTSAM's ``graph.error`` (robust per-diode loss, offset and
    motion priors), also after the noise levels were rescaled; with reflections, so the
    robust branch of the loss is exercised."""
    sim = _capture("default", duration_s=1.0, reflection_fraction=0.03)
    options = GraphOptions.of(loss=loss)
    _, graph, ev, values = _graph(sim, options)
    assert ev.cost(values) == pytest.approx(graph.error(values), rel=1e-12)
    ev.motion.scale(0.3)
    ev.bearing.scale_noise(2.0)
    assert ev.cost(values) == pytest.approx(graph.error(values), rel=1e-12)
    assert np.abs(ev.bearing.whitened_residuals()).max() > 3 * options.robust.huber_k


def test_rescaled_linearisation_is_the_one_made_at_those_levels():
    """Linearised, rescaled at the same point (its Jacobians kept and rescaled, not computed
    again) and linearised again, the graph gives the linear system of a graph built with
    those levels in its options (angle variance x2, motion-prior PSDs x0.3); and the
    levels do change the system."""
    sim = _capture("default", duration_s=1.0, reflection_fraction=0.03)
    options = GraphOptions()
    _, graph, ev, values = _graph(sim, options)
    first, _ = graph.linearize(values).jacobian()  # the Jacobians at the first levels
    ev.motion.scale(0.3)
    ev.bearing.scale_noise(2.0)
    levels = options.with_values(angle_sigma_rad=options.noise.angle_sigma_rad * np.sqrt(2.0),
                                 accel_psd_rot=options.motion.accel_psd_rot * 0.3,
                                 accel_psd_pos=options.motion.accel_psd_pos * 0.3)
    _, built_graph, _, _ = _graph(sim, levels)
    A, b = graph.linearize(values).jacobian()
    A_built, b_built = built_graph.linearize(values).jacobian()
    assert A.shape == A_built.shape
    scale = np.abs(A_built).max()
    assert np.abs(A - A_built).max() < 1e-12 * scale
    assert np.allclose(b, b_built, rtol=1e-12, atol=1e-12 * np.abs(b_built).max())
    assert np.abs(A - first).max() > 1e-3 * scale


def test_diode_biases_are_estimated_with_the_stations():
    """Every station sees every diode with its own constant angle bias (100 µrad, as the
    hive recording's per-diode mean residuals): ignored, they move station 1 by millimetres;
    as graph variables (``diode_bias_sigma_rad``) they are recovered (up to the part a
    station's rotation takes, their mean per station and axis) and the station is found
    again; the numpy cost stays the graph's error with the biases (and the sensor offsets)
    in it."""
    sim = _capture("default", duration_s=4.0)
    rng = np.random.default_rng(7)
    n = len(sim.board.positions)
    bias = rng.normal(0.0, 1e-4, (2, 2, n))
    angles = sim.angles.select(np.arange(len(sim.angles)))
    angles.angle = angles.angle + bias[angles.lighthouse, angles.axis,
                                       angles.check_board(sim.board)]
    plain = solve_graph(sim.board, angles)
    assert plain.diode_bias_rad is None
    biased = solve_graph(sim.board, angles, options=GraphOptions.of(diode_bias_sigma_rad=1e-4))
    err_plain = station_errors(sim.truth, plain.stations)[0].position_norm_m
    err = station_errors(sim.truth, biased.stations)[0].position_norm_m
    assert err_plain > 2e-3 and err < 0.4 * err_plain
    for s in (0, 1):
        found = biased.diode_bias_rad[s]
        seen = np.flatnonzero(np.bincount(angles.check_board(sim.board)[angles.lighthouse == s],
                                          minlength=n))
        for axis in (0, 1):
            a, b = found[axis, seen], bias[s, axis, seen]
            assert np.corrcoef(a - a.mean(), b - b.mean())[0, 1] > 0.9
    # the numpy cost is the graph's error with diode biases and sensor offsets in it
    options = GraphOptions.of(diode_bias_sigma_rad=1e-4, sensor_offset_sigma_m=3e-4)
    problem = build_problem(sim.board, angles, {}, 0)
    graph, ev = build_graph(problem, options)
    values = initial_values(ev.layout, PnPKabschInitialiser()(sim.board, angles, problem))
    for family in (ev.layout.family(DIODE_BIAS), ev.layout.family(SENSOR_OFFSET)):
        for i in ev.layout.indices(family):
            values.update(family.key(i), rng.normal(0.0, 1e-4, family.dim))
    assert ev.cost(values) == pytest.approx(graph.error(values), rel=1e-12)
    assert np.abs(ev.corrections.sensor_offsets()).max() > 0


@pytest.mark.parametrize("kind", ["cauchy", "huber"])
def test_robust_loss_is_gtsams_estimator(kind):
    """The numpy loss and weights are those of the m-estimator the factors use."""
    loss = RobustLoss(kind, 3.0)
    estimator = loss.estimator()
    x = np.array([0.0, 0.5, -2.9, 3.0, 4.0, -30.0])
    np.testing.assert_allclose(loss.cost(x), [estimator.loss(v) for v in x], rtol=1e-14)
    sigma = 1e-4
    np.testing.assert_allclose(loss.weights(x[1:] * sigma, sigma),
                               [estimator.weight(v) for v in x[1:]], rtol=1e-14)
    with pytest.raises(SolverError, match="unknown loss"):
        RobustLoss("tukey", 3.0)


def test_receiver_scale_sigma_resolves_by_receiver():
    """Rule 9: few-diode data get FEW_DIODE_SCALE_SIGMA unless the board's scale is solved
    (the IMU stage); many diodes none; a value given is kept."""
    few, many = DataFacts(True, False, 0), DataFacts(False, False, 0)

    def resolved(options, facts, inertial=False):
        return resolve_options(options, facts, inertial).options.uncertainty.receiver_scale_sigma

    assert resolved(GraphOptions(), few) == FEW_DIODE_SCALE_SIGMA
    assert resolved(GraphOptions(), many) == 0.0
    scale = GraphOptions.of(board_scale_sigma=0.02)
    assert resolved(scale, few, inertial=True) == 0.0
    assert resolved(scale, few, inertial=False) == FEW_DIODE_SCALE_SIGMA  # light-only stage
    assert resolved(GraphOptions.of(receiver_scale_sigma=0.0), few) == 0.0
    assert resolved(GraphOptions.of(receiver_scale_sigma=0.01), many) == 0.01
    line = [a for a in resolve_options(GraphOptions(), few).applied
            if a.startswith("receiver_scale_sigma")]
    assert line == [f"receiver_scale_sigma = {FEW_DIODE_SCALE_SIGMA!r} (unset: few-diode data, "
                    "the board's scale not solved; given None)"]


def test_covariance_from_the_last_iteration_matches_marginals_at_the_result():
    """The station covariance read off the last LM iteration's Bayes tree (it is reused: no
    new linearisation) agrees with GTSAM's ``Marginals`` of a fresh linearisation at the
    solution."""
    sim = _capture("default", duration_s=2.0)
    options = resolve_options(GraphOptions(), DataFacts(False, False, 0)).options
    _, graph, ev, values = _graph(sim, options)
    fit = levenberg_marquardt(graph, values, ev.cost, ev.layout, LMParams.from_options(options),
                              NoiseAdaptation(graph, ev, options))
    assert fit.status == Status.CONVERGED and fit.covariance_from_last_iteration
    assert len(fit.error_history) == fit.iterations + 1
    assert fit.final_error == fit.error_history[-1] == pytest.approx(graph.error(fit.values))
    key = STATION_POSE.key(1)
    fresh = gtsam.Marginals(graph.linearize(fit.values), fit.values).marginalCovariance(key)
    np.testing.assert_allclose(fit.covariance(key), fresh, rtol=1e-3,
                               atol=1e-3 * np.abs(fresh).max())


def test_motion_prior_redundancy_against_the_dense_hat_matrix():
    """``redundancy`` (Hutchinson's trace through the sequential Bayes net) against the
    motion rows' block of the dense hat matrix ``A N^-1 A^T`` of the same linear system."""
    sim = _capture("default", duration_s=1.0)
    _, graph, ev, values = _graph(sim, GraphOptions())
    lin = graph.linearize(values)
    A, _ = lin.jacobian()
    bounds = np.cumsum([0] + [lin.at(i).rows() for i in range(lin.size())])
    rows = np.concatenate([np.arange(bounds[i], bounds[i + 1]) for i in ev.motion.indices])
    A_m = A[rows]
    exact = len(rows) - np.trace(A_m @ np.linalg.solve(A.T @ A, A_m.T))
    [(n, dof)] = redundancy(lin, [ev.motion.indices], ev.layout.elimination_ordering(),
                            probes=16)
    assert n == len(rows) == 12 * len(ev.motion.indices)
    assert 0 < exact < n
    assert dof == pytest.approx(exact, rel=0.15)


def test_redundancy_estimate_loosens_the_prior_without_a_floor():
    """The plain mean square of the prior's whitened residuals sits far below 1 at the
    solution (the fit absorbs them) and needs the floor; counted over the prior's redundancy
    the estimate lands between that and the floor's start, and a solve with it still finds
    the stations."""
    sim = _capture("default", duration_s=3.0)
    plain = solve_graph(sim.board, sim.angles, _models(sim), GraphOptions.of(min_psd_factor=1e-4))
    counted = solve_graph(sim.board, sim.angles, _models(sim),
                          GraphOptions.of(motion_prior_estimate="redundancy"))
    assert plain.diagnostics["accel_psd_pos"] < counted.diagnostics["accel_psd_pos"]
    assert counted.diagnostics["accel_psd_pos"] < GraphOptions().motion.accel_psd_pos
    assert counted.status == "converged"
    assert station_errors(sim.truth, counted.stations)[0].position_norm_m < 3e-3


@pytest.mark.parametrize(("name", "seed"), [("default", 1), ("realistic", 1)])
def test_noise_levels_follow_the_solution_after_a_bad_start(name, seed):
    """With station 1 started 1.5 m and 1 rad off, the early noise estimates are far too
    large; the levels keep adapting, so the learned diode sigma ends at the residuals' robust
    spread (or the floor), not frozen at a transient value, and the station is found."""
    sim = _capture(name, seed=seed)

    def bad_start(board, angles, problem):
        init = PnPKabschInitialiser()(board, angles, problem)
        init.L[1] = init.L[1] @ se3_exp(np.array([1.0, 0.0, 0.0, 1.5, 0.0, 0.0]))
        return init

    result = solve_graph(sim.board, sim.angles, _models(sim), initialiser=bad_start)
    assert result.status == "converged"
    spread = max(1.4826 * np.median(np.abs(result.residuals.residual_rad)),
                 GraphOptions().noise.angle_sigma_rad)
    assert spread <= result.diagnostics["angle_sigma_rad"] < 1.25 * spread
    truth = sim.truth.stations[1].T_world_lh
    assert np.linalg.norm(result.stations.pose(1)[:3, 3] - truth[:3, 3]) < 3e-3


@pytest.mark.parametrize(("name", "seed"), [("default", 1), ("default", 2), ("facing", 1),
                                            ("facing", 2)])
def test_early_stop_is_close_to_full_convergence(name, seed):
    """The stopping rule's estimate: the stations end within a tenth of a standard deviation
    (per coordinate) of where LM run to a 1e-12 relative error change ends."""
    sim = _capture(name, duration_s=2.0, seed=seed)
    early = solve_graph(sim.board, sim.angles)
    full = solve_graph(sim.board, sim.angles, options=GraphOptions.of(
        step_tolerance_sigma=0.0, relative_tolerance=1e-12))
    difference = se3_log(inverse(early.stations.pose(1)) @ full.stations.pose(1))
    sigma = np.sqrt(np.diag(full.stations.stations[1].covariance))
    assert np.all(np.abs(difference) < 0.1 * sigma)


def test_remaining_distance_sums_the_geometric_tail():
    """Steps shrinking at rate rho leave step * rho / (1 - rho) to go; without a previous
    step, or when the steps grow, the step itself counts."""
    assert remaining_sigmas(0.1, 1.0) == pytest.approx(0.1 * 0.1 / 0.9)
    assert remaining_sigmas(0.4, 0.5) == pytest.approx(1.6)
    assert remaining_sigmas(0.3, None) == 0.3
    assert remaining_sigmas(0.3, 0.2) == 0.3


def test_layout_reads_every_family_by_key():
    """The layout's vectorised reads of values and steps agree with reading every key on its
    own, with stations, poses, twists and offsets present; the board step is the largest
    pose step."""
    sim = _capture("default", duration_s=0.5)
    problem, graph, ev, values = _graph(sim, GraphOptions())
    layout = ev.layout
    delta = graph.linearize(values).optimize()
    for family in (BOARD_POSE, BOARD_TWIST, SWEEP_OFFSET, STATION_POSE):
        by_key = np.array([delta.at(key) for key in layout.keys(family)])
        np.testing.assert_array_equal(layout.read_steps(delta, family), by_key)
    poses = layout.read_poses(values)
    for family in (BOARD_POSE, STATION_POSE):
        by_key = np.array([values.atPose3(key).matrix() for key in layout.keys(family)])
        np.testing.assert_array_equal(poses[family], by_key)
    for family in (BOARD_TWIST, SWEEP_OFFSET):
        by_key = np.array([values.atVector(key) for key in layout.keys(family)])
        np.testing.assert_array_equal(layout.read_vectors(values, family), by_key)
    steps = np.array([delta.at(BOARD_POSE.key(k)) for k in range(problem.n_states)])
    rad, m = largest_board_step(delta, layout)
    assert rad == np.linalg.norm(steps[:, :3], axis=1).max()
    assert m == np.linalg.norm(steps[:, 3:], axis=1).max()


def test_elimination_ordering_follows_the_families():
    """The chain state by state, each state's leaves after it, the root last; a new chain
    family (an IMU bias, say) joins the chain without other changes."""
    bias = VariableFamily("imu bias", "b", 6, False, "chain", 0.1, "accelerometer/gyro bias")
    layout = VariableLayout({BOARD_POSE: range(3), BOARD_TWIST: range(3), bias: range(3),
                             SWEEP_OFFSET: range(3), STATION_POSE: range(1, 3)})
    o, x, w, b, L = (f.key for f in (SWEEP_OFFSET, BOARD_POSE, BOARD_TWIST, bias, STATION_POSE))
    expected = [key for k in range(3) for key in (x(k), w(k), b(k), o(k))] + [L(1), L(2)]
    ordering = layout.elimination_ordering()
    assert [ordering.at(i) for i in range(ordering.size())] == expected
    assert all(f.key(i) == gtsam.symbol(f.symbol, i) for f in (bias, BOARD_POSE, STATION_POSE)
               for i in (0, 7, 2**40))
    with pytest.raises(ValueError, match="same state indices"):
        VariableLayout({BOARD_POSE: range(3), BOARD_TWIST: range(2)})


def test_chain_dissection_is_a_nested_dissection_of_the_states():
    assert chain_dissection(10, leaf=2) == [0, 1, 3, 4, 2, 6, 7, 9, 8, 5]
    for n in (0, 1, 64, 65, 12345):
        assert sorted(chain_dissection(n)) == list(range(n))


def _room_graph(n_states: int, n_stations: int) -> gtsam.SymbolicFactorGraph:
    """A room's structure: the board goes round once, seeing two neighbouring stations at a
    time (slots 1..n_stations; the reference is no variable)."""
    x, w, o, lh = (f.key for f in (BOARD_POSE, BOARD_TWIST, SWEEP_OFFSET, STATION_POSE))
    graph = gtsam.SymbolicFactorGraph()
    for k in range(n_states):
        first = 1 + k * n_stations // n_states
        for s in (first, first % n_stations + 1):
            graph.push_factor(x(k), lh(s))
            graph.push_factor(o(k), x(k), lh(s))
        graph.push_factor(x(k), w(k))
        if k:
            graph.push_factor(x(k - 1), w(k - 1), x(k), w(k))
    return graph


def test_elimination_ordering_keeps_a_rooms_cliques_to_the_stations_in_view():
    """8 stations round a room, two in view at a time: with the layout's order almost no board
    state's conditional holds more than 4 stations (time order: most of them do), and with
    the stations fixed (tracking) the states go in time order."""
    n = 2000
    stations = {STATION_POSE.key(s) for s in range(1, 9)}
    graph = _room_graph(n, 8)
    x, w, o = (f.key for f in (BOARD_POSE, BOARD_TWIST, SWEEP_OFFSET))

    def stations_held(ordering: gtsam.Ordering) -> np.ndarray:
        net = graph.eliminateSequential(ordering)
        return np.array([len(set(net.at(i).keys()) & stations) for i in range(net.size())
                         if gtsam.Symbol(net.at(i).firstFrontalKey()).chr() == ord("x")])

    held = stations_held(VariableLayout.of_problem(n, 9).elimination_ordering())
    assert len(held) == n
    assert np.median(held) <= 2 and np.mean(held > 4) < 0.01
    time_order = gtsam.Ordering()
    for key in ([o(k) for k in range(n)] + [key for k in range(n) for key in (x(k), w(k))]
                + sorted(stations)):
        time_order.push_back(key)
    assert np.mean(stations_held(time_order) > 4) > 0.5
    tracking = VariableLayout.of_problem(5, 1, fixed_stations=True).elimination_ordering()
    assert [tracking.at(i) for i in range(tracking.size())] == [
        key for k in range(5) for key in (x(k), w(k), o(k))]


def test_limit_board_steps_scales_only_the_states_beyond_the_trust_region():
    layout = VariableLayout.of_problem(3, 2)
    steps = {0: np.r_[0.1, 0, 0, 0.01, 0, 0],  # within both limits
             1: np.r_[0, 0.6, 0, 0.02, 0, 0],  # twice the rotation limit
             2: np.r_[0, 0, 0.1, 0, 0.4, 0]}  # four times the translation limit
    delta = gtsam.VectorValues()
    for k, step in steps.items():
        delta.insert(BOARD_POSE.key(k), step)
        delta.insert(BOARD_TWIST.key(k), np.full(6, 1.0 + k))
        delta.insert(SWEEP_OFFSET.key(k), np.array([1e-3]))
    delta.insert(STATION_POSE.key(1), np.full(6, 0.5))
    assert limit_board_steps(delta, layout, max_rad=0.3, max_m=0.1)
    out = delta  # scaled in place
    np.testing.assert_array_equal(out.at(BOARD_POSE.key(0)), steps[0])
    np.testing.assert_allclose(out.at(BOARD_POSE.key(1)), steps[1] / 2)
    np.testing.assert_allclose(out.at(BOARD_TWIST.key(1)), np.full(6, 2.0) / 2)
    np.testing.assert_allclose(out.at(BOARD_POSE.key(2)), steps[2] / 4)
    np.testing.assert_allclose(out.at(BOARD_TWIST.key(2)), np.full(6, 3.0) / 4)
    # the stations and the sweep offsets are not board states: left alone
    np.testing.assert_array_equal(out.at(STATION_POSE.key(1)), np.full(6, 0.5))
    np.testing.assert_array_equal(out.at(SWEEP_OFFSET.key(2)), [1e-3])
    # nothing beyond the limits any more: nothing scaled, said so
    assert not limit_board_steps(delta, layout, max_rad=0.3, max_m=0.1)
    np.testing.assert_allclose(delta.at(BOARD_POSE.key(1)), steps[1] / 2)


def test_an_undetermined_variable_is_named_as_the_user_knows_it():
    # GTSAM's indeterminate-system error names a key (Symbol: x12); the solver's one line
    # says which board state that is (time, station, hits, the gaps around it), or which
    # station, and falls back to the general sentence when the message names no variable
    from lhgraph.estimation.graph.batch import undetermined

    sim = _capture("default", duration_s=1.0)
    problem, _, ev, _ = _graph(sim, GraphOptions())
    k = 12
    blind = gtsam.GaussianFactorGraph()  # no information on board pose k: Cholesky fails
    blind.add(gtsam.JacobianFactor(BOARD_POSE.key(k), np.zeros((6, 6)), np.zeros(6),
                                   gtsam.noiseModel.Unit.Create(6)))
    with pytest.raises(RuntimeError) as err:
        blind.eliminateMultifrontal(gtsam.Ordering.ColamdGaussianFactorGraph(blind))
    line = undetermined(str(err.value), ev.layout, problem)
    t = problem.state_time
    a, b = problem.bounds[k], problem.bounds[k + 1]
    station = problem.station_ids[problem.state_station[k]]
    assert line.startswith("the linearised problem cannot be solved: board pose 12 (t = "
                           f"{t[k] - t[0]:.3f} s, station {station}: {b - a} hits of ")
    assert f"{t[k] - t[k - 1]:.3f} s before, {t[k + 1] - t[k]:.3f} s after)" in line
    assert "\n" not in line
    station_line = undetermined("Indeterminate linear system detected while working near "
                                f"variable\n{STATION_POSE.key(1)} (Symbol: l1).", ev.layout,
                                problem)
    assert f"station {problem.station_ids[1]} is not determined" in station_line
    assert "some board state or station" in undetermined("out of memory", ev.layout, problem)
