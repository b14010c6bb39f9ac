"""Tracking with the stations held fixed (``lhgraph track``, docs/track.md) on simulated
captures with known truth: the 32-diode board and the 4-diode Crazyflie deck, batch and per
sync cycle; a gap bridged by the motion prior; bad inputs.

Why the bounds: the captures have 2 MHz quantisation only (the deck: plus 30 % dropped hits),
~0.5 mm per diode hit at 2.5 m; a state's pose combines its sweep's diodes and, through the
motion prior, its neighbours', so the batch path sits at a few tenths of a millimetre
(measured: 32-diode board 0.22 mm median, deck 0.24 mm over 20 s; docs/results/track.md).
The streaming estimate is filtered (a state is reported when it arrives, before later data
can smooth it), so its bounds are looser.
"""

from __future__ import annotations

import dataclasses

import gtsam
import numpy as np
import pytest

from lhgraph.cli import main
from lhgraph.errors import InputError
from lhgraph.estimation.graph import batch
from lhgraph.estimation.graph.factors import build_graph
from lhgraph.estimation.graph.optimizer import isam2_batch
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.graph.path_residuals import path_residuals
from lhgraph.estimation.graph.streaming import track_stream
from lhgraph.estimation.graph.track import TrackedPath, track, tracking_problem
from lhgraph.estimation.graph.variables import STATION_POSE, VariableLayout
from lhgraph.estimation.spread import robust_sigma
from lhgraph.io.stations import Stations, save_stations
from lhgraph.io.trajectory import Trajectory, load_trajectory
from lhgraph.sim.simulate import default_simulation_config, simulate, write_simulation
from lhgraph.workflow.track import track_files

DECK = dataclasses.replace(
    default_simulation_config(), board="crazyflie_deck", duration_s=8.0,
    noise=dataclasses.replace(default_simulation_config().noise, dropout_fraction=0.3))


@pytest.fixture(scope="module")
def board32():
    return simulate(dataclasses.replace(default_simulation_config(), duration_s=4.0), 3)


@pytest.fixture(scope="module")
def deck():
    return simulate(DECK, 3)


def position_errors(cap, path: TrackedPath) -> np.ndarray:
    truth = cap.trajectory.at(path.trajectory.time)
    return np.linalg.norm(path.trajectory.T_world_board[:, :3, 3] - truth[:, :3, 3], axis=1)


def test_fixed_stations_are_no_variables(board32):
    layout = VariableLayout.of_problem(10, 2, fixed_stations=True)
    assert len(layout.indices(STATION_POSE)) == 0 and not layout.holds(STATION_POSE, 1)
    problem, T_world_lh = tracking_problem(board32.board, board32.angles, board32.truth)
    graph, ev = build_graph(problem, GraphOptions(), T_world_lh)
    symbols = {chr(gtsam.Symbol(k).chr()) for f in range(graph.size())
               for k in graph.at(f).keys()}
    assert symbols == {"x", "w", "o"}
    assert np.array_equal(ev.station_poses(), T_world_lh)


def test_track_board32_batch_and_streaming(board32):
    batch = track(board32.board, board32.angles, board32.truth)
    assert batch.status == "converged"
    err = position_errors(board32, batch.path)
    assert len(err) == len(np.unique(board32.angles.sweep_ids()))
    assert np.median(err) < 0.5e-3 and err.max() < 2e-3
    # the reported sigma is of the right size: errors mostly within 3 sigma
    assert np.mean(err < 3 * batch.path.sigma_m) > 0.9
    estimates = list(track_stream(board32.board, board32.angles, board32.truth))
    assert 90 < len(estimates) < 130  # one per 33 ms cycle after the 0.5 s warm-up
    stream = TrackedPath.concatenate([e.path for e in estimates if e.path])
    assert np.array_equal(stream.trajectory.time, batch.path.trajectory.time)
    assert np.median(position_errors(board32, stream)) < 1e-3


