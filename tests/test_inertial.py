"""IMU factors (lhgraph.estimation.imu.inertial): the accelerometer residual's Jacobians against
numerical ones, the IMU readings at the board states, and tracking a simulated deck with a
simulated IMU (known bias and gravity).

Why the bounds: the simulated IMU has 2e-3 rad/s and 0.02 m/s^2 of white noise per 100 Hz
sample and biases of 5e-3 rad/s / 0.05 m/s^2; over 20 s of deck data the gravity direction
comes out within a few tenths of a degree (measured 0.23 deg) and the gyro bias within
2e-3 rad/s per axis (it trades off against the motion prior's angular rates); the IMU
halves the rotation error of the few-diode path (measured 0.58 -> 0.30 deg) and does not
worsen the positions."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from lhgraph.cli import main
from lhgraph.errors import InputError
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.graph.track import track
from lhgraph.estimation.imu.inertial import inertial_data
from lhgraph.estimation.residuals import accel_residuals, gyro_residuals
from lhgraph.geometry.transforms import rotation_angle, se3_exp, so3_exp
from lhgraph.importers.crazyflie import import_crazyflie
from lhgraph.io.angles import load_angles
from lhgraph.io.imu import ImuStream, load_imu, save_imu
from lhgraph.io.stations import load_stations, save_stations
from lhgraph.model.boards import crazyflie_deck
from lhgraph.model.calibration import StationCalibration, save_calibration
from lhgraph.sim.simulate import load_simulation_config, simulate, simulate_imu, write_simulation
from lhgraph.workflow.inputs import station_models
from lhgraph.workflow.solve import solve

FACING = "configs/simulation/facing_planar_imu.toml"
"""Stations 170 deg apart, the planar 32-diode board, a 1 kHz IMU."""


@pytest.fixture(scope="module")
def deck_with_imu():
    config = dataclasses.replace(load_simulation_config("configs/simulation/deck.toml"),
                                 duration_s=20.0)
    capture = simulate(config, 2)
    return capture, simulate_imu(capture, seed=1)


def test_accel_jacobians_match_numerical():
    rng = np.random.default_rng(1)
    K, eps = 5, 1e-7
    X0, X1 = se3_exp(rng.normal(size=(K, 6))), se3_exp(rng.normal(size=(K, 6)))
    V0, V1 = rng.normal(size=(K, 6)), rng.normal(size=(K, 6))
    dt = rng.uniform(0.01, 0.03, K)
    force, bias, gravity = rng.normal(size=(K, 3)), rng.normal(size=3), rng.normal(size=3)
    args = [X0, V0, X1, V1, bias, gravity]
    e, H = accel_residuals(X0, V0, X1, V1, dt, force, bias, gravity)
    for i, analytic in enumerate(H):
        numerical = np.zeros_like(analytic)
        for j in range(analytic.shape[2]):
            d = np.zeros(analytic.shape[2])
            d[j] = eps
            moved = list(args)
            moved[i] = args[i] @ se3_exp(np.broadcast_to(d, (K, 6))) if i in (0, 2) \
                else args[i] + d
            ep, _ = accel_residuals(*moved[:4], dt, force, *moved[4:], jacobians=False)
            numerical[:, :, j] = (ep - e) / eps
        scale = max(1.0, float(np.max(np.abs(analytic))))
        assert np.max(np.abs(numerical - analytic)) < 1e-5 * scale, i


def test_accel_residual_zero_on_true_motion():
    # constant acceleration a, turning at omega: the residual vanishes with the true
    # specific force in state 0's frame
    R0 = so3_exp(np.array([[0.1, -0.2, 0.3]]))
    omega, dt = np.array([0.5, 0.2, -0.4]), np.array([0.02])
    R1 = R0 @ so3_exp(omega * dt[0])[None]
    u0, a, g = np.array([0.3, -0.1, 0.2]), np.array([1.0, 2.0, -0.5]), np.array([0, 0, -9.81])
    u1 = u0 + a * dt[0]
    X0, X1 = np.eye(4)[None].repeat(1, 0), np.eye(4)[None].repeat(1, 0)
    X0[:, :3, :3], X1[:, :3, :3] = R0, R1
    V0 = np.concatenate([omega, R0[0].T @ u0])[None]
    V1 = np.concatenate([omega, R1[0].T @ u1])[None]
    force = (R0[0].T @ (a - g))[None]
    e, _ = accel_residuals(X0, V0, X1, V1, dt, force, np.zeros(3), g, jacobians=False)
    assert np.allclose(e, 0.0, atol=1e-12)
    assert np.allclose(gyro_residuals(V0, np.zeros(3), omega[None]), 0.0)


def test_readings_at_states_rotated_and_gapped():
    t = np.arange(0.0, 1.0, 0.01)
    omega = np.array([0.0, 0.0, 2.0])
    stream = ImuStream(t, np.tile([1.0, 0.0, 9.8], (len(t), 1)), np.tile(omega, (len(t), 1)))
    states = np.array([0.105, 0.125, 0.5, 1.5])  # the last one after the stream
    d = inertial_data(stream, states, max_gap_s=0.05)
    assert d.rate_ok.tolist() == [True, True, True, False]
    assert np.allclose(d.rate[:3], omega)
    # the force over the first step, at its middle, seen from state 0's frame
    expected = so3_exp(omega * 0.01) @ np.array([1.0, 0.0, 9.8])
    assert np.allclose(d.force[0], expected)
    assert d.force_ok.tolist() == [True, True, False]
    with pytest.raises(InputError, match="no gyro"):
        inertial_data(ImuStream(t, stream.accel_mps2), states)
    with pytest.raises(InputError, match="not on the light's clock"):
        inertial_data(stream, states + 100.0)


def test_track_deck_with_imu_recovers_gravity_and_bias(deck_with_imu):
    capture, imu = deck_with_imu
    truth = capture.trajectory

    def errors(path):
        T = truth.at(path.trajectory.time)
        pos = np.linalg.norm(path.trajectory.T_world_board[:, :3, 3] - T[:, :3, 3], axis=1)
        rot = rotation_angle(np.einsum("kji,kjl->kil", T[:, :3, :3],
                                       path.trajectory.T_world_board[:, :3, :3]))
        return np.median(pos), np.median(rot)

    plain = track(capture.board, capture.angles, capture.truth)
    with_imu = track(capture.board, capture.angles, capture.truth, imu=imu.stream)
    assert with_imu.status == "converged"
    angle = np.arccos(with_imu.gravity @ imu.gravity
                      / np.linalg.norm(with_imu.gravity) / np.linalg.norm(imu.gravity))
    assert np.degrees(angle) < 1.0
    assert abs(np.linalg.norm(with_imu.gravity) - 9.80665) < 0.1
    assert np.max(np.abs(with_imu.imu_bias[:3] - imu.bias[:3])) < 3e-3
    pos0, rot0 = errors(plain.path)
    pos1, rot1 = errors(with_imu.path)
    assert rot1 < 0.7 * rot0
    assert pos1 < 1.05 * pos0
    assert plain.gravity is None and "gravity_mps2" not in plain.diagnostics


def test_cli_track_imu(tmp_path, capsys, deck_with_imu):
    capture, imu = deck_with_imu
    short = dataclasses.replace(capture.config, duration_s=3.0)
    sim = simulate(short, 4)
    write_simulation(sim, tmp_path / "sim")
    save_stations(sim.truth, tmp_path / "stations.toml")
    save_imu(simulate_imu(sim, seed=2).stream, tmp_path / "imu.csv")
    common = ["track", "--stations", str(tmp_path / "stations.toml"), "--board",
              "crazyflie_deck", "--angles", str(tmp_path / "sim" / "angles.csv"), "--imu",
              str(tmp_path / "imu.csv")]
    assert main([*common, "--output", str(tmp_path / "t.csv"), "--quiet"]) == 0
    assert (tmp_path / "t.csv").is_file()
    assert main([*common, "--output", str(tmp_path / "s.csv"), "--streaming"]) == 2
    assert "batch only" in capsys.readouterr().err
    assert not (tmp_path / "s.csv").exists()


def test_solve_with_imu(tmp_path, capsys, deck_with_imu):
    # the calibration refined with the IMU (CLI flag and config key); the paper's method
    # has no use for an IMU: one line, exit 2
    capture, imu = deck_with_imu
    write_simulation(capture, tmp_path / "sim")
    save_imu(imu.stream, tmp_path / "imu.csv")
    save_calibration({k: StationCalibration(s.model.calibration)
                      for k, s in capture.truth.stations.items()}, tmp_path / "ootx.toml")
    out = tmp_path / "st.toml"
    args = ["solve", "--board", str(tmp_path / "sim" / "board.toml"), "--angles",
            str(tmp_path / "sim" / "angles.csv"), "--calibration", str(tmp_path / "ootx.toml"),
            "--imu", str(tmp_path / "imu.csv")]
    assert main([*args, "--output", str(out), "--quiet"]) == 0
    solved = load_stations(out)
    truth = capture.truth
    T = np.linalg.inv(truth.pose(0)) @ truth.pose(1)
    assert np.linalg.norm(solved.pose(1)[:3, 3] - T[:3, 3]) < 0.01
    assert main([*args, "--output", str(tmp_path / "p.toml"), "--method", "paper"]) == 2
    assert "does not use an IMU" in capsys.readouterr().err
    (tmp_path / "solve.toml").write_text(
        'board = "sim/board.toml"\nangles = "sim/angles.csv"\nimu = "imu.csv"\n'
        'calibration = "ootx.toml"\noutput = "c.toml"\n')
    assert main(["solve", str(tmp_path / "solve.toml"), "--quiet"]) == 0
    assert (tmp_path / "c.toml").is_file()


def test_world_gravity_from_the_imu(tmp_path, deck_with_imu):
    # --world gravity with --imu: +z is the up the IMU observed (the simulated truth's), and
    # with the stations' OOTX vectors too the angle between the two ups is reported
    capture, imu = deck_with_imu
    models = {k: s.model for k, s in capture.truth.stations.items()}
    up0 = np.asarray(capture.truth.extra["simulation"]["up"])  # station 0 = the sim's world
    result = solve(capture.board, capture.angles, models=models, world_up={},
                   imu=imu.stream)
    R0 = result.stations.pose(0)[:3, :3]  # station 0 in the gravity world
    assert np.degrees(np.arccos(np.clip((R0 @ up0)[2], -1, 1))) < 1.0
    assert result.stations.extra["world"] == "gravity"
    assert result.gravity_world[2] < -9.0
    ootx_up = {k: np.linalg.inv(capture.truth.pose(k))[:3, :3] @ up0 for k in (0, 1)}
    both = solve(capture.board, capture.angles, models=models, world_up=ootx_up,
                 imu=imu.stream)
    assert both.diagnostics["imu_ootx_up_deg"] < 1.0
    with pytest.raises(InputError, match="--imu"):
        solve(capture.board, capture.angles, models=models, world_up={})


def test_simulate_writes_imu_csv(tmp_path, capsys):
    # an [imu] table: lhgraph simulate writes imu.csv, the light unchanged, the truth's
    # bias and gravity recorded; a bad key is one line, exit 2
    base = (Path("configs/simulation/deck.toml").read_text()
            .replace("duration_s = 120.0", "duration_s = 2.0"))
    (tmp_path / "plain.toml").write_text(base)
    (tmp_path / "imu.toml").write_text(base + "\n[imu]\nrate_hz = 200.0\n")
    for name in ("plain", "imu"):
        assert main(["simulate", str(tmp_path / f"{name}.toml"), "--output",
                     str(tmp_path / name), "--quiet"]) == 0
    stream = load_imu(tmp_path / "imu" / "imu.csv")
    assert np.median(np.diff(stream.time)) == pytest.approx(1 / 200, rel=1e-3)
    assert not (tmp_path / "plain" / "imu.csv").exists()
    assert ((tmp_path / "imu" / "angles.csv").read_bytes()
            == (tmp_path / "plain" / "angles.csv").read_bytes())
    truth = load_stations(tmp_path / "imu" / "truth.toml")
    assert len(truth.extra["simulation"]["imu_bias"]) == 6
    (tmp_path / "bad.toml").write_text(base + "\n[imu]\nrate = 100.0\n")
    assert main(["simulate", str(tmp_path / "bad.toml"), "--output",
                 str(tmp_path / "bad")]) == 2
    assert "imu" in capsys.readouterr().err


LH1_LOG = (Path(__file__).resolve().parents[2] / "shared" / "data" / "bitcraze-positioning"
           / "lh1_crossingBeam_move")


@pytest.mark.skipif(not (LH1_LOG / "log02").is_file(), reason="needs ../shared's Crazyflie log")
def test_real_crazyflie_imu_fits_the_light(tmp_path):
    # 15 s of Bitcraze's LH1 log tracked through cfclient's geometry: the deck's IMU, taken
    # in the board frame on the light's clock, fits the path (a wrong frame or clock would
    # leave residuals of ~1 rad/s: the deck turns at a median 1.2 rad/s). The twist factors'
    # rms residuals; the combined factors' whitened mean squares (measured 0.37 for the
    # rotation, 2.2 for the velocity: the deck's vibration and hit times)
    import_crazyflie(LH1_LOG / "log02", tmp_path, LH1_LOG / "system-config.yaml")
    angles = load_angles(tmp_path / "angles.csv")
    angles = angles.select(np.flatnonzero((angles.time > 20.0) & (angles.time < 35.0)))

    def diagnostics(kind: str) -> dict[str, float]:
        return track(crazyflie_deck(), angles,
                     load_stations(tmp_path / "stations-cfclient.toml"),
                     station_models(tmp_path / "ootx.toml"), GraphOptions.of(imu_factors=kind),
                     imu=load_imu(tmp_path / "imu.csv")).diagnostics

    d = diagnostics("twist")
    assert d["gyro_rms_rad_s"] < 0.02
    assert d["accel_rms_mps2"] < 1.0
    assert abs(d["gravity_mps2"] - 9.80665) < 1.0  # 15 s: the magnitude trades with a bias
    d = diagnostics("combined")
    assert d["imu_chi2_rotation"] < 1.5 and d["imu_chi2_velocity"] < 5.0, d
    assert d["imu_factors"] > 400
    assert abs(d["gravity_mps2"] - 9.80665) < 1.0


def test_gyro_scale_and_time_offset_are_solved(miscalibrated_imu):
    # solved with the IMU calibration: the scales within 2 %, the offset within 2 ms (it
    # comes out 1.5-1.7 ms low over these 8 s, with either accelerometer noise estimate), and
    # station 1 better than with the IMU taken as read
    from lhgraph.estimation.graph.solver import solve_graph
    from lhgraph.estimation.metrics import station_errors

    sim = miscalibrated_imu
    models = {k: s.model for k, s in sim.truth.stations.items()}
    as_read = solve_graph(sim.board, sim.angles, models, GraphOptions.of(imu_factors="twist"),
                         imu=sim.imu.stream)
    solved = solve_graph(sim.board, sim.angles, models,
                         GraphOptions.of(gyro_scale_sigma=1.0, imu_time_offset_sigma_s=0.02,
                                      imu_rotation_sigma_rad=0.1),
                         imu=sim.imu.stream)
    d = solved.diagnostics
    np.testing.assert_allclose([d["gyro_scale_x"], d["gyro_scale_y"], d["gyro_scale_z"]],
                               [0.5, 0.47, 0.52], rtol=0.02)
    assert d["imu_time_offset_s"] == pytest.approx(0.006, abs=2e-3)
    assert np.radians(d["imu_rotation_deg"]) == pytest.approx(
        np.linalg.norm([0.02, -0.015, 0.01]), abs=3e-3)
    assert "gyro_scale_x" not in as_read.diagnostics
    error = {name: station_errors(sim.truth, r.stations)[0].position_norm_m
             for name, r in (("as read", as_read), ("solved", solved))}
    assert error["solved"] < 0.5 * error["as read"]
    assert error["solved"] < 1e-3


def test_imu_position_is_solved():
    # an IMU 5-8 cm from the board origin (the accelerometer reads that point's centripetal
    # and angular acceleration too): solved with imu_position_sigma_m, its position within
    # 1 cm per axis and the accelerometer's residuals several times smaller than with the
    # IMU taken at the origin
    from lhgraph.estimation.graph.solver import solve_graph
    from lhgraph.sim.imu import ImuConfig

    position = np.array([0.05, -0.04, 0.06])
    config = dataclasses.replace(
        load_simulation_config("configs/simulation/default.toml"),
        imu=ImuConfig(position_x_m=position[0], position_y_m=position[1],
                      position_z_m=position[2]))
    sim = simulate(config, 1)
    models = {k: s.model for k, s in sim.truth.stations.items()}
    as_read = solve_graph(sim.board, sim.angles, models, GraphOptions.of(imu_factors="twist"),
                         imu=sim.imu.stream)
    solved = solve_graph(sim.board, sim.angles, models, GraphOptions.of(imu_position_sigma_m=0.1),
                         imu=sim.imu.stream)
    d = solved.diagnostics
    found = np.array([d["imu_position_x_m"], d["imu_position_y_m"], d["imu_position_z_m"]])
    np.testing.assert_allclose(found, position, atol=0.01)
    assert d["accel_rms_mps2"] < 0.4 * as_read.diagnostics["accel_rms_mps2"]


def test_imu_calibration_jacobians_match_numerical(miscalibrated_imu):
    # the gyro and accelerometer factors' Jacobians with respect to the calibration (scale
    # error per axis, time offset, IMU rotation and position) and, with the lever arm, the
    # accelerometer factors' with respect to the states' angular rates, against central
    # differences of the evaluator's residuals
    from lhgraph.estimation.graph.factors import build_graph
    from lhgraph.estimation.graph.variables import BOARD_TWIST, IMU_CALIBRATION, initial_values
    from lhgraph.estimation.imu.inertial import initial_gravity
    from lhgraph.estimation.init.pnp_kabsch import PnPKabschInitialiser
    from lhgraph.estimation.problem import build_problem

    sim = miscalibrated_imu
    options = GraphOptions.of(gyro_scale_sigma=1.0, imu_time_offset_sigma_s=0.02,
                           imu_rotation_sigma_rad=0.1, imu_position_sigma_m=0.1)
    problem = build_problem(sim.board, sim.angles, {}, 0)
    data = inertial_data(sim.imu.stream, problem.state_time)
    graph, ev = build_graph(problem, options, inertial=data)
    init = PnPKabschInitialiser()(sim.board, sim.angles, problem)
    values = initial_values(ev.layout, init, initial_gravity(data, init.X))
    key = IMU_CALIBRATION.key(0)
    c0 = np.array([-0.4, 0.1, 0.05, 0.003, 0.02, -0.01, 0.015, 0.03, -0.05, 0.04])
    values.update(key, c0)
    lin = graph.linearize(values)
    gyro_rows, accel_rows = [], []
    for i in range(graph.size()):
        keys = list(graph.at(i).keys())
        if keys[-1] == key and len(keys) == 3:
            gyro_rows.append(i)
        elif keys[-1] == key and len(keys) > 3:
            accel_rows.append(i)
    assert len(gyro_rows) == int(data.rate_ok.sum()) and len(accel_rows) > 0
    h = np.array([1e-6, 1e-6, 1e-6, 1e-7, 1e-6, 1e-6, 1e-6, 1e-6, 1e-6, 1e-6])
    dim = IMU_CALIBRATION.dim
    numerical = []
    for j in range(dim):
        residuals = []
        for sign in (1, -1):
            v = gtsam_values_with(values, key, c0 + sign * h[j] * np.eye(dim)[j])
            ev.evaluate(v)
            residuals.append(ev.twist_imu.terms.residuals())
        numerical.append([(p - m) / (2 * h[j]) for p, m in zip(*residuals, strict=True)])
    ev.evaluate(values)
    for rows, which in ((gyro_rows, 0), (accel_rows, 1)):
        states = np.flatnonzero(data.rate_ok if which == 0 else data.force_ok)
        for i, k in zip(rows[::25], states[::25], strict=False):
            sigma = (options.imu.gyro_sigma_rad_s if which == 0
                     else ev.twist_imu.terms.accel_sigmas[k])
            A = lin.at(i).getA()[:, -dim:] * sigma  # unwhitened
            num = np.stack([numerical[j][which][k] for j in range(dim)], axis=1)
            np.testing.assert_allclose(A, num, atol=1e-4 * max(1.0, np.abs(num).max()))
    # the accelerometer factor over k -> k + 1 by state k's and state k + 1's angular rate
    # (the twist's first three columns after each pose's six)
    for i, k in zip(accel_rows[5::40], np.flatnonzero(data.force_ok)[5::40], strict=False):
        A = lin.at(i).getA() * ev.twist_imu.terms.accel_sigmas[k]
        for state, columns in ((k, slice(6, 9)), (k + 1, slice(18, 21))):
            twist_key = BOARD_TWIST.key(int(state))
            w0 = values.atVector(twist_key)
            num = []
            for j in range(3):
                residuals = []
                for sign in (1, -1):
                    ev.evaluate(gtsam_values_with(values, twist_key,
                                                  w0 + sign * 1e-6 * np.eye(6)[j]))
                    residuals.append(ev.twist_imu.terms.residuals()[1][k])
                num.append((residuals[0] - residuals[1]) / 2e-6)
            num = np.stack(num, axis=1)
            np.testing.assert_allclose(A[:, columns], num,
                                       atol=1e-4 * max(1.0, np.abs(num).max()))


def gtsam_values_with(values, key, vector):
    """A copy of ``values`` with ``key`` set to ``vector``."""
    import gtsam

    out = gtsam.Values(values)
    out.update(key, vector)
    return out


def test_dead_reckoning_follows_the_true_motion():
    # noise-free, bias-free 1 kHz IMU of the simulator's exact motion: half a second of dead
    # reckoning from the true pose and velocity lands on the true pose
    from lhgraph.estimation.imu.bridge import dead_reckon
    from lhgraph.sim.imu import ImuConfig, imu_of_motion

    config = load_simulation_config("configs/simulation/default.toml")
    sim = simulate(config, 1)
    up = sim.truth.extra["simulation"]["up"]
    imu = imu_of_motion(sim.motion, up, 8.0, ImuConfig(
        rate_hz=1000.0, gyro_sigma_rad_s=0.0, accel_sigma_mps2=0.0, gyro_bias_sigma_rad_s=0.0,
        accel_bias_sigma_mps2=0.0), np.random.default_rng(0))
    t0 = np.array([2.0, 5.0, 6.5])
    t1 = t0 + np.array([0.5, -0.4, 0.3])
    T0, T1 = sim.motion.pose(t0), sim.motion.pose(t1)
    h = 1e-4
    v0 = (sim.motion.pose(t0 + h)[:, :3, 3] - sim.motion.pose(t0 - h)[:, :3, 3]) / (2 * h)
    T = dead_reckon(imu.stream, t0, T0, v0, imu.gravity, t1)
    assert np.max(np.linalg.norm(T[:, :3, 3] - T1[:, :3, 3], axis=1)) < 1e-3
    assert np.max(rotation_angle(np.swapaxes(T[:, :3, :3], 1, 2) @ T1[:, :3, :3])) < 1e-3


def test_facing_stations_with_a_one_sided_board_join_through_the_imu():
    # 170 degrees apart, the board never seen by both at once: the light alone cannot join
    # the stations (one line naming the cause); with the board's IMU it can
    from lhgraph.errors import SolverError
    from lhgraph.estimation.graph.solver import solve_graph
    from lhgraph.estimation.metrics import station_errors

    sim = simulate(load_simulation_config(FACING), 1)
    models = {k: s.model for k, s in sim.truth.stations.items()}
    with pytest.raises(SolverError, match="never seen by it and the reference"):
        solve_graph(sim.board, sim.angles, models)

    # the twist factors (GTSAM's combined factors, the default: tests/test_combined_imu.py)
    result = solve_graph(sim.board, sim.angles, models, GraphOptions.of(imu_factors="twist"),
                         imu=sim.imu.stream)
    error = station_errors(sim.truth, result.stations)[0]
    assert error.position_norm_m < 5e-3 and np.degrees(error.rotation_rad) < 0.3
    # the preintegrated gyro ties the rotations across the turns no station sees
    tied = solve_graph(sim.board, sim.angles, models, GraphOptions.of(gyro_preintegration=True),
                       imu=sim.imu.stream)
    tied_error = station_errors(sim.truth, tied.stations)[0]
    assert tied_error.rotation_rad < 0.5 * error.rotation_rad
    assert np.degrees(tied_error.rotation_rad) < 0.05 and tied_error.position_norm_m < 2e-3
    # the preintegrated gyro's noise is learned from its residuals: from the loose 0.02
    # rad/s down to about the simulated part's 0.002 per reading; held at 0.02, station 1's
    # covariance is several times wider than its error (NEES 0.9 of 6 over six captures)
    part = load_simulation_config(FACING).imu.gyro_sigma_rad_s
    learned = tied.diagnostics["preintegration_sigma_rad_s"]
    assert 0.7 * part < learned < 1.5 * part, learned
    fixed = solve_graph(sim.board, sim.angles, models, GraphOptions.of(
        gyro_preintegration=True, adapt_gyro_sigma=False), imu=sim.imu.stream)
    assert fixed.diagnostics["preintegration_sigma_rad_s"] == 0.02
    rotation_sigma = [np.sqrt(np.trace(r.stations.relative_to_reference().stations[1]
                                       .covariance[:3, :3])) for r in (tied, fixed)]
    assert rotation_sigma[0] < 0.5 * rotation_sigma[1], rotation_sigma


def test_preintegrated_gyro_jacobians_match_numerical(miscalibrated_imu):
    # the preintegrated gyro factors' Jacobians (both poses' rotations, the gyro bias)
    # against central differences of their residuals, at a point off the solution
    import gtsam

    from lhgraph.estimation.graph.factors import build_graph
    from lhgraph.estimation.graph.variables import BOARD_POSE, IMU_BIAS, initial_values
    from lhgraph.estimation.imu.inertial import initial_gravity
    from lhgraph.estimation.init.pnp_kabsch import PnPKabschInitialiser
    from lhgraph.estimation.problem import build_problem

    sim = miscalibrated_imu
    problem = build_problem(sim.board, sim.angles, {}, 0)
    data = inertial_data(sim.imu.stream, problem.state_time)
    graph, ev = build_graph(problem, GraphOptions.of(gyro_preintegration=True), inertial=data)
    init = PnPKabschInitialiser()(sim.board, sim.angles, problem)
    values = initial_values(ev.layout, init, initial_gravity(data, init.X))
    values.update(IMU_BIAS.key(0), np.array([0.02, -0.01, 0.03, 0.0, 0.0, 0.0]))
    ev.evaluate(values)
    ev.twist_imu.jacobians()
    H0, H1, Hb = (H.copy() for H in ev.twist_imu.terms.Hp)
    steps = ev.twist_imu.terms.preintegrated
    assert len(steps) > 0.9 * problem.n_states
    h = 1e-6
    for i in range(0, len(steps), 40):
        k = int(steps[i])
        for key, H in ((BOARD_POSE.key(k), H0), (BOARD_POSE.key(k + 1), H1),
                       (IMU_BIAS.key(0), Hb)):
            num = np.zeros((3, 6))
            for j in range(6):
                out = []
                for sign in (1, -1):
                    v = gtsam.Values(values)
                    d = np.zeros(6)
                    d[j] = sign * h
                    if key == IMU_BIAS.key(0):
                        v.update(key, values.atVector(key) + d)
                    else:
                        v.update(key, values.atPose3(key).retract(d))
                    ev.evaluate(v)
                    out.append(ev.twist_imu.terms.p[i].copy())
                num[:, j] = (out[0] - out[1]) / (2 * h)
            np.testing.assert_allclose(H[i], num, atol=1e-5)
    ev.evaluate(values)


def test_board_capture_carries_the_imu_to_the_solve(tmp_path):
    # the board's path: a simulated capture.lhcap with the ICM-42688-P's records (version 2),
    # `lhgraph decode` writes imu.csv on the angles' clock (times exact, values within half a
    # count), and the facing stations join through it as through the simulator's own stream
    from lhgraph.estimation.graph.solver import solve_graph
    from lhgraph.estimation.metrics import station_errors

    config = FACING
    sim_dir, dec_dir = tmp_path / "sim", tmp_path / "dec"
    assert main(["simulate", config, "--seed", "1", "--capture", "--output", str(sim_dir),
                 "--quiet"]) == 0
    assert main(["decode", str(sim_dir / "capture.lhcap"), "--output", str(dec_dir),
                 "--quiet"]) == 0
    truth, decoded = load_imu(sim_dir / "imu.csv"), load_imu(dec_dir / "imu.csv")
    assert len(decoded.time) == len(truth.time) == 8000
    assert np.abs(decoded.time - truth.time).max() < 0.5e-6  # stamped on the 2 MHz clock
    assert np.abs(decoded.accel_mps2 - truth.accel_mps2).max() <= 16 * 9.80665 / 65536 + 1e-9
    assert np.abs(decoded.gyro_rad_s - truth.gyro_rad_s).max() <= np.radians(2000) / 65536
    sim = simulate(load_simulation_config(config), 1)
    models = {k: s.model for k, s in sim.truth.stations.items()}
    result = solve_graph(sim.board, load_angles(dec_dir / "angles.csv"), models, imu=decoded)
    error = station_errors(sim.truth, result.stations)[0]
    assert error.position_norm_m < 5e-3 and np.degrees(error.rotation_rad) < 0.3


def test_reading_noise_and_the_accelerometer_factor_sigma():
    # the difference-based estimate finds a white noise under a smooth hand-held signal;
    # the options take 4x it for the accelerometer factors, within [floor, ceiling]
    from lhgraph.estimation.imu.inertial import (
        ACCEL_FACTOR_NOISE_RATIO,
        gyro_reading_sigma,
        reading_noise,
    )

    rng = np.random.default_rng(4)
    t = np.arange(0, 60, 0.01)
    smooth = np.stack([3 * np.sin(2 * np.pi * f * t + f) for f in (0.7, 1.3, 2.1)], axis=1)
    sigma = np.array([0.02, 0.05, 0.1])
    noisy = smooth + rng.normal(0, 1, smooth.shape) * sigma
    assert np.allclose(reading_noise(noisy), sigma, rtol=0.1)
    assert gyro_reading_sigma(ImuStream(t, np.zeros_like(noisy), noisy)) == pytest.approx(
        0.1, rel=0.1)  # the noisiest axis
    stream = ImuStream(t, noisy, np.zeros_like(noisy))
    assert GraphOptions().imu.accel_start_sigma(stream) == pytest.approx(
        ACCEL_FACTOR_NOISE_RATIO * 0.1, rel=0.1)
    assert GraphOptions.of(adapt_accel_sigma=False).imu.accel_start_sigma(stream) == 0.5
    assert GraphOptions.of(accel_sigma_mps2=0.1).imu.accel_start_sigma(stream) == 0.1
    slow = np.sin(2 * np.pi * 0.5 * t)[:, None] * np.ones(3)  # no noise: the floor
    assert GraphOptions().imu.accel_start_sigma(ImuStream(t, slow, slow)) == 0.02


def test_long_steps_loosen_their_accelerometer_factor():
    # each step's noise adds, in quadrature, how far the middle reading is from the mean of
    # the readings in the step: a steady or linearly changing force keeps the base noise
    # (the middle reading is the mean), a force that turns within a long step loosens it
    t = np.arange(0.0, 1.2, 0.01)
    accel = np.zeros((len(t), 3))
    accel[:, 1] = t  # a ramp: the middle reading is the mean
    accel[60:, 0] = np.where(t[60:] < 0.9, 0.0, 3.0)  # a step of 3 m/s^2 at 0.9 s
    stream = ImuStream(t, accel, np.zeros_like(accel))
    states = np.array([0.0, 0.005, 0.3, 0.6, 1.0])
    data = inertial_data(stream, states, max_gap_s=0.5)
    assert data.force_spread[0] == 0.0  # one reading
    assert np.allclose(data.force_spread[1:3], 0.0, atol=5e-3)  # the ramp (to a sample)
    # 0.6-1.0 s: middle 0.8 s reads 0, the mean of x is 3 * 10/40: rms over 3 axes
    assert data.force_spread[3] == pytest.approx(0.75 / np.sqrt(3), rel=1e-3)
    assert np.allclose(data.accel_sigmas(0.1), np.sqrt(0.01 + data.force_spread**2))


def test_accelerometer_noise_over_its_redundancy(deck_with_imu):
    # a simulated deck whose accelerometer reads with 0.2 m/s^2 of white noise: the factors'
    # noise starts at 4x the readings' noise from the stream (the 0.5 ceiling here) and stays
    # there with "stream"; over the factors' redundancy ("auto" on few-diode data) it comes
    # out at the simulated noise; "auto" picks the redundancy on few-diode data and with the
    # IMU calibration solved, the stream's start otherwise
    from lhgraph.estimation.graph.resolve import DataFacts, resolve_options
    from lhgraph.estimation.graph.solver import solve_graph
    from lhgraph.sim.imu import ImuConfig

    capture, _ = deck_with_imu
    imu = simulate_imu(capture, ImuConfig(accel_sigma_mps2=0.2), seed=1)
    found = {}
    for estimate in ("stream", "auto"):
        result = solve_graph(capture.board, capture.angles,
                             options=GraphOptions.of(accel_sigma_estimate=estimate,
                                                  imu_factors="twist"),
                             imu=imu.stream)
        found[estimate] = result.diagnostics["accel_sigma_mps2"]
    assert found["stream"] == pytest.approx(0.5, rel=0.05)  # + each step's own term
    assert found["auto"] == pytest.approx(0.2, rel=0.25)
    picks = {(few, calibrated): resolve_options(
        GraphOptions.of(gyro_scale_sigma=0.1 if calibrated else 0.0),
        DataFacts(few, False, 0), inertial=True).options.imu.accel_sigma_estimate
        for few in (False, True) for calibrated in (False, True)}
    assert picks == {(False, False): "stream", (False, True): "redundancy",
                     (True, False): "redundancy", (True, True): "redundancy"}


def test_a_track_can_solve_the_gyro_scale_the_held_stations_determine(miscalibrated_imu):
    # a gyro reading half the rate (as the hive tracker's): tracked as read, the IMU pulls
    # the path off the light; with its scale solved the track fits the light as the
    # light-only track does (a track takes the gyro as read unless told: docs/track.md)
    from lhgraph.estimation.spread import robust_sigma

    sim = miscalibrated_imu
    light = track(sim.board, sim.angles, sim.truth)
    as_read = track(sim.board, sim.angles, sim.truth, imu=sim.imu.stream)
    solved = track(sim.board, sim.angles, sim.truth, options=GraphOptions.of(
        gyro_scale_sigma=0.5), imu=sim.imu.stream)
    spread = {name: robust_sigma(r.residuals.residual_rad)
              for name, r in (("light", light), ("as read", as_read), ("solved", solved))}
    assert solved.status == "converged"
    np.testing.assert_allclose([solved.diagnostics[f"gyro_scale_{a}"] for a in "xyz"],
                               [0.5, 0.47, 0.52], rtol=0.05)
    assert spread["solved"] < 1.2 * spread["light"]
    assert spread["as read"] > 1.5 * spread["solved"], spread
