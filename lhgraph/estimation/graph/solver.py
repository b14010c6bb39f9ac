"""The factor-graph calibration (``method = "graph"``), on GTSAM: :func:`solve_graph`.

angles prepared and options resolved (:mod:`.resolve`) -> problem
(:mod:`lhgraph.estimation.problem`) -> initial values (an
:class:`lhgraph.estimation.init.Initialiser`) -> graph and optimiser
(:func:`.batch.build_and_optimise`) -> with an IMU the refinement
(:mod:`lhgraph.estimation.imu.refinement`) -> :class:`lhgraph.estimation.result.SolveResult`.
"""

from __future__ import annotations

import functools
import re
import time
from collections.abc import Callable
from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from lhgraph.errors import InputError, SolverError
from lhgraph.estimation.graph.batch import build_and_optimise
from lhgraph.estimation.graph.block_covariance import StationCovariances, station_covariances
from lhgraph.estimation.graph.evaluator import FactorEvaluator
from lhgraph.estimation.graph.optimizer import OptimizerResult
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.graph.resolve import Resolution, prepare, resolve_options
from lhgraph.estimation.graph.variables import BOARD_SCALE
from lhgraph.estimation.imu.refinement import refine_with_imu
from lhgraph.estimation.init import Initialiser
from lhgraph.estimation.init.few_diode import FewDiodeInitialiser
from lhgraph.estimation.init.pnp_kabsch import PnPKabschInitialiser, chain_to_reference
from lhgraph.estimation.problem import GraphProblem, build_problem
from lhgraph.estimation.receiver_scale import RESULT_KEY
from lhgraph.estimation.rests import thin_rests
from lhgraph.estimation.result import Residuals, SolveResult
from lhgraph.estimation.station_prior import StationPriors
from lhgraph.io.angles import Angles
from lhgraph.io.imu import ImuStream
from lhgraph.io.stations import Station, Stations
from lhgraph.io.trajectory import Trajectory
from lhgraph.model.board import Board
from lhgraph.model.station import StationModel

Array = NDArray[np.float64]
Progress = Callable[[str], None]