def test_track_crazyflie_deck(deck):
    """Four diodes, 30 % of hits dropped: most sweeps hold 2-3 diodes, a PnP pose exists
    only for the few pairs that saw all four; the rest start from the bearings of one
    cycle and the graph does the rest."""
    counts = np.bincount(np.bincount(deck.angles.sweep_ids()), minlength=5)
    assert counts[4] < counts[1] + counts[2] + counts[3]
    batch = track(deck.board, deck.angles, deck.truth)
    assert batch.initialised < 0.1 * len(batch.path.hits)
    err = position_errors(deck, batch.path)
    assert np.median(err) < 0.6e-3 and np.percentile(err, 99) < 2e-3
    stream = TrackedPath.concatenate(
        [e.path for e in track_stream(deck.board, deck.angles, deck.truth) if e.path])
    assert np.median(position_errors(deck, stream)) < 1e-3


def test_a_gap_is_the_motion_prior_and_says_so(board32):
    """0.3 s with only one station's azimuth sweeps: those states are not determined by
    their own bearings; the path there is the motion prior's bridge, and sigma_m says it."""
    a = board32.angles
    gap = (a.time > 2.0) & (a.time < 2.3)
    cut = a.select(~gap | ((a.lighthouse == 0) & (a.axis == 0)))
    path = track(board32.board, cut, board32.truth).path
    t = path.trajectory.time
    inside = (t > 2.05) & (t < 2.25)
    outside = (t < 1.8) | (t > 2.5)
    assert np.median(path.sigma_m[inside]) > 3 * np.median(path.sigma_m[outside])
    err = position_errors(board32, path)
    assert np.median(err[inside] / path.sigma_m[inside]) < 3


def test_cli_writes_the_contract_csv(tmp_path, capsys):
    sim = simulate(dataclasses.replace(DECK, duration_s=3.0), 4)
    write_simulation(sim, tmp_path / "sim")
    out = tmp_path / "track.csv"
    args = ["track", "--stations", str(tmp_path / "sim" / "truth.toml"), "--board",
            "crazyflie_deck", "--angles", str(tmp_path / "sim" / "angles.csv"), "--output",
            str(out)]
    assert main(args) == 0
    header = out.read_text().splitlines()[0]
    assert header == "time,x,y,z,qw,qx,qy,qz,lighthouse,hits,sigma_m"
    traj = load_trajectory(out)
    assert np.median(np.linalg.norm(
        traj.T_world_board[:, :3, 3] - sim.trajectory.at(traj.time)[:, :3, 3], axis=1)) < 1e-3
    capsys.readouterr()
    assert main(args + ["--streaming"]) == 2  # exists: no overwrite without --force
    assert "exists already" in capsys.readouterr().err
    assert main(args + ["--streaming", "--force"]) == 0
    assert "streaming" in capsys.readouterr().out
    # streaming: one state per sweep; batch: one per station rotor cycle (few-diode data)
    n_sweeps = len(np.unique(sim.angles.sweep_ids()))
    assert len(load_trajectory(out).time) == n_sweeps
    assert 0.45 * n_sweeps < len(traj.time) < 0.8 * n_sweeps


def test_bad_inputs_one_line_exit_2_nothing_written(tmp_path, capsys):
    sim = simulate(dataclasses.replace(DECK, duration_s=1.0), 5)
    write_simulation(sim, tmp_path)
    only0 = tmp_path / "only0.toml"
    save_stations(Stations(0, {0: sim.truth.stations[0]}), only0)
    out = tmp_path / "out" / "t.csv"
    base = {"--stations": tmp_path / "truth.toml", "--board": tmp_path / "board.toml",
            "--angles": tmp_path / "angles.csv", "--output": out}
    cases = [({"--stations": only0}, "only0.toml: no [lighthouses.<index>] table for station(s) 1"),
             ({"--angles": tmp_path / "nope.csv"}, "nope.csv: file not found"),
             ({"--stations": tmp_path / "nope.toml"}, "nope.toml: file not found"),
             ({"--board": tmp_path / "nope.toml"}, "neither a built-in board"),
             ({"--calibration": tmp_path / "nope_ootx.toml"}, "nope_ootx.toml"),
             ({"--delay": 0.1}, "--delay: a delay applies to streaming only")]
    for change, message in cases:
        argv = ["track"] + [str(x) for k, v in (base | change).items() for x in (k, v)]
        capsys.readouterr()
        assert main(argv) == 2, change
        err = capsys.readouterr().err
        assert message in err and len(err.strip().splitlines()) == 1, err
        assert not out.exists()
    with pytest.raises(InputError, match="only0.toml: no"):
        track_files(tmp_path / "board.toml", tmp_path / "angles.csv", only0, out)


