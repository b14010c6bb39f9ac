"""The light's residuals of a path already reported (a streaming track's), against stations
held fixed: :func:`path_residuals`, what the streaming track's verdict judges.

A streaming track reports each board state once, as estimated then; no graph is left at the
end to read residuals from. Here every hit of the capture is predicted from its state's
reported pose by the shared measurement model
(:func:`lhgraph.estimation.residuals.bearing_residuals`), as the batch graph would:

1. the states of the capture (one per sweep, as the streaming smoother has them) matched to
   the path's by time (hits of states the path does not hold are left out);
2. each state's body twist from the reported poses around it (central differences), so a
   hit's offset in time from its state moves the board as in the graph;
3. each sweep's common offset as the graph estimates it: the residuals' mean shrunk by its
   zero-mean prior (``sweep_offset_sigma_rad`` against the diodes' noise);
4. robust weights of the graph's loss at the residuals' own robust spread (the noise level
   the graph would learn).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from lhgraph.estimation.graph.loss import RobustLoss
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.graph.track import TrackedPath, tracking_problem
from lhgraph.estimation.residuals import bearing_residuals
from lhgraph.estimation.result import Residuals
from lhgraph.estimation.spread import robust_sigma
from lhgraph.geometry.transforms import inverse, se3_log
from lhgraph.io.angles import Angles
from lhgraph.io.stations import Stations
from lhgraph.model.board import Board
from lhgraph.model.station import StationModel

Array = NDArray[np.float64]
TIME_MATCH_S = 1e-9
"""A path state and a capture state are the same when their times agree to this (s)."""


def state_twists(time: Array, T_world_board: Array) -> Array:
    """Body twists ``[omega, v]`` (rad/s, m/s; board frame) of poses ``T_world_board``
    (K, 4, 4) at ``time`` (K,): central differences of the neighbours (one-sided at the
    ends, zero where two states share a time or there is one state)."""
    K = len(time)
    W = np.zeros((K, 6))
    if K < 2:
        return W
    before, after = np.r_[0, np.arange(K - 1)], np.r_[np.arange(1, K), K - 1]
    dt = time[after] - time[before]
    ok = dt > 0
    xi = se3_log(inverse(T_world_board[before[ok]]) @ T_world_board[after[ok]])
    W[ok] = xi / dt[ok, None]
    return W


def path_residuals(board: Board, angles: Angles, stations: Stations, path: TrackedPath,
                   models: dict[int, StationModel] | None = None,
                   options: GraphOptions | None = None) -> Residuals:
    """Per-hit residuals (measured - predicted, rad) and robust weights of ``angles`` against
    ``path``'s board poses with ``stations`` fixed (see the module docstring); only the hits
    of states ``path`` holds."""
    options = options or GraphOptions()
    problem, T_world_lh = tracking_problem(board, angles, stations, models)
    t = problem.state_time
    j = np.clip(np.searchsorted(path.trajectory.time, t), 0, len(path.trajectory.time) - 1)
    # the nearest path state at or after, or the one before
    prev = np.clip(j - 1, 0, None)
    closer = np.abs(path.trajectory.time[prev] - t) < np.abs(path.trajectory.time[j] - t)
    j = np.where(closer, prev, j)
    if len(path.trajectory.time) == len(t) and np.allclose(path.trajectory.time, t,
                                                           atol=TIME_MATCH_S):
        j = np.arange(len(t))
    held = np.abs(path.trajectory.time[j] - t) <= TIME_MATCH_S
    X = path.trajectory.T_world_board[j]
    W = state_twists(path.trajectory.time, path.trajectory.T_world_board)[j]
    hits = problem.hits
    r = bearing_residuals(hits, X, W, T_world_lh, problem.models, False)[0]
    keep = held[hits.state]
    # each sweep's offset as the graph estimates it: the mean shrunk by its prior
    sigma = float(robust_sigma(r[keep], about_zero=True)) if np.any(keep) else 1.0
    n = np.bincount(hits.state[keep], minlength=problem.n_states)
    total = np.bincount(hits.state[keep], weights=r[keep], minlength=problem.n_states)
    offset = -total / (n + (sigma / options.noise.sweep_offset_sigma_rad) ** 2)
    r = r + offset[hits.state]
    sigma = float(robust_sigma(r[keep], about_zero=True)) if np.any(keep) else 1.0
    loss = RobustLoss(options.robust.loss, options.robust.huber_k)
    rows = problem.hit_rows[keep]
    return Residuals(angles.time[rows], angles.lighthouse[rows], hits.axis[keep],
                     angles.sensor[rows], -r[keep], loss.weights(r[keep], max(sigma, 1e-12)))
