"""Run directories: `lhgraph solve CONFIG.toml --output DIR` (files, summary, report, rules)."""

from __future__ import annotations

import dataclasses
import hashlib
import json
from pathlib import Path

import numpy as np
import pytest

from lhgraph.cli import main
from lhgraph.errors import InputError
from lhgraph.io.files import read_csv_columns
from lhgraph.io.stations import load_stations
from lhgraph.sim.simulate import default_simulation_config, simulate, write_simulation
from lhgraph.workflow.rundir import is_run_directory, run_to_directory
from lhgraph.workflow.solve_config import load_solve_config


@pytest.fixture(scope="module")
def capture_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 1.5 s simulated capture (default layout) with its raw .lhcap and truth; station 0
    flashes first, so decoded station indices equal the simulator's (docs/decoding.md)."""
    from lhgraph.sim.capture_sim import write_simulated_capture

    out = tmp_path_factory.mktemp("capture")
    sim = simulate(dataclasses.replace(default_simulation_config(), duration_s=1.5,
                                       first_station=0), seed=3)
    write_simulation(sim, out)
    write_simulated_capture(sim, out)
    return out


def write_config(folder: Path, text: str, name: str = "run.toml") -> Path:
    path = folder / name
    path.write_text(text)
    return path


GRAPH_CONFIG = 'board = "board.toml"\nangles = "angles.csv"\ntruth = "truth.toml"\nseed = 3\n'


def test_output_rule(tmp_path: Path) -> None:
    assert is_run_directory(tmp_path / "out")
    assert is_run_directory(tmp_path / "out.d")
    assert not is_run_directory(tmp_path / "stations.toml")
    (tmp_path / "dir.toml").mkdir()
    assert is_run_directory(tmp_path / "dir.toml")


def test_run_directory_files_summary_report(capture_dir: Path, tmp_path: Path,
                                           capsys: pytest.CaptureFixture) -> None:
    config = write_config(capture_dir, GRAPH_CONFIG)
    out = tmp_path / "run"
    assert main(["solve", str(config), "--output", str(out), "--quiet"]) == 0
    assert sorted(p.name for p in out.iterdir()) == sorted(
        ["stations.toml", "trajectory.csv", "residuals.csv", "summary.json", "report.html"])
    summary = json.loads((out / "summary.json").read_text())
    angles_file = capture_dir / "angles.csv"
    assert summary["inputs"]["angles"]["sha256"] == hashlib.sha256(
        angles_file.read_bytes()).hexdigest()
    assert set(summary["inputs"]) == {"config", "board", "angles", "truth"}
    assert summary["seed"] == 3 and summary["method"] == "graph"
    assert {"lhgraph", "gtsam", "numpy", "python"} <= set(summary["versions"])
    assert summary["errors"]["1"]["position_norm_mm"] < 5.0
    history = summary["error_history"]
    assert len(history) >= 2 and history[-1] < history[0]
    # residuals.csv: one row per hit of the solve, the contract columns of the brief
    res = read_csv_columns(out / "residuals.csv", [("time", float), ("lighthouse", int),
                                                   ("axis", int), ("sensor", int),
                                                   ("residual_rad", float), ("weight", float)])
    assert len(res["time"]) == summary["residuals"]["hits"] == summary["hits"]
    inl = res["weight"] > 0.5
    rms = np.sqrt(np.mean(res["residual_rad"][inl] ** 2)) * 1e6
    assert rms == pytest.approx(summary["residuals"]["rms_urad"], rel=1e-3)
    # stations.toml is the contract file with the covariance
    st = load_stations(out / "stations.toml")
    assert st.stations[1].covariance is not None and np.all(np.diag(st.stations[1].covariance)
                                                            > 0)
    html = (out / "report.html").read_text()
    assert html.count("data:image/png;base64,") >= 5  # scene, histograms, angle, sensor, conv.
    assert "src=\"http" not in html and "<script" not in html  # self-contained
    # nothing is overwritten without --force; with it, the run is redone
    assert main(["solve", str(config), "--output", str(out), "--quiet"]) == 2
    assert "exists already" in capsys.readouterr().err
    assert main(["solve", str(config), "--output", str(out), "--quiet", "--force"]) == 0


