"""The factor-graph calibration (``method = "graph"``), on GTSAM.

Variables (``gtsam.symbol_shorthand``): ``X(k)`` board pose ``T_world_board`` and ``V(k)``
board body twist ``[omega, v]`` at sweep k; ``L(s)`` pose ``T_world_lh`` of every
non-reference station (the reference station is the world frame, so it is no variable).
Factors:
1. one bearing factor per sweep, holding every diode that sweep hit (residual per diode =
   predicted - measured angle of the full station model, Huber loss per diode with the
   ``Scalar`` reweight scheme), keys ``X(k), V(k), B(k)[, L(s)]``, where ``B(k)`` is the
   angle offset common to all diodes of sweep k (the sampled sync edge), with a prior;
2. a white-noise-on-acceleration motion prior between consecutive states.
Residuals and Jacobians come from :mod:`lhgraph.estimation.residuals`, computed for all sweeps
in one
vectorised pass and cached, so each GTSAM callback only slices arrays.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import gtsam
import numpy as np
from gtsam.symbol_shorthand import B, L, V, X
from numpy.typing import NDArray

from lhgraph.errors import SolverError
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.init import Initialiser
from lhgraph.estimation.init.pnp_kabsch import Initialisation, PnPKabschInitialiser
from lhgraph.estimation.problem import GraphProblem, build_problem
from lhgraph.estimation.residuals import (
    bearing_residuals,
    motion_residuals,
    wnoa_covariance,
)
from lhgraph.estimation.result import Residuals, SolveResult
from lhgraph.io.angles import Angles
from lhgraph.io.stations import Station, Stations
from lhgraph.io.trajectory import Trajectory
from lhgraph.model.board import Board
from lhgraph.model.lh1 import StationModel

Array = NDArray[np.float64]
Progress = Callable[[str], None]


# --- factors ----------------------------------------------------------------------------------


class _Evaluator:
    """Vectorised residuals of every factor, recomputed only when the linearisation point of a
    factor's own variables differs from the cached one; also the graph's cost in numpy (the
    same number as ``graph.error``, without a Python callback per factor)."""

    def __init__(self, problem: GraphProblem, options: GraphOptions):
        self.p = problem
        self.options = options
        self.error_history: list[float] = []  # graph error per LM iteration (SolveResult)
        K, S = problem.n_states, len(problem.station_ids)
        self.X = np.full((K, 4, 4), np.nan)
        self.V = np.full((K, 6), np.nan)
        self.L = np.repeat(np.eye(4)[None], S, axis=0)
        self.dt = np.diff(problem.state_time)
        self.B = np.full(K, np.nan)
        self._ones = np.ones((len(problem.hits.angle), 1))
        self.recomputes = 0
        self._values: gtsam.Values | None = None
        self._psd = (options.accel_psd_rot, options.accel_psd_pos)
        self.Q = wnoa_covariance(self.dt, *self._psd)  # the motion factors' noise models
        self._Q_inv = np.linalg.inv(self.Q)
        self.motion_scale = 1.0  # 1/sqrt(s): the motion prior's covariance is s * Q
        self.bearing_scale = 1.0  # sigma_0 / sigma: the diodes' noise is sigma, not sigma_0
        self._jacobians_ready = False

    def scale_bearing_noise(self, factor: float) -> None:
        """Multiply the diodes' angle variance by ``factor``."""
        self.bearing_scale /= np.sqrt(factor)
        self._scale_residuals()

    def scale_motion_prior(self, factor: float) -> None:
        """Multiply the motion prior's covariance by ``factor``."""
        self.motion_scale /= np.sqrt(factor)
        self._scale_residuals()

    def _scale_residuals(self) -> None:
        self.r_whitened = self.r * self.bearing_scale
        self.e = self.e_raw * self.motion_scale
        self._jacobians_ready = False

    def _motion_chi2(self) -> Array:
        """Whitened squared residual ``e^T Q^-1 e`` of every motion prior (K-1,)."""
        return np.einsum("ki,kij,kj->k", self.e, self._Q_inv, self.e)

    def motion_chi2_per_dof(self) -> float:
        """Mean whitened squared motion-prior residual per degree of freedom under the current
        prior (1 if its strength matches the solved motion)."""
        return float(np.mean(self._motion_chi2()) / 12)

    def angle_sigma(self) -> float:
        """Effective per-diode angle noise (rad) now."""
        return self.options.angle_sigma_rad / self.bearing_scale

    def motion_psd(self) -> tuple[float, float]:
        """Effective (rotational, linear) acceleration PSD of the motion prior now."""
        s = self.motion_scale ** -2
        return self._psd[0] * s, self._psd[1] * s

    def cost(self, values: gtsam.Values) -> float:
        """The graph's error at ``values`` (what ``graph.error`` returns): robust loss of the
        whitened diode residuals, plus half the squared whitened offset priors and motion
        priors."""
        self.at(values)
        o = self.options
        x = self.r_whitened / o.angle_sigma_rad
        k = o.huber_k
        if o.loss == "cauchy":
            bearing = 0.5 * k**2 * np.log1p((x / k) ** 2)
        else:
            ax = np.abs(x)
            bearing = np.where(ax <= k, 0.5 * x**2, k * ax - 0.5 * k**2)
        offsets = 0.5 * (self.B / o.sweep_offset_sigma_rad) ** 2
        return float(bearing.sum() + offsets.sum() + 0.5 * self._motion_chi2().sum())

    def at(self, values: gtsam.Values) -> None:
        """Evaluate the residuals at ``values`` unless they are the cached point."""
        if values is not self._values:
            self._read(values)

    def _read(self, values: gtsam.Values) -> None:
        poses = gtsam.utilities.extractPose3(values)
        S = len(self.p.station_ids)
        T = np.zeros((len(poses), 4, 4))
        T[:, :3, :3] = poses[:, :9].reshape(-1, 3, 3)
        T[:, :3, 3] = poses[:, 9:]
        T[:, 3, 3] = 1.0
        self.L[1:] = T[: S - 1]
        self.X = T[S - 1:]
        self.V = gtsam.utilities.extractVectors(values, "v")
        self.B = gtsam.utilities.extractVectors(values, "b")[:, 0]
        h = self.p.hits
        self.r = bearing_residuals(h, self.X, self.V, self.L, self.p.models, False)[0]
        self.r += self.B[h.state]
        self.e_raw = motion_residuals(self.X[:-1], self.V[:-1], self.X[1:], self.V[1:],
                                      self.dt, False)[0]
        self._scale_residuals()
        self.recomputes += 1
        self._values = values

    def _jacobians(self) -> None:
        """Jacobians at the cached point, computed once, on the first linearising callback
        (error-only evaluations never need them)."""
        if self._jacobians_ready:
            return
        _, HX, HV, HL = bearing_residuals(self.p.hits, self.X, self.V, self.L, self.p.models)
        self.HX, self.HV, self.HL = (H * self.bearing_scale for H in (HX, HV, HL))
        self._offset_jacobian = self._ones * self.bearing_scale
        _, He = motion_residuals(self.X[:-1], self.V[:-1], self.X[1:], self.V[1:], self.dt)
        self.He = tuple(H * self.motion_scale for H in He)
        self._jacobians_ready = True

    def _ensure(self, values: gtsam.Values, k: int, slot: int | None) -> None:
        # A Python-owned Values reaches every callback as the same object: identity is
        # enough. Values copied by GTSAM's optimisers are compared by content.
        if values is self._values:
            return
        if (np.array_equal(values.atPose3(X(k)).matrix(), self.X[k])
                and np.array_equal(values.atVector(V(k)), self.V[k])
                and values.atVector(B(k))[0] == self.B[k]
                and (slot is None or np.array_equal(values.atPose3(L(slot)).matrix(),
                                                    self.L[slot]))):
            self._values = values
            return
        self._read(values)

    def bearing(self, k: int, slot: int) -> Callable:
        a, b = self.p.bounds[k], self.p.bounds[k + 1]
        station_var = slot if slot > 0 else None

        def error(_f: gtsam.CustomFactor, values: gtsam.Values, H: list | None) -> Array:
            self._ensure(values, k, station_var)
            if H is not None:
                self._jacobians()
                H[0] = self.HX[a:b]
                H[1] = self.HV[a:b]
                H[2] = self._offset_jacobian[a:b]
                if station_var is not None:
                    H[3] = self.HL[a:b]
            return self.r_whitened[a:b]

        return error

    def motion(self, k: int) -> Callable:
        def error(_f: gtsam.CustomFactor, values: gtsam.Values, H: list | None) -> Array:
            self._ensure(values, k, None)
            self._ensure(values, k + 1, None)
            if H is not None:
                self._jacobians()
                for j in range(4):
                    H[j] = self.He[j][k]
            return self.e[k]

        return error