def test_track_honours_isam2(board32, monkeypatch):
    """One build-and-optimise path: tracking takes the solver option like the calibration."""
    lm = track(board32.board, board32.angles, board32.truth)
    calls = []
    monkeypatch.setattr(batch, "isam2_batch",
                        lambda *args, **kw: calls.append(1) or isam2_batch(*args, **kw))
    isam = track(board32.board, board32.angles, board32.truth,
                 options=GraphOptions.of(solver="isam2"))
    gap = np.linalg.norm(isam.path.trajectory.T_world_board[:, :3, 3]
                         - lm.path.trajectory.T_world_board[:, :3, 3], axis=1)
    assert calls and np.median(gap) < 2e-4
    assert np.median(position_errors(board32, isam.path)) < 0.5e-3


@pytest.mark.parametrize("name, value", [("diode_bias_sigma_rad", 1e-4),
                                         ("sensor_offset_sigma_m", 1e-3),
                                         ("rest_keep_every", 3)])
def test_streaming_refuses_what_it_cannot_honour(board32, name, value):
    with pytest.raises(InputError, match=name):
        list(track_stream(board32.board, board32.angles, board32.truth,
                          options=GraphOptions.of(**{name: value})))



def test_track_refuses_rest_thinning(board32):
    with pytest.raises(InputError, match="rest_keep_every"):
        track(board32.board, board32.angles, board32.truth,
              options=GraphOptions.of(rest_keep_every=3))


def test_path_residuals_of_the_true_path_are_the_noise(board32):
    """The batch track's own path gives the batch graph's residual spread (within 5 %:
    measured 41.8 against 41.5 urad, the simulator's quantisation of hit and sync edges);
    the true path the same level (under 50 urad) with every hit; a path 5 cm off residuals
    over 10x wider; a path of half the states keeps their hits only."""
    batch = track(board32.board, board32.angles, board32.truth)
    again = path_residuals(board32.board, board32.angles, board32.truth, batch.path)
    assert robust_sigma(again.residual_rad) == pytest.approx(
        robust_sigma(batch.residuals.residual_rad), rel=0.05)
    problem, _ = tracking_problem(board32.board, board32.angles, board32.truth)
    t = problem.state_time
    truth = TrackedPath(Trajectory(t, board32.trajectory.at(t)), np.zeros(len(t), int),
                        np.zeros(len(t), int), np.zeros(len(t)))
    res = path_residuals(board32.board, board32.angles, board32.truth, truth)
    assert len(res.residual_rad) == len(problem.hits.angle)
    assert robust_sigma(res.residual_rad) < 5e-5 and res.inlier_fraction() > 0.99
    shifted = truth.trajectory.T_world_board.copy()
    shifted[:, 0, 3] += 0.05
    off = dataclasses.replace(truth, trajectory=Trajectory(t, shifted))
    bad = path_residuals(board32.board, board32.angles, board32.truth, off)
    assert robust_sigma(bad.residual_rad) > 10 * robust_sigma(res.residual_rad)
    half = dataclasses.replace(truth, trajectory=Trajectory(t[::2], truth.trajectory
                                                            .T_world_board[::2]))
    kept = path_residuals(board32.board, board32.angles, board32.truth, half)
    assert len(kept.residual_rad) == int(np.sum(np.diff(problem.bounds)[::2]))
