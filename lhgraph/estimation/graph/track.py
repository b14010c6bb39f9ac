"""Tracking: the receiver's path with every station held fixed at a known pose (what a lab
does with a calibration), batch: :func:`track`.

The graph is the calibration's (:func:`lhgraph.estimation.graph.factors.build_graph` with
``T_world_lh``: one bearing factor per sweep, the sweep-offset priors, the motion prior), with
no station variable; Levenberg-Marquardt and the noise adaptation as in
:func:`lhgraph.estimation.graph.solver.solve_graph`. Initial values: each station's PnP path
(:func:`lhgraph.estimation.init.pnp_kabsch.station_paths`) put into the world by the known
``T_world_lh`` and merged by time (:func:`~lhgraph.estimation.init.pnp_kabsch.world_states`).
Few-diode data (the Crazyflie deck: 4 diodes, of which a sweep holds ~3) is prepared as for
the calibration (:func:`~lhgraph.estimation.graph.resolve.prepare`: one state
per station rotor cycle) and starts from the planar twins with the stations known
(:meth:`~lhgraph.estimation.init.few_diode.FewDiodeInitialiser.with_stations`). Each state's
position standard deviation ``sigma_m`` (from the marginal covariance) says how well its
sweep and its neighbours determine it: where the receiver went unseen for long, the path is
the motion prior's bridge and ``sigma_m`` grows.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial
from typing import Any

import numpy as np
from numpy.typing import NDArray

from lhgraph.errors import InputError, SolverError
from lhgraph.estimation.graph.batch import build_and_optimise
from lhgraph.estimation.graph.evaluator import FactorEvaluator
from lhgraph.estimation.graph.optimizer import OptimizerResult
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.graph.resolve import prepare, resolve_options
from lhgraph.estimation.graph.solver import say_resolution
from lhgraph.estimation.graph.variables import BOARD_POSE
from lhgraph.estimation.imu.inertial import inertial_data, start_with_imu
from lhgraph.estimation.init.few_diode import FewDiodeInitialiser
from lhgraph.estimation.init.pnp import board_poses
from lhgraph.estimation.init.pnp_kabsch import (
    Initialisation,
    PoseSolver,
    station_paths,
    world_states,
)
from lhgraph.estimation.problem import GraphProblem, build_problem, expand_ranges
from lhgraph.estimation.residuals import BearingHits, bearing_residuals
from lhgraph.estimation.result import Residuals
from lhgraph.estimation.spread import robust_sigma
from lhgraph.geometry.transforms import se3_exp
from lhgraph.io.angles import Angles
from lhgraph.io.imu import ImuStream
from lhgraph.io.stations import Stations
from lhgraph.io.trajectory import Trajectory
from lhgraph.model.board import Board
from lhgraph.model.station import StationModel

Array = NDArray[np.float64]
Progress = Callable[[str], None]
TRACK_CROSS_GAP_S = 0.5
"""How far apart in time two stations' planar twins are compared when the stations are known
(:class:`FewDiodeInitialiser`'s ``cross_max_gap_s``): on a simulated deck with 30 % of hits
dropped it halves the states started in the mirror twin (138 -> 47 of 1200) and the LM
iterations (46 -> 16) against the calibration's 0.05 s."""
PNP_MIN_SENSORS = 5
"""Sensors a PnP pose needs on both axes (few-diode receivers start from planar twins)."""


@dataclass(frozen=True)
class TrackedPath:
    """Board states of a tracked path: ``trajectory`` (``T_world_board``, one state per sweep,
    per station rotor cycle on few-diode data, in the stations' world) and per state the
    sweeping station's index ``lighthouse``, the diodes it hit ``hits`` and the position
    standard deviation ``sigma_m`` (m, the largest axis of the marginal position
    covariance)."""

    trajectory: Trajectory
    lighthouse: NDArray[np.int64]
    hits: NDArray[np.int64]
    sigma_m: Array

    def columns(self) -> dict[str, NDArray]:
        """The trajectory CSV's added columns, in order."""
        return {"lighthouse": self.lighthouse, "hits": self.hits, "sigma_m": self.sigma_m}

    @staticmethod
    def concatenate(parts: list[TrackedPath]) -> TrackedPath:
        """One path from consecutive ones."""
        return TrackedPath(
            Trajectory(np.concatenate([p.trajectory.time for p in parts]),
                       np.concatenate([p.trajectory.T_world_board for p in parts])),
            *(np.concatenate([getattr(p, c) for p in parts])
              for c in ("lighthouse", "hits", "sigma_m")))


def path_of(problem: GraphProblem, T_world_board: Array, sigma_m: Array) -> TrackedPath:
    """The :class:`TrackedPath` of ``problem``'s states at poses ``T_world_board``."""
    ids = np.asarray(problem.station_ids)
    return TrackedPath(Trajectory(problem.state_time, T_world_board), ids[problem.state_station],
                       np.diff(problem.bounds), sigma_m)


@dataclass(frozen=True)
class TrackResult:
    """A batch track: the ``path``; ``initialised`` = PnP poses the start was made of (0 for
    few-diode data, which starts from planar twins); the
    optimiser's status and iterations; timings (s); the learned noise levels; with an IMU
    its estimated ``imu_bias`` ``[gyro (rad/s), accelerometer (m/s^2)]`` (6,) and
    ``gravity`` (3,) m/s^2 in the stations' world; the per-hit ``residuals`` of the light
    at the result (measured - predicted angle, robust weights), as a solve's."""

    path: TrackedPath
    initialised: int
    status: str
    iterations: int
    timings_s: dict[str, float] = field(default_factory=dict)
    diagnostics: dict[str, float] = field(default_factory=dict)
    imu_bias: Array | None = None
    gravity: Array | None = None
    options: dict[str, dict[str, Any]] = field(default_factory=dict)
    """The options the track ran with, every choice resolved, by group."""
    option_rules: list[str] = field(default_factory=list)
    """One line per rule that changed the options given."""
    residuals: Residuals | None = None


def station_slot_poses(stations: Stations, station_ids: list[int]) -> Array:
    """``T_world_lh`` (S, 4, 4) of ``station_ids`` in order; SolverError naming the stations
    seen in the angles that ``stations`` does not hold."""
    missing = [s for s in station_ids if s not in stations.stations]
    if missing:
        raise SolverError(f"station(s) {missing} seen in the angles but not in the stations "
                          f"(which hold {stations.indices()})")
    return np.stack([stations.pose(s) for s in station_ids])


def tracking_problem(board: Board, angles: Angles, stations: Stations,
                     models: dict[int, StationModel] | None = None,
                     station_ids: list[int] | None = None) -> tuple[GraphProblem, Array]:
    """The graph problem of ``angles`` (slots = ``station_ids``, default the stations seen, in
    index order) and the fixed ``T_world_lh`` (S, 4, 4) of its slots. Station models:
    ``models`` where given, else the stations file's own."""
    ids = angles.stations() if station_ids is None else station_ids
    T_world_lh = station_slot_poses(stations, ids)
    merged = {s: stations.stations[s].model for s in ids} | dict(models or {})
    return build_problem(board, angles, merged, ids[0], ids), T_world_lh


def initial_path(board: Board, angles: Angles, problem: GraphProblem, T_world_lh: Array,
                 pose_solver: PoseSolver | None = None, max_pnp_gap_s: float = 0.02
                 ) -> tuple[Initialisation, int]:
    """Initial board poses and twists at the problem's states, and how many PnP poses they
    rest on: every station's PnP path in the known world, merged by time and interpolated,
    then the position of each state more than ``max_pnp_gap_s`` from any
    PnP pose from the bearings around it (:func:`snapshot_poses`)."""
    solver = pose_solver or partial(board_poses, min_sensors=PNP_MIN_SENSORS)
    paths = station_paths(board, angles, problem, solver)
    n = sum(len(p[0]) for p in paths)
    if n == 0:
        raise SolverError(f"no azimuth/elevation pair of any station saw enough of the "
                          f"board's {len(board.positions)} diodes for a pose: cannot start "
                          "the path")
    t = problem.state_time
    X0, V0 = world_states(paths, T_world_lh, t)
    # states without a PnP pose near them: position from the bearings around them
    t_pnp = np.sort(np.concatenate([p[0] for p in paths]))
    i = np.searchsorted(t_pnp, t)
    near = np.minimum(np.abs(t - t_pnp[np.maximum(i - 1, 0)]),
                      np.abs(t_pnp[np.minimum(i, len(t_pnp) - 1)] - t))
    X0 = snapshot_poses(problem, X0, V0, T_world_lh, np.flatnonzero(near > max_pnp_gap_s))
    V0 = world_states([(problem.state_time, X0, None)], np.eye(4)[None], problem.state_time)[1]
    return Initialisation(T_world_lh, X0, V0), n


def _window_hits(problem: GraphProblem, states: NDArray[np.int64], window_s: float
                 ) -> BearingHits:
    """For each of ``states`` (j-th: state j of the result), the hits of every state within
    ``window_s`` of it, as hits of that state (``dt`` from its time)."""
    t = problem.state_time
    lo = np.searchsorted(t, t[states] - window_s, side="left")
    hi = np.searchsorted(t, t[states] + window_s, side="right")
    first = problem.bounds[lo]
    count = problem.bounds[hi] - first
    state, rows = expand_ranges(first, count)
    h = problem.hits
    return BearingHits(state, h.station[rows], h.s_board[rows], h.axis[rows],
                       t[h.state[rows]] + h.dt[rows] - t[states][state], h.angle[rows])


def _sum_by_state(state: NDArray[np.int64], x: Array, K: int) -> Array:
    """Sums (K, ...) of the rows of ``x`` (n, ...) by ``state``."""
    flat = x.reshape(len(x), -1)
    out = np.stack([np.bincount(state, flat[:, j], K) for j in range(flat.shape[1])], axis=1)
    return out.reshape((K,) + x.shape[1:])


def snapshot_poses(problem: GraphProblem, X: Array, V: Array, T_world_lh: Array,
                   states: NDArray[np.int64], window_s: float = 0.02, iterations: int = 8
                   ) -> Array:
    """Board poses ``T_world_board`` (K, 4, 4) with the positions of ``states`` refined, each
    on its own, from ``X`` by damped Gauss-Newton on the bearings of every hit within
    ``window_s`` of it (both stations, both axes: what a few-diode receiver gives in about one
    sync cycle), moved by the twists ``V``, Cauchy-weighted; rotations kept; a state its
    window does not determine stays near its start. Vectorised over the states."""
    hits = _window_hits(problem, states, window_s)
    K = len(states)
    X = X.copy()
    if K == 0:
        return X
    for _ in range(iterations):
        r, H, _, _ = bearing_residuals(hits, X[states], V[states], T_world_lh, problem.models)
        scale = max(3.0 * robust_sigma(r, about_zero=True), 1e-4)
        w = 1.0 / (1.0 + (r / scale) ** 2)
        H = H[:, 3:]  # position only: a few diodes leave the rotation barely determined
        A = _sum_by_state(hits.state, w[:, None, None] * H[:, :, None] * H[:, None, :], K)
        b = _sum_by_state(hits.state, (w * r)[:, None] * H, K)
        damping = 1e-3 * np.trace(A, axis1=1, axis2=2) + 1e-12
        step = np.zeros((K, 6))
        step[:, 3:] = np.linalg.solve(A + damping[:, None, None] * np.eye(3), -b[..., None])[..., 0]
        X[states] = X[states] @ se3_exp(step)
    return X


def largest_sigma(pose_covariances: Array) -> Array:
    """The largest position standard deviation (m) of each pose covariance (n, 6, 6)
    (tangent order [rx, ry, rz, tx, ty, tz]; the translation block's eigenvalues do not
    depend on the frame it is expressed in)."""
    return np.sqrt(np.linalg.eigvalsh(pose_covariances[:, 3:, 3:])[:, -1])


def state_sigmas(fit: OptimizerResult, ev: FactorEvaluator) -> Array:
    """Per state, the largest position standard deviation (m) of its marginal covariance."""
    return largest_sigma(np.stack([fit.covariance(key) for key in ev.layout.keys(BOARD_POSE)]))


def track(board: Board, angles: Angles, stations: Stations,
          models: dict[int, StationModel] | None = None, options: GraphOptions | None = None,
          pose_solver: PoseSolver | None = None, progress: Progress | None = None,
          imu: ImuStream | None = None) -> TrackResult:
    """The board's path ``T_world_board`` (one state per sweep; per station rotor cycle on
    few-diode data) with every station held at its
    ``T_world_lh`` in ``stations`` (the world is the stations file's). ``angles`` as measured
    (rad, before factory correction); ``models`` by station index (default: the stations
    file's); ``pose_solver`` the per-measurement PnP of a many-diode board (default: planar
    homography; few-diode data starts from :meth:`FewDiodeInitialiser.with_stations`);
    ``imu`` the receiver's IMU stream (board frame, the angles' clock): gyro and
    accelerometer factors join the graph (:mod:`lhgraph.estimation.imu.inertial`), the initial
    angular rates are the gyro's, and the IMU bias and the world's gravity are estimated."""
    options = options or GraphOptions()
    if options.data.rest_keep_every > 1:
        raise InputError("the tracker keeps every hit (the path is the product): "
                         "rest_keep_every thins the calibration's rests only; leave it at 1",
                         where="rest_keep_every")
    t0 = time.perf_counter()
    angles, facts = prepare(angles, options, models or {k: stations.stations[k].model
                                                        for k in stations.indices()},
                            progress)
    resolution = resolve_options(options, facts, inertial=imu is not None, tracking=True)
    say_resolution(resolution, progress)
    options, few = resolution.options, facts.few_diode
    problem, T_world_lh = tracking_problem(board, angles, stations, models)
    if few:
        init = FewDiodeInitialiser(cross_max_gap_s=TRACK_CROSS_GAP_S).with_stations(
            board, angles, problem, T_world_lh)
        n_pnp = 0
    else:
        init, n_pnp = initial_path(board, angles, problem, T_world_lh, pose_solver)
    inertial = gravity = None
    if imu is not None:
        if options.imu.calibration_from_light:
            raise InputError("the tracker finds no IMU calibration for GTSAM's combined IMU "
                             "factors (the calibration finds it from a light-only solution): "
                             "use imu_factors = 'twist' or 'auto'", where="imu_factors")
        inertial = inertial_data(imu, problem.state_time, options.imu.imu_max_gap_s)
        init, gravity = start_with_imu(init, inertial)
    timings = {"initialise": time.perf_counter() - t0}
    if progress:
        progress(f"initialised {problem.n_states} board states"
                 + (f" from {n_pnp} PnP poses" if n_pnp else " from planar twins")
                 + ("" if inertial is None else
                    f"; IMU factors at {int(inertial.rate_ok.sum())} states"))
    fit, ev, sigma = build_and_optimise(problem, options, init, state_sigmas, progress,
                                        T_world_lh, inertial, gravity)
    ev.evaluate(fit.values)
    timings["optimise"] = time.perf_counter() - t0 - timings["initialise"]
    return TrackResult(
        path=path_of(problem, ev.board_poses().copy(), sigma),
        initialised=n_pnp,
        status=fit.status.value,
        iterations=fit.iterations,
        timings_s=timings,
        diagnostics=ev.summary(),
        imu_bias=ev.imu_bias(),
        gravity=ev.gravity(),
        options=options.nested(),
        option_rules=list(resolution.applied),
        residuals=Residuals(angles.time[problem.hit_rows], angles.lighthouse[problem.hit_rows],
                            problem.hits.axis, angles.sensor[problem.hit_rows],
                            -ev.bearing.residuals(), ev.bearing.robust_weights()),
    )
