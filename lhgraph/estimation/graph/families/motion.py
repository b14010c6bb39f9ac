"""The motion prior between consecutive board states: :class:`MotionPrior`.

White noise on acceleration (:func:`lhgraph.estimation.residuals.motion_residuals`, its
covariance :func:`~lhgraph.estimation.residuals.wnoa_covariance` of the power spectral
densities ``accel_psd_rot`` (rad^2/s^3) and ``accel_psd_pos`` (m^2/s^3)), keys
:func:`motion_keys`; none between the last state of one capture and the first of the next
when the problem joins several (:meth:`GraphProblem.linked`).
"""

from __future__ import annotations

import gtsam
import numpy as np

from lhgraph.estimation.graph.families.base import (
    Array,
    BoardPoint,
    Ensure,
    FactorError,
    FactorFamily,
    indexed_callback,
)
from lhgraph.estimation.graph.variables import BOARD_POSE, BOARD_TWIST, VariableFamily
from lhgraph.estimation.problem import GraphProblem
from lhgraph.estimation.residuals import motion_residuals, wnoa_covariance


def motion_keys(k: int) -> list[int]:
    """Keys of the motion prior between states k and k + 1."""
    return [BOARD_POSE.key(k), BOARD_TWIST.key(k), BOARD_POSE.key(k + 1), BOARD_TWIST.key(k + 1)]


def motion_factor(k: int, covariance: Array, error: FactorError) -> gtsam.CustomFactor:
    """The motion prior between states k and k + 1 of ``covariance`` (12, 12)."""
    return gtsam.CustomFactor(gtsam.noiseModel.Gaussian.Covariance(covariance), motion_keys(k),
                              error)


class MotionPrior(FactorFamily):
    """The motion priors of one graph at PSDs ``psd`` (rotational, linear), rescaled by
    :meth:`scale` (the factors' noise models keep the configured ones: the residuals and
    Jacobians are scaled instead)."""

    name = "motion prior"
    variables: tuple[VariableFamily, ...] = (BOARD_POSE, BOARD_TWIST)

    def __init__(self, problem: GraphProblem, psd: tuple[float, float]):
        self._psd = psd
        self._dt = np.diff(problem.state_time)
        self._linked = problem.linked()
        self.covariances = wnoa_covariance(self._dt, *psd)
        """``(K - 1, 12, 12)`` covariance of each prior at the configured PSDs (the factors'
        noise models)."""
        self._Q_inv = np.linalg.inv(self.covariances)
        self._scale = 1.0  # 1/sqrt(s): the motion prior's covariance is s * Q
        self._raw: tuple | None = None
        self._ready = False
        self._e_raw = self._e = np.zeros((0, 12))

    def keys(self, i: int) -> list[int]:
        return motion_keys(i)

    def add_to(self, graph: gtsam.NonlinearFactorGraph, ensure: Ensure) -> None:
        first = graph.size()
        for k in np.flatnonzero(self._linked).tolist():
            graph.add(motion_factor(k, self.covariances[k], indexed_callback(
                ensure, (k, k + 1), k, self, lambda: self._e, lambda: self._He)))
        self.indices = range(first, graph.size())

    def read(self, values: gtsam.Values, point: BoardPoint) -> None:
        X, W = point.X, point.W
        self._point = point
        self._e_raw = motion_residuals(X[:-1], W[:-1], X[1:], W[1:], self._dt, False)[0]
        self._raw = None
        self._rescale()

    def jacobians(self) -> None:
        if self._ready:
            return
        if self._raw is None:
            X, W = self._point.X, self._point.W
            self._raw = motion_residuals(X[:-1], W[:-1], X[1:], W[1:], self._dt)[1]
        self._He = tuple(H * self._scale for H in self._raw)
        self._ready = True

    def cost(self, values: gtsam.Values) -> float:
        return float(0.5 * self.chi2().sum())

    def chi2(self) -> Array:
        """Whitened squared residual ``e^T Q^-1 e`` of every prior in the graph (the linked
        pairs of states)."""
        chi2 = np.einsum("ki,kij,kj->k", self._e, self._Q_inv, self._e)
        return chi2[self._linked]

    def scale(self, factor: float) -> None:
        """Multiply the prior's covariance by ``factor`` (before the first evaluation
        too)."""
        self._scale /= np.sqrt(factor)
        self._rescale()

    def psd_factor(self) -> float:
        """Effective PSDs over the configured ones."""
        return self._scale ** -2

    def psd(self) -> tuple[float, float]:
        """Effective (rotational, linear) acceleration PSD now."""
        s = self._scale ** -2
        return self._psd[0] * s, self._psd[1] * s

    def chi2_per_dof(self) -> float:
        """Mean whitened squared residual per degree of freedom under the current prior (1
        if its strength matches the solved motion)."""
        return float(np.mean(self.chi2()) / 12)

    def _rescale(self) -> None:
        self._e = self._e_raw * self._scale
        self._ready = False
