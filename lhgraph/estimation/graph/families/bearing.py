"""The bearing factors (one per sweep) and their sweep-offset priors: :class:`Bearings`.

Sweep k's factor, keys :func:`bearing_keys` (board pose, twist and sweep offset of state k,
the station's pose unless it is held fixed, the board's corrections when the graph has
them, :mod:`.corrections`, and the station's factory-term corrections, :mod:`.factory`):
one row per diode hit in that sweep, residual = predicted angle of the full station model
(its factory terms corrected; :func:`lhgraph.estimation.residuals.bearing_residuals`) +
sweep offset - measured, isotropic diode noise wrapped in the per-diode robust loss
(:mod:`lhgraph.estimation.graph.loss`). Every sweep offset has a zero-mean prior (GTSAM's
``PriorFactorVector``).
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
    read_only,
)
from lhgraph.estimation.graph.families.corrections import BoardCorrections
from lhgraph.estimation.graph.families.factory import FactoryCorrections
from lhgraph.estimation.graph.loss import RobustLoss
from lhgraph.estimation.graph.variables import (
    BOARD_POSE,
    BOARD_TWIST,
    STATION_POSE,
    SWEEP_OFFSET,
    VariableFamily,
    VariableLayout,
)
from lhgraph.estimation.problem import GraphProblem
from lhgraph.estimation.residuals import bearing_residuals


def bearing_keys(k: int, station_var: int | None, corrections: list[int] | None = None
                 ) -> list[int]:
    """Keys of sweep k's bearing factor; ``station_var``: the slot of the sweeping station
    when its pose is a variable, None when it is held fixed (the reference);
    ``corrections``: the keys of the corrections the graph has, in order (the sweeping
    station's diode-bias vector, the sensor offsets, the station's factory terms)."""
    keys = [BOARD_POSE.key(k), BOARD_TWIST.key(k), SWEEP_OFFSET.key(k)]
    if station_var is not None:
        keys.append(STATION_POSE.key(station_var))
    return keys + list(corrections or [])


def bearing_factor(keys: list[int], n_hits: int, angle_sigma_rad: float,
                   estimator: gtsam.noiseModel.mEstimator.Base, error: FactorError
                   ) -> gtsam.CustomFactor:
    """A sweep's bearing factor on ``keys`` (:func:`bearing_keys`): ``n_hits`` diodes of
    noise ``angle_sigma_rad``, wrapped in the robust ``estimator``
    (:meth:`RobustLoss.estimator`)."""
    noise = gtsam.noiseModel.Robust.Create(
        estimator, gtsam.noiseModel.Isotropic.Sigma(n_hits, angle_sigma_rad))
    return gtsam.CustomFactor(noise, keys, error)


def offset_prior(k: int, noise: gtsam.noiseModel.Base) -> gtsam.PriorFactorVector:
    """The zero-mean prior of ``noise`` (1-D, rad) on sweep k's offset."""
    return gtsam.PriorFactorVector(SWEEP_OFFSET.key(k), np.zeros(1), noise)