def solve_graph(board: Board, angles: Angles, models: dict[int, StationModel] | None = None,
                options: GraphOptions | None = None, progress: Progress | None = None,
                initialiser: Initialiser | None = None, imu: ImuStream | None = None,
                prior: StationPriors | None = None) -> SolveResult:
    """Calibrate every station's pose ``T_world_lh`` by the joint factor graph.

    ``angles`` as measured (rad, before factory correction), ``models`` the station models by
    index (factory calibration, rotor offsets). The world frame is the reference station's.
    The sweeps are first prepared and the options resolved for the data
    (:func:`~lhgraph.estimation.graph.resolve.prepare`,
    :func:`~lhgraph.estimation.graph.resolve.resolve_options`: each rule that changes an
    option is a progress line and is kept in the result's ``option_rules``, the options run
    in its ``options``). ``initialiser`` gives the initial values (default:
    :class:`PnPKabschInitialiser`, or :class:`FewDiodeInitialiser` on few-diode data, too few
    diodes per sweep for the default's per-measurement PnP). ``imu``: the receiver's IMU
    stream (board frame, the angles' clock): the light-only solution is refined with IMU
    factors (:func:`~lhgraph.estimation.imu.refinement.refine_with_imu`). With
    ``options.data.rest_keep_every`` > 1 the board's rests are thinned first
    (:func:`~lhgraph.estimation.rests.thin_rests`; the hits left out are counted in
    ``diagnostics["rest_hits_dropped"]``). Angles that join several captures (a
    ``capture`` column, :func:`lhgraph.io.captures.join_captures`) get one board trajectory
    per capture. ``prior``: an earlier result in this solve's world
    (:func:`lhgraph.estimation.station_prior.station_priors`), a prior factor on each
    station it holds; a station only the prior holds is the prior's in the result.
    """
    options = options or GraphOptions()
    models = models or {}
    stations = angles.stations()
    reference = options.data.reference if options.data.reference is not None else stations[0]
    if reference not in stations:
        raise SolverError(f"reference station {reference} has no hits")
    if len(stations) < 2:
        raise SolverError(f"only station(s) {stations} seen: need at least two")
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    rests = None
    if options.data.rest_keep_every > 1:
        angles, rests = thin_rests(angles, options.data.rest_keep_every)
        if progress and rests.hits_dropped:
            progress(rests.summary())
    angles, facts = prepare(angles, options, models, progress)
    if imu is None and options.board.board_scale_sigma > 0:
        raise InputError("the board's scale needs an IMU stream (--imu): angles alone "
                         "cannot tell a larger board in a larger room", where="board_scale_sigma")
    if imu is not None and facts.few_diode and options.imu.calibration_from_light:
        raise SolverError("the IMU's calibration for the combined IMU factors comes from the "
                          "light's rotations, which a few-diode receiver's sweeps determine "
                          "too weakly (the real Crazyflie log: gyro scales 0.50 / 0.82 / 0.65,"
                          " the frame 16 deg off): use imu_factors = 'twist' or 'auto'")
    resolution = resolve_options(options, facts)
    say_resolution(resolution, progress)
    problem = build_problem(board, angles, models, reference)
    if prior is not None:
        if prior.reference != reference:
            raise SolverError(f"the prior is in station {prior.reference}'s frame, the solve "
                              f"in station {reference}'s")
        problem = replace(problem, station_priors={
            slot: prior.priors[sid] for slot, sid in enumerate(problem.station_ids)
            if sid in prior.priors})
    if initialiser is None:
        initialiser = (FewDiodeInitialiser() if facts.few_diode
                       else PnPKabschInitialiser(imu=imu))
    init = initialiser(board, angles, problem)
    timings["initialise"] = time.perf_counter() - t0
    if progress:
        progress(f"initialised {problem.n_states} board states, {len(problem.hits.angle)} hits")
    t1 = time.perf_counter()
    # with an IMU the refinement's covariances are the result's: the light's white ones will do
    uncertainty = (resolution.options.uncertainty if imu is None else
                   replace(resolution.options.uncertainty, covariance="white"))
    fit, ev, cov = build_and_optimise(
        problem, resolution.options, init,
        functools.partial(station_covariances, options=uncertainty), progress)
    notes: list[str] = []
    extra = {} if rests is None else {"rest_hits_dropped": float(rests.hits_dropped)}
    if imu is not None:
        resolution = resolve_options(options, facts, inertial=True)
        refined = refine_with_imu(problem, resolution, options.imu.imu_factors == "auto", imu,
                                  fit, ev, progress)
        fit, ev, cov = refined.fit, refined.ev, refined.covariances
        resolution = refined.resolution
        notes += refined.notes
        extra |= refined.diagnostics
    timings["optimise"] = time.perf_counter() - t1
    ev.evaluate(fit.values)
    k, k_sigma = ev.corrections.scale(), options.board.board_scale_sigma
    if ev.corrections.scaled and abs(k) > SCALE_WARN * k_sigma:
        notes.append(f"the board's scale moved by {k * 100:+.2f} % ({abs(k) / k_sigma:.1f} "
                     "times its prior spread): the IMU and the light disagree on the metric "
                     "size; the stations' distances follow the IMU")
    result = _result(angles, problem, ev, fit, cov, resolution, timings, t0, init.parents,
                     extra, notes)
    return with_prior_only(result, prior, models) if prior is not None else result


SCALE_WARN = 3.0
"""A solved board scale further than this many prior spreads from the board file's is a
warning (the real Crazyflie logs: -3 to -8 % against the mocap's +0.04 to +0.9 %)."""
PRIOR_CHI2_WARN = 22.46
"""A station's prior chi2 (6 dof, in the prior's honest covariance) above this (the 99.9 %
point) is a warning: the capture puts it where the earlier result says it is not."""


def with_prior_only(result: SolveResult, prior: StationPriors,
                    models: dict[int, StationModel]) -> SolveResult:
    """``result`` with the stations only the prior holds (its pose and covariance), a line
    per prior station and a warning for each the capture disagrees with."""
    reference = result.stations.reference
    slots = [reference] + [k for k in sorted(result.stations.stations) if k != reference]
    stations = dict(result.stations.stations)
    lines, warnings = [], list(result.warnings) + list(prior.notes)
    for sid in sorted(prior.priors):
        T, white, honest = prior.priors[sid]
        if sid not in stations:
            stations[sid] = Station(T.copy(), honest.copy(), models.get(sid, StationModel()),
                                    white.copy())
            lines.append(f"prior: station {sid} not seen by this capture: the prior's pose "
                         "and covariance")
            continue
        chi2 = result.diagnostics.get(f"station_prior_chi2_{slots.index(sid)}", float("nan"))
        lines.append(f"prior: station {sid} refined by this capture (its prior's chi2 "
                     f"{chi2:.1f}, 6 dof)")
        if chi2 > PRIOR_CHI2_WARN:
            warnings.append(f"station {sid} lies {np.sqrt(chi2):.1f} sigma from the prior "
                            f"(chi2 {chi2:.1f} for 6 dof): moved since it was calibrated?")
    return replace(result, stations=replace(result.stations, stations=stations),
                   warnings=warnings, captures=list(result.captures) + lines)


