"""The calibration's second stage with an IMU: :func:`refine_with_imu`.

The light-only solution is refined by a second optimisation with IMU factors (the options'
``imu.factor_kind``: GTSAM's combined factors, :mod:`lhgraph.estimation.imu.combined`, or the
twist factors, :mod:`lhgraph.estimation.imu.inertial`), the IMU biases and the world's
gravity estimated with the stations, on the same build-and-optimise path
(:func:`~lhgraph.estimation.graph.batch.build_and_optimise`). With ``imu_factors = "auto"``,
combined factors that raise the light's median angle residual more than
``IMU_DISAGREEMENT`` times are replaced by the twist factors, whose noise follows the misfit
(a warning says so); with the board's scale solved (``board_scale_sigma``) they are judged
at their end, not after their first steps (the light's solution they start from has the
board file's scale, which they first correct). Started from the initialiser instead of the
light's solution, the IMU factors hold states in their mirror poses: on the real Crazyflie
log that solve did not converge in 60 iterations.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass, replace

import gtsam
import numpy as np
from numpy.typing import NDArray

from lhgraph.estimation.graph.batch import Watch, build_and_optimise
from lhgraph.estimation.graph.block_covariance import StationCovariances, station_covariances
from lhgraph.estimation.graph.evaluator import FactorEvaluator
from lhgraph.estimation.graph.optimizer import OptimizerResult
from lhgraph.estimation.graph.resolve import Resolution
from lhgraph.estimation.imu.calibration import fit_imu_calibration
from lhgraph.estimation.imu.inertial import inertial_data, initial_gravity
from lhgraph.estimation.init.pnp_kabsch import Initialisation
from lhgraph.estimation.problem import GraphProblem
from lhgraph.io.imu import ImuStream

Array = NDArray[np.float64]
Progress = Callable[[str], None]
IMU_DISAGREEMENT = 1.5
"""The IMU refinement warns when it raises the light's median absolute residual by more than
this factor, and with ``imu_factors = "auto"`` replaces GTSAM's combined factors that do
so by the twist factors (on the hive recording with its gyro taken as read, 0.48x the true
rate: 47 -> 527 urad; a simulated gyro reading 0.5x: 1.28x; consistent simulated IMUs
1.02-1.10x; the real Crazyflie LH1 log: 37 -> 257 urad, its deck's accelerometer misfits
~10x its readings' noise)."""
DISAGREEMENT_STEPS = 2
"""From this accepted LM step on, combined IMU factors that have raised the light's median
residual past ``IMU_DISAGREEMENT`` times end their optimisation (with ``imu_factors =
"auto"``): on the real Crazyflie LH1 log the first step took it from 37 to 208 urad and it
never came back under 257; on the simulated decks the first steps stay at 1.2-1.3x."""
IMU_FACTOR_NAMES = {"combined": "GTSAM's combined IMU factors",
                    "twist": "gyro and accelerometer factors on the twists"}


@dataclass(frozen=True)
class ImuRefinement:
    """The refined solve: the optimiser's ``fit`` (iterations and error history counting
    the light-only stage's), its evaluator ``ev``, the stations' ``covariances``,
    the options it ran with (``resolution``), warnings (``notes``) and figures of its own
    (``diagnostics``: the IMU calibration found from the light)."""

    fit: OptimizerResult
    ev: FactorEvaluator
    covariances: StationCovariances
    resolution: Resolution
    notes: list[str]
    diagnostics: dict[str, float]


class Disagreement(Exception):
    """Raised by :meth:`watch`'s check when IMU factors have raised the light's median
    angle residual to ``median_rad`` after ``steps`` accepted LM steps."""

    def __init__(self, median_rad: float, steps: int):
        super().__init__(f"median angle residual {median_rad * 1e6:.0f} urad")
        self.median_rad, self.steps = median_rad, steps

    @staticmethod
    def watch(limit_rad: float, after_steps: int = DISAGREEMENT_STEPS) -> Watch:
        """A check, after every accepted LM step, that raises :class:`Disagreement` from the
        ``after_steps``-th on when the evaluator's median angle residual exceeds
        ``limit_rad``."""
        steps = 0

        def check(ev: FactorEvaluator, values: gtsam.Values) -> None:
            nonlocal steps
            steps += 1
            if steps >= after_steps and (median := median_residual(ev, values)) > limit_rad:
                raise Disagreement(median, steps)

        return check


def median_residual(ev: FactorEvaluator, values: gtsam.Values) -> float:
    """Median absolute angle residual (rad) of ``ev``'s hits at ``values``."""
    ev.evaluate(values)
    return float(np.median(np.abs(ev.bearing.residuals())))


def refine_with_imu(problem: GraphProblem, resolution: Resolution, auto: bool,
                    imu: ImuStream, light: OptimizerResult, light_ev: FactorEvaluator,
                    progress: Progress | None = None) -> ImuRefinement:
    """The light-only solve ``light`` (evaluator ``light_ev``) of ``problem`` refined with
    the IMU stream ``imu`` under the resolved options ``resolution`` (``auto``: the user
    left ``imu_factors`` to the solve, which may then fall back to the twist factors)."""
    options = resolution.options
    marginals = functools.partial(station_covariances, options=options.uncertainty)
    refined = Initialisation(light_ev.station_poses().copy(), light_ev.board_poses().copy(),
                             light_ev.board_twists().copy())
    light_median = median_residual(light_ev, light.values)
    kind = options.imu.factor_kind
    notes: list[str] = []
    found: dict[str, float] = {}
    if options.imu.calibration_from_light:
        calibration = fit_imu_calibration(
            imu, problem.state_time, refined.X, scale=options.imu.gyro_scale_sigma > 0,
            offset=options.imu.imu_time_offset_sigma_s > 0,
            rotation=options.imu.imu_rotation_sigma_rad > 0)
        imu = calibration.apply(imu)
        found = calibration.summary()
        if progress:
            progress("the IMU's calibration from the light's rotations: "
                     + ", ".join(f"{k} {v:.4g}" for k, v in found.items()))
    inertial = inertial_data(imu, problem.state_time, options.imu.imu_max_gap_s)
    gravity = initial_gravity(inertial, refined.X)
    if progress:
        progress(f"refining with the IMU: {IMU_FACTOR_NAMES[kind]}")
    limit = IMU_DISAGREEMENT * light_median
    fallback = kind == "combined" and auto
    early = fallback and options.board.board_scale_sigma == 0
    watch = Disagreement.watch(limit) if early else None
    try:
        fit, ev, cov = build_and_optimise(problem, options, refined, marginals,
                                          progress, inertial=inertial, gravity=gravity,
                                          levels=light_ev, watch=watch)
        imu_median, spent = median_residual(ev, fit.values), fit.iterations
    except Disagreement as stop:
        imu_median, spent = stop.median_rad, stop.steps
    if fallback and imu_median > limit:
        notes.append(f"GTSAM's combined IMU factors disagree with the light (they raised "
                     f"the median angle residual from {light_median * 1e6:.0f} to "
                     f"{imu_median * 1e6:.0f} urad in {spent} LM steps): refined with the "
                     "twist factors instead, whose noise is the stream's misfit, not its "
                     "readings'")
        if progress:
            progress(notes[-1])
        options = options.with_values(imu_factors="twist")
        resolution = Resolution(options, resolution.applied + (
            "imu_factors = 'twist' (GTSAM's combined factors disagreed with the light)",))
        light = replace(light, iterations=light.iterations + spent)
        fit, ev, cov = build_and_optimise(problem, options, refined, marginals,
                                          progress, inertial=inertial, gravity=gravity,
                                          levels=light_ev)
        imu_median = median_residual(ev, fit.values)
    if imu_median > limit:
        notes.append(f"the IMU disagrees with the light: its factors raised the median "
                     f"angle residual from {light_median * 1e6:.0f} to "
                     f"{imu_median * 1e6:.0f} urad (a gyro scale error or time offset? "
                     "solve them with gyro_scale_sigma / imu_time_offset_sigma_s; or "
                     "the IMU's frame is not the board's)")
    fit = replace(fit, iterations=light.iterations + fit.iterations,
                  error_history=light.error_history + fit.error_history)
    return ImuRefinement(fit, ev, cov, resolution, notes, found)
