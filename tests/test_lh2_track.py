"""LH2 tracking and solving on simulated captures with truth: `track` (batch and streaming)
through the true stations, and the CLI's solve of a two-station LH2 capture with the
simulator's ootx.toml (generation 2: the angles are light planes)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from lhgraph.cli import main
from lhgraph.estimation.graph.streaming import track_stream
from lhgraph.estimation.graph.track import TrackedPath, track
from lhgraph.estimation.metrics import station_errors
from lhgraph.io.stations import load_stations
from lhgraph.sim.simulate import load_simulation_config, simulate, write_simulation

CONFIG = Path(__file__).resolve().parents[1] / "configs" / "sim_lh2.toml"


def position_errors(cap, path: TrackedPath) -> np.ndarray:
    truth = cap.trajectory.at(path.trajectory.time)
    return np.linalg.norm(path.trajectory.T_world_board[:, :3, 3] - truth[:, :3, 3], axis=1)


@pytest.mark.parametrize("board, duration_s", [("paper32", 4.0), ("crazyflie_deck", 8.0)])
def test_track_lh2_batch_and_streaming(board, duration_s):
    config = dataclasses.replace(load_simulation_config(CONFIG), board=board,
                                 duration_s=duration_s)
    cap = simulate(config, 3)
    assert all(s.model.generation == 2 for s in cap.truth.stations.values())
    batch = track(cap.board, cap.angles, cap.truth)
    assert batch.status == "converged"
    err = position_errors(cap, batch.path)
    assert np.median(err) < 0.2e-3 and np.percentile(err, 99) < 0.5e-3
    stream = TrackedPath.concatenate(
        [e.path for e in track_stream(cap.board, cap.angles, cap.truth) if e.path])
    assert np.median(position_errors(cap, stream)) < 0.3e-3


def test_cli_solves_an_lh2_capture(tmp_path, capsys):
    cap = simulate(dataclasses.replace(load_simulation_config(CONFIG), duration_s=4.0), 5)
    paths = write_simulation(cap, tmp_path)
    assert main(["solve", "--board", str(paths["board"]), "--angles", str(paths["angles"]),
                 "--calibration", str(paths["ootx"]), "--output", str(tmp_path / "ours.toml"),
                 "--quiet"]) == 0
    ours = load_stations(tmp_path / "ours.toml")
    assert ours.stations[1].model.generation == 2
    err = station_errors(cap.truth, ours)[0]
    assert err.position_norm_m < 1e-3 and np.degrees(err.rotation_rad) < 0.02
    # read as LH1 (no ootx.toml, not even beside the angles), the same angles give no
    # sensible answer
    paths["ootx"].rename(tmp_path / "elsewhere.toml")
    assert main(["solve", "--board", str(paths["board"]), "--angles", str(paths["angles"]),
                 "--output", str(tmp_path / "lh1.toml"), "--quiet"]) in (0, 3)
    if (tmp_path / "lh1.toml").exists():
        lh1 = station_errors(cap.truth, load_stations(tmp_path / "lh1.toml"))[0]
        assert lh1.position_norm_m > 0.05


def test_paper_method_refuses_lh2(tmp_path, capsys):
    cap = simulate(dataclasses.replace(load_simulation_config(CONFIG), duration_s=1.0), 1)
    paths = write_simulation(cap, tmp_path)
    out = tmp_path / "paper.toml"
    assert main(["solve", "--board", str(paths["board"]), "--angles", str(paths["angles"]),
                 "--calibration", str(paths["ootx"]), "--method", "paper", "--output",
                 str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "LH1 stations" in err[0] and not out.exists()