def build_graph(problem: GraphProblem, options: GraphOptions
                ) -> tuple[gtsam.NonlinearFactorGraph, _Evaluator]:
    """The nonlinear factor graph of ``problem`` (named noise models, one factor per sweep)."""
    ev = _Evaluator(problem, options)
    graph = gtsam.NonlinearFactorGraph()
    estimators = {"huber": gtsam.noiseModel.mEstimator.Huber,
                  "cauchy": gtsam.noiseModel.mEstimator.Cauchy}
    if options.loss not in estimators:
        raise SolverError(f"unknown loss '{options.loss}' (expected huber or cauchy)")
    huber = estimators[options.loss].Create(
        options.huber_k, gtsam.noiseModel.mEstimator.Base.ReweightScheme.Scalar)
    for k in range(problem.n_states):
        a, b = problem.bounds[k], problem.bounds[k + 1]
        slot = int(problem.state_station[k])
        diode_noise = gtsam.noiseModel.Isotropic.Sigma(int(b - a), options.angle_sigma_rad)
        robust_noise = gtsam.noiseModel.Robust.Create(huber, diode_noise)
        keys = [X(k), V(k), B(k)] + ([L(slot)] if slot > 0 else [])
        graph.add(gtsam.CustomFactor(robust_noise, keys, ev.bearing(k, slot)))
    offset_noise = gtsam.noiseModel.Isotropic.Sigma(1, options.sweep_offset_sigma_rad)
    for k in range(problem.n_states):
        graph.add(gtsam.PriorFactorVector(B(k), np.zeros(1), offset_noise))
    for k in range(problem.n_states - 1):
        motion_noise = gtsam.noiseModel.Gaussian.Covariance(ev.Q[k])
        graph.add(gtsam.CustomFactor(motion_noise, [X(k), V(k), X(k + 1), V(k + 1)],
                                     ev.motion(k)))
    return graph, ev


