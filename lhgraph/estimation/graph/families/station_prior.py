"""Priors on the station poses from an earlier calibration: :class:`StationPriorFactors`.

One GTSAM ``PriorFactorPose3`` per station slot the problem's ``station_priors`` name (the
earlier result re-expressed in this solve's world, :mod:`lhgraph.estimation.station_prior`),
its noise model the earlier white covariance; :meth:`StationPriorFactors.whitened_errors`
gives the covariance of each whitened residual the honest covariance implies (for the new
result's honest covariance).
"""

from __future__ import annotations

import gtsam
import numpy as np

from lhgraph.estimation.graph.families.base import Ensure, FactorFamily
from lhgraph.estimation.graph.variables import STATION_POSE, VariableFamily, VariableLayout
from lhgraph.estimation.problem import GraphProblem


class StationPriorFactors(FactorFamily):
    """The station priors of one graph (slots that are station variables only)."""

    name = "station prior"
    variables: tuple[VariableFamily, ...] = (STATION_POSE,)

    def __init__(self, problem: GraphProblem, layout: VariableLayout):
        priors = problem.station_priors or {}
        self.slots = [s for s in sorted(priors) if layout.holds(STATION_POSE, s)]
        self._priors = [priors[s] for s in self.slots]
        self._factors: list[gtsam.NonlinearFactor] = []

    def keys(self, i: int) -> list[int]:
        return [STATION_POSE.key(self.slots[i])]

    def add_to(self, graph: gtsam.NonlinearFactorGraph, ensure: Ensure) -> None:
        first = graph.size()
        self._factors = [gtsam.PriorFactorPose3(STATION_POSE.key(slot), gtsam.Pose3(T),
                                                gtsam.noiseModel.Gaussian.Covariance(white))
                         for slot, (T, white, _) in zip(self.slots, self._priors, strict=True)]
        for factor in self._factors:
            graph.add(factor)
        self.indices = range(first, graph.size())

    def whitened_errors(self) -> list[np.ndarray]:
        """Per prior (graph order), the 6x6 covariance of its whitened residual when the
        earlier estimate's error has the honest covariance: ``R C R^T`` with the white
        noise model's ``R`` (``Sigma_white^-1 = R^T R``); the identity when the two agree."""
        out = []
        for _, white, honest in self._priors:
            R = np.linalg.cholesky(np.linalg.inv(white)).T
            out.append(R @ honest @ R.T)
        return out

    def chi2(self, values: gtsam.Values) -> np.ndarray:
        """Each prior's whitened squared residual at ``values`` (6 dof each)."""
        return np.array([2.0 * f.error(values) for f in self._factors])

    def cost(self, values: gtsam.Values) -> float:
        return float(0.5 * self.chi2(values).sum())

    def honest_chi2(self, values: gtsam.Values) -> np.ndarray:
        """Each prior's squared residual ``Log(T_prior^-1 T)`` at ``values`` in units of the
        prior's honest covariance (6 dof each: how far this capture puts the station from
        where the earlier result says it is, as that result's own error would)."""
        out = []
        for slot, (T, _, honest) in zip(self.slots, self._priors, strict=True):
            now = values.atPose3(STATION_POSE.key(slot))
            r = gtsam.Pose3.Logmap(gtsam.Pose3(T).between(now))
            out.append(float(r @ np.linalg.solve(honest, r)))
        return np.array(out)

    def summary(self, values: gtsam.Values) -> dict[str, float]:
        return {f"station_prior_chi2_{slot}": float(c)
                for slot, c in zip(self.slots, self.honest_chi2(values), strict=True)}
