"""Levenberg-Marquardt driven from Python on GTSAM's sparse linear solver (and iSAM2 in batch,
a cross-check).

Why a hand-driven loop: GTSAM's own optimisers (``LevenbergMarquardtOptimizer``,
``ISAM2.update``) copy the whole ``Values`` for every Python factor callback; for an 8 s
capture (1900 variables, 1900 callbacks per linearisation) they took 7-9 s, against 0.5 s for
this loop, which linearises a Python-owned ``Values`` (no copies) and evaluates candidate
steps with a numpy cost instead of ``graph.error`` (no callback per factor).

Each iteration linearises the graph, eliminates it multifrontally in the layout's order
(:meth:`VariableLayout.elimination_ordering`: the stations in the root clique, so their
marginal covariances come with the Bayes tree) and steps; a step that raises the error is
retried with each board state's step limited to ``max_board_step_rad`` / ``_m``
(:func:`limit_board_steps`), then with damping ``sqrt(lam) I`` on every variable (``lam``
x10 from 1e-6, up to 1e8).

**Stopping rule.** After every accepted step the noise hook (if any) may change the noise
levels; the solve has *converged* at an iteration that left the levels as they were and
either

- lowered the error by less than ``relative_tolerance`` (relative, floored at 1), or
- left the root variables (the stations; with the IMU also its biases, gravity and
  calibration) within ``step_tolerance_sigma`` standard deviations
  of where the iteration converges to (per coordinate, estimated from how fast the steps
  shrink: :func:`remaining_sigmas`) while no board pose moved by more than
  ``board_step_tolerance_rad`` / ``_m`` (the path is an output too: on the hive recording the
  stations settle while states started in mirror poses are still turning by degrees).

It has *stalled* when even the most damped step does not lower the error, and stops at
``max_iterations`` otherwise. The covariance comes from the last iteration's Bayes tree when
it converged undamped (linearised one converged step before the result, at the final noise
levels); otherwise the graph is linearised again at the result.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from enum import StrEnum

import gtsam
import numpy as np
from numpy.typing import NDArray

from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.graph.variables import BOARD_POSE, VariableLayout

Array = NDArray[np.float64]
Progress = Callable[[str], None]
Cost = Callable[[gtsam.Values], float]
"""The graph's error at some values (the same number as ``graph.error``)."""
Linearized = Callable[[], gtsam.GaussianFactorGraph]
"""The graph linearised at the current values, made on the first call (and reused by the next
iteration when the noise levels stay)."""
NoiseHook = Callable[[gtsam.Values, Linearized], bool]
"""Called with the values after every accepted step (and their linearisation, on demand);
returns whether it changed the noise levels (the cost function then gives new numbers)."""


class Status(StrEnum):
    """How an optimisation ended."""

    CONVERGED = "converged"
    MAX_ITERATIONS = "max_iterations"
    STALLED = "stalled"


@dataclass(frozen=True)
class LMParams:
    """Iteration limit and the stopping rule's tolerances (see the module docstring); made
    from resolved :class:`GraphOptions`."""

    max_iterations: int
    relative_tolerance: float
    step_tolerance_sigma: float
    board_step_tolerance_rad: float
    board_step_tolerance_m: float
    board_step_quantile: float
    max_board_step_rad: float
    max_board_step_m: float

    @classmethod
    def from_options(cls, options: GraphOptions) -> LMParams:
        """The optimizer group of resolved options
        (:func:`~lhgraph.estimation.graph.resolve.resolve_options`: no tolerance unset)."""
        o = options.optimizer
        if o.step_tolerance_sigma is None or o.board_step_quantile is None:
            raise ValueError("the stopping rule needs resolved options (resolve_options)")
        return cls(o.max_iterations, o.relative_tolerance, o.step_tolerance_sigma,
                   o.board_step_tolerance_rad, o.board_step_tolerance_m, o.board_step_quantile,
                   o.max_board_step_rad, o.max_board_step_m)


@dataclass(frozen=True)
class OptimizerResult:
    """End of an optimisation: the values, status, iterations taken, the error at the start
    and after each iteration (empty for iSAM2), the final error, and the eliminated linear
    system at the result (``tree``; ``covariance_from_last_iteration``: it is the last LM
    iteration's undamped one rather than a new linearisation) and the ``graph`` optimised."""

    values: gtsam.Values
    status: Status
    iterations: int
    error_history: list[float]
    final_error: float
    tree: gtsam.GaussianBayesTree
    covariance_from_last_iteration: bool
    graph: gtsam.NonlinearFactorGraph

    def covariance(self, key: int) -> Array:
        """Marginal covariance of variable ``key`` (tangent space)."""
        return self.tree.marginalCovariance(key)


