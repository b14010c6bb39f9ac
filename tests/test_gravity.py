"""Gravity-aligned world from the OOTX accelerometer vectors: mapping, alignment, real data."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from lhgraph.cli import main
from lhgraph.errors import InputError
from lhgraph.estimation.graph.solver import solve_graph
from lhgraph.estimation.gravity import (
    accel_dir_from_up,
    gravity_rotation,
    to_gravity_world,
    up_in_station,
    up_vectors,
)
from lhgraph.estimation.result import SolveResult
from lhgraph.geometry.transforms import make_pose, so3_exp
from lhgraph.io.stations import Station, Stations, load_stations
from lhgraph.model.board import load_board
from lhgraph.signal.formats import decode_file
from lhgraph.sim.capture_sim import default_calibrations
from lhgraph.sim.simulate import load_simulation_config, simulate
from lhgraph.workflow.inputs import models_of

ROOT = Path(__file__).resolve().parent.parent
FIXTURE = ROOT / "tests" / "data" / "libsurvive" / "lh1_test_cal_hmd_7s.rec.gz"


def angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b),
                                              -1, 1))))


def test_native_axes_map_to_ours():
    # native frame: x right, y up, z backward; ours: x forward, y left, z up
    np.testing.assert_allclose(up_in_station([0, 127, 0]), [0, 0, 1])
    np.testing.assert_allclose(up_in_station([127, 0, 0]), [0, -1, 0])
    np.testing.assert_allclose(up_in_station([0, 0, 127]), [-1, 0, 0])
    u = np.array([0.2, -0.3, 0.93])
    np.testing.assert_allclose(up_in_station(accel_dir_from_up(u)), u / np.linalg.norm(u),
                               atol=0.01)
    with pytest.raises(InputError, match="accel_dir"):
        up_in_station([0, 0, 0])


def _stations_in(T_world_lh: list[np.ndarray]) -> Stations:
    return Stations(0, {i: Station(T) for i, T in enumerate(T_world_lh)})


def test_alignment_puts_every_station_up_on_z_and_keeps_the_geometry():
    # truth in a z-up world: station 0 pitched down 20 deg, station 1 facing it, rolled 3 deg
    T0 = make_pose(so3_exp([0, 0, 0.3]) @ so3_exp([0, np.radians(20), 0]), [0, 0, 2.0])
    T1 = make_pose(so3_exp([0, 0, np.pi + 0.3]) @ so3_exp([np.radians(3), np.radians(25), 0]),
                   [4.0, 1.0, 2.2])
    up = {i: up_in_station(accel_dir_from_up(T[:3, :3].T @ [0, 0, 1]))
          for i, T in enumerate((T0, T1))}
    solved = _stations_in([T0, T1]).relative_to_reference()  # what a solve returns
    T, spread = gravity_rotation(solved, up)
    assert spread < 0.6  # int8 quantisation only
    for i, T_true in enumerate((T0, T1)):
        R = (T @ solved.pose(i))[:3, :3]
        assert angle_deg(R @ up[i], np.array([0, 0, 1.0])) < 0.6
        # same tilt as the truth: the world differs from the truth's by a yaw only
        assert angle_deg(R.T @ [0, 0, 1], T_true[:3, :3].T @ [0, 0, 1]) < 0.6
    ref_forward = (T @ solved.pose(0))[:3, 0]
    assert abs(ref_forward[1]) < 1e-9 and ref_forward[0] > 0  # heading: reference's forward
    np.testing.assert_allclose(np.linalg.inv(T @ solved.pose(0)) @ (T @ solved.pose(1)),
                               solved.pose(1), atol=1e-12)


def test_no_accelerometer_vector_is_a_clear_error():
    with pytest.raises(InputError, match="no accelerometer vector"):
        gravity_rotation(_stations_in([np.eye(4), np.eye(4)]), {})


def test_disagreeing_stations_warn():
    stations = _stations_in([np.eye(4), make_pose(np.eye(3), [3.0, 0, 0])])
    up = {0: np.array([0, 0, 1.0]), 1: up_in_station(accel_dir_from_up([0, 0.1, 1.0]))}
    result = to_gravity_world(SolveResult("graph", stations, None, None), up)
    assert result.diagnostics["gravity_spread_deg"] > 2.0
    assert any("disagree" in w for w in result.warnings)
    assert result.stations.extra["world"] == "gravity"


def test_simulated_capture_end_to_end(tmp_path):
    """simulate --capture writes each station's accel_dir from the scene's up vector; the
    decoded OOTX brings it back and --world gravity recovers the truth's vertical."""
    cfg = load_simulation_config(ROOT / "configs/simulation/default.toml")
    sim = simulate(dataclasses.replace(cfg, duration_s=3.0), seed=3)
    up_world = np.asarray(sim.truth.extra["simulation"]["up"])
    calibrations = default_calibrations(sim)
    result = solve_graph(sim.board, sim.angles, models_of(calibrations))
    aligned = to_gravity_world(result, up_vectors(calibrations))
    for k, station in aligned.stations.stations.items():
        true_up_in_station = sim.truth.pose(k)[:3, :3].T @ up_world
        assert angle_deg(station.T_world_lh[:3, :3].T @ [0, 0, 1], true_up_in_station) < 0.6
    # the trajectory moves with the stations
    T = aligned.stations.pose(0) @ np.linalg.inv(result.stations.pose(0))
    np.testing.assert_allclose(aligned.trajectory.T_world_board,
                               T @ result.trajectory.T_world_board, atol=1e-12)


