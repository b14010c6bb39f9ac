"""GTSAM's combined IMU factors in the batch graph (lhgraph.estimation.imu.combined):
the preintegration against a simulated stream with known truth, the steps the stream does
not cover, the variables' layout, the options, and solves with known answers.

Why the bounds: at the truth, with a 1 kHz stream of the simulated part's white noise and
a constant bias, each preintegrated factor's whitened rotation and velocity residuals have
a mean square near 1 (measured 0.92 and 0.96 here, 0.94 and 0.94 over a 120 s deck); its
position residual is dominated by the integration noise, far below 1. The facing stations
with the planar board and a 1 kHz IMU (issue #16's family) solve to within 2 mm / 0.05 deg
(measured 0.18 mm / 0.007 deg on seed 1, the gyro bias's norm to 1e-6 rad/s)."""

from __future__ import annotations

import dataclasses

import gtsam
import numpy as np
import pytest

from lhgraph.errors import InputError
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.graph.solver import solve_graph
from lhgraph.estimation.graph.variables import (
    BOARD_POSE,
    GRAVITY,
    IMU_BIAS_STATE,
    IMU_VELOCITY,
    VariableLayout,
)
from lhgraph.estimation.imu.combined import RESIDUAL_GROUPS, preintegrate
from lhgraph.estimation.metrics import station_errors
from lhgraph.io.imu import ImuStream
from lhgraph.sim.imu import ImuConfig
from lhgraph.sim.simulate import load_simulation_config, simulate, simulate_imu

FACING = "configs/simulation/facing_planar_imu.toml"
STILL_BIAS = dict(gyro_bias_walk_rad_s_per_sqrt_s=0.0, accel_bias_walk_mps2_per_sqrt_s=0.0)


@pytest.fixture(scope="module")
def short_deck():
    config = dataclasses.replace(load_simulation_config("configs/simulation/deck.toml"),
                                 duration_s=20.0)
    return simulate(config, 2)


def true_states(capture, times):
    """The true poses (K, 4, 4) and world velocities (K, 3) of ``capture`` at ``times``."""
    h = 1e-4
    T = capture.trajectory.at(times)
    v = (capture.trajectory.at(times + h)[:, :3, 3]
         - capture.trajectory.at(times - h)[:, :3, 3]) / (2 * h)
    return T, v


def test_preintegration_predicts_the_true_motion(short_deck):
    # 1 kHz stream, constant bias: from the true state k and the true bias, every
    # preintegrated step predicts state k + 1 to within what the noise allows, and the
    # factors' whitened residuals at the truth have the mean squares their noise models say
    imu = simulate_imu(short_deck, ImuConfig(rate_hz=1000.0, **STILL_BIAS), seed=3)
    times = np.arange(0.5, 19.5, 0.02)
    T, v = true_states(short_deck, times)
    pre = preintegrate(imu.stream, times, GraphOptions.of(imu_noise_factor=1.0))
    assert len(pre.steps) == len(times) - 1 and len(pre.gaps) == 0
    bias = gtsam.imuBias.ConstantBias(imu.bias[3:], imu.bias[:3])
    values = gtsam.Values()
    for k in range(len(times)):
        values.insert(BOARD_POSE.key(k), gtsam.Pose3(T[k]))
        values.insert(IMU_VELOCITY.key(k), v[k])
        values.insert(IMU_BIAS_STATE.key(k), bias)
    values.insert(GRAVITY.key(0), imu.gravity)
    errors, whitened = [], []
    for k, pim in zip(pre.steps.tolist(), pre.measurements, strict=True):
        predicted = pim.predict(gtsam.NavState(gtsam.Pose3(T[k]), v[k]), bias)
        errors.append(np.linalg.norm(predicted.position() - T[k + 1][:3, 3]))
        factor = gtsam.CombinedImuFactorWithGravityVector(
            BOARD_POSE.key(k), IMU_VELOCITY.key(k), BOARD_POSE.key(k + 1),
            IMU_VELOCITY.key(k + 1), IMU_BIAS_STATE.key(k), IMU_BIAS_STATE.key(k + 1),
            GRAVITY.key(0), pim)
        whitened.append(factor.whitenedError(values))
    # the gravity of the predictions is the parameters' (standard, along -z), the
    # simulation's world has its own up: compare in the factors, which take the variable
    e = np.array(whitened)
    for group in ("rotation", "velocity"):
        chi2 = float(np.mean(e[:, RESIDUAL_GROUPS[group]] ** 2))
        assert 0.6 < chi2 < 1.6, (group, chi2)
    assert np.mean(e[:, RESIDUAL_GROUPS["position"]] ** 2) < 0.5
    assert np.all(e[:, RESIDUAL_GROUPS["bias"]] == 0.0)
    # a wrong gravity or bias shows: 0.1 m/s^2 off raises the velocity residuals many-fold
    values.update(GRAVITY.key(0), imu.gravity + np.array([0.1, 0.0, 0.0]))
    factor = gtsam.CombinedImuFactorWithGravityVector(
        BOARD_POSE.key(0), IMU_VELOCITY.key(0), BOARD_POSE.key(1), IMU_VELOCITY.key(1),
        IMU_BIAS_STATE.key(0), IMU_BIAS_STATE.key(1), GRAVITY.key(0), pre.measurements[0])
    off = factor.whitenedError(values)[RESIDUAL_GROUPS["velocity"]]
    assert np.sum(off**2) > 10 * np.sum(e[0, RESIDUAL_GROUPS["velocity"]] ** 2)
    assert len(errors) == len(pre.steps)


