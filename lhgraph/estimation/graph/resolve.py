"""The options a solve runs with, decided once and in the open: :func:`resolve_options`.

The user's :class:`~lhgraph.estimation.graph.options.GraphOptions` leave some choices to the
data (``"auto"``, None). :func:`prepare` reads what decides them off the capture
(:class:`DataFacts`: few-diode data, every station LH2) and puts the sweeps where the graph
wants them; :func:`resolve_options` then applies every rule below to the options, in this
order, and says which changed what (:attr:`Resolution.applied`, printed by the solve and
kept in its result and ``summary.json``):

1. every station LH2: the angle-noise floor is ``lh2_angle_sigma_rad``;
2. few-diode data: the angle-noise floor is at least ``few_diode_sigma_rad``, and the
   stopping rule's unset board-step quantile and station tolerance are those of
   ``FEW_DIODE_CALIBRATION`` (``FEW_DIODE_TRACKING`` when tracking);
3. the stopping rule's still unset station tolerance is ``STEP_TOLERANCE_SIGMA`` and its
   board-step quantile 1 (every state);
4. ``motion_prior_estimate = "auto"``: ``"redundancy"`` on few-diode data without IMU
   factors, ``"chi2"`` otherwise;
5. ``accel_sigma_estimate = "auto"``: ``"redundancy"`` on few-diode data or with the IMU
   calibration solved, ``"stream"`` otherwise;
6. ``imu_factors = "auto"`` (with IMU factors): ``"twist"`` when the IMU calibration is
   solved or the gyro preintegrated, ``"combined"`` otherwise;
7. ``reference`` unset: the lowest station index seen;
8. ``board_scale_sigma`` > 0 in a calibration without IMU factors (the light-only stage
   before the IMU refinement): 0. Angles cannot see the board's scale, and a free scale
   shrinks under the motion prior (smaller accelerations cost less: on a simulated deck
   capture it ran to -73 %); the IMU stage solves it;
9. ``receiver_scale_sigma`` unset: ``FEW_DIODE_SCALE_SIGMA`` on few-diode data whose board
   scale is not solved (``board_scale_sigma`` 0), else 0. A few-diode deck's size sets the
   scale of everything solved from it, and on the shared Crazyflie logs the mocap puts our
   station 1 0.38-0.84 % too close (benchmarks/anchored_stations.py, docs/uncertainty.md).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.sweep_times import co_logged_stations, plane_cycles, retime_cycles
from lhgraph.io.angles import Angles
from lhgraph.model.station import StationModel

Progress = Callable[[str], None]
FEW_DIODES = 5
"""The default initialiser's PnP needs this many diodes with both angles per measurement:
data whose median sweep holds fewer is few-diode."""
STEP_TOLERANCE_SIGMA = 0.05
"""The stations' test of the stopping rule where the options leave it unset: LM stops when
they are estimated within this many standard deviations of convergence."""
FEW_DIODE_SCALE_SIGMA = 0.006
"""The receiver-scale uncertainty (relative) of few-diode data: the rms of station 1's
shortfall along the baseline against the mocap-anchored stations on the four shared
Crazyflie logs (0.68, 0.84, 0.38, 0.40 %; docs/results/anchored_stations.md)."""


@dataclass(frozen=True)
class FewDiodeStop:
    """The stopping rule on few-diode data where the user's options leave it unset:
    ``board_step_quantile`` and ``step_tolerance_sigma`` of the optimizer options."""

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
(``python -m benchmarks deck_benchmark``). The test applies to every root variable of the
graph: with the IMU also its biases, gravity and calibration."""
FEW_DIODE_TRACKING = FewDiodeStop(board_step_quantile=0.95,
                                  step_tolerance_sigma=STEP_TOLERANCE_SIGMA)
"""Tracking few-diode data: the path is the product (states seen by one station only can sit
in a mirror pose that turns for dozens of iterations)."""


@dataclass(frozen=True)
class DataFacts:
    """What of a capture decides the options: ``few_diode`` (the median sweep holds fewer
    than ``FEW_DIODES`` hits), ``all_lh2`` (every station seen is LH2), ``first_station``
    (the lowest index seen)."""

    few_diode: bool
    all_lh2: bool
    first_station: int


@dataclass(frozen=True)
class Resolution:
    """Resolved ``options`` and one line per rule that changed them (``applied``)."""

    options: GraphOptions
    applied: tuple[str, ...]


def few_diode(angles: Angles) -> bool:
    """Whether the median sweep of ``angles`` holds fewer than ``FEW_DIODES`` hits."""
    return bool(np.median(np.bincount(angles.sweep_ids())) < FEW_DIODES)


