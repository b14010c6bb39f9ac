"""One entry point for every calibration method, and the solve configuration file.

``solve(board, angles, method=...)`` dispatches to the factor graph (``"graph"``, default)
or the paper's pipeline (``"paper"``). :func:`load_solve_config` reads the TOML that
``lhgraph solve CONFIG.toml`` takes (docs/solve.md).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

from .angles import Angles, load_angles
from .board import Board, load_board
from .calibration import load_calibration
from .errors import InputError
from .fileio import as_float, as_int, read_toml
from .graph import GraphOptions, solve_graph
from .model import Convention, StationModel
from .result import SolveResult
from .stations import save_stations
from .trajectory import save_trajectory

METHODS = ("graph", "paper")


def station_models(calibration_path: str | Path | None,
                   convention: Convention | None = None) -> dict[int, StationModel]:
    """Station models from an ``ootx.toml`` (empty: ideal stations)."""
    if calibration_path is None:
        return {}
    convention = convention or Convention()
    return {k: StationModel(c.calibration, convention=convention)
            for k, c in load_calibration(calibration_path).items()}


def solve(board: Board, angles: Angles, method: str = "graph",
          models: dict[int, StationModel] | None = None, reference: int | None = None,
          graph_options: GraphOptions | None = None,
          progress: Callable[[str], None] | None = None) -> SolveResult:
    """Calibrate the stations seen in ``angles`` with ``method`` ("graph" or "paper")."""
    angles.check_board(board)
    if method == "graph":
        options = graph_options or GraphOptions()
        if reference is not None:
            options.reference = reference
        return solve_graph(board, angles, models, options, progress)
    if method == "paper":
        from .baseline import solve_paper

        return solve_paper(board, angles, models, reference, progress=progress)
    raise InputError(f"unknown method '{method}' (expected one of {', '.join(METHODS)})",
                     where="--method")


def write_solution(result: SolveResult, output: str | Path, trajectory: str | Path | None,
                   overwrite: bool) -> list[Path]:
    """Write the stations TOML (and the board trajectory CSV when asked)."""
    written = [save_stations(result.stations, output, overwrite)]
    if trajectory is not None and result.trajectory is not None:
        written.append(save_trajectory(result.trajectory, trajectory, overwrite))
    return written


@dataclass
class SolveConfig:
    """A solve described by a file: inputs, method and options (paths absolute)."""

    board: Path
    angles: Path
    output: Path | None = None
    method: str = "graph"
    calibration: Path | None = None
    trajectory: Path | None = None
    truth: Path | None = None
    reference: int | None = None
    graph: GraphOptions = field(default_factory=GraphOptions)


def load_solve_config(path: str | Path) -> SolveConfig:
    """Read a solve configuration; relative paths are relative to the file's folder."""
    path = Path(path)
    data = read_toml(path)
    base = path.parent
    known = {"board", "angles", "output", "method", "calibration", "trajectory", "truth",
             "reference", "graph"}
    for key in data:
        if key not in known:
            raise InputError(f"unknown key '{key}' (known: {', '.join(sorted(known))})", path,
                             key)

    def a_path(key: str, required: bool = False) -> Path | None:
        if key not in data:
            if required:
                raise InputError(f"missing key '{key}'", path, key)
            return None
        if not isinstance(data[key], str):
            raise InputError("expected a path string", path, key)
        return base / data[key]

    method = data.get("method", "graph")
    if method not in METHODS:
        raise InputError(f"unknown method '{method}' (expected one of {', '.join(METHODS)})",
                         path, "method")
    graph = GraphOptions()
    table: dict[str, Any] = data.get("graph", {})
    if not isinstance(table, dict):
        raise InputError("expected a table", path, "graph")
    names = {f.name: f.type for f in fields(GraphOptions)}
    for key, value in table.items():
        where = f"graph.{key}"
        if key not in names:
            raise InputError(f"unknown option (known: {', '.join(sorted(names))})", path, where)
        choices = {"solver": ("lm", "isam2"), "loss": ("cauchy", "huber")}
        if key in choices:
            if value not in choices[key]:
                raise InputError(f"expected one of {', '.join(choices[key])}", path, where)
        elif key in ("max_iterations", "reference"):
            value = as_int(value, path, where)
        else:
            value = as_float(value, path, where)
        setattr(graph, key, value)
    reference = as_int(data["reference"], path, "reference") if "reference" in data else None
    return SolveConfig(
        board=a_path("board", True), angles=a_path("angles", True), output=a_path("output"),
        method=method, calibration=a_path("calibration"), trajectory=a_path("trajectory"),
        truth=a_path("truth"), reference=reference, graph=graph,
    )


def run_config(config: SolveConfig, progress: Callable[[str], None] | None = None
               ) -> SolveResult:
    """Load the inputs a config names and solve."""
    board = load_board(config.board)
    angles = load_angles(config.angles)
    angles.check_board(board, config.angles)
    models = station_models(config.calibration)
    return solve(board, angles, config.method, models, config.reference, config.graph,
                 progress)
