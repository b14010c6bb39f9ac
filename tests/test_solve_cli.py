"""`lhgraph solve` with flags: outputs, --duration, refusing to overwrite."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from lhgraph.cli import main
from lhgraph.io.stations import load_stations
from lhgraph.io.trajectory import load_trajectory
from lhgraph.sim.simulate import load_simulation_config, simulate, write_simulation

CONFIG = Path(__file__).resolve().parents[1] / "configs" / "simulation" / "default.toml"


def test_solve_flags_duration_and_no_overwrite(tmp_path, capsys):
    sim = simulate(dataclasses.replace(load_simulation_config(CONFIG), duration_s=3.0), 7)
    write_simulation(sim, tmp_path)
    out, traj = tmp_path / "result.toml", tmp_path / "traj.csv"
    args = ["solve", "--board", str(tmp_path / "board.toml"), "--angles",
            str(tmp_path / "angles.csv"), "--output", str(out), "--trajectory", str(traj),
            "--truth", str(tmp_path / "truth.toml"), "--duration", "1.5", "--quiet"]
    assert main(args) == 0
    result = load_stations(out)
    assert result.reference == 0 and result.stations[1].covariance.shape == (6, 6)
    t = load_trajectory(traj).time
    assert t[-1] - t[0] < 1.5
    assert np.linalg.norm(result.pose(1)[:3, 3] - sim.truth.relative_to_reference().pose(1)[
        :3, 3]) < 5e-3
    # a second run must not overwrite without --force
    capsys.readouterr()
    assert main(args) == 2
    assert "exists already" in capsys.readouterr().err
    assert main([*args, "--force"]) == 0
