"""The configuration layer: declared ranges refused at load with one line naming file and key,
unknown keys listing the allowed ones, the old key spelling, options objects not mutated."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from lhgraph.cli import main
from lhgraph.config import load_options, override
from lhgraph.errors import InputError
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.sim.simulate import default_simulation_config, simulate, write_simulation
from lhgraph.workflow.solve import solve
from lhgraph.workflow.solve_config import SolveConfig, load_solve_config


@pytest.mark.parametrize(("key", "value", "problem"), [
    ("max_iterations", "-3", "must be > 0 (got -3)"),
    ("angle_sigma_rad", "-1", "must be > 0 (got -1.0)"),
    ("min_psd_factor", "2.0", "must be in (0, 1] (got 2.0)"),
    ("loss", '"l2"', "must be one of cauchy, huber (got 'l2')"),
    ("solver", '"gn"', "must be one of lm, isam2 (got 'gn')"),
    ("max_iterations", '"60"', "expected an integer, got '60'"),
    ("adapt_angle_sigma", "1", "expected true or false, got 1"),
])
def test_graph_option_refused_at_load(tmp_path: Path, key: str, value: str,
                                      problem: str) -> None:
    path = tmp_path / "run.toml"
    path.write_text(f'board = "b.toml"\nangles = "a.csv"\n[graph]\n{key} = {value}\n')
    with pytest.raises(InputError) as info:
        load_solve_config(path)
    assert str(info.value) == f"{path}:graph.{key}: {problem}"


def test_unknown_key_lists_allowed(tmp_path: Path) -> None:
    with pytest.raises(InputError) as info:
        load_options(GraphOptions, {"max_iteration": 3}, "x.toml", "graph")
    message = str(info.value)
    assert message.startswith("x.toml:graph.max_iteration: unknown key 'max_iteration'")
    assert "max_iterations" in message and "\n" not in message


def test_graph_options_flat_or_by_group(tmp_path: Path) -> None:
    """A [graph] option may be given flat or in its group's table; both name the key."""
    flat = load_options(GraphOptions, {"max_iterations": 7, "loss": "huber"}, "x.toml", "graph")
    nested = load_options(GraphOptions, {"optimizer": {"max_iterations": 7},
                                         "robust": {"loss": "huber"}}, "x.toml", "graph")
    assert flat == nested == GraphOptions.of(max_iterations=7, loss="huber")
    assert flat.optimizer.max_iterations == 7 and flat.robust.loss == "huber"
    with pytest.raises(InputError, match="x.toml:graph.optimizer.max_iterations: must be > 0"):
        load_options(GraphOptions, {"optimizer": {"max_iterations": 0}}, "x.toml", "graph")
    with pytest.raises(InputError, match="not both"):
        load_options(GraphOptions, {"max_iterations": 3, "optimizer": {"max_iterations": 4}},
                     "x.toml", "graph")
    with pytest.raises(InputError, match="unknown key 'loss'"):  # in the wrong group
        load_options(GraphOptions, {"optimizer": {"loss": "huber"}}, "x.toml", "graph")
    with pytest.raises(InputError, match="no graph option 'max_iteration'"):
        GraphOptions.of(max_iteration=3)
    assert GraphOptions().flat()["max_iterations"] == 60 and len(GraphOptions().flat()) == 56


