"""Streaming calibration and tracking: sync cycles are added to an incremental smoother as
they arrive.

The first ``warmup_s`` seconds are solved in batch
(:func:`lhgraph.estimation.graph.solver.solve_graph`; tracking:
:func:`lhgraph.estimation.graph.track.track`) to
initialise; afterwards every call of :meth:`StreamingSolver.add` appends the new sweeps'
board states, bearing factors, offset priors and motion priors to GTSAM's
``IncrementalFixedLagSmoother`` (iSAM2 underneath) and returns the current station
estimate. Board states older than ``lag_s`` are marginalised; the station poses never are.
Tracking (``stations`` given, :func:`track_stream`): every station is held at its known pose,
no station variable, and each estimate carries the board states the update added.
The factors are the batch graph's (:mod:`lhgraph.estimation.graph.families`); inside iSAM2
each factor callback evaluates only its own sweep (GTSAM copies the Values for every Python
callback, so the window, not the capture, sets the cost).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import gtsam
import numpy as np
from numpy.typing import NDArray

from lhgraph.errors import InputError, SolverError
from lhgraph.estimation.graph.families.bearing import bearing_factor, bearing_keys, offset_prior
from lhgraph.estimation.graph.families.motion import motion_factor
from lhgraph.estimation.graph.loss import RobustLoss
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.graph.solver import solve_graph
from lhgraph.estimation.graph.track import (
    TrackedPath,
    largest_sigma,
    path_of,
    station_slot_poses,
    track,
    tracking_problem,
)
from lhgraph.estimation.graph.variables import (
    BOARD_POSE,
    BOARD_TWIST,
    FAMILIES,
    STATION_POSE,
    SWEEP_OFFSET,
)
from lhgraph.estimation.problem import build_problem
from lhgraph.estimation.residuals import (
    BearingHits,
    bearing_residuals,
    motion_residuals,
    wnoa_covariance,
)
from lhgraph.geometry.transforms import se3_exp
from lhgraph.io.angles import Angles
from lhgraph.io.stations import Stations
from lhgraph.io.trajectory import Trajectory
from lhgraph.model.board import Board
from lhgraph.model.station import StationModel

Array = NDArray[np.float64]
DELAY_S = 0.1
"""Default age at which a tracked state is reported (three sync cycles: a few-diode receiver's
depth from one station is poor, the other station's sweeps of the next cycles fix it)."""


@dataclass(frozen=True)
class StreamingEstimate:
    """Station poses ``T_world_lh`` (index -> 4x4) and covariances after an update; when
    tracking, ``path``: the board states reported by the update (the warm-up: all of its own;
    then those at least ``delay_s`` old, each as estimated then: smoothed by the data of that
    delay only; None when none is due)."""

    time: float
    stations: dict[int, Array]
    covariances: dict[int, Array]
    update_s: float
    path: TrackedPath | None = None


def _bearing_error(hits: BearingHits, k: int, slot: int, model: StationModel,
                   T_world_lh: Array | None) -> Callable:
    """Callback of one sweep's bearing factor, evaluating only that sweep; the station is
    held at ``T_world_lh`` when given, else it is variable ``slot`` (or the world: slot 0)."""
    models = [StationModel()] * slot + [model]
    variable = T_world_lh is None and slot > 0

    def error(_f: gtsam.CustomFactor, values: gtsam.Values, H: list | None) -> Array:
        Xk = values.atPose3(BOARD_POSE.key(k)).matrix()[None]
        Wk = values.atVector(BOARD_TWIST.key(k))[None]
        Ls = np.repeat(np.eye(4)[None], slot + 1, axis=0)
        if T_world_lh is not None:
            Ls[slot] = T_world_lh
        elif variable:
            Ls[slot] = values.atPose3(STATION_POSE.key(slot)).matrix()
        r, HX, HW, HL = bearing_residuals(hits, Xk, Wk, Ls, models, jacobians=H is not None)
        r = r + values.atVector(SWEEP_OFFSET.key(k))[0]
        if H is not None:
            H[0], H[1], H[2] = HX, HW, np.ones((len(r), 1))
            if variable:
                H[3] = HL
        return r

    return error


def _motion_error(k: int, dt: float) -> Callable:
    """Callback of the motion prior between states k and k+1."""
    def error(_f: gtsam.CustomFactor, values: gtsam.Values, H: list | None) -> Array:
        Xs = [values.atPose3(BOARD_POSE.key(j)).matrix()[None] for j in (k, k + 1)]
        Ws = [values.atVector(BOARD_TWIST.key(j))[None] for j in (k, k + 1)]
        e, He = motion_residuals(Xs[0], Ws[0], Xs[1], Ws[1], np.array([dt]),
                                 jacobians=H is not None)
        if H is not None:
            for j in range(4):
                H[j] = He[j][0]
        return e[0]

    return error


def _isam2_params() -> gtsam.ISAM2Params:
    """iSAM2 settings: gtsam's defaults (every 10th update), relinearising each variable
    family beyond its ``relinearize_threshold``: 0.1 (gtsam's default) for the poses, 1.0 for
    the twists and sweep offsets: the motion prior is linear in the twists and the bearing
    factors nearly so (they see a twist only through the < 0.2 ms spread of a sweep), and
    linear in the offsets. Relinearising them with the poses cost a 50 ms spike every 10th
    update (mean 7.8 ms against 3.7 ms, same station estimate;
    ``benchmarks/graph_benchmark.py``)."""
    params = gtsam.ISAM2Params()
    thresholds = gtsam.ISAM2ThresholdMap()
    for family in FAMILIES:
        thresholds.insert((family.symbol, np.full((family.dim, 1), family.relinearize_threshold)))
    params.setRelinearizeThreshold(thresholds)
    return params


STREAMING_UNSUPPORTED = ("diode_bias_sigma_rad", "sensor_offset_sigma_m", "gyro_preintegration",
                         "gyro_scale_sigma", "imu_time_offset_sigma_s",
                         "imu_rotation_sigma_rad", "imu_position_sigma_m", "rest_keep_every",
                         "factory_terms", "board_scale_sigma")
"""Options the streaming smoother cannot honour: refused when set, never ignored."""


class StreamingSolver:
    """Incremental calibration of the stations in ``station_ids`` (first = reference), or,
    with ``stations``, tracking with every one of them held at its pose there (the world is
    the stations file's; ``models`` default to its own), each board state reported once it is
    ``delay_s`` old (< ``lag_s``; :meth:`flush` reports the rest at the end)."""

    def __init__(self, board: Board, station_ids: list[int],
                 models: dict[int, StationModel] | None = None,
                 options: GraphOptions | None = None, lag_s: float = 0.5,
                 warmup_s: float = 1.0, stations: Stations | None = None,
                 delay_s: float = 0.0):
        self.board = board
        self.station_ids = list(station_ids)
        self.stations = stations
        self._T_world_lh = (None if stations is None
                            else station_slot_poses(stations, self.station_ids))
        if not 0 <= delay_s < lag_s:
            raise SolverError(f"delay_s must be in [0, lag_s = {lag_s:g}) (got {delay_s:g})")
        self.delay_s = delay_s
        self._queue: list[tuple[int, TrackedPath]] = []  # (first state, states) unreported
        self.models = models or {}
        if stations is not None:
            self.models = {s: stations.stations[s].model for s in self.station_ids} | self.models
        self.options = options or GraphOptions()
        unsupported = [name for name in STREAMING_UNSUPPORTED
                       if self.options.flat()[name] != GraphOptions().flat()[name]]
        if unsupported:
            raise InputError(f"the streaming smoother has no {unsupported[0]} (its "
                             "incremental graph holds bearings, sweep offsets and the motion "
                             "prior only): solve in batch, or leave it at its default",
                             where=unsupported[0])
        self.lag_s = lag_s
        self.warmup_s = warmup_s
        self._pending: list[Angles] = []
        self._smoother: gtsam.IncrementalFixedLagSmoother | None = None
        self._k = 0  # next state index
        self._last: tuple[float, Array, Array] | None = None  # time, pose, twist of last state
        self._psd = (self.options.motion.accel_psd_rot, self.options.motion.accel_psd_pos)
        self._sigma = self.options.noise.angle_sigma_rad  # the warm-up's learned value later
        robust = self.options.robust
        self._estimator = RobustLoss(robust.loss, robust.huber_k).estimator()
        self._offset_noise = gtsam.noiseModel.Isotropic.Sigma(
            1, self.options.noise.sweep_offset_sigma_rad)

    def add(self, chunk: Angles) -> StreamingEstimate | None:
        """Add the hits of one or more complete sync cycles; returns the current estimate
        (``None`` while warming up)."""
        tic = time.perf_counter()
        if self._smoother is None:
            self._pending.append(chunk)
            data = _concat(self._pending)
            if data.time[-1] - data.time[0] < self.warmup_s:
                return None
            path = self._start(data)
        else:
            path = self._extend(chunk)
        return self.estimate(time.perf_counter() - tic, path)

    def estimate(self, update_s: float = 0.0, path: TrackedPath | None = None
                 ) -> StreamingEstimate:
        """Current station poses and marginal covariances (tracking: the fixed ones, zero),
        with the board states ``path`` of the update."""
        if self._smoother is None:
            raise SolverError("no estimate yet: still warming up")
        if self._T_world_lh is not None:
            return StreamingEstimate(
                self._last[0], dict(zip(self.station_ids, self._T_world_lh, strict=True)),
                {sid: np.zeros((6, 6)) for sid in self.station_ids}, update_s, path)
        values = self._smoother.calculateEstimate()
        poses = {self.station_ids[0]: np.eye(4)}
        covs = {self.station_ids[0]: np.zeros((6, 6))}
        for slot, sid in enumerate(self.station_ids[1:], start=1):
            poses[sid] = values.atPose3(STATION_POSE.key(slot)).matrix()
            covs[sid] = self._smoother.marginalCovariance(STATION_POSE.key(slot))
        return StreamingEstimate(self._last[0], poses, covs, update_s)

    def _start(self, data: Angles) -> TrackedPath | None:
        """The warm-up batch and the smoother's start; tracking: the warm-up's path."""
        if self.stations is None:
            batch = solve_graph(self.board, data, self.models,
                                self.options.with_values(reference=self.station_ids[0]))
            path = None
        else:
            # one state per sweep, as the smoother adds them (no rotor-grid cycles)
            batch = track(self.board, data, self.stations, self.models,
                          self.options.with_values(sweep_times="stamped"))
            path = batch.path
        self._psd = (batch.diagnostics.get("accel_psd_rot", self._psd[0]),
                     batch.diagnostics.get("accel_psd_pos", self._psd[1]))
        if path is not None:
            # a filter predicts: never stiffer than the configured start, which the warm-up's
            # smoothing adaptation may undercut (on a fast hand-held deck: twice the error)
            self._psd = (max(self._psd[0], self.options.motion.accel_psd_rot),
                         max(self._psd[1], self.options.motion.accel_psd_pos))
        self._sigma = batch.diagnostics.get("angle_sigma_rad", self._sigma)
        self._smoother = gtsam.IncrementalFixedLagSmoother(self.lag_s, _isam2_params())
        graph = gtsam.NonlinearFactorGraph()
        values = gtsam.Values()
        stamps = gtsam.FixedLagSmootherKeyTimestampMap()
        trajectory = batch.trajectory if path is None else path.trajectory
        t_now = float(trajectory.time[-1])
        for slot, sid in enumerate(self.station_ids[1:] if path is None else [], start=1):
            T = batch.stations.pose(sid)
            values.insert(STATION_POSE.key(slot), gtsam.Pose3(T))
            stamps.insert((STATION_POSE.key(slot), t_now))
            # the batch result as a prior keeps what the warm-up data said about the station
            cov = batch.stations.stations[sid].covariance
            graph.add(gtsam.PriorFactorPose3(STATION_POSE.key(slot), gtsam.Pose3(T),
                                             gtsam.noiseModel.Gaussian.Covariance(cov)))
        # the last warm-up state starts the chain, with a prior from the batch solution
        T_last = trajectory.T_world_board[-1]
        T_step = np.linalg.inv(trajectory.T_world_board[-2]) @ T_last
        dt = trajectory.time[-1] - trajectory.time[-2]
        xi = gtsam.Pose3.Logmap(gtsam.Pose3(T_step)) / dt
        k = self._new_state(values, stamps, t_now, T_last, xi)
        graph.add(gtsam.PriorFactorPose3(BOARD_POSE.key(k), gtsam.Pose3(T_last),
                                         gtsam.noiseModel.Isotropic.Sigma(6, 1e-3)))
        graph.add(gtsam.PriorFactorVector(BOARD_TWIST.key(k), xi,
                                          gtsam.noiseModel.Isotropic.Sigma(6, 0.5)))
        self._smoother.update(graph, values, stamps)
        return path

    def _new_state(self, values: gtsam.Values, stamps, t: float, T: Array, xi: Array) -> int:
        k = self._k
        values.insert(BOARD_POSE.key(k), gtsam.Pose3(T))
        values.insert(BOARD_TWIST.key(k), xi)
        values.insert(SWEEP_OFFSET.key(k), np.zeros(1))
        for family in (BOARD_POSE, BOARD_TWIST, SWEEP_OFFSET):
            stamps.insert((family.key(k), t))
        self._k += 1
        self._last = (t, T, xi)
        return k

    def _extend(self, chunk: Angles) -> TrackedPath | None:
        if self.stations is None:
            problem = build_problem(self.board, chunk, self.models, self.station_ids[0],
                                    self.station_ids)
        else:
            problem = tracking_problem(self.board, chunk, self.stations, self.models,
                                       self.station_ids)[0]
        tracking = self._T_world_lh is not None
        first = self._k
        graph = gtsam.NonlinearFactorGraph()
        values = gtsam.Values()
        stamps = gtsam.FixedLagSmootherKeyTimestampMap()
        h = problem.hits
        for j in range(problem.n_states):
            t_prev, T_prev, xi = self._last
            t = float(problem.state_time[j])
            dt = t - t_prev
            k = self._new_state(values, stamps, t, T_prev @ se3_exp(dt * xi), xi)
            a, b = problem.bounds[j], problem.bounds[j + 1]
            slot = int(problem.state_station[j])
            sweep = BearingHits(np.zeros(b - a, dtype=np.int64), h.station[a:b], h.s_board[a:b],
                                h.axis[a:b], h.dt[a:b], h.angle[a:b])
            fixed = self._T_world_lh[slot] if tracking else None
            graph.add(bearing_factor(
                bearing_keys(k, None if tracking or slot == 0 else slot), int(b - a),
                self._sigma, self._estimator,
                _bearing_error(sweep, k, slot, problem.models[slot], fixed)))
            graph.add(offset_prior(k, self._offset_noise))
            Q = wnoa_covariance(np.array([dt]), *self._psd)[0]
            graph.add(motion_factor(k - 1, Q, _motion_error(k - 1, dt)))
        t_now = self._last[0]
        for slot in range(1, 1 if tracking else len(self.station_ids)):
            stamps.insert((STATION_POSE.key(slot), t_now))
        # after a gap, queued states this update marginalises are reported first, younger
        early = (self._report(self._smoother.calculateEstimate(), t_now - self.lag_s + 0.05, 0)
                 if tracking and self._queue
                 and self._queue[0][1].trajectory.time[0] < t_now - self.lag_s + 0.05 else None)
        self._smoother.update(graph, values, stamps)
        current = self._smoother.calculateEstimate()
        self._last = (t_now, current.atPose3(BOARD_POSE.key(self._k - 1)).matrix(),
                      current.atVector(BOARD_TWIST.key(self._k - 1)))
        if not tracking:
            return None
        K = problem.n_states
        self._queue.append((first, path_of(problem, np.zeros((K, 4, 4)), np.zeros(K))))
        due = [p for p in (early, self._report(current, t_now - self.delay_s)) if p]
        return TrackedPath.concatenate(due) if due else None

    def _report(self, values: gtsam.Values, until: float, end: int = -1) -> TrackedPath | None:
        """The queued states of every update whose last (``end=0``: first) state is not after
        ``until``, at their estimates in ``values`` with their position sigmas (None if
        none)."""
        ready = [q for q in self._queue if q[1].trajectory.time[end] <= until]
        if not ready:
            return None
        self._queue = self._queue[len(ready):]
        parts = []
        for first, states in ready:
            keys = [BOARD_POSE.key(k) for k in range(first, first + len(states.hits))]
            T = np.stack([values.atPose3(key).matrix() for key in keys])
            cov = np.stack([self._smoother.marginalCovariance(key) for key in keys])
            parts.append(dataclasses.replace(
                states, trajectory=Trajectory(states.trajectory.time, T),
                sigma_m=largest_sigma(cov)))
        return TrackedPath.concatenate(parts)

    def flush(self) -> StreamingEstimate:
        """The estimate with every state not reported yet (tracking, at the end of a stream)."""
        if self._smoother is None:
            raise SolverError("no estimate yet: still warming up")
        return self.estimate(0.0, self._report(self._smoother.calculateEstimate(), np.inf))


def _concat(chunks: list[Angles]) -> Angles:
    """One Angles table from consecutive chunks."""
    cols = ("time", "lighthouse", "axis", "sensor", "angle")
    parts = {c: np.concatenate([getattr(a, c) for a in chunks]) for c in cols}
    extra = {k: np.concatenate([a.extra[k] for a in chunks]) for k in chunks[0].extra}
    return Angles(**parts, extra=extra)


def track_stream(board: Board, angles: Angles, stations: Stations,
                 models: dict[int, StationModel] | None = None,
                 options: GraphOptions | None = None, lag_s: float = 0.5,
                 warmup_s: float = 0.5, delay_s: float = DELAY_S
                 ) -> Iterator[StreamingEstimate]:
    """Track the board through ``angles`` one sync cycle at a time (:func:`cycles`) with every
    station held at its pose in ``stations``: one estimate per cycle after the warm-up, its
    ``path`` the states that became ``delay_s`` old (the first: the warm-up's batch path),
    and a last one with the states still unreported."""
    solver = StreamingSolver(board, angles.stations(), models, options, lag_s, warmup_s,
                             stations, delay_s)
    for chunk in cycles(angles):
        estimate = solver.add(chunk)
        if estimate is not None:
            yield estimate
    if solver._smoother is not None:
        yield solver.flush()


def cycles(angles: Angles, cycle_s: float = 4 / 120.0) -> Iterator[Angles]:
    """Split a capture into consecutive chunks of whole sweeps, about ``cycle_s`` long (one
    LH1 sync cycle of 4 slots by default), as they would arrive live."""
    sweep = angles.sweep_ids()
    first = np.r_[0, np.flatnonzero(np.diff(sweep)) + 1]
    start_time = angles.time[first]
    edges = np.searchsorted(start_time, np.arange(start_time[0], start_time[-1] + cycle_s,
                                                  cycle_s), side="left")
    bounds = np.r_[first[np.unique(edges[edges < len(first)])], len(sweep)]
    for a, b in zip(bounds[:-1], bounds[1:], strict=True):
        if b > a:
            yield angles.select(np.arange(a, b))
