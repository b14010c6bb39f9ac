"""Moved-station watch (``lhgraph track --watch``, docs/track.md): is every station still
where the calibration put it, all through a capture?

A station bumped mid-capture does not show in the tracker's residuals: with the stations held
fixed, the board path absorbs the change (measured on a simulated 32-diode board shifted 10 mm
in x: the per-station residual spread rose 40 -> 55 urad, the deck's 30 -> 35 urad; a
0.2 deg turn 40 -> 60 urad, within what a fast wave does). What does show is the stations'
*relative* pose re-estimated from a short stretch of the capture. So the watch:

1. cuts the capture into windows of ``window_s`` every ``step_s``, and keeps those in which
   the board moves (a still board leaves a window's solve where it started; the change from
   rest to motion read as a 160 mm "move" on the LH1 flight log);
2. solves each window's graph with every station free but the reference
   (:func:`~lhgraph.estimation.graph.solver.solve_graph`, white covariance), started from the
   calibration and the tracked path (:class:`CalibrationStart`; no initialiser to fail on a
   short window);
3. per station, the window's difference from the calibration ``e = log(T_cal^-1 T_win)``
   (``[rotation rad, translation m]`` in the station's own frame);
4. tests it against the station's history, the windows before it that do not overlap it
   (:class:`StationWatch`, at least ``min_history`` of them): ``z`` = the Mahalanobis
   distance of ``e`` from the history's median in the window's white covariance, divided by
   how much wider than their own white covariances the history's windows scatter (the
   square root of the 90 % point of their squared distances over a 6-dof chi-square's, at
   least 1). The window is *out* when ``z`` exceeds ``k_sigma`` and the difference exceeds
   ``floor_mm`` or ``floor_deg``;
5. ``sustain`` out windows in a row: the station moved, at the first one's centre (± half a
   window), detected at the last one's end; its history starts again after the move.

Why a scatter from the history and not the white covariance alone: on real recordings the
window solves wander far beyond it as the board moves about (hive 8.11, 3 s windows: white
sigma ~1.2 mm, the windows 8-32 mm from the calibration; Crazyflie decks: ~15 mm against
~100 mm), from model errors the calibration averages away. The defaults (10 windows of
history, 10 sigma) are the ones under which no shared real log raises an alarm while the
simulated 10 mm / 0.2 deg moves are found (docs/results/moved_station_watch.md).

The history makes it a change test: a calibration a few mm off throughout (another
recording's, real-data accuracy) is the track's verdict's business, not a move. A capture
with one reference and one other station sees relative motion only: the move is the
non-reference station's; with three stations or more, every other station out at once is
the reference's move. Causal (each window needs data up to its end only), so the batch
and the streaming watch (:meth:`StationWatch.add` per window as it completes) agree.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from lhgraph.errors import LhgraphError
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.graph.solver import solve_graph
from lhgraph.estimation.init.pnp_kabsch import Initialisation, world_states
from lhgraph.estimation.problem import GraphProblem
from lhgraph.estimation.rests import motion_rate
from lhgraph.estimation.watch_options import WatchOptions
from lhgraph.geometry.transforms import inverse, se3_log
from lhgraph.io.angles import Angles
from lhgraph.io.stations import Stations
from lhgraph.model.board import Board
from lhgraph.model.station import StationModel

Array = NDArray[np.float64]
Progress = Callable[[str], None]
HISTORY_QUANTILE, CHI2_6_Q90 = 0.9, 10.645
"""The history's scatter is read at its 90 % point of the squared distances, against a 6-dof
chi-square's (10.645): real recordings' windows scatter with heavy tails, which the median
undercuts (own-calibration peaks of the shared logs 9.7 -> 7.2 sigma, the simulated moves
unchanged; docs/track.md)."""
BIN_S = 0.25
"""The bins (s) of :func:`~lhgraph.estimation.rests.motion_rate` by which a window's motion
is judged."""


@dataclass(frozen=True)
class WindowDifference:
    """One window ``[t0_s, t1_s)``: per station seen (not the reference), the difference
    from the calibration ``e`` (6,) = ``[rotation rad, translation m]`` in the station's
    frame and the window solve's white covariance of it ``cov`` (6, 6)."""

    t0_s: float
    t1_s: float
    e: dict[int, Array]
    cov: dict[int, Array]


@dataclass(frozen=True)
class WindowTest:
    """A station's test in one window: the distance from its history's median in history
    sigmas ``z``, the size of the difference from that median (``position_m``,
    ``rotation_rad``) and whether the window is out."""

    station: int
    t0_s: float
    t1_s: float
    z: float
    position_m: float
    rotation_rad: float
    out: bool


