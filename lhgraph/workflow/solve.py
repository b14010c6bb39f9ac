"""One entry point for every calibration method, and the solve configuration file.

``solve(board, angles, method=...)`` dispatches to the factor graph (``"graph"``, default)
or the paper's pipeline (``"paper"``). :func:`load_solve_config` reads the TOML that
``lhgraph solve CONFIG.toml`` takes (docs/solve.md).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from lhgraph.errors import InputError
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.graph.solver import solve_graph
from lhgraph.estimation.gravity import to_gravity_world, up_vectors
from lhgraph.estimation.result import SolveResult
from lhgraph.io.angles import Angles, load_angles
from lhgraph.io.files import as_float, as_int, read_toml
from lhgraph.io.stations import save_stations
from lhgraph.io.trajectory import save_trajectory
from lhgraph.model.board import Board, load_board
from lhgraph.model.calibration import StationCalibration, load_calibration
from lhgraph.model.lh1 import Convention, StationModel

if TYPE_CHECKING:
    from lhgraph.estimation.baseline import PaperOptions

METHODS = ("graph", "paper")
WORLDS = ("reference", "gravity")


def station_models(calibration_path: str | Path | None,
                   convention: Convention | None = None) -> dict[int, StationModel]:
    """Station models from an ``ootx.toml`` (empty: ideal stations)."""
    if calibration_path is None:
        return {}
    return models_of(load_calibration(calibration_path), convention)


def models_of(calibrations: dict[int, StationCalibration],
              convention: Convention | None = None) -> dict[int, StationModel]:
    """Station models (by index) from decoded or loaded factory calibrations."""
    convention = convention or Convention()
    return {k: StationModel(c.calibration, convention=convention)
            for k, c in calibrations.items()}


def solve(board: Board, angles: Angles, method: str = "graph",
          models: dict[int, StationModel] | None = None, reference: int | None = None,
          graph_options: GraphOptions | None = None,
          progress: Callable[[str], None] | None = None,
          paper_options: PaperOptions | None = None,
          world_up: dict[int, NDArray[np.float64]] | None = None) -> SolveResult:
    """Calibrate the stations seen in ``angles`` with ``method`` ("graph" or "paper").

    The world is the reference station's frame, or with ``world_up`` (station index -> up
    vector in the station frame, :func:`lhgraph.estimation.gravity.up_vectors`) gravity-aligned.
    """
    angles.check_board(board)
    if method == "graph":
        options = graph_options or GraphOptions()
        if reference is not None:
            options.reference = reference
        result = solve_graph(board, angles, models, options, progress)
    elif method == "paper":
        from lhgraph.estimation.baseline import solve_paper

        staged = None if progress is None else (
            lambda stage, done, total: progress(f"{stage}: {done}/{total}"))
        result = solve_paper(board, angles, models, reference, paper_options, staged)
    else:
        raise InputError(f"unknown method '{method}' (expected one of {', '.join(METHODS)})",
                         where="--method")
    return result if world_up is None else to_gravity_world(result, world_up)


def write_solution(result: SolveResult, output: str | Path, trajectory: str | Path | None,
                   overwrite: bool) -> list[Path]:
    """Write the stations TOML (and the board trajectory CSV when asked)."""
    written = [save_stations(result.stations, output, overwrite)]
    if trajectory is not None and result.trajectory is not None:
        written.append(save_trajectory(result.trajectory, trajectory, overwrite))
    return written


@dataclass
class SolveConfig:
    """A solve described by a file: inputs, method(s) and options (paths absolute).

    The angles come from ``angles`` or, when ``capture`` is set instead, from decoding that
    capture (its OOTX calibration is used unless ``calibration`` is given). ``methods``
    (several methods, run directory output only) overrides ``method``; ``seed`` is recorded
    in a run directory's summary; ``path`` is the configuration file itself; ``duration_s``
    keeps only that many seconds from the moment the board starts moving; ``world`` is
    ``"reference"`` (the reference station's frame) or ``"gravity"`` (z up from the stations'
    OOTX accelerometer vectors, :mod:`lhgraph.estimation.gravity`).
    """

    board: Path
    angles: Path | None
    output: Path | None = None
    method: str = "graph"
    calibration: Path | None = None
    trajectory: Path | None = None
    truth: Path | None = None
    reference: int | None = None
    graph: GraphOptions = field(default_factory=GraphOptions)
    capture: Path | None = None
    methods: list[str] | None = None
    seed: int | None = None
    path: Path | None = None
    duration_s: float | None = None
    world: str = "reference"

    def method_list(self) -> list[str]:
        """The methods to run, in order."""
        return list(self.methods) if self.methods else [self.method]


@dataclass
class SolveInputs:
    """What a config's files hold: board, angles, station models, decoder report lines, and
    the stations' up vectors when the config asks for a gravity-aligned world."""

    board: Board
    angles: Angles
    models: dict[int, StationModel]
    notes: list[str] = field(default_factory=list)
    world_up: dict[int, NDArray[np.float64]] | None = None


