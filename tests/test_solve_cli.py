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
    # one file named for two outputs is refused before solving, whatever the spelling
    capsys.readouterr()
    same = [str(tmp_path / "." / "result.toml") if a == str(traj) else a for a in args]
    assert main([*same, "--force"]) == 2
    assert "must be different files" in capsys.readouterr().err
    assert load_stations(out).reference == 0


def test_version_and_plain_progress(tmp_path, capsys):
    import importlib.metadata

    import pytest

    import lhgraph

    with pytest.raises(SystemExit) as info:
        main(["--version"])
    assert info.value.code == 0
    out = capsys.readouterr().out
    assert out == f"lhgraph {importlib.metadata.version('lhgraph')}\n"
    assert importlib.metadata.version("lhgraph") == lhgraph.__version__
    sim = simulate(dataclasses.replace(load_simulation_config(CONFIG), duration_s=1.0), 3)
    write_simulation(sim, tmp_path)
    args = ["solve", "--board", str(tmp_path / "board.toml"), "--angles",
            str(tmp_path / "angles.csv"), "--output", str(tmp_path / "r.toml")]
    assert main(args) == 0
    captured = capsys.readouterr()
    assert "noise level learned:" in captured.err and "µrad per diode" in captured.err
    assert "iteration 1: converging" in captured.err
    assert "chi2" not in captured.err and "urad" not in captured.err.replace("µrad", "")
    assert "sigma: length of the 1-sigma uncertainty" in captured.out
    assert main([*args, "--force", "--verbose"]) == 0
    assert "chi2/dof" in capsys.readouterr().err


def test_board_output_solves_the_sensor_positions(tmp_path, capsys):
    """A board file whose sensors are 0.5 mm off (rms per axis): with ``--board-output`` the
    graph solves for the sensor positions too and writes the board with them, nearer the true
    one than the file it was given, and station 1 nearer the truth; the paper method cannot
    (exit 2, nothing written)."""
    from lhgraph.model.board import load_board, save_board, with_sensor_offsets

    sim = simulate(dataclasses.replace(load_simulation_config(CONFIG), duration_s=4.0), 5)
    write_simulation(sim, tmp_path)
    true = load_board(tmp_path / "board.toml")
    offsets = np.random.default_rng(5).normal(0.0, 5e-4, true.positions.shape)
    save_board(with_sensor_offsets(true, offsets), tmp_path / "wrong.toml")
    base = ["solve", "--board", str(tmp_path / "wrong.toml"), "--angles",
            str(tmp_path / "angles.csv"), "--quiet"]
    assert main([*base, "--output", str(tmp_path / "plain.toml")]) == 0
    assert main([*base, "--output", str(tmp_path / "ours.toml"),
                 "--board-output", str(tmp_path / "fixed.toml")]) == 0
    fixed = load_board(tmp_path / "fixed.toml")
    np.testing.assert_array_equal(fixed.ids, true.ids)
    np.testing.assert_allclose(fixed.normals, true.normals)

    def rms(b):
        return np.sqrt(np.mean(np.sum((b.positions - true.positions) ** 2, axis=1)))

    assert rms(fixed) < 0.5 * rms(load_board(tmp_path / "wrong.toml"))

    def error(name):
        found = load_stations(tmp_path / name).pose(1)[:3, 3]
        return np.linalg.norm(found - sim.truth.relative_to_reference().pose(1)[:3, 3])

    assert error("ours.toml") < 0.6 * error("plain.toml")
    capsys.readouterr()
    assert main([*base, "--output", str(tmp_path / "p.toml"), "--method", "paper",
                 "--board-output", str(tmp_path / "p-board.toml")]) == 2
    assert "board_output" in capsys.readouterr().err
    assert not (tmp_path / "p.toml").exists() and not (tmp_path / "p-board.toml").exists()
