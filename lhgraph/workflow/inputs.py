"""What a solve configuration's files hold: board, angles (read or decoded), station models.

:func:`check_inputs` refuses missing input files before anything is written;
:func:`load_inputs` reads them all. :func:`calibration_beside` finds the ``ootx.toml`` that
decode and the importers write beside the angles; :func:`check_generations` refuses a
calibration of the other Lighthouse generation than the angles' sweeps.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from lhgraph.errors import InputError
from lhgraph.estimation.gravity import up_vectors
from lhgraph.estimation.station_prior import StationPriors, station_priors
from lhgraph.estimation.sweep_times import swept_generations
from lhgraph.io.angles import Angles, load_angles
from lhgraph.io.captures import capture_lines, join_captures
from lhgraph.io.files import protect_inputs
from lhgraph.io.imu import ImuStream, load_imu
from lhgraph.io.stations import load_stations
from lhgraph.model.board import Board, load_board
from lhgraph.model.calibration import StationCalibration, load_calibration
from lhgraph.model.station import Convention, StationModel
from lhgraph.signal.formats import OOTX_FILE
from lhgraph.workflow.solve_config import SolveConfig


def station_models(calibration_path: str | Path | None,
                   convention: Convention | None = None) -> dict[int, StationModel]:
    """Station models from an ``ootx.toml`` (empty: ideal stations)."""
    if calibration_path is None:
        return {}
    return models_of(load_calibration(calibration_path), convention)


def calibration_beside(angles: str | Path | None, calibration: str | Path | None
                       ) -> tuple[Path | None, str | None]:
    """The factory calibration to use with ``angles``: ``calibration`` when given, else the
    ``ootx.toml`` beside the angles file (as decode and the importers write it) with one
    line saying so (the file joins the guarded inputs, :func:`~lhgraph.io.files.
    protect_inputs`), else None (ideal stations)."""
    if calibration is not None or angles is None:
        return (None if calibration is None else Path(calibration)), None
    beside = Path(angles).parent / OOTX_FILE
    if not beside.is_file():
        return None, None
    protect_inputs([beside])
    return beside, (f"using the factory calibration beside the angles, {beside} "
                    "(--calibration to give another)")


def check_generations(models: dict[int, StationModel], angles: Angles,
                      calibration: str | Path, source: str | Path) -> None:
    """InputError naming ``calibration`` when a station's model (from it) is of the other
    Lighthouse generation than its sweeps in ``angles`` (read from ``source``) show
    (:func:`~lhgraph.estimation.sweep_times.swept_generations`)."""
    swept = swept_generations(angles)
    for generation, how in ((1, "LH2's, once per 18.5-20 ms revolution"),
                            (2, "LH1's, whole 1/60 s rotor turns apart")):
        wrong = sorted(k for k, m in models.items()
                       if m.generation == generation and swept.get(k) not in (None, generation))
        if wrong:
            raise InputError(f"station(s) {', '.join(map(str, wrong))} are LH{generation} in "
                             f"this file but their sweeps in {source} are {how}: not a "
                             "calibration of these stations (wrong ootx.toml?)", calibration)


def models_of(calibrations: dict[int, StationCalibration],
              convention: Convention | None = None) -> dict[int, StationModel]:
    """Station models (by index) from decoded or loaded factory calibrations."""
    return {k: c.model(convention) for k, c in calibrations.items()}


@dataclass
class SolveInputs:
    """What a config's files hold: board, angles, station models, decoder report lines, and
    the stations' up vectors when the config asks for a gravity-aligned world."""

    board: Board
    angles: Angles
    models: dict[int, StationModel]
    notes: list[str] = field(default_factory=list)
    world_up: dict[int, NDArray[np.float64]] | None = None
    imu: ImuStream | None = None
    prior: StationPriors | None = None
    captures: list[str] = field(default_factory=list)
    """With several captures: a line per capture (its stations and hits) and the joining's
    notes."""


def check_inputs(config: SolveConfig) -> None:
    """InputError unless every input file the config names exists and is a file (run before
    any output is created, so a bad input leaves nothing behind)."""
    names = ("board", "angles", "capture", "calibration", "truth", "imu", "prior")
    named = [(name, getattr(config, name)) for name in names]
    named += [("angles", more) for more in config.more_angles]
    protect_inputs([config.path, *(path for _, path in named)])
    for name, path in named:
        if path is None:
            continue
        if not path.exists():
            raise InputError(f"{name} file not found", path)
        if not path.is_file():
            raise InputError(f"is a directory, expected the {name} file", path)


def load_inputs(config: SolveConfig) -> SolveInputs:
    """Read the board, the angles (or decode the capture) and the station models."""
    check_inputs(config)
    board = load_board(config.board)
    notes: list[str] = []
    captures: list[str] = []
    calibrations = load_calibration(config.calibration) if config.calibration else {}
    if config.capture is not None:
        from lhgraph.signal.formats import decode_file

        decoded, warnings = decode_file(config.capture, board=board)
        angles = decoded.angles
        notes = [*warnings, *decoded.report.lines()]
        if config.calibration is None:
            calibrations = decoded.calibrations
        source: Path = config.capture
    elif config.angles is not None:
        angles = load_angles(config.angles)
        source = config.angles
        if config.more_angles:
            angles, captures = _joined(config, board, angles)
    else:
        raise InputError("no angles: give 'angles' or 'capture'", config.path, "angles")
    angles.check_board(board, source)
    if config.calibration is not None:
        check_generations(models_of(calibrations), angles, config.calibration, source)
    if config.duration_s is not None:
        from lhgraph.workflow.window import moving_window

        angles = moving_window(angles, config.duration_s)
        notes.append(f"solved {config.duration_s:g} s from the start of motion "
                     f"(t = {angles.time[0]:.3f} s)")
    world_up = None
    if config.world == "gravity":
        world_up = up_vectors(calibrations)
        if not world_up and config.imu is None:
            raise InputError("world = 'gravity' needs the stations' accelerometer vectors "
                             "(accel_dir in an ootx.toml, or a capture's OOTX) or the "
                             "receiver's IMU (imu, --imu): none given",
                             config.calibration or config.capture or config.path, "world")
    imu = None if config.imu is None else load_imu(config.imu)
    prior = None
    if config.prior is not None:
        reference = config.reference if config.reference is not None else min(
            angles.stations())
        prior = station_priors(load_stations(config.prior), reference, config.prior)
    return SolveInputs(board, angles, models_of(calibrations), notes, world_up, imu, prior,
                       captures)


def _joined(config: SolveConfig, board: Board, first: Angles) -> tuple[Angles, list[str]]:
    """The config's captures joined into one table (:func:`join_captures`), and a line per
    capture; InputError for what a joint solve does not take yet (an IMU, a duration)."""
    for key, value in (("imu", config.imu), ("duration", config.duration_s)):
        if value is not None:
            raise InputError(f"several captures (angles) do not take '{key}' yet: solve "
                             "them without it, or one capture at a time", config.path, key)
    captures, names = [first], [config.angles]
    for path in config.more_angles:
        more = load_angles(path)
        more.check_board(board, path)
        captures.append(more)
        names.append(path)
    joined, spans, notes = join_captures(captures, names)
    return joined, capture_lines(spans) + notes
