"""The batch graph's factor families evaluated together at one point: :class:`FactorEvaluator`.

The evaluator composes the families (:mod:`lhgraph.estimation.graph.families`): it reads the
board states and stations once per point (:class:`~.families.base.BoardPoint`), hands them
to each family in turn, serves the families' callbacks the point they need
(:meth:`FactorEvaluator.ensure`: recomputed only when a callback's variables differ from the
cached ones), and sums the families' costs (the number ``graph.error`` returns, without a
Python callback per factor). What each family found is read off the family itself:
:attr:`FactorEvaluator.bearing`, :attr:`~FactorEvaluator.motion`,
:attr:`~FactorEvaluator.corrections`, :attr:`~FactorEvaluator.factory`,
:attr:`~FactorEvaluator.imu`.
"""

from __future__ import annotations

from typing import TypeVar

import gtsam
import numpy as np

from lhgraph.estimation.graph.families.base import Array, BoardPoint, FactorFamily, read_only
from lhgraph.estimation.graph.families.bearing import Bearings
from lhgraph.estimation.graph.families.corrections import BoardCorrections
from lhgraph.estimation.graph.families.factory import FactoryCorrections
from lhgraph.estimation.graph.families.motion import MotionPrior
from lhgraph.estimation.graph.variables import (
    BOARD_POSE,
    BOARD_TWIST,
    STATION_POSE,
    VariableLayout,
)
from lhgraph.estimation.imu.families import CombinedImuFamily, TwistImu
from lhgraph.estimation.problem import GraphProblem

F = TypeVar("F", bound=FactorFamily)


class FactorEvaluator:
    """The ``families`` of ``problem``'s batch graph on the variables of ``layout``, in the
    order their factors sit in the graph. Station slots that are no variable of ``layout``
    are held at ``T_world_lh`` ``(S, 4, 4)`` (default: the identity, i.e. the reference
    station is the world)."""

    def __init__(self, problem: GraphProblem, layout: VariableLayout,
                 families: list[FactorFamily], T_world_lh: Array | None = None):
        self.problem, self.layout, self.families = problem, layout, families
        for family in families:
            missing = [v.name for v in family.variables if v not in layout.families]
            if missing:
                raise ValueError(f"the {family.name} family needs variables the graph's "
                                 f"layout does not hold: {', '.join(missing)}")
        K, S = problem.n_states, len(problem.station_ids)
        self.point = BoardPoint(
            np.full((K, 4, 4), np.nan), np.full((K, 6), np.nan),
            np.repeat(np.eye(4)[None], S, axis=0) if T_world_lh is None
            else np.array(T_world_lh, dtype=float))
        self._values: gtsam.Values | None = None
        self._read_order: list[FactorFamily] = []
        for family in families:
            self._schedule(family)
        self.bearing = self._one(Bearings)
        """The bearing factors and sweep-offset priors (:class:`Bearings`)."""
        self.motion = self._one(MotionPrior)
        """The motion prior (:class:`MotionPrior`)."""
        self.corrections = self._one(BoardCorrections)
        """The board's diode biases and sensor offsets (:class:`BoardCorrections`)."""
        self.factory = self._one(FactoryCorrections)
        """The stations' factory-term corrections (:class:`FactoryCorrections`)."""
        self.imu = next((f for f in families if isinstance(f, TwistImu | CombinedImuFamily)),
                        None)
        """The IMU factors (:class:`TwistImu` or :class:`CombinedImuFamily`; None without)."""

    def _schedule(self, family: FactorFamily) -> None:
        """Put ``family`` in the read order after the families it depends on."""
        for first in family.depends_on:
            self._schedule(first)
        if family not in self._read_order:
            self._read_order.append(family)

    def _one(self, kind: type[F]) -> F:
        found = [f for f in self.families if isinstance(f, kind)]
        if len(found) != 1:
            raise ValueError(f"the graph needs one {kind.name} family, has {len(found)}")
        return found[0]

    @property
    def twist_imu(self) -> TwistImu | None:
        """The twist IMU factors when the graph has them (else None)."""
        return self.imu if isinstance(self.imu, TwistImu) else None

    # --- evaluation -----------------------------------------------------------------------

    def evaluate(self, values: gtsam.Values) -> None:
        """Make ``values`` the evaluated point (recomputed unless it is the cached one)."""
        if values is not self._values:
            self._read(values)

    def ensure(self, values: gtsam.Values, states: tuple[int, ...], slot: int | None) -> None:
        """Make ``values`` the evaluated point unless the cached one holds the same board
        ``states``, station ``slot`` (None: none) and every family's own variables there.

        A Python-owned Values reaches every callback as the same object: identity is
        enough. Values copied by GTSAM's optimisers are compared by content."""
        if values is self._values:
            return
        pt = self.point
        for k in states:
            if not (np.array_equal(values.atPose3(BOARD_POSE.key(k)).matrix(), pt.X[k])
                    and np.array_equal(values.atVector(BOARD_TWIST.key(k)), pt.W[k])
                    and (slot is None or np.array_equal(
                        values.atPose3(STATION_POSE.key(slot)).matrix(), pt.L[slot]))
                    and all(f.matches(values, k) for f in self.families)):
                self._read(values)
                return
        self._values = values

    def cost(self, values: gtsam.Values) -> float:
        """The graph's error at ``values`` (what ``graph.error`` returns): the sum of its
        families' costs."""
        self.evaluate(values)
        total = 0.0
        for family in self.families:
            total += family.cost(values)
        return float(total)

    # --- what the families found ----------------------------------------------------------

    def station_poses(self) -> Array:
        """``T_world_lh`` of every station slot ``(S, 4, 4)`` (fixed ones as given)."""
        return read_only(self.point.L)

    def board_poses(self) -> Array:
        """``T_world_board`` of every board state ``(K, 4, 4)``."""
        return read_only(self.point.X)

    def board_twists(self) -> Array:
        """Body twist ``[omega, v]`` of every board state ``(K, 6)``."""
        return read_only(self.point.W)

    def imu_bias(self) -> Array | None:
        """The IMU bias ``[gyro (rad/s), accelerometer (m/s^2)]`` (6,) now (None without IMU
        factors; with the combined factors the states' mean)."""
        return None if self.imu is None else self.imu.bias(self._values)

    def gravity(self) -> Array | None:
        """The gravity vector (m/s^2, world) at the evaluated point (None without IMU
        factors)."""
        return None if self.imu is None else self.imu.gravity(self._values)

    def summary(self) -> dict[str, float]:
        """Every family's figures at the evaluated point (the result's diagnostics): the
        motion prior's PSDs and chi2 per degree of freedom, the angle noise, and what the
        IMU factors found."""
        psd_rot, psd_pos = self.motion.psd()
        out = {"accel_psd_rot": psd_rot, "accel_psd_pos": psd_pos,
               "motion_chi2_per_dof": self.motion.chi2_per_dof(),
               "angle_sigma_rad": self.bearing.angle_sigma()}
        for family in self.families:
            out |= family.summary(self._values)
        return out

    def _read(self, values: gtsam.Values) -> None:
        poses = self.layout.read_poses(values)
        pt = self.point
        pt.L[self.layout.indices(STATION_POSE)] = poses[STATION_POSE]
        pt.X = poses[BOARD_POSE]
        pt.W = self.layout.read_vectors(values, BOARD_TWIST)
        for family in self._read_order:
            family.read(values, pt)
        self._values = values
