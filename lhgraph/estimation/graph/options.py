"""The graph solver's options, nested by concern: :class:`GraphOptions` holds one frozen
dataclass per concern (the optimiser and its stopping rule, the diodes' noise, the robust
loss, the motion prior, the IMU, the board's and the stations' self-calibration, the data,
the stations' uncertainty), each of whose fields declares its allowed values
(:func:`lhgraph.config.option`).

Every option keeps one name across the groups, so a configuration's ``[graph]`` table may
give it flat (``max_iterations = 30``) or in its group's sub-table (``[graph.optimizer]``);
:meth:`GraphOptions.of` and :meth:`GraphOptions.with_values` take flat names too. What a
solve actually runs with is :func:`lhgraph.estimation.graph.resolve.resolve_options` of
these: every ``"auto"`` and unset value decided, in the open.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from lhgraph.config import check_fields, group, groups, option
from lhgraph.errors import InputError
from lhgraph.estimation.imu.inertial import accel_factor_sigma
from lhgraph.io.imu import ImuStream
from lhgraph.model.factory import CALIBRATION_KEYS, LH2_CALIBRATION_KEYS

LOSSES = ("cauchy", "huber")
SOLVERS = ("lm", "isam2")
SWEEP_TIMES = ("auto", "stamped")
PRIOR_ESTIMATES = ("auto", "chi2", "redundancy")
ACCEL_ESTIMATES = ("auto", "stream", "redundancy")
IMU_FACTORS = ("auto", "combined", "twist")
COVARIANCES = ("blocks", "white")
BLOCK_ESTIMATORS = ("jackknife", "plain")


@dataclass(frozen=True)
class OptimizerOptions:
    """The optimiser and its stopping rule.

    ``solver``: ``"lm"`` (Levenberg-Marquardt on GTSAM's linear solver) or ``"isam2"``;
    ``max_iterations``; LM stops when the stations are estimated to be within
    ``step_tolerance_sigma`` of their standard deviations from the converged solution (None:
    decided by :func:`~lhgraph.estimation.graph.resolve.resolve_options`) and no board state
    moved by more than ``board_step_tolerance_rad`` and ``board_step_tolerance_m`` in the
    last iteration, or an iteration lowers the error by less than the fraction
    ``relative_tolerance``; ``board_step_quantile``: the board-step test applies to this
    quantile of the states' steps (None: resolved; few-diode states seen by one station only
    can sit in a mirror pose that turns for dozens of iterations without moving the
    stations); ``max_board_step_rad`` / ``max_board_step_m``: when an LM step raises the
    error, it is tried again with each board state's rotation / translation step scaled down
    to these (a trust region per state) before the damping that slows every variable."""

    solver: str = option("lm", choices=SOLVERS)
    max_iterations: int = option(60, gt=0)
    relative_tolerance: float = option(1e-5, ge=0, lt=1)
    step_tolerance_sigma: float | None = option(None, kind=float, ge=0)
    board_step_tolerance_rad: float = option(1e-3, ge=0)
    board_step_tolerance_m: float = option(1e-4, ge=0)
    board_step_quantile: float | None = option(None, kind=float, gt=0, le=1)
    max_board_step_rad: float = option(0.3, gt=0)
    max_board_step_m: float = option(0.1, gt=0)

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class NoiseOptions:
    """The light's noise.

    ``angle_sigma_rad``: per-diode angle noise (the floor when ``adapt_angle_sigma``: then
    the updates also raise it to the residuals' robust spread, at most ``max_sigma_factor``
    times); ``sweep_offset_sigma_rad``: noise common to all diodes of one sweep (the sampled
    sync edge); ``few_diode_sigma_rad``: the floor of the angle noise on few-diode data (a
    real LH1 station's noise, SPEC §3: with ~7 hits per state, the state's pose and offset
    absorb much of the residual, so their spread underestimates the noise);
    ``lh2_angle_sigma_rad``: the angle-noise floor when every station is LH2 (a receiver
    decodes LH2 with its own fast timer, not the board's 2 MHz sampler; on 12 simulated
    protocol captures the LH1 floor left the covariance pessimistic: mean NEES 2.4 of 6,
    4.0 with this one)."""

    angle_sigma_rad: float = option(4e-5, gt=0)
    sweep_offset_sigma_rad: float = option(5.5e-5, gt=0)
    adapt_angle_sigma: bool = option(True)
    max_sigma_factor: float = option(10.0, ge=1)
    few_diode_sigma_rad: float = option(6.5e-5, gt=0)
    lh2_angle_sigma_rad: float = option(1e-5, gt=0)

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class RobustOptions:
    """The per-diode robust loss: ``loss`` (``"cauchy"`` or ``"huber"``) and ``huber_k``, its
    scale in sigmas."""

    loss: str = option("cauchy", choices=LOSSES)
    huber_k: float = option(3.0, gt=0)

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class MotionOptions:
    """The motion prior (white noise on acceleration).

    ``accel_psd_rot`` / ``accel_psd_pos``: power spectral density of the board's angular
    (rad^2/s^3) and linear (m^2/s^3) acceleration noise (starting values when
    ``adapt_motion_prior``: then up to ``motion_prior_rounds`` variance-component updates
    rescale both to the solved motion, LM solver only, kept within [``min_psd_factor``,
    ``max_psd_factor``] times the start); ``motion_prior_estimate``: how an update rescales
    the prior: ``"chi2"`` to its whitened residuals' mean square per degree of freedom,
    ``"redundancy"`` to their sum over the prior's redundancy (its rows less the trace of
    their hat matrix, :func:`~lhgraph.estimation.graph.noise.redundancy`; no floor),
    ``"auto"``: resolved (``"redundancy"`` on few-diode data without IMU factors: on the
    simulated decks the floored chi2 prior put the stations 1.9 mm off with NEES 15.5, the
    redundancy 1.0 mm with NEES 3.4)."""

    accel_psd_rot: float = option(10.0, gt=0)
    accel_psd_pos: float = option(1.0, gt=0)
    adapt_motion_prior: bool = option(True)
    max_psd_factor: float = option(10.0, ge=1)
    min_psd_factor: float = option(0.2, gt=0, le=1)
    motion_prior_rounds: int = option(5, ge=0)
    motion_prior_estimate: str = option("auto", choices=PRIOR_ESTIMATES)

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class ImuOptions:
    """The IMU factors (used when an IMU stream is given, :mod:`lhgraph.estimation.imu`).

    ``imu_factors``: ``"combined"`` (GTSAM's preintegrated ``CombinedImuFactor``, its
    readings' noise the stream's own times ``imu_noise_factor``, its biases wandering by
    ``gyro_bias_walk`` (rad/s per root second) and ``accel_bias_walk`` (m/s^2 per root
    second)), ``"twist"`` (a gyro factor per state and an accelerometer factor per step on
    the states' twists, of noise ``gyro_sigma_rad_s`` / ``accel_sigma_mps2``; the factors
    that solve the IMU's calibration and take ``gyro_preintegration``) or ``"auto"``
    (:attr:`factor_kind`); samples count within ``imu_max_gap_s`` of a state.
    ``adapt_accel_sigma``: the accelerometer factors' noise is the stream's own
    (:func:`~lhgraph.estimation.imu.inertial.accel_factor_sigma`) between
    ``min_accel_sigma_mps2`` and ``accel_sigma_mps2``; ``accel_sigma_estimate``:
    ``"redundancy"``: the variance-component updates rescale it over the factors'
    redundancy, ``"stream"``: it stays, ``"auto"``: resolved (``"redundancy"`` on few-diode
    data or with the calibration solved). ``gyro_preintegration``: also a factor per step
    on the rotation the gyro's readings integrate to (off by default: on the real Crazyflie
    log it raised the light's residuals from 70 to 160 urad rms); ``adapt_gyro_sigma``: its
    reading noise rescaled by the updates, never below the stream's own (at least
    ``min_gyro_sigma_rad_s``). ``gyro_scale_sigma`` / ``imu_time_offset_sigma_s`` /
    ``imu_rotation_sigma_rad`` / ``imu_position_sigma_m``: when positive, the IMU's per-axis
    gyro scale error, its time offset to the light (s), its frame's rotation in the board's
    and its position in the board frame (m) are solved with this prior spread (0: not
    estimated)."""

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

    def __post_init__(self) -> None:
        check_fields(self)
        if self.imu_factors == "combined" and (self.imu_position_sigma_m > 0
                                                or self.gyro_preintegration):
            raise InputError("GTSAM's combined IMU factors take no lever arm and have their "
                             "own gyro preintegration: use 'twist' (or 'auto') with "
                             "imu_position_sigma_m or gyro_preintegration", where="imu_factors")

    @property
    def calibrated(self) -> bool:
        """Whether the graph solves an IMU calibration (any of its four sigmas set)."""
        return (self.gyro_scale_sigma > 0 or self.imu_time_offset_sigma_s > 0
                or self.imu_rotation_sigma_rad > 0 or self.imu_position_sigma_m > 0)

    @property
    def factor_kind(self) -> str:
        """``imu_factors`` with ``"auto"`` resolved: ``"twist"`` when the IMU calibration is
        solved or ``gyro_preintegration`` asked (GTSAM's combined factor has neither),
        ``"combined"`` otherwise."""
        if self.imu_factors != "auto":
            return self.imu_factors
        return "twist" if self.calibrated or self.gyro_preintegration else "combined"

    @property
    def calibration_from_light(self) -> bool:
        """Whether the IMU's calibration is found from the light-only solution
        (:mod:`lhgraph.estimation.imu.calibration`): asked for with GTSAM's combined
        factors, which cannot solve it."""
        return self.factor_kind == "combined" and self.calibrated

    def accel_start_sigma(self, imu: ImuStream) -> float:
        """The accelerometer factors' noise (m/s^2) to start from with the stream ``imu``:
        with ``adapt_accel_sigma`` its :func:`~lhgraph.estimation.imu.inertial.
        accel_factor_sigma` clipped to [``min_accel_sigma_mps2``, ``accel_sigma_mps2``] (the
        ceiling wins), else ``accel_sigma_mps2``."""
        if not self.adapt_accel_sigma:
            return self.accel_sigma_mps2
        return float(np.clip(accel_factor_sigma(imu), self.min_accel_sigma_mps2,
                             self.accel_sigma_mps2))


@dataclass(frozen=True)
class BoardOptions:
    """The board's self-calibration (:mod:`lhgraph.estimation.graph.families.corrections`):
    ``diode_bias_sigma_rad``: when positive, every station sees every diode on each axis
    with a constant angle bias of this prior spread; ``sensor_offset_sigma_m``: when
    positive, a correction of every sensor's position is solved with this prior spread;
    ``board_scale_sigma``: when positive, the board's scale (a relative correction of every
    sensor position) is solved with this prior spread: determined by an IMU's metric
    accelerations only (without one the stations' covariance carries the prior's scale
    uncertainty)."""

    diode_bias_sigma_rad: float = option(0.0, ge=0)
    sensor_offset_sigma_m: float = option(0.0, ge=0)
    board_scale_sigma: float = option(0.0, ge=0, lt=0.5)

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class FactoryOptions:
    """The stations' self-calibration (:mod:`lhgraph.estimation.graph.families.factory`):
    ``factory_terms``: the factory terms solved as graph variables, comma-separated names of
    :data:`~lhgraph.model.factory.CALIBRATION_KEYS` and the LH2 ogee terms (``"tilt,gibmag"``;
    each per axis and station; ``""``, the default: none, the decoded values held, for why
    see docs/self_calibration.md); ``factory_sigma_rad``: the spread of their prior, centred
    on each station's decoded (OOTX) value."""

    factory_terms: str = option("")
    factory_sigma_rad: float = option(0.003, gt=0)

    def __post_init__(self) -> None:
        check_fields(self)
        known = CALIBRATION_KEYS + LH2_CALIBRATION_KEYS
        bad = [t for t in self.terms if t not in known]
        if bad or len(set(self.terms)) != len(self.terms):
            raise InputError(f"{self.factory_terms!r}: expected distinct names among "
                             f"{', '.join(known)}, separated by commas", where="factory_terms")

    @property
    def terms(self) -> tuple[str, ...]:
        """The names of ``factory_terms`` (empty: none solved)."""
        return tuple(t.strip() for t in self.factory_terms.split(",") if t.strip())


