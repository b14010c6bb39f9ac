"""The information the data hold about the stations: a Cramér–Rao-type bound at the truth.

The graph's own measurement model (bearing factors, sweep offsets, the white-noise-on-
acceleration motion prior) is linearised at the true values instead of an estimate and
eliminated as the solver does; the inverse information of each station is the covariance
an efficient estimator of that model would reach. The per-diode robust loss is replaced by
a Gaussian (the bound of the direct hits). Two variants: the motion prior at the strength
the true motion has (its chi2 per degree of freedom at the truth made 1), and the board's
path known (its poses and twists held at the truth), a floor for any estimate of the path.
``benchmarks/crlb.py`` compares the solver's errors with it; ``tests/test_bound.py`` checks
it against the Monte-Carlo spread of the estimate.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import gtsam
import numpy as np
from numpy.typing import NDArray

from lhgraph.estimation.graph.factors import build_graph
from lhgraph.estimation.graph.options import GraphOptions
from lhgraph.estimation.graph.variables import (
    BOARD_POSE,
    BOARD_TWIST,
    STATION_POSE,
    initial_values,
)
from lhgraph.estimation.init.pnp_kabsch import Initialisation
from lhgraph.estimation.problem import GraphProblem
from lhgraph.geometry.transforms import inverse, se3_log
from lhgraph.io.stations import Stations

Array = NDArray[np.float64]
KNOWN_SIGMA = 1e-9
"""Prior spread (rad, m; rad/s, m/s) that holds a board pose or twist at the truth."""
GAUSSIAN_HUBER_K = 1e6
"""A Huber scale no residual reaches: the loss is the Gaussian's."""
TWIST_STEP_S = 1e-4
"""Half the time step of the central difference that gives the true body twists."""


@dataclass(frozen=True)
class Bound:
    """Each estimated station slot's 6x6 covariance ``[rotation, position]`` (station frame),
    and the motion-prior PSD factor the bound used (the true motion's, or 1)."""

    covariance: dict[int, Array]
    psd_factor: float

    def position_rms_m(self, slot: int) -> float:
        """``sqrt(trace)`` of the slot's position covariance: the rms length of its position
        error at the bound (m)."""
        return float(np.sqrt(np.trace(self.covariance[slot][3:, 3:])))


def true_values(pose_at: Callable[[Array], Array], stations: Stations, state_time: Array
                ) -> Initialisation:
    """The truth as graph values: ``stations``' poses by slot (world = the reference, the
    other stations in index order), and at ``state_time`` (s) the board's poses
    ``pose_at(t)`` -> ``T_world_board`` (K, 4, 4) and body twists ``[omega, v]`` (rad/s,
    m/s, board frame; central difference of ``pose_at``)."""
    truth = stations.relative_to_reference()
    slots = [truth.reference] + [s for s in sorted(truth.indices()) if s != truth.reference]
    before = pose_at(state_time - TWIST_STEP_S)
    after = pose_at(state_time + TWIST_STEP_S)
    return Initialisation(np.array([truth.pose(s) for s in slots]), pose_at(state_time),
                          se3_log(inverse(before) @ after) / (2 * TWIST_STEP_S))


def information_bound(problem: GraphProblem, truth: Initialisation, options: GraphOptions,
                      known_path: bool = False, true_motion_prior: bool = True) -> Bound:
    """The bound of ``problem``'s stations at ``truth`` (stations by slot, the board's poses
    and body twists at the state times) with ``options``' noise levels (``angle_sigma_rad``,
    ``sweep_offset_sigma_rad``, the motion PSDs); ``true_motion_prior``: the PSDs scaled to
    the true motion first; ``known_path``: the board's poses and twists held at the truth."""
    options = options.with_values(loss="huber", huber_k=GAUSSIAN_HUBER_K)
    graph, ev = build_graph(problem, options)
    values = initial_values(ev.layout, truth)
    ev.evaluate(values)
    factor = ev.motion.chi2_per_dof() if true_motion_prior else 1.0
    if true_motion_prior:
        ev.motion.scale(factor)
    linear = graph.linearize(values)
    if known_path:
        held = gtsam.noiseModel.Isotropic.Sigma(6, KNOWN_SIGMA)
        for family in (BOARD_POSE, BOARD_TWIST):
            for key in ev.layout.keys(family):
                linear.add(gtsam.JacobianFactor(key, np.eye(6), np.zeros(6), held))
    tree = linear.eliminateMultifrontal(ev.layout.elimination_ordering())
    return Bound({slot: tree.marginalCovariance(STATION_POSE.key(slot))
                  for slot in ev.layout.indices(STATION_POSE)}, float(factor))