def _status(converged: bool, iterations: int, max_iterations: int) -> Status:
    if converged:
        return Status.CONVERGED
    return Status.MAX_ITERATIONS if iterations >= max_iterations else Status.STALLED


def remaining_sigmas(step: float, previous: float | None) -> float:
    """How far (in standard deviations) the stations still are from convergence after a step
    of ``step``: converging linearly at the rate ``rho = step / previous`` the steps still to
    come add up to ``step rho / (1 - rho)``; without a previous step at the same noise
    levels, or when the steps do not shrink, the step itself."""
    if previous is None or step >= previous:
        return step
    rho = step / previous
    return step * rho / (1.0 - rho)


def largest_board_step(delta: gtsam.VectorValues, layout: VariableLayout,
                       quantile: float = 1.0) -> tuple[float, float]:
    """Largest rotation (rad) and translation (m) step of any board pose in ``delta`` (with
    ``quantile`` < 1: that quantile of the board poses' steps)."""
    step = layout.read_steps(delta, BOARD_POSE)
    rot, pos = np.linalg.norm(step[:, :3], axis=1), np.linalg.norm(step[:, 3:], axis=1)
    if quantile >= 1.0:
        return float(np.max(rot)), float(np.max(pos))
    return float(np.quantile(rot, quantile)), float(np.quantile(pos, quantile))


def _root_step_sigmas(tree: gtsam.GaussianBayesTree, delta: gtsam.VectorValues,
                      layout: VariableLayout) -> float:
    """Largest step of any root-variable (station, IMU bias, gravity) coordinate in its
    standard deviations (0 without root variables: tracking without IMU, the stations held
    fixed)."""
    steps = [float(np.max(np.abs(delta.at(key))
                          / np.sqrt(np.diag(tree.marginalCovariance(key)))))
             for family in layout.families if family.elimination == "root"
             for key in layout.keys(family)]
    return max(steps, default=0.0)


class _Damping:
    """Levenberg-Marquardt damping ``sqrt(lam) I`` on every variable of ``values``, one graph
    per ``lam`` built on first use (a graph holds a factor per variable: thousands of Python
    constructions that an LM run would otherwise repeat for every damped try)."""

    def __init__(self, values: gtsam.Values):
        self._dims = list(values.dims().items())
        self._graphs: dict[float, gtsam.GaussianFactorGraph] = {}

    def __call__(self, lam: float) -> gtsam.GaussianFactorGraph:
        if lam not in self._graphs:
            damp = gtsam.GaussianFactorGraph()
            eye = {d: np.sqrt(lam) * np.eye(d) for d in {d for _, d in self._dims}}
            zero = {d: np.zeros(d) for d in eye}
            unit = {d: gtsam.noiseModel.Unit.Create(d) for d in eye}
            for key, dim in self._dims:
                damp.add(gtsam.JacobianFactor(key, eye[dim], zero[dim], unit[dim]))
            self._graphs[lam] = damp
        return self._graphs[lam]


def limit_board_steps(delta: gtsam.VectorValues, layout: VariableLayout, max_rad: float,
                      max_m: float) -> bool:
    """Scale down, in place in ``delta``, every board state's step (all its variables
    together: pose, twist and, with GTSAM's combined IMU factors, velocity and IMU bias)
    whose pose's rotation exceeds ``max_rad`` or translation ``max_m`` to those limits: a trust
    region per state. A state far from its solution (a mirror pose, a few hits bridged by a
    weak motion prior) otherwise takes a Gauss-Newton step that the linearisation does not
    hold, the step fails, and the damping that rescues it slows every other variable.
    Returns whether any step was scaled."""
    step = layout.read_steps(delta, BOARD_POSE)
    excess = np.maximum(np.linalg.norm(step[:, :3], axis=1) / max_rad,
                        np.linalg.norm(step[:, 3:], axis=1) / max_m)
    big = np.flatnonzero(excess > 1.0)
    if len(big) == 0:
        return False
    scaled = gtsam.VectorValues()
    for family in (f for f in layout.families if f.elimination == "chain"):
        keys = layout.keys(family)
        for i in big.tolist():
            scaled.insert(keys[i], delta.at(keys[i]) / excess[i])
    delta.update(scaled)
    return True


