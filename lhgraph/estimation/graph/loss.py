"""The per-diode robust loss of the bearing factors, in one place: GTSAM's m-estimator (for
the factors) and the same loss and weights in numpy (for the optimiser's cost and the
result's per-hit weights).

``cauchy`` (default): ``rho(x) = k^2 / 2 log(1 + (x / k)^2)``, weight ``1 / (1 + (x / k)^2)``;
``huber``: ``rho(x) = x^2 / 2`` for ``|x| <= k``, else ``k |x| - k^2 / 2``, weight
``min(1, k / |x|)``; ``x`` the whitened residual (sigmas), ``k`` the scale in sigmas
(``GraphOptions.huber_k``, named so for the config files whatever the loss). The
m-estimator uses GTSAM's ``Scalar`` reweight scheme: each diode is weighted on its own (the
default ``Block`` would down-weight a whole sweep for one reflection).
"""

from __future__ import annotations

from dataclasses import dataclass

import gtsam
import numpy as np
from numpy.typing import NDArray

from lhgraph.errors import SolverError
from lhgraph.estimation.graph.options import LOSSES

Array = NDArray[np.float64]


@dataclass(frozen=True)
class RobustLoss:
    """Robust loss ``kind`` (``"cauchy"`` or ``"huber"``) of scale ``scale_sigmas``."""

    kind: str
    scale_sigmas: float

    def __post_init__(self) -> None:
        if self.kind not in LOSSES:
            raise SolverError(f"unknown loss '{self.kind}' (expected one of "
                              f"{', '.join(LOSSES)})")

    def estimator(self) -> gtsam.noiseModel.mEstimator.Base:
        """GTSAM's m-estimator of this loss, reweighting each residual row on its own."""
        make = (gtsam.noiseModel.mEstimator.Cauchy if self.kind == "cauchy"
                else gtsam.noiseModel.mEstimator.Huber)
        return make.Create(self.scale_sigmas,
                           gtsam.noiseModel.mEstimator.Base.ReweightScheme.Scalar)

    def cost(self, x: Array) -> Array:
        """``rho`` of whitened residuals ``x`` (sigmas): what GTSAM's robust noise model adds
        to the graph error per row."""
        k = self.scale_sigmas
        if self.kind == "cauchy":
            return 0.5 * k**2 * np.log1p((x / k) ** 2)
        ax = np.abs(x)
        return np.where(ax <= k, 0.5 * x**2, k * ax - 0.5 * k**2)

    def weights(self, residual: Array, sigma: float) -> Array:
        """Robust weight in [0, 1] of residuals ``residual`` (rad) at noise ``sigma`` (rad)."""
        z = np.abs(residual) / (sigma * self.scale_sigmas)
        return 1.0 / (1.0 + z**2) if self.kind == "cauchy" else np.minimum(1.0, 1.0 / z)
