"""The stations' self-calibration: chosen factory terms as graph variables,
:class:`FactoryCorrections`.

With ``factory_terms`` set (:class:`~lhgraph.estimation.graph.options.FactoryOptions`), every
station slot gets one vector (:func:`~lhgraph.estimation.graph.variables.factory_family`):
the correction (rad) of each chosen term, per axis, to the station's decoded (OOTX) value,
key-major (``[key0 axis0, key0 axis1, key1 axis0, ...]``). Its prior is zero-mean of spread
``factory_sigma_rad``: the terms stay at OOTX unless the capture says otherwise. The
bearing factors (:mod:`.bearing`) evaluate each station with its corrected model
(:meth:`FactoryCorrections.models`); their Jacobian in the corrections is the central
difference of the shared measurement model (:func:`lhgraph.estimation.residuals.
bearing_residuals`, at the board corrections' sensors), one evaluation pair per term and
axis for every station at once.
"""

from __future__ import annotations

from dataclasses import replace

import gtsam
import numpy as np

from lhgraph.estimation.graph.families.base import Array, BoardPoint, Ensure, FactorFamily
from lhgraph.estimation.graph.families.corrections import BoardCorrections
from lhgraph.estimation.graph.variables import FACTORY_TERMS, VariableFamily, VariableLayout
from lhgraph.estimation.problem import GraphProblem
from lhgraph.estimation.residuals import bearing_residuals
from lhgraph.model.station import StationModel

STEP_RAD = 1e-6
"""Half-step of the central difference in each term (rad; the terms are mrad to 0.1 rad)."""


def with_term_deltas(model: StationModel, keys: tuple[str, ...], delta: Array) -> StationModel:
    """``model`` with its factory terms ``keys`` moved by ``delta`` (rad, ``(len(keys), 2)``
    or flat key-major: ``[key0 axis0, key0 axis1, ...]``)."""
    d = np.asarray(delta, dtype=float).reshape(len(keys), 2)
    cal = model.calibration
    moved = {key: np.asarray(getattr(cal, key), dtype=float) + d[i]
             for i, key in enumerate(keys)}
    return replace(model, calibration=replace(cal, **moved))


class FactoryCorrections(FactorFamily):
    """The zero-mean priors on every station slot's factory-term corrections and their
    values at the evaluated point: :meth:`models` (the stations' corrected models, for the
    bearing factors), :meth:`hit_jacobian`, :meth:`corrections`. No factor and no variable
    when ``keys`` is empty."""

    name = "factory terms"

    def __init__(self, problem: GraphProblem, layout: VariableLayout, keys: tuple[str, ...],
                 sigma_rad: float, board: BoardCorrections):
        self.problem, self.layout, self.keys_solved = problem, layout, tuple(keys)
        self.board = board
        self.family = layout.family(FACTORY_TERMS)
        """The correction variables (None without; the layout's, made by
        :func:`~lhgraph.estimation.graph.variables.factory_family`)."""
        self._sigma = sigma_rad
        S = len(problem.station_ids)
        self._D = np.zeros((S, 0 if self.family is None else self.family.dim))
        self._models = list(problem.models)
        self._point: BoardPoint | None = None
        self._J: Array | None = None

    @property
    def variables(self) -> tuple[VariableFamily, ...]:
        return () if self.family is None else (self.family,)

    @property
    def depends_on(self) -> tuple[FactorFamily, ...]:
        return (self.board,)

    def keys(self, i: int) -> list[int]:
        """Keys of factor ``i``: station slot ``i``'s prior."""
        return [self.family.key(i)]

    def bearing_keys(self, slot: int) -> list[int]:
        """The correction key of a bearing factor of station ``slot`` (none without)."""
        return [] if self.family is None else [self.family.key(slot)]

    def add_to(self, graph: gtsam.NonlinearFactorGraph, ensure: Ensure) -> None:
        first = graph.size()
        if self.family is not None:
            noise = gtsam.noiseModel.Isotropic.Sigma(self.family.dim, self._sigma)
            for slot in self.layout.indices(self.family):
                graph.add(gtsam.PriorFactorVector(self.family.key(slot),
                                                  np.zeros(self.family.dim), noise))
        self.indices = range(first, graph.size())

    def read(self, values: gtsam.Values, point: BoardPoint) -> None:
        self._point, self._J = point, None
        if self.family is None:
            return
        self._D = self.layout.read_vectors(values, self.family)
        self._models = [with_term_deltas(m, self.keys_solved, d)
                        for m, d in zip(self.problem.models, self._D, strict=True)]

    def matches(self, values: gtsam.Values, k: int) -> bool:
        """Whether ``values`` hold state ``k``'s station's corrections as last read (the
        only ones its factors see: one key, not the family)."""
        if self.family is None:
            return True
        slot = int(self.problem.state_station[k])
        return np.array_equal(values.atVector(self.family.key(slot)), self._D[slot])

    def cost(self, values: gtsam.Values) -> float:
        return 0.5 * float(np.sum((self._D / self._sigma) ** 2))

    def models(self) -> list[StationModel]:
        """Every station slot's model with its corrections at the evaluated point (the
        problem's models without the family)."""
        return self._models

    def hit_jacobian(self, a: int, b: int, scale: float) -> list[Array]:
        """Jacobian ``(b - a, dim)`` of hits ``a:b`` (one sweep, whitened by ``scale``) with
        respect to their station's corrections (an empty list without the family)."""
        if self.family is None:
            return []
        if self._J is None:
            self._J = self._jacobian()
        return [self._J[a:b] * scale]

    def _jacobian(self) -> Array:
        """``d residual / d correction`` of every hit, in its own station's columns."""
        pt, h = self._point, self.board.hits
        J = np.zeros((len(h.angle), self.family.dim))
        for j in range(self.family.dim):
            step = np.zeros(self.family.dim)
            step[j] = STEP_RAD
            sides = [bearing_residuals(h, pt.X, pt.W, pt.L,
                                       [with_term_deltas(m, self.keys_solved, d + sign * step)
                                        for m, d in zip(self.problem.models, self._D,
                                                        strict=True)], False)[0]
                     for sign in (1.0, -1.0)]
            J[:, j] = (sides[0] - sides[1]) / (2 * STEP_RAD)
        return J

    def corrections(self) -> Array:
        """Every station slot's corrections ``(S, dim)`` (rad, key-major; ``(S, 0)``
        without)."""
        return self._D.copy()