def initial_values(init: Initialisation) -> gtsam.Values:
    """GTSAM Values of an initialisation."""
    values = gtsam.Values()
    for slot in range(1, len(init.L)):
        values.insert(L(slot), gtsam.Pose3(init.L[slot]))
    for k in range(len(init.X)):
        values.insert(X(k), gtsam.Pose3(init.X[k]))
        values.insert(V(k), init.V[k])
        values.insert(B(k), np.zeros(1))
    return values


# --- solve ------------------------------------------------------------------------------------


def _damping(values: gtsam.Values, lam: float) -> gtsam.GaussianFactorGraph:
    """Levenberg-Marquardt damping ``sqrt(lam) I`` on every variable."""
    damp = gtsam.GaussianFactorGraph()
    for key in values.keys():
        dim = 1 if gtsam.Symbol(key).chr() == ord("b") else 6
        damp.add(gtsam.JacobianFactor(key, np.sqrt(lam) * np.eye(dim), np.zeros(dim),
                                      gtsam.noiseModel.Unit.Create(dim)))
    return damp


def elimination_ordering(problem: GraphProblem) -> gtsam.Ordering:
    """Sweep offsets first, then the board states in time order, the stations last: the
    chain eliminates without fill-in, and the stations' marginals are read off the root."""
    ordering = gtsam.Ordering()
    for k in range(problem.n_states):
        ordering.push_back(B(k))
    for k in range(problem.n_states):
        ordering.push_back(X(k))
        ordering.push_back(V(k))
    for slot in range(1, len(problem.station_ids)):
        ordering.push_back(L(slot))
    return ordering


@dataclass
class LMOutcome:
    """End of a Levenberg-Marquardt solve: the values, the iterations taken, the final error,
    whether it converged, and the eliminated (undamped) linear system of the last iteration
    at the final noise levels, if there is one (for the covariance)."""

    values: gtsam.Values
    iterations: int
    error: float
    converged: bool
    tree: gtsam.GaussianBayesTree | None