@dataclass(frozen=True)
class StationMove:
    """A station found moved: at ``t_s`` (within ``t_uncertainty_s``: half the first out
    window), detected at ``detected_s`` (both on the capture's clock), by ``position_m`` /
    ``rotation_rad`` (the last out window's difference from the history) at ``z`` history
    sigmas (the smallest of its out windows); ``reference``: the reference station's move,
    seen as every other station's."""

    station: int
    t_s: float
    t_uncertainty_s: float
    detected_s: float
    position_m: float
    rotation_rad: float
    z: float
    reference: bool = False

    def message(self) -> str:
        """``station N moved at t = … s (… sigma)``, with the size of the move."""
        whose = " (the reference: every other station moved alike)" if self.reference else ""
        return (f"station {self.station} moved at t = {self.t_s:.1f} s "
                f"(± {self.t_uncertainty_s:.1f} s; {self.z:.0f} sigma){whose}: "
                f"{self.position_m * 1e3:.1f} mm, {np.degrees(self.rotation_rad):.3f} deg, "
                f"detected at {self.detected_s:.1f} s")


class CalibrationStart:
    """Initial values of a window's graph: the stations where the calibration has them (in
    the reference station's frame) and the board where the track put it (interpolated at the
    window's states)."""

    def __init__(self, stations: Stations, reference: int, time: Array, T_world_board: Array):
        T_ref_world = inverse(stations.pose(reference))
        self.T_ref_lh = {k: T_ref_world @ stations.pose(k) for k in stations.indices()}
        self.time = time
        self.T_ref_board = T_ref_world @ T_world_board

    def __call__(self, board: Board, angles: Angles, problem: GraphProblem) -> Initialisation:
        """The :class:`~lhgraph.estimation.init.Initialiser` protocol."""
        L = np.stack([self.T_ref_lh[s] for s in problem.station_ids])
        X, V = world_states([(self.time, self.T_ref_board, None)], np.eye(4)[None],
                            problem.state_time)
        return Initialisation(L, X, V)


def window_starts(t_first: float, t_last: float, options: WatchOptions) -> Array:
    """Start times (s) of the whole windows in ``[t_first, t_last]``."""
    n = int(np.floor((t_last - t_first - options.window_s) / options.step_s + 1e-9)) + 1
    return t_first + options.step_s * np.arange(max(n, 0))


def window_difference(board: Board, angles: Angles, start: CalibrationStart, t0_s: float,
                      t1_s: float, models: dict[int, StationModel], options: GraphOptions
                      ) -> WindowDifference | str:
    """The window ``[t0_s, t1_s)``'s :class:`WindowDifference`, or why it has none (the
    reference unseen, one station only, the solve failing or not converging)."""
    reference = options.data.reference
    window = angles.select((angles.time >= t0_s) & (angles.time < t1_s))
    seen = window.stations()
    if reference not in seen:
        return f"reference station {reference} unseen"
    if len(seen) < 2:
        return "one station only"
    try:
        result = solve_graph(board, window, {k: models[k] for k in seen}, options,
                             initialiser=start)
    except LhgraphError as e:
        return f"no solve ({e})"
    if result.status != "converged":
        return f"solve {result.status}"
    e, cov = {}, {}
    for k in seen:
        station = result.stations.stations[k]
        white = station.covariance_white
        if k == reference or (white is None and station.covariance is None):
            continue
        e[k] = se3_log(inverse(start.T_ref_lh[k]) @ station.T_world_lh)
        cov[k] = white if white is not None else station.covariance
    return WindowDifference(t0_s, t1_s, e, cov)


def mahalanobis2(d: Array, cov: Array) -> float:
    """``d^T cov^-1 d`` (cov symmetric positive semi-definite; its null directions
    ignored)."""
    return float(d @ np.linalg.lstsq(cov, d, rcond=1e-12)[0])


