"""The factor-graph calibration (``method = "graph"``), on GTSAM: :func:`solve_graph`.

problem (:mod:`lhgraph.estimation.problem`) -> initial values (an
:class:`lhgraph.estimation.init.Initialiser`) -> graph (:mod:`.factors`, variables as in
:mod:`.variables`) -> optimiser (:mod:`.optimizer`, noise adaptation :mod:`.noise`) ->
:class:`lhgraph.estimation.result.SolveResult`.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace

import gtsam
import numpy as np
from numpy.typing import NDArray

from lhgraph.errors import SolverError
from lhgraph.estimation.graph.batch import Watch, build_and_optimise, station_covariances
from lhgraph.estimation.graph.evaluator import FactorEvaluator
from lhgraph.estimation.graph.optimizer import (
    OptimizerResult,
)
from lhgraph.estimation.graph.options import FEW_DIODE_CALIBRATION, FewDiodeStop, GraphOptions
from lhgraph.estimation.imu.calibration import fit_imu_calibration
from lhgraph.estimation.imu.inertial import inertial_data, initial_gravity
from lhgraph.estimation.init import Initialiser
from lhgraph.estimation.init.few_diode import FewDiodeInitialiser
from lhgraph.estimation.init.pnp_kabsch import Initialisation, PnPKabschInitialiser
from lhgraph.estimation.problem import GraphProblem, build_problem
from lhgraph.estimation.rests import thin_rests
from lhgraph.estimation.result import Residuals, SolveResult
from lhgraph.estimation.sweep_times import co_logged_stations, plane_cycles, retime_cycles
from lhgraph.io.angles import Angles
from lhgraph.io.imu import ImuStream
from lhgraph.io.stations import Station, Stations
from lhgraph.io.trajectory import Trajectory
from lhgraph.model.board import Board
from lhgraph.model.station import StationModel

Array = NDArray[np.float64]
Progress = Callable[[str], None]
FEW_DIODES = 5
"""The default initialiser's PnP needs this many diodes with both angles per measurement."""
IMU_DISAGREEMENT = 1.5
"""The IMU refinement warns when it raises the light's median absolute residual by more than
this factor, and with ``imu_factors = "auto"`` replaces GTSAM's combined factors that do
so by the twist factors (on the hive recording with its gyro taken as read, 0.48x the true
rate: 47 -> 527 urad; a simulated gyro reading 0.5x: 1.28x; consistent simulated IMUs
1.02-1.10x)."""


DISAGREEMENT_STEPS = 2
"""From this accepted LM step on, combined IMU factors that have raised the light's median
residual past ``IMU_DISAGREEMENT`` times end their optimisation (with ``imu_factors =
"auto"``): on the real Crazyflie LH1 log the first step took it from 37 to 208 urad and it
never came back under 257; on the simulated decks the first steps stay at 1.2-1.3x."""
IMU_FACTOR_NAMES = {"combined": "GTSAM's combined IMU factors",
                    "twist": "gyro and accelerometer factors on the twists"}