def test_real_stations_agree_on_up():
    """libsurvive fixture: two real stations facing each other; with our solved rotation
    their accelerometer vectors agree (0.5 deg on the full recording, docs/model.md)."""
    decoded, _ = decode_file(FIXTURE, "libsurvive", device="HMD")
    board = load_board(FIXTURE.parent / "hmd_board.toml")
    up = up_vectors(decoded.calibrations)
    assert len(up) == 2
    result = solve_graph(board, decoded.angles, models_of(decoded.calibrations))
    aligned = to_gravity_world(result, up)
    assert aligned.diagnostics["gravity_spread_deg"] < 1.0
    assert not any("disagree" in w for w in aligned.warnings)


def test_cli_world_gravity(tmp_path, capsys):
    sim_dir = tmp_path / "sim"
    sim_config = tmp_path / "sim.toml"
    sim_config.write_text((ROOT / "configs/simulation/default.toml").read_text().replace(
        "duration_s = 8.0", "duration_s = 4.0"))
    assert main(["simulate", str(sim_config), "--output", str(sim_dir), "--capture",
                 "--quiet"]) == 0
    out = tmp_path / "stations.toml"
    # angles alone carry no OOTX: a clear error, exit 2
    code = main(["solve", "--board", str(sim_dir / "board.toml"), "--angles",
                 str(sim_dir / "angles.csv"), "--output", str(out), "--world", "gravity"])
    assert code == 2
    assert "accelerometer" in capsys.readouterr().err
    config = tmp_path / "solve.toml"
    config.write_text(f'board = "{sim_dir / "board.toml"}"\ncapture = '
                      f'"{sim_dir / "capture.lhcap"}"\nworld = "gravity"\n')
    assert main(["solve", str(config), "--output", str(out)]) == 0
    assert "world: gravity-aligned" in capsys.readouterr().out
    stations = load_stations(out)
    assert stations.extra["world"] == "gravity"
    truth = load_stations(sim_dir / "truth.toml")
    up_world = np.asarray(truth.extra["simulation"]["up"])
    for k in stations.indices():
        true_up = truth.pose(k)[:3, :3].T @ up_world
        assert angle_deg(stations.pose(k)[:3, :3].T @ [0, 0, 1], true_up) < 0.6