def _joined(a: gtsam.GaussianFactorGraph, b: gtsam.GaussianFactorGraph
            ) -> gtsam.GaussianFactorGraph:
    out = gtsam.GaussianFactorGraph()
    out.push_back(a)
    out.push_back(b)
    return out


def levenberg_marquardt(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, cost: Cost,
                        layout: VariableLayout, params: LMParams,
                        noise_hook: NoiseHook | None = None,
                        progress: Progress | None = None) -> OptimizerResult:
    """Minimise ``graph`` from ``values`` (``cost`` gives its error) by the stopping rule of
    the module docstring; ``noise_hook`` adapts the noise levels after accepted steps."""
    ordering = layout.elimination_ordering()
    error = cost(values)
    history = [error]
    lam = 0.0
    tree = None
    converged = False
    iterations = 0
    previous_step = None  # the last accepted station step at the current noise levels
    damping = _Damping(values)
    linearized = None  # the hook's linearisation at the accepted values, if it made one
    for iterations in range(1, params.max_iterations + 1):
        lin = linearized() if linearized is not None else graph.linearize(values)
        while True:
            system = lin if lam == 0.0 else _joined(lin, damping(lam))
            tree = system.eliminateMultifrontal(ordering)
            delta = tree.optimize()
            # the full step first; if it fails, the same step within each board state's
            # trust region; if that fails too, damping
            for limited in (False, True):
                if limited and not limit_board_steps(delta, layout, params.max_board_step_rad,
                                                     params.max_board_step_m):
                    break  # no state beyond its trust region: the same step failed
                candidate = values.retract(delta)
                new_error = cost(candidate)
                if new_error <= error:
                    break
            if new_error <= error or lam > 1e8:
                break
            lam = max(lam * 10.0, 1e-6)
        damped = lam > 0.0
        improvement = error - new_error
        station_step = _root_step_sigmas(tree, delta, layout)
        if progress:
            progress(f"iteration {iterations}: error {new_error:.6g}")
        accepted = new_error <= error
        if accepted:
            values, error = candidate, new_error
            lam = lam / 10.0 if lam > 1e-6 else 0.0
        history.append(error)
        if not accepted:  # no descent even with the strongest damping: stalled
            break
        linearized = functools.cache(lambda at=values: graph.linearize(at))
        rescaled = noise_hook(values, linearized) if noise_hook is not None else False
        if rescaled or linearized.cache_info().currsize == 0:
            linearized = None  # made at other noise levels, or not made
        if rescaled:
            error = cost(values)
        remaining = remaining_sigmas(station_step, previous_step)
        board_rad, board_m = largest_board_step(delta, layout, params.board_step_quantile)
        board_settled = (board_rad < params.board_step_tolerance_rad
                         and board_m < params.board_step_tolerance_m)
        small = (improvement < params.relative_tolerance * max(error, 1.0)
                 or (remaining < params.step_tolerance_sigma and board_settled))
        if small and not rescaled:
            converged = True
            break
        # a damped step is measured against damped marginals: no basis for a rate
        previous_step = None if rescaled or damped else station_step
    reused = converged and not damped
    if not reused:
        tree = graph.linearize(values).eliminateMultifrontal(ordering)
    return OptimizerResult(values, _status(converged, iterations, params.max_iterations),
                           iterations, history, error, tree, reused, graph)


def isam2_batch(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values,
                layout: VariableLayout, max_iterations: int,
                progress: Progress | None = None) -> OptimizerResult:
    """Batch solve with iSAM2: all factors, then updates until the error stops falling
    (relative change < 1e-6); the covariance from a linearisation at the result."""
    params = gtsam.ISAM2Params()
    params.setRelinearizeThreshold(1e-9)
    params.relinearizeSkip = 1
    isam = gtsam.ISAM2(params)
    isam.update(graph, values)
    previous = np.inf
    iterations = 1
    converged = False
    for iterations in range(2, max_iterations + 1):
        isam.update()
        error = graph.error(isam.calculateEstimate())
        if progress:
            progress(f"iteration {iterations}: error {error:.6g}")
        if previous - error < 1e-6 * max(previous, 1.0):
            converged = True
            break
        previous = error
    result = gtsam.Values(isam.calculateEstimate())
    error = graph.error(result)
    tree = graph.linearize(result).eliminateMultifrontal(layout.elimination_ordering())
    return OptimizerResult(result, _status(converged, iterations, max_iterations), iterations,
                           [], error, tree, False, graph)
