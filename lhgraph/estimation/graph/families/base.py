"""The interface every factor family of the batch graph implements, and the point they share.

A **factor family** is one kind of factor (the bearing factors, the motion prior, ...): one
object that

1. declares the variables its factors connect (:attr:`FactorFamily.variables`) and the keys
   of each factor (:meth:`FactorFamily.keys`);
2. adds its GTSAM factors to a graph (:meth:`FactorFamily.add_to`), whose callbacks ask the
   evaluator for the point first (an :data:`Ensure`);
3. evaluates its residuals at that point, vectorised (:meth:`FactorFamily.read`), its
   Jacobians on the first linearising callback there (:meth:`FactorFamily.jacobians`) and
   its share of the graph's error (:meth:`FactorFamily.cost`).

:class:`~lhgraph.estimation.graph.evaluator.FactorEvaluator` only composes the families:
it reads the board states and stations every family needs (:class:`BoardPoint`) once per
point and hands it to each family in turn.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from typing import ClassVar

import gtsam
import numpy as np
from numpy.typing import NDArray

from lhgraph.estimation.graph.variables import VariableFamily

Array = NDArray[np.float64]
FactorError = Callable[[gtsam.CustomFactor, gtsam.Values, list | None], Array]
"""A ``gtsam.CustomFactor`` callback: ``(factor, values, jacobians or None) -> residual``."""
Ensure = Callable[[gtsam.Values, tuple[int, ...], int | None], None]
"""The evaluator's ``ensure(values, states, slot)``: make ``values`` the evaluated point
unless the cached one holds the same board ``states``, station ``slot`` (None: no station
variable) and root variables."""


def read_only(a: Array) -> Array:
    """A read-only view of ``a``."""
    view = a.view()
    view.flags.writeable = False
    return view


@dataclass
class BoardPoint:
    """The board states and stations at the evaluated point: ``X`` ``T_world_board``
    (K, 4, 4), ``W`` body twists ``[omega, v]`` (K, 6), ``L`` ``T_world_lh`` by station slot
    (S, 4, 4; slots that are no variable stay at their given pose)."""

    X: Array
    W: Array
    L: Array


class FactorFamily(ABC):
    """One family of factors of the batch graph (see the module docstring for the life
    cycle). ``indices``: where its factors sit in the graph (set by :meth:`add_to`)."""

    name: ClassVar[str]
    indices: range = range(0)

    @property
    @abstractmethod
    def variables(self) -> tuple[VariableFamily, ...]:
        """The variable families its factors connect."""

    @abstractmethod
    def keys(self, i: int) -> list[int]:
        """Keys of its ``i``-th factor, in the order of the factor's Jacobians."""

    @abstractmethod
    def add_to(self, graph: gtsam.NonlinearFactorGraph, ensure: Ensure) -> None:
        """Add its factors to ``graph`` (and set :attr:`indices`)."""

    @property
    def depends_on(self) -> tuple[FactorFamily, ...]:
        """The families whose values at the point its residuals use (read before it)."""
        return ()

    def read(self, values: gtsam.Values, point: BoardPoint) -> None:
        """Evaluate its residuals at ``values``, whose board states are ``point`` (none by
        default: a family of linear or C++ factors has nothing to cache)."""
        return None

    def jacobians(self) -> None:
        """Make its Jacobians at the point of the last :meth:`read` (once per point; none by
        default)."""
        return None

    def matches(self, values: gtsam.Values, k: int) -> bool:
        """Whether ``values`` hold the family's own variables of board state ``k`` and its
        root variables as last read."""
        return True

    @abstractmethod
    def cost(self, values: gtsam.Values) -> float:
        """Its share of the graph's error at the point of the last :meth:`read`."""

    def summary(self, values: gtsam.Values) -> dict[str, float]:
        """Figures of what it found at the evaluated point (for the result's diagnostics)."""
        return {}


def indexed_callback(ensure: Ensure, states: tuple[int, ...], row: int,
                     family: FactorFamily, residuals: Callable[[], Array],
                     jacobians: Callable[[], tuple[Array, ...]]) -> FactorError:
    """The callback of a factor on board ``states`` (and root variables) whose residual and
    Jacobians are ``row`` of the arrays ``residuals()`` and ``jacobians()`` give once
    ``family`` evaluated them."""
    def error(_f: gtsam.CustomFactor, values: gtsam.Values, H: list | None) -> Array:
        ensure(values, states, None)
        if H is not None:
            family.jacobians()
            for j, H_j in enumerate(jacobians()):
                H[j] = H_j[row]
        return residuals()[row]

    return error