def say_resolution(resolution: Resolution, progress: Progress | None) -> None:
    """One progress line per rule that overrode an option for the data (the LH2 and
    few-diode rules); the choices left to the solve (``auto``, unset) are only recorded
    (the result's ``option_rules``)."""
    if progress:
        for line in resolution.applied:
            if not re.search(r"\((auto|unset)\b", line):
                progress(f"option {line}")


def _result(angles: Angles, problem: GraphProblem, ev: FactorEvaluator, fit: OptimizerResult,
            cov: StationCovariances, resolution: Resolution, timings: dict[str, float], t0: float,
            parents: list[int] | None = None, diagnostics: dict[str, float] | None = None,
            notes: list[str] | None = None) -> SolveResult:
    """The :class:`SolveResult` of a finished solve, ``ev`` evaluated at the result;
    ``parents``: the slot each station's initial pose was joined to (the initialiser's
    overlap tree), for the weak-link warning; ``diagnostics``: figures of the solve's own
    stages, added to the evaluator's; ``notes``: warnings of the solve's own stages."""
    options = resolution.options
    scale = options.uncertainty.receiver_scale_sigma or 0.0
    reference = problem.station_ids[0]
    poses = ev.station_poses()
    models = ev.factory.models()
    out: dict[int, Station] = {reference: Station(np.eye(4), np.zeros((6, 6)),
                                                  models[0], np.zeros((6, 6)))}
    warnings = list(notes or [])
    for slot in range(1, len(problem.station_ids)):
        sid = problem.station_ids[slot]
        out[sid] = Station(poses[slot].copy(), cov.honest[slot], models[slot],
                           cov.white[slot])
        sigma_m = float(np.sqrt(np.max(np.linalg.eigvalsh(cov.white[slot][3:, 3:]))))
        if sigma_m > options.data.weak_link_sigma_m:
            chain = chain_to_reference(slot, parents or [])
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
        stations=Stations(reference, out, {RESULT_KEY: scale} if scale > 0 else {}),
        trajectory=Trajectory(problem.state_time, ev.board_poses().copy()),
        residuals=residuals,
        status=fit.status.value,
        iterations=fit.iterations,
        final_error=float(fit.final_error),
        timings_s=timings,
        warnings=warnings,
        error_history=fit.error_history,
        diagnostics=ev.summary() | cov.summary() | (diagnostics or {}),
        gravity_world=ev.gravity(),
        diode_bias_rad=({sid: b.reshape(2, -1).copy() for sid, b in zip(
                            problem.station_ids, ev.corrections.diode_biases(), strict=True)}
                        if options.board.diode_bias_sigma_rad > 0 else None),
        sensor_offset_m=(ev.corrections.sensor_offsets().copy()
                         if options.board.sensor_offset_sigma_m > 0 else None),
        options=options.nested(),
        factory_terms=factory_estimates(problem, ev, cov),
        board_scale=board_scale(ev, cov),
        factory_information=None if cov.factory is None else cov.factory.as_dict(),
        option_rules=list(resolution.applied),
    )


def factory_estimates(problem: GraphProblem, ev: FactorEvaluator, cov: StationCovariances
                      ) -> dict[int, dict[str, dict[str, list[float]]]] | None:
    """The solved factory terms by station index (:attr:`SolveResult.factory_terms`; None
    when the graph solves none)."""
    keys = ev.factory.keys_solved
    if not keys or cov.calibration_white is None:
        return None
    out: dict[int, dict[str, dict[str, list[float]]]] = {}
    D = ev.factory.corrections()
    for slot, sid in enumerate(problem.station_ids):
        key = ev.factory.family.key(slot)
        white = np.sqrt(np.diag(cov.calibration_white[key])).reshape(-1, 2)
        honest = np.sqrt(np.diag(cov.calibration_honest[key])).reshape(-1, 2)
        shift = D[slot].reshape(-1, 2)
        cal = problem.models[slot].calibration
        out[int(sid)] = {term: {
            "decoded_rad": getattr(cal, term).tolist(),
            "solved_rad": (getattr(cal, term) + shift[i]).tolist(),
            "shift_rad": shift[i].tolist(),
            "sigma_rad": honest[i].tolist(), "sigma_white_rad": white[i].tolist()}
            for i, term in enumerate(keys)}
    return out


def board_scale(ev: FactorEvaluator, cov: StationCovariances) -> dict[str, float] | None:
    """The solved board scale (:attr:`SolveResult.board_scale`; None when the graph has
    none)."""
    if not ev.corrections.scaled or cov.calibration_white is None:
        return None
    key = BOARD_SCALE.key(0)
    return {"correction": ev.corrections.scale(),
            "sigma": float(np.sqrt(cov.calibration_honest[key][0, 0])),
            "sigma_white": float(np.sqrt(cov.calibration_white[key][0, 0]))}
