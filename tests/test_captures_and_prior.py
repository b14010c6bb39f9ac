"""Several captures in one solve and an earlier result as a prior (issue #41 items 1, 2):
``lhgraph solve --angles A --angles B`` / ``angles = [A, B]`` and ``--prior stations.toml``,
on simulated captures of one room with known truth."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from lhgraph.cli import main
from lhgraph.estimation.graph.factors import build_graph
from lhgraph.estimation.graph.families.motion import MotionPrior
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.problem import build_problem
from lhgraph.geometry.transforms import inverse, se3_exp, se3_log
from lhgraph.io.angles import load_angles
from lhgraph.io.captures import CAPTURE_GAP_S, join_captures
from lhgraph.io.stations import load_stations, save_stations
from lhgraph.model.board import load_board
from lhgraph.sim.simulate import load_simulation_config, simulate, write_simulation

CONFIGS = Path(__file__).resolve().parents[1] / "configs" / "simulation"


@pytest.fixture(scope="module")
def captures(tmp_path_factory) -> dict[str, Path]:
    """Two 3 s captures of the default room: the same two stations, different waves."""
    root = tmp_path_factory.mktemp("captures")
    cfg = dataclasses.replace(load_simulation_config(CONFIGS / "default.toml"), duration_s=3.0)
    out = {}
    for name, seed in (("a", 1), ("b", 2)):
        write_simulation(simulate(cfg, seed), root / name)
        out[name] = root / name
    return out


def _solve(tmp: Path, name: str, *args: str) -> Path:
    out = tmp / f"{name}.toml"
    assert main(["solve", "--output", str(out), "--quiet", *args]) == 0
    return out


def _delta(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``Log(a^-1 b)`` ([omega, v])."""
    return se3_log(inverse(a) @ b)


def test_join_keeps_each_capture_apart(captures):
    a, b = (load_angles(captures[k] / "angles.csv") for k in "ab")
    joined, spans, notes = join_captures([a, b], ["a", "b"])
    assert len(joined) == len(a) + len(b) and not notes
    assert np.all(np.diff(joined.time) >= 0)
    first_b = int(np.argmax(joined.extra["capture"] == 1))
    assert joined.time[first_b] - joined.time[first_b - 1] >= CAPTURE_GAP_S
    assert spans[1].hits == {k: int(np.sum(b.lighthouse == k)) for k in (0, 1)}
    # one board path per capture: no motion prior joins the last state of a to the first of b
    board = load_board(captures["a"] / "board.toml")
    problem = build_problem(board, joined, {}, 0)
    _, ev = build_graph(problem, GraphOptions())
    motion = next(f for f in ev.families if isinstance(f, MotionPrior))
    assert len(motion.indices) == problem.n_states - 2
    assert np.sum(~problem.linked()) == 1


def test_joint_solve_beats_each_capture_and_lists_them(captures, tmp_path, capsys):
    a, b = captures["a"], captures["b"]
    truth = load_stations(a / "truth.toml").relative_to_reference()
    alone = [load_stations(_solve(tmp_path, k, "--board", str(c / "board.toml"), "--angles",
                                  str(c / "angles.csv"))) for k, c in (("a", a), ("b", b))]
    out = tmp_path / "joint.toml"
    assert main(["solve", "--board", str(a / "board.toml"), "--angles", str(a / "angles.csv"),
                 "--angles", str(b / "angles.csv"), "--output", str(out)]) == 0
    printed = capsys.readouterr().out
    assert f"capture 1 ({b / 'angles.csv'}): station 0" in printed
    joint = load_stations(out)
    error = np.linalg.norm(joint.pose(1)[:3, 3] - truth.pose(1)[:3, 3])
    assert error < 2e-3
    sigma = [np.sqrt(np.trace(s.stations[1].covariance_white[3:, 3:])) for s in alone]
    joint_sigma = np.sqrt(np.trace(joint.stations[1].covariance_white[3:, 3:]))
    assert joint_sigma < 0.8 * min(sigma)  # two captures' information, not one's