@dataclass(frozen=True)
class DataOptions:
    """How the capture is read into the graph.

    ``reference``: station index of the world frame (default: the lowest index present);
    ``weak_link_sigma_m``: a station whose position 1-sigma exceeds it is reported as weakly
    linked; ``sweep_times``: ``"auto"`` puts the sweeps of a receiver that logs a station's
    two sweeps together (the Crazyflie deck) at their sweep times
    (:mod:`lhgraph.estimation.sweep_times`), ``"stamped"`` takes every stamp as the hit time;
    ``rest_keep_every``: where the board rests (still for 1 s or more) the calibration keeps
    the hits of one 0.1 s window in this many (1: all; :mod:`lhgraph.estimation.rests`)."""

    reference: int | None = option(None, kind=int, ge=0)
    weak_link_sigma_m: float = option(0.02, gt=0)
    sweep_times: str = option("auto", choices=SWEEP_TIMES)
    rest_keep_every: int = option(1, ge=1)

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class UncertaintyOptions:
    """Which covariance the stations carry (:mod:`lhgraph.estimation.graph.block_covariance`).

    ``covariance``: ``"blocks"`` (the time-block sandwich, never narrower than the white
    one: it covers the residuals' correlation in time, docs/uncertainty.md) or ``"white"``
    (the graph's marginals, which hold for independent residuals only); the white one is
    kept beside it either way. ``covariance_blocks``: the capture is cut into this many
    time blocks, each at least ``min_block_s`` long. ``block_estimator``: ``"jackknife"``
    (each block's score scaled up by its own leverage, the leave-one-block-out estimate's
    change: the plain sandwich reads low by about the share of the information a block
    holds, most where a few blocks hold much of it) or ``"plain"`` (the scores as they are,
    ``C / (C - 1)``). ``factory_information``: also how well
    the capture determines each station's factory terms at the result
    (:mod:`lhgraph.estimation.graph.factory_information`; the result's
    ``factory_information``). ``receiver_scale_sigma``: the receiver's scale uncertainty
    (relative) added to the honest covariance, as a world scaled about the reference station
    (angles cannot see a scale: a receiver a fraction ``k`` larger than its file puts every
    station ``k`` farther out); None: the resolved default, on few-diode data without a
    solved board scale ``FEW_DIODE_SCALE_SIGMA`` of
    :mod:`~lhgraph.estimation.graph.resolve`, else 0 (docs/uncertainty.md)."""

    covariance: str = option("blocks", choices=COVARIANCES)
    covariance_blocks: int = option(30, ge=2, le=10000)
    min_block_s: float = option(0.5, gt=0)
    block_estimator: str = option("jackknife", choices=BLOCK_ESTIMATORS)
    factory_information: bool = option(False)
    receiver_scale_sigma: float | None = option(None, kind=float, ge=0, lt=0.5)

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class GraphOptions:
    """Every option of the graph solver, one group per concern (defaults suit 2 MHz LH1
    captures). Each option's allowed range is declared next to it; a value outside it
    raises :class:`~lhgraph.errors.InputError` naming the option."""

    optimizer: OptimizerOptions = group(OptimizerOptions)
    noise: NoiseOptions = group(NoiseOptions)
    robust: RobustOptions = group(RobustOptions)
    motion: MotionOptions = group(MotionOptions)
    imu: ImuOptions = group(ImuOptions)
    board: BoardOptions = group(BoardOptions)
    factory: FactoryOptions = group(FactoryOptions)
    data: DataOptions = group(DataOptions)
    uncertainty: UncertaintyOptions = group(UncertaintyOptions)

    @classmethod
    def of(cls, **flat: Any) -> GraphOptions:
        """The defaults with the options named (flat, any group) replaced:
        ``GraphOptions.of(max_iterations=30, loss="huber")``."""
        return cls().with_values(**flat)

    def with_values(self, **flat: Any) -> GraphOptions:
        """A copy with the options named (flat, any group) replaced; InputError for a name
        that is no option."""
        by_group: dict[str, dict[str, Any]] = {}
        for name, value in flat.items():
            by_group.setdefault(option_group(name), {})[name] = value
        return dataclasses.replace(self, **{g: dataclasses.replace(getattr(self, g), **values)
                                            for g, values in by_group.items()})

    def nested(self) -> dict[str, dict[str, Any]]:
        """Every option by group, then name (what a run records)."""
        return dataclasses.asdict(self)

    def flat(self) -> dict[str, Any]:
        """Every option by its (flat) name."""
        return {name: value for g in groups(GraphOptions)
                for name, value in dataclasses.asdict(getattr(self, g)).items()}


def option_group(name: str) -> str:
    """The group of :class:`GraphOptions` that holds option ``name`` (InputError if none)."""
    for g, cls in groups(GraphOptions).items():
        if name in {f.name for f in dataclasses.fields(cls)}:
            return g
    raise InputError(f"no graph option '{name}'", where=name)