def _update_noise_levels(ev: _Evaluator, options: GraphOptions,
                         progress: Progress | None) -> bool:
    """One variance-component update at the evaluator's current point: rescale the motion
    prior until its whitened residuals have unit variance per degree of freedom (so the prior
    matches how the board actually moved) and the diodes' noise to the residuals' robust
    spread. Returns whether anything changed (False: both match the data or sit at their
    bounds)."""
    chi2 = ev.motion_chi2_per_dof()
    ratio = float(np.clip(chi2, 1e-3, 1e3))
    if not options.adapt_motion_prior:
        ratio = 1.0
    # a model misfit shows up as board jitter: never loosen the prior beyond the cap
    ratio = min(ratio, options.max_psd_factor / ev.motion_scale**-2)
    # nor stiffen it below the floor: a real board's motion is not exactly WNOA, and an
    # over-stiff prior trades the station's accuracy for smoothness
    ratio = max(ratio, options.min_psd_factor / ev.motion_scale**-2)
    # the diodes' noise from the residuals (robust: MAD), never below the configured
    # sigma (the 2 MHz quantisation) nor above max_sigma_factor times it
    sigma_hat = 1.4826 * float(np.median(np.abs(ev.r)))
    noise = 1.0
    if options.adapt_angle_sigma:
        noise = float(np.clip(sigma_hat, options.angle_sigma_rad,
                              options.max_sigma_factor * options.angle_sigma_rad)
                      / ev.angle_sigma())**2
    if progress:
        progress(f"motion prior: chi2/dof {chi2:.3g} (PSD scaled by {ratio:.3g}); angle noise "
                 f"{sigma_hat * 1e6:.1f} urad")
    if 0.8 < ratio < 1.25 and 0.8 < noise < 1.25:
        return False
    ev.scale_motion_prior(ratio)
    ev.scale_bearing_noise(noise)
    return True


def _station_step_sigmas(tree: gtsam.GaussianBayesTree, delta: gtsam.VectorValues,
                         n_stations: int) -> float:
    """Largest step of any station coordinate in units of its standard deviation."""
    steps = [np.abs(delta.at(L(slot))) / np.sqrt(np.diag(tree.marginalCovariance(L(slot))))
             for slot in range(1, n_stations)]
    return float(np.max(steps))


def _board_steps(delta: gtsam.VectorValues, n_states: int) -> tuple[float, float]:
    """Largest rotation (rad) and translation (m) step of any board state. ``delta`` holds
    the keys in GTSAM's key order (symbol character, then index: b, l, v, x), so the board
    poses' 6-vectors are its last ``6 n_states`` entries."""
    step = delta.vector()[-6 * n_states:].reshape(n_states, 6)
    return (float(np.max(np.linalg.norm(step[:, :3], axis=1))),
            float(np.max(np.linalg.norm(step[:, 3:], axis=1))))


def _remaining_sigmas(step: float, previous: float | None) -> float:
    """How far (in standard deviations) the stations still are from convergence after a step
    of ``step``: converging linearly at the rate ``rho = step / previous`` the steps still to
    come add up to ``step rho / (1 - rho)``; without a previous step at the same noise
    levels, or when the steps do not shrink, the step itself."""
    if previous is None or step >= previous:
        return step
    rho = step / previous
    return step * rho / (1.0 - rho)