def prepare(angles: Angles, options: GraphOptions,
            models: dict[int, StationModel] | None = None, progress: Progress | None = None
            ) -> tuple[Angles, DataFacts]:
    """``angles`` made ready for the graph and the facts that decide the options:

    - LH1 sweeps of few-diode data, or of a receiver that logs a station's two sweeps
      together, on each station's rotor grid with one board state per rotor cycle
      (``sweep_times = "auto"``, :func:`retime_cycles`);
    - LH2 few-diode data, whose hit times the importer derives from the planes' rotor
      angles: both planes of a turn share a state (:func:`plane_cycles`).

    Shared by the calibration and by tracking."""
    models = models or {}
    few = few_diode(angles)
    logged = co_logged_stations(angles)
    lh2 = any(m.generation == 2 for m in models.values())
    all_lh2 = lh2 and all(s in models and models[s].generation == 2
                          for s in angles.stations())
    facts = DataFacts(few, all_lh2, angles.stations()[0])
    if options.data.sweep_times == "auto" and few and lh2:
        angles = plane_cycles(angles)
        if progress:
            progress("both light planes of a rotor turn share one board state")
    elif options.data.sweep_times == "auto" and (few or logged) and not lh2:
        angles = retime_cycles(angles, logged)
        if progress:
            progress("sweeps put on each station's rotor grid, one board state per cycle")
    return angles, facts


def resolve_options(options: GraphOptions, facts: DataFacts, inertial: bool = False,
                    tracking: bool = False) -> Resolution:
    """``options`` with every rule of the module docstring applied for data of ``facts``
    (``inertial``: the graph has IMU factors; ``tracking``: the stations are held)."""
    applied: list[str] = []
    flat = options.flat()
    new: dict[str, object] = {}

    def set_to(name: str, value: object, why: str) -> None:
        if flat[name] != value:
            applied.append(f"{name} = {value!r} ({why}; given {flat[name]!r})")
            new[name] = flat[name] = value

    if facts.all_lh2:
        set_to("angle_sigma_rad", flat["lh2_angle_sigma_rad"],
               "every station LH2: lh2_angle_sigma_rad")
    if facts.few_diode:
        stop = FEW_DIODE_TRACKING if tracking else FEW_DIODE_CALIBRATION
        set_to("angle_sigma_rad", max(flat["angle_sigma_rad"], flat["few_diode_sigma_rad"]),
               "few-diode data: at least few_diode_sigma_rad")
        if flat["board_step_quantile"] is None:
            set_to("board_step_quantile", stop.board_step_quantile, "few-diode data")
        if flat["step_tolerance_sigma"] is None:
            set_to("step_tolerance_sigma", stop.step_tolerance_sigma, "few-diode data")
    if flat["step_tolerance_sigma"] is None:
        set_to("step_tolerance_sigma", STEP_TOLERANCE_SIGMA, "unset: the default")
    if flat["board_step_quantile"] is None:
        set_to("board_step_quantile", 1.0, "unset: every state")
    if flat["motion_prior_estimate"] == "auto":
        set_to("motion_prior_estimate",
               "redundancy" if facts.few_diode and not inertial else "chi2",
               "auto: few-diode data without IMU factors" if facts.few_diode and not inertial
               else "auto")
    if flat["accel_sigma_estimate"] == "auto":
        calibrated = options.imu.calibrated
        set_to("accel_sigma_estimate",
               "redundancy" if facts.few_diode or calibrated else "stream",
               "auto: few-diode data or the IMU calibration solved"
               if facts.few_diode or calibrated else "auto")
    if inertial and flat["imu_factors"] == "auto":
        set_to("imu_factors", options.imu.factor_kind, "auto")
    if flat["reference"] is None:
        set_to("reference", facts.first_station, "unset: the lowest station index seen")
    if flat["board_scale_sigma"] > 0 and not inertial and not tracking:
        set_to("board_scale_sigma", 0.0, "light-only stage: the IMU refinement solves the "
               "board's scale")
    if flat["receiver_scale_sigma"] is None:
        solved = flat["board_scale_sigma"] > 0
        set_to("receiver_scale_sigma",
               FEW_DIODE_SCALE_SIGMA if facts.few_diode and not solved else 0.0,
               "unset: few-diode data, the board's scale not solved" if facts.few_diode
               and not solved else "unset: the board's scale solved" if solved
               else "unset: a receiver of many diodes")
    return Resolution(options.with_values(**new) if new else options, tuple(applied))