@dataclass
class StationWatch:
    """The causal test (module docstring, steps 4-5): :meth:`add` one window after another
    (in time order); each returns the moves it completes."""

    options: WatchOptions
    n_stations: int
    reference: int
    history: dict[int, list[WindowDifference]] = field(default_factory=dict)
    tests: list[WindowTest] = field(default_factory=list)
    outs: dict[int, list[WindowTest]] = field(default_factory=dict)
    moves: list[StationMove] = field(default_factory=list)
    since: dict[int, float] = field(default_factory=dict)
    weak: int = 0

    def determined(self, cov: Array) -> bool:
        """Whether a window's white covariance of a station (6, 6) is within the options'
        ``max_sigma_mm`` and ``max_sigma_deg`` (the norm of each block's sigmas)."""
        sigma = np.sqrt(np.clip(np.diag(cov), 0, None))
        return bool(np.linalg.norm(sigma[3:]) <= self.options.max_sigma_mm * 1e-3
                    and np.linalg.norm(sigma[:3]) <= np.radians(self.options.max_sigma_deg))

    def add(self, window: WindowDifference) -> list[StationMove]:
        """Test every station of ``window`` against its history, then add it to the history
        of the stations not out in it. After a move the station's history starts again
        (from the windows after the move: a later bump is a new move)."""
        tested: dict[int, WindowTest] = {}
        for k in window.e:
            if window.t0_s < self.since.get(k, -np.inf):
                continue  # still holds some of the data before the last move
            if not self.determined(window.cov[k]):
                self.weak += 1
                continue
            test = self._test(k, window)
            if test is not None:
                tested[k] = test
                self.tests.append(test)
            if test is None or not test.out:
                self.outs[k] = []
                self.history.setdefault(k, []).append(window)
            else:
                self.outs[k] = self.outs.get(k, []) + [test]
        done = [k for k in tested if len(self.outs[k]) >= self.options.sustain]
        if self.n_stations >= 3 and len(tested) >= 2 and set(done) == set(tested):
            ref = self._move(self.reference, self.outs[done[0]], reference=True)
            move_of, found = {k: ref for k in done}, [ref]
        else:
            move_of = {k: self._move(k, self.outs[k]) for k in done}
            found = list(move_of.values())
        for k, move in move_of.items():
            self.outs[k], self.history[k] = [], []
            self.since[k] = move.t_s + move.t_uncertainty_s
        self.moves += found
        return found

    def _test(self, k: int, window: WindowDifference) -> WindowTest | None:
        past = [w for w in self.history.get(k, []) if w.t1_s <= window.t0_s + 1e-9]
        if len(past) < self.options.min_history:
            return None
        E = np.stack([w.e[k] for w in past])
        centre = np.median(E, axis=0)
        # how much wider the windows scatter than their white covariance says (>= 1)
        scale = max(1.0, float(np.quantile([mahalanobis2(w.e[k] - centre, w.cov[k])
                                            for w in past], HISTORY_QUANTILE)) / CHI2_6_Q90)
        d = window.e[k] - centre
        z = float(np.sqrt(mahalanobis2(d, window.cov[k]) / scale))
        position, rotation = float(np.linalg.norm(d[3:])), float(np.linalg.norm(d[:3]))
        big = (position > self.options.floor_mm * 1e-3
               or rotation > np.radians(self.options.floor_deg))
        return WindowTest(k, window.t0_s, window.t1_s, z, position, rotation,
                          bool(z > self.options.k_sigma and big))

    def _move(self, k: int, runs: list[WindowTest], reference: bool = False) -> StationMove:
        """The move of ``runs`` (out windows in time order; every other station's with
        ``reference``): at the first window's centre, its size the last window's."""
        first, last = runs[0], runs[-1]
        half = 0.5 * (first.t1_s - first.t0_s)
        return StationMove(k, first.t0_s + half, half, last.t1_s, last.position_m,
                           last.rotation_rad, min(t.z for t in runs), reference)


@dataclass(frozen=True)
class WatchResult:
    """What the watch found: the ``moves``, every station test (``tests``), the windows
    solved (``windows``), those skipped with the reason (``skipped``: ``(t0_s, why)``) and
    how many station windows were too weakly determined to test (``weak``)."""

    moves: list[StationMove]
    tests: list[WindowTest]
    windows: list[WindowDifference]
    skipped: list[tuple[float, str]]
    options: WatchOptions
    weak: int = 0

    @property
    def blind(self) -> bool:
        """No station tested in any window: the watch could not have seen a move."""
        return not self.tests

    def summary(self) -> str:
        """One line on the windows, then one per move (or that none moved)."""
        n = len(self.windows) + len(self.skipped)
        lines = [f"watch: {len(self.windows)} of {n} windows of {self.options.window_s:g} s "
                 f"solved, {len(self.tests)} station tests"]
        if self.skipped:
            reasons = sorted({why.split(" (")[0] for _, why in self.skipped})
            lines[0] += f" ({len(self.skipped)} skipped: {'; '.join(reasons)})"
        o = self.options
        if self.weak:
            lines[0] += (f"; {self.weak} station windows not determined to {o.max_sigma_mm:g} "
                         f"mm / {o.max_sigma_deg:g} deg, untested")
        if self.blind:
            lines.append(f"watch: check: no station was tested (a test needs "
                         f"{o.min_history} earlier windows of a moving board, "
                         f"{o.window_s:g} s each): this capture cannot show a move")
        elif not self.moves:
            peak = max((t.z for t in self.tests), default=float("nan"))
            lines.append(f"watch: no station moved (largest window {peak:.1f} sigma from "
                         f"its history, threshold {self.options.k_sigma:g})")
        lines += [f"MOVED: {m.message()}" for m in self.moves]
        return "\n".join(lines)


