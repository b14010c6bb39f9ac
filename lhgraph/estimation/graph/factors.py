"""The batch graph built from its factor families, in one place: :func:`build_graph`.

:func:`factor_families` is the registry: the families a graph gets from its options, in the
order their factors go into the graph (:mod:`lhgraph.estimation.graph.families`):

1. **bearings** (:class:`~.families.bearing.Bearings`): a bearing factor per sweep and a
   zero-mean prior on every sweep offset;
2. **board corrections** (:class:`~.families.corrections.BoardCorrections`): with
   ``diode_bias_sigma_rad`` the diode biases' priors, with ``sensor_offset_sigma_m`` the
   sensor offsets' prior and scale factor, with ``board_scale_sigma`` the board scale's
   prior (no factor when none is asked);
3. **factory terms** (:class:`~.families.factory.FactoryCorrections`): with
   ``factory_terms`` a zero-mean prior on every station slot's corrections to its decoded
   factory terms (no factor without);
4. **motion prior** (:class:`~.families.motion.MotionPrior`) between consecutive states;
5. with an IMU stream: ``imu_factors`` resolving to ``"combined"``, GTSAM's preintegrated
   combined IMU factors (:class:`~lhgraph.estimation.imu.families.CombinedImuFamily`), to
   ``"twist"`` the gyro, accelerometer and preintegrated gyro factors on the twists
   (:class:`~lhgraph.estimation.imu.families.TwistImu`);
6. with an earlier result as a prior (the problem's ``station_priors``) and station
   variables: a prior factor per station it holds
   (:class:`~.families.station_prior.StationPriorFactors`).

Adding a family: one module implementing :class:`~.families.base.FactorFamily`, one line
here (docs/architecture.md walks through it).
"""

from __future__ import annotations

import gtsam
import numpy as np
from numpy.typing import NDArray

from lhgraph.estimation.graph.evaluator import FactorEvaluator
from lhgraph.estimation.graph.families.base import FactorFamily
from lhgraph.estimation.graph.families.bearing import Bearings
from lhgraph.estimation.graph.families.corrections import BoardCorrections
from lhgraph.estimation.graph.families.factory import FactoryCorrections
from lhgraph.estimation.graph.families.motion import MotionPrior
from lhgraph.estimation.graph.families.station_prior import StationPriorFactors
from lhgraph.estimation.graph.loss import RobustLoss
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.graph.variables import (
    STATION_POSE,
    VariableLayout,
    diode_bias_family,
    factory_family,
    sensor_offset_family,
)
from lhgraph.estimation.imu.families import CombinedImuFamily, TwistImu
from lhgraph.estimation.imu.inertial import InertialData
from lhgraph.estimation.problem import GraphProblem

Array = NDArray[np.float64]


def graph_layout(problem: GraphProblem, options: GraphOptions, tracking: bool,
                 inertial: bool) -> VariableLayout:
    """The variables of ``problem``'s batch graph under ``options``: no station variable
    when ``tracking``, the IMU's when ``inertial``."""
    n = problem.n_sensors
    return VariableLayout.of_problem(
        problem.n_states, len(problem.station_ids), fixed_stations=tracking,
        inertial=inertial,
        diode_bias=diode_bias_family(n) if options.board.diode_bias_sigma_rad > 0 else None,
        sensor_offset=sensor_offset_family(n) if options.board.sensor_offset_sigma_m > 0 else None,
        imu_calibration=options.imu.calibrated,
        combined_imu=inertial and options.imu.factor_kind == "combined",
        factory=factory_family(len(terms)) if (terms := options.factory.terms) else None,
        board_scale=options.board.board_scale_sigma > 0)


def factor_families(problem: GraphProblem, layout: VariableLayout, options: GraphOptions,
                    inertial: InertialData | None = None) -> list[FactorFamily]:
    """The registry: the factor families of ``problem``'s graph under ``options`` (with
    ``inertial`` the IMU's), in graph order."""
    corrections = BoardCorrections(problem, layout, options.board.diode_bias_sigma_rad,
                                   options.board.sensor_offset_sigma_m,
                                   options.board.board_scale_sigma)
    factory = FactoryCorrections(problem, layout, options.factory.terms,
                                 options.factory.factory_sigma_rad, corrections)
    families: list[FactorFamily] = [
        Bearings(problem, layout, RobustLoss(options.robust.loss, options.robust.huber_k),
                 options.noise.angle_sigma_rad, options.noise.sweep_offset_sigma_rad, corrections,
                 factory),
        corrections, factory,
        MotionPrior(problem, (options.motion.accel_psd_rot, options.motion.accel_psd_pos))]
    if inertial is not None and options.imu.factor_kind == "combined":
        families.append(CombinedImuFamily(inertial.stream, problem.state_time, layout,
                                          options))
    elif inertial is not None:
        families.append(TwistImu(inertial, layout, options))
    if problem.station_priors and len(layout.indices(STATION_POSE)):
        families.append(StationPriorFactors(problem, layout))
    return families


def build_graph(problem: GraphProblem, options: GraphOptions, T_world_lh: Array | None = None,
                inertial: InertialData | None = None
                ) -> tuple[gtsam.NonlinearFactorGraph, FactorEvaluator]:
    """The nonlinear factor graph of ``problem`` (every family of :func:`factor_families`)
    and the evaluator its callbacks use. ``T_world_lh`` ``(S, 4, 4)`` by station slot holds
    every station fixed at that pose (tracking); without it the stations but the reference
    are variables."""
    layout = graph_layout(problem, options, T_world_lh is not None, inertial is not None)
    ev = FactorEvaluator(problem, layout, factor_families(problem, layout, options, inertial),
                         T_world_lh)
    graph = gtsam.NonlinearFactorGraph()
    for family in ev.families:
        family.add_to(graph, ev.ensure)
    return graph, ev