def solve_graph(board: Board, angles: Angles, models: dict[int, StationModel] | None = None,
                options: GraphOptions | None = None, progress: Progress | None = None,
                initialiser: Initialiser | None = None, imu: ImuStream | None = None
                ) -> SolveResult:
    """Calibrate every station's pose ``T_world_lh`` by the joint factor graph.

    ``angles`` as measured (rad, before factory correction), ``models`` the station models by
    index (factory calibration, rotor offsets). The world frame is the reference station's.
    ``initialiser`` gives the initial values (default: :class:`PnPKabschInitialiser`, or
    :class:`FewDiodeInitialiser` when the sweeps hold fewer than ``FEW_DIODES`` hits in the
    median, too few for the default's per-measurement PnP). The sweeps of few-diode data, or
    of a receiver that logs a station's two sweeps together, are first put on each station's
    rotor grid, one board state per rotor cycle (``options.sweep_times``,
    :func:`retime_cycles`). ``imu``: the receiver's IMU stream (board frame, the angles'
    clock): the light-only solution is refined by a second optimisation with IMU factors
    (``options.imu_factor_kind``: GTSAM's combined factors,
    :mod:`lhgraph.estimation.imu.combined`, or the twist factors,
    :mod:`lhgraph.estimation.imu.inertial`), the IMU biases and the world's gravity estimated
    with the stations; with ``imu_factors = "auto"``, combined factors that raise the light's
    median angle residual more than ``IMU_DISAGREEMENT`` times (the real Crazyflie LH1 log:
    37 -> 257 urad, its deck's accelerometer misfits ~10x its readings' noise) are replaced
    by the twist factors, whose noise follows the misfit (a warning says so). Started from
    the initialiser instead, the IMU
    factors hold states in their mirror poses: on the Crazyflie log that solve did not
    converge in 60 iterations). With ``options.rest_keep_every`` > 1 the board's rests are
    thinned first (:func:`~lhgraph.estimation.rests.thin_rests`; the hits left out are
    counted in ``diagnostics["rest_hits_dropped"]``).
    """
    options = options or GraphOptions()
    models = models or {}
    stations = angles.stations()
    reference = options.reference if options.reference is not None else stations[0]
    if reference not in stations:
        raise SolverError(f"reference station {reference} has no hits")
    if len(stations) < 2:
        raise SolverError(f"only station(s) {stations} seen: need at least two")
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    rests = None
    if options.rest_keep_every > 1:
        angles, rests = thin_rests(angles, options.rest_keep_every)
        if progress and rests.hits_dropped:
            progress(rests.summary())
    angles, options, few = graph_preparation(angles, options, progress, models)
    if imu is not None and few and options.imu_calibration_from_light:
        raise SolverError("the IMU's calibration for the combined IMU factors comes from the "
                          "light's rotations, which a few-diode receiver's sweeps determine "
                          "too weakly (the real Crazyflie log: gyro scales 0.50 / 0.82 / 0.65,"
                          " the frame 16 deg off): use imu_factors = 'twist' or 'auto'")
    problem = build_problem(board, angles, models, reference)
    if initialiser is None:
        initialiser = FewDiodeInitialiser() if few else PnPKabschInitialiser(imu=imu)
    init = initialiser(board, angles, problem)
    timings["initialise"] = time.perf_counter() - t0
    if progress:
        progress(f"initialised {problem.n_states} board states, {len(problem.hits.angle)} hits")
    t1 = time.perf_counter()
    fit, ev, cov = build_and_optimise(problem, resolve_estimates(options, few, False), init,
                                      station_covariances, progress)
    notes = []
    extra = {} if rests is None else {"rest_hits_dropped": float(rests.hits_dropped)}
    if imu is not None:
        options = resolve_estimates(options, few, True)
        refined = Initialisation(ev.station_poses().copy(), ev.board_poses().copy(),
                                 ev.board_twists().copy())
        light, light_ev = fit, ev
        light_median = _median_residual(ev, light.values)
        kind = options.imu_factor_kind
        if options.imu_calibration_from_light:
            calibration = fit_imu_calibration(
                imu, problem.state_time, refined.X, scale=options.gyro_scale_sigma > 0,
                offset=options.imu_time_offset_sigma_s > 0,
                rotation=options.imu_rotation_sigma_rad > 0)
            imu = calibration.apply(imu)
            found = calibration.summary()
            extra |= found
            if progress:
                progress("the IMU's calibration from the light's rotations: "
                         + ", ".join(f"{k} {v:.4g}" for k, v in found.items()))
        inertial = inertial_data(imu, problem.state_time, options.imu_max_gap_s)
        gravity = initial_gravity(inertial, refined.X)
        if progress:
            progress(f"refining with the IMU: {IMU_FACTOR_NAMES[kind]}")
        limit = IMU_DISAGREEMENT * light_median
        watch = (Disagreement.watch(limit)
                 if kind == "combined" and options.imu_factors == "auto" else None)
        try:
            fit, ev, cov = build_and_optimise(
                problem, options, refined, station_covariances, progress, inertial=inertial,
                gravity=gravity, levels=light_ev, watch=watch)
            imu_median, spent = _median_residual(ev, fit.values), fit.iterations
        except Disagreement as stop:
            imu_median, spent = stop.median_rad, stop.steps
        if watch is not None and imu_median > limit:
            notes.append(f"GTSAM's combined IMU factors disagree with the light (they raised "
                         f"the median angle residual from {light_median * 1e6:.0f} to "
                         f"{imu_median * 1e6:.0f} urad in {spent} LM steps): refined with the "
                         "twist factors instead, whose noise is the stream's misfit, not its "
                         "readings'")
            if progress:
                progress(notes[-1])
            options = replace(options, imu_factors="twist")
            light = replace(light, iterations=light.iterations + spent)
            fit, ev, cov = build_and_optimise(
                problem, options, refined, station_covariances, progress, inertial=inertial,
                gravity=gravity, levels=light_ev)
            imu_median = _median_residual(ev, fit.values)
        if imu_median > limit:
            notes.append(f"the IMU disagrees with the light: its factors raised the median "
                         f"angle residual from {light_median * 1e6:.0f} to "
                         f"{imu_median * 1e6:.0f} urad (a gyro scale error or time offset? "
                         "solve them with gyro_scale_sigma / imu_time_offset_sigma_s; or "
                         "the IMU's frame is not the board's)")
        fit = replace(fit, iterations=light.iterations + fit.iterations,
                      error_history=light.error_history + fit.error_history)
    timings["optimise"] = time.perf_counter() - t1
    ev.evaluate(fit.values)
    return _result(angles, problem, ev, fit, cov, options, timings, t0, init.parents, extra,
                   notes)