def test_flag_form_and_toml_output_unchanged(capture_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "r.toml"
    assert main(["solve", "--board", str(capture_dir / "board.toml"), "--angles",
                 str(capture_dir / "angles.csv"), "--output", str(out), "--quiet"]) == 0
    assert out.is_file()
    config = write_config(capture_dir, GRAPH_CONFIG)
    out2 = tmp_path / "s.toml"
    assert main(["solve", str(config), "--output", str(out2), "--quiet"]) == 0
    assert out2.is_file() and load_stations(out2).stations[1].covariance is not None


def test_capture_and_two_methods(capture_dir: Path, tmp_path: Path) -> None:
    """A config naming the raw capture: decoded first; both methods, comparison report."""
    config = load_solve_config(write_config(capture_dir, (
        'board = "board.toml"\ncapture = "capture.lhcap"\ntruth = "truth.toml"\n'
        'methods = ["graph", "paper"]\n'), "two.toml"))
    messages: list[str] = []
    run = run_to_directory(config, tmp_path / "two", progress=messages.append)
    assert [r.method for r in run.runs] == ["graph", "paper"]
    for method in ("graph", "paper"):
        assert (tmp_path / "two" / method / "report.html").is_file()
    summary = json.loads((tmp_path / "two" / "summary.json").read_text())
    assert {r["method"] for r in summary["comparison"]} == {"graph", "paper"}
    assert "capture" in summary["inputs"] and "angles" not in summary["inputs"]
    graph_error = run.runs[0].errors[0].position_norm_m
    assert graph_error < 5e-3
    html = run.report.read_text()
    assert "graph/report.html" in html and "paper/report.html" in html
    assert any("[paper]" in m for m in messages) and any("[graph]" in m for m in messages)
    assert json.loads((tmp_path / "two" / "graph" / "summary.json").read_text())["decode"]


@pytest.mark.parametrize(("text", "key"), [
    ('board = "b.toml"\nangles = "a.csv"\nspeed = 3\n', "speed"),
    ('board = "b.toml"\nangles = "a.csv"\ncapture = "c.lhcap"\n', "angles"),
    ('board = "b.toml"\n', "capture"),
    ('board = "b.toml"\nangles = "a.csv"\nmethods = ["graph", "graph"]\n', "methods"),
    ('board = "b.toml"\nangles = "a.csv"\nmethods = []\n', "methods"),
    ('board = "b.toml"\nangles = "a.csv"\nmethods = ["graph"]\nmethod = "paper"\n', "methods"),
    ('board = "b.toml"\nangles = "a.csv"\nseed = "x"\n', "seed"),
    ('board = "b.toml"\nangles = "a.csv"\n[graph]\nadapt_motion_prior = 1\n',
     "graph.adapt_motion_prior"),
])
def test_config_errors_name_file_and_key(tmp_path: Path, text: str, key: str) -> None:
    path = write_config(tmp_path, text, "bad.toml")
    with pytest.raises(InputError) as info:
        load_solve_config(path)
    assert str(path) in str(info.value) and key in str(info.value)


def test_trajectory_key_refused_for_run_directory(capture_dir: Path, tmp_path: Path,
                                                  capsys: pytest.CaptureFixture) -> None:
    config = write_config(capture_dir, GRAPH_CONFIG + 'trajectory = "t.csv"\n', "traj.toml")
    assert main(["solve", str(config), "--output", str(tmp_path / "x"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "traj.toml" in err and "trajectory" in err
    assert not (tmp_path / "x").exists()


def test_interrupted_run_resumes(capture_dir: Path, tmp_path: Path,
                                 capsys: pytest.CaptureFixture) -> None:
    """A method whose summary.json (written last) is there with the same inputs is kept by
    --resume, the rest computed; without --resume or --force: one line saying how."""
    config = write_config(capture_dir, 'board = "board.toml"\nangles = "angles.csv"\n'
                          'methods = ["graph", "paper"]\n', "resume.toml")
    out = tmp_path / "run"
    assert main(["solve", str(config), "--output", str(out), "--quiet"]) == 0
    graph_bytes = (out / "graph" / "stations.toml").read_bytes()
    graph_summary = (out / "graph" / "summary.json").read_text()
    paper_summary = json.loads((out / "paper" / "summary.json").read_text())
    (out / "paper" / "summary.json").unlink()  # interrupted while writing the paper method
    (out / "summary.json").unlink()
    assert main(["solve", str(config), "--output", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "--resume" in err and "--force" in err
    assert not (out / "paper" / "summary.json").exists()  # nothing written
    assert main(["solve", str(config), "--output", str(out), "--resume"]) == 0
    captured = capsys.readouterr()
    assert "[graph] kept" in captured.err and "[paper] solving" in captured.err
    assert "[graph] solving" not in captured.err
    assert (out / "graph" / "stations.toml").read_bytes() == graph_bytes
    assert (out / "graph" / "summary.json").read_text() == graph_summary
    paper = json.loads((out / "paper" / "summary.json").read_text())
    assert paper["stations"] == paper_summary["stations"]
    assert json.loads((out / "summary.json").read_text())["kept"] == ["graph"]
    assert "method graph" in captured.out and "method paper" in captured.out
    # changed options: nothing kept (the resume key covers them)
    (capture_dir / "resume2.toml").write_text(config.read_text() + "[graph]\nloss = \"huber\"\n")
    messages: list[str] = []
    run_to_directory(load_solve_config(capture_dir / "resume2.toml"), out,
                     progress=messages.append, resume=True)
    assert any(m == "[graph] solving" for m in messages)
    assert any(m.startswith("[paper] kept") for m in messages)
    # --resume is for run directories only
    assert main(["solve", str(config), "--output", str(tmp_path / "s.toml"), "--resume",
                 "--method", "graph", "--quiet"]) == 2
    assert "--resume is for a run directory" in capsys.readouterr().err


def test_run_directory_holds_the_solved_board(capture_dir: Path, tmp_path: Path,
                                              capsys: pytest.CaptureFixture) -> None:
    """With the graph's sensor offsets on, the run directory also holds board.toml (the
    board with the solved sensor positions: the simulated board is exact, so they move by
    well under a millimetre); ``board_output`` is refused for a run directory."""
    from lhgraph.model.board import load_board

    config = write_config(capture_dir, GRAPH_CONFIG + "[graph]\nsensor_offset_sigma_m = 3e-4\n",
                          "offsets.toml")
    out = tmp_path / "run"
    assert main(["solve", str(config), "--output", str(out), "--quiet"]) == 0
    moved = load_board(out / "board.toml").positions - load_board(capture_dir / "board.toml"
                                                                  ).positions
    assert 0 < np.abs(moved).max() < 1e-3
    config = write_config(capture_dir, GRAPH_CONFIG + 'board_output = "b.toml"\n', "bo.toml")
    assert main(["solve", str(config), "--output", str(tmp_path / "x"), "--quiet"]) == 2
    assert "board_output" in capsys.readouterr().err and not (tmp_path / "x").exists()