def _levenberg_marquardt(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values,
                         ev: _Evaluator, ordering: gtsam.Ordering, options: GraphOptions,
                         progress: Progress | None) -> LMOutcome:
    """Levenberg-Marquardt driven from Python on GTSAM's sparse linear solver.

    Each iteration linearises the graph (GTSAM calls the factors, which slice the
    evaluator's vectorised Jacobians), eliminates it in ``ordering`` and steps; the error is
    the evaluator's numpy cost. While the noise levels adapt (``options.adapt_motion_prior``
    / ``adapt_angle_sigma``), every accepted step is followed by a variance-component update
    (at most ``motion_prior_rounds`` of them change the levels). Converged: an iteration left
    the noise levels as they were and either lowered the error by less than
    ``options.relative_tolerance`` or left the stations within
    ``options.step_tolerance_sigma`` standard deviations of where the iteration converges to
    (per coordinate, estimated from how fast the steps shrink: :func:`_remaining_sigmas`)
    while no board state moved by more than ``options.board_step_tolerance_rad`` /
    ``_m`` (the path is an output too). Stalled (returned as not converged, before
    ``max_iterations``): no step lowers the error, even damped.

    GTSAM's own optimisers copy the whole ``Values`` for every Python factor callback (7 s
    instead of 0.5 s for an 8 s capture); linearising a Python-owned ``Values`` does not.
    """
    error = ev.cost(values)
    ev.error_history.append(error)
    adapting = options.adapt_motion_prior or options.adapt_angle_sigma
    updates = options.motion_prior_rounds if adapting else 0
    lam = 0.0
    tree = None
    converged = False
    iterations = 0
    previous_step = None  # the last accepted station step at the current noise levels
    for iterations in range(1, options.max_iterations + 1):
        lin = graph.linearize(values)
        while True:
            system = lin if lam == 0.0 else _with(lin, _damping(values, lam))
            tree = system.eliminateMultifrontal(ordering)
            delta = tree.optimize()
            candidate = values.retract(delta)
            new_error = ev.cost(candidate)
            if new_error <= error or lam > 1e8:
                break
            lam = max(lam * 10.0, 1e-6)
        damped = lam > 0.0
        improvement = error - new_error
        station_step = _station_step_sigmas(tree, delta, len(ev.p.station_ids))
        if progress:
            progress(f"iteration {iterations}: error {new_error:.6g}")
        accepted = new_error <= error
        if accepted:
            values, error = candidate, new_error
            lam = lam / 10.0 if lam > 1e-6 else 0.0
        ev.error_history.append(error)
        if not accepted:  # no descent even with the strongest damping: stalled
            break
        rescaled = False
        if updates > 0:
            ev.at(values)
            rescaled = _update_noise_levels(ev, options, progress)
            if rescaled:
                updates -= 1
                error = ev.cost(values)
        remaining = _remaining_sigmas(station_step, previous_step)
        board_rad, board_m = _board_steps(delta, ev.p.n_states)
        board_settled = (board_rad < options.board_step_tolerance_rad
                         and board_m < options.board_step_tolerance_m)
        small = (improvement < options.relative_tolerance * max(error, 1.0)
                 or (remaining < options.step_tolerance_sigma and board_settled))
        if small and not rescaled:
            converged = True
            break
        # a damped step is measured against damped marginals: no basis for a rate
        previous_step = None if rescaled or damped else station_step
    usable = converged and not damped
    return LMOutcome(values, iterations, error, converged, tree if usable else None)


def _with(a: gtsam.GaussianFactorGraph, b: gtsam.GaussianFactorGraph
          ) -> gtsam.GaussianFactorGraph:
    out = gtsam.GaussianFactorGraph()
    out.push_back(a)
    out.push_back(b)
    return out


def _isam2(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, options: GraphOptions,
           progress: Progress | None) -> tuple[gtsam.Values, int, bool]:
    """Batch solve with iSAM2: all factors, then updates until the error stops falling;
    returns the values, the updates made and whether the error stopped falling."""
    params = gtsam.ISAM2Params()
    params.setRelinearizeThreshold(1e-9)
    params.relinearizeSkip = 1
    isam = gtsam.ISAM2(params)
    isam.update(graph, values)
    previous = np.inf
    iterations = 1
    for iterations in range(2, options.max_iterations + 1):
        isam.update()
        error = graph.error(isam.calculateEstimate())
        if progress:
            progress(f"iteration {iterations}: error {error:.6g}")
        if previous - error < 1e-6 * max(previous, 1.0):
            return isam.calculateEstimate(), iterations, True
        previous = error
    return isam.calculateEstimate(), iterations, False