class Bearings(FactorFamily):
    """Every sweep's bearing factor and sweep-offset prior, evaluated at once.

    Noise: ``angle_sigma_rad`` per diode (the factors' noise models), scaled by
    :meth:`scale_noise` (the residuals and Jacobians are scaled instead of the models);
    ``sweep_offset_sigma_rad`` per sweep offset. Read API at the last evaluated point
    (read-only arrays, valid until the next evaluation): :meth:`residuals`,
    :meth:`whitened_residuals`, :meth:`robust_weights`, :meth:`angle_sigma`."""

    name = "bearing"

    def __init__(self, problem: GraphProblem, layout: VariableLayout, loss: RobustLoss,
                 angle_sigma_rad: float, sweep_offset_sigma_rad: float,
                 corrections: BoardCorrections, factory: FactoryCorrections):
        self.problem, self.layout, self.loss = problem, layout, loss
        self.corrections, self.factory = corrections, factory
        self._sigma0 = angle_sigma_rad
        self._offset_sigma = sweep_offset_sigma_rad
        self._scale = 1.0  # sigma_0 / sigma: the diodes' noise is sigma, not sigma_0
        self._O = np.full(problem.n_states, np.nan)
        self._ones = np.ones((len(problem.hits.angle), 1))
        self._raw: tuple[Array, Array, Array] | None = None
        self._ready = False
        self._r = self._r_whitened = np.zeros(0)

    @property
    def variables(self) -> tuple[VariableFamily, ...]:
        return ((BOARD_POSE, BOARD_TWIST, SWEEP_OFFSET, STATION_POSE)
                + self.corrections.variables + self.factory.variables)

    @property
    def depends_on(self) -> tuple[FactorFamily, ...]:
        return (self.corrections, self.factory)

    def _station_var(self, slot: int) -> int | None:
        return slot if self.layout.holds(STATION_POSE, slot) else None

    def keys(self, i: int) -> list[int]:
        """Keys of sweep ``i``'s bearing factor (the offset priors follow them: factor
        ``n_states + k`` is sweep k's prior, key its offset)."""
        K = self.problem.n_states
        if i >= K:
            return [SWEEP_OFFSET.key(i - K)]
        slot = int(self.problem.state_station[i])
        return bearing_keys(i, self._station_var(slot), self.corrections.bearing_keys(slot)
                            + self.factory.bearing_keys(slot))

    def add_to(self, graph: gtsam.NonlinearFactorGraph, ensure: Ensure) -> None:
        first, p = graph.size(), self.problem
        estimator = self.loss.estimator()
        for k in range(p.n_states):
            n = int(p.bounds[k + 1] - p.bounds[k])
            graph.add(bearing_factor(self.keys(k), n, self._sigma0, estimator,
                                     self._error(ensure, k)))
        noise = gtsam.noiseModel.Isotropic.Sigma(1, self._offset_sigma)
        for k in range(p.n_states):
            graph.add(offset_prior(k, noise))
        self.indices = range(first, graph.size())

    def read(self, values: gtsam.Values, point: BoardPoint) -> None:
        self._O = self.layout.read_vectors(values, SWEEP_OFFSET)[:, 0]
        h = self.corrections.hits
        self._point = point
        self._r = bearing_residuals(h, point.X, point.W, point.L, self.factory.models(),
                                    False)[0]
        self._r += self._O[h.state]
        self._r += self.corrections.angle_biases()
        self._raw = None
        self._rescale()

    def matches(self, values: gtsam.Values, k: int) -> bool:
        return values.atVector(SWEEP_OFFSET.key(k))[0] == self._O[k]

    def jacobians(self) -> None:
        """Computed once per point; only rescaled when the noise level changes there."""
        if self._ready:
            return
        if self._raw is None:
            pt = self._point
            _, HX, HW, HL = bearing_residuals(self.corrections.hits, pt.X, pt.W, pt.L,
                                              self.factory.models())
            self._raw = HX, HW, HL
        self._HX, self._HW, self._HL = (H * self._scale for H in self._raw)
        self._offset_jacobian = self._ones * self._scale
        self._ready = True

    def cost(self, values: gtsam.Values) -> float:
        """Robust loss of the whitened diode residuals plus half the squared whitened
        offset priors."""
        bearing = self.loss.cost(self._r_whitened / self._sigma0)
        offsets = 0.5 * (self._O / self._offset_sigma) ** 2
        return float(bearing.sum() + offsets.sum())

    # --- noise level and read API ----------------------------------------------------------

    def scale_noise(self, factor: float) -> None:
        """Multiply the diodes' angle variance by ``factor`` (before the first evaluation
        too: the residuals are scaled when they are read)."""
        self._scale /= np.sqrt(factor)
        self._rescale()

    def angle_sigma(self) -> float:
        """Effective per-diode angle noise (rad) now."""
        return self._sigma0 / self._scale

    def residuals(self) -> Array:
        """Per-hit angle residual, predicted (+ sweep offset) - measured (rad), in the
        problem's hit order."""
        return read_only(self._r)

    def whitened_residuals(self) -> Array:
        """Per-hit residuals in units of the current diode noise (sigmas)."""
        return self._r_whitened / self._sigma0

    def robust_weights(self) -> Array:
        """Per-hit robust weight in [0, 1] at the current diode noise."""
        return self.loss.weights(self._r, self.angle_sigma())

    def _rescale(self) -> None:
        self._r_whitened = self._r * self._scale
        self._ready = False

    def _error(self, ensure: Ensure, k: int) -> FactorError:
        """Callback of sweep k's bearing factor (keys as in :meth:`keys`)."""
        a, b = self.problem.bounds[k], self.problem.bounds[k + 1]
        station_var = self._station_var(int(self.problem.state_station[k]))

        def error(_f: gtsam.CustomFactor, values: gtsam.Values, H: list | None) -> Array:
            ensure(values, (k,), station_var)
            if H is not None:
                self.jacobians()
                H[0] = self._HX[a:b]
                H[1] = self._HW[a:b]
                H[2] = self._offset_jacobian[a:b]
                j = 3
                if station_var is not None:
                    H[3] = self._HL[a:b]
                    j = 4
                for H_j in (self.corrections.hit_jacobians(a, b, self._HX, self._scale)
                            + self.factory.hit_jacobian(a, b, self._scale)):
                    H[j] = H_j
                    j += 1
            return self._r_whitened[a:b]

        return error
