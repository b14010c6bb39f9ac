"""Calibration on the real hive recording (8 s from the start of motion) and the OptiTrack
comparison.

The bag is read from ``<repo>/../shared/data/hive-env8/data8.11.bag`` (no licence: never
copied into the repository); the real-data tests skip when it is absent. Bounds and why:

- inlier residual rms < 300 urad: the recording's angle noise is ~50 urad (single-station
  fits, docs/hive.md); a wrong station pose or a mirrored board path gives mrad;
- inlier fraction > 0.75: with the graph's default noise (40 urad, Cauchy scale 3 sigma =
  120 urad) the measured fraction is 0.81-0.90 (hive's float angles have heavier tails than
  2 MHz quantisation); a failed solve gives ~0.5;
- station distance 2-4 m: both stations see the tracker at ~2 m (single-station PnP) from
  two sides of a room; the solved distance is 2.8 m;
- trajectory vs OptiTrack RMSE < 20 mm: measured ~10 mm (docs/results/hive_evaluation.md);
  time-stamp jitter (+-4 ms at 0.2 m/s) and OptiTrack noise explain ~1-2 mm, single-station
  PnP reaches ~2 mm; a mirrored or mis-scaled path is off by > 50 mm.
"""

from __future__ import annotations

import numpy as np
import pytest

from lhgraph.estimation.graph.solver import solve_graph
from lhgraph.estimation.init.pnp import board_poses, facing_fraction
from lhgraph.estimation.init.pnp_nonplanar import tracker_board_poses
from lhgraph.estimation.reconstruct import reconstruct_measurements
from lhgraph.geometry.transforms import make_pose, pose_from_quat, se3_exp
from lhgraph.importers.hive import align_to_mocap
from lhgraph.io.angles import load_angles
from lhgraph.io.trajectory import Trajectory, load_trajectory
from lhgraph.model.board import load_board
from lhgraph.workflow.window import moving_window


@pytest.fixture(scope="module")
def hive(hive_import):
    _, out = hive_import
    board, angles = load_board(out / "board.toml"), load_angles(out / "angles.csv")
    return board, moving_window(angles, 8.0), load_trajectory(out / "mocap.csv")


@pytest.fixture(scope="module")
def solved(hive):
    board, angles, _ = hive
    return solve_graph(board, angles)


def test_window_starts_when_the_tracker_moves(hive):
    _, angles, mocap = hive
    assert 3.0 < angles.time.min() < 5.0  # OptiTrack: still until ~3.5 s, moving from ~4 s
    assert angles.time.max() - angles.time.min() == pytest.approx(8.0, abs=0.05)


def test_pnp_poses_face_the_station(hive):
    """A photodiode sees only stations in front of it: hit sensors must face the station.
    The planar initialiser once put them all backwards on the curved tracker (mirror poses)."""
    board, angles, _ = hive
    meas = reconstruct_measurements(angles.select(angles.lighthouse == 0), board, "merge")
    pick = np.flatnonzero(meas.both().sum(axis=1) >= 8)[:40]
    az, el, seen = meas.azimuth[pick], meas.elevation[pick], meas.both()[pick]
    tracker = tracker_board_poses(az, el, board.positions, board.normals)
    assert np.all(facing_fraction(tracker.T_lh_board, board.positions, board.normals, seen) == 1)
    assert np.median(tracker.rms_rad) < 100e-6
    planar = board_poses(az, el, board.positions, board.normals)
    ok = planar.valid
    facing = facing_fraction(planar.T_lh_board[ok], board.positions, board.normals, seen[ok])
    assert np.mean(facing == 1) > 0.9


def test_graph_residuals_on_real_data(solved):
    assert solved.residuals.rms_urad() < 300
    assert solved.residuals.inlier_fraction() > 0.75


def test_stations_at_a_plausible_distance(solved):
    p = solved.stations.stations[1].T_world_lh[:3, 3]
    assert 2.0 < np.linalg.norm(p) < 4.0


def test_trajectory_matches_optitrack(hive, solved):
    al = align_to_mocap(solved.trajectory, hive[2])
    assert len(al.time) > 500
    assert al.rmse_mm() < 20.0
    assert al.rmse_deg() < 3.0
    assert abs(al.time_offset_s) < 0.05


def test_align_to_mocap_recovers_known_transforms_and_offset():
    t = np.arange(0.0, 6.0, 1 / 120)
    w = 2 * np.pi * np.array([0.3, 0.5, 0.7])
    rot = np.stack([0.6 * np.sin(w[0] * t), 0.4 * np.sin(w[1] * t), 0.8 * np.sin(w[2] * t)], 1)
    pos = np.stack([0.3 * np.sin(w[1] * t), 0.2 * np.cos(w[0] * t), 0.1 * np.sin(w[2] * t)], 1)
    T_opti_body = se3_exp(np.c_[rot, pos])
    W = make_pose(se3_exp(np.array([0.2, -1.0, 0.5, 0, 0, 0]))[:3, :3], [1.0, 2.0, 0.5])
    H = pose_from_quat([0.02, -0.05, 0.03], [0.9, 0.1, -0.3, 0.2])
    dt = 0.012
    t_path = np.arange(0.5, 5.5, 1 / 120)
    truth = Trajectory(t_path, W @ Trajectory(t, T_opti_body).at(t_path + dt) @ H)
    al = align_to_mocap(truth, Trajectory(t, T_opti_body))
    assert al.time_offset_s == pytest.approx(dt, abs=1e-4)
    assert al.rmse_mm() < 0.1
    assert np.allclose(al.T_body_board, H, atol=1e-4)
    assert np.allclose(al.T_world_opti, W, atol=1e-4)


def test_hive_imu_scale_solved_and_a_wrong_scale_flagged(hive_import):
    # the tracker's gyro reads ~0.48x the true rate (docs/hive.md, against OptiTrack): taken
    # as read, with the preintegrated gyro, the IMU refinement pulls the light apart and says
    # so; with the scale solved (per axis) it finds ~0.5 and agrees with the light
    from lhgraph.estimation.graph.options import GraphOptions
    from lhgraph.io.imu import load_imu
    from lhgraph.model.station import Convention
    from lhgraph.workflow.inputs import station_models

    _, out = hive_import
    board, angles = load_board(out / "board.toml"), moving_window(load_angles(
        out / "angles.csv"), 8.0)
    imu = load_imu(out / "imu.csv")
    models = station_models(out / "ootx.toml", Convention(-1, 1))
    as_read = solve_graph(board, angles, models, GraphOptions.of(gyro_preintegration=True),
                          imu=imu)
    assert any("the IMU disagrees with the light" in w for w in as_read.warnings)
    solved = solve_graph(board, angles, models, GraphOptions.of(
        gyro_preintegration=True, gyro_scale_sigma=1.0), imu=imu)
    scales = [solved.diagnostics[f"gyro_scale_{a}"] for a in "xyz"]
    assert all(0.43 < s < 0.57 for s in scales), scales
    assert not any("disagrees" in w for w in solved.warnings)