def parse_graph_options(table: Any, path: str | Path, where: str = "graph") -> GraphOptions:
    """GraphOptions from a config's ``[graph]`` table (unknown or mistyped keys: InputError)."""
    graph = GraphOptions()
    if not isinstance(table, dict):
        raise InputError("expected a table", path, where)
    names = {f.name: f.type for f in fields(GraphOptions)}
    for key, value in table.items():
        at = f"{where}.{key}"
        if key not in names:
            raise InputError(f"unknown option (known: {', '.join(sorted(names))})", path, at)
        choices = {"solver": ("lm", "isam2"), "loss": ("cauchy", "huber")}
        default = getattr(graph, key)
        if key in choices:
            if value not in choices[key]:
                raise InputError(f"expected one of {', '.join(choices[key])}", path, at)
        elif isinstance(default, bool):
            if not isinstance(value, bool):
                raise InputError(f"expected true or false, got {value!r}", path, at)
        elif key == "reference" or isinstance(default, int):
            value = as_int(value, path, at)
        else:
            value = as_float(value, path, at)
        setattr(graph, key, value)
    return graph


def load_solve_config(path: str | Path) -> SolveConfig:
    """Read a solve configuration; relative paths are relative to the file's folder."""
    path = Path(path)
    data = read_toml(path)
    base = path.parent
    known = {"board", "angles", "output", "method", "calibration", "trajectory", "truth",
             "reference", "graph", "capture", "methods", "seed", "duration", "world"}
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
    methods = data.get("methods")
    if methods is not None:
        if "method" in data:
            raise InputError("give 'method' or 'methods', not both", path, "methods")
        if (not isinstance(methods, list) or not methods
                or any(m not in METHODS for m in methods) or len(set(methods)) != len(methods)):
            raise InputError(f"expected a non-empty list of distinct methods from "
                             f"{', '.join(METHODS)}, got {methods!r}", path, "methods")
    if ("angles" in data) == ("capture" in data):
        raise InputError("give exactly one of 'angles' and 'capture'", path,
                         "angles" if "angles" in data else "capture")
    graph = parse_graph_options(data.get("graph", {}), path)
    reference = as_int(data["reference"], path, "reference") if "reference" in data else None
    seed = as_int(data["seed"], path, "seed") if "seed" in data else None
    duration = as_float(data["duration"], path, "duration") if "duration" in data else None
    world = data.get("world", "reference")
    if world not in WORLDS:
        raise InputError(f"expected one of {', '.join(WORLDS)}, got {world!r}", path, "world")
    return SolveConfig(
        board=a_path("board", True), angles=a_path("angles"), output=a_path("output"),
        method=method, calibration=a_path("calibration"), trajectory=a_path("trajectory"),
        truth=a_path("truth"), reference=reference, graph=graph, capture=a_path("capture"),
        methods=methods, seed=seed, path=path, duration_s=duration, world=world,
    )


def load_inputs(config: SolveConfig) -> SolveInputs:
    """Read the board, the angles (or decode the capture) and the station models."""
    board = load_board(config.board)
    notes: list[str] = []
    calibrations = load_calibration(config.calibration) if config.calibration else {}
    if config.capture is not None:
        from lhgraph.signal.decode import decode_file

        decoded, warnings = decode_file(config.capture, board=board)
        angles = decoded.angles
        notes = [*warnings, *decoded.report.lines()]
        if config.calibration is None:
            calibrations = decoded.calibrations
        source: Path = config.capture
    elif config.angles is not None:
        angles = load_angles(config.angles)
        source = config.angles
    else:
        raise InputError("no angles: give 'angles' or 'capture'", config.path, "angles")
    angles.check_board(board, source)
    if config.duration_s is not None:
        from lhgraph.workflow.window import moving_window

        angles = moving_window(angles, config.duration_s)
        notes.append(f"solved {config.duration_s:g} s from the start of motion "
                     f"(t = {angles.time[0]:.3f} s)")
    world_up = None
    if config.world == "gravity":
        world_up = up_vectors(calibrations)
        if not world_up:
            raise InputError("world = 'gravity' needs the stations' accelerometer vectors "
                             "(accel_dir in an ootx.toml, or a capture's OOTX): none given",
                             config.calibration or config.capture or config.path, "world")
    return SolveInputs(board, angles, models_of(calibrations), notes, world_up)


def run_config(config: SolveConfig, progress: Callable[[str], None] | None = None
               ) -> SolveResult:
    """Load the inputs a config names and solve with its (first) method."""
    inputs = load_inputs(config)
    return solve(inputs.board, inputs.angles, config.method_list()[0], inputs.models,
                 config.reference, config.graph, progress, world_up=inputs.world_up)