def test_steps_outside_the_stream_are_gaps():
    # a 0.3 s hole in a 100 Hz stream and states before its start: the steps that reach
    # into either get no preintegrated factor; a step with no time between its states
    # neither
    t = np.arange(0.0, 3.0, 0.01)
    t = t[(t < 1.0) | (t > 1.3)]
    stream = ImuStream(t, np.tile([0.0, 0.0, 9.8], (len(t), 1)), np.zeros((len(t), 3)))
    states = np.array([-0.1, 0.05, 0.5, 0.9, 1.1, 1.2, 1.5, 1.5, 2.0])
    pre = preintegrate(stream, states, GraphOptions())
    assert pre.steps.tolist() == [1, 2, 7]
    assert pre.gaps.tolist() == [0, 3, 4, 5, 6]
    # a step within the stream integrates its time exactly
    assert [m.deltaTij() for m in pre.measurements] == pytest.approx([0.45, 0.4, 0.5])


def test_bias_family_round_trip():
    # the per-state bias is a ConstantBias in the values; the layout reads its vectors back
    layout = VariableLayout.of_problem(3, 2, inertial=True, combined_imu=True)
    assert layout.holds(IMU_BIAS_STATE, 2) and layout.holds(IMU_VELOCITY, 2)
    assert layout.holds(GRAVITY, 0)
    values = gtsam.Values()
    data = np.arange(18.0).reshape(3, 6)
    layout.insert(values, IMU_BIAS_STATE, data)
    np.testing.assert_array_equal(layout.read_vectors(values, IMU_BIAS_STATE), data)
    bias = values.atConstantBias(IMU_BIAS_STATE.key(1))
    np.testing.assert_array_equal(bias.accelerometer(), data[1, :3])
    np.testing.assert_array_equal(bias.gyroscope(), data[1, 3:])


def test_imu_factor_choice():
    assert GraphOptions().imu.factor_kind == "combined"
    assert GraphOptions.of(gyro_scale_sigma=0.1).imu.factor_kind == "twist"
    assert GraphOptions.of(gyro_preintegration=True).imu.factor_kind == "twist"
    assert GraphOptions.of(imu_factors="twist").imu.factor_kind == "twist"
    assert GraphOptions.of(imu_factors="combined", imu_time_offset_sigma_s=0.01).imu.calibrated
    with pytest.raises(InputError, match="imu_factors"):
        GraphOptions.of(imu_factors="combined", imu_position_sigma_m=0.01)
    with pytest.raises(InputError, match="imu_factors"):
        GraphOptions.of(imu_factors="combined", gyro_preintegration=True)


