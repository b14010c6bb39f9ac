"""The graph solver's options: a frozen dataclass whose fields declare their allowed values."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lhgraph.config import check_fields, option
from lhgraph.errors import InputError
from lhgraph.estimation.imu.inertial import accel_factor_sigma
from lhgraph.io.imu import ImuStream

LOSSES = ("cauchy", "huber")
SOLVERS = ("lm", "isam2")
SWEEP_TIMES = ("auto", "stamped")
PRIOR_ESTIMATES = ("auto", "chi2", "redundancy")
ACCEL_ESTIMATES = ("auto", "stream", "redundancy")
IMU_FACTORS = ("auto", "combined", "twist")
STEP_TOLERANCE_SIGMA = 0.05
"""The stations' test of the stopping rule (``GraphOptions.step_tolerance_sigma`` unset): LM
stops when they are estimated within this many standard deviations of convergence."""


@dataclass(frozen=True)
class FewDiodeStop:
    """The stopping rule on few-diode data where the user's options leave it unset:
    ``board_step_quantile`` and ``step_tolerance_sigma`` of :class:`GraphOptions`."""

    board_step_quantile: float
    step_tolerance_sigma: float


FEW_DIODE_CALIBRATION = FewDiodeStop(board_step_quantile=0.5, step_tolerance_sigma=0.25)
"""Calibrating few-diode data. The stations, the product, have their own test: the bulk of the
path must have settled, not every state (on the real Crazyflie LH1 log the 0.95 quantile took
36 LM iterations instead of 15, for station 1 within 0.5 mm, half its 1-sigma, of the same
place, the same measure (b) and the same path against the mocap). Their steps shrink slowly
and unevenly while weakly seen states still turn, so the rate estimate of what remains is
rough, and a quarter of a sigma is the test (not 0.05): on the real LH1 log 11 iterations
instead of 15 (station 1 0.48 mm from the 36-iteration answer, against 0.49), on the LH2 log
11 instead of 18 (0.37 mm from it), measure (b) the same on both; on 10 simulated decks
station 1 1.17 mm / 0.029 deg from the truth (median) against 1.05 mm / 0.025 deg
(``benchmarks/deck_benchmark.py``). The test applies to every root variable of the graph:
with the IMU also its biases, gravity and calibration."""
FEW_DIODE_TRACKING = FewDiodeStop(board_step_quantile=0.95,
                                  step_tolerance_sigma=STEP_TOLERANCE_SIGMA)
"""Tracking few-diode data: the path is the product (states seen by one station only can sit
in a mirror pose that turns for dozens of iterations)."""


@dataclass(frozen=True)
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
    ``max_psd_factor``] times the start); ``motion_prior_estimate``: how an update rescales
    the prior: ``"chi2"`` to its whitened residuals' mean square per degree of freedom,
    ``"redundancy"`` to their sum over the prior's redundancy (its rows less the trace of
    their hat matrix, :func:`~lhgraph.estimation.graph.noise.redundancy`: the degrees of
    freedom the fit leaves the prior; no floor, ``min_psd_factor`` unused), ``"auto"``:
    ``"redundancy"`` on few-diode data without IMU factors, ``"chi2"`` otherwise
    (:func:`~lhgraph.estimation.graph.solver.resolve_estimates`; on the simulated decks the
    floored chi2 prior is too stiff for a hand-held 4-diode deck: with the twins chosen well
    its stations were 1.9 mm off with NEES 15.5, 1.0 mm with NEES 3.4 by the redundancy);
    ``solver``:
    ``"lm"`` (Levenberg-Marquardt on GTSAM's linear solver) or ``"isam2"``;
    ``max_iterations``; LM stops when the stations are estimated to be within
    ``step_tolerance_sigma`` of their standard deviations from the converged solution (None =
    ``STEP_TOLERANCE_SIGMA``, or on few-diode data when calibrating
    ``FEW_DIODE_CALIBRATION.step_tolerance_sigma``) and no
    board state moved by more than ``board_step_tolerance_rad`` and ``board_step_tolerance_m``
    in the last iteration, or an iteration lowers the error by less than the fraction
    ``relative_tolerance``;
    ``reference``: station index of the world frame (default: the lowest index present);
    ``weak_link_sigma_m``: a station whose position 1-sigma exceeds it is reported as weakly
    linked; ``sweep_times``: ``"auto"`` puts the sweeps of a receiver that logs a station's
    two sweeps together (the Crazyflie deck) at their sweep times
    (:mod:`lhgraph.estimation.sweep_times`), ``"stamped"`` takes every stamp as the hit time;
    ``board_step_quantile``: the board-step test of the stopping rule applies to this quantile
    of the states' steps (1 = every state; None = 1, or on few-diode data, whose states seen
    by one station only can sit in a mirror pose that turns for dozens of iterations without
    moving the stations, the median when calibrating and 0.95 when tracking:
    ``FEW_DIODE_CALIBRATION``, ``FEW_DIODE_TRACKING``); ``few_diode_sigma_rad``: the
    floor of the angle noise on few-diode data instead of ``angle_sigma_rad`` (a real LH1
    station's noise, SPEC §3; with ~7 hits per state, the state's pose and offset absorb
    much of the residual, so their spread underestimates the noise);
    ``lh2_angle_sigma_rad``: the angle-noise floor when every station is LH2 (SteamVR 2.0),
    instead of ``angle_sigma_rad``: a receiver decodes LH2 with its own fast timer (the
    deck's 24 MHz: 13 µrad a tick), not the board's 2 MHz sampler (on 12 simulated protocol
    captures the LH1 floor left the covariance pessimistic: mean NEES 2.4 of 6, 4.0 with
    this one). The sweep offsets stay: an LH2 station has no sync flash, but on the real
    LH2 log, holding them at zero took 51 LM iterations against 19, for a geometry no better
    (measure (b) 6.6 against 6.5 mm): they absorb what the deck's hit times leave of a
    sweep's common error);
    ``max_board_step_rad`` / ``max_board_step_m``: when an LM step raises the error, it is
    tried again with each board state's rotation / translation step scaled down to these
    (a trust region per state: a state far from its solution, e.g. a mirror pose, turns this
    far instead of taking a step the linearisation does not hold) before the damping that
    slows every variable; ``gyro_sigma_rad_s`` / ``accel_sigma_mps2``: noise of the IMU
    factors (a gyro reading at a state's time; an accelerometer reading over a step, which
    also carries the vibration and the lever arm the model leaves out), used when an IMU
    stream is given (:mod:`lhgraph.estimation.imu.inertial`), whose samples count within
    ``imu_max_gap_s`` of a state; ``adapt_accel_sigma``: the accelerometer factors' noise
    is instead :func:`~lhgraph.estimation.imu.inertial.accel_factor_sigma` of the stream (its
    readings' own noise, vibration included), between ``min_accel_sigma_mps2`` and
    ``accel_sigma_mps2`` (the ceiling); ``accel_sigma_estimate``: ``"redundancy"``: from
    there the variance-component updates rescale the accelerometer factors' noise to their
    chi2 over their redundancy (the degrees of freedom the fit leaves them, as for the motion
    prior), within the same bounds; ``"stream"``: it stays where the stream put it;
    ``"auto"`` (the default): ``"redundancy"`` on few-diode data or with the IMU calibration
    solved (:attr:`imu_calibrated`), ``"stream"`` otherwise (many diodes pin the path: the
    accelerometer factors keep ~2 % of their rows as redundancy, too little to estimate
    from, and it took the 8 s capture's IMU solve from 1.3x to 1.8x the light-only one;
    docs/solve.md); ``gyro_preintegration``:
    also a factor per step on the rotation the gyro's readings between the two states
    integrate to
    (:mod:`lhgraph.estimation.imu.twist_terms`; off by default: on the real Crazyflie log the
    deck's hit times and IMU stamps disagree by milliseconds at turns of ~1 rad/s, far above
    its noise, and it raised the light's residuals from 70 to 160 urad rms);
    ``adapt_gyro_sigma``: the variance-component updates (as for the motion prior) also
    rescale the preintegrated gyro factors' reading noise to their residuals, starting from
    ``gyro_sigma_rad_s`` (the ceiling) and never below the stream's own reading noise
    (:func:`~lhgraph.estimation.imu.inertial.gyro_reading_sigma`, at least
    ``min_gyro_sigma_rad_s``): on the simulated facing stations with a 1 kHz gyro of 0.002
    rad/s the fixed 0.02 left station 1's covariance several times too wide (mean NEES 0.9
    of 6), while the stream's noise from the start pulled hive's gyro scale to 0.95 instead of
    its ~0.5 (the light bent to the gyro before the scale could move);
    ``gyro_scale_sigma`` /
    ``imu_time_offset_sigma_s``: when
    positive, the IMU's per-axis gyro scale error (the gyro reads ``(1 + s) omega``; the hive
    tracker's reads ~0.48x) / its time offset to the light (s) are solved with this prior
    spread (the variable family ``IMU calibration``); 0: not estimated;
    ``imu_rotation_sigma_rad``: likewise the rotation of the IMU's frame in the board's (the
    hive tracker's gyro axes are ~1.5 deg off its light frame);
    ``imu_position_sigma_m``: likewise the IMU's position in the board frame (m), the lever
    arm that adds the board's centripetal and angular acceleration to what the accelerometer
    reads;
    ``imu_factors``: which IMU factors the graph gets: ``"combined"``, GTSAM's preintegrated
    ``CombinedImuFactor`` between consecutive states, evaluated in C++, with a velocity and
    an IMU bias per state (:mod:`lhgraph.estimation.imu.combined`; its readings'
    noise the stream's own times ``imu_noise_factor``, its biases wandering by
    ``gyro_bias_walk`` (rad/s per root second) and ``accel_bias_walk`` (m/s^2 per root
    second)); ``"twist"``, a gyro factor per state and an accelerometer factor per step on
    the states' twists with one IMU bias (:mod:`lhgraph.estimation.imu.inertial`: the factors
    that solve the IMU's calibration and take ``gyro_preintegration``); ``"auto"``
    (:attr:`imu_factor_kind`): ``"twist"`` when the calibration is solved or
    ``gyro_preintegration`` is asked, ``"combined"`` otherwise (``"combined"`` with
    ``gyro_scale_sigma``, ``imu_time_offset_sigma_s`` or ``imu_rotation_sigma_rad`` takes
    the calibration found from the light-only solution,
    :mod:`lhgraph.estimation.imu.calibration`; with ``imu_position_sigma_m`` or
    ``gyro_preintegration`` it is an error);
    ``diode_bias_sigma_rad``: when positive, every station sees every diode on each axis
    with a constant angle bias of this prior spread (variables of the graph,
    :func:`~lhgraph.estimation.graph.variables.diode_bias_family`: the board's geometry
    errors and the diodes' own delays, which repeat from sweep to sweep); 0: none;
    ``sensor_offset_sigma_m``: when positive, a correction of every sensor's position is
    solved with this prior spread (:func:`~lhgraph.estimation.graph.variables.
    sensor_offset_family`); ``rest_keep_every``: where the board rests (still for 1 s or
    more, :func:`~lhgraph.estimation.rests.rest_spans`) the calibration keeps the hits of one
    0.1 s window in this many (1: all), since a rest's sweeps repeat one pose and its
    repeating errors (:mod:`lhgraph.estimation.rests`).
    Each field's
    allowed range is declared next to it; a value outside it raises
    :class:`~lhgraph.errors.InputError` naming the field.
    """

    angle_sigma_rad: float = option(4e-5, gt=0)
    sweep_offset_sigma_rad: float = option(5.5e-5, gt=0)
    huber_k: float = option(3.0, gt=0)
    loss: str = option("cauchy", choices=LOSSES)
    accel_psd_rot: float = option(10.0, gt=0)
    accel_psd_pos: float = option(1.0, gt=0)
    adapt_motion_prior: bool = option(True)
    max_psd_factor: float = option(10.0, ge=1)
    adapt_angle_sigma: bool = option(True)
    max_sigma_factor: float = option(10.0, ge=1)
    min_psd_factor: float = option(0.2, gt=0, le=1)
    motion_prior_rounds: int = option(5, ge=0)
    motion_prior_estimate: str = option("auto", choices=PRIOR_ESTIMATES)
    solver: str = option("lm", choices=SOLVERS)
    max_iterations: int = option(60, gt=0)
    relative_tolerance: float = option(1e-5, ge=0, lt=1)
    step_tolerance_sigma: float | None = option(None, kind=float, ge=0)
    board_step_tolerance_rad: float = option(1e-3, ge=0)
    board_step_tolerance_m: float = option(1e-4, ge=0)
    reference: int | None = option(None, kind=int, ge=0)
    weak_link_sigma_m: float = option(0.02, gt=0)
    sweep_times: str = option("auto", choices=SWEEP_TIMES)
    board_step_quantile: float | None = option(None, kind=float, gt=0, le=1)
    few_diode_sigma_rad: float = option(6.5e-5, gt=0)
    lh2_angle_sigma_rad: float = option(1e-5, gt=0)
    max_board_step_rad: float = option(0.3, gt=0)
    max_board_step_m: float = option(0.1, gt=0)
    gyro_sigma_rad_s: float = option(0.02, gt=0)
    accel_sigma_mps2: float = option(0.5, gt=0)
    adapt_accel_sigma: bool = option(True)
    min_accel_sigma_mps2: float = option(0.02, gt=0)
    accel_sigma_estimate: str = option("auto", choices=ACCEL_ESTIMATES)
    imu_max_gap_s: float = option(0.05, gt=0)
    gyro_preintegration: bool = option(False)
    adapt_gyro_sigma: bool = option(True)
    min_gyro_sigma_rad_s: float = option(5e-4, gt=0)
    gyro_scale_sigma: float = option(0.0, ge=0)
    imu_time_offset_sigma_s: float = option(0.0, ge=0)
    imu_rotation_sigma_rad: float = option(0.0, ge=0)
    imu_position_sigma_m: float = option(0.0, ge=0)
    imu_factors: str = option("auto", choices=IMU_FACTORS)
    imu_noise_factor: float = option(1.0, gt=0)
    gyro_bias_walk: float = option(1e-4, gt=0)
    accel_bias_walk: float = option(1e-3, gt=0)
    diode_bias_sigma_rad: float = option(0.0, ge=0)
    sensor_offset_sigma_m: float = option(0.0, ge=0)
    rest_keep_every: int = option(1, ge=1)

    def __post_init__(self) -> None:
        check_fields(self)
        if self.imu_factors == "combined" and (self.imu_position_sigma_m > 0
                                                or self.gyro_preintegration):
            raise InputError("GTSAM's combined IMU factors take no lever arm and have their "
                             "own gyro preintegration: use 'twist' (or 'auto') with "
                             "imu_position_sigma_m or gyro_preintegration", where="imu_factors")

    @property
    def imu_calibrated(self) -> bool:
        """Whether the graph solves an IMU calibration (any of its four sigmas set)."""
        return (self.gyro_scale_sigma > 0 or self.imu_time_offset_sigma_s > 0
                or self.imu_rotation_sigma_rad > 0 or self.imu_position_sigma_m > 0)

    @property
    def imu_factor_kind(self) -> str:
        """``imu_factors`` with ``"auto"`` resolved: ``"twist"`` when the IMU calibration is
        solved or ``gyro_preintegration`` asked (GTSAM's combined factor has neither),
        ``"combined"`` otherwise."""
        if self.imu_factors != "auto":
            return self.imu_factors
        return "twist" if self.imu_calibrated or self.gyro_preintegration else "combined"

    @property
    def imu_calibration_from_light(self) -> bool:
        """Whether the IMU's calibration is found from the light-only solution
        (:mod:`lhgraph.estimation.imu.calibration`): asked for with GTSAM's combined factors,
        which cannot solve it."""
        return self.imu_factor_kind == "combined" and self.imu_calibrated

    def accel_start_sigma(self, imu: ImuStream) -> float:
        """The accelerometer factors' noise (m/s^2) to start from with the stream ``imu``:
        with ``adapt_accel_sigma`` its :func:`~lhgraph.estimation.imu.inertial.accel_factor_sigma`
        clipped to [``min_accel_sigma_mps2``, ``accel_sigma_mps2``] (the ceiling wins), else
        ``accel_sigma_mps2``."""
        if not self.adapt_accel_sigma:
            return self.accel_sigma_mps2
        return float(np.clip(accel_factor_sigma(imu), self.min_accel_sigma_mps2,
                             self.accel_sigma_mps2))