def window_graph_options(options: GraphOptions | None, reference: int) -> GraphOptions:
    """The windows' graph options: ``options`` with the watch's reference and the white
    covariance (the history gives the spread that repeats)."""
    return (options or GraphOptions()).with_values(reference=reference, covariance="white")


class Watcher:
    """The watch of one capture, window by window: :meth:`window` solves and tests one
    (batch: every window with the whole tracked path; streaming: each as soon as the path
    covers it), :meth:`result` gathers what was found. ``reference``: the station the
    others are watched from (default: the calibration's if the capture sees it, else the
    lowest seen)."""

    def __init__(self, board: Board, angles: Angles, calibration: Stations,
                 models: dict[int, StationModel], options: WatchOptions | None = None,
                 graph_options: GraphOptions | None = None, reference: int | None = None):
        seen = angles.stations()
        if reference is None:
            reference = calibration.reference if calibration.reference in seen else seen[0]
        self.board, self.angles, self.calibration, self.models = (board, angles, calibration,
                                                                  models)
        self.options = options or WatchOptions()
        self.graph_options = window_graph_options(graph_options, reference)
        self.reference = reference
        self.detector = StationWatch(self.options, len(seen), reference)
        self.windows: list[WindowDifference] = []
        self.skipped: list[tuple[float, str]] = []
        self.starts = window_starts(float(angles.time[0]), float(angles.time[-1]),
                                    self.options)
        self.done = 0
        self.bin_start, rate = motion_rate(angles, BIN_S)
        self.bin_moving = np.nan_to_num(rate, nan=0.0) > self.options.motion_threshold_rad_s

    def window(self, t0_s: float, time: Array, T_world_board: Array) -> list[StationMove]:
        """Solve and test the window starting at ``t0_s``, started from the tracked path
        (``time`` s, ``T_world_board`` (K, 4, 4) in the calibration's world); the moves it
        completes."""
        t1_s = t0_s + self.options.window_s
        bins = (self.bin_start >= t0_s) & (self.bin_start + BIN_S <= t1_s + 1e-9)
        moving = float(np.mean(self.bin_moving[bins])) if bins.any() else 0.0
        if moving < self.options.min_moving_fraction:
            self.skipped.append((t0_s, f"board still ({moving:.0%} of it moving)"))
            return []
        start = CalibrationStart(self.calibration, self.reference, time, T_world_board)
        w = window_difference(self.board, self.angles, start, t0_s,
                              t1_s, self.models, self.graph_options)
        if isinstance(w, str):
            self.skipped.append((t0_s, w))
            return []
        self.windows.append(w)
        return self.detector.add(w)

    def due(self, covered_s: float) -> bool:
        """Whether a window not yet done ends by ``covered_s`` (s)."""
        return (self.done < len(self.starts)
                and self.starts[self.done] + self.options.window_s <= covered_s)

    def catch_up(self, time: Array, T_world_board: Array, covered_s: float = np.inf,
                 progress: Progress | None = None) -> list[StationMove]:
        """Solve and test every window not yet done that ends by ``covered_s`` (s: how far
        the tracked path ``time``, ``T_world_board`` reaches; batch: all); each move is said
        through ``progress`` when found, and every 20 windows how far the watch is."""
        found = []
        while self.due(covered_s):
            moves = self.window(float(self.starts[self.done]), time, T_world_board)
            self.done += 1
            for move in moves:
                if progress:
                    progress(f"MOVED: {move.message()}")
            if progress and self.done % 20 == 0:
                progress(f"watch: {self.done} of {len(self.starts)} windows")
            found += moves
        return found

    def result(self) -> WatchResult:
        """Every move, test and window so far."""
        return WatchResult(self.detector.moves, self.detector.tests, self.windows,
                           self.skipped, self.options, self.detector.weak)


def watch(board: Board, angles: Angles, calibration: Stations, time: Array,
          T_world_board: Array, models: dict[int, StationModel],
          options: WatchOptions | None = None, graph_options: GraphOptions | None = None,
          progress: Progress | None = None) -> WatchResult:
    """The batch watch of ``angles`` (as measured, rad) against ``calibration`` (poses in
    its world), started from a tracked path (``time`` s, ``T_world_board`` (K, 4, 4) in
    the calibration's world); ``models`` by station index; progress as
    :meth:`Watcher.catch_up`'s."""
    watcher = Watcher(board, angles, calibration, models, options, graph_options)
    watcher.catch_up(time, T_world_board, progress=progress)
    return watcher.result()