def test_facing_stations_solve_with_the_combined_factors():
    # issue #16's family: the light alone cannot join the stations; with GTSAM's combined
    # IMU factors station 1 comes out within 2 mm / 0.05 deg, the gravity's direction
    # within 0.2 deg and the gyro bias within 1e-3 rad/s of the simulation's
    sim = simulate(load_simulation_config(FACING), 1)
    models = {k: s.model for k, s in sim.truth.stations.items()}
    result = solve_graph(sim.board, sim.angles, models, GraphOptions.of(imu_factors="combined"),
                         imu=sim.imu.stream)
    error = station_errors(sim.truth, result.stations)[0]
    assert error.position_norm_m < 2e-3 and np.degrees(error.rotation_rad) < 0.05, error
    d = result.diagnostics
    assert d["imu_factors"] > 0.9 * len(result.trajectory.time)
    assert abs(d["gravity_mps2"] - 9.80665) < 0.1
    assert abs(d["gyro_bias_rad_s"] - np.linalg.norm(sim.imu.bias[:3])) < 1e-3
    up = np.asarray(sim.truth.extra["simulation"]["up"])
    R0 = sim.truth.pose(0)[:3, :3]  # the world here is station 0's frame
    down = -(R0.T @ up) / np.linalg.norm(up)
    g = result.gravity_world / np.linalg.norm(result.gravity_world)
    assert np.degrees(np.arccos(np.clip(g @ down, -1, 1))) < 0.2


def test_deck_with_a_hole_in_the_imu_solves(short_deck):
    # a 1 s hole in the IMU stream: the steps in it get a bias walk and their states a
    # loose velocity prior, so the graph stays determined and the stations come out as
    # well as with the light alone
    imu = simulate_imu(short_deck, seed=1).stream
    keep = (imu.time < 8.0) | (imu.time > 9.0)
    holed = ImuStream(imu.time[keep], imu.accel_mps2[keep], imu.gyro_rad_s[keep])
    models = {k: s.model for k, s in short_deck.truth.stations.items()}
    light = solve_graph(short_deck.board, short_deck.angles, models)
    result = solve_graph(short_deck.board, short_deck.angles, models, imu=holed)
    assert result.status == "converged"
    n = len(result.trajectory.time)
    assert 0.8 * n < result.diagnostics["imu_factors"] < n - 20
    errors = [station_errors(short_deck.truth, r.stations)[0].position_norm_m
              for r in (light, result)]
    assert errors[1] < max(errors[0], 2e-3), errors
    # the IMU calibration from the light's rotations is refused on few-diode data
    from lhgraph.errors import SolverError

    with pytest.raises(SolverError, match="few-diode"):
        solve_graph(short_deck.board, short_deck.angles, models,
                    GraphOptions.of(imu_factors="combined", gyro_scale_sigma=0.1), imu=holed)


def test_an_imu_that_misfits_the_light_falls_back_to_the_twist_factors():
    # a gyro reading half the rate (as hive's does): GTSAM's combined factors, trusting the
    # readings' own noise, bend the light; the solve says so and refines with the twist
    # factors instead (asked for explicitly, the combined factors stay, with the warning)
    config = dataclasses.replace(load_simulation_config("configs/simulation/default.toml"),
                                 duration_s=4.0,
                                 imu=ImuConfig(rate_hz=500.0, gyro_scale_x=0.5,
                                               gyro_scale_y=0.5, gyro_scale_z=0.5))
    sim = simulate(config, 1)
    models = {k: s.model for k, s in sim.truth.stations.items()}
    result = solve_graph(sim.board, sim.angles, models, imu=sim.imu.stream)
    assert any("refined with the twist factors" in w for w in result.warnings)
    assert "accel_sigma_mps2" in result.diagnostics  # the twist factors' summary
    kept = solve_graph(sim.board, sim.angles, models, GraphOptions.of(imu_factors="combined"),
                       imu=sim.imu.stream)
    assert not any("twist" in w for w in kept.warnings)
    assert any("the IMU disagrees with the light" in w for w in kept.warnings)
    assert "imu_chi2_rotation" in kept.diagnostics