class Disagreement(Exception):
    """Raised by :meth:`watch`'s check when IMU factors have raised the light's median
    angle residual to ``median_rad`` after ``steps`` accepted LM steps."""

    def __init__(self, median_rad: float, steps: int):
        super().__init__(f"median angle residual {median_rad * 1e6:.0f} urad")
        self.median_rad, self.steps = median_rad, steps

    @staticmethod
    def watch(limit_rad: float, after_steps: int = DISAGREEMENT_STEPS
              ) -> Watch:
        """A check, after every accepted LM step, that raises :class:`Disagreement` from the
        ``after_steps``-th on when the evaluator's median angle residual exceeds
        ``limit_rad``."""
        steps = 0

        def check(ev: FactorEvaluator, values: gtsam.Values) -> None:
            nonlocal steps
            steps += 1
            if steps >= after_steps and (median := _median_residual(ev, values)) > limit_rad:
                raise Disagreement(median, steps)

        return check


def graph_preparation(angles: Angles, options: GraphOptions,
                          progress: Progress | None = None,
                          models: dict[int, StationModel] | None = None,
                          stop: FewDiodeStop = FEW_DIODE_CALIBRATION
                          ) -> tuple[Angles, GraphOptions, bool]:
    """``angles``, ``options`` and whether the data is few-diode, made ready for the graph
    by the stations' generation (``models``) and the receiver's diodes:

    - LH1 sweeps of few-diode data, or of a receiver that logs a station's two sweeps
      together, on each station's rotor grid with one board state per rotor cycle
      (``options.sweep_times``, :func:`retime_cycles`);
    - LH2 few-diode data, whose hit times the importer derives from the planes' rotor
      angles: both planes of a turn share a state (:func:`plane_cycles`);
    - every station LH2: the angle-noise floor ``options.lh2_angle_sigma_rad``;
    - few-diode data: the angle-noise floor ``few_diode_sigma_rad`` and, unless set, the
      stopping rule's board-step quantile and station tolerance of ``stop`` (the
      calibration's ``FEW_DIODE_CALIBRATION``; tracking passes ``FEW_DIODE_TRACKING``).

    Shared by the calibration and by tracking."""
    few = few_diode(angles)
    logged = co_logged_stations(angles)
    lh2 = any(m.generation == 2 for m in (models or {}).values())
    if lh2 and all(s in models and models[s].generation == 2 for s in angles.stations()):
        options = replace(options, angle_sigma_rad=options.lh2_angle_sigma_rad)
    if options.sweep_times == "auto" and few and lh2:
        angles = plane_cycles(angles)
        if progress:
            progress("both light planes of a rotor turn share one board state")
    elif options.sweep_times == "auto" and (few or logged) and not lh2:
        angles = retime_cycles(angles, logged)
        if progress:
            progress("sweeps put on each station's rotor grid, one board state per cycle")
    if few:
        options = replace(
            options,
            angle_sigma_rad=max(options.angle_sigma_rad, options.few_diode_sigma_rad),
            board_step_quantile=options.board_step_quantile or stop.board_step_quantile,
            step_tolerance_sigma=(stop.step_tolerance_sigma
                                  if options.step_tolerance_sigma is None
                                  else options.step_tolerance_sigma))
    return angles, options, few