def test_config_lists_captures(captures, tmp_path):
    a, b = captures["a"], captures["b"]
    config = tmp_path / "solve.toml"
    config.write_text(f'board = "{a / "board.toml"}"\nangles = ["{a / "angles.csv"}", '
                      f'"{b / "angles.csv"}"]\noutput = "{tmp_path / "c.toml"}"\n')
    assert main(["solve", str(config), "--quiet"]) == 0
    cli = _solve(tmp_path, "cli", "--board", str(a / "board.toml"), "--angles",
                 str(a / "angles.csv"), "--angles", str(b / "angles.csv"))
    np.testing.assert_allclose(load_stations(tmp_path / "c.toml").pose(1),
                               load_stations(cli).pose(1), atol=1e-9)


def test_prior_of_a_then_b_agrees_with_the_joint_solve(captures, tmp_path):
    a, b = captures["a"], captures["b"]
    board = str(a / "board.toml")
    first = _solve(tmp_path, "a", "--board", board, "--angles", str(a / "angles.csv"))
    chained = load_stations(_solve(tmp_path, "b_prior", "--board", board, "--angles",
                                   str(b / "angles.csv"), "--prior", str(first)))
    joint = load_stations(_solve(tmp_path, "joint", "--board", board, "--angles",
                                 str(a / "angles.csv"), "--angles", str(b / "angles.csv")))
    d = _delta(joint.pose(1), chained.pose(1))
    cov = joint.stations[1].covariance
    assert float(d @ np.linalg.solve(cov, d)) ** 0.5 < 0.5  # within 0.5 sigma (6-dof)
    alone_b = load_stations(_solve(tmp_path, "b", "--board", board, "--angles",
                                   str(b / "angles.csv")))
    assert np.trace(chained.stations[1].covariance) < np.trace(alone_b.stations[1].covariance)


def test_prior_flags_a_moved_station_and_keeps_unseen_ones(captures, tmp_path, capsys):
    a, b = captures["a"], captures["b"]
    board = str(a / "board.toml")
    first = load_stations(_solve(tmp_path, "a", "--board", board, "--angles",
                                 str(a / "angles.csv")))
    moved = dataclasses.replace(first, stations={
        **first.stations,
        1: first.stations[1].moved(se3_exp(np.r_[0, 0, 0, 0.05, 0, 0])),  # 50 mm in x
        7: first.stations[1]})  # a station this capture never sees
    save_stations(moved, tmp_path / "moved.toml")
    out = tmp_path / "out.toml"
    code = main(["solve", "--board", board, "--angles", str(b / "angles.csv"), "--prior",
                 str(tmp_path / "moved.toml"), "--output", str(out)])
    printed = capsys.readouterr().out
    assert code == 0 and "station 1 lies" in printed and "moved since" in printed
    assert "prior: station 7 not seen by this capture" in printed
    result = load_stations(out)
    np.testing.assert_allclose(result.pose(7), first.pose(1), atol=1e-12)


@pytest.mark.parametrize("case, message", [
    ("no reference", "the prior has no station 0"),
    ("no covariance", "no station of the prior has a covariance"),
])
def test_bad_prior_exits_2(captures, tmp_path, capsys, case, message):
    a = captures["a"]
    first = load_stations(_solve(tmp_path, "a", "--board", str(a / "board.toml"), "--angles",
                                 str(a / "angles.csv")))
    if case == "no reference":
        bad = dataclasses.replace(first, reference=1, stations={1: first.stations[1]})
    else:
        bad = dataclasses.replace(first, stations={
            k: dataclasses.replace(s, covariance=None, covariance_white=None)
            for k, s in first.stations.items()})
    save_stations(bad, tmp_path / "bad.toml")
    code = main(["solve", "--board", str(a / "board.toml"), "--angles",
                 str(a / "angles.csv"), "--prior", str(tmp_path / "bad.toml"), "--output",
                 str(tmp_path / "o.toml")])
    err = capsys.readouterr().err
    assert code == 2 and message in err and str(tmp_path / "bad.toml") in err
    assert not (tmp_path / "o.toml").exists()


def test_several_captures_refuse_an_imu_for_now(captures, tmp_path, capsys):
    a, b = captures["a"], captures["b"]
    imu = tmp_path / "imu.csv"
    imu.write_text("time,ax,ay,az\n0,0,0,9.81\n1,0,0,9.81\n2,0,0,9.81\n")
    code = main(["solve", "--board", str(a / "board.toml"), "--angles", str(a / "angles.csv"),
                 "--angles", str(b / "angles.csv"), "--imu", str(imu), "--output",
                 str(tmp_path / "o.toml")])
    assert code == 2 and "several captures" in capsys.readouterr().err