def test_imu_calibration_from_the_true_poses(miscalibrated_imu):
    # from the true path, the window fit finds the scales within 0.005, the offset within
    # 1 ms and the frame within 0.2 deg; applied, the stream reads the board's rates
    from lhgraph.estimation.imu.calibration import fit_imu_calibration
    from lhgraph.geometry.transforms import rotation_angle, so3_exp

    sim = miscalibrated_imu
    times = np.arange(0.2, 7.8, 0.008)
    found = fit_imu_calibration(sim.imu.stream, times, sim.trajectory.at(times))
    np.testing.assert_allclose(found.scale, [0.5, 0.47, 0.52], atol=0.005)
    assert abs(found.time_offset_s - 0.006) < 1e-3
    R = so3_exp([0.02, -0.015, 0.01])  # IMU to board
    assert np.degrees(rotation_angle(found.R_board_imu.T @ R)) < 0.2
    nothing = fit_imu_calibration(sim.imu.stream, times, sim.trajectory.at(times),
                                  scale=False, offset=False, rotation=False)
    assert nothing.time_offset_s == 0.0
    np.testing.assert_array_equal(nothing.scale, np.ones(3))
    np.testing.assert_allclose(nothing.R_board_imu, np.eye(3), atol=1e-12)
    fixed = found.apply(sim.imu.stream)
    np.testing.assert_allclose(fixed.time, sim.imu.stream.time - found.time_offset_s)


def test_combined_factors_with_the_calibration_from_the_light(miscalibrated_imu):
    # asked to solve the calibration, the combined factors take it from the light-only
    # solution: station 1 as close as with the twist factors that solve it in the graph
    # (measured 0.43 against 0.39 mm, light alone 0.32), the calibration in the diagnostics;
    # the tracker, with no light-only stage, refuses that combination in one line
    from lhgraph.estimation.graph.track import track

    sim = miscalibrated_imu
    models = {k: s.model for k, s in sim.truth.stations.items()}
    asked = dict(gyro_scale_sigma=1.0, imu_time_offset_sigma_s=0.02,
                 imu_rotation_sigma_rad=0.1)
    result = solve_graph(sim.board, sim.angles, models,
                         GraphOptions.of(imu_factors="combined", **asked), imu=sim.imu.stream)
    error = station_errors(sim.truth, result.stations)[0]
    assert error.position_norm_m < 1e-3, error
    d = result.diagnostics
    np.testing.assert_allclose([d["gyro_scale_x"], d["gyro_scale_y"], d["gyro_scale_z"]],
                               [0.5, 0.47, 0.52], atol=0.01)
    assert abs(d["imu_time_offset_s"] - 0.006) < 0.004
    assert d["imu_chi2_rotation"] < 1.0 and not result.warnings
    with pytest.raises(InputError, match="imu_factors"):
        track(sim.board, sim.angles, sim.truth, models,
              GraphOptions.of(imu_factors="combined", **asked), imu=sim.imu.stream)


def test_a_stream_that_covers_no_step_is_refused(short_deck):
    # a stream whose samples are all further apart than imu_max_gap_s: one line naming it
    imu = simulate_imu(short_deck, seed=1).stream
    sparse = ImuStream(imu.time[::8], imu.accel_mps2[::8], imu.gyro_rad_s[::8])  # 12.5 Hz
    models = {k: s.model for k, s in short_deck.truth.stations.items()}
    with pytest.raises(InputError, match="covers no step"):
        solve_graph(short_deck.board, short_deck.angles, models,
                    GraphOptions.of(imu_max_gap_s=0.05), imu=sparse)
