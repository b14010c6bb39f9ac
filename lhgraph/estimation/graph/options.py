"""The graph solver's options."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]
Progress = Callable[[str], None]


@dataclass
class GraphOptions:
    """Solver settings (units in the names; defaults suit 2 MHz LH1 captures).

    ``angle_sigma_rad``: per-diode angle noise (the floor when ``adapt_angle_sigma``: then the
    updates also raise it to the residuals' robust spread, at most ``max_sigma_factor`` times);
    ``sweep_offset_sigma_rad``: noise common to all diodes of one sweep (the sampled sync
    edge); ``loss``: per-diode robust loss (``"cauchy"`` or ``"huber"``) and ``huber_k``
    its scale in sigmas;
    ``accel_psd_rot``/``accel_psd_pos``: power spectral density of the board's angular
    (rad^2/s^3) and linear (m^2/s^3) acceleration noise in the motion prior (starting values
    when ``adapt_motion_prior``: then up to ``motion_prior_rounds`` variance-component updates
    rescale both to the solved motion, LM solver only, kept within [``min_psd_factor``,
    ``max_psd_factor``] times the start); ``solver``:
    ``"lm"`` (Levenberg-Marquardt on GTSAM's linear solver) or ``"isam2"``;
    ``max_iterations``; LM stops when the stations are estimated to be within
    ``step_tolerance_sigma`` of their standard deviations from the converged solution and no
    board state moved by more than ``board_step_tolerance_rad`` and ``board_step_tolerance_m``
    in the last iteration, or an iteration lowers the error by less than the fraction
    ``relative_tolerance``;
    ``reference``: station index of the world frame (default: the lowest index present).
    """

    angle_sigma_rad: float = 4e-5
    sweep_offset_sigma_rad: float = 5.5e-5
    huber_k: float = 3.0
    loss: str = "cauchy"
    accel_psd_rot: float = 10.0
    accel_psd_pos: float = 1.0
    adapt_motion_prior: bool = True
    max_psd_factor: float = 10.0
    adapt_angle_sigma: bool = True
    max_sigma_factor: float = 10.0
    min_psd_factor: float = 0.2
    motion_prior_rounds: int = 5
    solver: str = "lm"
    max_iterations: int = 60
    relative_tolerance: float = 1e-5
    step_tolerance_sigma: float = 0.05
    board_step_tolerance_rad: float = 1e-3
    board_step_tolerance_m: float = 1e-4
    reference: int | None = None
    weak_link_sigma_m: float = 0.02