def test_python_construction_validated() -> None:
    with pytest.raises(InputError, match="max_iterations: must be > 0"):
        GraphOptions.of(max_iterations=0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        GraphOptions().optimizer.max_iterations = 3  # type: ignore[misc]


def test_duration_old_spelling(tmp_path: Path) -> None:
    path = tmp_path / "run.toml"
    path.write_text('board = "b.toml"\nangles = "a.csv"\nduration = 2.5\n')
    assert load_solve_config(path).duration_s == 2.5
    path.write_text('board = "b.toml"\nangles = "a.csv"\nduration_s = 3\n')
    assert load_solve_config(path).duration_s == 3.0
    path.write_text('board = "b.toml"\nangles = "a.csv"\nduration_s = 3\nduration = 2\n')
    with pytest.raises(InputError, match="duration"):
        load_solve_config(path)
    path.write_text('board = "b.toml"\nangles = "a.csv"\nduration = -1\n')
    with pytest.raises(InputError, match=r"duration: must be > 0 \(got -1.0\)"):
        load_solve_config(path)


def test_override_names_the_flag() -> None:
    config = SolveConfig(Path("b.toml"), Path("a.csv"))
    assert override(config, {"--reference": ("reference", None)}) is config
    assert override(config, {"--reference": ("reference", 1)}).reference == 1
    with pytest.raises(InputError, match=r"^--duration: must be > 0 \(got -2.0\)$"):
        override(config, {"--duration": ("duration_s", -2.0)})


def test_solve_does_not_mutate_options() -> None:
    sim = simulate(dataclasses.replace(default_simulation_config(), duration_s=1.5), 3)
    options = GraphOptions.of(max_iterations=5)
    result = solve(sim.board, sim.angles, "graph", reference=1, graph_options=options)
    assert options == GraphOptions.of(max_iterations=5)
    # the result says what ran: every choice resolved, and which rule decided it
    ran = result.options
    assert ran["optimizer"]["max_iterations"] == 5 and ran["data"]["reference"] == 1
    assert ran["optimizer"]["step_tolerance_sigma"] == 0.05
    assert ran["motion"]["motion_prior_estimate"] == "chi2"
    assert any(r.startswith("motion_prior_estimate = 'chi2' (auto")
               for r in result.option_rules)
    assert not any(r.startswith("reference") for r in result.option_rules)  # given: kept


@pytest.fixture(scope="module")
def inputs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("inputs")
    sim = simulate(dataclasses.replace(default_simulation_config(), duration_s=1.0), 2)
    write_simulation(sim, folder)
    return folder


def one_line_exit_2(capsys: pytest.CaptureFixture, argv: list[str]) -> str:
    capsys.readouterr()
    assert main(argv) == 2
    captured = capsys.readouterr()
    assert captured.err.count("\n") == 1 and "Traceback" not in captured.err
    return captured.err


@pytest.mark.parametrize("body", ["max_iterations = -3", "angle_sigma_rad = -1"])
def test_cli_bad_option_in_config(inputs: Path, tmp_path: Path, capsys, body: str) -> None:
    config = tmp_path / "bad.toml"
    config.write_text(f'board = "{inputs}/board.toml"\nangles = "{inputs}/angles.csv"\n'
                      f"[graph]\n{body}\n")
    err = one_line_exit_2(capsys, ["solve", str(config), "--output", str(tmp_path / "run")])
    assert str(config) in err and "must be > 0" in err
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("angles", ["missing.csv", "."])
@pytest.mark.parametrize("run_directory", [True, False])
def test_cli_missing_or_directory_angles(inputs: Path, tmp_path: Path, capsys, angles: str,
                                         run_directory: bool) -> None:
    out = tmp_path / ("run" if run_directory else "stations.toml")
    bad = tmp_path / angles
    if run_directory:
        config = tmp_path / "c.toml"
        config.write_text(f'board = "{inputs}/board.toml"\nangles = "{bad}"\n')
        argv = ["solve", str(config), "--output", str(out)]
    else:
        argv = ["solve", "--board", str(inputs / "board.toml"), "--angles", str(bad),
                "--output", str(out)]
    err = one_line_exit_2(capsys, argv)
    assert str(bad) in err
    assert not out.exists()


def test_cli_flag_out_of_range(inputs: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "s.toml"
    base = ["solve", "--board", str(inputs / "board.toml"), "--angles",
            str(inputs / "angles.csv"), "--output", str(out)]
    assert "--duration: must be > 0" in one_line_exit_2(capsys, [*base, "--duration", "-1"])
    assert "--reference: must be >= 0" in one_line_exit_2(capsys, [*base, "--reference", "-1"])
    assert not out.exists()
