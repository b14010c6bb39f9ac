"""The board's self-calibration: per-diode angle biases, sensor-position corrections and the
board's scale, :class:`BoardCorrections`.

With ``diode_bias_sigma_rad`` > 0 every station slot sees every diode on each axis with a
constant angle bias (a vector per slot, :func:`~lhgraph.estimation.graph.variables.
diode_bias_family`, zero-mean prior of that spread); with ``sensor_offset_sigma_m`` > 0 one
vector corrects every sensor's position in the board frame
(:func:`~lhgraph.estimation.graph.variables.sensor_offset_family`, zero-mean prior of that
spread, and one factor holding the offsets' scale mode at zero, ``SCALE_SIGMA_M2``: the board
keeps the board file's size); with ``board_scale_sigma`` > 0 one scalar ``k``
(:data:`~lhgraph.estimation.graph.variables.BOARD_SCALE`, zero-mean prior of that spread)
scales every sensor position by ``1 + k`` about the board origin: the metric size of the
board, which angles alone cannot see (a board and a world both larger look the same) but an
accelerometer's metric path can. All enter the bearing factors (:mod:`.bearing`): the biases
add to each hit's angle, the offsets and the scale move each hit's sensor.
"""

from __future__ import annotations

from dataclasses import replace

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
from lhgraph.estimation.graph.variables import (
    BOARD_SCALE,
    DIODE_BIAS,
    SENSOR_OFFSET,
    VariableFamily,
    VariableLayout,
)
from lhgraph.estimation.problem import GraphProblem

SCALE_SIGMA_M2 = 1e-6
"""Spread of the sensor offsets' scale mode (sum over sensors of offset . position about the
board's centroid, m^2): held at zero, the board keeps the board file's size."""