def resolve_estimates(options: GraphOptions, few: bool, inertial: bool) -> GraphOptions:
    """``options`` with its ``"auto"`` estimates resolved: ``motion_prior_estimate``
    ``"redundancy"`` on few-diode data (``few``) without IMU factors, else ``"chi2"`` (with
    the IMU factors of a simulated deck the floored estimate put station 1 1.06 mm off, the
    redundancy 1.32 mm); ``accel_sigma_estimate`` ``"redundancy"`` on few-diode data or with
    the IMU calibration solved, else ``"stream"``."""
    motion = options.motion_prior_estimate
    if motion == "auto":
        motion = "redundancy" if few and not inertial else "chi2"
    accel = options.accel_sigma_estimate
    if accel == "auto":
        accel = "redundancy" if few or options.imu_calibrated else "stream"
    return replace(options, motion_prior_estimate=motion, accel_sigma_estimate=accel)


def _median_residual(ev: FactorEvaluator, values: gtsam.Values) -> float:
    """Median absolute angle residual (rad) of ``ev``'s hits at ``values``."""
    ev.evaluate(values)
    return float(np.median(np.abs(ev.bearing.residuals())))


def _chain(slot: int, parents: list[int]) -> list[int]:
    """Slots from ``slot`` to the reference (slot 0) along ``parents`` (``[slot, 0]`` when
    the parents are not known)."""
    chain = [slot]
    while chain[-1] != 0 and len(chain) <= len(parents):
        chain.append(parents[chain[-1]] if chain[-1] < len(parents) else 0)
    return chain if chain[-1] == 0 else [slot, 0]


def few_diode(angles: Angles) -> bool:
    """Whether the median sweep of ``angles`` holds fewer than ``FEW_DIODES`` hits."""
    return bool(np.median(np.bincount(angles.sweep_ids())) < FEW_DIODES)


def _result(angles: Angles, problem: GraphProblem, ev: FactorEvaluator, fit: OptimizerResult,
            cov: dict[int, Array], options: GraphOptions, timings: dict[str, float], t0: float,
            parents: list[int] | None = None, diagnostics: dict[str, float] | None = None,
            notes: list[str] | None = None) -> SolveResult:
    """The :class:`SolveResult` of a finished solve, ``ev`` evaluated at the result;
    ``parents``: the slot each station's initial pose was joined to (the initialiser's
    overlap tree), for the weak-link warning; ``diagnostics``: figures of the solve's own
    stages, added to the evaluator's; ``notes``: warnings of the solve's own stages."""
    reference = problem.station_ids[0]
    poses = ev.station_poses()
    out: dict[int, Station] = {reference: Station(np.eye(4), np.zeros((6, 6)),
                                                  problem.models[0])}
    warnings = list(notes or [])
    for slot in range(1, len(problem.station_ids)):
        sid = problem.station_ids[slot]
        out[sid] = Station(poses[slot].copy(), cov[slot], problem.models[slot])
        sigma_m = float(np.sqrt(np.max(np.linalg.eigvalsh(cov[slot][3:, 3:]))))
        if sigma_m > options.weak_link_sigma_m:
            chain = _chain(slot, parents or [])
            via = (" by both" if len(chain) <= 2 else " by two neighbours of the chain "
                   + " - ".join(str(problem.station_ids[c]) for c in chain))
            warnings.append(f"station {sid}: weak link to the reference (position sigma "
                            f"{sigma_m * 1e3:.0f} mm); the board was rarely seen{via}")
    h = problem.hits
    rows = problem.hit_rows
    residuals = Residuals(angles.time[rows], angles.lighthouse[rows], h.axis,
                          angles.sensor[rows], -ev.bearing.residuals(), ev.bearing.robust_weights())
    timings["total"] = time.perf_counter() - t0
    return SolveResult(
        method="graph",
        stations=Stations(reference, out),
        trajectory=Trajectory(problem.state_time, ev.board_poses().copy()),
        residuals=residuals,
        status=fit.status.value,
        iterations=fit.iterations,
        final_error=float(fit.final_error),
        timings_s=timings,
        warnings=warnings,
        error_history=fit.error_history,
        diagnostics=ev.summary() | (diagnostics or {}),
        gravity_world=ev.gravity(),
        diode_bias_rad=({sid: b.reshape(2, -1).copy() for sid, b in zip(
                            problem.station_ids, ev.corrections.diode_biases(), strict=True)}
                        if options.diode_bias_sigma_rad > 0 else None),
        sensor_offset_m=(ev.corrections.sensor_offsets().copy()
                         if options.sensor_offset_sigma_m > 0 else None),
    )
