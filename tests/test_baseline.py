"""The paper pipeline: per-measurement pose, superposition, refinement, end to end."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from lhgraph.errors import InputError, SolverError
from lhgraph.estimation.baseline import PaperOptions, solve_paper
from lhgraph.estimation.baseline.board_poses import (
    BoardPoses,
    estimate_board_pose,
    estimate_board_poses,
    initial_board_pose,
    mirror_pose,
)
from lhgraph.estimation.baseline.station_pose import (
    initial_station_pose,
    interpolate_path,
    refine_station_pose,
)
from lhgraph.estimation.metrics import station_errors
from lhgraph.estimation.reconstruct import Measurements, reconstruct_measurements
from lhgraph.geometry.transforms import (
    interpolate_poses,
    make_pose,
    matrix_to_quat,
    rotation_angle,
    so3_exp,
    transform_points,
)
from lhgraph.io.angles import Angles
from lhgraph.io.trajectory import Trajectory
from lhgraph.model.boards import paper_board
from lhgraph.model.station import FactoryCalibration, StationModel, ideal_angles
from lhgraph.sim.simulate import load_simulation_config, parse_simulation_config, simulate

ROOT = Path(__file__).resolve().parent.parent
DEFAULT = ROOT / "configs" / "simulation" / "default.toml"
BOARD = paper_board()
EXACT = PaperOptions(pose_xatol=1e-10, pose_fatol=1e-24, refine_xatol=1e-10,
                     refine_fatol=1e-24)


def facing(p: np.ndarray, tilt: np.ndarray) -> np.ndarray:
    """Rotation of a board at ``p`` (station frame) whose +z normal faces the station, tilted."""
    z = -p / np.linalg.norm(p)
    x = np.cross([0.0, 0.0, 1.0], z)
    x /= np.linalg.norm(x)
    return so3_exp(tilt) @ np.stack([x, np.cross(z, x), z], axis=1)


def random_board_pose(rng: np.random.Generator, max_tilt: float = 0.8) -> np.ndarray:
    d = rng.uniform(2.0, 5.0)
    direction = np.array([1.0, rng.uniform(-0.6, 0.6), rng.uniform(-0.4, 0.4)])
    p = d * direction / np.linalg.norm(direction)
    tilt = rng.normal(size=3)
    return make_pose(facing(p, tilt / np.linalg.norm(tilt) * rng.uniform(0, max_tilt)), p)


def pose_error(T_est, T_true):
    return (np.linalg.norm(T_est[:3, 3] - T_true[:3, 3]),
            float(rotation_angle(T_true[:3, :3].T @ T_est[:3, :3])))


# --- per-measurement pose ------------------------------------------------------------------------


@pytest.mark.parametrize("seed", range(6))
def test_board_pose_from_exact_angles(seed):
    T = random_board_pose(np.random.default_rng(seed))
    a = ideal_angles(transform_points(T, BOARD.positions))
    T_est, cost, nfev = estimate_board_pose(a[:, 0], a[:, 1], BOARD.positions, BOARD.normals,
                                            options=EXACT)
    dp, dr = pose_error(T_est, T)
    assert dp < 1e-6 and dr < 1e-6 and cost < 1e-18 and nfev > 0
    # warm start from a nearby pose lands on the same answer
    T_near = make_pose(so3_exp([0.01, -0.01, 0.02]) @ T[:3, :3], T[:3, 3] + 0.01)
    T_warm, _, _ = estimate_board_pose(a[:, 0], a[:, 1], BOARD.positions, BOARD.normals,
                                       T_init=T_near, options=EXACT)
    assert max(pose_error(T_warm, T)) < 1e-6


def test_initial_guess_faces_the_station_at_the_right_distance():
    p = np.array([3.0, 0.8, -0.4])
    turn = so3_exp(0.3 * p / np.linalg.norm(p))  # 0.3 rad about the line of sight
    T = make_pose(turn @ facing(p, np.zeros(3)), p)
    a = ideal_angles(transform_points(T, BOARD.positions))
    T0 = initial_board_pose(a[:, 0], a[:, 1], BOARD.positions, BOARD.normals)
    centre = BOARD.positions.mean(axis=0)
    c0, c = transform_points(T0, centre), transform_points(T, centre)
    assert np.linalg.norm(c0 - c) < 0.05 * np.linalg.norm(c)
    assert rotation_angle(T[:3, :3].T @ T0[:3, :3]) < np.radians(5)


def test_mirror_pose_is_the_planar_ambiguity():
    T = random_board_pose(np.random.default_rng(3), max_tilt=0.0)
    T = make_pose(so3_exp([0.0, 0.5, 0.0]) @ T[:3, :3], T[:3, 3])
    Tm = mirror_pose(T, BOARD.positions)
    np.testing.assert_allclose(mirror_pose(Tm, BOARD.positions), T, atol=1e-12)
    assert np.linalg.det(Tm[:3, :3]) == pytest.approx(1.0)
    assert rotation_angle(T[:3, :3].T @ Tm[:3, :3]) > 0.5  # a really different orientation
    a = ideal_angles(transform_points(T, BOARD.positions))
    am = ideal_angles(transform_points(Tm, BOARD.positions))
    spread = np.ptp(a, axis=0).max()
    assert np.abs(am - a).max() < 0.05 * spread  # ... that looks almost the same


# --- paths, superposition, refinement ------------------------------------------------------------


def moving_board(t: np.ndarray) -> np.ndarray:
    """T_ref_board along a curved path, piecewise slerp/lerp between keyframes 1/60 s apart
    (so interpolating between samples at the keyframe times is exact)."""
    k = np.arange(-2, 64) / 60.0
    p = np.c_[3.0 + 0.3 * np.sin(4 * k), 0.3 * np.cos(3 * k), 0.1 + 0.2 * k]
    R = so3_exp(np.outer(np.sin(2 * k), [0.1, 0.4, -0.2])) @ facing(p[0], np.zeros(3))
    return interpolate_poses(k, make_pose(R, p), t)


T_REF_SLAVE = make_pose(so3_exp([0.05, -0.1, 0.6]), [0.4, -1.8, 0.3])


def board_poses(lighthouse: int, t: np.ndarray, T: np.ndarray, cost: np.ndarray) -> BoardPoses:
    n = len(t)
    return BoardPoses(lighthouse, t, T, cost, np.full(n, 32), np.ones(n, dtype=bool),
                      np.ones(n, dtype=np.int64))


def test_interpolated_superposition_recovers_the_station_pose():
    rng = np.random.default_rng(1)
    t_slave = np.arange(40) / 60.0  # the keyframe times: slave interpolation is exact
    t_master = t_slave - 1 / 120.0 + 0.003
    T_slave_ref = np.linalg.inv(T_REF_SLAVE)
    master = board_poses(0, t_master, moving_board(t_master), rng.uniform(1e-8, 1e-6, 40))
    slave = board_poses(1, t_slave, T_slave_ref @ moving_board(t_slave),
                        rng.uniform(1e-8, 1e-6, 40))
    T, ms, ok = interpolate_path(slave, t_master)
    assert not ok[0] and ok[1:].all()  # the first master time precedes the slave path
    assert not np.allclose(T[1:], T_slave_ref @ moving_board(t_slave[1:]), atol=1e-3)
    np.testing.assert_allclose(T[ok], T_slave_ref @ moving_board(t_master[ok]), atol=1e-12)
    for points in ("board", "sensors"):
        T_est = initial_station_pose(master, slave, BOARD, PaperOptions(kabsch_points=points))
        np.testing.assert_allclose(T_est, T_REF_SLAVE, atol=1e-9)
    # a gap in the slave path is not bridged
    gap = np.r_[0:10, 20:40]
    slave_gap = board_poses(1, t_slave[gap], slave.T_lh_board[gap], slave.cost[gap])
    _, _, ok = interpolate_path(slave_gap, t_master)
    assert not ok[11:20].any() and ok[21:].all()


def test_refinement_recovers_the_station_pose_from_exact_data():
    t = np.arange(60) / 60.0
    traj = Trajectory(t, moving_board(t))
    t_meas = t[1:-1] + 1 / 120.0
    p = transform_points(np.linalg.inv(T_REF_SLAVE) @ moving_board(t_meas)[:, None],
                         BOARD.positions[None])
    a = ideal_angles(p)
    meas = Measurements(1, t_meas, a[..., 0], a[..., 1], BOARD.ids, np.zeros(len(t_meas), int))
    T0 = make_pose(so3_exp([0.02, -0.03, 0.01]) @ T_REF_SLAVE[:3, :3],
                   T_REF_SLAVE[:3, 3] + [0.03, -0.02, 0.04])
    ref = refine_station_pose(T0, meas, traj, BOARD, EXACT)
    dp, dr = pose_error(ref.T_ref_lh, T_REF_SLAVE)
    assert dp < 1e-6 and dr < 1e-6 and ref.converged and ref.n_measurements == len(t_meas)


# --- end to end on simulated captures ------------------------------------------------------------


def short_capture(duration_s: float, seed: int, **changes):
    config = replace(load_simulation_config(DEFAULT), duration_s=duration_s, **changes)
    return simulate(config, seed)


def test_end_to_end_paper_accuracy():
    cap = short_capture(2.0, 1)
    events = []
    result = solve_paper(cap.board, cap.angles, progress=lambda *e: events.append(e))
    (err,) = station_errors(cap.truth, result.stations)
    # the paper reaches ~7-9 mm and 0.1-0.2 deg on 8 s captures; 2 s captures are noisier
    assert err.position_norm_m < 0.025 and np.degrees(err.rotation_rad) < 0.5
    assert result.method == "paper" and result.status == "converged"
    assert result.stations.reference == 0
    np.testing.assert_array_equal(result.stations.pose(0), np.eye(4))
    assert result.stations.stations[1].covariance is None
    traj = result.trajectory
    assert np.all(np.diff(traj.time) > 0) and len(traj.time) > 80
    truth_board = cap.trajectory.at(traj.time)  # truth in station 0's frame = the world
    assert np.median(np.linalg.norm(traj.T_world_board[:, :3, 3] - truth_board[:, :3, 3],
                                    axis=1)) < 0.01
    res = result.residuals
    assert len(res.residual_rad) == len(cap.angles) and np.all(res.weight == 1.0)
    assert res.rms_urad() < 1000
    assert np.isfinite(result.final_error) and result.iterations > 0
    assert {"reconstruct", "board_poses", "kabsch", "refine"} <= set(result.timings_s)
    assert events and events[-1] == ("station poses", 1, 1)


def test_factory_calibration_is_removed_before_the_pipeline():
    cal = FactoryCalibration(phase=[0.02, -0.015], tilt=[0.01, -0.02], curve=[0.003, 0.002],
                             gibphase=[1.0, 2.0], gibmag=[0.004, -0.003])
    models = {0: StationModel(cal), 1: StationModel(replace(cal, phase=[-0.01, 0.02]))}
    cap = short_capture(1.2, 2, station_models=models)
    fast = PaperOptions(warm_start=True)
    with_cal = solve_paper(cap.board, cap.angles, models, options=fast)
    without = solve_paper(cap.board, cap.angles, options=fast)
    (good,) = station_errors(cap.truth, with_cal.stations)
    (bad,) = station_errors(cap.truth, without.stations)
    assert good.position_norm_m < 0.03 and np.degrees(good.rotation_rad) < 0.5
    assert bad.position_norm_m > 2 * good.position_norm_m
    assert with_cal.stations.stations[1].model == models[1]
    # residuals are against the raw angles, predicted with the factory model
    assert with_cal.residuals.rms_urad() < 0.5 * without.residuals.rms_urad()


def test_three_stations_each_against_the_reference():
    centre = np.array([0.0, 0.0, 1.2])
    stations = []
    for p in ([-1.0, -2.8, 2.0], [1.2, -2.6, 2.2], [2.6, -1.2, 1.9]):
        x = centre - p
        x /= np.linalg.norm(x)
        y = np.cross([0.0, 0.0, 1.0], x)
        y /= np.linalg.norm(y)
        R = np.stack([x, y, np.cross(x, y)], axis=1)
        stations.append({"position": p, "quaternion": matrix_to_quat(R).tolist()})
    doc = {"duration_s": 1.2, "board": "paper32", "seed": 4, "stations": stations,
           "motion": {"pattern": "wave", "speed_mps": 0.4, "centre_m": centre.tolist()}}
    cap = simulate(parse_simulation_config(doc, "test"))
    result = solve_paper(cap.board, cap.angles, reference=1,
                         options=PaperOptions(warm_start=True))
    assert result.stations.reference == 1 and result.stations.indices() == [0, 1, 2]
    errors = station_errors(cap.truth, result.stations)
    assert len(errors) == 2
    for err in errors:
        assert err.position_norm_m < 0.03 and np.degrees(err.rotation_rad) < 0.5


# --- bad input -----------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def small_capture():
    return short_capture(1.0, 3)


def test_bad_inputs(small_capture):
    cap = small_capture
    a = cap.angles
    with pytest.raises(SolverError, match="reference station 7 never seen"):
        solve_paper(cap.board, a, reference=7)
    with pytest.raises(SolverError, match="at least two stations"):
        solve_paper(cap.board, a.select(a.lighthouse == 0))
    with pytest.raises(SolverError, match="usable measurements"):
        solve_paper(cap.board, a.select(a.time < 0.1))
    wrong = Angles(a.time, a.lighthouse, a.axis, a.sensor + 100, a.angle)
    with pytest.raises(InputError, match="not on the board"):
        solve_paper(cap.board, wrong)
    with pytest.raises(SolverError, match="angles table is empty"):
        solve_paper(cap.board, a.select(a.time < -1))
    with pytest.raises(InputError, match="reconstruction"):
        PaperOptions(reconstruction="cubic")
    with pytest.raises(InputError, match="kabsch_points"):
        PaperOptions(kabsch_points="all")


def test_no_time_overlap_is_reported(small_capture):
    cap = small_capture
    a = cap.angles
    late = (a.lighthouse == 1) & (a.time > 0.6)
    early = (a.lighthouse == 0) & (a.time < 0.4)
    with pytest.raises(SolverError, match="overlap"):
        solve_paper(cap.board, a.select(late | early), options=PaperOptions(warm_start=True))


def test_estimate_board_poses_marks_thin_measurements_invalid(small_capture):
    cap = small_capture
    a = cap.angles.select(cap.angles.lighthouse == 0)
    meas = reconstruct_measurements(a, cap.board)
    meas.azimuth[5, 3:] = np.nan  # only 3 sensors left with both angles
    poses = estimate_board_poses(meas, cap.board, PaperOptions(warm_start=True))
    assert not poses.valid[5] and np.isnan(poses.T_lh_board[5]).all()
    assert poses.valid.sum() >= len(meas) - 3
    assert len(poses.path().time) == poses.valid.sum()


def test_board_pose_fits_identical_on_several_processes(small_capture):
    """The cold fits are independent: a process pool gives bit-identical poses and costs,
    and the progress still reaches every measurement."""
    from lhgraph.estimation.baseline.board_poses import PARALLEL_MIN_FITS, fit_workers

    cap = small_capture
    meas = reconstruct_measurements(cap.angles.select(cap.angles.lighthouse == 0), cap.board)
    assert len(meas) >= PARALLEL_MIN_FITS
    assert fit_workers(2, PARALLEL_MIN_FITS - 1) == 1 and fit_workers(2, 100) == 2
    assert fit_workers(1, 1000) == 1
    seen: list[int] = []
    one = estimate_board_poses(meas, cap.board, PaperOptions(n_jobs=1))
    two = estimate_board_poses(meas, cap.board, PaperOptions(n_jobs=2),
                               lambda stage, done, total: seen.append(done))
    np.testing.assert_array_equal(one.T_lh_board, two.T_lh_board)
    np.testing.assert_array_equal(one.cost, two.cost)
    np.testing.assert_array_equal(one.evaluations, two.evaluations)
    assert seen[0] == 0 and seen[-1] == len(meas) and seen == sorted(seen)
    with pytest.raises(InputError, match="n_jobs"):
        PaperOptions(n_jobs=-1)
