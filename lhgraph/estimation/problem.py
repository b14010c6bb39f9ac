"""The measurements arranged as a graph problem: one board state per sweep, hits sorted by state."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from lhgraph.estimation.residuals import BearingHits
from lhgraph.io.angles import Angles
from lhgraph.model.board import Board
from lhgraph.model.station import StationModel

Array = NDArray[np.float64]


@dataclass(frozen=True)
class GraphProblem:
    """The measurements arranged as a graph: one state per sweep, hits sorted by state."""

    station_ids: list[int]            # station slot -> station index; slot 0 = reference
    models: list[StationModel]
    state_time: Array                 # (K,) s
    state_station: NDArray[np.int64]  # (K,) station slot of each sweep
    hits: BearingHits
    hit_rows: NDArray[np.int64]       # (N,) row of each sorted hit in the input table
    bounds: NDArray[np.int64]         # (K + 1,) hit slice of state k = bounds[k]:bounds[k+1]
    hit_sensor: NDArray[np.int64]     # (N,) board row of each sorted hit's sensor
    n_sensors: int                    # the board's sensor count
    state_capture: NDArray[np.int64] | None = None
    """(K,) capture of each state when the angles join several captures (their ``capture``
    column, :mod:`lhgraph.io.captures`): no motion prior links states of two captures."""
    station_priors: dict[int, tuple[Array, Array, Array]] | None = None
    """Station slot -> (``T_world_lh``, the 6x6 covariance that weighs it, the honest one):
    an earlier result's prior on that station (:mod:`lhgraph.estimation.station_prior`);
    None: none."""

    def linked(self) -> NDArray[np.bool_]:
        """(K - 1,) whether states k and k + 1 belong to one capture (a motion prior links
        them)."""
        if self.state_capture is None:
            return np.ones(max(self.n_states - 1, 0), dtype=bool)
        return self.state_capture[1:] == self.state_capture[:-1]

    @property
    def n_states(self) -> int:
        return len(self.state_time)


def build_problem(board: Board, angles: Angles, models: dict[int, StationModel],
                  reference: int, station_ids: list[int] | None = None) -> GraphProblem:
    """Group hits into sweeps (one board state each) and order everything for the graph.

    ``station_ids`` fixes the station slots (slot 0 = reference); by default the stations
    present in ``angles``."""
    if station_ids is None:
        station_ids = [reference] + [s for s in angles.stations() if s != reference]
    slot_of = {s: i for i, s in enumerate(station_ids)}
    sensor_rows = angles.check_board(board)
    sweep = angles.sweep_ids()
    n_sweeps = int(sweep.max()) + 1
    counts = np.bincount(sweep, minlength=n_sweeps)
    mean_time = np.bincount(sweep, weights=angles.time, minlength=n_sweeps) / counts
    order_states = np.argsort(mean_time, kind="stable")
    state_of_sweep = np.empty(n_sweeps, dtype=np.int64)
    state_of_sweep[order_states] = np.arange(n_sweeps)
    state = state_of_sweep[sweep]
    rows = np.lexsort((angles.time, state))
    state = state[rows]
    station_slot = np.array([slot_of[s] for s in angles.lighthouse[rows].tolist()], dtype=np.int64)
    state_time = mean_time[order_states]
    hits = BearingHits(
        state=state,
        station=station_slot,
        s_board=board.positions[sensor_rows[rows]],
        axis=angles.axis[rows],
        dt=angles.time[rows] - state_time[state],
        angle=angles.angle[rows],
    )
    bounds = np.searchsorted(state, np.arange(n_sweeps + 1))
    state_station = station_slot[bounds[:-1]]
    capture = angles.extra.get("capture")
    state_capture = (None if capture is None else
                     np.asarray(capture, dtype=np.int64)[rows][bounds[:-1]])
    return GraphProblem(station_ids, [models.get(s, StationModel()) for s in station_ids],
                        state_time, state_station, hits, rows, bounds,
                        sensor_rows[rows], len(board.positions), state_capture)


def expand_ranges(first: NDArray[np.int64], count: NDArray[np.int64]
                  ) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """The ranges ``first[j] : first[j] + count[j]`` laid end to end: each element's range
    ``j`` and its index, both ``(count.sum(),)``."""
    owner = np.repeat(np.arange(len(count)), count)
    return owner, np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count) + first[owner]