class BoardCorrections(FactorFamily):
    """The priors on the diode biases, the sensor offsets and the board scale (none of each
    when its sigma is 0), and their values at the evaluated point: :attr:`hits` (the
    problem's hits with the sensors moved), :meth:`angle_biases`, :meth:`diode_biases`,
    :meth:`sensor_offsets`, :meth:`scale`."""

    name = "board corrections"

    def __init__(self, problem: GraphProblem, layout: VariableLayout,
                 diode_bias_sigma_rad: float, sensor_offset_sigma_m: float,
                 board_scale_sigma: float = 0.0):
        self.problem, self.layout = problem, layout
        n, S = problem.n_sensors, len(problem.station_ids)
        self.bias = layout.family(DIODE_BIAS)
        """The diode-bias variables (None without; the layout's, made by
        :func:`~lhgraph.estimation.graph.variables.diode_bias_family`)."""
        self.offset = layout.family(SENSOR_OFFSET)
        """The sensor-offset variables (None without; the layout's, made by
        :func:`~lhgraph.estimation.graph.variables.sensor_offset_family`)."""
        self.scaled = layout.holds(BOARD_SCALE, 0)
        """Whether the board's scale is a variable (``board_scale_sigma`` > 0)."""
        self._bias_sigma, self._offset_sigma = diode_bias_sigma_rad, sensor_offset_sigma_m
        self._scale_sigma, self._k = board_scale_sigma, 0.0
        self._unscaled = problem.hits.s_board
        self._B = np.zeros((S, 0 if self.bias is None else self.bias.dim))
        self._bias_column = problem.hits.axis * n + problem.hit_sensor
        self._P = np.zeros((n, 3))
        self.hits = problem.hits
        """The problem's hits with every sensor moved by its offset, at the evaluated
        point."""
        seen = np.zeros((n, 3))
        seen[problem.hit_sensor] = problem.hits.s_board
        hit = np.zeros(n, dtype=bool)
        hit[problem.hit_sensor] = True
        self._scale_row = np.where(hit[:, None], seen - seen[hit].mean(axis=0), 0.0).ravel()

    @property
    def variables(self) -> tuple[VariableFamily, ...]:
        return (tuple(f for f in (self.bias, self.offset) if f is not None)
                + ((BOARD_SCALE,) if self.scaled else ()))

    def keys(self, i: int) -> list[int]:
        """Keys of factor ``i``: the diode biases' priors (one per station slot), then the
        sensor offsets' prior and scale factor, then the board scale's prior."""
        rows = [] if self.bias is None else [[self.bias.key(s)]
                                             for s in self.layout.indices(self.bias)]
        rows += [] if self.offset is None else [[self.offset.key(0)]] * 2
        rows += [[BOARD_SCALE.key(0)]] if self.scaled else []
        return rows[i]

    def bearing_keys(self, slot: int) -> list[int]:
        """The correction keys of a bearing factor of station ``slot`` (its diode biases,
        the sensor offsets, the board scale): the first correction keys of
        :func:`~.bearing.bearing_keys`."""
        return [f.key(slot if f is self.bias else 0) for f in self.variables]

    def add_to(self, graph: gtsam.NonlinearFactorGraph, ensure: Ensure) -> None:
        first = graph.size()
        if self.bias is not None:
            noise = gtsam.noiseModel.Isotropic.Sigma(self.bias.dim, self._bias_sigma)
            for slot in self.layout.indices(self.bias):
                graph.add(gtsam.PriorFactorVector(self.bias.key(slot), np.zeros(self.bias.dim),
                                                  noise))
        if self.offset is not None:
            key, dim = self.offset.key(0), self.offset.dim
            graph.add(gtsam.PriorFactorVector(
                key, np.zeros(dim), gtsam.noiseModel.Isotropic.Sigma(dim, self._offset_sigma)))
            graph.add(gtsam.CustomFactor(gtsam.noiseModel.Isotropic.Sigma(1, SCALE_SIGMA_M2),
                                         [key], self._scale_error()))
        if self.scaled:
            graph.add(gtsam.PriorFactorVector(
                BOARD_SCALE.key(0), np.zeros(1),
                gtsam.noiseModel.Isotropic.Sigma(1, self._scale_sigma)))
        self.indices = range(first, graph.size())

    def read(self, values: gtsam.Values, point: BoardPoint) -> None:
        p = self.problem
        if self.offset is not None:
            self._P = self.layout.read_vectors(values, self.offset)[0].reshape(-1, 3)
        if self.scaled:
            self._k = float(values.atVector(BOARD_SCALE.key(0))[0])
        if self.offset is not None or self.scaled:
            self._unscaled = p.hits.s_board + self._P[p.hit_sensor]
            self.hits = replace(p.hits, s_board=(1.0 + self._k) * self._unscaled)
        if self.bias is not None:
            self._B[self.layout.indices(self.bias)] = self.layout.read_vectors(values,
                                                                                self.bias)

    def matches(self, values: gtsam.Values, k: int) -> bool:
        return ((self.offset is None
                 or np.array_equal(values.atVector(self.offset.key(0)), self._P.ravel()))
                and (not self.scaled or values.atVector(BOARD_SCALE.key(0))[0] == self._k)
                and (self.bias is None
                     or np.array_equal(self.layout.read_vectors(values, self.bias), self._B)))

    def cost(self, values: gtsam.Values) -> float:
        cost = 0.0
        if self.bias is not None:
            cost += 0.5 * float(np.sum((self._B / self._bias_sigma) ** 2))
        if self.offset is not None:
            cost += 0.5 * float(np.sum((self._P / self._offset_sigma) ** 2)
                                + (self._scale_row @ self._P.ravel() / SCALE_SIGMA_M2) ** 2)
        if self.scaled:
            cost += 0.5 * (self._k / self._scale_sigma) ** 2
        return cost

    def angle_biases(self) -> Array | float:
        """Each hit's angle bias (rad; 0 without diode biases)."""
        if self.bias is None:
            return 0.0
        return self._B[self.hits.station, self._bias_column]

    def hit_jacobians(self, a: int, b: int, HX: Array, scale: float) -> list[Array]:
        """Jacobians of hits ``a:b`` (whitened by ``scale``) with respect to the bearing
        factor's correction keys: their station's diode biases, then the sensor offsets
        (the board pose's translation columns ``HX[:, 3:]``, already scaled: a sensor
        moved in the board frame moves like the board; times ``1 + k``), then the board
        scale (``HX[:, 3:]`` along the unscaled sensor position)."""
        out = []
        if self.bias is not None:
            H = np.zeros((b - a, self.bias.dim))
            H[np.arange(b - a), self._bias_column[a:b]] = scale
            out.append(H)
        if self.offset is not None:
            H = np.zeros((b - a, self.offset.dim))
            cols = 3 * self.problem.hit_sensor[a:b]
            rows = np.arange(b - a)
            for j in range(3):
                H[rows, cols + j] = HX[a:b, 3 + j] * (1.0 + self._k)
            out.append(H)
        if self.scaled:
            out.append(np.einsum("nj,nj->n", HX[a:b, 3:], self._unscaled[a:b])[:, None])
        return out

    def diode_biases(self) -> Array:
        """Every station slot's diode-bias vector ``(S, 2 * n_sensors)`` (rad, axis-major;
        ``(S, 0)`` when the graph has none)."""
        return read_only(self._B)

    def sensor_offsets(self) -> Array:
        """The sensor-position corrections ``(n_sensors, 3)`` (m, board frame; zeros when the
        graph has none)."""
        return read_only(self._P)

    def scale(self) -> float:
        """The board scale correction ``k`` (sensors at ``1 + k`` times their position; 0
        when the graph has none)."""
        return self._k

    def _scale_error(self) -> FactorError:
        """Callback of the factor holding the sensor offsets' scale mode at zero."""
        def error(_f: gtsam.CustomFactor, values: gtsam.Values, H: list | None) -> Array:
            p = values.atVector(self.offset.key(0))
            if H is not None:
                H[0] = self._scale_row[None]
            return np.array([self._scale_row @ p])

        return error
