"""Initial values for the estimators: the :class:`Initialiser` protocol and its
implementations (per-station PnP joined by a weighted Kabsch)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:
    from lhgraph.estimation.init.pnp_kabsch import Initialisation
    from lhgraph.estimation.problem import GraphProblem
    from lhgraph.io.angles import Angles
    from lhgraph.model.board import Board


class Initialiser(Protocol):
    """Anything that gives a graph problem its initial values: station poses ``T_world_lh``
    (slot 0, the reference, is the identity), board poses and twists at every state."""

    def __call__(self, board: Board, angles: Angles, problem: GraphProblem
                 ) -> Initialisation: ...
