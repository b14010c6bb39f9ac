"""The one build-and-optimise path of the batch graph, shared by the calibration
(:func:`lhgraph.estimation.graph.solver.solve_graph`) and tracking
(:func:`lhgraph.estimation.graph.track.track`): :func:`build_and_optimise`.

1. build the graph of every factor family the options ask for (:func:`~.factors.build_graph`);
2. its initial values from an initialisation (and the gravity, with IMU factors);
3. the noise levels started where a previous stage left them (``levels``);
4. optimise: ``options.optimizer.solver`` ``"lm"`` (:func:`~.optimizer.levenberg_marquardt` with the
   variance-component adaptation of :mod:`.noise`, and a ``watch`` after every accepted
   step) or ``"isam2"`` (:func:`~.optimizer.isam2_batch`, no noise adaptation);
5. the marginals the caller asks for, at the result (the stations' for the calibration,
   every state's for tracking).

A GTSAM error on the way (an undetermined linear system) becomes one
:class:`~lhgraph.errors.SolverError` line naming the variable (:func:`undetermined`).
"""

from __future__ import annotations

import functools
import re
from collections.abc import Callable
from typing import TypeVar

import gtsam
import numpy as np
from numpy.typing import NDArray

from lhgraph.errors import SolverError
from lhgraph.estimation.graph.evaluator import FactorEvaluator
from lhgraph.estimation.graph.factors import build_graph
from lhgraph.estimation.graph.noise import NoiseAdaptation
from lhgraph.estimation.graph.optimizer import (
    Linearized,
    LMParams,
    NoiseHook,
    OptimizerResult,
    isam2_batch,
    levenberg_marquardt,
)
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.graph.variables import STATION_POSE, VariableLayout, initial_values
from lhgraph.estimation.imu.inertial import InertialData
from lhgraph.estimation.init.pnp_kabsch import Initialisation
from lhgraph.estimation.problem import GraphProblem

Array = NDArray[np.float64]
Progress = Callable[[str], None]
Watch = Callable[[FactorEvaluator, gtsam.Values], None]
"""Called with the evaluator and the values after every accepted LM step (its exception ends
the optimisation)."""
M = TypeVar("M")


def build_and_optimise(problem: GraphProblem, options: GraphOptions, init: Initialisation,
                       marginals: Callable[[OptimizerResult, FactorEvaluator], M],
                       progress: Progress | None = None, T_world_lh: Array | None = None,
                       inertial: InertialData | None = None, gravity: Array | None = None,
                       levels: FactorEvaluator | None = None, watch: Watch | None = None
                       ) -> tuple[OptimizerResult, FactorEvaluator, M]:
    """The graph of ``problem`` optimised from ``init`` (and ``gravity``): the optimiser's
    result, the evaluator (at the last point it evaluated: ``ev.evaluate(fit.values)`` before
    reading the result off it) and ``marginals(fit, ev)``.

    ``T_world_lh`` ``(S, 4, 4)`` holds every station at that pose (tracking); ``inertial``
    adds the IMU factors; ``levels``: a previous stage's evaluator whose noise levels this
    one starts at (default: the options'); ``watch`` (LM only): see :data:`Watch`."""
    graph, ev = build_graph(problem, options, T_world_lh, inertial)
    values = initial_values(ev.layout, init, gravity)
    if levels is not None:
        ev.bearing.scale_noise((levels.bearing.angle_sigma() / ev.bearing.angle_sigma()) ** 2)
        ev.motion.scale(levels.motion.psd_factor() / ev.motion.psd_factor())
    try:
        if options.optimizer.solver == "lm":
            hook = (NoiseAdaptation(graph, ev, options, progress)
                    if NoiseAdaptation.enabled(options) else None)
            if watch is not None:
                hook = functools.partial(_watched, watch, ev, hook)
            fit = levenberg_marquardt(graph, values, ev.cost, ev.layout,
                                      LMParams.from_options(options), hook, progress)
        else:
            fit = isam2_batch(graph, values, ev.layout, options.optimizer.max_iterations, progress)
        found = marginals(fit, ev)
    except RuntimeError as err:  # gtsam's IndeterminateLinearSystemException and kin
        raise SolverError(undetermined(str(err), ev.layout, problem)) from err
    return fit, ev, found


def _watched(watch: Watch, ev: FactorEvaluator, hook: NoiseHook | None, values: gtsam.Values,
             linearized: Linearized | None = None) -> bool:
    """The noise hook ``hook`` (None: none) after ``watch(ev, values)``."""
    watch(ev, values)
    return hook(values, linearized) if hook is not None else False


def undetermined(message: str, layout: VariableLayout, problem: GraphProblem) -> str:
    """One line for a GTSAM error ``message`` raised while solving the graph of ``problem``:
    the variable it names (GTSAM: ``(Symbol: x1495)``) as the user knows it (a board state:
    its time from the capture's first state, its station, how many hits of how many diodes it
    has and how far the states around it are), or that some variable is not determined when
    the message names none."""
    found = re.search(r"Symbol: ([A-Za-z])(\d+)", message)
    family = None if found is None else next(
        (f for f in layout.families if f.symbol == found[1]), None)
    if family is None:
        first = next((line.strip() for line in message.splitlines() if line.strip()), "")
        return (f"the linearised problem cannot be solved ({first}): some board state or "
                "station is not determined by the data")
    index = int(found[2])
    what = f"{family.name} {index}"
    if family.elimination == "chain" and index < problem.n_states:
        t = problem.state_time
        a, b = problem.bounds[index], problem.bounds[index + 1]
        before = f"{t[index] - t[index - 1]:.3f} s before" if index > 0 else "none before"
        after = (f"{t[index + 1] - t[index]:.3f} s after" if index + 1 < len(t)
                 else "none after")
        what += (f" (t = {t[index] - t[0]:.3f} s, station "
                 f"{problem.station_ids[problem.state_station[index]]}: {b - a} hits of "
                 f"{len(np.unique(problem.hit_sensor[a:b]))} diodes; the nearest states "
                 f"{before}, {after})")
    elif family.name == STATION_POSE.name and index < len(problem.station_ids):
        what = f"station {problem.station_ids[index]}"
    return (f"the linearised problem cannot be solved: {what} is not determined by the data "
            "(GTSAM: indeterminate linear system); another robust loss, a stiffer motion "
            "prior (a lower max_psd_factor) or leaving that stretch of the capture out may "
            "help")
