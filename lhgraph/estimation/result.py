"""What a solver returns: the result dataclass shared by every method."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from lhgraph.io.stations import Stations
from lhgraph.io.trajectory import Trajectory
from lhgraph.model.board import Board, with_sensor_offsets


@dataclass(frozen=True)
class Residuals:
    """Per-hit residuals of the final solution (one row per hit used).

    ``residual_rad`` = measured - predicted angle; ``weight`` is the robust weight in [0, 1].
    """

    time: NDArray[np.float64]
    lighthouse: NDArray[np.int64]
    axis: NDArray[np.int64]
    sensor: NDArray[np.int64]
    residual_rad: NDArray[np.float64]
    weight: NDArray[np.float64]

    def rms_urad(self, inliers_only: bool = True) -> float:
        """Root-mean-square residual (microradians), of inliers (weight > 0.5) by default."""
        r = self.residual_rad[self.weight > 0.5] if inliers_only else self.residual_rad
        return float(np.sqrt(np.mean(r**2)) * 1e6) if len(r) else float("nan")

    def inlier_fraction(self) -> float:
        """Fraction of hits with robust weight > 0.5."""
        return float(np.mean(self.weight > 0.5)) if len(self.weight) else float("nan")


@dataclass(frozen=True)
class SolveResult:
    """Outcome of a calibration: station poses (world = reference station unless set
    otherwise), the board path, status and diagnostics. ``timings_s`` maps stage -> seconds."""

    method: str
    stations: Stations
    trajectory: Trajectory | None
    residuals: Residuals | None
    status: str = "converged"
    iterations: int = 0
    final_error: float = float("nan")
    timings_s: dict[str, float] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    diagnostics: dict[str, float] = field(default_factory=dict)
    """Method-specific figures, e.g. the graph's adapted motion-prior PSDs."""
    error_history: list[float] = field(default_factory=list)
    """Graph error (0.5 * sum of whitened squared residuals) at the initial values and after
    each optimiser iteration; empty for methods without such a loop."""
    gravity_world: NDArray[np.float64] | None = None
    """With an IMU: the gravity vector (m/s^2, pointing down) in the result's world."""
    diode_bias_rad: dict[int, NDArray[np.float64]] | None = None
    """With the graph's diode biases (``diode_bias_sigma_rad``): per station index, the
    ``(2, n_sensors)`` angle bias (rad) of each axis and board row."""
    options: dict[str, dict[str, Any]] | None = None
    """The options the solve ran with, every choice resolved, by group (the graph's
    :func:`~lhgraph.estimation.graph.resolve.resolve_options`; None for other methods)."""
    option_rules: list[str] = field(default_factory=list)
    """One line per rule that changed the options given (the graph's)."""
    captures: list[str] = field(default_factory=list)
    """With several captures joined (:mod:`lhgraph.io.captures`) or an earlier result as a
    prior: one line per capture (the stations it saw) and per prior station (used, or the
    prior's alone)."""
    sensor_offset_m: NDArray[np.float64] | None = None
    """With the graph's sensor offsets (``sensor_offset_sigma_m``): the correction ``(n_sensors,
    3)`` (m, board frame) of every sensor position of the board file, by board row."""
    factory_terms: dict[int, dict[str, dict[str, list[float]]]] | None = None
    """With the graph's solved factory terms (``factory_terms``): per station index, per
    term, per axis (lists of two, rad): ``decoded_rad`` (the value the solve was given,
    OOTX), ``solved_rad``, ``shift_rad`` (solved - decoded), ``sigma_rad`` (honest) and
    ``sigma_white_rad``. The result's station models carry the solved values."""
    board_scale: dict[str, float] | None = None
    """With the graph's board scale (``board_scale_sigma``): ``correction`` k (the sensors
    solved at ``1 + k`` times the board file's positions), its honest ``sigma`` and
    ``sigma_white``."""
    factory_information: dict[str, list] | None = None
    """With the graph's ``factory_information``: how well the capture determines each
    station's factory terms (:meth:`lhgraph.estimation.graph.factory_information.
    FactoryInformation.as_dict`)."""

    def corrected_board(self, board: Board) -> Board:
        """``board`` with the sensor positions the graph solved (its sensor offsets, then its
        board scale; ``board`` itself when it solved neither)."""
        if self.sensor_offset_m is None and self.board_scale is None:
            return board
        offsets = (np.zeros_like(board.positions) if self.sensor_offset_m is None
                   else np.asarray(self.sensor_offset_m))
        k = 0.0 if self.board_scale is None else self.board_scale["correction"]
        return with_sensor_offsets(board, (1.0 + k) * (board.positions + offsets)
                                   - board.positions)