def _optimise(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, problem: GraphProblem,
              ev: _Evaluator, options: GraphOptions, progress: Progress | None
              ) -> tuple[gtsam.Values, dict[int, Array], int, float, bool]:
    """Batch solve; returns values, station covariances, iterations, final error and
    whether the solver converged.

    The covariances come from the last LM iteration's eliminated system when it converged
    undamped (linearised one converged step before the result, at the final noise levels),
    otherwise from a linearisation at the result."""
    if options.solver not in ("lm", "isam2"):
        raise SolverError(f"unknown solver '{options.solver}' (expected lm or isam2)")
    ordering = elimination_ordering(problem)
    try:
        if options.solver == "lm":
            fit = _levenberg_marquardt(graph, values, ev, ordering, options, progress)
            result, iterations, error = fit.values, fit.iterations, fit.error
            converged, tree = fit.converged, fit.tree
        else:
            result, iterations, converged = _isam2(graph, values, options, progress)
            result = gtsam.Values(result)
            error = graph.error(result)
            tree = None
        if tree is None:
            tree = graph.linearize(result).eliminateMultifrontal(ordering)
        cov = {slot: tree.marginalCovariance(L(slot))
               for slot in range(1, len(problem.station_ids))}
    except RuntimeError as err:  # gtsam's IndeterminateLinearSystemException and kin
        first = next((line.strip() for line in str(err).splitlines() if line.strip()), "")
        raise SolverError(f"the linearised problem cannot be solved ({first}): some board "
                          "state or station is not determined by the data") from err
    return result, cov, iterations, error, converged


def solve_graph(board: Board, angles: Angles, models: dict[int, StationModel] | None = None,
                options: GraphOptions | None = None, progress: Progress | None = None,
                initialiser: Initialiser | None = None) -> SolveResult:
    """Calibrate every station's pose ``T_world_lh`` by the joint factor graph.

    ``angles`` as measured (rad, before factory correction), ``models`` the station models by
    index (factory calibration, rotor offsets). The world frame is the reference station's.
    ``initialiser`` gives the initial values (default :class:`PnPKabschInitialiser`).
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
    problem = build_problem(board, angles, models, reference)
    init = (initialiser or PnPKabschInitialiser())(board, angles, problem)
    timings["initialise"] = time.perf_counter() - t0
    if progress:
        progress(f"initialised {problem.n_states} board states, {len(problem.hits.angle)} hits")
    t1 = time.perf_counter()
    graph, ev = build_graph(problem, options)
    values = initial_values(init)
    result, cov, iterations, final_error, converged = _optimise(graph, values, problem, ev,
                                                                options, progress)
    timings["optimise"] = time.perf_counter() - t1
    ev.at(result)
    warnings = []
    out: dict[int, Station] = {reference: Station(np.eye(4), np.zeros((6, 6)),
                                                  problem.models[0])}
    for slot in range(1, len(problem.station_ids)):
        sid = problem.station_ids[slot]
        out[sid] = Station(ev.L[slot], cov[slot], problem.models[slot])
        sigma_m = float(np.sqrt(np.max(np.linalg.eigvalsh(cov[slot][3:, 3:]))))
        if sigma_m > options.weak_link_sigma_m:
            warnings.append(f"station {sid}: weak link to the reference (position sigma "
                            f"{sigma_m * 1e3:.0f} mm); the board was rarely seen by both")
    h = problem.hits
    z = np.abs(ev.r) / (ev.angle_sigma() * options.huber_k)
    weight = 1.0 / (1.0 + z**2) if options.loss == "cauchy" else np.minimum(1.0, 1.0 / z)
    rows = problem.hit_rows
    residuals = Residuals(angles.time[rows], angles.lighthouse[rows], h.axis,
                          angles.sensor[rows], -ev.r, weight)
    timings["total"] = time.perf_counter() - t0
    return SolveResult(
        method="graph",
        stations=Stations(reference, out),
        trajectory=Trajectory(problem.state_time, ev.X.copy()),
        residuals=residuals,
        status=("converged" if converged else "max_iterations"
                if iterations >= options.max_iterations else "stalled"),
        iterations=iterations,
        final_error=float(final_error),
        timings_s=timings,
        warnings=warnings,
        error_history=ev.error_history,
        diagnostics={"accel_psd_rot": ev.motion_psd()[0], "accel_psd_pos": ev.motion_psd()[1],
                     "motion_chi2_per_dof": ev.motion_chi2_per_dof(),
                     "angle_sigma_rad": ev.angle_sigma()},
    )
